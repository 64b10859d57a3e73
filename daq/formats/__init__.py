"""Every recording file shakeid reads, in one registry: the CLI (identify, explain, batch), the service's
upload check and its jobs all open files here, so a format is one module of this package (defining
FORMAT) plus its line in FORMAT_MODULES.

A format's module turns a file into named channels (samples, unit, clock); identify.data.recording's
recording_from_channels then chooses input, output and time by name (--input/--output/--time), checks
units and the sample clock: one path for every format. Formats with a reader of their own (the DAQ's
HDF5: gaps, quality flags, row ranges read without loading the rest) give `open` instead.
Third-party libraries are imported inside the readers: naming the formats costs nothing.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import Callable

from identify.errors import RecordingError
from identify.data.recording import LAYOUTS, Recording, check_file, recording_from_channels

#: The registry: one line per format, its module's name in this package.
FORMAT_MODULES = (
    "hdf5",  # the DAQ's own HDF5 recordings (daq.recorder)
    "csvtext",  # CSV / text columns with a header (identify.data.csvfile)
    "matlab",  # MATLAB .mat v4-v7 (scipy)
    "tdms",  # NI TDMS: LabVIEW, DAQmx (npTDMS)
    "uff58",  # Universal File Format type 58, ASCII and binary 58b: Testlab, ME'scope, modal software (pyuff)
    "mdf4",  # ASAM MDF 4: automotive and many DAQ systems (asammdf)
)


@dataclass(frozen=True)
class FileFormat:
    """name: as the operator knows it; suffixes: lower case, with the dot; magic: what a file of the format
    begins with (None: any, e.g. text), `magic_words` saying it; channels(path, wanted) -> {name: samples |
    Channel | NotASignal | None (present, not loaded)}, loading at least the names wanted; noun: what the
    format calls a channel; open(path, request, samples) -> Recording and check(path, request) -> upload
    info for formats with their own reader."""

    name: str
    suffixes: tuple[str, ...]
    channels: Callable | None = None
    magic: re.Pattern | None = None
    magic_words: str = ""
    noun: str = "channel"
    open: Callable | None = None
    check: Callable | None = None


@dataclass(frozen=True)
class ReadRequest:
    """Which channels to read: the options --layout, --input, --output, --time, --fs."""

    layout: str = "base"
    input: str | None = None
    output: str | None = None
    time: str | None = None
    fs_hz: float | None = None

    @classmethod
    def from_options(cls, options: dict) -> "ReadRequest":
        """From a job's or an upload's read options (keys layout, input, output, time, fs_hz)."""
        return cls(options.get("layout", "base"), options.get("input"), options.get("output"), options.get("time"),
                   options.get("fs_hz"))


FORMATS: tuple[FileFormat, ...] = tuple(import_module(f"{__name__}.{m}").FORMAT for m in FORMAT_MODULES)
SUFFIXES: tuple[str, ...] = tuple(s for f in FORMATS for s in f.suffixes)
#: The formats by name, for help texts: "HDF5, CSV, MAT, TDMS, UFF58, MDF4".
NAMES = ", ".join(f.name for f in FORMATS)
#: Bytes read to tell a file's format from its content.
MAGIC_BYTES = 64


def format_of(path) -> FileFormat:
    """The format of a file by its suffix, or RecordingError listing the readable ones."""
    suffix = Path(path).suffix.lower()
    for fmt in FORMATS:
        if suffix in fmt.suffixes:
            return fmt
    raise RecordingError(f"{path}: unsupported file type {suffix!r} ("
                         + ", ".join(f"{f.name} {' '.join(f.suffixes)}" for f in FORMATS) + ")")


def check_content(path: Path, fmt: FileFormat) -> None:
    """Refuse a file whose first bytes are not its suffix's format, naming the format they look like."""
    if fmt.magic is None:
        return
    with open(path, "rb") as f:
        head = f.read(MAGIC_BYTES)
    if fmt.magic.match(head):
        return
    like = next((f for f in FORMATS if f.magic is not None and f.magic.match(head)), None)
    hint = f"; it looks like a {like.name} file, whose names end in {like.suffixes[0]}" if like else ""
    raise RecordingError(f"{path}: not in {fmt.name} format ({fmt.magic_words}){hint}")


def open_recording(path, layout: str = "base", input: str | None = None, output: str | None = None,
                   time_column: str | None = None, fs_hz: float | None = None,
                   samples: tuple[int, int] | None = None) -> Recording:
    """Any recording file, cut to rows samples=[a, b) if given, read as `shakeid identify` reads it."""
    fmt = format_of(path)
    path = check_file(path)
    request = ReadRequest(layout, input, output, time_column, fs_hz)
    if fmt.open is not None:  # its own reader says what is wrong with a file that is not of its format
        return fmt.open(path, request, samples)
    rec = read_channels(fmt, path, request)
    if samples:
        a, b = samples
        if not 0 <= a < b <= rec.n_samples:
            raise RecordingError(f"{path}: samples [{a}, {b}) requested: need 0 <= start < stop <= {rec.n_samples}, "
                                 "the recording's length")
        warnings = rec.metadata.get("warnings")
        rec = rec.slice(a, b)
        Recording.__post_init__(rec)  # the cut must still be a usable recording
        rec.metadata["first_row"] = a
        if warnings:
            rec.metadata["warnings"] = warnings
    return rec


def read_channels(fmt: FileFormat, path: Path, request: ReadRequest) -> Recording:
    """A file of a channel format as a Recording; a library's own exception on a damaged file becomes a
    RecordingError naming the file and the format."""
    check_content(path, fmt)
    names = LAYOUTS.get(request.layout, LAYOUTS["base"])
    wanted = {request.input or names["input"], request.output or names["output"], request.time or names["time"]}
    try:
        channels = fmt.channels(path, wanted)
    except (RecordingError, MemoryError):
        raise
    except Exception as exc:  # the library tripping on a damaged file: the file's problem, said plainly
        raise RecordingError(f"{path}: not a readable {fmt.name} file ({type(exc).__name__}: {exc})") from None
    return recording_from_channels(channels, str(path), request.layout, request.input, request.output,
                                   request.time, request.fs_hz, fmt.noun)


def check_upload(path, options: dict) -> dict:
    """What the service records of an upload, reading it as a job will: {samples, fs_hz[, warnings] ...}."""
    fmt = format_of(path)
    path = check_file(path)
    request = ReadRequest.from_options(options)
    if fmt.check is not None:
        return fmt.check(path, request)
    rec = open_recording(path, request.layout, request.input, request.output, request.time, request.fs_hz)
    info = {"samples": rec.n_samples, "fs_hz": rec.fs_hz}
    if rec.metadata.get("warnings"):
        info["warnings"] = rec.metadata["warnings"]
    return info
