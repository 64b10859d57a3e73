"""The sensor noise's share of a refit's variance, linearised and computed on the band's bins, without
random draws: what the SIMEX replicates' spread estimated by Monte Carlo (identify.trust.uncertainty).

A refit's shift under a small change d of the signals (q1, q2, q1_dot, input on the fitted rows) is, to
first order, G^-1 sum_t sum_v g_v(t) d_v(t), with

    g_v(t) = dtheta(t)/dy_v r(t) + theta(t) (dtarget(t)/dy_v - sum_j beta_j dtheta_j(t)/dy_v),

theta the kept columns, r the residual and beta the coefficients: the derivative of the score
theta (target - theta . beta). The sensor noise's image d is the band-limited white noise of the raw
channels (chain_noise.BandLimitedNoise): d_v = H_v e_i(v) on the band's bins, e the white response and input
noise of per-sample covariance c. Its variance is therefore exact and needs no draw:

    V = G^-1 [sum_ij c_ij / nfft sum_k w_k Re(U_i(k) U_j(k)^H)] G^-1,   U_i(k) = sum_{v of row i} conj(H_v(k)) Phi_v(k),

Phi_v the transform of g_v on the band's bins (identify.chain.spectral.polyphase_rfft; G^-1 is applied once, to
the |S| x |S| sum). The noise is correlated over time (q2's near the band's bottom for seconds), so,
unlike the chain bias (identify.chain.bias_correction), this is not a Gram quantity: it costs transforms of the
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
(the variances moved by < 1e-4). Each row is a polynomial of the signals, evaluated by a compiled loop
(identify/_polyrows.c) straight into the transform's buffer, each sample's monomials made once per
batch: a million-sample fit spends 0.054-0.055 s CPU here, about half of it in pocketfft, against
0.062-0.063 s when numpy made the rows in whole-array passes from signals first copied into the
polyphase order (benchmarks/identify_speed.py --sizes 1000000 --repeat 4 --no-simulation
--uncertainty-parts, "the noise's share of the variance", two rounds each, alternating, 2026-11-24;
0.062-0.069 s in double precision (DTYPE) in the first rounds; 0.100-0.122 s before the rows were built
in the transforms' polyphase order and batched across signals and equations). Against SIMEX's replicate
spread (256 replicates, ~6 % Monte Carlo error) on the Table 1 rig: within 1-7 % at 0.5 % noise, 5-20 %
at 5 % (where the replicates' antithetic halves carry third-order terms too). Why it is worth it: for a
weak term the block estimates of the
variance (sandwich, jackknife) are noisy because its information sits in a few blocks, while this one is
not (docs/identification.md section 5). Monomial terms only (their derivatives are monomials); the caller
falls back to SIMEX otherwise.
"""
from __future__ import annotations

import numpy as np

from .. import _polyrows
from ..chain.bias_correction import SIGNALS
from ..regression.gram import scaled_pinv
from ..chain.spectral import polyphase_factor, polyphase_rfft

#: Rows transformed together, times the step (a row at step D is D times shorter): a padded
#: million-sample record's polyphase buffer stays ~35 MB (single precision, DTYPE; one for all batches).
BATCH = 8
#: Largest sampling step of the score's transforms (decimation).
MAX_STEP = 8
#: Precision of the score's rows (their evaluation too, identify/_polyrows.c) and their transforms. A
#: variance that sets a standard error needs a few digits; single precision moves it by a few 1e-7 of
#: itself at most (against double: 5e-8 and 1.2e-7 on the 30 s records of
#: tests/identify/test_noise_spread.py at 0.5 and 5 % noise, 2.0e-7 on the million samples of
#: benchmarks/identify_speed.py; 3e-8, 1.2e-7 and 5e-8 when numpy made the rows from single-precision
#: copies of the signals), and halves the memory the rows are built in and the time pocketfft takes on
#: them. The sums over the band's bins (U, and the product that squares it) and the filters H_v are in
#: double precision (H_v in single moved the variances by 5e-9 only, and saved no measurable time: kept
#: double, with no cast).
DTYPE = np.float32


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


def _poly_add(p: dict, q: dict, scale: float = 1.0) -> dict:
    """p + scale q, polynomials as {exponents: coefficient} over corrected.SIGNALS (q1, q2, q1_dot, input)."""
    out = dict(p)
    for k, c in q.items():
        out[k] = out.get(k, 0.0) + scale * c
    return out


def _poly_mul(p: dict, q: dict) -> dict:
    out: dict = {}
    for kp, cp in p.items():
        for kq, cq in q.items():
            k = tuple(x + y for x, y in zip(kp, kq))
            out[k] = out.get(k, 0.0) + cp * cq
    return out


def _poly_derivative(k: tuple, v: int) -> dict:
    """d y^k / d y_v: {k - e_v: k_v}, or {} where y_v does not appear."""
    if not k[v]:
        return {}
    lower = list(k)
    lower[v] -= 1
    return {tuple(lower): float(k[v])}


def _lower(k: tuple) -> tuple[tuple, int]:
    """The monomial y^k is made from: (k less one power of its first signal, that signal)."""
    v = next(i for i, e in enumerate(k) if e)
    return tuple(e - (i == v) for i, e in enumerate(k)), v


def packed_rows(polys: list) -> tuple:
    """The polynomials as identify._polyrows.poly_rows reads them: (parent, var, row_ptr, mono, coef).
    Every monomial they use, with the ones it is made from down to the constant, is listed once by degree:
    monomial i = monomial parent[i] times signal var[i], parent[i] < i, monomial 0 the constant; row r
    is sum over k in [row_ptr[r], row_ptr[r + 1]) of coef[k] times monomial mono[k]."""
    table, todo = {(0,) * len(SIGNALS)}, [k for p in polys for k in p]
    while todo:
        k = todo.pop()
        if k not in table:
            table.add(k)
            todo.append(_lower(k)[0])
    order = sorted(table, key=lambda k: (sum(k), k))
    index = {k: i for i, k in enumerate(order)}
    parent, var = np.zeros(len(order), dtype=np.int32), np.zeros(len(order), dtype=np.int32)
    for i, k in enumerate(order[1:], start=1):
        lower, var[i] = _lower(k)
        parent[i] = index[lower]
    ptr = np.cumsum([0] + [len(p) for p in polys]).astype(np.int32)
    mono = np.array([index[k] for p in polys for k in p], dtype=np.int32)
    coef = np.array([c for p in polys for c in p.values()], dtype=np.float64)
    return parent, var, ptr, mono, coef


class _Score:
    """The transforms of one equation's score derivatives g_v on one recording's band bins: theta (kept
    columns) and the residual r where a signal's slope and Jacobians are constants (combined on the bins),
    g_v term by term otherwise, each at the step its degree allows. Each row is a polynomial of the
    signals (row) evaluated straight into the transform's buffer (_transform batches the rows of every
    equation by step: q1's and q2's g rows of a cubic model share their steps)."""

    def __init__(self, n: int, noise, cols: list, target: tuple, beta: np.ndarray):
        """n : the recording's fitted rows. Leaves in self.jobs the rows to transform, {step: [job]}
        (_transform makes them; ("theta", a), ("resid",) or (v, a): g_v of term a)."""
        self.noise, self.cols, self.target, self.beta = noise, cols, target, beta
        self.kk, self.nfft = noise.responses[0].size, noise.nfft
        self.r_degree = max([_degree(k) for k in cols] + [_degree(target)])
        self.spec = {}
        self.plans = [self._plan(v) for v in range(len(noise.requests))]
        jobs: dict = {}
        for v, plan in enumerate(self.plans):
            if isinstance(plan, tuple):  # constants: theta's and r's transforms, combined on the bins
                jac, slope = plan
                for a, k in enumerate(cols if slope != 0.0 else ()):
                    if any(k):
                        jobs.setdefault(decimation(noise, _degree(k)), []).append(("theta", a))
                    else:
                        self.spec[("theta", a)] = boxcar_spectrum(n, self.nfft, self.kk)
                if any(d != 0.0 for d in jac):
                    jobs.setdefault(decimation(noise, self.r_degree), []).append(("resid",))
            elif plan is not None:
                for a, step in plan.items():
                    jobs.setdefault(step, []).append((v, a))
        # theta and r once, however many signals combine them
        self.jobs = {step: list(dict.fromkeys(todo)) for step, todo in jobs.items()}

    def _plan(self, v: int):
        """None where v does not move the score; (Jacobians, slope) as numbers where they are constants
        (the target's own signal: g = theta; a linear input column: -beta theta + r); else {term: step},
        the step of g_v's degree per term (theta's plus the slope's, or the Jacobian's plus r's)."""
        jac_deg = [_derivative_degree(k, v) for k in self.cols]
        slope_terms = [_derivative_degree(self.target, v)] + [_derivative_degree(k, v)
                                                              for k, b in zip(self.cols, self.beta) if b]
        slope_deg = max((d for d in slope_terms if d is not None), default=None)
        if slope_deg is None and all(d is None for d in jac_deg):
            return None
        if (slope_deg is None or slope_deg == 0) and all(d is None or d == 0 for d in jac_deg):
            jac = [float(k[v]) for k in self.cols]  # degree 0: k_v y^0
            return jac, float(self.target[v]) - sum(b * d for b, d in zip(self.beta, jac) if b)
        return {a: decimation(self.noise, max(_degree(k) + (slope_deg if slope_deg is not None else -1),
                                              jac_deg[a] + self.r_degree if jac_deg[a] is not None else -1))
                for a, k in enumerate(self.cols)}

    def row(self, job: tuple) -> dict:
        """Row `job` as a polynomial of the signals: ("theta", a) the kept column a; ("resid",) the residual
        r = target - theta . beta; (v, a) g_v of term a = theta_a slope_v + dtheta_a/dy_v r, with
        slope_v = dtarget/dy_v - sum_j beta_j dtheta_j/dy_v."""
        if job[0] == "theta":
            return {self.cols[job[1]]: 1.0}
        resid = {self.target: 1.0}
        for b, k in zip(self.beta, self.cols):
            if b:
                resid = _poly_add(resid, {k: 1.0}, -float(b))
        if job[0] == "resid":
            return resid
        v, a = job
        slope = _poly_derivative(self.target, v)
        for b, k in zip(self.beta, self.cols):
            if b:
                slope = _poly_add(slope, _poly_derivative(k, v), -float(b))
        return _poly_add(_poly_mul({self.cols[a]: 1.0}, slope), _poly_mul(_poly_derivative(self.cols[a], v), resid))

    def accumulate(self, U: np.ndarray):
        """U[row of v] += conj(H_v) Phi_v for every signal v, Phi_v the (|S|, kk) transform of
        g_v = dtheta/dy_v r + theta slope_v per term; U (2, |S|, kk), in double precision, the transforms
        in DTYPE's: multiplied term by term, with no (|S|, kk) copy per signal."""
        for v, (row, _) in enumerate(self.noise.requests):
            plan, h = self.plans[v], np.conj(self.noise.responses[v])
            if isinstance(plan, tuple):  # constants: combined from theta's and r's transforms
                jac, slope = plan
                for a, d in enumerate(jac):
                    terms = ([slope * self.spec[("theta", a)]] if slope != 0.0 else []) + \
                            ([d * self.spec[("resid",)]] if d != 0.0 else [])
                    if terms:
                        phi = terms[0] if len(terms) == 1 else np.add(*terms, out=terms[0])
                        U[row, a] += phi * h  # widened to double by h
            elif plan is not None:
                for a in plan:
                    U[row, a] += self.spec.pop((v, a)) * h


def _transform(scores, y, noise):
    """Every score's rows (_Score.jobs) of one recording, transformed on the band's bins: the rows of one
    step, all equations', evaluated together (identify._polyrows: a sample's monomials made once per batch,
    written in the polyphase order of the step's transform) and transformed together, BATCH x step at a
    time (a buffer as large as BATCH rows at full rate). Batches matter: pocketfft transforms several
    rows at once with vector instructions (24 rows of 180,000 points: 23 ms in one call, 33 ms in 24
    calls, scipy 1.17 on this machine). y : the recording's (q1, q2, q1_dot, input) on the fitted rows."""
    y = tuple(np.ascontiguousarray(x, dtype=np.float64) for x in y)
    n, kk = y[0].size, noise.responses[0].size
    by_step: dict = {}
    for score in scores:
        for step, jobs in score.jobs.items():
            by_step.setdefault(step, []).extend((score, job) for job in jobs)
    chunks = [(step, todo[first:first + BATCH * step]) for step, todo in by_step.items()
              for first in range(0, len(todo), BATCH * step)]
    # one buffer for every chunk's rows, touched once (a new one per chunk paid its pages each time:
    # 0.6 ms more for the 13 MB of a million-sample record's step-3 rows)
    scratch = np.empty(max((len(chunk) * (noise.nfft // step) for step, chunk in chunks), default=0), dtype=DTYPE)
    for step, chunk in chunks:
        length = noise.nfft // step
        m = polyphase_factor(length, kk - 1)
        width = -(-len(range(0, n, step)) // m)
        buf = scratch[:len(chunk) * length].reshape(len(chunk), m, length // m)
        _polyrows.poly_rows(y, n, step, m, width, *packed_rows([score.row(job) for score, job in chunk]), buf)
        spec = polyphase_rfft(buf, length, kk - 1)
        if step > 1:
            spec *= step
        for (score, job), row in zip(chunk, spec):
            score.spec[job] = row


def noise_variance(parts, supports: dict, coefs: dict, G: np.ndarray, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) variance of the refit from the sensor noise, linearised}.

    parts : per recording (signals, noise, (std_in, std_out)): signals the (q1, q2, q1_dot, input) rows
    the Gram was summed over, noise its chain_noise.BandLimitedNoise; or, for a record read in chunks,
    per chunk (signals, noise, floors, core): the chunk's rows with an overlap on each side, the noise
    on that stretch, and the slice of the chunk's own rows in it (any iterable: consumed once); G : the all-rows normal matrix (all
    recordings); coefs : {equation: (m,) all-rows coefficients}; col_exps, target_exps : monomial
    exponents of the columns and of each equation's target (identify.chain.bias_correction). Exact responses
    H_v = gain (j w)^p on the bins (chain_noise.BandLimitedNoise), as the chain and the noise draws have them."""
    # an equation whose one kept column is its own target (q2_dot = q1: the chain's q1 is the derivative
    # of its q2) fits it exactly, coefficient 1 and residual 0 to rounding: its score does not move (0)
    kept = {e: np.flatnonzero(sup) for e, sup in supports.items()
            if sup.any() and not (sup.sum() == 1 and col_exps[np.flatnonzero(sup)[0]] == target_exps[e])}
    V = {e: np.zeros((S.size, S.size)) for e, S in kept.items()}

    def sums(y, noise) -> dict:
        """{equation: (2, |S|, kk) U} of rows y on noise's bins."""
        scores = {e: _Score(y[0].size, noise, [col_exps[j] for j in S], target_exps[e], coefs[e][S])
                  for e, S in kept.items()}
        _transform(scores.values(), y, noise)
        out = {}
        for e, score in scores.items():
            out[e] = np.zeros((2, kept[e].size, noise.responses[0].size), dtype=complex)
            score.accumulate(out[e])
        return out

    for part in parts:
        y, noise, (s_in, s_out) = part[:3]
        U_all = sums(y, noise)
        U_core = U_all
        if len(part) > 3:
            # a stretch of a record read in chunks (identify.out_of_core): the rows `core` of y, paired with
            # all of y (core and its overlap on each side), so the sum over chunks pairs every row with the
            # rows within the overlap of it, as the whole record's transform does up to the noise's
            # correlation beyond the overlap; the core's transform is shifted to y's time origin
            core = part[3]
            U_core = sums(tuple(x[core] for x in y), noise)
            shift = np.exp(-2j * np.pi * np.arange(noise.responses[0].size) * core.start / noise.nfft)
            for U in U_core.values():
                U *= shift
        c, w = noise.white_covariance(s_in, s_out), noise.bin_weights()
        for e in kept:
            # sum_ij c_ij / nfft sum_k w_k Re(U_i U_j^H): every (i, j) block of one (2|S|, 2|S|) product, in
            # real arithmetic (Re(a conj b) = a_re b_re + a_im b_im: U's real view), with w_k = 2 on every
            # bin and the few bins of another weight (DC, Nyquist) corrected after: no weighted copy of U
            Ur = U_all[e].reshape(2 * kept[e].size, -1).view(float)
            Uc = Ur if U_core is U_all else U_core[e].reshape(2 * kept[e].size, -1).view(float)
            P = 2.0 * (Uc @ Ur.T)
            for k in np.flatnonzero(w != 2.0):
                P += (w[k] - 2.0) * (Uc[:, 2 * k:2 * k + 2] @ Ur[:, 2 * k:2 * k + 2].T)
            if Uc is not Ur:
                P = 0.5 * (P + P.T)
            P = P.reshape(2, kept[e].size, 2, kept[e].size)
            V[e] += np.einsum("ij,iajb->ab", c, P) / noise.nfft
    out = {}
    for e, sup in supports.items():
        out[e] = np.zeros(sup.size)
        if e in kept:
            S = kept[e]
            ginv = scaled_pinv(G[np.ix_(S, S)])
            out[e][S] = np.maximum(np.diag(ginv @ V[e] @ ginv), 0.0)  # G^-1 once, on the |S| x |S| sum
    return out
