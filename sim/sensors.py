"""Accelerometer model: scale, bias, white noise, ADC quantisation and clipping, the sensor faults of
the discrepancy suite (sim/scenarios.py): a gain error, a delay, a drifting bias, and its measurement
nuisances: mains hum and an N-bit converter ranged to the record."""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

#: The fault and nuisance fields; their defaults are a healthy, ideal sensor. The hum's frequency and phase
#: belong to hum_fraction.
FAULT_FIELDS = ("gain", "delay_s", "bias_drift_ms2", "hum_fraction", "adc_bits")


@dataclass
class Accelerometer:
    """noise_fraction : white-noise std as a fraction of the channel's own std (0.005 = 0.5 %);
    noise_ms2 : absolute noise std (m/s^2), added to the above; bias_ms2 : constant offset;
    lsb_ms2 : ADC step (0 = ideal); range_ms2 : clipping level (inf = none).

    Faults (defaults: none, and then the readings are the fault-free ones sample for sample):
    gain : the sensor's true sensitivity over its nominal one (1.02: reads 2 % high);
    delay_s : the reading at t is the acceleration at t - delay_s (s, >= 0; fractional samples, exact: see
        `measure`); a delay on one of two channels is the inter-channel delay;
    bias_drift_ms2 : the bias changes linearly by this much (m/s^2) from the first to the last sample.
    The noise std stays a fraction of the true signal's std (the fault does not change the noise).

    Nuisances (defaults: none):
    hum_fraction : mains hum, a sine of RMS hum_fraction x the true signal's std at hum_hz (50 or 60 Hz)
        and phase hum_phase_rad at the first sample, picked up before the converter;
    adc_bits : the readings quantised by an adc_bits converter whose full scale is the record's largest
        |reading| (the best a range setting can do): step 2 max|y| / 2^adc_bits (0 = ideal)."""

    noise_fraction: float = 0.005
    noise_ms2: float = 0.0
    bias_ms2: float = 0.0
    lsb_ms2: float = 0.0
    range_ms2: float = np.inf
    gain: float = 1.0
    delay_s: float = 0.0
    bias_drift_ms2: float = 0.0
    hum_fraction: float = 0.0
    hum_hz: float = 50.0
    hum_phase_rad: float = 0.0
    adc_bits: int = 0

    def __post_init__(self):
        if not (0 <= self.delay_s < np.inf and np.isfinite(self.gain) and np.isfinite(self.bias_drift_ms2)):
            raise ValueError(f"sensor delay_s must be >= 0 and finite, gain and bias_drift_ms2 finite "
                             f"(got {self.delay_s}, {self.gain}, {self.bias_drift_ms2})")
        if not (0 <= self.hum_fraction < np.inf and self.hum_hz > 0 and np.isfinite(self.hum_phase_rad)):
            raise ValueError(f"sensor hum_fraction must be >= 0 and finite, hum_hz positive (got "
                             f"{self.hum_fraction}, {self.hum_hz})")
        if not (self.adc_bits == 0 or 2 <= self.adc_bits <= 32):
            raise ValueError(f"sensor adc_bits must be 0 (ideal) or 2-32, got {self.adc_bits}")

    def faults(self) -> dict:
        """The fault and nuisance fields that differ from a healthy, ideal sensor (for a recording's truth);
        the hum's frequency and phase are listed with its fraction."""
        healthy = {f.name: f.default for f in fields(self)}
        out = {k: getattr(self, k) for k in FAULT_FIELDS if getattr(self, k) != healthy[k]}
        if self.hum_fraction:
            out.update(hum_hz=self.hum_hz, hum_phase_rad=self.hum_phase_rad)
        return out

    def measure(self, true_ms2: np.ndarray, rng: np.random.Generator, fs_hz: float | None = None,
                delayed_ms2: np.ndarray | None = None) -> np.ndarray:
        """Readings (m/s^2) of the true acceleration: beyond the range they read the range (clipped),
        and follow the motion again as soon as it is back inside. A non-finite input is refused: no
        reading may stand in for a physics that failed.

        With a delay, `delayed_ms2` is the true acceleration at t - delay_s when the caller has it exactly
        (run_sweep: the sweep's analytic table motion; the mass re-simulated under the delayed input);
        without it the signal (sampled at `fs_hz`) is delayed in the frequency domain, exp(-i w delay) on
        the zero-padded record: exact only for a band-limited signal that starts and ends at rest (a
        record cut while the mass still rings is off near its end: 0.4 % of the peak at 0.5 s settling,
        tests/sim/test_effects_physics.py)."""
        x = np.asarray(true_ms2, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError(f"accelerometer input not finite ({np.count_nonzero(~np.isfinite(x))} samples)")
        std = np.hypot(self.noise_fraction * np.std(x), self.noise_ms2)
        seen = x
        if self.delay_s:
            if not fs_hz and delayed_ms2 is None:
                raise ValueError("a sensor delay needs the sample rate fs_hz")
            seen = np.asarray(delayed_ms2, dtype=float) if delayed_ms2 is not None else delay(x, self.delay_s * fs_hz)
        if self.gain != 1.0:
            seen = self.gain * seen
        y = seen + self.bias_ms2 + std * rng.standard_normal(x.shape)
        if self.bias_drift_ms2:
            y = y + self.bias_drift_ms2 * np.linspace(0.0, 1.0, x.size)
        if self.hum_fraction:
            if not fs_hz:
                raise ValueError("mains hum needs the sample rate fs_hz")
            t = np.arange(x.size) / fs_hz
            y = y + self.hum_fraction * np.std(x) * np.sqrt(2) * np.sin(2 * np.pi * self.hum_hz * t + self.hum_phase_rad)
        if self.adc_bits:
            step = 2 * np.max(np.abs(y)) / 2**self.adc_bits
            y = step * np.round(y / step) if step > 0 else y
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
    nyquist = spec[-1].real  # n_fft is even: the Nyquist bin of a real signal is real
    spec *= np.exp(-2j * np.pi * np.fft.rfftfreq(n_fft) * samples)
    spec[-1] = nyquist * np.cos(np.pi * samples)  # and stays real: the real part of its delayed value
    return np.fft.irfft(spec, n_fft)[:n]
