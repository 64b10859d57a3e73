"""FFT mechanics of the measurement chain, arranged to do each transform once.

`welch_psd` is scipy.signal.welch with a periodic Hann window, 50 % overlap, linear detrend of every
segment, density scaling and a one-sided mean, for one or several equally long signals: the same
numbers (tests/identify/test_spectral.py: to 1e-12 of the largest bin), at a fraction of the cost,
because the per-segment straight line is a closed-form projection instead of a least-squares solve per
segment, and all segments of all signals go through one batched rfft.
"""
from __future__ import annotations

import numpy as np
from scipy.fft import rfft, rfftfreq


def welch_psd(x: np.ndarray, fs_hz: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and power spectral density ((unit)^2/Hz) of x, shape (n,) or (k, n) (one PSD per row).

    Equal to scipy.signal.welch(x, fs_hz, nperseg=nperseg, detrend="linear", axis=-1)."""
    x = np.asarray(x, dtype=float)
    rows = x[None, :] if x.ndim == 1 else x
    n = rows.shape[-1]
    nperseg = int(min(nperseg, n))
    noverlap = nperseg // 2
    hop = nperseg - noverlap
    n_seg = (n - noverlap) // hop
    # (k, n_seg, nperseg) views of the overlapping segments; the arithmetic below makes one copy
    segs = np.lib.stride_tricks.sliding_window_view(rows, nperseg, axis=-1)[:, ::hop][:, :n_seg]
    # least-squares line per segment: t centred, so mean and slope are independent projections
    t = np.arange(nperseg) - (nperseg - 1) / 2.0
    mean = segs.mean(axis=-1)
    slope = (segs @ t) / (t @ t)
    win = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)  # periodic Hann
    detrended = segs - mean[..., None]
    detrended -= slope[..., None] * t
    detrended *= win
    spec = rfft(detrended, axis=-1)
    power = spec.real**2 + spec.imag**2
    p = power.mean(axis=1) / (fs_hz * float(np.sum(win**2)))
    p[:, 1:-1 if nperseg % 2 == 0 else None] *= 2.0  # one-sided: negative frequencies folded in
    f = rfftfreq(nperseg, 1.0 / fs_hz)
    return f, (p[0] if x.ndim == 1 else p)
