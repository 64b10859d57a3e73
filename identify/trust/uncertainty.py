"""What the identified model can be trusted for: reported coefficients, their standard errors, and
how sure the selection is of each term.

Three things, all on the per-block normal equations (identify.regression.gram), so they cost little beside the
measurement chain:

1. **Reported coefficients: refit on all rows.** Selection needs held-out blocks, but a weak term
   (q1*q2^2 of the Table 1 rig) is carried by the few seconds around the jump; whether a held-out
   block covers them moved its training-only estimate by 0.2-6 % (docs/identification.md section 6).
   The kept support is refit by least squares on every block, so the reported coefficients do not
   depend on where the held-out blocks fall. (Validation keeps the training-only fit: identify.identifier.)
2. **Chain bias removed.** The states are integrated from noisy accelerations, so the regressors carry
   noise correlated with the target's (errors in variables), which biases least squares by a multiple
   of the noise variance (Table 1 rig, 1.3 mm, 5 % noise: q2 -0.21 %, q2^3 +0.35 %, 2-3 standard errors
   of a 4-record mean). The raw channels' white-noise levels are read from their spectra above the
   integration band (where white sensor noise is all there is). By default the bias is in closed form
   (analytic_chain_bias, identify.chain.bias_correction): the chain's image of that noise is Gaussian with a lag-0
   covariance known from the band's filters, and the corrected-score normal equations (every moment
   sum replaced by its Hermite-corrected version) have the noise-free expectation; the bias is the raw
   refit less theirs. No random numbers and no pass over the record. Where the kept terms are not all
   monomials of the states and input, or an offset is carried (band-limited columns), SIMEX (Cook &
   Stefanski 1994, chain_bias) does it: fresh noise at the recorded level is put through the chain
   (NoiseChain), added to the states, the support refit on the same rows, and the mean shift of the
   coefficients, to first order the bias at the recorded noise level, is subtracted.
   Standard errors: block-robust over all (contiguous) blocks with one lag of Newey-West weights
   (refit_all_rows). A weak term's information sits in a few blocks, which makes any block estimate of
   its variance noisy; the sensor noise's share of the variance is known without blocks, so the larger
   of the two is used: in closed form, linearised on the band's bins (identify.trust.noise_spread), or with
   SIMEX the replicates' spread plus the bias estimate's Monte Carlo error (spread^2 / replicates).
3. **Inclusion probability** of each library term: the fraction of random choices of which blocks are
   held out (same number of blocks) for which path + selection keep the term: it reruns exactly the
   decision that was made. (PySINDy's ensembles resample rows, which perturbs only the sampling noise;
   the issue measured the truth at 4.2 of their sigmas.)
"""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from ..chain.states import STATE_REQUESTS, BandSpectra, spectral_ops
from ..noise.chain_noise import BandLimitedNoise
from ..chain.bias_correction import CorrectedSums, analytic_bias, gram_moments, term_exponents
from ..regression.gram import BlockGram, scaled_pinv
from ..noise.floor import noise_std
from .noise_spread import noise_variance
from ..regression.optimizers.base import least_squares
from ..chain.spectral import welch_psd, welch_segments

#: Random held-out placements for the inclusion probabilities (a probability to +-0.1 at worst).
N_PLACEMENTS = 24
#: A kept term within SIGNIFICANT_Z standard errors of zero is an uncertain term: the data do not establish
#: it, so it leaves the model, its refit and its simulation, least significant first (least_significant),
#: and is reported apart (result()["uncertain_terms"]; identify.fitting.trust, docs/identification.md
#: section 5). Noise-input records (Table 1 rig): spurious even terms at 0.9-3.1 SE and P(kept) 0.50-0.92,
#: which a bound that also asked P(kept) < 0.5 kept; fresh sweeps and plain rigs: every true term beyond 5
#: SE. A term beyond it stays whatever its probability (design rig beyond the jump, 2 % noise: the damping
#: q1 at P(kept) 0.38 but -3.72 +- 0.39; left out, the refit lost the input, zdd -0.10 for -1).
SIGNIFICANT_Z = 3.0
#: An inclusion probability below this marks a kept term (beyond SIGNIFICANT_Z) as unsettled, at or above
#: it a term the selection left out (reports.text.unsettled_terms): the placements disagree with the fit.
MIN_INCLUSION_PROBABILITY = 0.5
#: SIMEX replicates by default: None = by the record's length (replicates_for). Each pair of replicates
#: is one band-limited noise draw and two Gram passes on the kept columns. The pairs' spread is also a
#: variance estimate, its square root good to about 1/sqrt(2 x pairs): 25 % with 8 pairs, 12.5 % with 32.
#: That error is in every standard error it sets, and it hid what a joint fit gains: three recordings
#: of 30 s at 1024 Hz reported the weak term's SE 26.1 against 23.2 for one alone with 16 replicates,
#: 20.7 against 31.5 with 64 (identify.joint, benchmarks/joint_se.py).
N_REPLICATES = None
#: ... as many as the budget of replicate samples allows, between the two bounds: 64 replicates up to
#: 250 000 samples in all, 16 from 1 000 000 (the 1e6-sample record's cost, benchmarks/identify_speed.py).
REPLICATE_SAMPLES = 16_000_000
MIN_REPLICATES, MAX_REPLICATES = 16, 64


def refit_all_rows(gram: BlockGram, support: np.ndarray, eq: int, covariance: bool = True):
    """(m,) least squares on `support` over every block, and its block-robust covariance (|S| x |S|;
    None unless `covariance`).

    The blocks are contiguous here, so neighbouring blocks' scores are correlated: the band-limited
    states' errors (strongest near the band's bottom, periods ~1 s against 1.2 s blocks) swing across a
    block boundary, and neighbours' scores come out negatively correlated. The plain block sandwich
    (identify.regression.gram.sandwich_covariance) ignores that and overstated the spread of q1 / q2 / q2^3 by 1.5-1.7x
    on the Table 1 sweep; Newey-West weights over one block lag (Bartlett: 1/2) take it into account and
    stay positive semi-definite. Blocks of different recordings (gram.segment, a joint fit) are not
    neighbours: their lag pairs get no weight."""
    everything = np.ones(gram.n_blocks, dtype=bool)
    ne = gram.equations(everything)
    coef = least_squares(ne.G, ne.B[:, eq], support)
    if not covariance:
        return coef, None
    S = np.flatnonzero(support)
    if S.size == 0:
        return coef, np.zeros((0, 0))
    scores = gram.block_scores(everything, S, coef[S], eq)
    k = scores.shape[0]
    same = (gram.segment[:-1] == gram.segment[1:])[:, None]  # pairs within one recording only
    lag1 = scores[:-1].T @ (scores[1:] * same)
    meat = (scores.T @ scores + 0.5 * (lag1 + lag1.T)) * k / max(k - 1, 1)
    bread = scaled_pinv(ne.G[np.ix_(S, S)])
    return coef, bread @ meat @ bread


class NoiseChain:
    """The measurement chain (identify.chain.states, in `sig`'s band and taper) applied to added noise alone.
    Every step of the chain (detrending, taper, FFT, band-limited (j w)^p, trimming) is linear, so the
    states of a record plus noise are sig's states plus these: a SIMEX replicate needs the transforms of
    the noise, not a rerun of the chain with its band search (tests/identify/test_uncertainty.py checks
    it against the chain)."""

    def __init__(self, sig, n: int, layout: str):
        self.n, self.layout, self.band, self.fs, self.taper_n = n, layout, tuple(sig.band_hz), sig.fs_hz, sig.taper_n
        self._fresh = None

    def __call__(self, e_in: np.ndarray, e_out: np.ndarray):
        """(q1, q2, q1_dot, input) that noise e_in, e_out on the raw channels adds, on all rows."""
        response = e_out - e_in if self.layout == "base" else e_out
        return tuple(spectral_ops([response, e_in], self.fs, self.band, STATE_REQUESTS[self.layout], self.taper_n))

    def draw(self, rng: np.random.Generator, s_in: float, s_out: float):
        """(q1, q2, q1_dot, input) of fresh white noise of std s_in, s_out on the raw channels: the
        stationary image the chain gives it on the valid rows, drawn on the band's bins alone
        (chain_noise.BandLimitedNoise: no forward transform, random numbers for the band's bins only)."""
        if self._fresh is None:
            self._fresh = BandLimitedNoise(self.n, self.fs, self.band, self.layout)
        return tuple(self._fresh.draw(s_in, s_out, rng))


def replicates_for(n_samples: int) -> int:
    """Default number of SIMEX replicates for records of n_samples in all (even: antithetic pairs)."""
    n = int(np.clip(REPLICATE_SAMPLES / max(n_samples, 1), MIN_REPLICATES, MAX_REPLICATES))
    return n + (n % 2)


def chain_bias(recording, sig, supports: dict, coefs: dict, gram_of, n_replicates: int | None = N_REPLICATES,
               seed: int = 0) -> dict | None:
    """SIMEX estimate of the bias the noisy measurement chain puts into each equation's refit.

    supports, coefs : {equation index: (m,) support, (m,) all-rows coefficients}; gram_of(sig, columns)
    -> BlockGram on sig.valid rows of the library columns `columns` (index array) only. Returns None
    when a channel's noise floor cannot be read, else {"noise_std": (input, output), "bias": {e: (m,)},
    "spread_var", "mc_var": {e: (m,)}, "replicates"}; bias is what to subtract, spread_var the
    variance the added noise gives a refit, mc_var that of the bias estimate.
    Several recordings (a joint fit, identify.joint): recording and sig are lists, every recording gets
    its own noise in each replicate, gram_of(list of sigs, columns) -> their joint BlockGram, and
    noise_std is a list of (input, output), one per recording.

    Replicates come in antithetic pairs (noise d and -d): the shift of a refit is, to first order,
    linear in the noise, and that part cancels in a pair's mean, leaving the quadratic part, the bias;
    half the pair's difference is the linear part, whose variance is spread_var. One noise draw serves
    two refits, and the bias estimate's Monte Carlo error is that of the quadratic part alone."""
    several = isinstance(recording, (list, tuple))
    pairs = list(zip(recording, sig)) if several else [(recording, sig)]
    if n_replicates is None:
        n_replicates = replicates_for(sum(r.input.size for r, _ in pairs))
    floors = [noise_floors(r, s.band_hz, s.spectra) for r, s in pairs]
    if any(f is None for fl in floors for f in fl) or n_replicates < 2:
        return None
    rng = np.random.default_rng(seed)
    n_pairs = (n_replicates + 1) // 2
    columns = np.flatnonzero(np.any([sup for sup in supports.values()], axis=0))
    means, halves = {e: [] for e in supports}, {e: [] for e in supports}
    chains = [NoiseChain(s, r.input.size, r.layout) for r, s in pairs]
    for _ in range(n_pairs):
        draws = [nc.draw(rng, s_in, s_out) for nc, (s_in, s_out) in zip(chains, floors)]
        refits = []
        for sign in (1.0, -1.0):
            noisy = [dataclasses.replace(s, q1=s.q1 + sign * d1, q2=s.q2 + sign * d2, q1_dot=s.q1_dot + sign * dd,
                                         input=s.input + sign * du)
                     for (_, s), (d1, d2, dd, du) in zip(pairs, draws)]
            g2 = gram_of(noisy if several else noisy[0], columns)
            ne = g2.equations(np.ones(g2.n_blocks, dtype=bool))
            refits.append({})
            for e, sup in supports.items():
                full = np.zeros(sup.size)
                full[columns] = least_squares(ne.G, ne.B[:, e], sup[columns])
                refits[-1][e] = full - coefs[e]
        for e in supports:
            means[e].append(0.5 * (refits[0][e] + refits[1][e]))
            halves[e].append(0.5 * (refits[0][e] - refits[1][e]))
    bias = {e: np.mean(d, axis=0) for e, d in means.items()}
    spread = {e: np.mean(np.square(h), axis=0) for e, h in halves.items()}  # the linear part has mean 0
    mc = {e: np.var(d, axis=0, ddof=1) / n_pairs if n_pairs > 1 else spread[e] for e, d in means.items()}
    return {"noise_std": floors if several else floors[0], "bias": bias, "spread_var": spread, "mc_var": mc,
            "replicates": 2 * n_pairs, "method": SIMEX}


#: Exponents (q1, q2, q1_dot, input) of each equation's target: q1_dot's is q1_dot, q2_dot's is q1.
TARGET_EXPONENTS = [(0, 0, 1, 0), (1, 0, 0, 0)]
ANALYTIC, SIMEX = "analytic (corrected score)", "SIMEX"


class RecordNoise:
    """What the closed-form chain bias and the noise's share of the variance read of one recording held
    in memory (identify.out_of_core.ChunkedEquations reads the same chunk by chunk): its noise floors, the
    chain's image of white noise, raw moment sums the Gram lacks, and the rows the score is built of."""

    def __init__(self, recording, sig):
        self.recording, self.sig = recording, sig

    def noise_floors(self):
        return noise_floors(self.recording, self.sig.band_hz, self.sig.spectra)

    def noise_model(self) -> BandLimitedNoise:
        r, s = self.recording, self.sig
        return BandLimitedNoise(r.input.size, s.fs_hz, s.band_hz, r.layout)

    def signals(self):
        v = self.sig.valid
        return self.sig.q1[v], self.sig.q2[v], self.sig.q1_dot[v], self.sig.input[v]

    def moment_sum(self, k: tuple) -> float:
        """sum over the valid rows of the monomial with exponents k over (q1, q2, q1_dot, input)."""
        y = self.signals()
        col = np.ones_like(y[0])
        for v, p in enumerate(k):
            if p:
                col = col * y[v] ** p
        return float(col.sum())

    def score_pieces(self, noise, floor) -> list:
        """noise_spread.noise_variance's parts: the valid rows whole."""
        return [(self.signals(), noise, floor)]


def closed_form_bias(records: list, gram: BlockGram, library, supports: dict, coefs: dict) -> dict | None:
    """The chain's bias in closed form (identify.chain.bias_correction), in chain_bias's shape with
    "method": ANALYTIC, "replicates": 0 and no Monte Carlo error (mc_var 0); spread_var is the noise's
    share of the refit's variance, linearised on the band's bins (identify.trust.noise_spread). None when SIMEX
    must do it: a kept term is not a monomial of the states and input, an offset is carried (the
    columns then go through the band: not monomials of the noisy states), or a noise floor cannot be read.
    records : per recording (gram's segments) a RecordNoise, or anything that reads the same (its .sig
    names the band and input; out of core: identify.out_of_core.ChunkedEquations)."""
    several = len(records) > 1
    if any(r.sig.q2_offset is not None for r in records):
        return None
    col_exps = [term_exponents(t, records[0].sig.input_name) for t in library.terms]
    if any(col_exps[j] is None for sup in supports.values() for j in np.flatnonzero(sup)):
        return None
    floors = [r.noise_floors() for r in records]
    if any(f is None for fl in floors for f in fl):
        return None
    parts, covs, spread_parts = [], [], []
    for i, (r, floor) in enumerate(zip(records, floors)):
        noise = r.noise_model()
        covs.append(noise.covariance(*floor))
        C = (gram.part(i) if several else gram).C.sum(0)
        parts.append(CorrectedSums(covs[-1], gram_moments(C, col_exps + TARGET_EXPONENTS[:gram.p]), r.moment_sum))
        spread_parts.append(r.score_pieces(noise, floor))  # lazily: out of core, chunk by chunk
    bias = analytic_bias(parts, supports, coefs, col_exps, TARGET_EXPONENTS)
    G = gram.equations(np.ones(gram.n_blocks, dtype=bool)).G
    spread = noise_variance(itertools.chain.from_iterable(spread_parts), supports, coefs, G, col_exps,
                            TARGET_EXPONENTS)
    zero = {e: np.zeros(sup.size) for e, sup in supports.items()}
    return {"noise_std": floors if several else floors[0], "bias": bias, "spread_var": spread, "mc_var": zero,
            "replicates": 0, "method": ANALYTIC, "noise_cov": covs if several else covs[0]}


def analytic_chain_bias(recording, sig, gram: BlockGram, library, supports: dict, coefs: dict) -> dict | None:
    """closed_form_bias of recordings in memory: recording, sig one of each, or lists (a joint fit)."""
    several = isinstance(recording, (list, tuple))
    pairs = list(zip(recording, sig)) if several else [(recording, sig)]
    return closed_form_bias([RecordNoise(r, s) for r, s in pairs], gram, library, supports, coefs)


def estimate_chain_bias(method: str, sources: list, gram: BlockGram, library, supports: dict, coefs: dict,
                        gram_of, n_replicates: int | None = N_REPLICATES) -> dict | None:
    """The chain's bias as `method` asks ("auto": in closed form where it applies, closed_form_bias;
    SIMEX, chain_bias, otherwise or for "simex", where every source holds its recording in memory:
    source.simex_inputs() -> (recording, sig), else None and no correction). sources: one per recording
    (identify.regression.sources.NormalEquationsSource: each is a RecordNoise's reader); gram_of as chain_bias's."""
    if method == "auto":
        closed = closed_form_bias(sources, gram, library, supports, coefs)
        if closed is not None:
            return closed
    held = [s.simex_inputs() for s in sources]
    if any(h is None for h in held):
        return None
    recs, sigs = [h[0] for h in held], [h[1] for h in held]
    if len(held) == 1:
        return chain_bias(recs[0], sigs[0], supports, coefs, gram_of, n_replicates)
    return chain_bias(recs, sigs, supports, coefs, gram_of, n_replicates)


#: The noise floors are read from at most this many stretches of FLOOR_STRETCH Welch segments, spread
#: evenly over the record: 64 x 7 = 448 segments of 50 % overlap put each bin's estimate within ~5 % and
#: the median over the hundreds of bins above the band within a fraction of a %; the whole of a
#: million-sample record (~1950 segments) cost 0.07 s of the closed-form bias's 0.08 s.
FLOOR_STRETCHES, FLOOR_STRETCH = 64, 4


def noise_floors(recording, band_hz, spectra: BandSpectra | None = None) -> tuple[float | None, float | None]:
    """White-noise std of the input and output channels (identify.noise.floor.noise_std, the one floor estimator).

    From the spectra the chain's band search read (StateSignals.spectra: base layout, the input's and
    the response's, output - input) when given: the sensors' noises are independent, so the output's
    variance is the response's less the input's (and the response's, which the chain integrates, is
    what the noise covariance uses: chain_noise.BandLimitedNoise.white_covariance). Otherwise one batched
    Welch of the two channels (on FLOOR_STRETCHES stretches spread over a long record, averaged: white
    noise is stationary)."""
    fs = recording.fs_hz
    if spectra is not None:
        s_in = noise_std(spectra.f_hz, spectra.input, spectra.segments, fs, band_hz)
        s_resp = noise_std(spectra.f_hz, spectra.response, spectra.segments, fs, band_hz)
        if s_in is None or s_resp is None:
            return s_in, s_resp
        return s_in, float(np.sqrt(max(s_resp**2 - s_in**2, 0.0)))
    return floors_read(lambda a, b: (recording.input[a:b], recording.output[a:b]), recording.input.size, fs, band_hz)


def floors_read(read, n: int, fs: float, band_hz) -> tuple[float | None, float | None]:
    """noise_floors' Welch of the two channels, read(a, b) -> (input, output) samples [a, b) of a record of
    n samples (a Recording's arrays, or a chunk source's reads out of core)."""
    nper = int(min(1024, max(n // 8, 64)))
    length = FLOOR_STRETCH * nper
    if n > 2 * FLOOR_STRETCHES * length:
        starts = np.linspace(0, n - length, FLOOR_STRETCHES).astype(int)
        f, p = welch_psd(np.concatenate([np.vstack(read(a, a + length)) for a in starts]), fs, nper)
        p = p.reshape(FLOOR_STRETCHES, 2, -1).mean(0)
        segments = FLOOR_STRETCHES * welch_segments(length, nper)
    else:
        f, p = welch_psd(np.vstack(read(0, n)), fs, nper)
        segments = welch_segments(n, nper)
    return noise_std(f, p[0], segments, fs, band_hz), noise_std(f, p[1], segments, fs, band_hz)


def placements(held: np.ndarray, n: int, seed: int = 0) -> list[np.ndarray]:
    """`n` random held-out masks with as many blocks as `held`."""
    rng = np.random.default_rng(seed)
    k, nb = int(held.sum()), held.size
    out = []
    for _ in range(n):
        m = np.zeros(nb, dtype=bool)
        m[rng.choice(nb, size=k, replace=False)] = True
        out.append(m)
    return out


def inclusion_probabilities(gram: BlockGram, held: np.ndarray, fit_and_select, n: int = N_PLACEMENTS,
                            seed: int = 0) -> np.ndarray | None:
    """(p, m) fraction of `n` random held-out placements for which the selection keeps each term.

    fit_and_select(trains, heldouts) -> per placement a sequence of (m,) supports, one per equation,
    from lists of the placements' training and held-out normal equations (the identifier's own path and
    rule, so the probability is that of the decision actually made; given all placements at once, the
    paths run as one batch, ADMMLasso.fit_paths). None without held-out blocks."""
    if not held.any() or held.all():
        return None
    masks = placements(held, n, seed)
    counts = np.zeros((gram.p, gram.m))
    for supports in fit_and_select([gram.equations(~m) for m in masks], [gram.equations(m) for m in masks]):
        for e, support in enumerate(supports):
            counts[e] += support
    return counts / n


def term_rules() -> dict:
    """The bounds a result's terms are judged by, as results state them (result["uncertainty"]["term_rules"])."""
    return {"significant_z": SIGNIFICANT_Z, "min_inclusion_probability": MIN_INCLUSION_PROBABILITY}


def least_significant(supports: dict, coefs: dict, var: dict) -> dict:
    """{equation index: its least significant kept term (var: variances), where it is within SIGNIFICANT_Z
    standard errors of zero and the equation keeps two terms or more}: one backward-elimination step."""
    out = {}
    for e, s in supports.items():
        kept = np.flatnonzero(s)
        if kept.size > 1:  # an equation keeps one term at least (a model of nothing simulates nothing)
            z2 = coefs[e][kept] ** 2 / np.maximum(var[e][kept], np.finfo(float).tiny)
            j = int(np.argmin(z2))
            if z2[j] <= SIGNIFICANT_Z ** 2:
                out[e] = int(kept[j])
    return out


def assess(gram: BlockGram, held: np.ndarray, supports: dict, bias_of=None, fit_and_select=None,
           n_placements: int = N_PLACEMENTS):
    """Reported coefficients {e: (m,)}, their variances {e: (m,)} and what they rest on.

    supports : {equation index: (m,) kept terms}; bias_of(supports, coefs) -> chain_bias(...) or None;
    fit_and_select : see inclusion_probabilities (None: no inclusion probabilities)."""
    coefs, var = {}, {}
    for e, sup in supports.items():
        coefs[e], cov = refit_all_rows(gram, sup, e)
        var[e] = np.zeros(sup.size)
        var[e][sup] = np.maximum(np.diag(cov), 0.0)
    bias = bias_of(supports, coefs) if bias_of is not None else None
    if bias is not None:
        coefs = {e: np.where(supports[e], c - bias["bias"][e], 0.0) for e, c in coefs.items()}
        # the larger of the sandwich and the noise's share (linearised in closed form, or the SIMEX
        # replicates' spread), plus the bias estimate's own Monte Carlo error (0 in closed form)
        var = {e: np.maximum(v, np.where(supports[e], bias["spread_var"][e], 0.0))
               + np.where(supports[e], bias["mc_var"][e], 0.0) for e, v in var.items()}
    p_in = None
    if fit_and_select is not None and n_placements:
        p_in = inclusion_probabilities(gram, held, fit_and_select, n_placements)
    return coefs, var, {"bias": bias, "inclusion": p_in, "placements": n_placements if p_in is not None else 0}


def name_info(info: dict, eqs, names, supports: dict) -> dict:
    """The JSON-ready account of `assess`'s info: by equation and term name."""
    bias, p_in = info["bias"], info["inclusion"]
    out = {"coefficients": "kept terms refit on all rows" + (f", chain bias removed ({bias['method']})" if bias else ""),
           "chain_bias": None, "inclusion_probability": None, "placements": info["placements"]}
    if bias is not None:
        floors = bias["noise_std"]
        named = [{"input": f[0], "output": f[1]} for f in (floors if isinstance(floors, list) else [floors])]
        out["chain_bias"] = {"noise_std": named if isinstance(floors, list) else named[0],
                             "method": bias["method"], "replicates": bias["replicates"],
                             **{eqs[e]: {names[j]: float(b[j]) for j in np.flatnonzero(supports[e])}
                                for e, b in bias["bias"].items()}}
    out["term_rules"] = term_rules()  # with or without inclusion probabilities: reports quote it
    if p_in is not None:  # every kept term, and every term some placement kept
        out["inclusion_probability"] = {eq: {n: float(p_in[e, j]) for j, n in enumerate(names)
                                             if p_in[e, j] > 0 or supports[e][j]} for e, eq in enumerate(eqs)}
    return out
