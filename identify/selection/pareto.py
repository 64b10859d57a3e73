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

from ..errors import IdentificationError
from ..regression.gram import NormalEquations
from ..regression.optimizers.base import SparsePath, distinct_rows, least_squares_many

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
        k, thr = _sparsest_under_the_line(score, nnz, tol, floor)
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
        s2 = _without_one_term(support)
        x2 = least_squares_many(train.G, b, s2)
        score = crit(x2, s2.sum(1))
        i = int(np.argmin(score))                               # the first of equal scores, as before
        over_budget = max_terms is not None and support.sum() > max_terms
        if over_budget or (rule == "heldout" and score[i] <= thr) or (rule == "bic" and score[i] < current):
            current, support, coef = float(score[i]), s2[i], x2[i]
        else:
            break
    return support, coef


def _sparsest_under_the_line(score: np.ndarray, nnz: np.ndarray, tol: float, floor: float) -> tuple[int, float]:
    """The heldout rule's choice on a path: the tolerance line (1 + tol) x the lowest held-out MSE (+ the
    numerical floor), and under it the fewest terms, then the lowest held-out error. (index, line)."""
    thr = (1 + tol) * score.min() + floor
    ok = np.flatnonzero(score <= thr)
    return int(ok[np.lexsort((score[ok], nnz[ok]))[0]]), float(thr)


def _without_one_term(support: np.ndarray) -> np.ndarray:
    """(|S|, m): row i is `support` without its i-th term (one backward-elimination round's trials)."""
    dropped = np.flatnonzero(support)
    s2 = np.repeat(support[None], dropped.size, axis=0)
    s2[np.arange(dropped.size), dropped] = False
    return s2


def heldout_supports(paths, eq: int, trains, heldouts, tolerance: float | None = None) -> list[np.ndarray]:
    """The supports `select` with rule "heldout" (no max_terms) chooses for equation `eq` on each of
    several paths, each with its own training and held-out sums (the inclusion probabilities' held-out
    placements, identify.trust.uncertainty), computed together: every refit of all placements in one batched
    solve per step (the paths' distinct supports, then each backward-elimination round of the placements
    still eliminating). The same decisions as `select` per placement, whose refits are the same solves
    one placement at a time (tests/identify/test_selection.py)."""
    tol = DEFAULT_TOLERANCE["heldout"] if tolerance is None else float(tolerance)
    n = len(paths)
    if any(h is None or h.n == 0 for h in heldouts):
        raise IdentificationError("selection 'heldout' needs held-out samples (holdout fraction > 0)")
    G_tr = np.stack([t.G for t in trains])
    b_tr = np.stack([t.B[:, eq] for t in trains])
    G_h = np.stack([h.G for h in heldouts])
    b_h = np.stack([h.B[:, eq] for h in heldouts])
    yy_h = np.array([h.yy[eq] for h in heldouts])
    n_h = np.array([h.n for h in heldouts], dtype=float)

    def refit_and_score(owner: np.ndarray, rows: np.ndarray):
        """Least-squares refits of support rows (r, m), row i on placement owner[i]'s training sums, and
        their held-out MSE (NormalEquations.mse, row by row)."""
        x = least_squares_many(G_tr[owner], b_tr[owner], rows)
        gx = np.einsum("rij,rj->ri", G_h[owner], x)
        return x, (yy_h[owner] - 2 * (b_h[owner] * x).sum(1) + (x * gx).sum(1)) / n_h[owner]

    supports = [p.coefs[:, :, eq] != 0 for p in paths]
    distinct = [distinct_rows(s) for s in supports]
    owner = np.concatenate([np.full(first.size, i) for i, (first, _) in enumerate(distinct)])
    _, score_all = refit_and_score(owner, np.concatenate([s[first] for s, (first, _) in zip(supports, distinct)]))
    chosen, thresholds, offset = [], np.empty(n), 0
    for i, (s, (first, which)) in enumerate(zip(supports, distinct)):
        score = score_all[offset:offset + first.size][which]
        offset += first.size
        floor = 1e-13 * trains[i].yy[eq] / max(trains[i].n, 1)
        k, thresholds[i] = _sparsest_under_the_line(score, s.sum(1), tol, floor)
        chosen.append(s[k].copy())
    # backward elimination (_backward_eliminate), every placement still eliminating in one round
    active = [i for i in range(n) if chosen[i].any()]
    while active:
        trials = [_without_one_term(chosen[i]) for i in active]
        owner = np.concatenate([np.full(t.shape[0], i) for i, t in zip(active, trials)])
        _, score_all = refit_and_score(owner, np.concatenate(trials))
        still, offset = [], 0
        for i, s2 in zip(active, trials):
            score = score_all[offset:offset + s2.shape[0]]
            offset += s2.shape[0]
            j = int(np.argmin(score))
            if score[j] <= thresholds[i]:
                chosen[i] = s2[j]
                if chosen[i].any():
                    still.append(i)
        active = still
    return chosen
