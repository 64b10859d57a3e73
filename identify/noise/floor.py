"""The sensor-noise floor: how much white noise the sensors put on a record, read from Welch spectra.

One estimator (spectral.noise_level): a quantile of the Welch bins divided by that quantile of a noise
bin's own chi-square distribution, so the level is the noise's mean PSD whatever the number of segments.
Every floor of the identification reads it:
- the band search (identify.chain.band.band_from_psd): the whole spectrum's low decile (the band may fill
  most bins), the threshold EXCITATION_MARGIN_DB over it;
- the channels' white-noise std (noise_std): the median of the bins from NOISE_FLOOR_ABOVE x the band's
  top to NOISE_FLOOR_BELOW x Nyquist, which the chain bias and the noise's share of the variance use
  (identify.trust.uncertainty.noise_floors);
- the gap's floor (noise_floor): the NRMSE that measurement noise alone leaves between a perfect model and
  the measured signal, which the discrepancy workflow (identify.explain.workflow) and its report compare the gap
  with (a gap near it cannot be closed by any model). Read above the band twice, in frequency (the median
  bin) and in time (the quiet windows, quiet_level), and the lower kept: both are upper estimates of the
  same white noise, each lifted by a different kind of rig content (see quiet_level).
"""
from __future__ import annotations

import numpy as np

from ..chain.band import excited_band
from ..chain.states import StateSignals, band_gain
from ..data.recording import Recording
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq

from ..chain.spectral import level_from_quantile, noise_level, welch_psd, welch_segments

#: The noise floor is read above this multiple of the band top (past the band edge's roll-off, 1.25 f_hi).
NOISE_FLOOR_ABOVE = 1.3
#: ... up to this fraction of Nyquist (anti-alias filters roll off beyond).
NOISE_FLOOR_BELOW = 0.95
#: Welch segment length of the gap's floor (noise_floor): 0.5 Hz bins at 2048 Hz, dozens of segments.
GAP_FLOOR_SEGMENT = 4096
#: The gap floor's reading in time (quiet_level): the signal above the band in windows of this many samples
#: (16-31 ms at 1000-2048 Hz, shorter than the half period of any excitation in a band up to 25 Hz) ...
GAP_FLOOR_WINDOW = 32
#: ... and the low decile of their power (as the band search reads the low decile of its bins).
GAP_FLOOR_QUIET = 0.1


def noise_std(f: np.ndarray, p: np.ndarray, segments: int, fs_hz: float, band_hz) -> float | None:
    """Std of white noise from a Welch spectrum p on the bins f (Hz), the mean over `segments` segments:
    noise_level's median over NOISE_FLOOR_ABOVE f_hi .. NOISE_FLOOR_BELOW Nyquist, robust to a stray
    harmonic. None when the band leaves less than a tenth of the spectrum above it to read the floor from."""
    nyq = fs_hz / 2
    lo, hi = NOISE_FLOOR_ABOVE * band_hz[1], NOISE_FLOOR_BELOW * nyq
    if hi - lo < 0.1 * nyq:
        return None
    sel = (f >= lo) & (f <= hi)
    if np.count_nonzero(sel) < 8:
        return None
    return float(np.sqrt(noise_level(p[sel], segments) * nyq))


def quiet_level(x: np.ndarray, fs_hz: float, above_hz: float) -> float:
    """The one-sided PSD of the white noise under x's content above `above_hz`, read in time: x high-passed
    there (a spectral mask), its power in windows of GAP_FLOOR_WINDOW samples, the GAP_FLOOR_QUIET quantile
    of it over that quantile of a noise window's own chi-square (share x window degrees of freedom, the
    share of the spectrum kept). inf when the record holds fewer than 10 windows.

    Why in time as well: rig content above the band that comes in bursts (a friction's stick-slip at every
    velocity reversal, an end stop's impacts) fills the spectrum broadband and lifts the median bin (a
    Coulomb friction's record read 1.9-4.6x the floor of the same rig without it, benchmarks/results/
    explain_robustness-3434713352.json), but leaves quiet windows between the bursts: read in them, the same
    records came to 1.3-1.5x; content that lasts (a hardening spring's harmonics near resonance) lifts the
    quiet windows and leaves the median bin. On records with neither the two readings agree within ~2 %."""
    n = x.size
    if n < 10 * GAP_FLOOR_WINDOW:
        return np.inf
    nfft = next_fast_len(n, real=True)
    f = rfftfreq(nfft, 1.0 / fs_hz)
    keep = f > above_hz
    high = irfft(rfft(x - x.mean(), nfft) * keep, nfft)[:n]
    m = n // GAP_FLOOR_WINDOW
    power = np.mean(high[:m * GAP_FLOOR_WINDOW].reshape(m, GAP_FLOOR_WINDOW) ** 2, axis=1)
    share = np.count_nonzero(keep) / f.size
    variance = level_from_quantile(power, GAP_FLOOR_QUIET, max(share * GAP_FLOOR_WINDOW, 1.0))
    return variance / (share * fs_hz / 2) if share > 0 else np.inf


def noise_floor(rec: Recording, sig: StateSignals, rows: np.ndarray) -> float:
    """Upper estimate of the noise NRMSE of the gap signal (q'' for base layouts, y for force layouts).

    Base: above the band the raw q'' = x'' - z'' holds only the two accelerometers' noise; its level
    there (noise_level, the median of the bins above NOISE_FLOOR_ABOVE x the band's top) times the band
    operator's noise bandwidth is the noise variance in the measured q''. The table sensor's noise also
    drives the simulation and partly cancels (a perfect model's NRMSE is ~80 % of this). Force: the
    output's level above the input's excited band (where only noise and the nonlinearity's weak
    harmonics are): an upper estimate too, as the harmonics count as noise. The level is the lower of the
    median bin and the quiet windows in time (quiet_level). 0 when there is no room above the band (fewer
    than 8 bins)."""
    fs, (lo, hi) = sig.fs_hz, sig.band_hz
    v = sig.valid
    if rec.layout == "base":
        raw = (rec.output - rec.input)[v]
        target = sig.q1_dot[v][rows]
        region_lo = min(NOISE_FLOOR_ABOVE * hi, 0.9 * fs / 2)
    else:
        raw = rec.output[v]
        target = sig.q2[v][rows]
        region_lo = min(1.2 * excited_band(rec.input, fs)[1], 0.9 * fs / 2)
    nper = int(min(raw.size, GAP_FLOOR_SEGMENT))
    f, p = welch_psd(raw, fs, nper)
    region = f > region_lo
    if np.count_nonzero(region) < 8:
        return 0.0
    gain = band_gain(f, (lo, hi), fs)
    level = min(noise_level(p[region], welch_segments(raw.size, nper)), quiet_level(raw, fs, region_lo))
    variance = level * np.sum(gain**2) * (f[1] - f[0])
    spread = np.std(target)
    return float(np.sqrt(variance) / spread) if spread > 0 else 0.0
