"""Memory the web server freed goes back to the system: its RSS returns to the baseline after a flood.

Measured with benchmarks/estop_latency.py's flood (200 SSE viewers, 50 pollers, 200 MB uploads back to
back, identification jobs; 2 cores, 120 s of it), looking into the web server with gdb afterwards: RSS
156 MB before, 254 MB at the peak, 235 MB 30 s after (+51 %); glibc held 122 MB, 48 MB of it in use; 15
arenas of the thread pool's workers held ~6 MB each with ~0.1 MB in use; Python's own objects 50.5 -> 51.9
MB (125803 -> 132658: the routes' validators FastAPI builds on first use, nothing per viewer or upload).
So nothing of the flood is kept by the server: its freed memory was kept by the allocator. glibc raises
its mmap threshold to the largest block freed so far (here up to 17 MB) and its trim threshold to twice
that, after which every arena keeps that much free memory at its top instead of returning it;
malloc_trim(0) called into the process took it from 235 to 174 MB. With the thresholds fixed at
MMAP_THRESHOLD_BYTES and TRIM_THRESHOLD_BYTES from the start (what this module does) the same flood peaked
at 192 MB and left 171 MB, 168 MB after a malloc_trim(0). Big transient blocks (an upload's writes, an
SSE batch, a JSON answer) are then mapped and unmapped on their own, and a freed heap top goes back at once.

Elsewhere than glibc (musl, macOS) both calls do nothing and say so (False).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools

#: glibc's mallopt parameters (malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: blocks from this size on get a mapping of their own, unmapped when freed (glibc's initial value,
#: fixed: setting it turns off the raising that kept the memory)
MMAP_THRESHOLD_BYTES = 128 * 1024
#: free memory at an arena's top past this goes back to the system (glibc's default, fixed likewise)
TRIM_THRESHOLD_BYTES = 128 * 1024


@functools.lru_cache(maxsize=1)
def _libc():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def fix_malloc_thresholds() -> bool:
    """Fix glibc's mmap and trim thresholds for this process (call once at start, before the load).
    True if glibc took both."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))


def release_freed_memory() -> bool:
    """Give the free pages of every malloc arena back to the system (glibc's malloc_trim(0): also the
    holes inside the heaps, which the trim threshold does not reach); called when a load ends (the last
    viewer of a live feed leaves, an upload is stored). True if memory was returned."""
    libc = _libc()
    return bool(libc.malloc_trim(0)) if libc is not None else False
