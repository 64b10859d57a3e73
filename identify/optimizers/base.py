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

    def fit_paths(self, nes) -> list[SparsePath]:
        """fit_path of each of several normal equations (of the same library): one loop here; an
        optimizer that can run them together overrides it (ADMMLasso: the inclusion probabilities' 24
        placements in one batch)."""
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
