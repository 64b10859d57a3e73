"""One candidate per catalog effect on top of the current explanation: each effect proposes its own
(identify.effects: its terms, its parameter search, its Wald statistic)."""
from __future__ import annotations

from .effects import CATALOG, Candidate, Effect, wald_p  # noqa: F401  (wald_p: the effects' Wald test)
from .structure import Fitter, Structure


def all_candidates(fitter: Fitter, cur: Structure, catalog: dict) -> list[Candidate]:
    """Every effect of `catalog` ({name: Effect, or None for the registered one}) fitted on top of `cur`,
    those that apply."""
    out = []
    for name, effect in catalog.items():
        effect: Effect = effect if effect is not None else CATALOG[name]
        c = effect.propose(fitter, cur)
        if c is not None:
            out.append(c)
    return out
