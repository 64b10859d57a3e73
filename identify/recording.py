"""Recordings: uniformly sampled input/output channels, and readers for CSV and MAT files.

Two layouts:
- ``base`` (the shaker rig): input = table acceleration, output = mass (absolute) acceleration, m/s^2.
  Default CSV header ``t,table_acc,mass_acc``.
- ``force`` (e.g. Silverbox): input = force-like `u`, output = displacement-like `y`; needs `fs_hz`
  when the file has no time column.

Every problem a file can have ends in a RecordingError naming the file and what is wrong.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import RecordingError

LAYOUTS = {
    "base": {"input": "table_acc", "output": "mass_acc", "time": "t", "units": ("m/s^2", "m/s^2")},
    "force": {"input": "u", "output": "y", "time": "t", "units": ("", "")},
}
#: Fewer samples than this cannot carry a sweep worth identifying.
MIN_SAMPLES = 256


@dataclass
class Recording:
    """Input and output samples at `fs_hz`; `layout` says what they are (see module doc)."""

    input: np.ndarray
    output: np.ndarray
    fs_hz: float
    layout: str = "base"
    input_name: str = "table_acc"
    output_name: str = "mass_acc"
    units: tuple[str, str] = ("m/s^2", "m/s^2")
    source: str = "<memory>"
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        self.input = np.asarray(self.input, dtype=float).ravel()
        self.output = np.asarray(self.output, dtype=float).ravel()
        if self.layout not in LAYOUTS:
            raise RecordingError(f"{self.source}: unknown layout {self.layout!r} (base or force)")
        if self.input.shape != self.output.shape:
            raise RecordingError(f"{self.source}: input has {self.input.size} samples, output {self.output.size}")
        if not (np.isfinite(self.fs_hz) and self.fs_hz > 0):
            raise RecordingError(f"{self.source}: sample rate must be positive, got {self.fs_hz}")
        for name, x in ((self.input_name, self.input), (self.output_name, self.output)):
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                raise RecordingError(f"{self.source}: column {name!r} has {bad.size} NaN/inf values "
                                     f"(first at sample {bad[0]})")
        if self.input.size < MIN_SAMPLES:
            raise RecordingError(f"{self.source}: too short: {self.input.size} samples, need at least {MIN_SAMPLES}")
        if np.ptp(self.input) == 0:
            raise RecordingError(f"{self.source}: input column {self.input_name!r} is constant: nothing was excited")

    @property
    def n_samples(self) -> int:
        return self.input.size

    def read(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(input, output) samples [start, stop): a Recording is a chunk source too (identify.chunked)."""
        return self.input[start:stop], self.output[start:stop]

    @property
    def dt(self) -> float:
        return 1.0 / self.fs_hz

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.n_samples) / self.fs_hz

    def slice(self, start: int, stop: int) -> "Recording":
        return Recording(self.input[start:stop], self.output[start:stop], self.fs_hz, self.layout,
                         self.input_name, self.output_name, self.units, f"{self.source}[{start}:{stop}]",
                         dict(self.metadata))


def _sample_rate_from_time(t: np.ndarray, source: str, name: str) -> float:
    if t.size < 2:
        raise RecordingError(f"{source}: time column {name!r} needs at least two samples")
    d = np.diff(t)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise RecordingError(f"{source}: time column {name!r} is not strictly increasing")
    dt = np.median(d)
    # A uniform clock drifts by float rounding only; a dropped or doubled sample shows as a whole dt.
    worst = np.max(np.abs(d - dt))
    if worst > 1e-3 * dt:
        k = int(np.argmax(np.abs(d - dt)))
        raise RecordingError(f"{source}: time column {name!r} is not uniformly sampled: step {d[k]:.6g} s at "
                             f"sample {k + 1}, median step {dt:.6g} s (gaps must be repaired, not spliced)")
    # the whole span is far less sensitive to the rounding of printed time stamps than any one step
    return (t.size - 1) / (t[-1] - t[0])


#: File types read_recording reads, and the DAQ's HDF5 recordings' (read by daq.recorder, which needs h5py:
#: named here so that a command can tell them apart without importing it).
CSV_SUFFIXES, MAT_SUFFIXES, H5_SUFFIXES = (".csv", ".txt"), (".mat",), (".h5", ".hdf5")


def check_file(path) -> Path:
    """The path as a Path, or RecordingError naming why it cannot be read: missing, or not a file."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if not path.is_file():
        raise RecordingError(f"{path}: not a file")
    return path


def read_recording(path, layout: str = "base", input: str | None = None, output: str | None = None,
                   time: str | None = None, fs_hz: float | None = None) -> Recording:
    """Read a CSV or MAT recording (HDF5 recordings of the DAQ arrive with the DAQ)."""
    path = Path(path)
    if layout not in LAYOUTS:
        raise RecordingError(f"unknown layout {layout!r} (base or force)")
    names = LAYOUTS[layout]
    input = input or names["input"]
    output = output or names["output"]
    time = time or names["time"]
    check_file(path)
    suffix = path.suffix.lower()
    if suffix in MAT_SUFFIXES:
        columns = _read_mat(path)
    elif suffix in CSV_SUFFIXES:
        columns = _read_csv(path)
    else:
        raise RecordingError(f"{path}: unsupported file type {suffix!r} (csv or mat)")
    for c in (input, output, time):
        if isinstance(columns.get(c), TextColumn):
            raise RecordingError(f"{path}: column {c!r} holds text, not numbers ({columns[c]})")
    columns = {c: v for c, v in columns.items() if not isinstance(v, TextColumn)}
    missing = [c for c in (input, output) if c not in columns]
    if missing:
        raise RecordingError(f"{path}: missing column(s) {', '.join(map(repr, missing))}; "
                             f"found {', '.join(map(repr, columns)) or 'none'}")
    if time in columns:
        fs = _sample_rate_from_time(columns[time], str(path), time)
        if fs_hz is not None and abs(float(fs_hz) / fs - 1) > 1e-3:  # a wrong rate scales every coefficient
            raise RecordingError(f"{path}: the sample rate given ({float(fs_hz):g} Hz, --fs) disagrees with the "
                                 f"time column {time!r} ({fs:.6g} Hz); the sample rate is for a file without one")
    elif fs_hz is not None:
        fs = float(fs_hz)
    else:
        raise RecordingError(f"{path}: no time column {time!r}; give the sample rate (--fs)")
    return Recording(columns[input], columns[output], fs, layout, input, output, names["units"], str(path))


#: CSV rows parsed at a time: memory stays near the parsed floats (8 bytes a value), whatever the file size
CSV_CHUNK_ROWS = 1 << 16


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    """Streamed: rows are parsed in chunks of CSV_CHUNK_ROWS into float arrays, so a 200 MB file never
    exists as Python strings (the whole-file reader took 19x the file size in memory)."""
    try:
        with path.open(newline="") as f:
            return _parse_csv(path, f)
    except UnicodeDecodeError:
        raise RecordingError(f"{path}: not a text CSV file") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from None


def _parse_csv(path: Path, f) -> dict[str, np.ndarray]:
    lines = ((k, ln) for k, ln in enumerate(f, start=1) if ln.strip() and not ln.lstrip().startswith("#"))
    first = next(lines, None)
    if first is None:
        raise RecordingError(f"{path}: empty file")
    try:
        delim = csv.Sniffer().sniff(first[1], delimiters=",;\t ").delimiter
    except csv.Error:
        delim = ","
    header = [h.strip() for h in next(csv.reader([first[1]], delimiter=delim))]
    if any(_is_number(h) for h in header):
        raise RecordingError(f"{path}: first line must be a header naming the columns, got {first[1].strip()!r}")
    chunks, numbers, rows = [], [], []
    text: dict[str, str] = {}  # columns of words (an operator, a comment): kept out, named if asked for
    used = list(range(len(header)))
    for k, ln in lines:
        if not numbers and not chunks:  # the first data row says which columns are text
            fields = _fields(ln, delim)
            text = {header[j]: f"line {k}: {v.strip()!r}" for j, v in enumerate(fields[:len(header)])
                    if not _is_number(v)}
            used = [j for j, h in enumerate(header) if h not in text]
        numbers.append(k)
        rows.append(ln)
        if len(rows) == CSV_CHUNK_ROWS:
            chunks.append(_parse_rows(path, rows, numbers, delim, len(header), used))
            numbers, rows = [], []
    if rows:
        chunks.append(_parse_rows(path, rows, numbers, delim, len(header), used))
    data = np.concatenate(chunks) if chunks else np.empty((0, len(used)))
    return {**{header[j]: data[:, i] for i, j in enumerate(used)}, **{h: TextColumn(v) for h, v in text.items()}}


class TextColumn(str):
    """A CSV column of words, not numbers (where its first value is, e.g. "line 2: 'alice'"): left out of
    the signals, and named if a signal is asked of it."""


def _fields(line: str, delim: str) -> list[str]:
    return line.split() if delim == " " else next(csv.reader([line], delimiter=delim))


def _parse_rows(path: Path, rows: list[str], numbers: list[int], delim: str, n_cols: int, used: list[int]) -> np.ndarray:
    """rows (text lines, file line numbers `numbers`) -> (len(rows), len(used)) floats of the columns
    `used` (the numeric ones), or the first bad line named."""
    try:
        data = np.loadtxt(rows, delimiter=None if delim == " " else delim, ndmin=2, dtype=float, comments=None,
                          usecols=used if len(used) < n_cols else None)
        if data.shape == (len(rows), len(used)):
            # loadtxt reads only `used`: a row with too few or too many fields is caught below
            if len(used) == n_cols or all(len(_fields(ln, delim)) == n_cols for ln in rows):
                return data
    except ValueError:
        pass
    for k, ln in zip(numbers, rows):  # the slow path, only to say which line is wrong
        row = _fields(ln, delim)
        if len(row) != n_cols:
            raise RecordingError(f"{path}: line {k} has {len(row)} fields, header has {n_cols}")
        try:
            [float(row[j]) for j in used]
        except ValueError:
            raise RecordingError(f"{path}: line {k} has a non-numeric value: {ln.strip()[:80]!r}") from None
    raise RecordingError(f"{path}: lines {numbers[0]}-{numbers[-1]} could not be read as numbers")


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _read_mat(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    try:
        raw = loadmat(path)
    except NotImplementedError:
        raise RecordingError(f"{path}: MATLAB v7.3 (HDF5) .mat files are not supported; save with -v7") from None
    except Exception as exc:  # scipy raises ValueError/TypeError/MatReadError on garbage
        raise RecordingError(f"{path}: not a readable MAT file ({exc.__class__.__name__}: {exc})") from None
    out = {}
    for k, v in raw.items():
        if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu":
            continue
        if v.ndim <= 2 and min(v.shape or (1,)) == 1 and v.size > 1:
            out[k] = v.astype(float).ravel()
    return out


def write_csv(path, recording: Recording, extra: dict[str, np.ndarray] | None = None) -> None:
    """Write a recording as CSV with a time column (header t,<input>,<output>[,extra...])."""
    cols = {"t": recording.time_s, recording.input_name: recording.input, recording.output_name: recording.output}
    cols.update(extra or {})
    data = np.column_stack(list(cols.values()))
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt="%.12g")
