"""Crash-safe HDF5 recordings in NeXus style.

    /entry                NXentry: @start_time @end_time @operator @software_version
                          @status (running | complete | aborted | fault) @status_reason
                          @samples_written @fs_hz, sweep/ (NXcollection, attributes), @rig_config (JSON),
                          @link_frames @link_frames_lost @link_frames_corrupt (sensor link counters)
    /entry/instrument     NXinstrument, one NXsensor per channel: @units, @sensitivity, @position
    /entry/data           NXdata @signal @axes="time": time (s), one dataset per channel (m/s^2),
                          chunked and appended in blocks
    /entry/gaps           (k, 2) int64: [first missing sample, count], from the sample indices
    /entry/quality        @usable_for_identification @reasons (JSON) @final (written at close, else at
                          the last flush) @mass_table_rms_ratio @clipped_share @rms @pair @thresholds;
                          flags: channel, kind (clipped | dead | stuck | nonfinite | ratio), first_row,
                          rows, samples, t_start_s, t_end_s, value (identify/data/quality.py says what each is)

Why this layout and this HDF5 mode (shared/notes, 12 SIGKILLs per mode): the default file format plus
a `flush()` at least every second leaves a file that any HDF5 reader opens after a SIGKILL, with every
row up to the last flush; SWMR files only open with swmr=True until `h5clear`, and libver="latest"
without SWMR did not open at all. So at most one second of samples is at risk, and a file found with
status "running" on the next start is a crashed recording: `recover()` marks it aborted, data intact.
Samples are never spliced: a missing stretch is listed in /entry/gaps and the time axis jumps.
"""
from __future__ import annotations

import json
import shutil
import time
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np

from identify.errors import RecordingError
from identify.data.quality import QualityMonitor, clip_level, verdict, with_status
from identify.data.recording import LAYOUTS, Recording, check_file

#: The channels a sweep records, and the (input, output) pair identification reads from a recording
#: unless told otherwise: the table's and the mass's accelerometers (the base layout's names).
DEFAULT_CHANNELS = (LAYOUTS["base"]["input"], LAYOUTS["base"]["output"])

STATUSES = ("running", "complete", "aborted", "fault")


class DiskFull(RecordingError):
    """Less free disk space than the recorder's reserve: the recording stops while the file is whole."""
FLUSH_EVERY_S = 1.0
CHUNK_ROWS = 4096
#: the quality detectors run over this many appended rows at a time (a stream frame is 64 rows: per-call
#: overhead would cost more than the detectors themselves), and at every flush
QUALITY_BATCH_ROWS = 8192
#: flags kept in the file (a pathological channel could produce one per tenth of a second for hours)
MAX_FLAGS = 10000
FLAG_DTYPE = np.dtype([("channel", "S32"), ("kind", "S16"), ("first_row", "<i8"), ("rows", "<i8"),
                       ("samples", "<i8"), ("t_start_s", "<f8"), ("t_end_s", "<f8"), ("value", "<f8")])
NOT_ASSESSED = {"assessed": False, "note": "not assessed: written before quality flags; identification "
                                           "assesses the rows it uses when it reads the file"}


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def software_version() -> str:
    try:
        from importlib.metadata import version

        return version("shakeid")
    except Exception:  # running from a source tree without installation metadata
        return "unknown"


class Recorder:
    """Append accelerometer blocks to a new HDF5 file; close with a final status.

    channels : names in stream order; units : per channel; fs_hz : sample rate; sensors : optional
    {channel: {"sensitivity": counts per unit, "position": "table"}}; sweep / rig_config : metadata;
    min_free_bytes : disk space to keep free, checked at every flush (DiskFull below it). Quality flags
    (identify/data/quality.py) are computed while recording and written at every flush and at close; their
    verdict is for pair = (input, output) channels (default table_acc, mass_acc, else the first two)."""

    def __init__(self, path, channels=DEFAULT_CHANNELS, fs_hz: float = 2048.0, operator: str = "",
                 sweep: dict | None = None, rig_config: dict | None = None, sensors: dict | None = None,
                 units: str = "m/s^2", min_free_bytes: int = 0, pair: tuple[str, str] | None = None):
        self.path = Path(path)
        self.min_free_bytes = int(min_free_bytes)  # flush() raises DiskFull below this much free space
        if self.path.exists():
            raise RecordingError(f"{self.path}: exists already; a recording is never overwritten")
        self.channels = tuple(channels)
        self.fs_hz = float(fs_hz)
        self.f = h5py.File(self.path, "w")
        e = self.f.create_group("entry")
        e.attrs.update(NX_class="NXentry", start_time=_now(), end_time="", operator=operator,
                       software_version=software_version(), status="running", status_reason="", samples_written=0,
                       fs_hz=self.fs_hz, rig_config=json.dumps(rig_config or {}))
        sw = e.create_group("sweep")
        sw.attrs["NX_class"] = "NXcollection"
        sw.attrs.update({k: v for k, v in (sweep or {}).items()})
        inst = e.create_group("instrument")
        inst.attrs["NX_class"] = "NXinstrument"
        levels = {}
        for ch in self.channels:
            g = inst.create_group(ch)
            meta = (sensors or {}).get(ch, {})
            sens = float(meta.get("sensitivity", 1.0))
            g.attrs.update(NX_class="NXsensor", units=units, sensitivity=sens,
                           position=str(meta.get("position", ch.split("_")[0])))
            levels[ch] = clip_level(sens)  # int16 counts at +-32767
        if pair is None:
            pair = DEFAULT_CHANNELS if set(DEFAULT_CHANNELS) <= set(self.channels) else self.channels[:2]
        self.pair = tuple(pair) if len(pair) == 2 else None
        self.quality_monitor = QualityMonitor(self.channels, self.fs_hz, levels, self.pair)
        self._pending: list[np.ndarray] = []  # appended rows the detectors have not seen yet
        self._pending_first = 0
        self._pending_rows = 0
        self.quality: dict = {}  # the final summary, set by close()
        d = e.create_group("data")
        d.attrs.update(NX_class="NXdata", signal=self.channels[-1], axes="time")
        self.time = d.create_dataset("time", (0,), maxshape=(None,), dtype="f8", chunks=(CHUNK_ROWS,))
        self.time.attrs["units"] = "s"
        self.data = {}
        for ch in self.channels:
            ds = d.create_dataset(ch, (0,), maxshape=(None,), dtype="f4", chunks=(CHUNK_ROWS,))
            ds.attrs["units"] = units
            self.data[ch] = ds
        self.gaps = e.create_dataset("gaps", (0, 2), maxshape=(None, 2), dtype="i8")
        self.gaps.attrs["columns"] = "first missing sample, count"
        q = e.create_group("quality")
        self.flags = q.create_dataset("flags", (0,), maxshape=(None,), dtype=FLAG_DTYPE, chunks=(64,))
        self._write_quality(final=False)
        self.next_index: int | None = None
        self.first_index: int | None = None  # sample index of the first sample recorded
        self.n = 0
        self.last_flush = time.monotonic()
        self.f.flush()  # the file and its "running" status exist on disk from the start

    def append(self, first_index: int, block: np.ndarray) -> None:
        """Samples (n, channels) whose first has sample index `first_index` (time = index / fs)."""
        block = np.asarray(block, dtype=np.float32)
        if block.ndim != 2 or block.shape[1] != len(self.channels):
            raise ValueError(f"block must be (n, {len(self.channels)})")
        if self.next_index is not None and first_index != self.next_index:
            if first_index < self.next_index:
                raise ValueError(f"samples out of order: {first_index} < {self.next_index}")
            self._assess()  # the detectors see each gap-free stretch with its own first sample index
            g = self.gaps.shape[0]
            self.gaps.resize((g + 1, 2))
            self.gaps[g] = (self.next_index, first_index - self.next_index)
        m = block.shape[0]
        if self.first_index is None:
            self.first_index = first_index
        self.time.resize((self.n + m,))
        self.time[self.n:] = (first_index + np.arange(m)) / self.fs_hz
        columns = np.ascontiguousarray(block.T)  # one transpose: h5py and the detectors read it contiguous
        for j, ch in enumerate(self.channels):
            ds = self.data[ch]
            ds.resize((self.n + m,))
            ds[self.n:] = columns[j]
        if not self._pending:
            self._pending_first = first_index
        self._pending.append(columns)
        self._pending_rows += m
        if self._pending_rows >= QUALITY_BATCH_ROWS:
            self._assess()
        self.n += m
        self.next_index = first_index + m
        if time.monotonic() - self.last_flush >= FLUSH_EVERY_S:
            self.flush()

    def _assess(self) -> None:
        """Run the quality detectors over the rows appended since they last ran."""
        if self._pending:
            columns = self._pending[0] if len(self._pending) == 1 else np.concatenate(self._pending, axis=1)
            self.quality_monitor.update_columns(columns, self._pending_first)
            self._pending, self._pending_rows = [], 0

    def quality_report(self) -> dict:
        """The detectors' report so far with the verdict for the pair: usable_for_identification, reasons."""
        self._assess()
        rep = self.quality_monitor.report()
        usable, reasons = verdict(rep, *self.pair) if self.pair else (True, [])
        return {**rep, "usable_for_identification": usable, "reasons": reasons}

    def _write_quality(self, final: bool, extra: dict | None = None) -> dict:
        rep = self.quality_report()
        flags = rep["flags"][:MAX_FLAGS]
        rows = np.array([(f["channel"].encode()[:32], f["kind"].encode(), f["first"], f["count"], f["samples"],
                          f["t_start_s"], f["t_end_s"], np.nan if f["value"] is None else f["value"]) for f in flags],
                        dtype=FLAG_DTYPE)
        self.flags.resize((rows.size,))
        if rows.size:
            self.flags[:] = rows
        ratio = rep["mass_table_rms_ratio"]
        self.flags.parent.attrs.update(
            usable_for_identification=rep["usable_for_identification"], reasons=json.dumps(rep["reasons"]),
            final=final, rows_assessed=rep["rows"], flags_total=len(rep["flags"]),
            mass_table_rms_ratio=np.nan if ratio is None else ratio, pair=json.dumps(rep["pair"]),
            clipped_share=json.dumps(rep["clipped_share"]), rms=json.dumps(rep["rms"]),
            thresholds=json.dumps(rep["thresholds"]), **(extra or {}))
        return rep

    def flush(self) -> None:
        """Make everything appended so far durable; first check the disk keeps its reserve (HDF5 that runs
        out of space mid-write can leave a file no reader opens: stopping early keeps it whole)."""
        free = shutil.disk_usage(self.path.parent).free
        if free < self.min_free_bytes:
            raise DiskFull(f"disk nearly full: {free / 2**20:.0f} MB free on {self.path.parent}, below the "
                           f"{self.min_free_bytes / 2**20:.0f} MB reserve; recording stopped with "
                           f"{self.n} samples kept")
        self.f["entry"].attrs["samples_written"] = self.n
        self._write_quality(final=False)  # a crashed file keeps the flags up to its last flush
        self.f.flush()
        self.last_flush = time.monotonic()

    def close(self, status: str = "complete", reason: str = "", link_stats: dict | None = None) -> None:
        """Final status and reason; link_stats (frames received / lost / corrupt, from the source) are
        kept as `link_*` attributes so a recording says how clean its sensor link was."""
        if status not in STATUSES[1:]:
            raise ValueError(f"final status must be one of {STATUSES[1:]}")
        e = self.f["entry"]
        e.attrs.update({f"link_{k}": int(v) for k, v in (link_stats or {}).items()})
        saturated = int((link_stats or {}).get("saturated_frames", 0))
        self.quality = quality_summary(self._write_quality(final=True, extra={"link_saturated_frames": saturated}))
        e.attrs.update(status=status, status_reason=reason, end_time=_now(), samples_written=self.n)
        self.f.close()


def quality_summary(report: dict) -> dict:
    """A short form of a quality report (for a sweep's result and the service's catalog)."""
    kinds = sorted({f"{f['channel']} {f['kind']}" for f in report.get("flags", [])})
    return {"usable_for_identification": report.get("usable_for_identification"),
            "reasons": report.get("reasons", []), "flags": len(report.get("flags", [])), "flagged": kinds}


def read_quality(f: h5py.File) -> dict:
    """The /entry/quality group of an open recording as a dict (NOT_ASSESSED for files without one)."""
    if "entry/quality" not in f:
        return dict(NOT_ASSESSED)
    q = f["entry/quality"]
    a = q.attrs
    ratio = float(a.get("mass_table_rms_ratio", np.nan))
    flags = [{"channel": r["channel"].decode(), "kind": r["kind"].decode(), "first": int(r["first_row"]),
              "count": int(r["rows"]), "samples": int(r["samples"]), "t_start_s": float(r["t_start_s"]),
              "t_end_s": float(r["t_end_s"]), "value": None if np.isnan(r["value"]) else float(r["value"])}
             for r in q["flags"][()]]
    out = {"assessed": True, "final": bool(a["final"]), "usable_for_identification": bool(a["usable_for_identification"]),
           "reasons": json.loads(a["reasons"]), "rows_assessed": int(a["rows_assessed"]),
           "flags_total": int(a.get("flags_total", len(flags))), "flags": flags,
           "mass_table_rms_ratio": None if np.isnan(ratio) else ratio}
    for k in ("pair", "clipped_share", "rms", "thresholds"):
        out[k] = json.loads(a[k])
    if "link_saturated_frames" in a:
        out["link_saturated_frames"] = int(a["link_saturated_frames"])
    return out


def recover(path) -> bool:
    """Mark a recording left "running" by a crash as aborted (data untouched). True if it was.

    Only a shakeid recording (an HDF5 file with /entry written by this recorder: @software_version,
    @status, entry/data/time) that says "running" is opened for writing. Anything else is left as it is,
    unopened for writing: a folder a sweep records into may hold the operator's own files, and a file
    another sweep is writing right now is locked by it (HDF5's lock), which is not a crash."""
    try:
        if not h5py.is_hdf5(path):
            return False
        with h5py.File(path, "r") as f:
            e = f.get("entry")
            if (not isinstance(e, h5py.Group) or "software_version" not in e.attrs
                    or e.attrs.get("status") != "running" or "data/time" not in e):
                return False
        f = h5py.File(path, "r+")
    except OSError:  # unreadable, or locked by the process writing it
        return False
    with f:
        e = f["entry"]
        n = int(f["entry/data/time"].shape[0])
        e.attrs.update(status="aborted", samples_written=n,
                       status_reason=f"found running by a recovery (a service's start or `shakeid recordings "
                                     f"--recover`): the recorder stopped without closing the file ({n} samples "
                                     f"up to its last flush are intact)")
        return True


def recover_directory(directory) -> list[Path]:
    """recover() every shakeid recording (.h5) of a directory left running; returns the files marked.
    Other files, HDF5 or not, are not touched."""
    return [p for p in sorted(Path(directory).glob("*.h5")) if recover(p)]


def check_h5_path(path) -> None:
    """Refuse, naming the problem in words, a path that cannot be an HDF5 recording: missing, not a file,
    or a file of another format (h5py's own message for these is its library's, errno and all)."""
    p = check_file(path)
    try:
        ok = h5py.is_hdf5(p)
    except OSError as exc:  # unreadable (permissions)
        raise RecordingError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not ok:
        raise RecordingError(f"{path}: not an HDF5 file (shakeid's recordings are the HDF5 files `shakeid sweep` "
                             "writes; CSV and MAT recordings end in .csv and .mat)")


def describe(path) -> dict:
    """Metadata, status, gaps and quality flags of a recording (for `shakeid recordings`)."""
    check_h5_path(path)
    try:
        with h5py.File(path, "r") as f:
            e = f["entry"]
            attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in e.attrs.items()}
            return {"path": str(path), **attrs,
                    "sweep": dict(e["sweep"].attrs), "channels": [k for k in e["data"] if k != "time"],
                    "samples": int(e["data/time"].shape[0]), "gaps": e["gaps"][()].tolist(),
                    "processed": [k for k in e["processed"] if k != "time"] if "processed" in e else [],
                    # the verdict with the status in it: an aborted recording is not usable, whatever its signals
                    "quality": with_status(read_quality(f), attrs.get("status"), attrs.get("status_reason"))}
    except (OSError, KeyError) as exc:
        if "unable to lock file" in str(exc):  # HDF5's lock: a writer has it open
            raise RecordingError(f"{path}: is open for writing by another process (a sweep still recording it?); "
                                 "read it when that has ended") from None
        raise RecordingError(f"{path}: not a shakeid HDF5 recording ({exc})") from None


def segments(time_s: np.ndarray, fs_hz: float) -> list[tuple[int, int]]:
    """Row ranges [a, b) of the gap-free stretches of a time axis (a gap: the index jumps by > 1)."""
    index = np.round(np.asarray(time_s) * fs_hz).astype(np.int64)
    breaks = np.flatnonzero(np.diff(index) != 1) + 1
    edges = np.concatenate([[0], breaks, [index.size]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def _rig_config(info: dict) -> dict:
    """The recording's @rig_config (JSON; {} when absent or unreadable)."""
    try:
        doc = json.loads(info.get("rig_config") or "{}")
    except (TypeError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def read_h5_recording(path, input: str = DEFAULT_CHANNELS[0], output: str = DEFAULT_CHANNELS[1],
                      samples: tuple[int, int] | None = None) -> Recording:
    """The recording (or rows samples=[a, b)) as identify's Recording. Samples are never spliced: a
    stretch that spans a gap is refused, naming the gap-free stretches to choose from."""
    info = describe(path)
    with h5py.File(path, "r") as f:
        d = f["entry/data"]
        missing = [c for c in (input, output) if c not in d]
        if missing:
            raise RecordingError(f"{path}: missing channel(s) {missing}; found {info['channels']}")
        fs = float(f["entry"].attrs["fs_hz"])
        a, b = samples or (0, info["samples"])
        if not 0 <= a < b <= info["samples"]:
            raise RecordingError(f"{path}: samples [{a}, {b}) requested: need 0 <= start < stop <= {info['samples']}, the recording's length")
        if info["gaps"]:
            segs = segments(d["time"][()], fs)
            if not any(sa <= a and b <= sb for sa, sb in segs):
                first, count = info["gaps"][0]
                longest = max(segs, key=lambda s: s[1] - s[0])
                raise RecordingError(
                    f"{path}: {len(info['gaps'])} gap(s) in the samples (first: {count} samples missing at "
                    f"sample {first}); identify a gap-free stretch with --samples A B (longest: rows "
                    f"{longest[0]} {longest[1]})")
        inst = f["entry/instrument"]
        full_scale = {c: clip_level(float(inst[c].attrs.get("sensitivity", 1.0))) for c in (input, output) if c in inst}
        rec = Recording(d[input][a:b], d[output][a:b], fs, "base", input, output,
                        (d[input].attrs.get("units", ""), d[output].attrs.get("units", "")), str(path),
                        {"status": info["status"], "status_reason": info.get("status_reason", ""),
                         "full_scale": full_scale, "first_row": a, "t0_s": float(d["time"][a]),
                         "moving_mass_kg": _rig_config(info).get("moving_mass_kg")})
    return rec
