"""The sensor noise's share of a refit's variance (identify.trust.noise_spread): its shortcuts (transforms of
theta and the residual shared between signals, decimated transforms) against the formula evaluated
directly, every signal's score derivative transformed at full rate."""
import numpy as np
import pytest
from scipy.fft import irfft, rfft

from identify.trust import noise_spread, uncertainty as unc
from identify.noise.chain_noise import BandLimitedNoise
from identify.chain.bias_correction import term_exponents
from identify.regression.gram import scaled_pinv
from identify.identifier import SparseIdentifier, holdout_blocks
from identify.trust.noise_spread import boxcar_spectrum, decimation, noise_variance
from identify.chain.spectral import lowband_rfft
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from protocol.sweep import SineSweep

FS, BAND = 2048.0, (1.2, 106.25)


def _band_limited(rng, noise, k: int) -> np.ndarray:
    """(k, nfft) periodic signals whose spectra are random on the band's bins and zero above them."""
    kk = noise.responses[0].size
    spec = np.zeros((k, noise.nfft // 2 + 1), dtype=complex)
    spec[:, 1:kk] = rng.standard_normal((k, kk - 1)) + 1j * rng.standard_normal((k, kk - 1))
    return irfft(spec, noise.nfft, axis=-1)


def _decimated(x: np.ndarray, nfft: int, kk: int, step: int) -> np.ndarray:
    """The band's bins of x (sampled every `step` samples of an nfft-point frame) from the transform on
    nfft / step points, times step: what noise_variance computes, in its plain form (rows in time order)."""
    return step * lowband_rfft(x[None], nfft // step, kk - 1)[0]


def test_decimated_transform_is_exact_while_products_have_no_image_on_the_band():
    """A product of `degree` band-limited signals, sampled every D samples with D as decimation picks it,
    has the same band bins (times D) as at full rate, to rounding; a step one larger than the rule
    allows puts the product's images on the band, and the bins move (the rule is not loose)."""
    rng = np.random.default_rng(0)
    noise = BandLimitedNoise(60_000, FS, BAND, "base")
    kk = noise.responses[0].size
    checked = []
    for degree in (1, 3, 5):
        factors = _band_limited(rng, noise, degree)
        x = np.prod(factors, axis=0)
        full = rfft(x)[:kk]
        step = decimation(noise, degree)
        assert step > 1
        fast = _decimated(x[::step], noise.nfft, kk, step)
        assert np.max(np.abs(fast - full)) < 1e-9 * np.max(np.abs(full)), degree
        # the next step that still has the band below its Nyquist frequency, if any
        f_top = (kk - 1) * FS / noise.nfft
        wider = [d for d in range(step + 1, 16) if noise.nfft % d == 0 and FS / d > 2 * f_top]
        if wider:
            wrong = _decimated(x[::wider[0]], noise.nfft, kk, wider[0])
            assert np.max(np.abs(wrong - full)) > 1e-3 * np.max(np.abs(full)), degree
            checked.append(degree)
    assert checked == [3, 5]
    # degree 5 with a band to 133 Hz at 2048 Hz: 2048 / D - 133 >= 5 x 133 allows D = 2 only
    assert decimation(noise, 5) == 2


def test_a_constant_columns_transform_is_the_boxcars():
    """A constant column is no band-limited signal (only its ends are on the band), so it is not decimated:
    its transform is the boxcar's in closed form, against rfft of the ones."""
    for n, nfft in ((1000, 1536), (61_440, 67_500), (999, 1000)):
        kk = 200
        np.testing.assert_allclose(boxcar_spectrum(n, nfft, kk), rfft(np.ones(n), nfft)[:kk], rtol=1e-9, atol=1e-9 * n)


def _direct(parts, supports, coefs, G, col_exps, target_exps) -> dict:
    """The linearised variance as noise_spread's docstring writes it, term by term: g_v built for every
    signal v with a numerical derivative of the score (no symbolic shortcuts), transformed at full rate."""
    out = {}
    for e, sup in supports.items():
        S = np.flatnonzero(sup)
        ginv = scaled_pinv(G[np.ix_(S, S)])
        V = np.zeros((S.size, S.size))
        for y, noise, (s_in, s_out) in parts:
            y = [np.asarray(s, dtype=float) for s in y]

            def mono(k, sig):
                out = np.ones_like(sig[0])
                for v, p in enumerate(k):
                    out = out * sig[v] ** p
                return out

            def score(sig):  # (|S|, n) theta (target - theta . beta) per row
                theta = np.array([mono(col_exps[j], sig) for j in S])
                return theta * (mono(target_exps[e], sig) - coefs[e][S] @ theta)

            kk = noise.responses[0].size
            U = np.zeros((2, S.size, kk), dtype=complex)
            for v, (row, _) in enumerate(noise.requests):
                h = 1e-6 * np.max(np.abs(y[v]))
                up, down = list(y), list(y)
                up[v], down[v] = y[v] + h, y[v] - h
                g = (score(up) - score(down)) / (2 * h)  # exact for the quadratic-in-y_v parts, O(h^2) else
                U[row] += np.conj(noise.responses[v]) * rfft(g, noise.nfft, axis=-1)[:, :kk]
            U = np.einsum("ab,ibk->iak", ginv, U)
            c, w = noise.white_covariance(s_in, s_out), noise.bin_weights()
            for i in range(2):
                for j in range(2):
                    V += c[i, j] * ((U[i] * w) @ U[j].conj().T).real / noise.nfft
        out[e] = np.zeros(sup.size)
        out[e][S] = np.diag(V)
    return out


@pytest.mark.parametrize("noise_fraction", [0.005, 0.05])
def test_noise_variance_is_the_formula_evaluated_directly(noise_fraction, monkeypatch):
    """On a 30 s sweep of the Table 1 rig (1.2 mm), the kept q1_dot terms' noise variance against the
    direct evaluation (numerical derivatives, every signal transformed at full rate, in double precision).
    Without decimation (MAX_STEP = 1) and in double precision (DTYPE), the shared transforms must give
    the same numbers: measured within 2e-11, asked 1e-9. In single precision (the default DTYPE) the
    rows' rounding adds: measured 5e-8 and 1.2e-7 (0.5 and 5 % noise), asked 1e-6. Decimated (the default, each term at the step its
    degree allows): the fitted rows' two ends leak; measured 5e-6 and 1.6e-5 (0.5 and 5 % noise), asked
    1e-4, a standard error moved by 5e-5 of itself at most."""
    sensors = {k: Accelerometer(noise_fraction=noise_fraction) for k in ("table_sensor", "mass_sensor")}
    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 30, 1.2), fs_hz=FS, seed=5, **sensors)
    ident = SparseIdentifier(validate=False, placements=0, bias_replicates=0).fit(run.recording)
    sig, rec = ident.states_, run.recording
    gram = ident._gram(sig, holdout_blocks(sig)[0])
    sups = {e: s.support for e, s in enumerate(ident.selections_.values())}
    coefs = {e: unc.refit_all_rows(gram, sups[e], e, covariance=False)[0] for e in sups}
    col_exps = [term_exponents(t, sig.input_name) for t in ident.library_.terms]
    v = sig.valid
    parts = [((sig.q1[v], sig.q2[v], sig.q1_dot[v], sig.input[v]),
              BandLimitedNoise(rec.input.size, sig.fs_hz, sig.band_hz, rec.layout),
              unc.noise_floors(rec, sig.band_hz, sig.spectra))]
    G = gram.equations(np.ones(gram.n_blocks, dtype=bool)).G
    fast = noise_variance(parts, {0: sups[0]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[0]
    direct = _direct(parts, {0: sups[0]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[0]
    S = np.flatnonzero(sups[0])
    assert S.size >= 4
    assert np.all(direct[S] > 0)
    np.testing.assert_allclose(fast[S], direct[S], rtol=1e-4)
    monkeypatch.setattr(noise_spread, "MAX_STEP", 1)
    full_rate = noise_variance(parts, {0: sups[0]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[0]
    np.testing.assert_allclose(full_rate[S], direct[S], rtol=1e-6)  # single precision's rounding alone
    monkeypatch.setattr(noise_spread, "DTYPE", np.float64)
    exact = noise_variance(parts, {0: sups[0]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[0]
    np.testing.assert_allclose(exact[S], direct[S], rtol=1e-9)  # the shared transforms' algebra
    # q2_dot = q1 (its one column is its own target): no transforms, variance 0; the formula evaluated
    # directly gives 0 to rounding too (the score q1 (q1 - q1 beta) does not move with the noise)
    S1 = np.flatnonzero(sups[1])
    assert [col_exps[j] for j in S1] == [unc.TARGET_EXPONENTS[1]] and coefs[1][S1[0]] == pytest.approx(1.0)
    assert np.all(noise_variance(parts, {1: sups[1]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[1] == 0)
    # measured 2.7e-37 and 4.8e-35 (0.5 and 5 % noise): a standard error of 1e-17 at most on a coefficient of 1
    assert _direct(parts, {1: sups[1]}, coefs, G, col_exps, unc.TARGET_EXPONENTS)[1][S1] < 1e-20


def _poly_call(polys, y, n, step, m, length, dtype):
    from identify import _polyrows
    from identify.trust.noise_spread import packed_rows

    width = -(-len(range(0, n, step)) // m)
    out = np.full((len(polys), m, length), np.nan, dtype=dtype)
    args = [y, n, step, m, width, *packed_rows(polys), out]
    _polyrows.poly_rows(*args)
    return out, width, args


def _poly_expected(poly, y, n, step, m, length):
    """A row in numpy, double precision: the decimated samples in time order, folded into m components."""
    t = np.arange(0, n, step)
    row = sum(c * np.prod([y[v][t] ** e for v, e in enumerate(k)], axis=0) for k, c in poly.items())
    expected = np.zeros(m * length)
    expected[:t.size] = row  # sample j m + c of the decimated row is component c, column j
    return expected.reshape(length, m).T


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_polynomial_rows_land_in_the_transforms_polyphase_order(dtype):
    """identify/_polyrows.c: rows sum_k c_k y^k of the signals on every step-th sample, component c of a
    row holding the samples (j m + c) step, zero past the record's end and in the padding, against numpy
    in double precision (float64 to rounding, float32 to its own); a constant monomial is zero there too
    (padding, not the constant). Records short and long against the kernel's blocks of 256 columns.
    Buffers of the wrong type or size, and steps that would overflow, are refused with ValueError."""
    from identify import _polyrows

    rng = np.random.default_rng(3)
    polys = [{(1, 2, 0, 0): 2.5, (0, 0, 1, 0): -1.0, (0, 0, 0, 0): 0.75}, {(0, 3, 0, 1): 1e3}, {(0, 0, 0, 0): 1.0},
             {(2, 1, 1, 1): -0.5, (0, 0, 0, 2): 3.0}]
    cases = [(999, 2, 3, 180), (5003, 1, 6, 900), (4099, 3, 2, 1000), (1, 1, 1, 4), (257, 1, 1, 300)]
    for n, step, m, length in cases:  # (5003, 1, 6): 834 columns, four blocks; (999, 2, 3): the last component short
        y = tuple(rng.standard_normal(n) for _ in range(4))
        out, width, args = _poly_call(polys, y, n, step, m, length, dtype)
        for r, p in enumerate(polys):
            expected = _poly_expected(p, y, n, step, m, length)
            if dtype == np.float64:
                np.testing.assert_allclose(out[r], expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
            else:
                np.testing.assert_allclose(out[r], expected, rtol=1e-5, atol=1e-5 * np.abs(expected).max())
        assert np.all(out[2, :, width:] == 0), (n, step, m)  # the padding: zero, not the constant
    out, width, args = _poly_call(polys, tuple(rng.standard_normal(999) for _ in range(4)), 999, 2, 3, 180, dtype)
    assert out[2, 2, width - 1] == 0 and out[2, 0, width - 1] == 1.0  # decimated samples 500 (past the end), 498
    refused = {"width > length": {4: 181}, "signals too short": {1: 2000}, "a step past the record": {2: 2**62},
               "no such monomial": {8: args[8] + 100}, "int64 indices": {5: args[5].astype(np.int64)},
               "float32 coefficients": {9: args[9].astype(np.float32)}, "int32 output": {10: args[10].astype(np.int32)}}
    for why, change in refused.items():
        call = [change.get(i, a) for i, a in enumerate(args)]
        with pytest.raises(ValueError):
            _polyrows.poly_rows(*call)
