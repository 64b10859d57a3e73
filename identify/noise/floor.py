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
  with (a gap near it cannot be closed by any model).
"""
from __future__ import annotations

import numpy as np

from ..chain.band import excited_band
from ..chain.states import StateSignals, band_gain
from ..data.recording import Recording
from ..chain.spectral import noise_level, welch_psd, welch_segments

#: The noise floor is read above this multiple of the band top (past the band edge's roll-off, 1.25 f_hi).
NOISE_FLOOR_ABOVE = 1.3
#: ... up to this fraction of Nyquist (anti-alias filters roll off beyond).
NOISE_FLOOR_BELOW = 0.95
#: Welch segment length of the gap's floor (noise_floor): 0.5 Hz bins at 2048 Hz, dozens of segments.
GAP_FLOOR_SEGMENT = 4096


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


def noise_floor(rec: Recording, sig: StateSignals, rows: np.ndarray, explained: np.ndarray | None = None) -> float:
    """Upper estimate of the noise NRMSE of the gap signal (q'' for base layouts, y for force layouts).

    Base: above the band the raw q'' = x'' - z'' holds only the two accelerometers' noise; its level
    there (noise_level, the median of the bins above NOISE_FLOOR_ABOVE x the band's top) times the band
    operator's noise bandwidth is the noise variance in the measured q''. The table sensor's noise also
    drives the simulation and partly cancels (a perfect model's NRMSE is ~80 % of this). Force: the
    output's level above the input's excited band (where only noise and the nonlinearity's weak
    harmonics are): an upper estimate too, as the harmonics count as noise. 0 when there is no room
    above the band (fewer than 8 bins). explained (base layout): what a model puts into q'' on the valid
    rows, taken off the raw q'' first, so its own content above the band (a friction's force steps) is not
    read as noise (identify.explain.workflow.DiscrepancyAnalysis._floor_after)."""
    fs, (lo, hi) = sig.fs_hz, sig.band_hz
    v = sig.valid
    if rec.layout == "base":
        raw = (rec.output - rec.input)[v]
        if explained is not None:
            raw = raw - explained
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
    variance = noise_level(p[region], welch_segments(raw.size, nper)) * np.sum(gain**2) * (f[1] - f[0])
    spread = np.std(target)
    return float(np.sqrt(variance) / spread) if spread > 0 else 0.0
