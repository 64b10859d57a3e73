"""LASSO by ADMM along a path of lambda values (the paper's Algorithm 1).

For each target y and each lambda:  min_x  1/2 x^T G x - b^T x + lambda ||x||_1   (G = A^T A / n
on unit-RMS columns, b = A^T y / n), i.e. the paper's LASSO with sklearn's 1/(2n) scaling.

ADMM splitting x = z (Boyd et al. 2011, sec. 6.4): x-update solves (G + rho I) x = b + rho (z - u),
z-update soft-thresholds, u accumulates x - z. The m x m system is diagonalised once (G = V D V^T), so
*every* lambda and every target run together as columns of one matrix: x = x0 + M (z - u) with
x0 = (G + rho I)^-1 b and M = rho (G + rho I)^-1, one small matrix product per iteration for the whole
path. Several problems (the inclusion probabilities' 24 held-out placements, identify.trust.uncertainty) run
as one batch (fit_paths), each leaving it at the iteration where it would have stopped alone: the same
paths (tests/identify/test_admm.py). rho = sqrt(d_min d_max) (Ghadimi et al. 2015) and over-relaxation
1.6 make the linear rate depend on sqrt(cond G).

A path point is finished in one of two ways. Polishing (every `polish_every` iterations, _Polisher):
ADMM's z already carries the solution's support and signs long before it meets the tolerance, and with
them the minimiser is one small solve, certified by the LASSO optimality conditions (sufficient, the
problem being convex); such a point is exact to rounding. Otherwise every column's primal and dual
residuals below `tol` (scaled units), tight enough to reproduce a reference solver's support at every
lambda (tests/identify/test_admm.py). On the 24 placements of a million-sample fit, polishing finished
every point by iteration 32 where the tolerance took up to 174, with the same supports and coefficients
within 4e-12 of the largest. Started from the fit's own path (fit_paths(start=...): a placement moves a
few blocks, so its solutions are near the fit's), by iteration 16; the batch's CPU time 0.053 s (tolerance
alone, cold) -> 0.021-0.024 s (polished) -> 0.008-0.012 s (polished, warm), the same supports at every
point (`benchmarks/identify_speed.py --uncertainty-parts` times the batch).
"""
from __future__ import annotations

import numpy as np

from .base import PathOptimizer, SparsePath, distinct_rows


#: Scaled coefficients below this are rounding (unit-RMS columns and target: a real term's coefficient
#: is ~1e-4 or more, ADMM's tolerance 1e-10): at lambda_max the entering term's soft-threshold leaves
#: ~4e-16 where the solution is exactly 0, and a support is "x != 0".
NUMERICAL_ZERO = 1e-14


def soft_threshold(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.sign(x) * np.maximum(np.abs(x) - t, 0.0)


class ADMMLasso(PathOptimizer):
    """n_lambdas log-spaced values from lambda_max (all coefficients zero) down to lambda_max * eps.
    polish_every : iterations between polishing attempts (0: none, the tolerance alone; libraries of
    more than 31 columns are not polished: a column's support and signs are coded in one integer)."""

    param_name = "lambda"

    def __init__(self, n_lambdas: int = 100, eps: float = 1e-5, tol: float = 1e-10, max_iter: int = 50000,
                 relaxation: float = 1.6, polish_every: int = 4):
        self.n_lambdas = n_lambdas
        self.polish_every = polish_every
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

    def fit_paths(self, nes, start: SparsePath | None = None) -> list:
        """fit_path of several normal equations run as one batch (the same iterations as one by one,
        each stopped where it converges on its own: the same paths to rounding).

        start : a path of a neighbouring problem (raw units, the same library and n_lambdas), e.g. the
        fit's own when the problems are its held-out placements: each problem starts from it (z its
        coefficients at the same point of the grid, u the matching dual (b - G z) / rho) instead of 0,
        so the iterates reach the solutions' supports and signs, and polishing certifies them, sooner.
        Where the iterates end does not depend on where they start (a convex problem)."""
        nes = list(nes)
        if not nes:
            return []
        scaled = [self._scaled(ne) for ne in nes]
        z0 = None
        if start is not None:  # (K, m, p) raw -> each problem's scaled units, columns (target, lambda)
            z0 = np.array([(start.coefs * (s[:, None] / ys[None, :])[None]).transpose(1, 2, 0).reshape(s.size, -1)
                           for _, _, (s, ys, _) in scaled])
        coefs, lam, iters = self._paths(np.array([g for g, _, _ in scaled]), np.array([b for _, b, _ in scaled]), z0)
        return [self._unscaled(c, la, it, sc) for c, la, it, (_, _, sc) in zip(coefs, lam, iters, scaled)]

    def _paths(self, G, B, z0=None):
        """Paths of P problems at once: G (P, m, m), B (P, m, p) -> coefs (P, K, m, p), lambdas
        (P, K, p), iterations (P, K, p). Each problem keeps the z of the iteration at which all its
        columns met the tolerance, as a run of its own would stop there. z0 (P, m, p K): starting
        iterates (columns ordered (target, lambda)); None: zero."""
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
        Bcols = np.repeat(B, K, axis=2)                      # (P, m, p K): columns ordered (target, lambda)
        lam_cols = lam.transpose(0, 2, 1).reshape(P, -1)     # (P, p K), the same order
        # x = (G + rho I)^-1 (b + rho (z - u)) = x0 + M (z - u): one small product per iteration
        x0 = V @ (inv[:, :, None] * (VT @ Bcols))
        M = (V * (rho[:, None] * inv)[:, None, :]) @ VT
        thr = (lam_cols / rho[:, None])[:, None, :]
        a = self.relaxation
        if z0 is None:
            z = np.zeros((P, m, p * K))
            u = np.zeros_like(z)
        else:  # the dual that makes z0 a fixed point of the x-update: G z + rho (z - z + u) = b
            z = np.array(z0, dtype=float)
            u = (Bcols - G @ z) / rho[:, None, None]
        iters = np.full((P, p * K), self.max_iter)
        result = np.zeros_like(z)
        run = np.arange(P)                                   # problems still iterating
        active = np.ones((P, p * K), dtype=bool)             # their columns not yet converged
        rho_run = rho[:, None]
        polish = _Polisher(G, Bcols, lam_cols, K)
        polish_every = self.polish_every if m <= _Polisher.MAX_COLUMNS else 0
        certified = np.zeros((P, p * K), dtype=bool)
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
            if polish_every and it % polish_every == 0:
                done |= polish(run, z, active, result, certified)
            newly = active & done
            it_run = iters[run]
            it_run[newly] = it
            iters[run] = it_run
            active &= ~done
            finished = ~active.any(axis=1)
            if finished.any():  # stop there, as a run of its own would, and drop it from the batch
                f = run[finished]
                result[f] = np.where(certified[f][:, None, :], result[f], z[finished])
                keep = ~finished
                run, active, z, u = run[keep], active[keep], z[keep], u[keep]
                x0, M, thr, rho_run = x0[keep], M[keep], thr[keep], rho_run[keep]
                if run.size == 0:
                    break
        result[run] = np.where(certified[run][:, None, :], result[run], z)
        result[np.abs(result) < NUMERICAL_ZERO] = 0.0  # rounding, not a term: supports are x != 0
        coefs = result.reshape(P, m, p, K).transpose(0, 3, 1, 2)  # (P, K, m, p)
        return coefs, lam, iters.reshape(P, p, K).transpose(0, 2, 1)


class _Polisher:
    """Exact LASSO solutions from ADMM's support and signs (active-set polishing, as OSQP polishes).

    At a lambda whose solution has support S and signs s, the LASSO optimality conditions are
    G_SS x_S = b_S - lambda s_S with sign(x_S) = s_S, and |b_j - (G x)_j| <= lambda off S. So once
    ADMM's z carries the right support and signs, one small solve gives the minimiser to rounding, and
    the conditions certify it (a convex problem: they are sufficient), long before the iterates meet
    `tol`. A column whose conditions fail keeps iterating, as before. Columns sharing a problem, a
    target, a support and signs share the solve: x = x_b - lambda x_s for all their lambdas."""

    #: Support and signs of a column are coded in one int64 (2 bits a library column).
    MAX_COLUMNS = 31
    #: Slack on |gradient| <= lambda off the support (scaled units: rounding of b - G x).
    KKT_SLACK = 1e-12

    def __init__(self, G: np.ndarray, Bcols: np.ndarray, lam: np.ndarray, n_lambdas: int):
        self.G, self.Bcols, self.lam = G, Bcols, lam    # (P, m, m), (P, m, C), (P, C)
        self.n_lambdas = n_lambdas
        P, m, C = Bcols.shape
        self.weights = (1 << np.arange(m, dtype=np.int64))
        self.tried = np.full((P, C), -1, dtype=np.int64)  # pattern code last found not optimal

    def __call__(self, run, z, active, result, certified) -> np.ndarray:
        """Certify what can be among the still active columns of the running problems `run` (z: their
        iterates (R, m, C)); writes result and certified for those; returns the (R, C) mask certified now."""
        R, m, C = z.shape
        new = np.zeros((R, C), dtype=bool)
        nz = z != 0
        code = (nz.transpose(0, 2, 1) @ self.weights) + ((z > 0).transpose(0, 2, 1) @ self.weights << m)
        cand = active & (code != self.tried[run])
        if not cand.any():
            return new
        ri, ci = np.nonzero(cand)
        prob = run[ri]
        target = ci // self.n_lambdas                          # columns are ordered (target, lambda)
        first, inv = distinct_rows(np.stack([prob, target, code[ri, ci]], axis=1))
        # one (embedded) solve per pattern: G_SS on S, identity elsewhere; right-hand sides b_S and s_S
        S = nz[ri[first], :, ci[first]]                         # (U, m)
        sign = np.where(z[ri[first], :, ci[first]] > 0, 1.0, -1.0) * S
        Gp = self.G[prob[first]]
        A = np.where(S[:, :, None] & S[:, None, :], Gp, 0.0)
        diag = np.arange(m)
        A[:, diag, diag] = np.where(S, A[:, diag, diag], 1.0)
        b_full = self.Bcols[prob[first], :, ci[first]]
        b = b_full * S
        try:
            sol = np.linalg.solve(A, np.stack([b, sign], axis=2))  # (U, m, 2)
        except np.linalg.LinAlgError:  # an exactly singular G_SS among them: leave these to the tolerance
            self.tried[prob, ci] = code[ri, ci]
            return new
        xb, xs = sol[..., 0] * S, sol[..., 1] * S
        lam = self.lam[prob, ci]
        x = xb[inv] - lam[:, None] * xs[inv]                   # (N, m)
        gb = (b_full - np.einsum("uij,uj->ui", Gp, xb))[inv]
        gs = np.einsum("uij,uj->ui", Gp, xs)[inv]
        grad = gb + lam[:, None] * gs                          # b - G x
        Sc = S[inv]
        ok = np.all(np.where(Sc, np.sign(x) == sign[inv], np.abs(grad) <= lam[:, None] * (1 + self.KKT_SLACK)
                             + self.KKT_SLACK), axis=1)
        self.tried[prob[~ok], ci[~ok]] = code[ri[~ok], ci[~ok]]
        new[ri[ok], ci[ok]] = True
        certified[prob[ok], ci[ok]] = True
        result[prob[ok], :, ci[ok]] = x[ok]
        return new
