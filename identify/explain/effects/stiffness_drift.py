"""Stiffness drift: k(t) = k (1 + r t/T) over the record, e.g. a warming spring; the term q2*tau with
tau = t/T - 1/2 a known input (identify.explain.structure.Fitter adds it where a term names it). The rig
simulator runs it from RigParameters stiffness_drift.

On a single sweep, time and excitation frequency move together, so a drift cannot be told from a
stiffness that depends on the excitation frequency: the named effect's value is then withheld and what
would separate it is said instead (annotate).
"""
from __future__ import annotations

import numpy as np
from scipy.stats import spearmanr

from .base import Effect

#: A record is one sweep when the excitation frequency over SWEEP_WINDOWS windows has a rank correlation
#: with time of at least ONE_SWEEP_RHO in size (then a stiffness drift is not separable).
SWEEP_WINDOWS = 20
ONE_SWEEP_RHO = 0.9
#: A window whose input peak is below this share of the loudest window's has no excitation frequency to
#: rank (the rig at rest before or after the sweep, or driven below the band): its peak is noise, at any
#: frequency. Service recordings of a 1-20 Hz, 1 mm campaign (2048 Hz, 0.02 m/s^2 sensor noise): windows at
#: rest at 3.1e-4 and 3.4e-4 of the loudest, the sweep's 1.9 Hz window at 1.3e-2; ranked, the rest window's
#: 82 Hz made a down-sweep's rho -0.71 (-0.46 in one CI run) instead of -1.
MIN_PEAK_SHARE = 1e-3


def sweep_direction(sig) -> float:
    """Rank correlation of the excitation frequency with time over SWEEP_WINDOWS windows of the valid
    rows, those driven (MIN_PEAK_SHARE) only (+1: one up-sweep, -1: one down-sweep, near 0: up and down, or
    a fixed frequency)."""
    from ..localise import excitation_peak

    u = sig.input[sig.valid]
    edges = np.linspace(0, u.size, SWEEP_WINDOWS + 1).astype(int)
    f, peak = np.array([excitation_peak(u, a, b, sig.fs_hz, sig.band_hz[0])
                        for a, b in zip(edges[:-1], edges[1:])]).T
    driven = peak >= MIN_PEAK_SHARE * peak.max() if peak.max() > 0 else np.zeros(f.size, dtype=bool)
    t, f = np.flatnonzero(driven), f[driven]  # windows at rest (MIN_PEAK_SHARE) have no frequency to rank
    return float(spearmanr(t, f)[0]) if f.size >= 3 and np.ptp(f) > 0 else 0.0


class StiffnessDrift(Effect):
    name, terms, unit = "stiffness_drift", ("q2*tau",), "N/m"
    description = "stiffness drifting over the record, k (1 + r t/T), e.g. a warming spring (tau = t/T - 1/2)"
    plain = False

    def annotate(self, entry: dict, analysis) -> None:
        """A stiffness drift over sweeps that all run one way is confounded with a stiffness that depends on
        the excitation frequency (time and frequency move together: the issue saw 27-94 % of k against
        truths within +-7 % on one up-sweep): its value is withheld and what would separate it is said
        instead. An up and a down sweep explained together (identify.explain.several) separate them."""
        rhos = analysis.sweep_rhos_
        if not all(abs(r) >= ONE_SWEEP_RHO for r in rhos) or len({r > 0 for r in rhos}) > 1:
            return
        rho = rhos[0]
        way = "up" if rho > 0 else "down"
        what = (f"this record: one {way}-sweep" if len(rhos) == 1
                else f"these records: {len(rhos)} recordings, each one {way}-sweep")
        value = entry["coefficients"].get("q2*tau")
        entry["separable"] = False
        entry["note"] = (f"not separable on {what}, so time and "
                         f"excitation frequency move together (rank correlation {rho:+.2f}) and a drift of the "
                         f"stiffness cannot be told from a frequency-dependent one (the confounded q2*tau "
                         f"would be {value:.4g}); an up and a down sweep, or the same sweep repeated, "
                         f"separate them")
        entry["coefficients"] = {}
