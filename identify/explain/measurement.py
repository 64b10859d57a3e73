"""Measurement effects inside the fit: the states a model sees when the recording itself is wrong.

The accelerometer rig records a_x (mass) and a_z (table); the chain integrates q'' = a_x - a_z into the
states (identify.chain.states). What each fault does, for a true mass acceleration x'' and table z'':
- mass gain g_m: a_x = (1 + g_m) x'', so the recorded q''_r = (1 + g_m) q'' + g_m z'', and the states
  integrated from it carry g_m times the table's own motion, which no function of the true states can
  absorb (below resonance q'' ~ 0 but q''_r ~ g_m z''). Its sign moves the apparent damping and the
  jump, which is how a 3 % gain error passed for displacement-dependent damping.
- table gain g_t: a_z = (1 + g_t) z'': the input and, through q''_r, the states are off.
- delay tau of the mass channel: a_x(t) = x''(t - tau), so q''_r = x''(t - tau) - z''(t) ~ q'' - tau x''';
  to first order a term tau d/dt of one channel, a phase error that grows with frequency and looks like
  (energy-injecting) damping to a model of the true states.
- bias drift b: a_x = x'' + b (t/T - 1/2): mostly below the band, but the taper and the band's roll-off
  pass part of a ramp's integral into the states.
- mains hum: a_x = x'' + a cos(2 pi f t) + b sin(2 pi f t) at f = 50 or 60 Hz, inside the band of a
  fast-sampled sweep, where it reads as a misfit at f that no force can make.
The chain is linear, so each channel is integrated once and the corrected states for any fault are
combinations of the parts (delay: the mass channel is shifted by tau in the frequency domain first).
The corrected model predicts the recorded q'' as (1 + g_m) (q''_model - q''_corrected) + q''_recorded,
so candidates are compared on the recorded signal: like with like.
"""
from __future__ import annotations

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq

from ..chain.states import StateSignals, spectral_op
from ..data.recording import Recording

#: Fault parameters and their search bounds: gains +-10 %, delay +-5 ms, drift +-1 m/s^2 over the record;
#: mains hum (identify.explain.effects.mains_hum): its frequency and each channel's cosine and sine amplitudes
#: (m/s^2), fitted by projection, not searched (bounds: what a channel could carry).
PARAMS = {"mass_acc_gain": (-0.1, 0.1), "table_acc_gain": (-0.1, 0.1), "channel_delay": (-5e-3, 5e-3),
          "bias_drift_mass": (-1.0, 1.0), "bias_drift_table": (-1.0, 1.0), "hum_hz": (0.0, 1e3),
          "hum_mass_cos": (-1e3, 1e3), "hum_mass_sin": (-1e3, 1e3), "hum_table_cos": (-1e3, 1e3),
          "hum_table_sin": (-1e3, 1e3)}
ZERO = {k: 0.0 for k in PARAMS}


class ChannelChain:
    """The measurement chain of one base-layout recording, split by channel, so that corrected states
    for any fault parameters cost a few vector operations (a delay: one more chain run of one channel)."""

    def __init__(self, rec: Recording, sig: StateSignals):
        self.rec, self.sig = rec, sig
        self.fs, self.band, self.taper = sig.fs_hz, sig.band_hz, sig.taper_n
        n = rec.n_samples
        self.ramp = np.arange(n) / max(n - 1, 1) - 0.5
        self.X = self._chain(rec.output)
        self.Z = self._chain(rec.input)
        self.R = self._chain(self.ramp)
        self._cache: dict[tuple, StateSignals] = {}
        self._hum: dict[float, tuple] = {}

    def _chain(self, a: np.ndarray) -> np.ndarray:
        """(velocity, displacement, acceleration) of one acceleration channel through the band."""
        return np.stack([spectral_op(a, self.fs, self.band, p, self.taper) for p in (-1, -2, 0)])

    def hum(self, p: dict, channel: str):
        """The chained mains hum of `channel` (a sinusoid at p["hum_hz"]: the chain is linear, so the
        cosine and sine are chained once per frequency); 0 without hum."""
        hz = p.get("hum_hz", 0.0)
        if not hz:
            return 0.0
        pair = self._hum.get(hz)
        if pair is None:
            t = np.arange(self.rec.n_samples) / self.fs
            pair = self._hum[hz] = (self._chain(np.cos(2 * np.pi * hz * t)), self._chain(np.sin(2 * np.pi * hz * t)))
        c, s = pair
        return p.get(f"hum_{channel}_cos", 0.0) * c + p.get(f"hum_{channel}_sin", 0.0) * s

    def shifted(self, a: np.ndarray, tau: float) -> np.ndarray:
        """a(t + tau): a channel recorded tau late, put back in time (frequency-domain shift)."""
        m = a.mean()
        nfft = next_fast_len(2 * a.size, real=True)
        f = rfftfreq(nfft, 1.0 / self.fs)
        return irfft(rfft(a - m, nfft) * np.exp(2j * np.pi * f * tau), nfft)[:a.size] + m

    def signals(self, p: dict) -> StateSignals:
        """States as the rig had them if the recording had the faults `p` (PARAMS keys)."""
        key = tuple(round(float(p.get(k, 0.0)), 12) for k in PARAMS)
        out = self._cache.get(key)  # .get, not `in` then [ ]: map_runs' threads share the cache
        if out is not None:
            return out
        gm, gt = 1 + p.get("mass_acc_gain", 0.0), 1 + p.get("table_acc_gain", 0.0)
        tau = p.get("channel_delay", 0.0)
        X = self._chain(self.shifted(self.rec.output, tau)) if tau else self.X
        X = (X - p.get("bias_drift_mass", 0.0) * self.R - self.hum(p, "mass")) / gm
        Z = (self.Z - p.get("bias_drift_table", 0.0) * self.R - self.hum(p, "table")) / gt
        Q = X - Z
        s = self.sig
        out = StateSignals(Q[0], Q[1], Q[2], Z[2], s.fs_hz, s.band_hz, s.valid, s.input_name, s.taper_n)
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = out
        return out
