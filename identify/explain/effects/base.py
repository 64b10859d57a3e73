"""The effect abstraction: one class per effect (its terms or states, its simulation, its parameters and
their search, its admissibility, its report fields), the `Candidate` an effect proposes on top of the
current explanation, and the registry every user reads (the rig simulator, the identification library,
the discrepancy workflow, the reports). Adding an effect is one module with its class plus one
`register(...)` line in identify/explain/effects/__init__.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from ...regression.gram import scaled_pinv

#: Relative tolerance on a restoring/dissipating sign (numerical zero).
SIGN_TOL = 1e-9
#: A coefficient of the wrong sign is a violation only beyond this many of its standard errors from zero.
SIGN_Z_WRONG = 2.0


def wrong_side(value: float, scale: float, se: float) -> bool:
    """`value` > 0 beyond numerical zero (relative to `scale`) and beyond SIGN_Z_WRONG x `se`."""
    return value > SIGN_TOL * scale and value > SIGN_Z_WRONG * se


def sides(coef: dict, se: dict, sym: str, asym: str):
    """Per side (upper, lower) of an end stop: (coefficient, scale, standard error) of sym +- asym."""
    c1, c2 = coef.get(sym, 0.0), coef.get(asym, 0.0)
    s = float(np.hypot(se.get(sym, 0.0), se.get(asym, 0.0)))
    return [(c1 + c2, abs(c1) + abs(c2), s), (c1 - c2, abs(c1) + abs(c2), s)]


@dataclass(eq=False)
class Candidate:
    """One effect fitted on top of the current explanation (Structure), and how the analysis scored it."""

    name: str
    kind: str                       # "physics" | "measurement"
    terms: list                     # the dq1/dt terms it adds
    structure: object               # identify.explain.structure.Structure, coefficients by equation error
    fit: object                     # identify.explain.structure.Fit of that structure
    wald: float | None = None       # Wald statistic of its terms (a fault: its test's t^2; None: not tested)
    p_value: float = 0.0
    extra: dict = field(default_factory=dict)     # its searched parameters (report fields)
    same_as: list = field(default_factory=list)   # effects the data cannot tell from it (reported as surrogates)
    # set by the analysis (identify.explain.rounds.Rounds._round)
    err: np.ndarray | None = None   # per-segment squared shooting error
    rejected: str = ""
    admissible: bool = False
    gap_share_closed: float = 0.0
    p_beats_current: float = 0.0
    score: float = 0.0              # share of the current held-out equation error it explains

    def refit(self, structure) -> "Candidate":
        """The same candidate with another structure (its shooting refit), to be scored again."""
        return replace(self, structure=structure)


def wald_p(fit, terms) -> tuple[float, float]:
    """(Wald statistic, p-value) of the joint hypothesis that `terms`' coefficients are zero."""
    pos = [fit.names.index(t) for t in terms if t in fit.names]
    if not pos:
        return 0.0, 1.0
    theta = np.array([fit.coef[fit.names[i]] for i in pos])
    cov = fit.cov[np.ix_(pos, pos)]
    w = float(theta @ scaled_pinv(cov) @ theta)
    # degrees of freedom: the free coefficients among `terms` (a one-sided stop's tied terms follow others)
    d = np.sqrt(np.maximum(np.diag(cov), 0.0))
    dof = int(np.linalg.matrix_rank(cov / np.outer(d, d), tol=1e-9)) if np.all(d > 0) else len(pos)
    return w, float(stats.chi2.sf(w, max(dof, 1)))


class Effect:
    """A physical force on the mass, F = coefficient x sum(weight x term(q1, q2)), or (kind
    "measurement") a fault of the recording. Subclasses set the class attributes and override what
    differs from plain library terms.

    name, terms (dq1/dt terms it adds), unit, description; kind; sign: the sign a dissipative effect's
    coefficient must have in dq1/dt (-1: the force opposes the motion; 0: free); group: effects the
    data often cannot tell apart (each other's surrogates); plain: simulated by the rig simulator from
    RigParameters(effects={name: coef}) and offered to the identification library as its terms;
    in_rounds: offered as a candidate in the discrepancy workflow's rounds."""

    name: str = ""
    terms: tuple[str, ...] = ()
    unit: str = ""
    description: str = ""
    kind: str = "physics"
    sign: int = 0
    group: str = ""
    plain: bool = True
    in_rounds: bool = True

    @property
    def dissipative(self) -> bool:
        return self.sign < 0

    @property
    def masked_sign(self) -> int:
        """The side a masked member of its group is looked for on (identify.explain.masking): its sign; a
        sign-free effect may name the side its masked form takes (0: it is not looked for under a mask)."""
        return self.sign

    # -- simulation -------------------------------------------------------------------------------
    @property
    def force(self) -> dict:
        """{term: weight}: the force the rig simulator adds per unit coefficient (plain effects)."""
        return {t: 1.0 for t in self.terms}

    # -- parameters and their search --------------------------------------------------------------
    def propose(self, fitter, cur) -> Candidate | None:
        """The candidate on top of `cur` (identify.explain.structure.Structure) with equation-error coefficients,
        or None when it does not apply (already there). Plain terms: one least-squares fit. Called for every
        effect of a round side by side (identify.threads.map_runs): it must not change shared state but the
        fitter's caches (which are made for that)."""
        if self.name in cur.effects or all(t in cur.terms for t in self.terms):
            return None
        return self.candidate(cur, cur.adding(self.name, self.terms), fitter)

    def candidate(self, cur, st, fitter, fit=None, extra=None) -> Candidate:
        """A physics candidate of structure `st` on top of `cur`: fitted (unless `fit` is given), with the
        Wald test of the terms it adds."""
        fit = fit if fit is not None else fitter.equation_fit(st)
        new = [t for t in st.terms if t not in cur.terms]
        w, p = wald_p(fit, new)
        return Candidate(self.name, "physics", new, replace(st, coef=tuple(fit.coef.items())), fit, w, p,
                         dict(extra or {}))

    # -- admissibility ----------------------------------------------------------------------------
    def admissibility(self, coef: dict, se: dict) -> str:
        """'' when the physics allows these coefficients, else the reason (identify.explain.admissibility: signs
        are judged statistically against the standard errors `se`)."""
        t = self.off_side(coef, se, self.sign) if self.kind == "physics" and self.dissipative else None
        return f"{t} has coefficient {coef[t]:+.4g} in dq1/dt: it injects energy instead of dissipating it" if t else ""

    def off_side(self, coef: dict, se: dict, sign: int) -> str | None:
        """The first of its terms whose coefficient is off the side `sign` (-1: negative in dq1/dt) beyond
        SIGN_Z_WRONG standard errors (wrong_side), or None: the one sign rule, here and under a mask
        (identify.explain.masking.masked_admissibility)."""
        return next((t for t in self.terms if wrong_side(-sign * coef.get(t, 0.0), 0.0, se.get(t, 0.0))), None)

    def without(self, st):
        """`st` with this effect taken out of a finished explanation (identify.explain.rounds.Rounds._recheck),
        or None where it is not taken out again (physics: each was judged against what was named before it)."""
        return None

    # -- report fields ----------------------------------------------------------------------------
    def refit_fields(self, st) -> dict:
        """Report fields of its nonlinear parameters as refit in structure `st` (beyond `Candidate.extra`)."""
        return {}

    def annotate(self, entry: dict, analysis) -> None:
        """Add to (or withhold from) a named effect's report entry what the record can say about it."""

    def after_rounds(self, analysis, recording, sig) -> list[dict]:
        """Report entries of what this effect shows outside the gap (looked for after the rounds)."""
        return []

    def __repr__(self) -> str:
        return f"<effect {self.name} ({self.kind})>"


#: The registry: {name: effect}, in registration order (the order candidates are offered and listed).
CATALOG: dict[str, Effect] = {}


def register(effect: Effect) -> Effect:
    """Add `effect` to the catalog (one line per effect in identify/explain/effects/__init__.py)."""
    if not effect.name or effect.name in CATALOG:
        raise ValueError(f"effect name {effect.name!r} is empty or registered already")
    if effect.kind not in ("physics", "measurement"):
        raise ValueError(f"effect {effect.name}: kind must be 'physics' or 'measurement', got {effect.kind!r}")
    CATALOG[effect.name] = effect
    return effect


def unregister(name: str) -> None:
    """Remove an effect registered at run time (a test's own effect)."""
    CATALOG.pop(name)


def plain_effects() -> dict:
    """Physics effects the rig simulator adds as plain force terms (RigParameters(effects=...))."""
    return {n: e for n, e in CATALOG.items() if e.plain and e.kind == "physics"}


def expand_terms(names) -> tuple[str, ...]:
    """Library term names with plain effects' names replaced by their terms ("coulomb_friction" ->
    "sign(q1)"): the identification library takes an effect by its name."""
    out: list[str] = []
    for n in names:
        e = CATALOG.get(n)
        for t in (e.terms if e is not None and e.plain and e.kind == "physics" else (n,)):
            if t not in out:
                out.append(t)
    return tuple(out)
