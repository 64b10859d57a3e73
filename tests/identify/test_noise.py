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


def _bursts(rng, n: int, fs: float, every_s: float, amplitude: float) -> np.ndarray:
    """A ringing burst (200-400 Hz, 3 ms decay) at random times, one per `every_s` on average: broadband
    content in time-limited bursts, as a friction's stick-slip or an end stop's impacts put above the band
    under a sweep (bursts at a fixed period would make lines, which the median bin ignores)."""
    t = np.arange(int(0.03 * fs)) / fs
    x = np.zeros(n)
    for a in np.sort(rng.integers(0, n - t.size, int(n / fs / every_s))):
        x[a:a + t.size] += amplitude * np.exp(-t / 0.003) * np.sin(2 * np.pi * rng.uniform(200, 400) * t)
    return x


def test_quiet_level_reads_the_noise_between_bursts():
    """White noise of std s (PSD s^2 / (fs / 2)) alone: the quiet windows read its level within 4 % (mean
    of 10 fresh records; the low decile over ~6000 windows spreads ~2 % per record), as the median bin does.
    With bursts every 60 ms on average (10x the noise's std at their peak) the median bin reads the level more than
    1.5x too high (seen: 2.4-2.5x), the quiet windows 0.95-1.25x (seen: 1.13-1.16x; the windows a burst's
    tail reaches are not quiet), so the gap's floor (the lower reading) follows the noise, not the bursts."""
    from identify.noise.floor import quiet_level

    rng = np.random.default_rng()
    fs, s, n, nper = 1000.0, 0.1, 200_000, 1024
    truth = s**2 / (fs / 2)
    plain, spectral, quiet = [], [], []
    for _ in range(10):
        x = s * rng.standard_normal(n)
        plain.append(quiet_level(x, fs, 130.0))
        y = x + _bursts(rng, n, fs, 0.06, 10 * s)
        f, p = welch_psd(y, fs, nper)
        spectral.append(noise_level(p[f > 130.0], welch_segments(n, nper)))
        quiet.append(quiet_level(y, fs, 130.0))
    assert np.mean(plain) == pytest.approx(truth, rel=0.04)
    assert np.mean(spectral) > 1.5 * truth
    assert 0.95 * truth < np.mean(quiet) < 1.25 * truth
    assert quiet_level(x[:100], fs, 130.0) == np.inf  # fewer than 10 windows: no reading
