"""The segment-clustered sandwich both shooting-error tests read their standard errors from: a measurement
fault's one parameter (identify.explain.effects.faults.ChannelFault.test) and a masked member's
coefficients (identify.explain.masking.shooting_test).

A fitted value there is an M-estimate, the minimum of a sum over training segments of each one's shooting
error, so its covariance is the sandwich over segments: H^-1 (sum_s g_s g_s') H^-1, g_s the gradient of
segment s's error and H the curvature of the sum. A few segments (the resonance's) carry most of the
curvature, so there are few effective clusters: each segment's contribution is taken as the jackknife's
shift without it, (H - H_s)^-1 g_s (CR3; Cameron and Miller, 2015), its leverage (the largest eigenvalue of
H^-1 H_s) capped at MAX_LEVERAGE (a segment holding all the curvature would otherwise divide by zero). The
Wald statistic over d coefficients is read as F(d, S - 1), S the segments; for d = 1 that is Student's t
with S - 1 degrees of freedom, two-sided. Any common factor of g_s and H (the error as a sum of squares or
half of it, Gauss-Newton or full curvature) cancels.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

#: A segment's leverage (its share of the curvature; largest eigenvalue of H^-1 H_s) above this is taken
#: as this in its CR3 correction.
MAX_LEVERAGE = 0.9


def cr3_covariance(H: np.ndarray, segment_H, segment_grad) -> np.ndarray:
    """(d, d) covariance sum_s shift_s shift_s', shift_s = (H - H_s)^-1 g_s with H_s scaled down to leverage
    MAX_LEVERAGE where it is above. H : (d, d) curvature of the sum, positive definite; segment_H : each
    segment's (d, d) curvature (a full, not Gauss-Newton, one can be negative: a segment whose largest
    leverage is not positive then takes none, H_s = 0); segment_grad : each segment's (d,) gradient."""
    root = np.linalg.cholesky(np.linalg.inv(H))  # leverage: eigenvalues of L' H_s L, L L' = H^-1
    shifts = []
    for Hs, g in zip(segment_H, segment_grad):
        Hs = np.atleast_2d(Hs)
        lev = float(np.max(np.linalg.eigvalsh(root.T @ Hs @ root)))
        Hs = Hs * min(1.0, MAX_LEVERAGE / lev) if lev > 0 else np.zeros_like(Hs)
        shifts.append(np.linalg.solve(H - Hs, np.atleast_1d(g)))
    D = np.array(shifts)
    return D.T @ D


def wald_p(coef: np.ndarray, cov: np.ndarray, n_segments: int) -> float:
    """p of the coefficients `coef` (d,) against zero under `cov` (d, d): W / d against F(d, S - 1), W the
    Wald statistic on the correlation scale; 1 where a variance is not positive or cov is singular."""
    var = np.diag(cov)
    if coef.size == 0 or not np.all(var > 0):
        return 1.0
    theta = coef / np.sqrt(var)
    corr = cov / np.sqrt(np.outer(var, var))
    try:
        w = float(theta @ np.linalg.solve(corr, theta))
    except np.linalg.LinAlgError:
        return 1.0
    return float(stats.f.sf(w / coef.size, coef.size, max(n_segments - 1, 1)))
