"""Uploaded recordings: streamed to disk under a size limit, then read once to check them.

The stored name is the catalog id plus the type's suffix, never the client's name; a file that is not
a usable recording is deleted and refused with the reader's own message (422).
"""
from __future__ import annotations

import asyncio
import os
from pathlib import Path

from fastapi import HTTPException, Request

from identify.errors import ShakeidError


async def store_upload(request: Request, directory: Path, rec_id: str, filename: str, options: dict,
                       max_bytes: int) -> tuple[Path, dict]:
    suffix = Path(filename).suffix.lower()
    path = directory / f"{rec_id}{suffix}"
    tmp = directory / f".{rec_id}.part{suffix}"  # the readers go by the suffix
    size = 0
    try:
        with open(tmp, "wb") as f:
            async for chunk in request.stream():
                size += len(chunk)
                if size > max_bytes:
                    raise HTTPException(413, f"upload larger than the limit of {max_bytes / 2**20:.0f} MB")
                f.write(chunk)
        if size == 0:
            raise HTTPException(422, "empty upload: send the file as the request body")
        # reading a large file takes seconds: off the event loop, so emergency stop and pollers are served
        info = await asyncio.to_thread(_check, tmp, suffix, filename, options)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path, {**info, "bytes": size}


def _check(path: Path, suffix: str, filename: str, options: dict) -> dict:
    """Read the file as a job will; a RecordingError names what is wrong with it."""
    try:
        if suffix in (".h5", ".hdf5"):
            from daq.recorder import describe

            d = describe(path)
            return {"samples": d["samples"], "fs_hz": d["fs_hz"], "gaps": len(d["gaps"]), "status_in_file": d["status"]}
        from identify.recording import read_recording

        rec = read_recording(path, options.get("layout", "base"), options.get("input"), options.get("output"),
                             options.get("time"), options.get("fs_hz"))
        return {"samples": rec.n_samples, "fs_hz": rec.fs_hz}
    except ShakeidError as exc:
        raise HTTPException(422, str(exc).replace(str(path), filename)) from None
    except Exception as exc:  # a reader tripping on garbage is still the file's problem, said plainly
        raise HTTPException(422, f"{filename}: not a readable recording ({type(exc).__name__}: {exc})") from None
