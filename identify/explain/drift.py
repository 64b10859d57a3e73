"""A sensor bias that drifts over the record: seen in the raw channels, never in the gap.

The measurement chain integrates within the excitation band, so an accelerometer whose zero drifts
slowly (thermal drift: a few hundredths of m/s^2 over a minute) leaves the states, and with them the
discrepancy workflow's gap, untouched: no term, physical or measurement, can close a gap the drift does
not cause (the suite's bias drifts left gaps at 0.8-1.0x the noise floor). What the chain throws away
is still in the raw channel, below the band: a sweep has nothing there (it starts at the band's
bottom), white sensor noise has little, and a drifting bias has nearly all of its power there.

So each accelerometer channel is low-passed at half the band's bottom (FFT, zero-padded), averaged over
WINDOWS equal windows of the valid rows, and the window means are regressed on time: the slope x the
record's duration is the bias change, and its t statistic (residual scatter of the window means, which
are ~independent: the low-pass's correlation time, ~1 / f_lo, is shorter than a window) decides.
"""
from __future__ import annotations

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq
from scipy.stats import t as student_t

#: Windows over the valid rows (each some seconds long on a minute's sweep).
WINDOWS = 40
#: |t| above which the trend is reported: far out in the tail (two-sided p ~ 1e-7 at 38 dof), so a
#: clean recording does not get a drift named for its noise.
T_REPORT = 8.0


def bias_trends(recording, sig) -> list[dict]:
    """Per accelerometer channel of a base-excited recording: {"channel", "change_ms2" (bias change from
    the record's first to its last sample, m/s^2, read as a straight line over the valid rows), "se_ms2", "t", "p_value"}. [] for force layouts (no
    accelerometers) or records with too few valid rows for WINDOWS windows."""
    if recording.layout != "base" or sig.band_hz[0] <= 0:
        return []
    v = sig.valid
    n_valid = v.stop - v.start
    if n_valid < WINDOWS * 16:
        return []
    fs, n = recording.fs_hz, recording.input.size
    nfft = next_fast_len(2 * n, real=True)
    keep = rfftfreq(nfft, 1.0 / fs) < 0.5 * sig.band_hz[0]
    edges = np.linspace(v.start, v.stop, WINDOWS + 1).round().astype(int)
    t = 0.5 * (edges[:-1] + edges[1:]) / fs
    duration = (n - 1) / fs  # the change from the record's first to its last sample
    out = []
    for channel, x in (("table", recording.input), ("mass", recording.output)):
        spec = rfft(x - np.mean(x), nfft)
        spec[~keep] = 0.0
        low = irfft(spec, nfft)[:n]
        means = np.add.reduceat(low[v.start:v.stop], edges[:-1] - v.start) / np.diff(edges)
        A = np.column_stack([np.ones_like(t), t - t.mean()])
        coef, *_ = np.linalg.lstsq(A, means, rcond=None)
        resid = means - A @ coef
        dof = WINDOWS - 2
        se_slope = np.sqrt(resid @ resid / dof / np.sum((t - t.mean()) ** 2))
        tstat = float(coef[1] / se_slope) if se_slope > 0 else float("inf")
        out.append({"channel": channel, "change_ms2": float(coef[1] * duration), "se_ms2": float(se_slope * duration),
                    "t": tstat, "p_value": float(2 * student_t.sf(abs(tstat), dof))})
    return out
