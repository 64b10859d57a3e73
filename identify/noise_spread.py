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
(identify.corrected), this is not a Gram quantity: it costs transforms of the record, two per kept term
in the base layout (the integrated signals' contributions are combined in time by running integrals,
_row_spectra), four in the force layout. Against SIMEX's replicate spread (256 replicates, ~6 %
Monte Carlo error) on the Table 1 rig: within 1-7 % at 0.5 % noise, 5-20 % at 5 % (where the
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


def _integrate(x: np.ndarray, dt: float) -> np.ndarray:
    """Trapezoidal running integral along the last axis of rows x (nfft long, periodic once their mean
    is removed; x is overwritten), up to a constant (the band has no DC): on bin k it multiplies by
    dt/2 (1 + z) / (1 - z), z = exp(-2 pi i k / nfft), which is 1/(j w) times (a/2) / tan(a/2),
    a = w dt: 0.986 at 133 Hz and 2048 Hz, 1 - 1e-5 at 2 Hz."""
    x -= x.mean(axis=-1, keepdims=True)
    out = np.cumsum(x, axis=-1)
    out -= 0.5 * x
    out *= dt
    return out


def _transform(x: np.ndarray, nfft: int, kk: int) -> np.ndarray:
    return np.concatenate([lowband_rfft(x[a:a + BATCH], nfft, kk - 1) for a in range(0, x.shape[0], BATCH)])


def _score_spectra(noise, g_of, n: int, n_terms: int) -> np.ndarray:
    """(2, |S|, band bins) sum over the signals v of row i of conj(H_v) times the transform of g_of(v)
    ((|S|, n) rows, or None: v does not move the score). In the base layout with the band above DC the
    signals of one row are combined before the transform: power p < 0 (q1, q2: integrated) by the
    adjoint of p running integrals in time, (-1)^p I^-p, power 0 as it is, and the sum filtered by the
    band gain: g_q1_dot - I(g_q1) + I(I(g_q2)) = g_q1_dot + I(I(g_q2) - g_q1), one transform per row
    and term (2 per term instead of 4). Otherwise each signal by its own transform and exact response."""
    kk, nfft, dt = noise.responses[0].size, noise.nfft, 1.0 / noise.fs_hz
    U = np.zeros((2, n_terms, kk), dtype=complex)
    combine = noise.band[0] > 0 and all(power <= 0 for _, power in noise.requests)
    by_power: dict = {}
    for v, (row, power) in enumerate(noise.requests):
        g = g_of(v)
        if g is None:
            continue
        if combine:
            by_power.setdefault(row, {})[power] = g
        else:
            U[row] += np.conj(noise.responses[v]) * _transform(g, nfft, kk)
    for row, gs in by_power.items():
        x = np.zeros((n_terms, nfft))
        for power in sorted(gs):  # -2, -1, 0: x <- I(x) - g_q1, then I(x) + g_q1_dot
            x[:, :n] += gs[power] if power % 2 == 0 else -gs[power]
            if power < 0:
                x = _integrate(x, dt)
        U[row] += np.conj(noise.gain) * _transform(x, nfft, kk)
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
        for y, noise, (s_in, s_out) in parts:
            n = y[0].size
            mono = _Monomials(y)
            theta = [mono(col_exps[j]) for j in S]
            resid = mono(target_exps[e]) - sum(b * t for b, t in zip(beta, theta))

            def g_of(v):
                """g_v (|S|, n): the score's derivative by signal v; None where it is 0."""
                jac = [mono.derivative(col_exps[j], v) for j in S]
                slope = mono.derivative(target_exps[e], v) - sum(b * d for b, d in zip(beta, jac) if b)
                if all(np.isscalar(d) and d == 0.0 for d in jac) and np.isscalar(slope) and slope == 0.0:
                    return None
                g = np.empty((S.size, n))
                for a, (d, th) in enumerate(zip(jac, theta)):
                    g[a] = th * slope
                    if not (np.isscalar(d) and d == 0.0):
                        g[a] += d * resid
                return g

            U = _score_spectra(noise, g_of, n, S.size)
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
