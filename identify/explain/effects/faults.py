"""Measurement faults of the accelerometer rig: the recording is wrong, not the rig. Each is fitted with
the model by correcting the channels (identify.explain.measurement.ChannelChain) and comparing the corrected
model's prediction of what was recorded; the fault parameter minimises the training segments' shooting
error of the recorded signal, the model's coefficients refit by equation error on the corrected states
at every trial value (bounded scalar search), so the fault and the model are fitted together. The
simulator makes them with sim.sensors.Accelerometer (gain, delay_s, bias_drift_ms2).

A fault's name needs the evidence a physical name needs (issue 32): a test of its own, its p held to the
analysis' alpha as a Wald p is. The fitted value is an M-estimate (the minimum of a sum over training
segments), so its standard error is the segment-clustered sandwich (identify.explain.clustered, which the
masking check's test shares), H^-1 sqrt(sum_s g_s^2), g_s the slope of segment s's error and H the
curvature of the sum at the fitted value (central differences at FAULT_STEP of the search range: three
shooting runs). A few segments (the resonance's) carry most of the curvature, so there are few effective
clusters: each slope is scaled by 1 / (1 - H_s / H), its segment's leverage (the CR3 / jackknife
correction, capped at clustered.MAX_LEVERAGE), and t = value / SE is read against Student's t with
segments - 1 degrees of freedom (the small-cluster recipe of Cameron and Miller, 2015). Kish's effective
number of segments as the degrees of freedom was tried and was too strict: a true 2.5 % gain beside
Coulomb friction, t = 65, came out at p = 0.01 (S_eff ~ 2) and a stiffness drift was named instead.
Segments that disagree on the fault (a misfit elsewhere bending it) widen it; a value the search settles on without the data asking for it (a 10 us delay, 0.02 samples,
once named at confidence 0.68 after a gain fault: benchmarks/explain_robustness.py --seed 646344572
--case 4) is not significant.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import minimize_scalar

from ..clustered import cr3_covariance, wald_p
from ..measurement import PARAMS
from .base import Candidate, Effect

#: Central-difference step of a fault's test, as a share of its search range (PARAMS): a gain step of
#: 4e-4, a delay step of 20 us. Small against the faults the suite draws (gains of 2-5 %, delays of
#: 0.3-2 ms), large against the shooting's rounding.
FAULT_STEP = 2e-3


class ChannelFault(Effect):
    """A fault with one or more scalar parameters (identify.explain.measurement.PARAMS keys), one searched at a
    time; the one that fits best is kept."""

    kind, plain = "measurement", False
    params: tuple[str, ...] = ()

    def propose(self, fitter, cur):
        if self.name in cur.effects or fitter.chain is None:
            return None
        return self._fault(fitter, cur)

    def without(self, st):
        """`st` with this fault's parameters back at no fault and its name taken out."""
        meas = dict(st.meas, **{k: 0.0 for k in self.params})
        return replace(st, meas=tuple(sorted(meas.items())), effects=tuple(n for n in st.effects if n != self.name))

    def with_fault(self, fitter, cur, key: str, value: float, band_limited: bool = True):
        """The structure with fault parameter `key` = value, coefficients by equation error, and its fit."""
        p = dict(cur.meas)
        p[key] = float(value)
        st = cur.adding(self.name, (), meas=tuple(sorted(p.items())))
        fit = fitter.equation_fit(st, band_limited=band_limited)
        return replace(st, coef=tuple(fit.coef.items())), fit

    def _fault(self, fitter, cur) -> Candidate:
        """The fault's parameter by bounded scalar search on the training segments' shooting error."""
        train = ~fitter.seg_held
        best = None
        for key in self.params:
            lo, hi = PARAMS[key]

            def cost(x: float) -> float:
                st, _ = self.with_fault(fitter, cur, key, x, band_limited=False)
                return float(np.nansum(fitter.data(st).run(fitter.model(st), train)[1]))

            res = minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                  options={"xatol": 1e-4 * (hi - lo), "maxiter": 10})
            if best is None or res.fun < best[1]:
                best = (key, float(res.fun), float(res.x))
        key, _, x = best
        z, p = self.test(fitter, cur, key, x)
        st, fit = self.with_fault(fitter, cur, key, x)
        return Candidate(self.name, "measurement", [], st, fit, z * z, p, {key: x, **self.derived(key, x)},
                         list(self.same_as))

    def test(self, fitter, cur, key: str, value: float) -> tuple[float, float]:
        """(t, two-sided p) of fault parameter `key` = `value` against no fault: the segment-clustered
        sandwich standard error of the training segments' shooting error, each segment's slope scaled by
        its leverage (CR3), against Student's t with segments - 1 degrees of freedom (module docstring).
        p = 1 where nothing is determined: the error not curved upwards there, a segment's free run
        diverging or the integration's step (substeps, samples per step) changing between the three runs (a
        jump, not a slope)."""
        train = ~fitter.seg_held
        lo, hi = PARAMS[key]
        h = FAULT_STEP * (hi - lo)
        e, steps = [], set()
        for x in (value - h, value, value + h):
            st, _ = self.with_fault(fitter, cur, key, x, band_limited=False)
            data = fitter.data(st)
            _, err, step = data.run(fitter.model(st), train)
            if np.any(err[train] == data.divergence_error()[train]):
                return 0.0, 1.0
            e.append(err[train])
            steps.add(step)
        per_segment = (e[2] - 2 * e[1] + e[0]) / h ** 2
        curvature = float(np.sum(per_segment))
        if len(steps) > 1 or not curvature > 0 or e[0].size < 2:
            return 0.0, 1.0
        cov = cr3_covariance(np.array([[curvature]]), per_segment[:, None, None], ((e[2] - e[0]) / (2 * h))[:, None])
        se = float(np.sqrt(cov[0, 0]))
        if not se > 0:
            return 0.0, 1.0
        return value / se, wald_p(np.array([value]), cov, e[0].size)

    same_as: tuple[str, ...] = ()

    def derived(self, key: str, value: float) -> dict:
        """Further report fields of a fitted value."""
        return {}


class MassAccGain(ChannelFault):
    """The two channels' gains are one effect to a base-excited recording: scaling both channels by one
    factor scales every state and the input alike, which the model absorbs (its cubic coefficient changes
    by the factor squared), so only their ratio shows. A table gain g_t reads as a mass gain
    (1 + g_m) = 1 / (1 + g_t); the gain is fitted on the mass channel and reported with table_acc_gain as
    its surrogate (and the equivalent table-channel value)."""

    name, unit = "mass_acc_gain", "1"
    description = "gain error of the mass accelerometer: it reads (1 + g) x''"
    params, same_as = ("mass_acc_gain",), ("table_acc_gain",)

    def derived(self, key: str, value: float) -> dict:
        return {"table_acc_gain_equivalent": 1.0 / (1.0 + value) - 1.0}


class TableAccGain(ChannelFault):
    """Not searched on its own: to a base-excited record it is the mass gain (MassAccGain), whose
    surrogate it is reported as."""

    name, unit = "table_acc_gain", "1"
    description = "gain error of the table accelerometer: it reads (1 + g) z''"
    params = ("table_acc_gain",)

    def propose(self, fitter, cur):
        return None


class ChannelDelay(ChannelFault):
    name, unit = "channel_delay", "s"
    description = "the mass channel lags the table channel by tau (s)"
    params = ("channel_delay",)
