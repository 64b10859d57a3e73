"""The sensor noise's share of a refit's variance, linearised and computed on the band's bins, without
random draws: what the SIMEX replicates' spread estimated by Monte Carlo (identify.uncertainty).

A refit's shift under a small change d of the signals (q1, q2, q1_dot, input on the fitted rows) is, to
first order, G^-1 sum_t sum_v g_v(t) d_v(t), with

    g_v(t) = dtheta(t)/dy_v r(t) + theta(t) (dtarget(t)/dy_v - sum_j beta_j dtheta_j(t)/dy_v),

theta the kept columns, r the residual and beta the coefficients: the derivative of the score
theta (target - theta . beta). The sensor noise's image d is the band-limited white noise of the raw
channels (chain_noise.BandLimitedNoise): d_v = H_v e_i(v) on the band's bins, e the white response and input
noise of per-sample covariance c. Its variance is therefore exact and needs no draw:

    V = G^-1 [sum_ij c_ij / nfft sum_k w_k Re(U_i(k) U_j(k)^H)] G^-1,   U_i(k) = sum_{v of row i} conj(H_v(k)) Phi_v(k),

Phi_v the transform of g_v on the band's bins (identify.spectral.polyphase_rfft; G^-1 is applied once, to
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
(the variances moved by < 1e-4). A million-sample fit spends 0.04-0.06 s CPU here, less than half of it
in pocketfft (0.040-0.054 s in three rounds of benchmarks/identify_speed.py --sizes 200000 1000000
--repeat 4 --no-simulation --uncertainty-parts, "the noise's share of the variance", 0.045-0.057 s in
three more the next day; 0.062-0.069 s in double precision (DTYPE) in the first rounds; 0.100-0.122 s
before the rows were built in the transforms' polyphase order, in place, and batched across signals and
equations). Against SIMEX's replicate spread (256 replicates, ~6 % Monte Carlo error) on the Table 1 rig: within 1-7 % at 0.5 % noise, 5-20 % at 5 % (where the replicates' antithetic halves carry
third-order terms too). Why it is worth it: for a weak term the block estimates of the
variance (sandwich, jackknife) are noisy because its information sits in a few blocks, while this one is
not (docs/identification.md section 5). Monomial terms only (their derivatives are monomials); the caller
falls back to SIMEX otherwise.
"""
from __future__ import annotations

import numpy as np

from .gram import scaled_pinv
from .spectral import polyphase_factor, polyphase_rfft

#: Rows transformed together, times the step (a row at step D is D times shorter): a padded
#: million-sample record's polyphase buffers stay ~35 MB (single precision, DTYPE).
BATCH = 8
#: Largest sampling step of the score's transforms (decimation).
MAX_STEP = 8
#: Precision of the score's rows and their transforms. A variance that sets a standard error needs a
#: few digits; single precision moves it by a few 1e-7 of itself at most (against double: 7-8e-8 on the
#: 30 s records of tests/identify/test_noise_spread.py, 7.5e-8 on a million samples, <= 2.5e-7 on the
#: five sweeps of benchmarks/uncertainty_numbers.py), and halves the memory the rows are built in and the
#: time pocketfft takes on them. The sums over the band's bins (U, and the product that squares it) and
#: the filters H_v are in double precision (H_v in single moved the variances by 5e-9 only, and saved no
#: measurable time: kept double, with no cast).
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


def _combination(terms, scratch) -> np.ndarray | float:
    """sum of c x over the (c, x) pairs, x an array or the constant monomial's 1.0, into one new array
    (each product made in `scratch`): no temporary per term."""
    const = float(sum(c for c, x in terms if not isinstance(x, np.ndarray)))
    # python floats: a numpy float64 coefficient would widen single-precision rows to double
    arrays = [(float(c), x) for c, x in terms if isinstance(x, np.ndarray)]
    if not arrays:
        return const
    out = np.multiply(arrays[0][1], arrays[0][0])
    for c, x in arrays[1:]:
        out += np.multiply(x, c, out=scratch)
    if const:
        out += const
    return out


class _Strided:
    """A recording's signals read every P-th sample: y_v[c::P] as row c of a (P, ceil(n / P)) array (0 past
    the end), each row read once. A strided read touches every cache line of y_v whatever P, and the
    steps whose transforms split into M components with M x step = P share rows (at 2048 Hz with the
    band to 106 Hz, steps 2, 3 and 6 all read every 6th sample: 4 reads of each signal instead of 6)."""

    def __init__(self, y):
        self.y, self._rows, self._read = y, {}, set()

    def __call__(self, v: int, stride: int, offsets) -> np.ndarray:
        y = self.y[v]
        if (v, stride) not in self._rows:
            self._rows[v, stride] = np.zeros((stride, -(-y.size // stride)), dtype=DTYPE)
        rows = self._rows[v, stride]
        for c in offsets:
            if (v, stride, c) not in self._read:
                part = y[c::stride]
                rows[c, :part.size] = part
                self._read.add((v, stride, c))
        return rows


class _Signals:
    """One recording's fitted rows at one sampling step, in the order the step's transform reads them, and
    their monomials (y^k, k exponents over q1, q2, q1_dot, input; each made once, shared by the equations).

    The transform on nfft / step points splits its rows into M polyphase components (spectral.
    polyphase_rfft); the signals are decimated straight into that order, shape (M, width): [r, j] is the
    decimated sample j M + r, 0 from the last sample on. Every g row is a sum of products of them taken
    sample by sample, so it is built in that order too, written into the transform's buffer: no
    decimated copy in time order and no second copy into the components."""

    def __init__(self, strided: _Strided, n: int, nfft: int, kk: int, step: int):
        self.strided, self.step, self.length, self.kk = strided, step, nfft // step, kk
        self.m = polyphase_factor(self.length, kk - 1)
        self.n = len(range(0, n, step))
        self.width = -(-self.n // self.m)
        # components whose last column is past the record's end: zeroed in every row transformed
        self.short = [r for r in range(self.m) if (self.width - 1) * self.m + r >= self.n]
        self._mono = {}
        self.scratch = np.empty((self.m, self.width), dtype=DTYPE)

    def signal(self, v: int) -> np.ndarray:
        """(M, width) y_v: component r is y_v[r step::M step], row r step of the recording's stride M step."""
        p = self.m * self.step
        return self.strided(v, p, range(0, p, self.step))[::self.step]

    def __call__(self, k: tuple):
        """y^k; the constant is the scalar 1.0."""
        if not any(k):
            return 1.0
        if k not in self._mono:
            v = next(i for i, p in enumerate(k) if p)
            lower = list(k)
            lower[v] -= 1
            rest = self(tuple(lower))
            self._mono[k] = self.signal(v) if np.isscalar(rest) else rest * self.signal(v)
        return self._mono[k]

    def derivative_term(self, k: tuple, v: int) -> tuple:
        """d y^k / d y_v as the pair (k_v, y^(k - e_v)) (k_v 0: y_v does not appear)."""
        if not k[v]:
            return 0.0, 1.0
        lower = list(k)
        lower[v] -= 1
        return float(k[v]), self(tuple(lower))


class _Score:
    """The transforms of one equation's score derivatives g_v on one recording's band bins: theta (kept
    columns) and the residual r where a signal's slope and Jacobians are constants (combined on the bins),
    g_v term by term otherwise, each at the step its degree allows. Each row is built in place in the
    transform's buffer (fill; _transform batches the rows of every equation by step: q1's and q2's g rows
    of a cubic model share their steps), from the step's signals, residual and slopes, each made once."""

    def __init__(self, n: int, noise, cols: list, target: tuple, beta: np.ndarray):
        """n : the recording's fitted rows. Leaves in self.jobs the rows to transform, {step: [job]}
        (_transform makes them; ("theta", a), ("resid",) or (v, a): g_v of term a)."""
        self.noise, self.cols, self.target, self.beta = noise, cols, target, beta
        self.kk, self.nfft = noise.responses[0].size, noise.nfft
        self.r_degree = max([_degree(k) for k in cols] + [_degree(target)])
        self._resid, self._slope, self.spec = {}, {}, {}
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

    def resid(self, sig: _Signals):
        """r = target - theta . beta on the rows of sig's step."""
        if sig.step not in self._resid:
            total = _combination([(b, sig(k)) for b, k in zip(self.beta, self.cols) if b], sig.scratch)
            target = sig(self.target)
            self._resid[sig.step] = (np.subtract(target, total, out=total) if isinstance(total, np.ndarray)
                                     else target - total)
        return self._resid[sig.step]

    def slope(self, sig: _Signals, v: int):
        """dtarget/dy_v - sum_j beta_j dtheta_j/dy_v on the rows of sig's step."""
        if (sig.step, v) not in self._slope:
            terms = [sig.derivative_term(self.target, v)]
            for b, k in zip(self.beta, self.cols):
                c, x = sig.derivative_term(k, v)
                if b and c:
                    terms.append((-b * c, x))
            self._slope[sig.step, v] = _combination([(c, x) for c, x in terms if c], sig.scratch)
        return self._slope[sig.step, v]

    def fill(self, sig: _Signals, job: tuple, out: np.ndarray):
        """Row `job` of the transform ("theta", a; "resid"; or v, a: g_v of term a) into out, (M, width)."""
        if job[0] == "theta":
            out[...] = sig(self.cols[job[1]])
        elif job[0] == "resid":
            out[...] = self.resid(sig)
        else:
            v, a = job
            np.multiply(sig(self.cols[a]), self.slope(sig, v), out=out)  # theta slope_v
            c, lower = sig.derivative_term(self.cols[a], v)
            if c:  # + dtheta/dy_v r
                term = np.multiply(lower, self.resid(sig), out=sig.scratch) if isinstance(lower, np.ndarray) \
                    else self.resid(sig)
                if c != 1.0:
                    term = np.multiply(term, c, out=sig.scratch)
                out += term

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


def _steps(y, noise):
    """step -> the recording's _Signals at that step, each made once."""
    cache: dict = {}
    strided = _Strided(y)

    def at(step: int) -> _Signals:
        if step not in cache:
            cache[step] = _Signals(strided, y[0].size, noise.nfft, noise.responses[0].size, step)
        return cache[step]
    return at


def _transform(scores, at):
    """Every score's rows (_Score.jobs) of one recording, transformed on the band's bins: the rows of one
    step, all equations', built in one buffer and transformed together, BATCH x step at a time (a buffer
    as large as BATCH rows at full rate). Batches matter: pocketfft transforms several rows at once with
    vector instructions (24 rows of 180,000 points: 23 ms in one call, 33 ms in 24 calls, scipy 1.17 on
    this machine). at : step -> the recording's _Signals."""
    by_step: dict = {}
    for score in scores:
        for step, jobs in score.jobs.items():
            by_step.setdefault(step, []).extend((score, job) for job in jobs)
    for step, todo in by_step.items():
        sig = at(step)
        for first in range(0, len(todo), BATCH * step):
            chunk = todo[first:first + BATCH * step]
            buf = np.empty((len(chunk), sig.m, sig.length // sig.m), dtype=DTYPE)
            for i, (score, job) in enumerate(chunk):
                score.fill(sig, job, buf[i, :, :sig.width])
            buf[:, :, sig.width:] = 0.0  # the zero padding to nfft / step points
            buf[:, sig.short, sig.width - 1] = 0.0  # and past the record's end
            spec = polyphase_rfft(buf, sig.length, sig.kk - 1)
            if step > 1:
                spec *= step
            for (score, job), row in zip(chunk, spec):
                score.spec[job] = row


def noise_variance(parts, supports: dict, coefs: dict, G: np.ndarray, col_exps: list, target_exps: list) -> dict:
    """{equation: (m,) variance of the refit from the sensor noise, linearised}.

    parts : per recording (signals, noise, (std_in, std_out)): signals the (q1, q2, q1_dot, input) rows
    the Gram was summed over, noise its chain_noise.BandLimitedNoise; G : the all-rows normal matrix (all
    recordings); coefs : {equation: (m,) all-rows coefficients}; col_exps, target_exps : monomial
    exponents of the columns and of each equation's target (identify.corrected). Exact responses
    H_v = gain (j w)^p on the bins (chain_noise.BandLimitedNoise), as the chain and the noise draws have them."""
    # an equation whose one kept column is its own target (q2_dot = q1: the chain's q1 is the derivative
    # of its q2) fits it exactly, coefficient 1 and residual 0 to rounding: its score does not move (0)
    kept = {e: np.flatnonzero(sup) for e, sup in supports.items()
            if sup.any() and not (sup.sum() == 1 and col_exps[np.flatnonzero(sup)[0]] == target_exps[e])}
    V = {e: np.zeros((S.size, S.size)) for e, S in kept.items()}
    for y, noise, (s_in, s_out) in parts:
        scores = {e: _Score(y[0].size, noise, [col_exps[j] for j in S], target_exps[e], coefs[e][S])
                  for e, S in kept.items()}
        _transform(scores.values(), _steps(y, noise))
        c, w = noise.white_covariance(s_in, s_out), noise.bin_weights()
        for e, score in scores.items():
            U = np.zeros((2, kept[e].size, noise.responses[0].size), dtype=complex)
            score.accumulate(U)
            # sum_ij c_ij / nfft sum_k w_k Re(U_i U_j^H): every (i, j) block of one (2|S|, 2|S|) product, in
            # real arithmetic (Re(a conj b) = a_re b_re + a_im b_im: U's real view), with w_k = 2 on every
            # bin and the few bins of another weight (DC, Nyquist) corrected after: no weighted copy of U
            Ur = U.reshape(U.shape[0] * U.shape[1], -1).view(float)
            P = 2.0 * (Ur @ Ur.T)
            for k in np.flatnonzero(w != 2.0):
                P += (w[k] - 2.0) * (Ur[:, 2 * k:2 * k + 2] @ Ur[:, 2 * k:2 * k + 2].T)
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
