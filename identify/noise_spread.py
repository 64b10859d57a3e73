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

Phi_v the transform of g_v on the band's bins (identify.spectral.lowband_rfft; G^-1 is applied once, to
the |S| x |S| sum). The noise is correlated over time (q2's near the band's bottom for seconds), so,
unlike the chain bias (identify.corrected), this is not a Gram quantity: it costs transforms of the
record, kept few and short in two ways. Where a signal's slope and Jacobian are constants (the target's
own signal, whose g_v is theta; a linear input column, -beta theta + r), g_v is a combination of the
transforms of theta and of the residual, each made once (the Table 1 model, base layout: 16 transforms,
3 per term plus the residual's). And every signal here is the chain's band-limited output, so a product
of them is transformed on every D-th sample, D by its degree (decimation: exact while its images miss
the band; at 2048 Hz with the band to 133 Hz, D = 2 for degree 5, the cubic terms' g_v, 3 for degree 3,
6 for a linear column; a constant column, only its ends on the band, is the boxcar in closed form).
Against the formula evaluated term by term at full rate (tests/identify/test_noise_spread.py, 30 s
records): 2e-11 without decimation, 5e-6 - 1.6e-5 with it (the fitted rows' two ends leak). It had
combined the integrated signals in time by running trapezoidal integrals (one transform per signal row
and term); the exact responses (j w)^p now multiply on the bins, as the chain's and the noise draws' do
(the variances moved by < 1e-4). A million-sample fit spends ~0.1 s here, a third of what it did
(docs/identification.md section 5). Against SIMEX's replicate spread (256 replicates, ~6 % Monte Carlo
error) on the Table 1 rig: within 1-7 % at 0.5 % noise, 5-20 % at 5 % (where the replicates' antithetic
halves carry third-order terms too). Why it is worth it: for a weak term the block estimates of the
variance (sandwich, jackknife) are noisy because its information sits in a few blocks, while this one is
not (docs/identification.md section 5). Monomial terms only (their derivatives are monomials); the caller
falls back to SIMEX otherwise.
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


def _derivative_degree(k: tuple, v: int):
    """Degree of d y^k / d y_v (None: it is 0)."""
    return sum(k) - 1 if k[v] else None


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


def boxcar_spectrum(n: int, nfft: int, kk: int) -> np.ndarray:
    """rfft(ones(n), nfft)[:kk] in closed form, (1 - z^n) / (1 - z) with z = exp(-2 pi i k / nfft) (n at
    DC): a constant column is no band-limited signal (its ends are all it has on the band), so it is
    neither decimated nor transformed."""
    k = np.arange(kk)
    z = np.exp(-2j * np.pi * k / nfft)
    zn = np.exp(-2j * np.pi * ((k * n) % nfft) / nfft)
    out = np.empty(kk, dtype=complex)
    out[0] = n
    out[1:] = (1 - zn[1:]) / (1 - z[1:])
    return out


class _Score:
    """The score's pieces for one equation and recording, each at the sampling step its degree allows:
    theta (kept columns) and the residual r on the fitted rows, their transforms on the band's bins
    (each made once), and the Jacobians and slopes of the signals."""

    def __init__(self, y, noise, cols: list, target: tuple, beta: np.ndarray):
        self.y, self.noise, self.cols, self.target, self.beta = y, noise, cols, target, beta
        self.kk, self.nfft = noise.responses[0].size, noise.nfft
        self.r_degree = max([_degree(k) for k in cols] + [_degree(target)])
        self._mono, self._resid, self._theta_spec, self._resid_spec = {}, {}, {}, None

    def mono(self, step: int) -> _Monomials:
        if step not in self._mono:
            y = self.y if step == 1 else tuple(np.ascontiguousarray(s[::step]) for s in self.y)
            self._mono[step] = _Monomials(y)
        return self._mono[step]

    def resid(self, step: int) -> np.ndarray:
        if step not in self._resid:
            mono = self.mono(step)
            self._resid[step] = mono(self.target) - sum(b * mono(k) for b, k in zip(self.beta, self.cols))
        return self._resid[step]

    def theta_spec(self, a: int) -> np.ndarray:
        """Transform of kept column a on the band's bins (all columns of its step made together)."""
        if a not in self._theta_spec:
            n = self.y[0].size
            by_step: dict = {}
            for b, k in enumerate(self.cols):
                if not any(k):
                    self._theta_spec[b] = boxcar_spectrum(n, self.nfft, self.kk)
                else:
                    by_step.setdefault(decimation(self.noise, _degree(k)), []).append(b)
            for step, idx in by_step.items():
                mono = self.mono(step)
                for b, spec in zip(idx, _spectra([mono(self.cols[b]) for b in idx], self.nfft, self.kk, step)):
                    self._theta_spec[b] = spec
        return self._theta_spec[a]

    def resid_spec(self) -> np.ndarray:
        if self._resid_spec is None:
            step = decimation(self.noise, self.r_degree)
            self._resid_spec = _spectra([self.resid(step)], self.nfft, self.kk, step)[0]
        return self._resid_spec

    def slopes(self, v: int, step: int):
        """(dtheta_a/dy_v per term, slope_v = dtarget/dy_v - sum_j beta_j dtheta_j/dy_v), on rows of `step`."""
        mono = self.mono(step)
        jac = [mono.derivative(k, v) for k in self.cols]
        slope = mono.derivative(self.target, v) - sum(b * d for b, d in zip(self.beta, jac) if b)
        return jac, slope

    def spectra(self, v: int) -> np.ndarray | None:
        """(|S|, kk) transform of g_v = dtheta/dy_v r + theta slope_v per term; None where v does not move
        the score. Constant slope and Jacobians (the target's own signal: g = theta; a linear input
        column: -beta theta + r) combine theta's and r's transforms; otherwise each term's g_v is
        transformed at the step of its degree (theta's plus the slope's, or the Jacobian's plus r's)."""
        jac_deg = [_derivative_degree(k, v) for k in self.cols]
        slope_terms = [_derivative_degree(self.target, v)] + [_derivative_degree(k, v)
                                                              for k, b in zip(self.cols, self.beta) if b]
        slope_deg = max((d for d in slope_terms if d is not None), default=None)
        if slope_deg is None and all(d is None for d in jac_deg):
            return None
        n_terms = len(self.cols)
        F = np.zeros((n_terms, self.kk), dtype=complex)
        if (slope_deg is None or slope_deg == 0) and all(d is None or d == 0 for d in jac_deg):
            jac, slope = self.slopes(v, 1)  # constants: the same on every step
            for a, d in enumerate(jac):
                if slope != 0.0:
                    F[a] += slope * self.theta_spec(a)
                if d != 0.0:
                    F[a] += d * self.resid_spec()
            return F
        by_step: dict = {}
        for a, k in enumerate(self.cols):
            deg = max(_degree(k) + (slope_deg if slope_deg is not None else -1),
                      jac_deg[a] + self.r_degree if jac_deg[a] is not None else -1)
            by_step.setdefault(decimation(self.noise, deg), []).append(a)
        for step, idx in by_step.items():
            mono = self.mono(step)
            jac, slope = self.slopes(v, step)
            resid, n = self.resid(step), mono.y[0].size
            g = np.empty((len(idx), n))
            for row, a in enumerate(idx):
                g[row] = mono(self.cols[a]) * slope
                if not (np.isscalar(jac[a]) and jac[a] == 0.0):
                    g[row] += jac[a] * resid
            F[idx] = _spectra(g, self.nfft, self.kk, step)
        return F


def noise_variance(parts, supports: dict, coefs: dict, G: np.ndarray, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) variance of the refit from the sensor noise, linearised}.

    parts : per recording (signals, noise, (std_in, std_out)): signals the (q1, q2, q1_dot, input) rows
    the Gram was summed over, noise its chain.BandLimitedNoise; G : the all-rows normal matrix (all
    recordings); coefs : {equation: (m,) all-rows coefficients}; col_exps, target_exps : monomial
    exponents of the columns and of each equation's target (identify.corrected). Exact responses
    H_v = gain (j w)^p on the bins (chain.BandLimitedNoise), as the chain and the noise draws have them."""
    out = {}
    for e, sup in supports.items():
        S = np.flatnonzero(sup)
        var = np.zeros(sup.size)
        if S.size == 0:
            out[e] = var
            continue
        ginv = scaled_pinv(G[np.ix_(S, S)])
        V = np.zeros((S.size, S.size))
        for y, noise, (s_in, s_out) in parts:
            score = _Score(y, noise, [col_exps[j] for j in S], target_exps[e], coefs[e][S])
            U = np.zeros((2, S.size, noise.responses[0].size), dtype=complex)
            for v, (row, _) in enumerate(noise.requests):
                F = score.spectra(v)
                if F is not None:
                    F *= np.conj(noise.responses[v])
                    U[row] += F
            # sum_ij c_ij / nfft sum_k w_k Re(U_i U_j^H): every (i, j) block of one (2|S|, 2|S|) product
            U = U.reshape(2 * S.size, -1)
            P = ((U * noise.bin_weights()) @ U.conj().T).real.reshape(2, S.size, 2, S.size)
            c = noise.white_covariance(s_in, s_out)
            V += np.einsum("ij,iajb->ab", c, P) / noise.nfft
        V = ginv @ V @ ginv  # G^-1 applied once to the |S| x |S| sum, not to every bin
        var[S] = np.maximum(np.diag(V), 0.0)
        out[e] = var
    return out
