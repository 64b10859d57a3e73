"""LASSO by ADMM along a path of lambda values (the paper's Algorithm 1).

For each target y and each lambda:  min_x  1/2 x^T G x - b^T x + lambda ||x||_1   (G = A^T A / n
on unit-RMS columns, b = A^T y / n), i.e. the paper's LASSO with sklearn's 1/(2n) scaling.

ADMM splitting x = z (Boyd et al. 2011, sec. 6.4): x-update solves (G + rho I) x = b + rho (z - u),
z-update soft-thresholds, u accumulates x - z. The m x m system is diagonalised once (G = V D V^T), so
*every* lambda and every target run together as columns of one matrix: one iteration is two small
matrix products for the whole path. rho = sqrt(d_min d_max) (Ghadimi et al. 2015) and over-relaxation
1.6 make the linear rate depend on sqrt(cond G). Stops when every column's primal and dual residuals are
below `tol` (scaled units), tight enough to reproduce a reference solver's support at every lambda
(tests/identify/test_admm.py).
"""
from __future__ import annotations

import numpy as np

from .base import PathOptimizer


def soft_threshold(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.sign(x) * np.maximum(np.abs(x) - t, 0.0)


class ADMMLasso(PathOptimizer):
    """n_lambdas log-spaced values from lambda_max (all coefficients zero) down to lambda_max * eps."""

    param_name = "lambda"

    def __init__(self, n_lambdas: int = 100, eps: float = 1e-5, tol: float = 1e-10, max_iter: int = 50000,
                 relaxation: float = 1.6):
        self.n_lambdas = n_lambdas
        self.eps = eps
        self.tol = tol
        self.max_iter = max_iter
        self.relaxation = relaxation

    def lambdas(self, B: np.ndarray) -> np.ndarray:
        lam_max = np.max(np.abs(B), axis=0)
        ratios = np.logspace(0, np.log10(self.eps), self.n_lambdas)
        return ratios[:, None] * lam_max[None, :]

    def _path(self, G, B):
        m, p = B.shape
        K = self.n_lambdas
        lam = self.lambdas(B)                       # (K, p)
        d, V = np.linalg.eigh(G)
        d = np.maximum(d, 0.0)
        pos = d[d > 1e-12 * d.max()] if d.max() > 0 else np.array([1.0])
        rho = float(np.sqrt(pos.min() * pos.max()))
        inv = 1.0 / (d + rho)
        Vb = V.T @ np.repeat(B, K, axis=1)          # columns ordered (target, lambda)
        thr = (lam.T.reshape(-1) / rho)[None, :]    # matching order
        a = self.relaxation
        z = np.zeros((m, p * K))
        u = np.zeros_like(z)
        iters = np.zeros(p * K, dtype=int)
        active = np.ones(p * K, dtype=bool)
        for it in range(1, self.max_iter + 1):
            x = V @ (inv[:, None] * (Vb + rho * (V.T @ (z - u))))
            xh = a * x + (1 - a) * z
            z_old = z
            z = soft_threshold(xh + u, thr)
            u = u + xh - z
            r = np.max(np.abs(x - z), axis=0)
            s = rho * np.max(np.abs(z - z_old), axis=0)
            done = (r < self.tol) & (s < self.tol)
            iters[active & done] = it
            active &= ~done
            if not active.any():
                break
        iters[active] = self.max_iter
        coefs = z.reshape(m, p, K).transpose(2, 0, 1)  # (K, m, p)
        return coefs, lam, iters.reshape(p, K).T
