"""server/memory.py: memory a process frees goes back to the system (the web server's RSS after a flood).

Each case runs in a fresh interpreter (the allocator's state is per process): a big block freed first,
which makes glibc raise its thresholds, as the flood's largest blocks did in the web server; then 40 MB
allocated in the pattern of the case, freed, and the RSS read before, at the peak and after.
"""
from __future__ import annotations

import asyncio
import gc
import os
import subprocess
import sys
from pathlib import Path

from server.livefeed import Feed, Frame, LiveFeeds, Viewer

from .test_livefeed import Source, consume

REPO = Path(__file__).resolve().parents[2]

PRELUDE = f"""
import sys, threading
sys.path.insert(0, {str(REPO)!r})
from server.memory import fix_malloc_thresholds, release_freed_memory
def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
"""

#: four worker threads (each its own malloc arena, as the server's thread pool) hold 10 MB each, then end
THREADS = PRELUDE + """
if sys.argv[1] == "fixed":
    assert fix_malloc_thresholds()
big = bytes(8 * 2**20); del big
before = rss_mb(); held, done = threading.Barrier(5), threading.Barrier(5)
def worker():
    blocks = [bytearray(200 * 1024) for _ in range(50)]
    held.wait(); done.wait()
threads = [threading.Thread(target=worker) for _ in range(4)]
for t in threads: t.start()
held.wait(); peak = rss_mb(); done.wait()
for t in threads: t.join()
print(before, peak, rss_mb())
"""

#: the event loop's thread (the main arena): 200 KB blocks, each followed by a small one that stays
HOLES = PRELUDE + """
big = bytes(8 * 2**20); del big
before = rss_mb(); blocks, kept = [], []
for _ in range(200):
    blocks.append(bytearray(200 * 1024)); kept.append(bytearray(1024))
peak = rss_mb(); del blocks
if sys.argv[1] == "trim":
    release_freed_memory()
print(before, peak, rss_mb())
"""


def kept_share(program: str, mode: str) -> float:
    """The share of the growth (peak - before) the process still holds after freeing it, in glibc's own
    defaults: the environment's malloc settings are not passed on (Dask's nanny puts MALLOC_TRIM_THRESHOLD_
    into its parent's os.environ for good, `distributed.nanny.pre-spawn-environ`, so after the suite's Dask
    tests every child process trimmed by itself and the "default" case showed nothing)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    out = subprocess.run([sys.executable, "-c", program, mode], capture_output=True, text=True, check=True,
                         env=env).stdout
    before, peak, after = map(float, out.split())
    assert peak - before > 30, f"the case did not grow the process as meant: {out}"
    return (after - before) / (peak - before)


def test_fixed_thresholds_give_back_what_worker_threads_freed():
    # without the fix glibc keeps the threads' freed memory (the flood's +51 %): the case shows the problem
    assert kept_share(THREADS, "default") > 0.5
    assert kept_share(THREADS, "fixed") < 0.2


def test_release_gives_back_holes_between_blocks_still_in_use():
    assert kept_share(HOLES, "default") > 0.5
    assert kept_share(HOLES, "trim") < 0.2


def test_a_feed_keeps_nothing_of_its_viewers_once_they_leave():
    """The fan-out's side of it: after 50 viewers joined, read and left (half of them mid-stream), no
    viewer, queue, batch or feed object is left for the allocator to keep."""
    async def scenario():
        source = Source(end=40, notify_at=10**9)
        feeds = LiveFeeds(source.read_live, source.read_status, poll_s=0.0)
        streams = [feeds.stream("rec", 0) for _ in range(50)]
        firsts = await asyncio.gather(*(s.__anext__() for s in streams))
        assert all(f.startswith(b"event: samples") for f in firsts)
        await asyncio.gather(*(s.aclose() for s in streams[:25]))  # disconnected mid-stream
        await asyncio.gather(*(consume(s, []) for s in streams[25:]))  # read to the end
        del streams, firsts
        assert feeds.feeds == {}
        gc.collect()  # with the feeds still in service: nothing of the viewers is reachable
        assert [type(o).__name__ for o in gc.get_objects() if isinstance(o, (Viewer, Feed, Frame))] == []
        feeds.close()

    asyncio.run(scenario())
