"""End stop: contact beyond a travel d (m), one or two sided, with the contact's spring
(stop(q2) = sign(q2) max(|q2| - d, 0)) and damping (q1 contact(q2)).

Two sided as the pair stop(q2) and sign(q2)*stop(q2) (the asymmetry between the sides), or one sided,
the asymmetry terms tied to the symmetric ones (Structure.side). The travel is searched over fractions
of the measured max |q2| (of that side's own peak, one sided); the shooting refit (Structure.travel_free)
refines it. The rig simulator runs it from RigParameters end_stop_travel_mm / end_stop_lower_mm /
end_stop_upper_mm.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from .base import Effect, sides, wrong_side

END_STOP_FRACTIONS = (0.5, 0.6, 0.7, 0.8, 0.88, 0.94)
SIDES = {None: "both", 1: "upper", -1: "lower"}


class EndStop(Effect):
    name, unit = "end_stop", "N/m"
    terms = ("stop(q2)", "sign(q2)*stop(q2)", "q1*contact(q2)", "q1*sign(q2)*contact(q2)")
    description = ("contact beyond a travel d, one or two sided, with the contact's spring (stop(q2) = sign(q2) "
                   "max(|q2| - d, 0)) and damping (q1 contact(q2)); d is searched")
    group, plain = "asymmetry", False

    def propose(self, fitter, cur):
        if self.name in cur.effects or cur.travel:
            return None
        st, fit = self._search(fitter, cur, fitter.displacement(cur))
        return self.candidate(cur, st, fitter, fit, {"travel_m": st.travel, "sides": SIDES[st.side]})

    def _search(self, fitter, cur, q2):
        """(structure, equation fit) of the end stop that fits best.

        Three variants: two sided, travel d at fractions of max |q2|, and one sided above or below, at
        fractions of that side's own peak (a stop on one side holds that side's excursion well below the
        other's). Within each, d by held-out equation error: the grid, then a bounded search between the
        best point's neighbours (the error changes several-fold over a grid step: a one-sided 9 mm stop on
        the design rig, fitted two sided at 8.8 mm, left a training shooting error of 606, at 9.4 mm 352,
        against 3693 without a stop). Tries whose stop pushes outwards somewhere count 10x, here and
        between the variants, which are compared on the same held-out error (comparing them on the
        training segments' shooting error instead chose the two-sided form, which has the one-sided as
        special cases, in all three single-stop cases of benchmarks/explain_robustness.py, and the
        one-sided stop of its case 72 then closed 45 % of the gap instead of 90 %)."""
        peaks = {None: float(np.max(np.abs(q2))), 1: float(max(np.max(q2), 0.0)), -1: float(max(-np.min(q2), 0.0))}
        fr = np.array(END_STOP_FRACTIONS)
        variants = []
        for side, peak in peaks.items():
            if not peak > 0:
                continue
            memo = {}

            def attempt(d: float):
                if d not in memo:
                    st = cur.adding(self.name, self.terms, travel=float(d), side=side, travel_free=True)
                    fit = fitter.equation_fit(st)
                    # signs at face value here: between the variants, a two-sided fit that pushes outwards
                    # by a hair on one side is the one-sided stop (case 72); the chosen one is then judged
                    # statistically (admissibility.SIGN_Z_WRONG)
                    sane = not self.admissibility(fit.coef, {})
                    memo[d] = (st, fit, sane, fit.mse_heldout * (1.0 if sane else 10.0))
                return memo[d]

            costs = [attempt(f * peak)[3] for f in fr]
            i = int(np.argmin(costs))
            lo, hi = fr[max(i - 1, 0)] * peak, (fr[i + 1] if i + 1 < fr.size else 1.0) * peak
            minimize_scalar(lambda d: attempt(d)[3], bounds=(lo, hi), method="bounded",
                            options={"xatol": 2e-3 * peak, "maxiter": 12})
            variants.append(min(memo.values(), key=lambda v: v[3]))  # every travel tried, the search's included

        st, fit, _, _ = min(variants, key=lambda v: v[3])
        return st, fit

    def admissibility(self, coef: dict, se: dict) -> str:
        """A stop restores and its contact dissipates, on each side, and it is stiffer than the spring it
        stops (identify.explain.admissibility, rule 1)."""
        if any(wrong_side(*v) for v in sides(coef, se, "stop(q2)", "sign(q2)*stop(q2)")):
            return "the end stop pushes the mass outwards on one side instead of stopping it"
        if any(wrong_side(*v) for v in sides(coef, se, "q1*contact(q2)", "q1*sign(q2)*contact(q2)")):
            return "the end stop's contact damping injects energy on one side instead of dissipating it"
        c1, c2 = coef.get("stop(q2)", 0.0), coef.get("sign(q2)*stop(q2)", 0.0)
        k, contact = -coef.get("q2", 0.0), max(-(c1 + c2), -(c1 - c2))
        if k > 0 and contact < k:
            return (f"its contact ({contact:.4g} N/m per kg on its stiffer side) is softer than the rig's own "
                    f"spring ({k:.4g}): a stiffness change beyond the travel, not a stop")
        return ""

    def refit_fields(self, st) -> dict:
        return {"travel_m": st.travel} if st.travel else {}
