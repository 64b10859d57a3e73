"""Choosing one model from the path (the paper's Pareto step) and refitting it.

Rules (per state equation):
- ``paper``: the paper's rule. MSE of each path model as it comes out of the LASSO (shrunken
  coefficients, training samples); tolerance line at (1 + 0.25) x the minimum; the sparsest model
  under the line. Reproduces the paper, but a real term whose share of the residual variance is below
  ~25 % is dropped (the paper's own q1*q2^2 at 1-10 % noise, docs/identification.md).
- ``heldout`` (default): every distinct support on the path is refit by least squares on the training
  samples and scored on the held-out samples. Refitting removes the LASSO shrinkage that inflates a
  sparse model's error; held-out samples make a spurious term cost error instead of buying it.
  Tolerance line at (1 + 0.003) x the minimum held-out MSE: a term must explain at least 0.3 % of the
  remaining held-out error to be kept. Systematic errors of the integrated states at high noise look
  like real terms on held-out data too, so some magnitude bar is needed; 0.3 % keeps the weak q1*q2^2
  term where 1 % loses it and admits no spurious term where 0.1 % does (benchmarks/selection_rules.py,
  docs/identification.md). The sparsest support under the line wins, then terms are
  removed one at a time while the refit stays under the line: the path moves in discrete lambda steps
  and can add two terms at once (a spurious one with a real one), so its supports alone may never
  contain the right model.
- ``bic``: refit supports scored by n_eff ln(MSE) + k ln(n_eff) with n_eff = 2 B T, the number of
  independent samples a band of B Hz carries over T seconds; backward elimination as for heldout.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import IdentificationError
from .gram import NormalEquations
from .optimizers.base import SparsePath, distinct_rows, least_squares_many

RULES = ("heldout", "paper", "bic")
DEFAULT_TOLERANCE = {"paper": 0.25, "heldout": 0.003, "bic": 0.0}


@dataclass
class Selection:
    """The chosen point of the path for one equation, and what it was chosen on."""

    rule: str
    index: int                # chosen path point
    support: np.ndarray       # (m,) bool
    coef: np.ndarray          # (m,) least-squares refit on the support
    path_mse: np.ndarray      # (k,) training MSE of the path's own coefficients (paper figure)
    path_nnz: np.ndarray      # (k,)
    score: np.ndarray         # (k,) the rule's criterion per path point
    threshold: float          # tolerance line on `score` (nan for bic)


def select(path: SparsePath, eq: int, train: NormalEquations, heldout: NormalEquations | None,
           rule: str = "heldout", tolerance: float | None = None, n_eff: float | None = None,
           max_terms: int | None = None) -> Selection:
    """Choose and refit one equation's model from the path. `max_terms` caps the support: past the
    rule's own choice, the least costly terms are eliminated until it fits the budget."""
    if rule not in RULES:
        raise IdentificationError(f"unknown selection rule {rule!r}; choose from {', '.join(RULES)}")
    if rule == "heldout" and (heldout is None or heldout.n == 0):
        raise IdentificationError("selection 'heldout' needs held-out samples (holdout fraction > 0)")
    tol = DEFAULT_TOLERANCE[rule] if tolerance is None else float(tolerance)
    X = path.coefs[:, :, eq]                       # (k, m)
    supports = X != 0
    nnz = supports.sum(1)
    path_mse = train.mse(X.T, eq)
    b = train.B[:, eq]
    first, which = distinct_rows(supports)                   # each support refit once
    coef_k = least_squares_many(train.G, b, supports[first])[which]
    floor = 1e-13 * train.yy[eq] / max(train.n, 1)  # numerical zero for exactly-fitting equations
    if rule == "paper":
        score = path_mse
        thr = (1 + tol) * score.min() + floor
        ok = np.flatnonzero(score <= thr)
        k = ok[np.lexsort((ok, nnz[ok]))[0]]  # fewest terms, then largest lambda (earliest point)
    elif rule == "heldout":
        score = heldout.mse(coef_k.T, eq)
        thr = (1 + tol) * score.min() + floor
        ok = np.flatnonzero(score <= thr)
        k = ok[np.lexsort((score[ok], nnz[ok]))[0]]  # fewest terms, then lowest held-out error
    else:
        n_eff = float(n_eff or train.n)
        mse = np.maximum(train.mse(coef_k.T, eq), floor)
        score = n_eff * np.log(mse) + nnz * np.log(n_eff)
        thr = float("nan")
        k = int(np.argmin(score))
    support, coef = supports[k].copy(), coef_k[k].copy()
    if rule != "paper":
        support, coef = _backward_eliminate(support, coef, train, heldout, eq, rule, thr, score[k], n_eff)
    if max_terms is not None and support.sum() > max_terms:
        support, coef = _backward_eliminate(support, coef, train, heldout, eq, rule, thr, score[k], n_eff,
                                            max_terms)
    return Selection(rule, int(k), support, coef, path_mse, nnz, score, float(thr))


def _backward_eliminate(support, coef, train, heldout, eq, rule, thr, current, n_eff, max_terms=None):
    """Drop terms one at a time while the refit model still meets the rule (under the tolerance line
    for heldout, a lower BIC for bic), or unconditionally while it has more than `max_terms`; each
    round drops the term whose removal costs least."""
    b = train.B[:, eq]
    floor = 1e-13 * train.yy[eq] / max(train.n, 1)

    def crit(X, k):
        """The rule's criterion of coefficient rows X (t, m) with k (t,) terms each."""
        if rule in ("heldout", "paper") and heldout is not None and heldout.n:
            return heldout.mse(X.T, eq)
        if rule == "paper":
            return train.mse(X.T, eq)
        return n_eff * np.log(np.maximum(train.mse(X.T, eq), floor)) + k * np.log(n_eff)

    while support.any():
        dropped = np.flatnonzero(support)
        s2 = np.repeat(support[None], dropped.size, axis=0)
        s2[np.arange(dropped.size), dropped] = False          # row i: support without its i-th term
        x2 = least_squares_many(train.G, b, s2)
        score = crit(x2, s2.sum(1))
        i = int(np.argmin(score))                               # the first of equal scores, as before
        over_budget = max_terms is not None and support.sum() > max_terms
        if over_budget or (rule == "heldout" and score[i] <= thr) or (rule == "bic" and score[i] < current):
            current, support, coef = float(score[i]), s2[i], x2[i]
        else:
            break
    return support, coef
