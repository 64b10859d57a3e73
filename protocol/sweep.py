"""The shaking table's motion: a linear sine sweep of displacement with smooth fade-in and fade-out.

Part of the rig protocol: the PLC computes it from its setpoints and moves the table along it; the DAQ
checks the same sweep against the limits before it writes them; the simulator synthesizes runs from it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def smoothstep(s: np.ndarray):
    """Quintic fade 0 -> 1 on s in [0, 1] and its first two derivatives (C2: z'' stays continuous)."""
    s = np.clip(s, 0.0, 1.0)
    w = s**3 * (10 - 15 * s + 6 * s**2)
    dw = 30 * s**2 * (1 - s) ** 2
    ddw = 60 * s * (1 - s) * (1 - 2 * s)
    return w, dw, ddw


@dataclass(frozen=True)
class SineSweep:
    """z(t) = amplitude * fade(t) * sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T))) for 0 <= t <= T, else 0.

    f_start_hz, f_end_hz : sweep range; duration_s : T; amplitude_mm : table displacement amplitude;
    fade_s : length of each fade (default: two periods of the start frequency, at most 10 % of T).
    """

    f_start_hz: float = 1.0
    f_end_hz: float = 20.0
    duration_s: float = 60.0
    amplitude_mm: float = 1.3
    fade_s: float | None = None

    def __post_init__(self):
        if not (self.f_start_hz > 0 and self.f_end_hz > 0 and self.duration_s > 0 and self.amplitude_mm >= 0):
            raise ValueError("sweep needs positive frequencies and duration and a non-negative amplitude")

    @property
    def fade(self) -> float:
        if self.fade_s is not None:
            return float(self.fade_s)
        return min(2.0 / min(self.f_start_hz, self.f_end_hz), 0.1 * self.duration_s)

    def frequency_hz(self, t) -> np.ndarray:
        t = np.clip(np.asarray(t, dtype=float), 0, self.duration_s)
        return self.f_start_hz + (self.f_end_hz - self.f_start_hz) * t / self.duration_s

    def kinematics(self, t):
        """Table displacement (m), velocity (m/s) and acceleration (m/s^2) at times t (s), exact."""
        t = np.asarray(t, dtype=float)
        T, f0, f1, A = self.duration_s, self.f_start_hz, self.f_end_hz, self.amplitude_mm * 1e-3
        F = self.fade
        tc = np.clip(t, 0, T)
        phi = 2 * np.pi * (f0 * tc + (f1 - f0) * tc**2 / (2 * T))
        dphi = 2 * np.pi * (f0 + (f1 - f0) * tc / T)
        ddphi = 2 * np.pi * (f1 - f0) / T
        # envelope = fade_in(t / F) * fade_out((T - t) / F): 1 between the fades, so evaluate only there
        w, dw, ddw = np.ones_like(tc), np.zeros_like(tc), np.zeros_like(tc)
        for edge in (tc < F, tc > T - F):
            te = tc[edge]
            w_in, dw_in, ddw_in = smoothstep(te / F)
            w_out, dw_out, ddw_out = smoothstep((T - te) / F)
            w[edge] = w_in * w_out
            dw[edge] = (dw_in * w_out - w_in * dw_out) / F  # d/dt of the fade-out flips sign
            ddw[edge] = (ddw_in * w_out - 2 * dw_in * dw_out + w_in * ddw_out) / F**2
        inside = (t >= 0) & (t <= T)
        s, c = np.sin(phi), np.cos(phi)
        z = A * w * s
        zd = A * (dw * s + w * c * dphi)
        zdd = A * (ddw * s + 2 * dw * c * dphi + w * (c * ddphi - s * dphi**2))
        return tuple(np.where(inside, v, 0.0) for v in (z, zd, zdd))
