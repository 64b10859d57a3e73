"""Measurement chain: band-limited integration and differentiation on signals with known integrals."""
import numpy as np
import pytest

from identify.chain.band import excited_band
from identify.chain.states import reconstruct_states, spectral_op
from identify.errors import IdentificationError
from identify.data.recording import Recording

FS = 2048.0


def _multitone(t, freqs, amps, phases):
    """Displacement made of tones, and its exact velocity and acceleration."""
    q = sum(a * np.sin(2 * np.pi * f * t + p) for f, a, p in zip(freqs, amps, phases))
    v = sum(a * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for f, a, p in zip(freqs, amps, phases))
    acc = sum(-a * (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t + p) for f, a, p in zip(freqs, amps, phases))
    return q, v, acc


def _max_err_mod_line(t, est, true):
    e = est - true
    e -= np.polyval(np.polyfit(t, e, 1), t)
    return np.max(np.abs(e))


def test_integration_recovers_velocity_and_displacement_of_in_band_tones():
    """Non-periodic record (tones not on FFT bins, nonzero at the edges), plus an accelerometer bias."""
    t = np.arange(int(30 * FS)) / FS
    q, v, acc = _multitone(t, [2.3, 5.71, 13.9], [3e-3, 1e-3, 2e-4], [0.3, 1.1, 2.0])
    table = 5.0 * np.sin(2 * np.pi * 4.4 * t) * np.exp(-((t - 15) / 8) ** 2)  # anything: cancels out
    bias = 0.05
    rec = Recording(table, acc + table + bias, FS, "base")
    s = reconstruct_states(rec, band_hz=(1.0, 40.0))
    v_ok = s.valid
    assert v_ok.start < 0.2 * t.size  # live edges: taper + 3 periods of f_lo trimmed, not the record
    # an acceleration record fixes displacement only up to a + b t: compare modulo that
    assert _max_err_mod_line(t[v_ok], s.q2[v_ok], q[v_ok]) < 2e-3 * np.max(np.abs(q))
    assert _max_err_mod_line(t[v_ok], s.q1[v_ok], v[v_ok]) < 2e-3 * np.max(np.abs(v))
    assert np.max(np.abs(s.q1_dot[v_ok] - acc[v_ok])) < 2e-3 * np.max(np.abs(acc))


def test_edges_at_rest_lose_only_the_taper(table1_run):
    s = reconstruct_states(table1_run.recording)
    taper = round(table1_run.recording.fs_hz / s.band_hz[0])
    assert s.valid.start < 1.6 * taper
    assert table1_run.recording.n_samples - s.valid.stop < 1.6 * taper


def test_out_of_band_drift_is_not_integrated():
    t = np.arange(int(20 * FS)) / FS
    q, _, acc = _multitone(t, [6.0], [1e-3], [0.0])
    drift = 0.02 * np.sin(2 * np.pi * 0.05 * t)  # 0.05 Hz: far below the band
    y = spectral_op(acc + drift, FS, (2.0, 50.0), -2, taper_n=int(FS / 2))
    inner = slice(int(2 * FS), int(18 * FS))
    # the drift alone, integrated twice, would be 0.02 / (2 pi 0.05)^2 = 0.2 m
    assert _max_err_mod_line(t[inner], y[inner], q[inner]) < 1e-2 * np.max(np.abs(q))


def test_differentiation_of_displacement_output():
    t = np.arange(int(20 * 610.35)) / 610.35
    q, v, acc = _multitone(t, [10.0, 37.0, 68.0], [0.1, 0.05, 0.02], [0.1, 0.7, 1.9])
    rec = Recording(np.sin(2 * np.pi * 11 * t), q + 0.01, 610.35, "force", "u", "y")
    s = reconstruct_states(rec, band_hz=(0.0, 200.0))
    ok = s.valid
    assert np.max(np.abs(s.q2[ok] - (q[ok] + 0.01))) < 1e-3 * np.max(np.abs(q))  # DC kept for force inputs
    assert np.max(np.abs(s.q1[ok] - v[ok])) < 1e-3 * np.max(np.abs(v))
    assert np.max(np.abs(s.q1_dot[ok] - acc[ok])) < 1e-3 * np.max(np.abs(acc))


def test_excited_band_of_a_sweep(table1_run):
    lo, hi = excited_band(table1_run.recording.input, FS)
    assert 0.7 < lo < 1.5 and 19.0 < hi < 22.0


def test_bad_band_and_short_records_are_refused():
    t = np.arange(4096) / FS
    rec = Recording(np.sin(2 * np.pi * 5 * t), 2 * np.sin(2 * np.pi * 5 * t), FS)
    with pytest.raises(IdentificationError, match="f_lo > 0"):
        reconstruct_states(rec, band_hz=(0.0, 50.0))
    with pytest.raises(IdentificationError, match="Nyquist"):
        reconstruct_states(rec, band_hz=(1.0, 5000.0))
    with pytest.raises(IdentificationError, match="too short"):
        reconstruct_states(rec.slice(0, 600), band_hz=(0.2, 50.0), taper_s=1.0)


@pytest.mark.parametrize("substeps", [1, 2])
def test_input_between_samples_is_the_band_limited_inputs_own(substeps):
    """StateSignals.input_fine: the chain's input is a trigonometric polynomial on the band's bins, so its
    values at the RK4 half steps are that polynomial's, exactly: equal to the spectrum transformed on a
    2 substeps times finer grid (scipy, zero-padded; measured 6e-16), the samples themselves kept bit for
    bit. For an in-band tone that is the tone itself away from the tapered edges (measured 4.6e-9 of a
    0.7 amplitude), where the windowed-sinc interpolation of the samples (fine_grid_input) is off by
    3.6-4.5e-4 (it scales the samples themselves by 1.0005)."""
    from dataclasses import replace

    from scipy.fft import irfft

    from identify.simulation.simulate import fine_grid_input
    t = np.arange(int(20 * FS)) / FS
    tone = 0.7 * np.sin(2 * np.pi * 6.3 * t + 0.4)
    table = tone * np.sin(np.pi * t / 20) ** 2  # faded in and out
    rec = Recording(table, 1.3 * table, FS, "base")
    s = reconstruct_states(rec, band_hz=(1.0, 40.0), dtype=np.float64)  # exactness: to double rounding
    v, up = s.valid, 2 * substeps
    fine = s.input_fine(substeps)[:, 0]
    n = v.stop - v.start
    assert fine.shape == ((n - 1) * up + 1,) and np.array_equal(fine[::up], s.input[v])
    spec = s.input_spectrum
    reference = up * irfft(spec.bins, up * spec.nfft)[v.start * up:(v.stop - 1) * up + 1]
    assert np.max(np.abs(fine - reference)) < 1e-12 * np.max(np.abs(reference))
    # against the tone itself, in the record's middle (away from the taper and the fades)
    tf = (v.start + np.arange(fine.size) / up) / FS
    inner = (tf > 5) & (tf < 15)
    truth = 0.7 * np.sin(2 * np.pi * 6.3 * tf + 0.4) * np.sin(np.pi * tf / 20) ** 2
    err = np.max(np.abs(fine - truth)[inner])
    filtered = np.max(np.abs(fine_grid_input(s.input[v], substeps)[:, 0] - truth)[inner])
    assert err < 1e-7 and filtered > 100 * err, (err, filtered)
    # in the default single-precision transforms: the same values to its rounding
    single = reconstruct_states(rec, band_hz=(1.0, 40.0)).input_fine(substeps)[:, 0]
    assert 0 < np.max(np.abs(single - fine)) < 1e-6 * np.max(np.abs(fine))
    # an input replaced after the chain (noise added, say) is interpolated, not taken from a stale spectrum
    noisy = replace(s, input=s.input + 1e-3)
    assert np.array_equal(noisy.input_fine(substeps), fine_grid_input(noisy.input[v], substeps))


@pytest.mark.parametrize("n_extra", [0, 1])  # both parities of the valid rows' intervals
def test_input_grid_of_a_strided_run_holds_what_its_steps_read(n_extra):
    """input_fine(1, stride=2): the samples, and the middle of the last step when it falls between
    samples (from the spectrum at that time: BandLimitedSignal.at), NaN at the half samples no step
    reads; a stride-2 run on it is the run on the full grid, to rounding (that middle is summed over the
    bins instead of transformed)."""
    from identify.model import SparseModel
    from identify.simulation.simulate import simulate
    t = np.arange(int(20 * FS) + n_extra) / FS
    table = 0.7 * np.sin(2 * np.pi * 6.3 * t + 0.4) * np.sin(np.pi * t / t[-1]) ** 2
    s = reconstruct_states(Recording(table, 1.3 * table, FS, "base"), band_hz=(1.0, 40.0))
    v = s.valid
    n = v.stop - v.start
    full, strided = s.input_fine(1), s.input_fine(1, stride=2)
    read = np.zeros(full.shape[0], dtype=bool)
    read[::2] = True
    if (n - 1) % 2:
        read[-2] = True  # the last step, one sample long: its middle is the half sample before the end
    np.testing.assert_allclose(strided[read], full[read], rtol=0, atol=1e-13 * np.max(np.abs(full)))
    assert np.all(np.isnan(strided[~read]))
    model = SparseModel({"q1_dot": {"q1": -3.7, "q2": -971.0, "q2^3": -2.5e6, "zdd": -1.0}, "q2_dot": {"q1": 1.0}})
    runs = [simulate(model, 1 / FS, [0.0, 0.0], inputs_fine=grid, substeps=1, n_samples=n, stride=2).states
            for grid in (full, strided)]
    assert np.all(np.isfinite(runs[1])) and np.allclose(runs[0], runs[1], rtol=0, atol=1e-15)
    # the spectrum evaluated at any time is the transform's interpolation
    spec = s.input_spectrum
    times = np.array([v.start + 0.5, v.start + 1000.25, v.stop - 1.5])
    ref = spec.between_samples([0.5, 0.25], v.stop)
    np.testing.assert_allclose(spec.at(times), [ref[0, v.start], ref[1, v.start + 1000], ref[0, v.stop - 2]],
                               rtol=0, atol=1e-12 * np.max(np.abs(ref)))


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["base", "force"])
def test_single_precision_transforms_add_nothing_beside_a_quiet_sensors_noise(make_run, layout):
    """The chain transforms in single precision (chain.STATE_DTYPE): its rounding acts as white noise of
    ~1e-7 of a channel's scale, imaged by the same linear operators as the sensors' noise. On a quiet
    record, noise at 1e-4 of each channel's std (a 14-bit converter's floor; the simulated rigs' is 5e-3)
    on the noise-free Table 1 sweep, the single-precision states differ from the double ones by < 2 % of
    that noise's image in each state, in RMS (measured 0.1-0.6 %: the noise's variance + < 4e-5), the
    force layout's twice-differentiated q1_dot included."""
    run = make_run(noise=0.0)
    fs = run.recording.fs_hz
    inp = run.recording.input
    out = run.recording.output if layout == "base" else run.states[:, 1]
    band = (1.0, 100.0) if layout == "base" else (0.0, 100.0)
    rng = np.random.default_rng(7)
    quiet = [x + 1e-4 * np.std(x) * rng.standard_normal(x.size) for x in (inp, out)]
    clean = reconstruct_states(Recording(inp, out, fs, layout), band, dtype=np.float64)
    noisy = Recording(*quiet, fs, layout)
    double, single = reconstruct_states(noisy, band, dtype=np.float64), reconstruct_states(noisy, band)
    v = double.valid
    for name in ("q1", "q2", "q1_dot", "input"):
        noise = getattr(double, name)[v] - getattr(clean, name)[v]
        rounding = getattr(single, name)[v] - getattr(double, name)[v]
        ratio = np.sqrt(np.mean(rounding**2) / np.mean(noise**2))
        assert 0 < ratio < 0.02, (name, ratio)
