"""The measurement chain's bias in closed form: the corrected-score estimator (Stefanski 1989;
Nakamura 1990), used instead of SIMEX's Monte Carlo wherever the library's kept terms are monomials.

The states the library is evaluated on (q1, q2, the input) and the target (q1_dot; q2_dot's is q1
itself) are the true signals plus the chain's image of the sensors' white noise (identify.trust.uncertainty):
a stationary Gaussian noise d, independent of the motion, whose lag-0 covariance Sigma (4 x 4 over
q1, q2, q1_dot, input; units squared) follows exactly from the band's filters and the channels' noise
floors (chain_noise.BandLimitedNoise.covariance). Every entry of the normal equations is a sum over t of a
monomial y_t^k of the noisy signals y = x + d at one time t, so only Sigma enters, not the noise's
correlation over time. For Gaussian d there is a polynomial T_k (the multivariate Hermite / Wick
polynomial of y^k) with E[T_k(x + d) | x] = x^k:

    T_k(y) = y^k - sum_{j < k} C(k, j) E[d^(k - j)] T_j(y)      (C(k, j) = prod_v binom(k_v, j_v)),

the Gaussian moments E[d^m] by Isserlis' theorem. Replacing every sum_t y_t^k of the normal equations
by sum_t T_k(y_t) gives normal equations whose expectation is the noise-free one, so their solution is
consistent (not only to first order in the noise variance, as SIMEX's linear extrapolation). T_k is a
combination of raw moment sums of lower-degree monomials, and those are entries of the full library's
Gram already computed (degree 4 in q1, q2: every monomial up to degree 8; a moment it lacks is summed
from the states), so the correction costs no pass over the record and no random numbers.

Non-monomial terms (sign, |q|, stop, contact) have no such polynomial: the caller falls back to SIMEX.
"""
from __future__ import annotations

from math import comb

import numpy as np

from ..regression.optimizers.base import least_squares

#: The noisy signals a Gram entry is a monomial of, in this order (BandLimitedNoise's order).
SIGNALS = ("q1", "q2", "q1_dot", "input")


def term_exponents(term, input_name: str) -> tuple | None:
    """Exponents of a library term over SIGNALS (the constant: all 0), or None when it is not a
    monomial of them (|q1|, sign(q1), stop(q2), contact(q2), another input)."""
    exps = [0, 0, 0, 0]
    names = {"q1": 0, "q2": 1, input_name: 3}
    for feature, power in term.factors:
        if feature not in names:
            return None
        exps[names[feature]] += power
    return tuple(exps)


class GaussianMoments:
    """E[d^m] (m: exponents over SIGNALS) of zero-mean Gaussian noise of covariance `cov`, by Isserlis'
    recursion E[d_a d^r] = sum_b cov_ab r_b E[d^(r - e_b)], memoised."""

    def __init__(self, cov: np.ndarray):
        self.cov = np.asarray(cov, dtype=float)
        self._memo = {(0,) * len(SIGNALS): 1.0}

    def __call__(self, m: tuple) -> float:
        if m in self._memo:
            return self._memo[m]
        if sum(m) % 2:
            return 0.0
        a = next(i for i, k in enumerate(m) if k)
        r = list(m)
        r[a] -= 1
        total = 0.0
        for b, rb in enumerate(r):
            if rb and self.cov[a, b] != 0.0:
                s = list(r)
                s[b] -= 1
                total += self.cov[a, b] * rb * self(tuple(s))
        self._memo[m] = total
        return total


def _below(k: tuple):
    """Every exponent tuple j <= k componentwise (k itself included)."""
    out = [()]
    for kv in k:
        out = [j + (v,) for j in out for v in range(kv + 1)]
    return out


class CorrectedSums:
    """Corrected moment sums sum_t T_k(y_t) of one recording: raw sums from its Gram (and, for a
    monomial the Gram lacks, from the signals), corrected with its noise covariance."""

    def __init__(self, cov: np.ndarray, raw: dict, signals):
        """raw : {exponents: sum over the fitted rows}; signals : (q1, q2, q1_dot, input) on those rows, or
        a function exponents -> that sum (a record read in chunks: out_of_core.ChunkedEquations.moment_sum),
        summed only for a moment missing from raw."""
        self.mu, self.raw, self._signals, self._poly = GaussianMoments(cov), dict(raw), signals, {}

    def raw_sum(self, k: tuple) -> float:
        if k not in self.raw:
            if callable(self._signals):
                self.raw[k] = float(self._signals(k))
                return self.raw[k]
            y = self._signals
            col = np.ones_like(y[0])
            for v, p in enumerate(k):
                if p:
                    col = col * y[v] ** p
            self.raw[k] = float(col.sum())
        return self.raw[k]

    def polynomial(self, k: tuple) -> dict:
        """T_k as {exponents j: coefficient of y^j}."""
        if k in self._poly:
            return self._poly[k]
        poly = {k: 1.0}
        for j in _below(k):
            diff = tuple(a - b for a, b in zip(k, j))
            if j == k or sum(diff) % 2:
                continue
            mu = self.mu(diff)
            if mu == 0.0:
                continue
            c = mu * np.prod([comb(a, b) for a, b in zip(k, j)])
            for i, ci in self.polynomial(j).items():
                poly[i] = poly.get(i, 0.0) - c * ci
        self._poly[k] = poly
        return poly

    def __call__(self, k: tuple) -> float:
        return float(sum(c * self.raw_sum(j) for j, c in self.polynomial(k).items()))


def gram_moments(C: np.ndarray, exps: list) -> dict:
    """{exponents: raw sum} read off an all-rows Gram C of columns with exponents `exps` (None for a
    column that is not a monomial): entry (i, j) is the sum of the monomial exps_i + exps_j."""
    out = {}
    for i, a in enumerate(exps):
        if a is None:
            continue
        for j in range(i, len(exps)):
            if exps[j] is not None:
                out.setdefault(tuple(x + y for x, y in zip(a, exps[j])), float(C[i, j]))
    return out


def corrected_refits(parts, supports: dict, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) coefficients} from the corrected normal equations of the kept terms.

    parts : one CorrectedSums per recording (their corrected sums add up, as the Grams do);
    col_exps : exponents of the library's columns; target_exps : of each equation's target."""
    out = {}
    for e, sup in supports.items():
        S = np.flatnonzero(sup)
        m = sup.size
        G, B = np.zeros((m, m)), np.zeros(m)
        for a, i in enumerate(S):
            B[i] = sum(p(tuple(x + y for x, y in zip(col_exps[i], target_exps[e]))) for p in parts)
            for j in S[a:]:
                G[i, j] = G[j, i] = sum(p(tuple(x + y for x, y in zip(col_exps[i], col_exps[j]))) for p in parts)
        out[e] = least_squares(G, B, sup)
    return out


def analytic_bias(parts, supports: dict, coefs: dict, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) bias} = the raw all-rows refit (coefs) less the corrected one. Every kept term must
    be a monomial (col_exps not None: uncertainty.analytic_chain_bias checks it before it reads the
    noise floors, and uses SIMEX otherwise)."""
    fixed = corrected_refits(parts, supports, col_exps, target_exps)
    return {e: np.where(supports[e], coefs[e] - fixed[e], 0.0) for e in supports}
