"""Recordings: uniformly sampled input/output channels; readers for CSV and MAT files, and the one path
from any file's channels to a Recording (recording_from_channels: daq.formats reads the other formats).

Two layouts:
- ``base`` (the shaker rig): input = table acceleration, output = mass (absolute) acceleration, m/s^2.
  Default CSV header ``t,table_acc,mass_acc``.
- ``force`` (e.g. Silverbox): input = force-like `u`, output = displacement-like `y`; needs `fs_hz`
  when the file has no time column.

Every problem a file can have ends in a RecordingError naming the file and what is wrong.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .channels import (ACCELERATION_UNITS_TO_M_S2, TIME_UNITS_TO_S, Channel, NotASignal, SampleClock,
                       clock_from_time, unit_factor)
from .csvfile import read_csv
from ..errors import RecordingError

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
        """(input, output) samples [start, stop): a Recording is a chunk source too (identify.chain.chunked)."""
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
    """Read a CSV or MAT recording (daq.formats reads every format, these two through here)."""
    path = Path(path)
    if layout not in LAYOUTS:
        raise RecordingError(f"unknown layout {layout!r} (base or force)")
    check_file(path)
    suffix = path.suffix.lower()
    if suffix in MAT_SUFFIXES:
        channels = read_mat(path)
    elif suffix in CSV_SUFFIXES:
        channels = read_csv(path)
    else:
        raise RecordingError(f"{path}: unsupported file type {suffix!r} (csv or mat)")
    return recording_from_channels(channels, str(path), layout, input, output, time, fs_hz)


#: A sample rate stored coarser than this (relative) is named in the recording's warnings when no --fs
#: gives it exactly: UFF's E13.5 increment stores 1/2048 s as 4.88281e-04, 2048.001 Hz (docs/recordings.md).
RATE_RESOLUTION_WARNING = 1e-7


def recording_from_channels(channels: dict, source: str, layout: str = "base", input: str | None = None,
                            output: str | None = None, time: str | None = None, fs_hz: float | None = None,
                            noun: str = "column") -> Recording:
    """The one path from a file's channels to a Recording, whatever the format: channels chosen by name (the
    layout's names by default), units checked (g converted to m/s^2, others refused), the sample rate from
    the time column, else from the channels' own clock, else from fs_hz (--fs), which must agree with the
    file's. channels: {name: samples | Channel | NotASignal (saying why it is none) | None (not loaded)};
    noun: what the format calls them (column, channel, dataset)."""
    if layout not in LAYOUTS:
        raise RecordingError(f"{source}: unknown layout {layout!r} (base or force)")
    names = LAYOUTS[layout]
    input, output, time = input or names["input"], output or names["output"], time or names["time"]
    for c in (input, output, time):
        if isinstance(channels.get(c), NotASignal):
            why = channels[c].why() if hasattr(channels[c], "why") else str(channels[c])
            raise RecordingError(f"{source}: {noun} {c!r} {why}")
    found = [c for c, v in channels.items() if not isinstance(v, NotASignal)]
    missing = [c for c in (input, output) if c not in found]
    if missing:
        raise RecordingError(f"{source}: missing {noun}(s) {', '.join(map(repr, missing))}; "
                             f"found {', '.join(map(repr, found)) or 'none'}")
    notes: list[str] = []
    x_in, unit_in, clock_in = _in_layout_units(channels[input], input, names["units"][0], source, noun, notes)
    x_out, unit_out, clock_out = _in_layout_units(channels[output], output, names["units"][1], source, noun, notes)
    clock = _sample_clock(channels.get(time), time, [(input, clock_in), (output, clock_out)], fs_hz, source, noun)
    rec = Recording(x_in, x_out, clock.fs_hz, layout, input, output, (unit_in, unit_out), source)
    if fs_hz is None and clock.rel_resolution > RATE_RESOLUTION_WARNING:
        notes.append(_rate_warning(clock))
    if notes:
        rec.metadata["warnings"] = notes
    return rec


def _in_layout_units(value, name: str, unit: str, source: str, noun: str, notes: list) -> tuple:
    """(samples in the layout's unit, that unit, the channel's own clock or None)."""
    if not isinstance(value, Channel):
        return value, unit, None
    if unit != "m/s^2":  # the force layout takes the file's units as they are
        return value.values, value.unit, value.clock
    factor = unit_factor(value.unit, ACCELERATION_UNITS_TO_M_S2)
    if factor is None:
        raise RecordingError(f"{source}: {noun} {name!r} is in {value.unit!r}, not an acceleration: the base layout "
                             f"reads the table's and the mass's accelerations in m/s^2 (g is converted); scale it to "
                             f"an acceleration in the acquisition software, or name the right {noun} (--input, --output)")
    if factor != 1.0:
        notes.append(f"{noun} {name!r} converted from {value.unit} to m/s^2 (x {factor:g})")
    return value.values * factor, unit, value.clock


def _sample_clock(time_value, time: str, clocks: list, fs_hz, source: str, noun: str) -> SampleClock:
    """The recording's clock: a time column, else the channels' own (which must agree), else --fs; a --fs
    beside a clock must agree with it (within 1e-3), and replaces it when within the file's stored resolution."""
    own = [(n, c) for n, c in clocks if c is not None]
    if time_value is not None and not isinstance(time_value, NotASignal):
        t, unit = (time_value.values, time_value.unit) if isinstance(time_value, Channel) else (time_value, "")
        factor = unit_factor(unit, TIME_UNITS_TO_S)
        if factor is None:
            raise RecordingError(f"{source}: time {noun} {time!r} is in {unit!r}; time is read in s or ms")
        clock = clock_from_time(np.asarray(t, dtype=float) * factor, source, time)
    elif own:
        (a, ca), (b, cb) = own[0], own[-1]
        if abs(ca.fs_hz / cb.fs_hz - 1) > max(ca.rel_resolution, cb.rel_resolution) + 1e-12:
            raise RecordingError(f"{source}: {noun} {a!r} is sampled at {ca.fs_hz:.9g} Hz, {b!r} at {cb.fs_hz:.9g} Hz: "
                                 "input and output must share one clock")
        if abs(ca.start_s - cb.start_s) > 1e-3 / ca.fs_hz:
            raise RecordingError(f"{source}: {noun} {a!r} starts at {ca.start_s:.9g} s, {b!r} at {cb.start_s:.9g} s: "
                                 "input and output must start together (they would be misaligned)")
        clock = ca
    elif fs_hz is None:
        raise RecordingError(f"{source}: no time {noun} {time!r} and no sample clock in the file; give the sample "
                             "rate (--fs)")
    else:
        return SampleClock(float(fs_hz), what="--fs")
    if fs_hz is not None:
        rel = abs(float(fs_hz) / clock.fs_hz - 1)
        if rel > 1e-3:  # a wrong rate scales every coefficient
            raise RecordingError(f"{source}: the sample rate given ({float(fs_hz):g} Hz, --fs) disagrees with the "
                                 f"{clock.what} ({clock.fs_hz:.6g} Hz); the sample rate is for a file without one")
        if rel <= clock.rel_resolution * (1 + 1e-9):  # the file stores it coarser than --fs says it
            clock = SampleClock(float(fs_hz), clock.start_s, 0.0, f"--fs, within the {clock.what}'s resolution")
    return clock


def _rate_warning(clock: SampleClock) -> str:
    nearest = round(clock.fs_hz)
    hint = (f"; if the acquisition ran at {nearest:g} Hz, give --fs {nearest:g}"
            if abs(nearest / clock.fs_hz - 1) <= clock.rel_resolution else "; give the exact rate with --fs")
    return (f"sample rate {clock.fs_hz:.10g} Hz from the {clock.what}, which the file stores only to "
            f"{clock.rel_resolution:.1e} relative (every coefficient carries that error){hint}")


def read_mat(path: Path) -> dict[str, np.ndarray]:
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
