"""Masking: a strong effect hides a weaker one of its own group (identify.explain.effects, Effect.group: the
effects the data often cannot tell apart), and the rounds' own way in cannot find it.

Seen (benchmarks/explain_robustness.py --seed 2590080356, cases 89, 122, 125, 155): Coulomb friction with
quadratic or cubic damping. Once Coulomb is named and refit, the gap is 0.6-0.8x the (upper-estimate) noise
floor, so the rounds stop; and had they gone on, the damping's equation-error fit on top of Coulomb comes
out on the wrong side of zero (+7.2 +- 5.3 against the truth's -3.7 in dq1/dt: linear damping plus Coulomb
fit most of it, and what is left the equation error reads with the rest of its coefficients moved far off
the refit model), so it is neither significant nor admissible and is never refit. Refit on the shooting error
from the explanation's own coefficients, with the damping started on its physical side, it settles at
-1.8 to -2.4 from starts of -1 to -7 and removes 38-56 % of the held-out squared error (block bootstrap
probability 1.0); on a Coulomb-only rig the same refit drifts to the wrong sign and raises the held-out
error.

So once the reported (trimmed) gap is down at the floor (identify.explain.workflow.CONTINUE_FACTOR x it; a
round on the plain sums may still have run and named nothing), the group of each named effect is checked once
(DiscrepancyAnalysis._explain, with refine on): screen() takes each other plain-term member with a physical
side (Effect.masked_sign: Coulomb friction, quadratic and cubic damping by their sign rule, displacement-
dependent damping, sign-free in the rounds, dissipating)'s Gauss-Newton step on the training
segments' shooting error from the explanation (one run per coefficient: the Jacobian of its coefficients, and
a secant for the member's terms) and keeps those it moves to their physical side; up to MASKED_REFITS of them
are refit on the shooting error from the explanation's coefficients and that step (not from the equation
error's, which is what is off); each is tested on the shooting error itself (shooting_test: its Wald statistic
under the segment-clustered sandwich), judged on the sign rules with those standard errors, and added if it
removes min_gap_closed of the held-out squared error and beats the explanation with MASKED_P_BEATS; the polish
after it (workflow.POLISH_NFEV) is not kept if it takes the term across zero. Below the floor this is where
the evidence is: the held-out segments are not fitted, so a drop of their error is the model's, not noise
fitted away. The entry says `masked_by`. Above the floor a round that names nothing is where the rounds end:
the check, run there too at first, named an energy-injecting displacement-dependent damping (closing 37 %, p
8e-19) on a Coulomb-only rig whose Coulomb model left 3.1x the floor (benchmarks/explain_robustness.py --seed
2433474371 --case 108).
On the design rig (30 s, 1-20 Hz at 1.3 mm, 0.5 % noise; tests/identify/test_masking.py) the joint shooting
refit finds quadratic damping within 7-13 % of truth beside Coulomb friction (p ~ 1e-20) and, on a Coulomb-
only rig, +0.3 +- 0.2 (p 0.02-0.14).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .clustered import cr3_covariance, wald_p
from .effects import CATALOG, Candidate
from .structure import Fit, Fitter, Structure
from ..threads import map_runs

#: A masked effect is added only when the block bootstrap says it beats the explanation before it with at
#: least this probability on the held-out segments (below the floor the held-out error is the evidence).
MASKED_P_BEATS = 0.99
#: Members of a group refit per check, the screen's first: every one the damping group can have. The
#: screen's order is not the refits' (seed 2590080356 case 122: it put cubic damping first, the refits
#: quadratic); the cap keeps a larger group's check to three refits (~100 shooting runs each).
MASKED_REFITS = 3
#: The screen's secant for a new term spans at least this many of its equation-error standard errors.
MIN_START_SE = 1.0
#: The shooting test's curvature (on unit columns) beyond this condition number determines nothing: p = 1.
MAX_CONDITION = 1e10
#: Relative step of the shooting test's finite differences (of each coefficient's magnitude).
TEST_STEP = 1e-5


class _Runs:
    """The training segments' shooting residuals of a structure's model with some coefficients changed:
    (residual rows, the integration's step (substeps, stride: ShootingData.run's), whether a segment diverged)."""

    def __init__(self, fitter: Fitter, st: Structure):
        self.fitter, self.st, self.train = fitter, st, ~fitter.seg_held
        self.data = fitter.data(st)
        self.ties = st.ties
        self.names = [t for t in st.coefficients if t not in self.ties]  # tied terms follow their free term
        d = self.data
        self.lengths = [int(b - a) for a, b, w in zip(d.starts, d.stops, self.train) if w]

    def __call__(self, values: dict | None = None):
        c = dict(self.st.coefficients, **(values or {}))
        c.update({t: f * c[s] for t, (s, f) in self.ties.items()})
        model = self.fitter.model(replace(self.st, coef=tuple((t, c[t]) for t in self.st.coefficients)))
        return self.data.run_residuals(model, self.train)

    def jacobian(self, r0: np.ndarray, steps0: tuple, names=None, sizes=None) -> np.ndarray | None:
        """Forward differences of the residuals in `names` (default: every free coefficient) at steps
        `sizes` (secants: a change of the integration's step is allowed, small beside the step) or
        TEST_STEP of each magnitude (derivatives: it is not); None where a run diverges, or a derivative's
        run changes its integration step (substeps or samples per step)."""
        names = self.names if names is None else names
        coef = self.st.coefficients
        J = np.empty((r0.size, len(names)))
        steps = [sizes[j] if sizes is not None else TEST_STEP * max(abs(coef[t]), 1e-12) for j, t in enumerate(names)]
        runs = map_runs(lambda th: self({th[0]: coef[th[0]] + th[1]}), zip(names, steps))  # columns side by side
        for j, ((r, step, bad), h) in enumerate(zip(runs, steps)):
            if bad or (sizes is None and step != steps0):
                return None
            J[:, j] = (r - r0) / h
        return J


def shooting_test(fitter: Fitter, st: Structure, terms: list) -> tuple[dict, float]:
    """({term: standard error}, p) of `terms`' coefficients in `st` against zero, on the training segments'
    shooting error: its Gauss-Newton curvature H = J'J (forward differences, one run per free coefficient)
    and the segment-clustered sandwich of identify.explain.clustered (each segment's score J_s' r_s
    taken as the jackknife's shift, CR3; the Wald statistic over d terms read as F(d, segments - 1), the
    case d = 1 being a fault's one-parameter t; W / d against F is looser than Hotelling's for d > 1, and
    every plain member has d = 1). The algebra is on unit-norm Jacobian columns (the coefficients span
    ~10 decades). A segment's leverage above clustered.MAX_LEVERAGE scales its whole H_s (exact for d = 1). The
    Bouc-Wen pair and a free end-stop travel, refit beside the coefficients by Fitter.refine, are held at
    their values here: their uncertainty is not in these standard errors. p = 1 where nothing is
    determined (a run diverging, the integration's step changing, a curvature with condition number
    beyond MAX_CONDITION)."""
    runs = _Runs(fitter, st)
    r0, steps0, bad = runs()
    J = None if bad else runs.jacobian(r0, steps0)
    if J is None:
        return {}, 1.0
    scale = np.linalg.norm(J, axis=0)  # the columns span ~10 decades (q2^3 against the input): unit columns
    if not np.all(scale > 0):
        return {}, 1.0
    Js_all = J / scale
    H = Js_all.T @ Js_all
    if not np.linalg.cond(H) < MAX_CONDITION:
        return {}, 1.0
    cuts = np.cumsum([0] + runs.lengths)
    pieces = [Js_all[a:b] for a, b in zip(cuts[:-1], cuts[1:])]
    cov = cr3_covariance(H, [Js.T @ Js for Js in pieces], [Js.T @ r0[a:b] for Js, a, b
                                                            in zip(pieces, cuts[:-1], cuts[1:])])
    cov = cov / np.outer(scale, scale)
    names, coef = runs.names, st.coefficients
    se = {t: float(np.sqrt(max(cov[j, j], 0.0))) for j, t in enumerate(names)}
    pos = [names.index(t) for t in terms if t in names]
    if not pos:
        return se, 1.0
    values = np.array([coef[names[i]] for i in pos])
    return se, wald_p(values, cov[np.ix_(pos, pos)], len(runs.lengths))


def _members(fitter: Fitter, cur: Structure, named: str, catalog: dict) -> list:
    """(effect, candidate) of the other plain-term physics members of the named effect's group that have a
    side to be looked for on (Effect.masked_sign): below the floor the sign is a guard the held-out error
    alone is not (displacement-dependent damping looked for on either side, energy-injecting, was named on
    a Coulomb-only rig)."""
    named_effect = catalog.get(named) or CATALOG.get(named)
    group = named_effect.group if named_effect is not None else ""
    out = []
    for name, effect in catalog.items():
        effect = effect if effect is not None else CATALOG[name]
        if group and effect.group == group and effect.plain and effect.kind == "physics" and effect.masked_sign:
            cand = effect.propose(fitter, cur)
            if cand is not None:
                out.append((effect, cand))
    return out


def masked_admissibility(effect, coef: dict, se: dict) -> str:
    """'' when a masked member's terms stay on the side it is looked for on (Effect.masked_sign, judged as
    the sign rules are: identify.explain.admissibility), else the reason; a sign-free effect's own
    admissibility does not hold it there."""
    t = effect.off_side(coef, se, effect.masked_sign)
    return f"its shooting refit takes {t} to {coef[t]:+.4g}, the side it is not looked for on under a mask" if t else ""


def screen(fitter: Fitter, cur: Structure, members: list) -> tuple[list, list]:
    """([(predicted drop of the training shooting error, effect, candidate, start of its new terms)], largest
    first, of the members whose Gauss-Newton step from the explanation (its coefficients' Jacobian and the
    new terms' secants at one equation-error size, MIN_START_SE standard errors at least) moves the new
    terms to their physical side (Effect.masked_sign); [(candidate, reason)] of the others): one run per
    coefficient and member, where a refit is ~100."""
    runs = _Runs(fitter, cur)
    r0, steps0, bad = runs()
    J = None if bad else runs.jacobian(r0, steps0)
    if J is None:
        return [], [(c, "the explanation's shooting error gave no Gauss-Newton step") for _, c in members]
    out, dropped = [], []
    for effect, cand in members:
        new = cand.terms
        size = [max(abs(cand.fit.coef.get(t, 0.0)), MIN_START_SE * cand.fit.se.get(t, 0.0)) or 1e-12 for t in new]
        st = replace(cand.structure, coef=tuple((t, cur.coefficients.get(t, 0.0)) for t in cand.structure.coefficients))
        cols = _Runs(fitter, st).jacobian(r0, steps0, new, [effect.masked_sign * h for h in size])
        A = None if cols is None else np.column_stack([J, cols])
        scale = None if A is None else np.linalg.norm(A, axis=0)
        if scale is None or not np.all(scale > 0):
            dropped.append((cand, "its free run diverged in the Gauss-Newton screen"))
            continue
        delta = np.linalg.lstsq(A / scale, -r0, rcond=None)[0] / scale  # on unit columns, as shooting_test
        move = delta[-len(new):]
        if not np.all(effect.masked_sign * move > 0):
            dropped.append((cand, f"its Gauss-Newton step on the shooting error goes to the wrong side "
                                  f"({', '.join(f'{t} {m:+.4g}' for t, m in zip(new, move))})"))
            continue
        drop = float(r0 @ r0 - np.sum((r0 + A @ delta) ** 2))
        out.append((drop, effect, cand, dict(zip(new, map(float, move)))))
    return sorted(out, key=lambda x: -x[0]), dropped


def masked_candidates(fitter: Fitter, cur: Structure, named: str, catalog: dict) -> list[Candidate]:
    """The members of the named effect's group that screen() finds moving to their physical side, the best
    MASKED_REFITS of them refit on the shooting error from the explanation's coefficients and that step,
    with their standard errors and p from shooting_test; then the others, at the explanation itself (their
    terms at zero), with the reason in `rejected` (for the report)."""
    kept, dropped = screen(fitter, cur, _members(fitter, cur, named, catalog))
    out = []

    def refit(member):  # on the shooting error alone: the refits run side by side (identify.threads.map_runs)
        _, _, cand, move = member
        start = dict(cur.coefficients, **move)
        st = fitter.refine_candidate(replace(cand.structure,
                                             coef=tuple((t, start[t]) for t in cand.structure.coefficients)))
        return (st, *shooting_test(fitter, st, cand.terms))

    for (_, _, cand, _), (st, se, p) in zip(kept[:MASKED_REFITS], map_runs(refit, kept[:MASKED_REFITS])):
        eq = fitter.equation_fit(st)
        fit = Fit(dict(st.coefficients), {**eq.se, **se}, eq.cov, eq.names, eq.mse_heldout)
        # the equation error's Wald statistic no longer applies: p is the shooting test's
        out.append(replace(cand, structure=st, fit=fit, p_value=p, wald=None))
    for _, _, cand, _ in kept[MASKED_REFITS:]:
        dropped.append((cand, f"not refit (beyond MASKED_REFITS = {MASKED_REFITS})"))
    for cand, reason in dropped:
        st = replace(cand.structure, coef=tuple((t, cur.coefficients.get(t, 0.0)) for t in cand.structure.coefficients))
        out.append(replace(cand, structure=st, p_value=1.0, wald=None, rejected=reason))
    return out
