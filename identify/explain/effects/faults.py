"""Measurement faults of the accelerometer rig: the recording is wrong, not the rig. Each is fitted with
the model by correcting the channels (identify.explain.measurement.ChannelChain) and comparing the corrected
model's prediction of what was recorded; the fault parameter minimises the training segments' shooting
error of the recorded signal, the model's coefficients refit by equation error on the corrected states
at every trial value (bounded scalar search), so the fault and the model are fitted together. The
simulator makes them with sim.sensors.Accelerometer (gain, delay_s, bias_drift_ms2).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import minimize_scalar

from ..measurement import PARAMS
from .base import Candidate, Effect


class ChannelFault(Effect):
    """A fault with one or more scalar parameters (identify.explain.measurement.PARAMS keys), one searched at a
    time; the one that fits best is kept."""

    kind, plain = "measurement", False
    params: tuple[str, ...] = ()

    def propose(self, fitter, cur):
        if self.name in cur.effects or fitter.chain is None:
            return None
        return self._fault(fitter, cur)

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
        st, fit = self.with_fault(fitter, cur, key, x)
        return Candidate(self.name, "measurement", [], st, fit, None, 0.0, {key: x, **self.derived(key, x)},
                         list(self.same_as))

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
