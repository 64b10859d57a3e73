"""Shared scaffolding: column scaling and the path container.

Raw library columns differ in magnitude by many orders (q2^4 ~ 1e-8 m^4 next to zdd ~ 10 m/s^2; the
Gram condition number reaches ~1e19). Every optimizer therefore works on columns scaled to unit RMS and
targets scaled to unit RMS, computed on the Gram matrix itself, and maps its coefficients back.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gram import NormalEquations


@dataclass
class SparsePath:
    """coefs: (k, m, p) raw-unit coefficients along the path; params: (k, p) the path parameter
    (lambda for LASSO, threshold for STLSQ), ordered from sparsest to densest; iterations per point."""

    coefs: np.ndarray
    params: np.ndarray
    param_name: str
    iterations: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        return self.coefs.shape[0]


class PathOptimizer:
    """Base class: subclasses implement `_path(G, B)` on scaled normal equations (G has unit diagonal,
    B columns are correlations with unit-RMS targets) and return (coefs (k, m, p), params (k, p), iters)."""

    param_name = "param"

    def fit_path(self, ne: NormalEquations) -> SparsePath:
        G, B, scale = self._scaled(ne)
        return self._unscaled(*self._path(G, B), scale)

    def fit_paths(self, nes, start: SparsePath | None = None) -> list[SparsePath]:
        """fit_path of each of several normal equations (of the same library): one loop here; an
        optimizer that can run them together overrides it (ADMMLasso: the inclusion probabilities' 24
        placements in one batch, started from `start`, the fit's own path; ignored here)."""
        return [self.fit_path(ne) for ne in nes]

    @staticmethod
    def _scaled(ne: NormalEquations):
        """(G, B) on unit-RMS columns and targets, and the scales to map coefficients back."""
        n = max(ne.n, 1)
        col_rms = np.sqrt(np.maximum(np.diag(ne.G), 0) / n)
        y_rms = np.sqrt(np.maximum(ne.yy, 0) / n)
        live = col_rms > 0
        s = np.where(live, col_rms, 1.0)
        ys = np.where(y_rms > 0, y_rms, 1.0)
        G = ne.G / n / np.outer(s, s)
        B = ne.B / n / s[:, None] / ys[None, :]
        G[~live, :] = 0
        G[:, ~live] = 0
        G[~live, ~live] = 1.0  # dead (all-zero) columns: decoupled, and B = 0 keeps them at zero
        B[~live] = 0
        return G, B, (s, ys, live)

    def _unscaled(self, coefs, params, iters, scale) -> SparsePath:
        s, ys, live = scale
        coefs = coefs / s[None, :, None] * ys[None, None, :]
        coefs[:, ~live, :] = 0.0
        return SparsePath(coefs, params, self.param_name, iters)

    def _path(self, G: np.ndarray, B: np.ndarray):  # pragma: no cover - abstract
        raise NotImplementedError


def least_squares(G: np.ndarray, b: np.ndarray, support: np.ndarray) -> np.ndarray:
    """Coefficients minimising ||y - A_S x||^2 from the normal equations, zero off the support.

    Solved on the RMS-scaled subsystem (well conditioned) with lstsq, so a rank-deficient support
    yields the minimum-norm solution instead of garbage.
    """
    x = np.zeros(G.shape[0])
    S = np.flatnonzero(support)
    if S.size == 0:
        return x
    d = np.sqrt(np.maximum(np.diag(G)[S], 1e-300))
    Gs = G[np.ix_(S, S)] / np.outer(d, d)
    x[S] = np.linalg.lstsq(Gs, b[S] / d, rcond=1e-12)[0] / d
    return x


def least_squares_many(G: np.ndarray, b: np.ndarray, supports: np.ndarray) -> np.ndarray:
    """least_squares on each row of `supports` (k, m), as one batch: (k, m) coefficients. G (m, m) and
    b (m,) are shared by every row, or given per row: G (k, m, m), b (k, m) (the inclusion
    probabilities' placements, each with its own training sums, in one batch).

    Each RMS-scaled subsystem is embedded in an m x m system (identity off its support), and all are
    inverted together: well conditioned after scaling, so the inverse's error is the solve's. A row
    whose subsystem is too close to singular for that (its smallest eigenvalue, bounded below by 1 /
    trace of the inverse, not clearly above lstsq's cut-off of 1e-12 x the largest) falls back to
    least_squares' minimum-norm lstsq, so the results are the same to rounding. The selection rule
    refits every distinct support of a path and every backward-elimination trial; one batch replaces a
    loop of small lstsq calls."""
    supports = np.asarray(supports, dtype=bool)
    k, m = supports.shape
    out = np.zeros((k, m))
    if k == 0:
        return out
    per_row = G.ndim == 3
    Gk, bk = (G, b) if per_row else (G[None], b[None])
    d = np.sqrt(np.maximum(np.diagonal(Gk, axis1=1, axis2=2), 1e-300))  # (k, m), or (1, m) shared
    Gs = Gk / (d[:, :, None] * d[:, None, :])
    both = supports[:, :, None] & supports[:, None, :]
    A = np.where(both, Gs, 0.0)
    diag = np.arange(m)
    A[:, diag, diag] = np.where(supports, A[:, diag, diag], 1.0)
    rhs = np.where(supports, bk / d, 0.0)
    n_s = supports.sum(1)
    try:
        inv = np.linalg.inv(A)
        x = np.einsum("kij,kj->ki", inv, rhs)
        trace_inv = np.trace(inv, axis1=1, axis2=2) - (m - n_s)  # of the support's own block
        ok = np.isfinite(x).all(1) & (trace_inv > 0) & (1.0 / np.maximum(trace_inv, 1e-300) > 1e-10 * n_s)
    except np.linalg.LinAlgError:  # an exactly singular subsystem: every row the slow way
        x, ok = np.zeros((k, m)), np.zeros(k, dtype=bool)
    out[ok] = (x * supports / d)[ok]
    for i in np.flatnonzero(~ok):
        out[i] = least_squares(Gk[i if per_row else 0], bk[i if per_row else 0], supports[i])
    return out


def distinct_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of a (k, c): the index of each one's first occurrence (ordered by row value),
    and (k,) which of them each row is. np.unique(axis=0) does the same through a structured-array sort
    that costs ~0.25 ms a call on a path's 100 supports; a lexsort over the columns does not."""
    a = np.asarray(a)
    if a.shape[0] == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(a.shape[0], dtype=bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(a.shape[0], dtype=int)
    inverse[order] = group
    return order[new], inverse
