"""LASSO by ADMM along a path of lambda values (the paper's Algorithm 1).

For each target y and each lambda:  min_x  1/2 x^T G x - b^T x + lambda ||x||_1   (G = A^T A / n
on unit-RMS columns, b = A^T y / n), i.e. the paper's LASSO with sklearn's 1/(2n) scaling.

ADMM splitting x = z (Boyd et al. 2011, sec. 6.4): x-update solves (G + rho I) x = b + rho (z - u),
z-update soft-thresholds, u accumulates x - z. The m x m system is diagonalised once (G = V D V^T), so
*every* lambda and every target run together as columns of one matrix: x = x0 + M (z - u) with
x0 = (G + rho I)^-1 b and M = rho (G + rho I)^-1, one small matrix product per iteration for the whole
path. Several problems (the inclusion probabilities' 24 held-out placements, identify.uncertainty) run
as one batch (fit_paths), each leaving it at the iteration where it would have stopped alone: the same
paths (tests/identify/test_admm.py): the 24 placements of a million-sample fit take 0.048 s of CPU
against 0.17-0.19 s one by one with two products per iteration (benchmarks/identify_speed.py
--uncertainty-parts). rho = sqrt(d_min d_max) (Ghadimi et al. 2015) and over-relaxation
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
        coefs, lam, iters = self._paths(G[None], B[None])
        return coefs[0], lam[0], iters[0]

    def fit_paths(self, nes) -> list:
        """fit_path of several normal equations run as one batch (the same iterations as one by one,
        each stopped where it converges on its own: the same paths to rounding)."""
        nes = list(nes)
        if not nes:
            return []
        scaled = [self._scaled(ne) for ne in nes]
        coefs, lam, iters = self._paths(np.array([g for g, _, _ in scaled]), np.array([b for _, b, _ in scaled]))
        return [self._unscaled(c, la, it, sc) for c, la, it, (_, _, sc) in zip(coefs, lam, iters, scaled)]

    def _paths(self, G, B):
        """Paths of P problems at once: G (P, m, m), B (P, m, p) -> coefs (P, K, m, p), lambdas
        (P, K, p), iterations (P, K, p). Each problem keeps the z of the iteration at which all its
        columns met the tolerance, as a run of its own would stop there."""
        P, m, p = B.shape
        K = self.n_lambdas
        lam = np.array([self.lambdas(b) for b in B])        # (P, K, p)
        d, V = np.linalg.eigh(G)
        d = np.maximum(d, 0.0)
        rho = np.empty(P)
        for i in range(P):
            pos = d[i][d[i] > 1e-12 * d[i].max()] if d[i].max() > 0 else np.array([1.0])
            rho[i] = float(np.sqrt(pos.min() * pos.max()))
        inv = 1.0 / (d + rho[:, None])                       # (P, m)
        VT = V.transpose(0, 2, 1)
        # x = (G + rho I)^-1 (b + rho (z - u)) = x0 + M (z - u): one small product per iteration
        x0 = V @ (inv[:, :, None] * (VT @ np.repeat(B, K, axis=2)))  # columns ordered (target, lambda)
        M = (V * (rho[:, None] * inv)[:, None, :]) @ VT
        thr = (lam.transpose(0, 2, 1).reshape(P, -1) / rho[:, None])[:, None, :]  # matching order
        a = self.relaxation
        z = np.zeros((P, m, p * K))
        u = np.zeros_like(z)
        iters = np.full((P, p * K), self.max_iter)
        result = np.zeros_like(z)
        run = np.arange(P)                                   # problems still iterating
        active = np.ones((P, p * K), dtype=bool)             # their columns not yet converged
        rho_run = rho[:, None]
        for it in range(1, self.max_iter + 1):
            x = x0 + M @ (z - u)
            xh = a * x
            xh += (1 - a) * z
            z_old = z
            xh += u                                          # z = soft_threshold(xh + u, thr) = v - clip(v)
            z = xh - np.clip(xh, -thr, thr)
            u = xh - z                                       # u + xh - z with xh already holding + u
            r = np.max(np.abs(x - z), axis=1)
            sd = rho_run * np.max(np.abs(z - z_old), axis=1)
            done = (r < self.tol) & (sd < self.tol)
            newly = active & done
            it_run = iters[run]
            it_run[newly] = it
            iters[run] = it_run
            active &= ~done
            finished = ~active.any(axis=1)
            if finished.any():  # stop there, as a run of its own would, and drop it from the batch
                result[run[finished]] = z[finished]
                keep = ~finished
                run, active, z, u = run[keep], active[keep], z[keep], u[keep]
                x0, M, thr, rho_run = x0[keep], M[keep], thr[keep], rho_run[keep]
                if run.size == 0:
                    break
        result[run] = z
        coefs = result.reshape(P, m, p, K).transpose(0, 3, 1, 2)  # (P, K, m, p)
        return coefs, lam, iters.reshape(P, p, K).transpose(0, 2, 1)
