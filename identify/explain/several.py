"""Several recordings of one rig explained together (identify.explain.workflow.DiscrepancyAnalysis.fit with a
list): what is refused at the door, how the per-recording noise floors pool into the one the gap is
compared with, and each recording's own account in the result.

Why several: on one sweep some effects are confounded. A stiffness drift over time (q2*tau) and a
stiffness that depends on the excitation frequency both change the stiffness along an up-sweep the same
way; over an up and a down sweep the drift keeps its sign in time while the frequency-dependent one
flips. Sweeps at several amplitudes separate amplitude-dependent effects (a cubic spring from an end
stop, quadratic from cubic damping) that one amplitude sees at one level only.
"""
from __future__ import annotations

import numpy as np

from ..data.recording import Recording
from ..errors import IdentificationError
from ..joint import _refuse_copies
from ..simulation.shooting import trimmed_total
from .jumps import jump_time
from .localise import excitation_hz


def as_recordings(recordings) -> list[Recording]:
    """A Recording or a list of them, checked at the door: at least one, none given twice (its evidence
    would count twice), and one rig set-up (layout, input channel and sampling rate) in all of them."""
    recs = [recordings] if isinstance(recordings, Recording) else list(recordings)
    if not recs:
        raise IdentificationError("no recordings to explain")
    if len(recs) > 1:
        _refuse_copies(recs)
        setups = {(r.layout, r.input_name, float(r.fs_hz)) for r in recs}
        if len(setups) > 1:
            raise IdentificationError(
                "one explanation over several recordings needs recordings of one rig set-up (the same layout, "
                "input channel and sampling rate); got " + ", ".join(
                    f"{r.source} ({r.layout} layout, input {r.input_name}, {r.fs_hz:g} Hz)" for r in recs)
                + ": explain them one by one")
    return recs


def pooled_floor(floors: list[float], measured: np.ndarray, rows_held: np.ndarray, fitter) -> float:
    """The noise floor of the pooled gap: each recording's floor (an NRMSE) weighted by its share of the
    pooled held-out signal energy, so floor^2 is the pooled noise energy over the pooled signal energy (the
    gap's own normalisation). One recording: its floor."""
    energy = []
    for p in fitter.parts:
        m = measured[p.offset:p.offset + p.n][rows_held[p.offset:p.offset + p.n]]
        energy.append(float(np.var(m) * m.size) if m.size else 0.0)
    total = sum(energy)
    if not total > 0:
        return float(max(floors))
    return float(np.sqrt(sum(e / total * f * f for e, f in zip(energy, floors))))


def jump_of(fitter, part, measured, before, after, f_res_hz: float) -> dict:
    """The jump of one recording (identify.explain.jumps): measured, and as the baseline's and the
    explanation's free runs predict it; None where there is none. Times from the recording's start."""
    sig = part.sig
    rows = slice(part.offset, part.offset + part.n)
    u = sig.input[sig.valid]

    def at(signal):
        j = jump_time(signal[rows], u, sig.fs_hz, f_res_hz)
        if j is None:
            return None
        r = j["row"]
        return {"t_s": (sig.valid.start + r) / sig.fs_hz, "direction": j["direction"], "ratio": j["ratio"],
                "excitation_hz": excitation_hz(u, max(r - 1, 0), r + 1, sig.fs_hz, sig.band_hz[0])}

    return {"measured": at(measured), "predicted_before": at(before), "predicted_after": at(after)}


def recording_entries(analysis) -> list[dict]:
    """Per recording used: its source, length, band, sweep direction (rank correlation of the excitation
    frequency with time: +1 one up-sweep, -1 one down-sweep), its own held-out gap before and after
    (as the pooled one: trimmed, over its own held-out segments and signal) with its own noise floor,
    and its jump."""
    fitter = analysis.fitter_
    meas = analysis.gap_measured_
    out = []
    for i, p in enumerate(fitter.parts):
        held = fitter.seg_held & (fitter.starts >= p.offset) & (fitter.starts < p.offset + p.n)
        m = meas[p.offset:p.offset + p.n]
        norm = float(np.sum((m - m[fitter.rows_held[p.offset:p.offset + p.n]].mean()) ** 2 *
                            fitter.rows_held[p.offset:p.offset + p.n]))

        def gap(err):
            return float(np.sqrt(trimmed_total(err[held]) / norm)) if norm > 0 else 0.0

        out.append({"source": p.rec.source, "n_samples": int(p.rec.n_samples),
                    "duration_s": float(p.rec.n_samples / p.rec.fs_hz), "band_hz": [float(b) for b in p.sig.band_hz],
                    "sweep_rho": analysis.sweep_rhos_[i], "noise_floor": analysis.noise_floors_[i],
                    "gap_before": gap(analysis.baseline_segment_errors_), "gap_after": gap(analysis.final_segment_errors_),
                    "jump": analysis.jumps_[i]})
    return out
