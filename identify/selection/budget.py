"""A term budget chosen by free-run error (SparseIdentifier(max_terms=K, budget="free-run")).

The equation-error budget (identify.selection.pareto) drops, one at a time, the terms whose removal costs least
one-step acceleration error. With few terms that is not the set that best reproduces the motion: on
Silverbox at 7 terms it keeps q1^2*q2 and drops q2^2, and the free run pays for it. Here the choice is
made on what the model is for, the free-run error, and on the estimation data only:

1. candidates: every subset of `max_terms` terms of the selection rule's support (when there are more
   than MAX_SUBSETS of them, terms are first eliminated one at a time by free-run error until there
   are not);
2. screening: each candidate is fitted by least squares (equation error, the training normal
   equations) and free-run simulated over the record; its free-run error on the fit rows ranks it;
3. the best `n_refit` are refit on their free-run error (identify.simulation.refine, fit rows) and the one with
   the lowest free-run error on the held-out rows (the fit rows when nothing is held out) wins;
4. the winner is refit to the full tolerance on `final_rows` (default: the fit rows; all estimation
   rows with SparseIdentifier(budget_refit="all"): the held-out rows have done their job once the
   terms are chosen, and on Silverbox they hold some of the highest amplitudes the extrapolating
   arrowhead test needs: 0.394 -> 0.385 mV, docs/identification.md).

The equation-error coefficients of a small support often free-run badly although the same terms,
refit, free-run well (Silverbox: the winner ranked 6th of 120 before its refit); hence step 3.

Several recordings of one rig (a joint fit, identify.joint): `train` is their summed normal equations,
and every free-run error is pooled over the recordings, each simulated from its own start on its own
rows (identify.simulation.refine.PooledFreeRunError).
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..regression.gram import NormalEquations
from ..model import SparseModel
from ..regression.optimizers.base import least_squares
from ..simulation.refine import free_run_error, refine_free_run

#: Most subsets screened by free run (each one simulation of the record).
MAX_SUBSETS = 300
#: Candidates refit on their free-run error (each ~20-60 simulations of the record).
N_REFIT = 8
#: Relative cost change at which a candidate's refit stops (the ranking needs no finer optimum).
REFIT_FTOL = 1e-4


@dataclass
class BudgetChoice:
    """The terms kept for one equation, the winner's refit model, and how every candidate scored
    (free-run error = sum over q2, q1 of MSE / variance, FreeRunError)."""

    support: np.ndarray          # (m,) bool over the library
    model: SparseModel           # the winner, its coefficients refit on the free-run error
    refinement: dict             # the winner's refine_free_run info
    candidates: list = field(default_factory=list)  # [{"terms", "screen", "refit"}], best first
    seconds: float = 0.0
    pool: list = field(default_factory=list)  # the terms it chose from (the selection rule's support)


def choose_budget(model: SparseModel, names, support: np.ndarray, max_terms: int, train: NormalEquations,
                  sig, fit_rows: np.ndarray, heldout_rows: np.ndarray | None = None, equation: str = "q1_dot",
                  eq_index: int = 0, n_refit: int = N_REFIT, max_subsets: int = MAX_SUBSETS,
                  final_rows: np.ndarray | None = None, signals=("q2", "q1")) -> BudgetChoice:
    """Choose at most `max_terms` of `support` (bool over the library `names`) for `equation` of
    `model` by free-run error; the other equations of `model` are kept as they are.

    train : normal equations of the fit rows (least-squares coefficients of each candidate).
    fit_rows, heldout_rows : masks over the valid rows of `sig` (StateSignals); held-out rows rank the
        refit candidates when there are any. Several recordings: `sig` a list of StateSignals and each
        mask a list of masks, one per recording (the free-run errors are pooled).
    final_rows : mask of the rows the winner's final refit uses (None: fit_rows). The choice itself
        never sees them beyond fit_rows and heldout_rows.
    signals : the simulated states whose error screens, refits and ranks (FreeRunError); ("q2",) is the
        output error alone (Silverbox: the same choice, benchmarks/silverbox_criteria.py --part output-error)."""
    t0 = time.perf_counter()
    support = np.asarray(support, dtype=bool)
    b = train.B[:, eq_index]

    def candidate(s: np.ndarray) -> SparseModel:
        x = least_squares(train.G, b, s)
        eqs = {eq: dict(c) for eq, c in model.equations.items()}
        eqs[equation] = {names[j]: float(x[j]) for j in np.flatnonzero(s)}
        return SparseModel(eqs, model.states, model.inputs, travel=model.travel or None)

    screen_error = free_run_error(sig, fit_rows, signals, model=model)

    def screen(s: np.ndarray) -> float:
        return screen_error.cost(candidate(s))

    # 1. backward elimination by free-run error while the subsets are too many to screen
    current = support.copy()
    while math.comb(int(current.sum()), max_terms) > max_subsets:
        trials = []
        for j in np.flatnonzero(current):
            s = current.copy()
            s[j] = False
            trials.append((screen(s), j))
        current[min(trials)[1]] = False
    # 2. screen every subset of the remaining support
    screened = []
    for keep in itertools.combinations(np.flatnonzero(current), min(max_terms, int(current.sum()))):
        s = np.zeros_like(current)
        s[list(keep)] = True
        screened.append((screen(s), keep, s))
    screened.sort(key=lambda t: (t[0], t[1]))
    # 3. refit the best on their free-run error, rank on the held-out rows
    several = isinstance(sig, (list, tuple))
    has_heldout = heldout_rows is not None and any(np.any(h) for h in (heldout_rows if several else [heldout_rows]))
    rank_error = free_run_error(sig, heldout_rows if has_heldout else fit_rows, signals, model=model)
    results = []
    for cost, keep, s in screened[:max(n_refit, 1)]:
        refit, info = refine_free_run(candidate(s), sig, fit_rows, equation, signals, ftol=REFIT_FTOL)
        results.append((rank_error.cost(refit), keep, s, refit, info, cost))
    results.sort(key=lambda t: (t[0], t[1]))
    best = results[0]
    final = fit_rows if final_rows is None else final_rows
    refit, info = refine_free_run(best[3], sig, final, equation, signals)  # the winner to the full tolerance
    if not info["accepted"] and final_rows is None:  # converged at the screening tolerance: that refit is it
        refit, info = best[3], best[4]
    table = [{"terms": [names[j] for j in r[1]], "screen": r[5], "refit": r[0]} for r in results]
    table += [{"terms": [names[j] for j in keep], "screen": cost, "refit": None}
              for cost, keep, _ in screened[max(n_refit, 1):]]
    return BudgetChoice(best[2], refit, info, table, time.perf_counter() - t0,
                        [names[j] for j in np.flatnonzero(support)])
