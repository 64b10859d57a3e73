"""Data quality of a recording: flags per channel and time range, and a verdict on identification.

    mon = QualityMonitor(("table_acc", "mass_acc"), fs_hz=2048, full_scale={"mass_acc": 50.0})
    mon.update(block)            # (n, channels), in order, as often as blocks arrive (the DAQ's recorder)
    report = mon.report()        # flags, clipped shares, RMS, the mass/table ratio
    usable, reasons = verdict(report, "table_acc", "mass_acc")
    assess_recording(rec)        # the same on a Recording's arrays (CSV, MAT, HDF5 read for identification)

Flag kinds (rows are 0-based rows of the recording; time from the sample index):

- clipped: |x| at the sensor's full scale (the stream's int16 counts at +-32767: |a| >= 32766.5 /
  sensitivity m/s^2); hits closer than MERGE_S are one flag, `samples` counts the clipped ones.
- dead / stuck: the channel holds exactly 0 / one other value for >= max(MIN_FLAT_SAMPLES, MIN_FLAT_S):
  a live accelerometer repeats a value on the next sample with probability p ~ q / (2 sqrt(pi) sigma)
  (ADC step q, noise sigma); even with sigma = q (p ~ 0.28) 64 equal samples have p^63 ~ 1e-35, and
  the simulated rig (sigma = 0.02 m/s^2, q = 1.5e-3) has p ~ 0.02. 50 ms covers oversampled sensors,
  whose neighbouring samples are correlated over about one period of their bandwidth (>= 100 Hz).
  A run at the full scale is clipping, not stuck.
- nonfinite: NaN or inf samples (merged as clipping).
- ratio: RMS (std) of mass over table acceleration outside RATIO_RANGE, for the whole record.

Limits: a noiseless (synthetic) channel that rests at exactly 0 is flagged dead, and a sensor whose noise
is well below one ADC step at rest is flagged stuck; both are said, not hidden.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: a value held this long (samples, and seconds) is a dead or stuck channel (module doc)
MIN_FLAT_SAMPLES = 64
MIN_FLAT_S = 0.05
#: clipped / non-finite samples closer than this (s) are one flag (a clipped sine clips every half period)
MERGE_S = 1.0
#: int16 full scale of the stream and CAN frames (protocol.frames.to_counts clips there)
FULL_SCALE_COUNTS = 32767
#: plausible std(mass) / std(table). Below 0.01 the mass moves less than the accelerometers' calibration
#: tolerance (1-2 %) of the table: q'' = x'' - z'' is then a sensitivity mismatch, and a mass channel
#: with noise only gives ~0.003 (sim rig: 0.02 / 6 m/s^2). Genuine sweeps measured 0.023 (design rig,
#: 20-50 Hz, 4-10x above resonance) to 17.9 (Table 1 rig swept 1-8 Hz around its 5 Hz resonance). A
#: passive oscillator cannot exceed its peak transmissibility ~1/(2 zeta); 100 needs zeta < 0.005 over
#: the whole record: above it, the table channel is dead-but-noisy or the units differ (mm/s^2 vs m/s^2).
RATIO_RANGE = (0.01, 100.0)
#: clipped share (of the rows identified) above which a channel makes the recording unusable. Measured
#: (Table 1 sweep, 0.5 % noise, mass channel clipped at its peaks): 0.03 % shifts q1*q2^2 by +0.02 %,
#: 0.06 % by +0.10 % (one standard error, 0.10 %), 0.15 % by +0.9 %, 0.7 % makes a -4587 % model.
MAX_CLIPPED_SHARE = 0.0005
KINDS = ("clipped", "dead", "stuck", "nonfinite", "ratio")


def clip_level(sensitivity: float, counts: int = FULL_SCALE_COUNTS) -> float:
    """|a| (units of the channel) at or above which a sample of an ADC with `counts` full scale and
    `sensitivity` counts per unit is clipped: half a count below full scale."""
    return (counts - 0.5) / sensitivity


@dataclass
class Flag:
    channel: str
    kind: str
    first: int          # first row
    count: int          # rows spanned
    samples: int        # rows affected within the span (clipped / nonfinite; = count otherwise)
    t_start_s: float
    t_end_s: float
    value: float = float("nan")  # the value held (dead / stuck), the ratio (ratio)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["value"] = None if not np.isfinite(self.value) else float(self.value)
        return d


class QualityMonitor:
    """Incremental detectors over blocks of rows (n, channels). full_scale: {channel: level} (|x| >=
    level is clipped) or {channel: (low, high)}; missing channels are never clipped. pair: (table,
    mass) channel names for the ratio, or None."""

    def __init__(self, channels, fs_hz: float, full_scale: dict | None = None,
                 pair: tuple[str, str] | None = ("table_acc", "mass_acc")):
        self.channels, self.fs_hz = tuple(channels), float(fs_hz)
        self.pair = pair if pair and all(c in self.channels for c in pair) else None
        self.min_flat = max(MIN_FLAT_SAMPLES, int(round(MIN_FLAT_S * self.fs_hz)))
        self.merge = max(1, int(round(MERGE_S * self.fs_hz)))
        lo, hi = [], []
        for c in self.channels:
            fsc = (full_scale or {}).get(c, np.inf)
            a, b = (-fsc, fsc) if np.isscalar(fsc) else fsc
            lo.append(a)
            hi.append(b)
        self.clip_lo, self.clip_hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
        k = len(self.channels)
        self.n = 0
        self.flags: list[Flag] = []   # closed flags
        self._open: dict[tuple[int, str], list[int]] = {}  # (channel, kind) -> [first, last, samples]
        self._run_val = np.full(k, np.nan)
        self._run_start = np.zeros(k, dtype=np.int64)
        self._run_len = np.zeros(k, dtype=np.int64)
        self.clipped = np.zeros(k, dtype=np.int64)
        self.nonfinite = np.zeros(k, dtype=np.int64)
        self._count = np.zeros(k)
        self._ref = None             # shift of the sums (_moments)
        self._sum = np.zeros(k)
        self._sumsq = np.zeros(k)
        self._breaks = [(0, 0)]       # (row, sample index) where the index jumps (gaps)

    # -- time axis -------------------------------------------------------------------------------
    def time_of(self, row: int) -> float:
        for r0, i0 in reversed(self._breaks):
            if row >= r0:
                return (i0 + row - r0) / self.fs_hz
        return row / self.fs_hz

    # -- detectors -------------------------------------------------------------------------------
    def update(self, block, first_index: int | None = None) -> None:
        """Rows (n, channels) appended in order; first_index: sample index of the first row (gaps shift
        the times)."""
        x = np.asarray(block)
        if x.ndim != 2 or x.shape[1] != len(self.channels):
            raise ValueError(f"block must be (n, {len(self.channels)})")
        # (channels, n) contiguous: reductions along rows are ~50x faster than down columns
        self.update_columns(np.ascontiguousarray(x.T), first_index)

    def update_columns(self, xt: np.ndarray, first_index: int | None = None) -> None:
        """As update(), with the block given as contiguous (channels, n) columns."""
        m = xt.shape[1]
        if m == 0:
            return
        n0 = self.n
        if first_index is not None:
            r0, i0 = self._breaks[-1]
            if i0 + n0 - r0 != first_index:
                self._breaks.append((n0, int(first_index)))
        mx, mn = xt.max(axis=1), xt.min(axis=1)  # cheap screens: most blocks are finite and unclipped
        all_finite = bool(np.isfinite(mx).all() and np.isfinite(mn).all())
        finite = None if all_finite else np.isfinite(xt)
        for j in np.flatnonzero((mx >= self.clip_hi) | (mn <= self.clip_lo) | (not all_finite)):
            hits = np.flatnonzero((xt[j] >= self.clip_hi[j]) | (xt[j] <= self.clip_lo[j]))
            if hits.size:
                self.clipped[j] += hits.size
                self._events(j, "clipped", hits + n0)
        if not all_finite:
            for j in np.flatnonzero(~finite.all(axis=1)):
                hits = np.flatnonzero(~finite[j])
                self.nonfinite[j] += hits.size
                self._events(j, "nonfinite", hits + n0)
        neq = xt[:, 1:] != xt[:, :-1]  # NaN != NaN: non-finite samples never form a run
        for j in range(len(self.channels)):
            self._runs(j, xt[j], neq[j], (m - 1) - np.count_nonzero(neq[j]), n0)
        self._moments(xt, finite)
        self.n += m

    def _moments(self, xt, finite) -> None:
        """Sums and sums of squares per channel about a fixed reference (the first finite sample): dot
        products in the block's own precision over <= 16384 samples, accumulated in float64. The shift
        keeps a channel's bias out of the squares (no cancellation); float32 keeps the pass cheap."""
        if self._ref is None:
            self._ref = np.array([row[np.isfinite(row)][0] if np.isfinite(row).any() else 0.0 for row in xt])
        d = xt - self._ref[:, None].astype(xt.dtype)
        if finite is None:
            nb = np.full(xt.shape[0], float(xt.shape[1]))
        else:
            nb = finite.sum(axis=1).astype(float)
            d[~finite] = 0.0
        self._count += nb
        for a in range(0, d.shape[1], 16384):
            c = d[:, a:a + 16384]
            self._sum += c @ np.ones(c.shape[1], dtype=c.dtype)
            self._sumsq += [np.dot(r, r) for r in c]

    def _runs(self, j: int, col: np.ndarray, neq: np.ndarray, n_eq: int, n0: int) -> None:
        """Runs of one repeated value; those of min_flat rows or more become dead / stuck flags. Only the
        runs at the block's ends are measured unless the block holds min_flat - 1 equal neighbours."""
        m = col.size
        if m == 1 or not neq.any():  # the whole block is one run
            if self._run_len[j] > 0 and col[0] == self._run_val[j]:
                self._run_len[j] += m
            else:
                self._close_run(j)
                self._run_val[j], self._run_start[j], self._run_len[j] = col[0], n0, m
            return
        lead = int(neq.argmax()) + 1                     # length of the block's first run
        w = neq[-256:]                                   # its last run, usually ends within a few samples
        tail = int((w if w.any() else neq)[::-1].argmax()) + 1
        if self._run_len[j] > 0 and col[0] == self._run_val[j]:
            first_start, first_len = self._run_start[j], self._run_len[j] + lead
        else:
            self._close_run(j)
            first_start, first_len = n0, lead
        if first_len >= self.min_flat:
            self._flat(j, first_start, first_len, col[0])
        if n_eq >= self.min_flat - 1 and m - tail > lead:  # an inner run may be long enough: measure them
            starts = np.flatnonzero(neq[lead:m - tail - 1]) + lead + 1
            bounds = np.concatenate(([lead], starts, [m - tail]))
            lengths = np.diff(bounds)
            for k in np.flatnonzero(lengths >= self.min_flat):
                self._flat(j, n0 + bounds[k], lengths[k], col[bounds[k]])
        self._run_val[j], self._run_start[j], self._run_len[j] = col[m - tail], n0 + m - tail, tail

    def _close_run(self, j: int) -> None:
        if self._run_len[j] >= self.min_flat:
            self._flat(j, self._run_start[j], self._run_len[j], self._run_val[j])
        self._run_len[j] = 0

    def _flat(self, j, first, count, value, into=None) -> None:
        value = float(value)
        if not np.isfinite(value) or value >= self.clip_hi[j] or value <= self.clip_lo[j]:
            return  # NaN never repeats; a run at full scale is clipping
        kind = "dead" if value == 0 else "stuck"
        (self.flags if into is None else into).append(self._flag(j, kind, int(first), int(count), int(count), value))

    def _flag(self, j, kind, first, count, samples, value=float("nan")) -> Flag:
        return Flag(self.channels[j], kind, first, count, samples, self.time_of(first),
                    self.time_of(first + count - 1), value)

    def _events(self, j: int, kind: str, rows: np.ndarray) -> None:
        """Group hit rows closer than `merge` into flags, continuing the open one."""
        cut = np.flatnonzero(np.diff(rows) > self.merge) + 1
        for group in np.split(rows, cut):
            a, b, k = int(group[0]), int(group[-1]), int(group.size)
            ev = self._open.get((j, kind))
            if ev is not None and a - ev[1] <= self.merge:
                ev[1], ev[2] = b, ev[2] + k
                continue
            if ev is not None:
                self.flags.append(self._flag(j, kind, ev[0], ev[1] - ev[0] + 1, ev[2]))
            self._open[(j, kind)] = [a, b, k]

    # -- results ---------------------------------------------------------------------------------
    def std(self) -> dict:
        """Standard deviation (RMS about the mean) of each channel's finite samples."""
        out = {}
        for j, c in enumerate(self.channels):
            n = self._count[j]
            out[c] = float(np.sqrt(max(self._sumsq[j] / n - (self._sum[j] / n) ** 2, 0.0))) if n else None
        return out

    def report(self) -> dict:
        """Flags so far (open stretches included, as they stand), clipped shares, RMS, the ratio."""
        flags = list(self.flags)
        for (j, kind), (a, b, k) in self._open.items():
            flags.append(self._flag(j, kind, a, b - a + 1, k))
        for j in range(len(self.channels)):
            if self._run_len[j] >= self.min_flat:
                self._flat(j, self._run_start[j], self._run_len[j], self._run_val[j], into=flags)
        std = self.std()
        ratio = None
        if self.pair:
            table, mass = (std[c] for c in self.pair)
            if table is not None and mass is not None:
                ratio = mass / table if table > 0 else float("inf")
                if not RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1] and self.n:
                    flags.append(Flag(self.pair[1], "ratio", 0, self.n, self.n, self.time_of(0),
                                      self.time_of(self.n - 1), ratio))
        flags.sort(key=lambda f: (f.first, f.channel, f.kind))
        n = max(self.n, 1)
        return {"rows": self.n, "fs_hz": self.fs_hz, "flags": [f.as_dict() for f in flags],
                "clipped_share": {c: float(self.clipped[j] / n) for j, c in enumerate(self.channels)},
                "nonfinite": {c: int(self.nonfinite[j]) for j, c in enumerate(self.channels)},
                "rms": std, "mass_table_rms_ratio": None if ratio is None else float(ratio),
                "pair": list(self.pair) if self.pair else None,
                "thresholds": {"min_flat_rows": self.min_flat, "merge_s": MERGE_S, "ratio_range": list(RATIO_RANGE),
                               "max_clipped_share": MAX_CLIPPED_SHARE}}


def verdict(report: dict, input: str, output: str) -> tuple[bool, list[str]]:
    """(usable for identification, reasons): a dead, stuck or non-finite stretch of the input or output,
    clipping above MAX_CLIPPED_SHARE of either, or a ratio out of range. Flags of other channels are
    listed by report() but do not decide."""
    reasons = []
    flags = [f for f in report["flags"] if f["channel"] in (input, output)]
    for ch in (input, output):
        for kind in ("dead", "stuck", "nonfinite"):
            hits = [f for f in flags if f["channel"] == ch and f["kind"] == kind]
            if not hits:
                continue
            f = hits[0]
            what = ("reads exactly 0" if kind == "dead" else f"is stuck at {f['value']:.6g}" if kind == "stuck"
                    else f"has {sum(h['samples'] for h in hits)} non-finite samples")
            more = f" (and {len(hits) - 1} more stretch(es))" if len(hits) > 1 else ""
            reasons.append(f"{ch} {what} from t = {f['t_start_s']:.3f} s{_into(f, report)} for {f['count']} samples "
                           f"({f['count'] / report['fs_hz']:.3g} s, rows {f['first']}-{f['first'] + f['count']}){more}")
        share = report["clipped_share"].get(ch, 0.0)
        if share > MAX_CLIPPED_SHARE:
            first = next(f for f in flags if f["channel"] == ch and f["kind"] == "clipped")
            reasons.append(f"{ch} clipped at full scale in {100 * share:.3g} % of the samples (limit "
                           f"{100 * MAX_CLIPPED_SHARE:g} %), from t = {first['t_start_s']:.3f} s{_into(first, report)}")
    ratio = report.get("mass_table_rms_ratio")
    if report.get("pair") == [input, output] and ratio is not None and not RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1]:
        reasons.append(f"RMS ratio {output}/{input} = {ratio:.3g}, outside the physically plausible "
                       f"{RATIO_RANGE[0]:g}-{RATIO_RANGE[1]:g}")
    return not reasons, reasons


def infer_full_scale(x: np.ndarray) -> tuple[float, float]:
    """(low, high) rails of a channel whose full scale is not known (CSV, MAT): its extreme value counts
    as a rail when it is held in >= 2 separate runs of >= 3 samples (a noisy signal reaches its extreme
    once; a quantised noiseless sine may plateau at its peak too: that case is flagged as clipping)."""
    out = []
    for v, sign in ((np.min(x), -1), (np.max(x), 1)):
        at = np.concatenate(([False], x == v, [False]))
        edges = np.flatnonzero(np.diff(at.astype(np.int8)))
        lengths = edges[1::2] - edges[::2]
        out.append(v if np.count_nonzero(lengths >= 3) >= 2 else sign * np.inf)
    return out[0], out[1]


def assess_arrays(columns: dict, fs_hz: float, full_scale: dict | None = None,
                  pair: tuple[str, str] | None = None) -> dict:
    """report() of the detectors over whole arrays {channel: samples}; full scale inferred where not given."""
    names = tuple(columns)
    data = np.column_stack([np.asarray(columns[c], dtype=float) for c in names])
    fsc = dict(full_scale or {})
    for j, c in enumerate(names):
        if c not in fsc:
            fsc[c] = infer_full_scale(data[np.isfinite(data[:, j]), j]) if np.isfinite(data[:, j]).any() else np.inf
    mon = QualityMonitor(names, fs_hz, fsc, pair)
    mon.update(data)
    return mon.report()


def assess_recording(rec) -> dict:
    """The detectors over an identify.data.recording.Recording's input and output; full scale from
    rec.metadata["full_scale"] ({channel: level}, the DAQ's files) or inferred; rows count from
    rec.metadata["first_row"] (a cut), times from rec.metadata["t0_s"] (the file's time axis at that row). The ratio only for the base layout (input = table, output = mass)."""
    pair = (rec.input_name, rec.output_name) if rec.layout == "base" else None
    report = assess_arrays({rec.input_name: rec.input, rec.output_name: rec.output}, rec.fs_hz,
                           rec.metadata.get("full_scale"), pair)
    row0 = int(rec.metadata.get("first_row", 0))  # rows and times of the file, for a cut (--samples)
    t0 = float(rec.metadata.get("t0_s", row0 / rec.fs_hz))  # the file's own time axis where it has one
    for f in report["flags"]:
        f["first"] += row0
        f["t_start_s"] += t0
        f["t_end_s"] += t0
    usable, reasons = verdict(report, rec.input_name, rec.output_name)
    return {**report, "usable_for_identification": usable, "reasons": reasons}


def _into(flag: dict, report: dict) -> str:
    """" (24.9 s into the recording)" where the file's time axis does not start at 0 (a DAQ file's is the
    rig's clock), so a time on it is not how far into the recording the flag is; "" where it is."""
    into = flag["first"] / report["fs_hz"]
    return f" ({into:.1f} s into the recording)" if abs(flag["t_start_s"] - into) > 0.5 else ""


def status_problem(status: str | None, reason: str | None = None) -> str | None:
    """Why a recording's status refuses it ("status is aborted (emergency stop), not complete"), or None:
    complete, or no status at all (CSV and MAT files have none)."""
    if status is None or status == "complete":
        return None
    return f"status is {status}" + (f" ({reason})" if reason else "") + ", not complete"


def with_status(quality: dict | None, status: str | None, reason: str | None = None) -> dict | None:
    """A recording's quality verdict with its status in it: the detectors judge the signals only, so an
    aborted or failed recording's report can read usable while identify refuses it. Its
    usable_for_identification is then False, the status problem first among the reasons; a running
    recording (not judged yet) and a complete one are returned as they are."""
    problem = None if status == "running" else status_problem(status, reason)
    if not quality or not problem:
        return quality
    reasons = [problem] + [r for r in quality.get("reasons") or [] if r != problem]
    return {**quality, "usable_for_identification": False, "reasons": reasons}


def identification_problems(rec) -> tuple[list[str], dict]:
    """Why a recording cannot carry a model (empty: it can), and its quality report: a status other than
    complete (the DAQ's files; CSV/MAT have none), then the verdict of assess_recording()."""
    status = status_problem(rec.metadata.get("status"), rec.metadata.get("status_reason"))
    problems = [status] if status else []
    quality = assess_recording(rec)
    return problems + quality["reasons"], quality


def check_identifiable(rec, name: str, accept_faulty: bool = False,
                       hint: str = "use --accept-faulty to identify it anyway") -> dict:
    """Refuse (RecordingError naming the file and every reason, with `hint`) a recording that cannot
    carry a model, unless accept_faulty. Returns what the result document says about the data:
    {"data_quality": {...}} and, when refused reasons were overridden, {"accepted_faulty": reasons}."""
    from ..errors import RecordingError

    problems, quality = identification_problems(rec)
    if problems and not accept_faulty:
        raise RecordingError(f"{name}: {'; '.join(problems)} ({hint})")
    out = {"data_quality": {
        "usable_for_identification": not problems, "reasons": problems,
        "assessed": "on read, over the rows identified",
        "flags": quality["flags"], "mass_table_rms_ratio": quality["mass_table_rms_ratio"],
        "clipped_share": quality["clipped_share"]}}
    if problems:
        out["accepted_faulty"] = problems
    return out
