"""The predicted frequency response of a model at one table amplitude: branches, stability, folds, jumps.

    resp = frequency_response(model, amplitude_mm=1.2)        # default band: (BAND_LOW, BAND_HIGH) x f0
    resp.jump_down_hz, resp.jump_up_hz                         # up-sweep's and down-sweep's jump, or None

The number of harmonics is chosen by convergence: the branch is continued with H harmonics, the
response at its largest amplitude and at its folds is solved again with H + HARMONICS_STEP, and H grows
until the amplitude there changes by less than HARMONICS_TOL of itself (or HARMONICS_MAX is reached,
then said in `accuracy`). The band is continued upwards from its low end; when that branch ends before
the band's top (the model's range of validity, identify.frf.validity), a second branch is continued
downwards from the top, so the down-sweep's fold is found too.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelError
from .balance import Basis, check_model, coefficient_amplitude, derivative_columns, is_smooth
from .continuation import Branch, Continuation, fold_between
from .floquet import is_stable, multipliers, substeps_for
from .validity import damping_limits

#: Default band, in multiples of the linear natural frequency f0 (Table 1 rig: 1.2-19.8 Hz).
BAND_LOW, BAND_HIGH = 0.25, 4.0
HARMONICS_START, HARMONICS_STEP, HARMONICS_MAX = 5, 2, 25
#: Convergence of the harmonics: relative change of the amplitude at the checked points.
HARMONICS_TOL = 1e-4
#: A branch whose amplitude exceeds this many times the table amplitude (and 1 m) has run away.
RUNAWAY_M = 1.0


@dataclass
class Fold:
    frequency_hz: float
    amplitude_mm: float
    branch: int        # index of the branch it is on (0: continued upwards, 1: downwards)
    kind: str          # "upper" (w turns back: the up-sweep jumps) | "lower" (the down-sweep jumps)


@dataclass
class FrequencyResponse:
    amplitude_mm: float
    band_hz: tuple[float, float]
    harmonics: int
    branches: list[dict] = field(default_factory=list)
    folds: list[Fold] = field(default_factory=list)
    jump_down_hz: float | None = None
    jump_up_hz: float | None = None
    validity: dict | None = None
    notes: list[str] = field(default_factory=list)
    accuracy: dict = field(default_factory=dict)
    _solver: object = field(default=None, repr=False)     # the Continuation the branches came from
    _points: list = field(default_factory=list, repr=False)  # BranchPoints per branch

    def amplitude_at(self, frequency_hz: float, near_mm: float) -> float | None:
        """The amplitude (mm) of the periodic response at `frequency_hz` on the branch nearest to
        (frequency_hz, near_mm), solved there by Newton from the nearest continued point; None when
        Newton does not converge (e.g. past a fold)."""
        pts = [p for branch in self._points for p in branch]
        w = 2 * np.pi * frequency_hz
        near = min(pts, key=lambda p: ((p.w - w) / w) ** 2 + ((p.amplitude_m * 1e3 - near_mm) / near_mm) ** 2)
        sol = self._solver.solve_fixed(near.X, w)
        return None if sol is None else coefficient_amplitude(sol[0]) * 1e3

    def to_dict(self) -> dict:
        return {"amplitude_mm": self.amplitude_mm, "band_hz": list(self.band_hz), "harmonics": self.harmonics,
                "jump_down_hz": self.jump_down_hz, "jump_up_hz": self.jump_up_hz,
                "folds": [vars(f) for f in self.folds], "branches": self.branches, "validity": self.validity,
                "accuracy": self.accuracy, "notes": list(self.notes)}


def natural_frequency_hz(model) -> float:
    """Linear natural frequency sqrt(-df/dq2 at rest) / 2 pi; ModelError when the model has none."""
    z = np.zeros(1)
    _, _, fq2, _ = derivative_columns(model, z, z, z, need_u=False)
    if not fq2[0] < 0:
        raise ModelError(f"the model has no linear stiffness at rest (df/dq2 = {fq2[0]:.4g} 1/s^2 >= 0): give the "
                         "band (--band F_LO F_HI) to look for a resonance")
    return float(np.sqrt(-fq2[0]) / (2 * np.pi))


def frequency_response(model, amplitude_mm: float, band_hz=None, harmonics: int | None = None) -> FrequencyResponse:
    """The periodic responses of `model` at table amplitude `amplitude_mm` (z = A sin wt) over `band_hz`
    (default: BAND_LOW..BAND_HIGH x the linear natural frequency); `harmonics` fixes H (default: by
    convergence)."""
    check_model(model)
    if not amplitude_mm > 0:
        raise ModelError(f"table amplitude must be positive, got {amplitude_mm} mm")
    if band_hz is None:
        f0 = natural_frequency_hz(model)
        band_hz = (BAND_LOW * f0, BAND_HIGH * f0)
    f_lo, f_hi = map(float, band_hz)
    if not 0 < f_lo < f_hi:
        raise ModelError(f"band must be 0 < F_LO < F_HI Hz, got {f_lo} {f_hi}")
    table_m = amplitude_mm * 1e-3
    limits = damping_limits(model)
    w_lo, w_hi = 2 * np.pi * f_lo, 2 * np.pi * f_hi
    try:
        w_scale = 2 * np.pi * natural_frequency_hz(model)
    except ModelError:
        w_scale = np.sqrt(w_lo * w_hi)
    H = harmonics or HARMONICS_START
    while True:
        branches, cont = _branches(model, H, table_m, w_lo, w_hi, w_scale, limits)
        if harmonics:
            change = None
            break
        change = _harmonics_change(cont, branches, H)
        if change < HARMONICS_TOL or H + HARMONICS_STEP > HARMONICS_MAX:
            break
        H += HARMONICS_STEP
    return _assemble(model, amplitude_mm, (f_lo, f_hi), H, branches, cont, limits, change)


def _branches(model, H, table_m, w_lo, w_hi, w_scale, limits):
    basis = Basis.for_model(model, H)
    cont = Continuation(model, basis, table_m, x_scale=10 * table_m, w_scale=w_scale)
    stop = _limit(limits)
    out = []
    for w_start, w_stop, direction in ((w_lo, w_hi, 1), (w_hi, w_lo, -1)):
        start = cont.solve_fixed(np.zeros(2 * H + 1), w_start)
        if start is None:
            raise ModelError(f"no periodic response found at {w_start / 2 / np.pi:.3g} Hz to start from: the model "
                             "may be unstable at rest, or its friction hold the mass to the table there (sticking "
                             "has no smooth periodic response to balance); give a band that starts higher")
        out.append(cont.run(start[0], w_start, w_stop, stop, direction))
        if out[0].stop == "band":  # the whole band in one branch: no second one needed
            break
    return out, cont


def _limit(limits):
    def stop(point):
        q2 = point.samples[1]
        if limits is not None and (q2.min() < limits[0] or q2.max() > limits[1]):
            side = limits[1] if q2.max() > limits[1] else limits[0]
            return "validity", (f"the response reaches {abs(side) * 1e3:.3g} mm, beyond which the model's damping "
                                f"is negative: outside its range of validity")
        if point.amplitude_m > RUNAWAY_M:
            return "runaway", f"the response exceeds {RUNAWAY_M:g} m"
        return None
    return stop


def _harmonics_change(cont: Continuation, branches: list[Branch], H: int) -> float:
    """Largest relative change of a point's amplitude or frequency, H -> H + HARMONICS_STEP, at each
    branch's largest response and its folds: each point solved again with more harmonics by the
    pseudo-arclength corrector along its own tangent (regular at a fold, where a fixed-frequency Newton
    is not)."""
    H2 = H + HARMONICS_STEP
    big = Continuation(cont.model, Basis.for_model(cont.model, H2), cont.table_m, cont.xs, cont.ws)
    worst = 0.0
    for br in branches:
        pts = br.points
        idx = {max(range(len(pts)), key=lambda i: pts[i].amplitude_m)}
        idx |= {i for i in range(len(pts) - 1) if pts[i].tangent[-1] * pts[i + 1].tangent[-1] < 0}
        for i in idx:
            p = pts[i]
            y = np.append(big.basis.resize(p.X, H2) / cont.xs, p.w / cont.ws)
            t = np.append(big.basis.resize(p.tangent[:-1], H2), p.tangent[-1])
            out = big.correct(y, t / np.linalg.norm(t))
            if out is None:
                return np.inf
            X2, w2 = out[0][:-1] * cont.xs, out[0][-1] * cont.ws
            worst = max(worst, abs(coefficient_amplitude(X2) - p.amplitude_m) / p.amplitude_m, abs(w2 - p.w) / p.w)
    return worst


def _assemble(model, amplitude_mm, band_hz, H, branches, cont, limits, change) -> FrequencyResponse:
    resp = FrequencyResponse(float(amplitude_mm), band_hz, H, _solver=cont, _points=[b.points for b in branches])
    resp.accuracy = {"harmonics": H, "harmonics_change": None if change is None else float(change),
                     "harmonics_tolerance": HARMONICS_TOL, "aft_samples": cont.basis.n_samples,
                     "smooth": is_smooth(model)}
    if limits is not None:
        resp.validity = {"damping_negative_below_mm": None if np.isinf(limits[0]) else limits[0] * 1e3,
                         "damping_negative_above_mm": None if np.isinf(limits[1]) else limits[1] * 1e3}
    for b, br in enumerate(branches):
        resp.branches.append(_branch_dict(model, cont, br, b))
        for i in range(len(br.points) - 1):
            p, q = br.points[i], br.points[i + 1]
            if p.tangent[-1] * q.tangent[-1] < 0 and not (br.stop != "band" and i + 1 == len(br.points) - 1):
                w, amp = fold_between(p, q, cont.xs, cont.ws)
                kind = "upper" if p.tangent[-1] > 0 else "lower"
                f = w / (2 * np.pi)
                if not any(abs(f - o.frequency_hz) < 1e-6 * f and o.kind == kind for o in resp.folds):
                    resp.folds.append(Fold(float(f), float(amp * 1e3), b, kind))
    first = [f for f in resp.folds if f.branch == 0]
    upper = [f for f in first if f.kind == "upper"]
    resp.jump_down_hz = upper[0].frequency_hz if upper else None
    if len(branches) > 1:
        lower = [f for f in resp.folds if f.branch == 1 and f.kind == "lower"]
        resp.jump_up_hz = lower[0].frequency_hz if lower else None
    else:
        lower = [f for f in first if f.kind == "lower"]
        resp.jump_up_hz = lower[-1].frequency_hz if lower else None
    if branches[0].stop != "band" and not upper:
        end = resp.branches[0]["end"]
        resp.notes.append(f"up-sweep: the upper branch leaves the model's range of validity at "
                          f"{end['frequency_hz']:.4g} Hz ({end['detail']}) before it folds: no jump-down is predicted "
                          "(in the model the response runs away; the rig would hit its end stops)")
    if not resp.accuracy["smooth"]:
        resp.notes.append(f"the model has non-smooth terms: their harmonics decay slowly and alias on the "
                          f"{cont.basis.n_samples} AFT samples; against time integration (docs/frf.md) amplitudes were "
                          "within 0.4 % with sign(q1) (its jump's harmonics' last change, "
                          f"{change if change is not None else float('nan'):.1e}, understates that), within 4e-5 "
                          "with |q1|, q1*|q1|, |q2|")
    if change is not None and change >= HARMONICS_TOL:
        resp.notes.append(f"harmonics not converged to {HARMONICS_TOL:g} at H = {H} (last change {change:.1e})")
    return resp


def _branch_dict(model, cont, br: Branch, index: int) -> dict:
    """A branch as lists (frequency_hz, amplitude_mm, stable, max Floquet multiplier) and how it ended."""
    f, a, stable, mu = [], [], [], []
    big = np.max([[np.max(np.abs(p.samples[0])), np.max(np.abs(p.samples[1]))] for p in br.points], axis=0)
    substeps = substeps_for(model, max(p.w for p in br.points), np.maximum(big, 1e-12))
    for p in br.points:
        q1, q2 = p.samples[0], p.samples[1]
        scale = np.array([max(np.ptp(q1), 1e-12), max(np.ptp(q2), 1e-12)])
        m = multipliers(model, p.w, cont.table_m, np.array([q1[0], q2[0]]), scale, substeps)
        f.append(p.w / (2 * np.pi))
        a.append(p.amplitude_m * 1e3)
        stable.append(is_stable(m))
        mu.append(float(np.max(np.abs(m))))
    last = br.points[-1]
    end = {"reason": br.stop, "detail": br.stop_detail, "frequency_hz": last.w / (2 * np.pi),
           "amplitude_mm": last.amplitude_m * 1e3}
    return {"direction": "up" if index == 0 else "down", "frequency_hz": f, "amplitude_mm": a, "stable": stable,
            "floquet_max": mu, "end": end}
