"""The DAQ's HDF5 recordings (daq.recorder) as a chunk source for out-of-core identification
(identify.chain.chunked, identify.out_of_core): rows are read on demand, never the whole file.

The source is picklable (path, channels, row range): a Dask worker that unpickles it opens the file
itself, so every worker must see the file at the same path (as `shakeid batch`). The open file handle
is per process and reopened after unpickling.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from identify.errors import RecordingError

from .recorder import DEFAULT_CHANNELS, check_h5_path

#: Rows of the time axis read at a time when looking for gaps (8 MB).
TIME_CHUNK_ROWS = 1 << 20


class H5ChunkSource:
    """Rows [start, stop) of channels `input`, `output` of a DAQ recording (base layout: accelerations).

    samples : (a, b) rows to identify (default: all). A stretch that spans a gap in the samples is
    refused, naming the longest gap-free stretch (as daq.recorder.read_h5_recording)."""

    layout = "base"

    def __init__(self, path, input: str = DEFAULT_CHANNELS[0], output: str = DEFAULT_CHANNELS[1],
                 samples: tuple[int, int] | None = None):
        self.path = str(Path(path).resolve())
        self.input_name, self.output_name = input, output
        self.source = str(path)
        self._f = None
        check_h5_path(path)
        f = self._file()
        if "entry/data" not in f:
            raise RecordingError(f"{path}: not a shakeid HDF5 recording (no /entry/data)")
        d = f["entry/data"]
        missing = [c for c in (input, output) if c not in d]
        if missing:
            raise RecordingError(f"{path}: missing channel(s) {missing}; found {[k for k in d if k != 'time']}")
        rows = int(d[input].shape[0])
        self.fs_hz = float(f["entry"].attrs["fs_hz"])
        self.units = (d[input].attrs.get("units", ""), d[output].attrs.get("units", ""))
        a, b = samples or (0, rows)
        if not 0 <= a < b <= rows:
            raise RecordingError(f"{path}: samples [{a}, {b}) requested: need 0 <= start < stop <= {rows}, the recording's length")
        if len(f["entry/gaps"]) if "entry/gaps" in f else 0:
            segs = self.segments()
            if not any(sa <= a and b <= sb for sa, sb in segs):
                longest = max(segs, key=lambda s: s[1] - s[0])
                raise RecordingError(f"{path}: the rows {a}-{b} span a gap in the samples; identify a gap-free "
                                     f"stretch with --samples A B (longest: rows {longest[0]} {longest[1]})")
        self.start, self.n_samples = a, b - a

    def _file(self) -> h5py.File:
        if self._f is None:
            self._f = h5py.File(self.path, "r")
        return self._f

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_f"] = None  # an open HDF5 handle does not travel; the receiving process opens its own
        return state

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def segments(self) -> list[tuple[int, int]]:
        """Row ranges [a, b) of the gap-free stretches, from the time axis read in chunks."""
        t = self._file()["entry/data/time"]
        edges, prev = [0], None
        for r0 in range(0, t.shape[0], TIME_CHUNK_ROWS):
            idx = np.round(t[r0:r0 + TIME_CHUNK_ROWS] * self.fs_hz).astype(np.int64)
            if prev is not None:
                idx = np.concatenate([[prev], idx])
            edges += list(np.flatnonzero(np.diff(idx) != 1) + r0 + (0 if prev is not None else 1))
            prev = idx[-1]
        edges.append(t.shape[0])
        return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]

    def read(self, start: int, stop: int):
        """(table, mass) accelerations of rows [start, stop) of the stretch, float64."""
        d = self._file()["entry/data"]
        a, b = self.start + start, self.start + stop
        return d[self.input_name][a:b].astype(float), d[self.output_name][a:b].astype(float)

    def quality(self) -> dict:
        """The recorder's quality verdict stored in the file (daq.recorder.read_quality)."""
        from daq.recorder import read_quality

        return read_quality(self._file())

    def status(self) -> str:
        return str(self._file()["entry"].attrs.get("status", ""))


def recording_rows(path) -> int:
    """Number of rows of a DAQ recording (0 when the file is not one): to choose the out-of-core path."""
    try:
        with h5py.File(path, "r") as f:
            return int(f["entry/data/time"].shape[0])
    except (OSError, KeyError):
        return 0
