"""Measurement chain: band-limited integration and differentiation on signals with known integrals."""
import numpy as np
import pytest

from identify.chain import excited_band, reconstruct_states, spectral_op
from identify.errors import IdentificationError
from identify.recording import Recording

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
