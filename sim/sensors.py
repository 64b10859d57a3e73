"""Accelerometer model: scale, bias, white noise, ADC quantisation and clipping, and the sensor faults of
the discrepancy suite (sim/scenarios.py): a gain error, a delay, a drifting bias."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class Accelerometer:
    """noise_fraction : white-noise std as a fraction of the channel's own std (0.005 = 0.5 %);
    noise_ms2 : absolute noise std (m/s^2), added to the above; bias_ms2 : constant offset;
    lsb_ms2 : ADC step (0 = ideal); range_ms2 : clipping level (inf = none).

    Faults (defaults: none, and then the readings are the fault-free ones sample for sample):
    gain : the sensor's true sensitivity over its nominal one (1.02: reads 2 % high);
    delay_s : the reading at t is the acceleration at t - delay_s (s; fractional samples, exact: see
        `measure`); a delay on one of two channels is the inter-channel delay;
    bias_drift_ms2 : the bias changes linearly by this much (m/s^2) from the first to the last sample.
    The noise std stays a fraction of the true signal's std (the fault does not change the noise)."""

    noise_fraction: float = 0.005
    noise_ms2: float = 0.0
    bias_ms2: float = 0.0
    lsb_ms2: float = 0.0
    range_ms2: float = np.inf
    gain: float = 1.0
    delay_s: float = 0.0
    bias_drift_ms2: float = 0.0

    def faults(self) -> dict:
        """The fault fields that differ from a healthy sensor (for a recording's truth)."""
        return {k: v for k, v in (("gain", self.gain), ("delay_s", self.delay_s),
                                  ("bias_drift_ms2", self.bias_drift_ms2)) if v != (1.0 if k == "gain" else 0.0)}

    def measure(self, true_ms2: np.ndarray, rng: np.random.Generator, fs_hz: float | None = None,
                true_at: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """Readings (m/s^2) of the true acceleration: beyond the range they read the range (clipped),
        and follow the motion again as soon as it is back inside. A non-finite input is refused: no
        reading may stand in for a physics that failed.

        A delay needs `fs_hz` (sample rate of `true_ms2`): with `true_at` (the true acceleration as a
        function of time, s, e.g. the sweep's analytic table motion) the delayed signal is evaluated
        exactly; otherwise it is delayed in the frequency domain (exp(-i w delay) on the zero-padded
        record), exact for a band-limited signal that starts and ends at rest, as a swept record
        with its settling time does."""
        x = np.asarray(true_ms2, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError(f"accelerometer input not finite ({np.count_nonzero(~np.isfinite(x))} samples)")
        std = np.hypot(self.noise_fraction * np.std(x), self.noise_ms2)
        seen = x
        if self.delay_s:
            if not fs_hz:
                raise ValueError("a sensor delay needs the sample rate fs_hz")
            seen = (np.asarray(true_at(np.arange(x.size) / fs_hz - self.delay_s), dtype=float) if true_at
                    else delay(x, self.delay_s * fs_hz))
        if self.gain != 1.0:
            seen = self.gain * seen
        y = seen + self.bias_ms2 + std * rng.standard_normal(x.shape)
        if self.bias_drift_ms2:
            y = y + self.bias_drift_ms2 * np.linspace(0.0, 1.0, x.size)
        if self.lsb_ms2 > 0:
            y = self.lsb_ms2 * np.round(y / self.lsb_ms2)
        return np.clip(y, -self.range_ms2, self.range_ms2)


def delay(x: np.ndarray, samples: float) -> np.ndarray:
    """x delayed by a (fractional) number of samples, band-limited: y[n] = x(n - samples), with x taken
    as zero outside the record (padded to at least twice its length, so nothing wraps around)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    n_fft = 1 << int(np.ceil(np.log2(max(2 * n, 2) + abs(samples) + 1)))
    spec = np.fft.rfft(x, n_fft)
    spec *= np.exp(-2j * np.pi * np.fft.rfftfreq(n_fft) * samples)
    if n_fft % 2 == 0:  # the Nyquist bin of a real signal stays real: its half-sample phase is ambiguous
        spec[-1] = spec[-1].real * np.cos(np.pi * samples)
    return np.fft.irfft(spec, n_fft)[:n]
