"""Uploaded recordings: refused early when too large, streamed to disk, checked in a process of their own.

The stored name is the catalog id plus the type's suffix, never the client's name. A Content-Length over
the limit is refused (413) before a byte is read; the body goes to a temporary file in 1 MB writes; the
check (reading the file as a job will) runs in a separate Python process with a memory cap, at most
CHECKS_AT_ONCE at a time, so a 200 MB CSV costs the web server neither its event loop nor its memory.
A file that is not a usable recording is deleted and refused with the reader's own message (422).

    python -m server.uploads FILE SUFFIX NAME OPTIONS_JSON   # the check; prints one JSON line
"""
from __future__ import annotations

import asyncio
import json
import os
import sys
from pathlib import Path

from fastapi import HTTPException, Request

from daq.formats import FORMATS, check_upload
from identify.errors import ShakeidError

from .memory import release_freed_memory

#: An upload's file name: its type (suffix) picks the reader, so only the types daq.formats reads are taken.
FILENAME_PATTERN = r"^[\w.\-]{1,100}\.(" + "|".join(sx.lstrip(".") for f in FORMATS for sx in f.suffixes) + ")$"
FILENAME_WORDS = ("a recording's file name: letters, digits, '.', '-' and '_' (up to 100), ending in "
                  + ", ".join(sx for f in FORMATS for sx in f.suffixes))
CHECKS_AT_ONCE = 2
CHECK_TIMEOUT_S = 600.0
#: address space the checking process may use: the interpreter with numpy/scipy/h5py (~1 GB of mostly
#: unused mappings) plus 4x the file (a CSV's floats take at most ~1x; the rest is headroom)
CHECK_BASE_BYTES = 1536 * 2**20
WRITE_BYTES = 2**20

_checks = asyncio.Semaphore(CHECKS_AT_ONCE)


async def store_upload(request: Request, directory: Path, rec_id: str, filename: str, options: dict,
                       max_bytes: int) -> tuple[Path, dict]:
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > max_bytes:
        raise HTTPException(413, f"upload of {int(declared) / 2**20:.0f} MB is larger than the limit of "
                                 f"{max_bytes / 2**20:.0f} MB")
    suffix = Path(filename).suffix.lower()
    path = directory / f"{rec_id}{suffix}"
    tmp = directory / f".{rec_id}.part{suffix}"  # the readers go by the suffix
    size = 0
    try:
        with open(tmp, "wb") as f:
            pending = bytearray()
            async for chunk in request.stream():
                size += len(chunk)
                if size > max_bytes:
                    raise HTTPException(413, f"upload larger than the limit of {max_bytes / 2**20:.0f} MB")
                pending += chunk
                if len(pending) >= WRITE_BYTES:
                    f.write(pending)
                    pending.clear()
            f.write(pending)
        if size == 0:
            raise HTTPException(422, "empty upload: send the file as the request body")
        async with _checks:
            info = await _check_in_process(tmp, suffix, filename, options, size)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        release_freed_memory()  # the body's buffers went through the allocator: back to the system
    return path, {**info, "bytes": size}


async def _check_in_process(path: Path, suffix: str, filename: str, options: dict, size: int) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "SHAKEID_CHECK_MEMORY_BYTES": str(CHECK_BASE_BYTES + 4 * size)}
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "server.uploads", str(path), suffix, filename, json.dumps(options),
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, stdin=asyncio.subprocess.DEVNULL, env=env)
    try:
        out, err = await asyncio.wait_for(proc.communicate(), CHECK_TIMEOUT_S)
    except (asyncio.TimeoutError, asyncio.CancelledError):  # too slow, or the client went away
        proc.kill()
        await proc.wait()
        raise HTTPException(422, f"{filename}: could not be checked within {CHECK_TIMEOUT_S:g} s") from None
    try:
        answer = json.loads(out.decode().strip().splitlines()[-1])
    except (ValueError, IndexError):
        tail = err.decode(errors="replace").strip().splitlines()[-1:] or [f"exit code {proc.returncode}"]
        raise HTTPException(422, f"{filename}: the check of the file failed ({tail[0][:200]})") from None
    if not answer.get("ok"):
        raise HTTPException(422, answer.get("detail", f"{filename}: not a usable recording"))
    return answer["info"]


def check(path: Path, suffix: str, filename: str, options: dict) -> dict:
    """Read the file as a job will (daq.formats: every format the CLI reads); a RecordingError names what is
    wrong with it (as the client's name)."""
    try:
        return check_upload(path, options)
    except ShakeidError as exc:
        raise ShakeidError(str(exc).replace(str(path), filename)) from None
    except MemoryError:
        raise ShakeidError(f"{filename}: too large to check within the memory the service allows") from None
    except Exception as exc:  # a reader tripping on garbage is still the file's problem, said plainly
        raise ShakeidError(f"{filename}: not a readable recording ({type(exc).__name__}: {exc})") from None


def _main(argv: list[str]) -> int:
    import resource

    os.nice(10)  # batch work: the web server and the rig controller keep the cores
    limit = int(os.environ.get("SHAKEID_CHECK_MEMORY_BYTES", "0"))
    if limit:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    path, suffix, filename, options = argv[0], argv[1], argv[2], json.loads(argv[3])
    try:
        answer = {"ok": True, "info": check(Path(path), suffix, filename, options)}
    except ShakeidError as exc:
        answer = {"ok": False, "detail": str(exc)}
    print(json.dumps(answer), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
