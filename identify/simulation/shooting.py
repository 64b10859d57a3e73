"""Multiple shooting: a model's free-run error segment by segment, each segment started from the measured
state at its start.

A single free run over a whole sweep judges a Duffing model mostly by where it jumps between the two
branches of its resonance curve: a model a hair off jumps a second early or late and is out of phase
for that second, and a textbook baseline refit on that error can settle on the wrong branch (seen: gap
0.46), after which any added term that happens to move the jump takes the credit. Restarting from the
measured state every few periods of the resonance keeps every segment on the measured branch, so a jump
in the wrong place costs one segment, not the rest of the record, while a missing effect still shows
in every segment it acts in (a few periods are enough for friction, damping and stiffness errors to
build up in the free run).

Segments tile the identification blocks (identify.identifier.holdout_blocks), so each is either
training or held-out, and the per-segment errors are the units the bootstrap resamples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import SparseModel
from ..threads import map_runs, run_threads
from .simulate import (choose_step, equation_rows, fine_grid_input, jumps_at_rest, sampled_q1_dot, sign_jump_terms, simulate,
                       simulate_segments)

#: Largest fine input grid a ShootingData keeps (bytes; one, for the last substeps). A model that needs
#: many RK4 substeps (a refit's trial step far out, a stiff contact) multiplies the record by 2 x substeps:
#: a 102 s record at 1000 Hz at 256 substeps is 52.6 M rows, 0.8 GB a grid, and with a grid kept per
#: substeps and per fault trial an explanation grew to 13.5 GB and was killed (benchmark seed 1706589829,
#: case 140). Above it each segment's grid is built for the run and dropped.
FINE_GRID_BYTES = 32 * 2**20
#: Rows either side of a segment its own fine grid is interpolated from (the band-limited filter's reach
#: is 10 rows; resample_poly's Kaiser window).
FINE_PAD = 32

#: A segment's mean acceleration, which its offset matches (ShootingData.offsets), is read on every
#: OFFSET_ROW_STEP-th row for a model whose force is smooth (no jumps_at_rest): a mean over a segment of
#: hundreds of rows does not need every one. What it moves is the measurement noise's share of the mean:
#: offsets within 4e-5 of the stroke of those on every row (the smooth candidates of
#: tests/identify/test_explain_masking.py's rig, 1000 Hz, 0.5 % noise, which alone puts ~1.6e-4 of it on
#: them; 1.2e-4 at a step of 4; end stops count as smooth here, measured only through runs 21-22 of
#: docs/discrepancy.md); a friction's force steps where the mass turns, and sampled at
#: every other row the offsets moved by 4e-4 of the stroke (tests/identify/test_explain_masking.py's
#: Coulomb rig, 1000 Hz): every row there. Four passes of the model over all rows had cost a quarter
#: of an explanation's CPU (an end stop beside cubic damping, 19 s at 2048 Hz: 2.9 of 11.6 s).
OFFSET_ROW_STEP = 2

#: Most masks ShootingData.segment_rows and .spans keep theirs for (segment_rows': a record's worth of
#: indices each).
ROW_CACHE = 32
#: Most segment sets ShootingData.offsets keeps its rows' states and inputs for (each a copy of them).
OFFSET_ROWS_CACHE = 4

#: Segment length in periods of the (linear) resonance.
SEGMENT_PERIODS = 4.0
MIN_SEGMENT = 48


def segment_edges(block_edges: np.ndarray, held: np.ndarray, fs_hz: float, f_res_hz: float):
    """Split each block into segments of ~SEGMENT_PERIODS resonance periods: (starts, stops, held)."""
    target = max(int(round(SEGMENT_PERIODS * fs_hz / max(f_res_hz, 1e-3))), MIN_SEGMENT)
    starts, stops, flags = [], [], []
    for a, b, h in zip(block_edges[:-1], block_edges[1:], held):
        k = max(int(round((b - a) / target)), 1)
        e = np.linspace(a, b, k + 1).round().astype(int)
        starts += list(e[:-1])
        stops += list(e[1:])
        flags += [bool(h)] * k
    return np.array(starts), np.array(stops), np.array(flags)


@dataclass
class ShootingData:
    """What every segment run needs, on the valid rows: initial states (n, n_states), inputs (n, n_inputs),
    the measured gap signal, and how the gap signal is formed: 'q1_dot' (the model's acceleration on the
    simulated states) or 'q2' (the simulated displacement/output)."""

    states: np.ndarray
    inputs: np.ndarray
    measured: np.ndarray
    gap: str
    fs_hz: float
    starts: np.ndarray
    stops: np.ndarray
    held: np.ndarray
    scale: float = 1.0          # the gap error is reported in recorded units: (1 + mass gain) x error
    lowpass: object = None      # callable: the measurement chain's band applied to a simulated signal
    #: rows where another recording starts (several recordings pooled, identify.explain.structure.Fitter):
    #: no segment crosses one, and the input between samples is interpolated within each recording
    cuts: tuple = ()

    def __post_init__(self):
        self._fine: dict[int, np.ndarray] = {}
        self._piece_means: list[float] | None = None  # segment_fine's recording means, once
        self._worst: np.ndarray | None = None  # divergence_error's, once
        self._rows: dict = {}  # segment_rows' by segment mask, once each (a refit asks ~100 times)
        self._spans: dict = {}  # spans', likewise
        self._offset_sets: dict = {}  # _offset_rows's, likewise
        #: each state's largest |value| over the rows: once, not per run (an abs and a max over the whole
        #: record were 6 % of an explanation's CPU)
        self.state_max = np.max(np.abs(self.states), axis=0)
        self.bound = 100.0 * float(np.max(self.state_max[:2])) + 1e-9

    def fine(self, substeps: int) -> np.ndarray | None:
        """The inputs every h/2 (simulate's inputs_fine), row r at index 2 substeps r: each recording's
        interpolated on its own, padded with its last value up to the next one's first row. Kept for the
        last `substeps` only, and only up to FINE_GRID_BYTES: None above (run builds each segment's own)."""
        grid = self._fine.get(substeps)  # runs in threads share it (identify.threads.map_runs): one read
        if grid is None:
            up = 2 * substeps
            if self.inputs.size * up * 8 > FINE_GRID_BYTES:
                return None
            pieces = np.split(self.inputs, list(self.cuts))
            grids = []
            for i, piece in enumerate(pieces):
                u = self._fine_piece(piece, substeps)
                grids.append(u if i == len(pieces) - 1 else np.vstack([u, np.repeat(u[-1:], up - 1, axis=0)]))
            grid = np.ascontiguousarray(grids[0] if len(grids) == 1 else np.vstack(grids))
            self._fine = {substeps: grid}
        return grid

    @staticmethod
    def _fine_piece(piece: np.ndarray, substeps: int, mean=None) -> np.ndarray:
        u = fine_grid_input(piece[:, :1], substeps, mean=mean)
        if piece.shape[1] > 1:  # known smooth extra inputs (the time ramp): linear interpolation
            u = np.column_stack([u, fine_grid_input(piece[:, 1:], substeps, "linear")])
        return u

    def segment_fine(self, a: int, b: int, substeps: int) -> np.ndarray:
        """The fine inputs of rows a..b-1 alone (what fine()[a up:(b-1) up + 1] holds), interpolated from
        the segment and FINE_PAD rows either side within its recording (the band-limited interpolation's
        filter reaches ~10 rows, and the recording's mean is removed as fine() removes it)."""
        edges = [0, *self.cuts, self.inputs.shape[0]]
        piece = int(np.searchsorted(edges, a, side="right")) - 1  # the recording holding the segment
        lo, hi = edges[piece], edges[piece + 1]
        a0, b0 = max(a - FINE_PAD, lo), min(b + FINE_PAD, hi)
        up = 2 * substeps
        if self._piece_means is None:  # each recording's input mean, once (not per segment and run)
            self._piece_means = [float(self.inputs[e0:e1, 0].mean()) for e0, e1 in zip(edges[:-1], edges[1:])]
        u = self._fine_piece(self.inputs[a0:b0], substeps, self._piece_means[piece])
        return np.ascontiguousarray(u[(a - a0) * up:(b - 1 - a0) * up + 1])

    def run(self, model: SparseModel, which: np.ndarray | None = None):
        """Piecewise free run: (simulated gap signal over the valid rows, NaN outside the segments run;
        per-segment squared error (diverged: 4x the segment's signal energy); the integration's step as
        (substeps per sample, samples per step): a caller differencing two runs tells a changed step by it)."""
        n = self.states.shape[0]
        scale = 1.5 * self.state_max
        jump_terms = sign_jump_terms(model)  # once per run, not per segment
        jumps = bool(jump_terms.any())
        substeps, stride = choose_step(model, 1.0 / self.fs_hz, scale)
        if jumps:  # a stuck mass's chatter must stay within a sample's reach (sampled_q1_dot)
            stride = 1
        uf = self.fine(substeps)  # None: too large to hold, built per segment
        out = np.full(n, np.nan)
        seg = np.arange(self.starts.size) if which is None else np.flatnonzero(which)
        dt = 1.0 / self.fs_hz
        offsets = self.offsets(model, seg, jumps) if self.gap == "q1_dot" else np.zeros(len(self.starts))
        states = np.empty((n, self.states.shape[1]))  # the runs' states, segment by segment
        x0s = self.states[self.starts[seg]]
        x0s[:, 1] += offsets[seg]
        mask = np.zeros(self.starts.size, dtype=bool)

        def part(j):  # a share of the segments (on a run thread already, e.g. a Jacobian's column, map_runs
            # runs the shares in turn): with the record's fine grid held, one compiled call, the GIL released
            # throughout; without it, each segment's own grid and run
            if uf is not None:
                return simulate_segments(model, dt, x0s[j], uf, substeps, self.starts[seg[j]], self.stops[seg[j]],
                                         states, bound=self.bound, stride=stride)
            written = np.zeros(j.size, dtype=np.int64)
            for k, i in enumerate(seg[j]):
                a, b = int(self.starts[i]), int(self.stops[i])
                res = simulate(model, dt, x0s[j[k]], inputs_fine=self.segment_fine(a, b, substeps), substeps=substeps,
                               n_samples=b - a, bound=self.bound, stride=stride)
                states[a:b], written[k] = res.states, res.n_valid
            return written

        written = np.concatenate(map_runs(part, np.array_split(np.arange(seg.size), run_threads())))
        mask[seg] = written == self.stops[seg] - self.starts[seg]
        # the read-out span by span of adjoining segments (row by row, the same numbers as segment by
        # segment: ~80 calls a run, whose overhead was ~28 % of a Coulomb case's CPU, docs/discrepancy.md "Time")
        for a, b in self.spans(mask):
            out[a:b] = (sampled_q1_dot(model, states[a:b], self.inputs[a:b], dt, jump_terms) if self.gap == "q1_dot"
                        else states[a:b, 1])
        if self.lowpass is not None:
            ok = np.isfinite(out)
            filled = np.where(ok, out, self.measured)
            out = np.where(ok, self.lowpass(filled), np.nan)
        err = np.array([np.sum((out[a:b] - self.measured[a:b]) ** 2) for a, b in zip(self.starts, self.stops)])
        err *= self.scale ** 2
        err = np.where(np.isfinite(err), err, self.divergence_error())
        if which is not None:
            err = np.where(which, err, np.nan)
        return out, err, (substeps, stride)

    def divergence_error(self) -> np.ndarray:
        """Per segment, the error run() gives a segment whose free run diverged: 4x its signal energy
        (once per ShootingData; a caller tells a diverged segment by it)."""
        if self._worst is None:
            self._worst = np.array([4 * np.sum(self.measured[a:b] ** 2) for a, b in zip(self.starts, self.stops)])
        return self._worst

    def offsets(self, model: SparseModel, seg: np.ndarray, jumps: bool | None = None) -> np.ndarray:
        """Per segment, the displacement offset the model implies but accelerometers cannot see.

        An asymmetric force (q2^2, |q2|, a one-sided stop) shifts the mean displacement under vibration;
        the chain's band removes it from the measured q2, so a segment started from the measured state
        would start off the model's orbit and ring. The offset is where the model's mean acceleration
        over the segment matches the measured one (two chord steps; ~0 for a symmetric model). Segments
        need not be contiguous (those around a jump are left out, jump_segments). Only the segments `seg`
        (None: all) are computed, each from its rows (every OFFSET_ROW_STEP-th for a smooth model; 0 for the
        others)."""
        n_seg = len(self.starts)
        idx = np.arange(n_seg) if seg is None else np.asarray(seg, dtype=int)
        out = np.zeros(n_seg)
        if idx.size == 0:
            return out
        h = 1e-3 * float(self.state_max[1]) + 1e-12
        jumps = jumps_at_rest(model) if jumps is None else jumps
        cols, u, cuts, length, seg_of_row, target = self._offset_rows(idx, 1 if jumps else OFFSET_ROW_STEP)
        d = np.zeros(idx.size)

        def mean_rhs(shift):
            shifted = [cols[0], cols[1] + shift[seg_of_row], *cols[2:]]
            return np.add.reduceat(equation_rows(model, shifted, u, 0), cuts) / length

        # two chord steps on all segments at once (each segment's own offset), the slope taken at 0
        f0 = mean_rhs(d) - target
        slope = (mean_rhs(d + h) - target - f0) / h
        ok = np.isfinite(slope) & (slope < 0)
        safe = np.where(ok, slope, 1.0)
        for chord in range(2):
            if chord:
                f0 = mean_rhs(d) - target
            good = ok & np.isfinite(f0)
            d = np.where(good, d - np.where(good, f0, 0.0) / safe, d)
        out[idx] = np.clip(np.nan_to_num(d), -0.5 * h * 1e3, 0.5 * h * 1e3)
        return out

    def _offset_rows(self, idx: np.ndarray, row_step: int):
        """offsets' rows of the segments idx, every row_step-th, once per (segments, step): the states and
        inputs there as columns, each segment's first row among them (cuts), its row count, each row's
        segment, each segment's measured mean acceleration. A refit asks for the same segments ~100 times,
        and gathering them was a fifth of the offsets' time."""
        key = (idx.tobytes(), row_step)
        found = self._offset_sets.get(key)
        if found is None:
            if len(self._offset_sets) >= OFFSET_ROWS_CACHE:  # each holds the rows' states: a few at most
                self._offset_sets.clear()
            picked = [np.arange(a, b, row_step) for a, b in zip(self.starts[idx], self.stops[idx])]
            length = np.array([p.size for p in picked])
            rows = np.concatenate(picked)
            cuts = np.concatenate([[0], np.cumsum(length)[:-1]])
            cols = [np.ascontiguousarray(c) for c in self.states[rows].T]
            u = np.ascontiguousarray(self.inputs[rows])
            target = np.add.reduceat(self.measured[rows], cuts) / length
            found = self._offset_sets[key] = (cols, u, cuts, length, np.repeat(np.arange(idx.size), length), target)
        return found

    def spans(self, which: np.ndarray) -> list[tuple[int, int]]:
        """The segments in `which` as (first row, end row) spans of adjoining segments (once per mask)."""
        key = np.asarray(which, dtype=bool).tobytes()  # run()'s: the segments that did not diverge
        spans = self._spans.get(key)
        if spans is None:
            if len(self._spans) >= ROW_CACHE:  # diverging trial runs make masks of their own: keep it bounded
                self._spans.clear()
            spans = []
            for a, b in zip(self.starts[which], self.stops[which]):
                if spans and spans[-1][1] == a:
                    spans[-1] = (spans[-1][0], int(b))
                else:
                    spans.append((int(a), int(b)))
            self._spans[key] = spans
        return spans

    def segment_rows(self, which: np.ndarray) -> np.ndarray:
        """The rows of the segments in `which`, segment after segment (spans' rows; made once per mask)."""
        key = np.asarray(which, dtype=bool).tobytes()
        rows = self._rows.get(key)
        if rows is None:
            if len(self._rows) >= ROW_CACHE:
                self._rows.clear()
            rows = self._rows[key] = np.concatenate([np.arange(a, b) for a, b in self.spans(which)])
        return rows

    def run_residuals(self, model: SparseModel, which: np.ndarray) -> tuple[np.ndarray, int, bool]:
        """(unscaled residuals simulated - measured over segment_rows(which), NaN where a segment's free run
        diverged; the step (run's); whether one did or a residual is not finite)."""
        out, err, step = self.run(model, which)
        rows = self.segment_rows(which)
        r = out[rows] - self.measured[rows]
        diverged = bool(np.any(err[which] == self.divergence_error()[which])) or not np.all(np.isfinite(r))
        return r, step, diverged

    def residuals(self, model: SparseModel, which: np.ndarray) -> np.ndarray:
        """Scaled residual vector over the rows of the segments in `which` (for least squares); a diverged
        segment's rows 10x their measured magnitude."""
        r, _, _ = self.run_residuals(model, which)
        r = r * self.scale
        return np.where(np.isfinite(r), r, 10.0 * np.abs(self.measured[self.segment_rows(which)]) + 1e-12)


#: Share of the segments whose largest errors are left out of any total that decides (at least one of
#: MIN_TRIMMED or more): the comparison's breakdown point. A hardening rig's jump is a bifurcation, and
#: the segment that holds it is on one branch or the other depending on a model's last digits (seen:
#: plain rigs whose jump fell in a held-out segment, that segment 55-97 % of the held-out error, the gap
#: 2.6-3.6x the noise floor; a true quadratic stiffness rejected for raising that one segment's error).
#: No single segment (nor a tenth of them) can decide whether anything is missing, or which effect.
TRIM_SHARE = 0.1
MIN_TRIMMED = 5


def n_trimmed(n: int) -> int:
    """How many of n segments' largest errors a trimmed total leaves out."""
    return max(1, int(TRIM_SHARE * n)) if n >= MIN_TRIMMED else 0


def trimmed_total(err: np.ndarray) -> np.ndarray:
    """Sum over the last axis without its n_trimmed largest entries, scaled back to all n entries (so
    noise alone gives the untrimmed total's expectation, up to its spread)."""
    err = np.asarray(err, float)
    n = err.shape[-1]
    k = n_trimmed(n)
    if k == 0:
        return err.sum(-1)
    return np.sort(err, axis=-1)[..., :n - k].sum(-1) * n / (n - k)


def bootstrap_prob(ref: np.ndarray, new: np.ndarray, n_boot: int = 4000, trim: bool = True) -> float:
    """Probability that `new` has the smaller trimmed total error than `ref` over segments resampled with
    replacement (ties count half). A paired t-test is the wrong tool: a missing effect shows in the
    segments that hold the resonance, not evenly."""
    ref, new = np.asarray(ref, float), np.asarray(new, float)
    if ref.size == 0:
        return 0.5
    rng = np.random.default_rng(0)  # reproducible
    idx = rng.integers(0, ref.size, (n_boot, ref.size))
    total = trimmed_total if trim else (lambda e: e.sum(-1))  # noqa: E731
    d = total(ref[idx]) - total(new[idx])
    return float(np.mean(d > 0) + 0.5 * np.mean(d == 0))
