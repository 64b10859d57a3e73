"""The one noise-floor estimator (identify.chain.spectral.noise_level, identify.noise.floor): the level of white noise
of known variance, from few Welch segments as from many, by the median and by the low decile."""
import numpy as np
import pytest

from identify.noise.floor import noise_floor, noise_std
from identify.chain.spectral import noise_level, welch_psd, welch_segments


@pytest.mark.parametrize("n, nper", [(4096, 1024), (400_000, 1024)])  # 7 and ~780 segments
@pytest.mark.parametrize("quantile", [0.5, 0.1])
def test_noise_level_is_the_white_noise_psd(n, nper, quantile):
    """White noise of std s at fs has a one-sided PSD of s^2 / (fs / 2) on every bin: the quantile over
    the chi-square's own quantile gives it for 7 segments as for 780 (undivided, the 7-segment low
    decile reads ~0.5 of it). Averaged over 20 fresh records so the check is on the estimator's bias,
    within 4 % (the spread of the 20-record mean of the 7-segment median is ~1.5 %)."""
    rng = np.random.default_rng()
    fs, s = 1000.0, 0.3
    levels = []
    for _ in range(20):
        f, p = welch_psd(s * rng.standard_normal(n), fs, nper)
        levels.append(noise_level(p[1:-1], welch_segments(n, nper), quantile))
    assert np.mean(levels) == pytest.approx(s**2 / (fs / 2), rel=0.04)


def test_noise_std_needs_room_above_the_band():
    rng = np.random.default_rng()
    x = 0.1 * rng.standard_normal(20000)
    f, p = welch_psd(x, 1000.0, 1024)
    segments = welch_segments(x.size, 1024)
    assert noise_std(f, p, segments, 1000.0, (1.0, 100.0)) == pytest.approx(0.1, rel=0.05)
    assert noise_std(f, p, segments, 1000.0, (1.0, 400.0)) is None  # band top 400 Hz x 1.3 is past 0.95 Nyquist


def test_gap_floor_of_white_noise_is_its_share_in_the_band():
    """A base-layout record whose response is white noise alone: the gap's floor is the noise's RMS
    through the band over the target's spread, here sqrt(in-band share of the bandwidth) / 1 within the
    band's roll-off (the target is the same noise band-limited)."""
    from identify.chain.states import reconstruct_states
    from identify.data.recording import Recording

    rng = np.random.default_rng()
    fs, n = 1000.0, 200_000
    t = np.arange(n) / fs
    zdd = np.sin(2 * np.pi * (1.0 + 0.05 * t) * t)  # a 1-11 Hz chirp, the input
    rec = Recording(zdd, zdd + 0.01 * rng.standard_normal(n), fs, layout="base")
    sig = reconstruct_states(rec, band_hz=(1.0, 60.0))
    rows = np.ones(sig.valid.stop - sig.valid.start, dtype=bool)
    floor = noise_floor(rec, sig, rows)
    # the target q1_dot is the band-limited noise itself: its NRMSE against its own noise is ~1
    assert floor == pytest.approx(1.0, rel=0.08)
