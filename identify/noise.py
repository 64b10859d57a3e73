"""The sensor-noise floor of the gap: the NRMSE that measurement noise alone leaves between a perfect model
and the measured signal. A gap near it cannot be closed by any model; the discrepancy workflow answers
`none` within ~2x of it."""
from __future__ import annotations

import numpy as np
from scipy.signal import welch

from .band import excited_band
from .chain import StateSignals, band_gain
from .recording import Recording


def noise_floor(rec: Recording, sig: StateSignals, rows: np.ndarray) -> float:
    """Upper estimate of the noise NRMSE of the gap signal (q'' for base layouts, y for force layouts).

    Base: above the band the raw q'' = x'' - z'' holds only the two accelerometers' noise; its PSD
    there times the band operator's noise bandwidth is the noise variance in the measured q''. The
    table sensor's noise also drives the simulation and partly cancels (a perfect model's NRMSE is
    ~80 % of this). Force: the output's PSD above the input's excited band (where only noise and the
    nonlinearity's weak harmonics are) times the band's width: an upper estimate too, as the harmonics
    count as noise. 0 when there is no room above the band."""
    fs, (lo, hi) = sig.fs_hz, sig.band_hz
    v = sig.valid
    if rec.layout == "base":
        raw = (rec.output - rec.input)[v]
        target = sig.q1_dot[v][rows]
        region_lo = min(1.3 * hi, 0.9 * fs / 2)
    else:
        raw = rec.output[v]
        target = sig.q2[v][rows]
        region_lo = min(1.2 * excited_band(rec.input, fs)[1], 0.9 * fs / 2)
    f, p = welch(raw, fs, nperseg=min(raw.size, 4096))
    region = f > region_lo
    if np.count_nonzero(region) < 8:
        return 0.0
    gain = band_gain(f, (lo, hi), fs)
    variance = np.median(p[region]) * np.sum(gain**2) * (f[1] - f[0])
    spread = np.std(target)
    return float(np.sqrt(variance) / spread) if spread > 0 else 0.0
