"""The sensor noise's share of a refit's variance, linearised and computed on the band's bins, without
random draws: what the SIMEX replicates' spread estimated by Monte Carlo (identify.uncertainty).

A refit's shift under a small change d of the signals (q1, q2, q1_dot, input on the fitted rows) is, to
first order, G^-1 sum_t sum_v g_v(t) d_v(t), with

    g_v(t) = dtheta(t)/dy_v r(t) + theta(t) (dtarget(t)/dy_v - sum_j beta_j dtheta_j(t)/dy_v),

theta the kept columns, r the residual and beta the coefficients: the derivative of the score
theta (target - theta . beta). The sensor noise's image d is the band-limited white noise of the raw
channels (chain.BandLimitedNoise): d_v = H_v e_i(v) on the band's bins, e the white response and input
noise of per-sample covariance c. Its variance is therefore exact and needs no draw:

    V = G^-1 [sum_ij c_ij / nfft sum_k w_k Re(U_i(k) U_j(k)^H)] G^-1,   U_i(k) = sum_{v of row i} conj(H_v(k)) Phi_v(k),

Phi_v the transform of G^-1 g_v on the band's bins (identify.spectral.lowband_rfft). The noise is
correlated over time (q2's near the band's bottom for seconds), so, unlike the chain bias
(identify.corrected), this is not a Gram quantity: it costs transforms of the record. Two things keep
them few and short: where a signal's slope and Jacobian are constants (the target's own signal, whose
g_v is theta; a linear input column, -beta theta + r), g_v is a combination of the transforms of theta
and of the residual, made once for all signals (a base-layout fit of the Table 1 model: 16 transforms,
3 per term plus the residual's); and every signal here is band-limited, so a product of them is
transformed on every D-th sample (decimation: exact while its images miss the band; D = 2 for the
degree-5 g_v of the Table 1 model with its band to 133 Hz at 2048 Hz, 8 for the linear q2_dot
equation). Against the formula evaluated term by term at full rate (tests/identify/test_noise_spread.py,
30 s records): 2e-11 without decimation, 1e-7 - 9e-6 with it (the fitted rows' two ends leak); on the
million-sample record of benchmarks/identify_speed.py the variances moved by < 4e-8 and this step's
CPU time went from 0.40 s to 0.13 s (--uncertainty-parts). It had combined the integrated signals in
time by running trapezoidal integrals; now their exact responses (j w)^p multiply on the bins, as the
chain's and the noise draws' do, which moved the variances by < 1e-4 (standard errors < 5e-5; five
sweeps, benchmarks/uncertainty_numbers.py). Against SIMEX's replicate
spread (256 replicates, ~6 % Monte Carlo error) on the Table 1 rig: within 1-7 % at 0.5 % noise, 5-20 % at 5 % (where the
replicates' antithetic halves carry third-order terms too). Why it is worth it: for a weak term the
block estimates of the variance (sandwich, jackknife) are noisy because its information sits in a
few blocks, while this one is not (docs/identification.md section 5). Monomial terms only (their
derivatives are monomials); the caller falls back to SIMEX otherwise.
"""
from __future__ import annotations

import numpy as np

from .gram import scaled_pinv
from .spectral import lowband_rfft

#: Rows transformed together: a padded million-sample record's polyphase buffers stay ~70 MB.
BATCH = 8
#: Largest sampling step of the score's transforms (decimation).
MAX_STEP = 8


class _Monomials:
    """y^k over the fitted rows (k: exponents over q1, q2, q1_dot, input), each computed once; the
    constant is the scalar 1.0."""

    def __init__(self, y):
        self.y, self._cache = y, {}

    def __call__(self, k: tuple):
        if not any(k):
            return 1.0
        if k not in self._cache:
            v = next(i for i, p in enumerate(k) if p)
            lower = list(k)
            lower[v] -= 1
            self._cache[k] = self(tuple(lower)) * self.y[v]
        return self._cache[k]

    def derivative(self, k: tuple, v: int):
        """d y^k / d y_v (0.0 when y_v does not appear)."""
        if not k[v]:
            return 0.0
        lower = list(k)
        lower[v] -= 1
        return k[v] * self(tuple(lower))


def _degree(k) -> int:
    return 0 if k is None else sum(k)


def decimation(noise, degree: int) -> int:
    """Sampling step for the score's transforms: the largest D <= MAX_STEP dividing nfft for which a
    signal made of products of `degree` band-limited factors has, on D-times coarser sampling, no image
    on the band's bins. Every signal the score is built of (q1, q2, q1_dot, input on the fitted rows)
    is the chain's band-limited output, zero above the band's top bin f_top, so a product of `degree`
    of them is zero above degree f_top; sampled every D samples, the band's bin k receives, beside
    itself, the bins at fs/D - f_k and beyond, none of which carry any of it while
    fs/D - f_top >= degree f_top. The transform on nfft/D points (times D) then gives the same bins:
    the only leak is that of the fitted rows' two ends (measured: tests/identify/test_noise_spread.py).
    1 when no D qualifies."""
    kk = noise.responses[0].size
    f_top = (kk - 1) * noise.fs_hz / noise.nfft
    for d in range(MAX_STEP, 1, -1):
        if noise.nfft % d == 0 and noise.fs_hz / d - f_top >= max(degree, 1) * f_top:
            return d
    return 1


def _spectra(rows, nfft: int, kk: int, step: int) -> np.ndarray:
    """(k, kk) rfft on the band's bins of rows (k, n / step) sampled every `step` samples of an
    nfft-point frame: step x the transform on nfft / step points (decimation says when that is exact)."""
    x = np.asarray(rows, dtype=float)
    length = nfft // step
    out = np.concatenate([lowband_rfft(x[a:a + BATCH], length, kk - 1) for a in range(0, x.shape[0], BATCH)])
    if step > 1:
        out *= step
    return out


def _scalar(d) -> bool:
    return np.isscalar(d)


def _score_spectra(noise, theta: list, resid: np.ndarray, slopes_of, n: int, step: int) -> np.ndarray:
    """(2, |S|, band bins) U_i = sum over the signals v of row i of conj(H_v) times the transform of
    g_v = dtheta/dy_v r + theta slope_v (rows of |S| terms). slopes_of(v) -> (jacobians, slope): per-term
    dtheta_a/dy_v and the scalar-or-array slope_v. Where both are constants (the target's own signal:
    g = theta; a linear input column: g = -beta theta + r), g_v is a combination of theta's and r's
    transforms, each computed once for all signals; otherwise g_v is transformed. Exact responses
    H_v = gain (j w)^p (chain.BandLimitedNoise), as the chain and the noise draws have them."""
    kk, nfft = noise.responses[0].size, noise.nfft
    n_terms = len(theta)
    U = np.zeros((2, n_terms, kk), dtype=complex)
    cache: dict = {}

    def theta_spec():
        if "theta" not in cache:
            cache["theta"] = _spectra([np.broadcast_to(t, (n,)) for t in theta], nfft, kk, step)
        return cache["theta"]

    def resid_spec():
        if "resid" not in cache:
            cache["resid"] = _spectra([resid], nfft, kk, step)[0]
        return cache["resid"]

    for v, (row, _) in enumerate(noise.requests):
        jac, slope = slopes_of(v)
        if all(_scalar(d) and d == 0.0 for d in jac) and _scalar(slope) and slope == 0.0:
            continue  # v does not move the score
        if all(_scalar(d) for d in jac) and _scalar(slope):
            F = np.zeros((n_terms, kk), dtype=complex)
            if slope != 0.0:
                F += slope * theta_spec()
            for a, d in enumerate(jac):
                if d != 0.0:
                    F[a] += d * resid_spec()
        else:
            g = np.empty((n_terms, n))
            for a, (d, th) in enumerate(zip(jac, theta)):
                g[a] = th * slope
                if not (_scalar(d) and d == 0.0):
                    g[a] += d * resid
            F = _spectra(g, nfft, kk, step)
            del g
        F *= np.conj(noise.responses[v])
        U[row] += F
    return U


def noise_variance(parts, supports: dict, coefs: dict, G: np.ndarray, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) variance of the refit from the sensor noise, linearised}.

    parts : per recording (signals, noise, (std_in, std_out)): signals the (q1, q2, q1_dot, input) rows
    the Gram was summed over, noise its chain.BandLimitedNoise; G : the all-rows normal matrix (all
    recordings); coefs : {equation: (m,) all-rows coefficients}; col_exps, target_exps : monomial
    exponents of the columns and of each equation's target (identify.corrected)."""
    out = {}
    for e, sup in supports.items():
        S = np.flatnonzero(sup)
        var = np.zeros(sup.size)
        if S.size == 0:
            out[e] = var
            continue
        ginv = scaled_pinv(G[np.ix_(S, S)])
        V = np.zeros((S.size, S.size))
        beta = coefs[e][S]
        # g_v's degree: a column's (theta) plus the residual's less one, or the reverse (dtheta/dy r)
        cols = max(_degree(col_exps[j]) for j in S)
        degree = cols + max(cols, _degree(target_exps[e])) - 1
        for y, noise, (s_in, s_out) in parts:
            step = decimation(noise, degree)
            if step > 1:
                y = tuple(np.ascontiguousarray(s[::step]) for s in y)
            n = y[0].size
            mono = _Monomials(y)
            theta = [mono(col_exps[j]) for j in S]
            resid = mono(target_exps[e]) - sum(b * t for b, t in zip(beta, theta))

            def slopes_of(v):
                """(dtheta_a/dy_v per term, slope_v = dtarget/dy_v - sum_j beta_j dtheta_j/dy_v)."""
                jac = [mono.derivative(col_exps[j], v) for j in S]
                slope = mono.derivative(target_exps[e], v) - sum(b * d for b, d in zip(beta, jac) if b)
                return jac, slope

            U = _score_spectra(noise, theta, resid, slopes_of, n, step)
            U = np.einsum("ab,ibk->iak", ginv, U)  # G^-1 applied on the band's bins, not the rows
            c = noise.white_covariance(s_in, s_out)
            w = noise.bin_weights()
            for i in range(2):
                for j in range(2):
                    if c[i, j]:
                        V += c[i, j] * ((U[i] * w) @ U[j].conj().T).real / noise.nfft
        var[S] = np.maximum(np.diag(V), 0.0)
        out[e] = var
    return out
