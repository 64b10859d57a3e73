"""Accelerometer model: scale, bias, white noise, ADC quantisation and clipping."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Accelerometer:
    """noise_fraction : white-noise std as a fraction of the channel's own std (0.005 = 0.5 %);
    noise_ms2 : absolute noise std (m/s^2), added to the above; bias_ms2 : constant offset;
    lsb_ms2 : ADC step (0 = ideal); range_ms2 : clipping level (inf = none)."""

    noise_fraction: float = 0.005
    noise_ms2: float = 0.0
    bias_ms2: float = 0.0
    lsb_ms2: float = 0.0
    range_ms2: float = np.inf

    def measure(self, true_ms2: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Readings (m/s^2) of the true acceleration: beyond the range they read the range (clipped),
        and follow the motion again as soon as it is back inside. A non-finite input is refused: no
        reading may stand in for a physics that failed."""
        x = np.asarray(true_ms2, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError(f"accelerometer input not finite ({np.count_nonzero(~np.isfinite(x))} samples)")
        std = np.hypot(self.noise_fraction * np.std(x), self.noise_ms2)
        y = x + self.bias_ms2 + std * rng.standard_normal(x.shape)
        if self.lsb_ms2 > 0:
            y = self.lsb_ms2 * np.round(y / self.lsb_ms2)
        return np.clip(y, -self.range_ms2, self.range_ms2)
