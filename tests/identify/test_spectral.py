"""The fast FFT mechanics compute what the straightforward formulation computed.

The references below are the chain's previous code, kept verbatim: one scipy welch per signal, and one
padded rfft / irfft pair per (signal, power) with the band gain and (j w)^power evaluated on every bin.
"""
import numpy as np
import pytest
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq
from scipy.signal import welch

from identify.chain import band, states as chain
from identify.chain.band import excited_band
from identify.chain.states import EDGE_FRACTION, band_gain, reconstruct_states, spectral_op, spectral_ops
from identify.data.recording import Recording
from identify.chain.spectral import welch_psd

FS = 2048.0


def _band_gain_before(f, band, fs_hz):
    lo, hi = band
    g = np.ones_like(f)
    if lo > 0:
        a = lo * (1 - EDGE_FRACTION)
        g = np.where(f < lo, 0.5 - 0.5 * np.cos(np.pi * np.clip((f - a) / (lo - a), 0, 1)), g)
    top = min(hi * (1 + EDGE_FRACTION / 2), fs_hz / 2)
    if top > hi:
        g = np.where(f > hi, 0.5 + 0.5 * np.cos(np.pi * np.clip((f - hi) / (top - hi), 0, 1)), g)
    return g


def _spectral_op_before(x, fs_hz, band, power, taper_n):
    """The chain's operator as first written, signal by signal on the whole spectrum, with today's
    detrending (chain.by_mean_alone: the mean alone also for a signal filtered with DC outside the band)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    if power < 0 or (power == 0 and band[0] > 0):
        line = np.full(n, x.mean())
    else:
        line = x[0] + (x[-1] - x[0]) * np.arange(n) / max(n - 1, 1)
    xd = x - line
    if taper_n > 0:
        ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(taper_n) + 0.5) / taper_n)
        xd[:taper_n] *= ramp
        xd[n - taper_n:] *= ramp[::-1]
    nfft = next_fast_len(2 * n, real=True)
    f = rfftfreq(nfft, 1.0 / fs_hz)
    jw = 2j * np.pi * f
    h = _band_gain_before(f, band, fs_hz).astype(complex)
    if power:
        with np.errstate(divide="ignore", invalid="ignore"):
            h *= jw ** power
        h[0] = 0.0 if power < 0 or band[0] > 0 else h[0]
    y = irfft(rfft(xd, nfft) * h, nfft)[:n]
    if band[0] == 0 and power in (0, 1):
        y += line if power == 0 else (x[-1] - x[0]) * fs_hz / max(n - 1, 1)
    return y


def _signal(n, seed=0):
    """A chirp with an offset, a drift and noise: nothing periodic, nothing zero at the edges."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    return (np.sin(2 * np.pi * (1.0 * t + 0.4 * t**2)) + 0.3 + 0.01 * t + 0.02 * rng.standard_normal(n))


def _close(a, b, tol=1e-12):
    return np.max(np.abs(a - b)) <= tol * np.max(np.abs(b))


@pytest.mark.parametrize("n,nperseg", [(50_001, 16384), (20_000, 4096), (3_000, 16384), (4_097, 256)])
def test_welch_psd_is_scipy_welch_with_linear_detrend(n, nperseg):
    x = np.vstack([_signal(n, 1), 5.0 * _signal(n, 2) ** 3])
    for row in x:
        f_ref, p_ref = welch(row, FS, nperseg=min(nperseg, n), detrend="linear")
        f, p = welch_psd(row, FS, nperseg)
        assert np.array_equal(f, f_ref)
        assert _close(p, p_ref)
    f, p2 = welch_psd(x, FS, nperseg)  # several signals in one call: one PSD per row
    assert p2.shape == (2, f.size)
    assert all(_close(p2[k], welch(x[k], FS, nperseg=min(nperseg, n), detrend="linear")[1]) for k in range(2))
    # segments transformed in single precision (excited_band): rounding's share of the largest bin
    f, p32 = welch_psd(x, FS, nperseg, np.float32)
    assert p32.dtype == np.float64 and all(_close(p32[k], p2[k], 1e-6) and not _close(p32[k], p2[k], 1e-12)
                                           for k in range(2))


def test_band_gain_is_unchanged():
    f = rfftfreq(200_000, 1 / FS)
    for band in [(2.5, 106.25), (0.0, 200.0), (1.0, 1000.0), (0.3, 0.9)]:
        assert np.array_equal(band_gain(f, band, FS), _band_gain_before(f, band, FS))


@pytest.mark.parametrize("band", [(2.0, 60.0), (0.0, 80.0)])
@pytest.mark.parametrize("taper_n", [0, 700])
def test_spectral_ops_equal_the_one_signal_operator(band, taper_n):
    """Every power on two signals in one batched call, against the previous per-signal operator."""
    x, u = _signal(30_011, 3), _signal(30_011, 4)
    requests = [(0, -2), (0, -1), (0, 0), (0, 1), (0, 2), (1, 0), (1, -1)]
    out = spectral_ops([x, u], FS, band, requests, taper_n)
    for (i, power), y in zip(requests, out):
        ref = _spectral_op_before((x, u)[i], FS, band, power, taper_n)
        assert _close(y, ref), (i, power)
        assert _close(spectral_op((x, u)[i], FS, band, power, taper_n), ref)


def test_reconstruct_states_equals_the_previous_chain(table1_run, monkeypatch):
    rec = table1_run.recording
    # in double precision: the algorithm against the previous one, to rounding (the default single
    # precision is bounded against the sensors' noise in test_chain.py)
    padded = reconstruct_states(rec, dtype=np.float64)
    monkeypatch.setattr(chain, "PAD_PERIODS", 1e12)  # the previous padding: the record's own length
    s = reconstruct_states(rec, dtype=np.float64)
    # the padding of PAD_PERIODS periods of f_lo moves the states by ~1e-8 of their peak (wrap-around of
    # the operators' decaying impulse responses): 5 orders below the 0.5 % sensor noise of this record
    v = s.valid
    for name in ("q1", "q2", "q1_dot", "input"):
        a, b = getattr(padded, name)[v], getattr(s, name)[v]
        assert np.max(np.abs(a - b)) < 1e-7 * np.max(np.abs(b)), name
    bands = [excited_band(x, rec.fs_hz) for x in (rec.input, rec.output - rec.input)]
    # the bands, estimated with scipy's welch as before (in double precision; excited_band's segments are
    # transformed in single), are the same bands
    monkeypatch.setattr(band, "welch_psd", lambda x, fs, nper, dtype=None: welch(x, fs, nperseg=nper,
                                                                                detrend="linear"))
    assert [excited_band(x, rec.fs_hz) for x in (rec.input, rec.output - rec.input)] == bands
    assert reconstruct_states(rec).band_hz == s.band_hz
    qdd = rec.output - rec.input
    ref = {"q1": _spectral_op_before(qdd, rec.fs_hz, s.band_hz, -1, s.taper_n),
           "q2": _spectral_op_before(qdd, rec.fs_hz, s.band_hz, -2, s.taper_n),
           "q1_dot": _spectral_op_before(qdd, rec.fs_hz, s.band_hz, 0, s.taper_n),
           "input": _spectral_op_before(rec.input, rec.fs_hz, s.band_hz, 0, s.taper_n)}
    for name, y in ref.items():
        assert _close(getattr(s, name), y), name


def test_force_layout_states_equal_the_previous_chain():
    fs = 610.35
    t = np.arange(int(20 * fs)) / fs
    y = 0.1 * np.sin(2 * np.pi * 10 * t) + 0.02 * np.sin(2 * np.pi * 68 * t + 1.9) + 0.01
    rec = Recording(np.sin(2 * np.pi * 11 * t), y, fs, "force", "u", "y")
    s = reconstruct_states(rec, band_hz=(0.0, 200.0), dtype=np.float64)  # double: to rounding
    for name, power in (("q2", 0), ("q1", 1), ("q1_dot", 2)):
        assert _close(getattr(s, name), _spectral_op_before(y, fs, (0.0, 200.0), power, s.taper_n)), name
    assert _close(s.input, _spectral_op_before(rec.input, fs, (0.0, 200.0), 0, s.taper_n))


def _free_run_before(model, sig):
    """identify.simulation.validation.free_run as it was: full right-hand side, one band_limit per signal, in double
    precision (the input between samples and the steps as now: StateSignals.input_fine, choose_step)."""
    from identify.simulation.simulate import choose_step, simulate
    v = sig.valid
    states = sig.states[v]
    u = sig.input[v][:, None]
    scale = 1.5 * np.max(np.abs(states), axis=0)
    subs, stride = choose_step(model, 1.0 / sig.fs_hz, scale)
    res = simulate(model, 1.0 / sig.fs_hz, states[0], inputs_fine=sig.input_fine(subs), substeps=subs,
                   n_samples=u.shape[0], bound=100.0 * float(np.max(scale)), stride=stride)
    qdot = np.full(u.shape[0], np.nan)
    qdot[:res.n_valid] = model.rhs(res.states[:res.n_valid], u[:res.n_valid])[:, 0]
    sim = np.column_stack([sig.band_limit(res.states[:, 0]), sig.band_limit(res.states[:, 1])])
    return sim, sig.band_limit(qdot)


def test_free_run_equals_the_previous_formulation(table1_run, table1_truth):
    """validation.free_run band-limits the simulated displacement and takes the velocity and acceleration
    as its derivatives on the band's bins (as the chain makes q1 and q1_dot from one spectrum), in single
    precision. Against each simulated signal band-limited on its own, in double: the displacement to
    rounding (measured 2.4e-7 of its peak); velocity and acceleration within 1e-5 of their peaks beyond
    3 tapers from the valid rows' ends (measured 1.8e-6, 5.8e-6: the acceleration's figure is the run's
    own, rhs at the samples a stride-2 run interpolates), and within 1e-3 at the ends, where the taper
    shapes each differently (2.8e-4, 1.9e-4)."""
    from identify.model import SparseModel
    from identify.simulation.validation import first_equation, free_run
    sig = reconstruct_states(table1_run.recording)
    model = SparseModel(table1_truth)
    sim, qdot, _, diverged, _ = free_run(model, sig)
    sim_ref, qdot_ref = _free_run_before(model, sig)
    assert not diverged and sim.shape == sim_ref.shape
    assert _close(sim[:, 1], sim_ref[:, 1], 1e-6) and not _close(sim[:, 1], sim_ref[:, 1], 1e-12)
    inside = slice(3 * sig.taper_n, sim.shape[0] - 3 * sig.taper_n)
    for a, b in ((sim[:, 0], sim_ref[:, 0]), (qdot, qdot_ref)):
        assert _close(a[inside], b[inside], 1e-5) and _close(a, b, 1e-3)
    # the first equation alone, for a model whose equations share and do not share terms
    other = SparseModel({"q1_dot": {"1": 0.2, "q1*|q1|": -3.0, "q2^3": -2e6, "zdd": -1.0},
                         "q2_dot": {"q1": 1.0, "q2^2": 5.0}})
    v = sig.valid
    assert _close(first_equation(other, sig.q1[v], sig.q2[v], sig.input[v][:, None]),
                  other.rhs(sig.states[v], sig.input[v][:, None])[:, 0])


def test_band_limit_many_is_band_limit_of_each(table1_run):
    """More signals than one batch holds (explain band-limits a whole library), each as band_limit."""
    sig = reconstruct_states(table1_run.recording)
    v = sig.valid
    xs = [sig.q1[v] ** k * sig.q2[v] for k in range(6)]
    # the same operator with single-precision transforms (the chain's states, chain.STATE_DTYPE)
    singles = spectral_ops(xs, sig.fs_hz, sig.band_hz, [(i, 0) for i in range(len(xs))], sig.taper_n, np.float32)
    for x, y, y32 in zip(xs, sig.band_limit_many(xs), singles):
        assert _close(y, sig.band_limit(x))
        # single-precision transforms: double results, within 1e-6 of the scale
        assert y32.dtype == np.float64 and _close(y32, y, 1e-6) and not _close(y32, y, 1e-12)


def test_band_limit_derivatives_are_the_derivatives_band_limited(table1_run):
    """StateSignals.band_limit_derivatives: one transform of x, times (j w)^p on the band's bins, is the
    band-limited derivative of x for a signal at rest at both ends (a faded multitone: the taper does not
    touch it): within 1e-7 of each derivative's peak in double precision (measured 0, 3.9e-8, 5.1e-8), and
    in single, whose rounding of x's transform (~1e-7 of x) the derivatives multiply by up to (w_top)^p
    (the band's top, 104 Hz here), within 1e-6, 3e-6 and 3e-5 (measured 2.9e-7, 8.9e-7, 1.1e-5)."""
    sig = reconstruct_states(table1_run.recording)
    v = sig.valid
    t = np.arange(v.stop - v.start) / sig.fs_hz
    fade = np.sin(np.pi * t / t[-1]) ** 4
    tones = [(3.1, 1e-3, 0.2), (8.7, 2e-4, 1.0), (17.3, 5e-5, 2.1)]
    x = sum(a * np.sin(2 * np.pi * f * t + p) for f, a, p in tones) * fade
    w = [2 * np.pi * f for f, _, _ in tones]
    s = [np.sin(wi * t + p) for wi, (_, _, p) in zip(w, tones)]
    c = [np.cos(wi * t + p) for wi, (_, _, p) in zip(w, tones)]
    g = np.pi / t[-1]
    f0, f1 = fade, 4 * np.sin(g * t) ** 3 * np.cos(g * t) * g
    f2 = g * g * (12 * np.sin(g * t) ** 2 * np.cos(g * t) ** 2 - 4 * np.sin(g * t) ** 4)
    dx = sum(a * (wi * ci * f0 + si * f1) for (_, a, _), wi, si, ci in zip(tones, w, s, c))
    ddx = sum(a * (-wi * wi * si * f0 + 2 * wi * ci * f1 + si * f2) for (_, a, _), wi, si, ci in zip(tones, w, s, c))
    want = sig.band_limit_many([x, dx, ddx])
    for dtype, tols in ((np.float64, (1e-7, 1e-7, 1e-7)), (np.float32, (1e-6, 3e-6, 3e-5))):
        got = sig.band_limit_derivatives(x, (0, 1, 2), dtype)
        assert all(_close(a, b, tol) for a, b, tol in zip(got, want, tols)), dtype


@pytest.mark.parametrize("n, nfft", [(997, next_fast_len(2 * 997, real=True)),
                                     (30_011, next_fast_len(2 * 30_011, real=True)),
                                     (30_000, 30_000)])  # no padding: every polyphase column whole
@pytest.mark.parametrize("band_share", [1.0, 0.4, 0.13, 0.01])
def test_lowband_transforms_are_the_band_bins_of_the_full_ones(n, nfft, band_share):
    """Polyphase split (M = 1, 2, 6, 8 here) against scipy's full-length transforms, in double precision
    and, forward, in single."""
    from identify.chain.spectral import lowband_irfft, lowband_rfft, polyphase_factor
    k_max = min(int(band_share * nfft / 2), nfft // 2)
    x = np.vstack([_signal(n, 5), _signal(n, 6) ** 2])
    ref = rfft(x, nfft, axis=-1)
    assert _close(lowband_rfft(x, nfft, k_max), ref[:, :k_max + 1], 1e-14)
    single = lowband_rfft(x, nfft, k_max, np.float32)
    assert single.dtype == np.complex64 and _close(single, ref[:, :k_max + 1], 1e-6)
    low = np.zeros_like(ref)
    low[:, :k_max + 1] = ref[:, :k_max + 1]
    y = lowband_irfft(ref[:, :k_max + 1], nfft, n)
    assert y.shape == (2, n) and _close(y, irfft(low, nfft, axis=-1)[:, :n], 1e-14)
    assert (polyphase_factor(nfft, k_max) > 1) == (band_share < 0.5)


def test_forward_and_inverse_transforms_share_their_twiddles():
    """The chain's forward (lowband_rfft, which passes its spectra's dtype) and inverse (lowband_irfft,
    the default) transforms of one record compute the twiddles once: one cache entry per precision,
    however the precision is spelled (a numpy dtype and the scalar type hash differently, and once made
    the chain compute them twice); single precision gets its own, rounded."""
    from identify.chain.spectral import _cached_twiddles, _twiddles, lowband_irfft, lowband_rfft
    n, nfft, k_max = 5000, 12000, 1000
    _cached_twiddles.cache_clear()
    spec = lowband_rfft(np.vstack([_signal(n, 5)]), nfft, k_max)
    lowband_irfft(spec, nfft, n)
    info = _cached_twiddles.cache_info()
    assert (info.misses, info.hits) == (1, 1), info
    assert _twiddles(nfft, 6, k_max) is _twiddles(nfft, 6, k_max, np.dtype(np.complex128))
    single = _twiddles(nfft, 6, k_max, np.complex64)
    assert single.dtype == np.complex64 and single is _twiddles(nfft, 6, k_max, np.dtype("complex64"))
    np.testing.assert_allclose(single, _twiddles(nfft, 6, k_max), atol=1e-7)


def test_twiddles_by_recurrence_match_the_exponentials():
    """The twiddles are built as powers of one row (w^(k r) = (w^k)^r), that row as products of two short
    tables of exponentials; on a million-sample record's transform (M = 8, ~59,000 bins) they stay
    within rounding of exp(-2 pi i (k r mod nfft) / nfft)."""
    from identify.chain.spectral import _twiddles
    nfft, m, k_max = 1_105_920, 8, 58_860
    kr = np.outer(np.arange(m), np.arange(k_max + 1)) % nfft
    exact = np.exp(-2j * np.pi * kr / nfft)
    tw = _twiddles(nfft, m, k_max)
    assert tw.shape == (m, k_max + 1)
    err = np.abs(tw - exact).max()
    assert err < 5e-15, err
    assert np.array_equal(tw[0], np.ones(k_max + 1))


@pytest.mark.parametrize("nfft", [1000, 1001])
def test_bin_weights_are_parsevals(nfft):
    """spectral.bin_weights (BandLimitedNoise's sums over the bins, BandLimitedSignal.at): sum_k w_k |X_k|^2
    / nfft over an rfft's bins is the signal's energy, for an even nfft (a Nyquist bin of weight 1) and an
    odd one (whose last bin has a twin: weight 2)."""
    from identify.chain.spectral import bin_weights
    x = np.random.default_rng(4).standard_normal(nfft)
    spec = rfft(x)
    w = bin_weights(spec.size, nfft)
    assert w[0] == 1.0 and w[-1] == (1.0 if nfft % 2 == 0 else 2.0)
    assert np.isclose(np.sum(w * np.abs(spec) ** 2) / nfft, np.sum(x ** 2), rtol=1e-12)
    assert np.all(bin_weights(10, nfft)[1:] == 2.0)  # the band's bins only: no Nyquist among them
