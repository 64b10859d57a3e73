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


def sweep_direction(sig) -> float:
    """Rank correlation of the excitation frequency with time over SWEEP_WINDOWS windows of the valid
    rows (+1: one up-sweep, -1: one down-sweep, near 0: up and down, or a fixed frequency)."""
    from ..localise import excitation_hz

    u = sig.input[sig.valid]
    edges = np.linspace(0, u.size, SWEEP_WINDOWS + 1).astype(int)
    f = np.array([excitation_hz(u, a, b, sig.fs_hz, sig.band_hz[0]) for a, b in zip(edges[:-1], edges[1:])])
    return float(spearmanr(np.arange(f.size), f)[0]) if np.ptp(f) > 0 else 0.0


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
