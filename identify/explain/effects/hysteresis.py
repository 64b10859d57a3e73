"""Bouc-Wen hysteresis with an internal state z (m): F = -alpha m z, z' = q1 - beta |q1| z - gamma q1 |z|
(n = 1). (beta, gamma) are searched on a grid scaled by the measured stroke, z integrated from the
measured velocity gives the column (identify.explain.structure.Fitter.z_state), and the shooting refit refines
them with the coefficients. The rig simulator runs it from RigParameters hysteresis_*.
"""
from __future__ import annotations

import numpy as np

from .base import Effect, wrong_side

#: Bouc-Wen: 1/(beta + gamma) (the state's saturation level) as fractions of the measured max |q2|,
#: and gamma's share of beta + gamma.
HYST_SATURATION = (0.1, 0.3, 1.0)
HYST_GAMMA_SHARE = (0.0, 0.5)


class Hysteresis(Effect):
    name, terms, unit = "hysteresis", ("z",), "N/m"
    description = ("Bouc-Wen hysteresis with an internal state z: z' = q1 - beta |q1| z - gamma q1 |z|; "
                   "(beta, gamma) searched")
    plain = False

    def propose(self, fitter, cur):
        if self.name in cur.effects or cur.hyst is not None:
            return None
        qmax = float(np.max(np.abs(fitter.displacement(cur))))
        tries = [cur.adding(self.name, self.terms, hyst=((1 - share) / (sat * qmax), share / (sat * qmax)))
                 for sat in HYST_SATURATION for share in HYST_GAMMA_SHARE]
        st, fit = min(((st, fitter.equation_fit(st)) for st in tries), key=lambda v: v[1].mse_heldout)
        return self.candidate(cur, st, fitter, fit, {"beta_per_m": st.hyst[0], "gamma_per_m": st.hyst[1]})

    def admissibility(self, coef: dict, se: dict) -> str:
        if wrong_side(coef.get("z", 0.0), 0.0, se.get("z", 0.0)):
            return "the hysteretic force pushes along the displacement instead of restoring"
        return ""

    def refit_fields(self, st) -> dict:
        return {"beta_per_m": st.hyst[0], "gamma_per_m": st.hyst[1]} if st.hyst is not None else {}
