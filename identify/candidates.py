"""One candidate per catalog effect on top of the current explanation: its structure, coefficients by
equation error (and a search over the effect's own nonlinear parameter), and its Wald statistic.

- plain physics terms: least squares with the new term(s) (band-limited columns);
- end_stop: two sided, or one sided (the asymmetry terms tied to the symmetric ones, Structure.side), its
  travel d searched over fractions of the measured max |q2| (of that side's peak, one sided); the best
  held-out equation error among the tries that stop the mass on every side;
- hysteresis: (beta, gamma) searched on a grid scaled by the measured stroke; the state z integrated
  from the measured velocity gives the column;
- stiffness_drift: the term q2*tau, tau = t/T - 1/2 a known input;
- measurement faults: the fault parameter minimises the training segments' shooting error of the
  recorded signal, the model's coefficients refit by equation error on the corrected states at every
  trial value (bounded scalar search), so the fault and the model are fitted together.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar

from . import admissibility
from .effects import CATALOG, Effect
from .gram import scaled_pinv
from .measurement import PARAMS
from .structure import Fit, Fitter, Structure

END_STOP_FRACTIONS = (0.5, 0.6, 0.7, 0.8, 0.88, 0.94)
#: Bouc-Wen: 1/(beta + gamma) (the state's saturation level) as fractions of the measured max |q2|,
#: and gamma's share of beta + gamma.
HYST_SATURATION = (0.1, 0.3, 1.0)
HYST_GAMMA_SHARE = (0.0, 0.5)
#: Which fault parameter(s) each measurement effect fits.
FAULT_PARAMS = {"mass_acc_gain": ("mass_acc_gain",), "table_acc_gain": ("table_acc_gain",),
                "channel_delay": ("channel_delay",), "bias_drift": ("bias_drift_mass", "bias_drift_table")}


def wald_p(fit: Fit, terms) -> tuple[float, float]:
    """(Wald statistic, p-value) of the joint hypothesis that `terms`' coefficients are zero."""
    pos = [fit.names.index(t) for t in terms if t in fit.names]
    if not pos:
        return 0.0, 1.0
    theta = np.array([fit.coef[fit.names[i]] for i in pos])
    w = float(theta @ scaled_pinv(fit.cov[np.ix_(pos, pos)]) @ theta)
    return w, float(stats.chi2.sf(w, len(pos)))


def propose(fitter: Fitter, cur: Structure, name: str, effect: Effect) -> dict | None:
    """The candidate structure for `effect` on top of `cur` with equation-error coefficients, or None
    when it does not apply (already added, or a measurement fault of a force-input recording)."""
    if name in cur.effects:
        return None
    if name == "table_acc_gain":  # the same effect as a mass gain to a base-excited record: see _fault
        return None
    if effect.kind == "measurement":
        return _fault(fitter, cur, name) if fitter.chain is not None else None
    sig = fitter.signals(cur)
    qmax = float(np.max(np.abs(sig.q2[sig.valid])))
    if name == "end_stop":
        if cur.travel:
            return None
        # two sided at fractions of max |q2|; one sided at fractions of that side's own peak (a stop on one
        # side only holds that side's excursion well below the other's)
        q2 = sig.q2[sig.valid]
        peaks = {None: qmax, 1: float(max(np.max(q2), 0.0)), -1: float(max(-np.min(q2), 0.0))}
        tries = [cur.adding(name, effect.terms, travel=f * peak, side=side)
                 for side, peak in peaks.items() if peak > 0 for f in END_STOP_FRACTIONS]
    elif name == "hysteresis":
        if cur.hyst is not None:
            return None
        tries = []
        for sat in HYST_SATURATION:
            for share in HYST_GAMMA_SHARE:
                s = 1.0 / (sat * qmax)
                tries.append(cur.adding(name, effect.terms, hyst=((1 - share) * s, share * s)))
    else:
        if all(t in cur.terms for t in effect.terms):
            return None
        tries = [cur.adding(name, effect.terms)]
    best = None
    for st in tries:
        fit = fitter.equation_fit(st)
        # a stop that pushes outwards somewhere is no stop: the best that holds on every side, if any
        sane = name != "end_stop" or not admissibility.check(name, fit.coef, {}, {})
        if best is None or (sane, -fit.mse_heldout) > (best[2], -best[1].mse_heldout):
            best = (st, fit, sane)
    st, fit, _ = best
    new = [t for t in st.terms if t not in cur.terms]
    w, p = wald_p(fit, new)
    extra = {}
    if st.travel and not cur.travel:
        extra["travel_m"] = st.travel
        extra["sides"] = {None: "both", 1: "upper", -1: "lower"}[st.side]
    if st.hyst is not None and cur.hyst is None:
        extra.update(beta_per_m=st.hyst[0], gamma_per_m=st.hyst[1])
    return {"name": name, "kind": "physics", "terms": new, "structure": replace(st, coef=tuple(fit.coef.items())),
            "fit": fit, "wald": w, "p_value": p, "extra": extra}


def _fault(fitter: Fitter, cur: Structure, name: str) -> dict:
    """A measurement fault's parameter by bounded scalar search on the training segments' shooting error.

    The two channels' gains are one effect to a base-excited recording: scaling both channels by one
    factor scales every state and the input alike, which the model absorbs (its cubic coefficient
    changes by the factor squared), so only their ratio shows. A table gain g_t reads as a mass gain
    (1 + g_m) = 1 / (1 + g_t); the gain is fitted on the mass channel and reported with
    table_acc_gain as its surrogate (and the equivalent table-channel value)."""
    train = ~fitter.seg_held
    best = None
    for key in FAULT_PARAMS[name]:
        lo, hi = PARAMS[key]

        def with_value(x: float) -> Structure:
            p = dict(cur.meas)
            p[key] = float(x)
            st = replace(cur, meas=tuple(sorted(p.items())), effects=cur.effects + (name,))
            fit = fitter.equation_fit(st, band_limited=False)
            return replace(st, coef=tuple(fit.coef.items()))

        def cost(x: float) -> float:
            st = with_value(x)
            return float(np.nansum(fitter.data(st).run(fitter.model(st), train)[1]))

        res = minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-4 * (hi - lo), "maxiter": 10})
        if best is None or res.fun < best[1]:
            best = (key, float(res.fun), float(res.x))
    key, _, x = best
    p = dict(cur.meas)
    p[key] = x
    st = replace(cur, meas=tuple(sorted(p.items())), effects=cur.effects + (name,))
    fit = fitter.equation_fit(st)
    extra, same = {key: x}, []
    if key == "mass_acc_gain":
        extra["table_acc_gain_equivalent"] = 1.0 / (1.0 + x) - 1.0
        same = ["table_acc_gain"]
    return {"name": name, "kind": "measurement", "terms": [], "structure": replace(st, coef=tuple(fit.coef.items())),
            "fit": fit, "wald": None, "p_value": 0.0, "extra": extra, "same_as": same}


def all_candidates(fitter: Fitter, cur: Structure, catalog: dict) -> list[dict]:
    out = []
    for name, effect in catalog.items():
        c = propose(fitter, cur, name, effect if effect is not None else CATALOG[name])
        if c is not None:
            out.append(c)
    return out
