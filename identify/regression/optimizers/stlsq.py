"""Sequentially thresholded least squares (Brunton, Proctor & Kutz 2016), the paper's Table 2 method.

Least squares, zero every coefficient below the threshold, refit the rest, repeat until the support
stops changing. With `threshold` given, a single model; otherwise a path of `n_thresholds` values so the
same selection rules apply. `normalize=False` thresholds raw coefficients as the paper did (lambda=0.95,
Table 2); the default thresholds coefficients of unit-RMS columns, which is scale-invariant.
"""
from __future__ import annotations

import numpy as np

from .base import PathOptimizer, SparsePath, least_squares


class STLSQ(PathOptimizer):
    param_name = "threshold"

    def __init__(self, threshold: float | None = None, n_thresholds: int = 100, eps: float = 1e-5,
                 normalize: bool = True, max_iter: int = 50):
        self.threshold = threshold
        self.n_thresholds = n_thresholds
        self.eps = eps
        self.normalize = normalize
        self.max_iter = max_iter

    def fit_path(self, ne):
        if self.normalize:
            return super().fit_path(ne)
        # raw coefficients: run on the unscaled system, thresholds in the coefficients' own units
        coefs, params, iters = self._path(ne.G, ne.B)
        return SparsePath(coefs, params, self.param_name, iters)

    def _solve(self, G, b, thr):
        support = np.ones(G.shape[0], dtype=bool)
        x = least_squares(G, b, support)
        for it in range(1, self.max_iter + 1):
            new = np.abs(x) >= thr
            if np.array_equal(new, support):
                return x, it
            support = new
            x = least_squares(G, b, support)
        return x, self.max_iter

    def _path(self, G, B):
        m, p = B.shape
        if self.threshold is not None:
            thr = np.full((1, p), float(self.threshold))
        else:
            top = np.array([np.max(np.abs(least_squares(G, B[:, e], np.ones(m, bool)))) for e in range(p)])
            thr = np.logspace(0, np.log10(self.eps), self.n_thresholds)[:, None] * top[None, :] * 1.0001
        coefs = np.zeros((thr.shape[0], m, p))
        iters = np.zeros(thr.shape, dtype=int)
        for k in range(thr.shape[0]):
            for e in range(p):
                coefs[k, :, e], iters[k, e] = self._solve(G, B[:, e], thr[k, e])
        return coefs, thr, iters
