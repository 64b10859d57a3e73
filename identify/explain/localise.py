"""Where a model's equation-error residual concentrates: along the sweep (time and excitation frequency),
in the frequency domain, and over the state space (displacement x velocity bins, sign of velocity,
amplitude). Each effect of the catalog leaves its own signature: Coulomb friction a step in the mean
residual against velocity, quadratic damping a parabola-signed one, displacement-dependent damping a
residual growing with |q2| at fixed velocity, quadratic stiffness one even in q2."""
from __future__ import annotations

import numpy as np
from scipy.signal import welch

from ..chain.states import StateSignals
from ..model import SparseModel

N_WINDOWS = 40
N_BINS = 9


def localise(model: SparseModel, sig: StateSignals) -> dict:
    v = sig.valid
    q1, q2, u = sig.q1[v], sig.q2[v], sig.input[v]
    r = sig.q1_dot[v] - model.rhs(np.column_stack([q1, q2]), u[:, None])[:, 0]
    fs = sig.fs_hz
    total = float(np.sqrt(np.mean(r**2))) or 1.0

    # along the record: residual RMS per window and the input's dominant frequency there
    edges = np.linspace(0, r.size, N_WINDOWS + 1).astype(int)
    windows = []
    for a, b in zip(edges[:-1], edges[1:]):
        windows.append({"t_start_s": (v.start + a) / fs, "t_end_s": (v.start + b) / fs,
                        "excitation_hz": excitation_hz(u, a, b, fs, sig.band_hz[0]),
                        "residual_rms": float(np.sqrt(np.mean(r[a:b] ** 2))),
                        "signal_rms": float(np.sqrt(np.mean(sig.q1_dot[v][a:b] ** 2)))})
    energy = np.array([w["residual_rms"] ** 2 for w in windows])
    top = np.argsort(energy)[::-1][: max(1, N_WINDOWS // 5)]
    worst = windows[int(top[0])]

    # frequency content of the residual
    f, p = welch(r, fs, nperseg=min(r.size, int(2 ** np.ceil(np.log2(fs * 4)))))
    peaks = np.argsort(p)[::-1][:3]

    # state space: mean and RMS residual over displacement x velocity bins (symmetric, linear)
    e2 = np.linspace(-1, 1, N_BINS + 1) * np.max(np.abs(q2))
    e1 = np.linspace(-1, 1, N_BINS + 1) * np.max(np.abs(q1))
    i2 = np.clip(np.digitize(q2, e2) - 1, 0, N_BINS - 1)
    i1 = np.clip(np.digitize(q1, e1) - 1, 0, N_BINS - 1)
    count = np.zeros((N_BINS, N_BINS))
    np.add.at(count, (i2, i1), 1)
    mean = np.zeros_like(count)
    np.add.at(mean, (i2, i1), r)
    sq = np.zeros_like(count)
    np.add.at(sq, (i2, i1), r**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 20, mean / count, np.nan)
        rms = np.where(count > 20, np.sqrt(sq / count), np.nan)
    # velocity signature: mean residual per velocity bin (all displacements)
    vel_mean = [float(np.mean(r[i1 == k])) if np.count_nonzero(i1 == k) > 20 else None for k in range(N_BINS)]
    amp = np.abs(q2) / (np.max(np.abs(q2)) or 1.0)
    return {
        "residual_rms": total,
        "relative_residual": total / (float(np.sqrt(np.mean(sig.q1_dot[v] ** 2))) or 1.0),
        "time": {"windows": windows, "worst_window": worst,
                 "share_in_top_fifth": float(energy[top].sum() / energy.sum()) if energy.sum() > 0 else 0.0},
        "frequency": {"peak_hz": [float(f[k]) for k in peaks]},
        "state": {"q2_edges_m": e2.tolist(), "q1_edges_ms": e1.tolist(),
                  "mean_residual": _nan_to_none(mean), "rms_residual": _nan_to_none(rms),
                  "velocity_signature": {"q1_centres_ms": (0.5 * (e1[1:] + e1[:-1])).tolist(),
                                         "mean_residual": vel_mean},
                  "sign_of_velocity": {"mean_residual_q1_pos": float(np.mean(r[q1 > 0]) / total),
                                       "mean_residual_q1_neg": float(np.mean(r[q1 < 0]) / total)},
                  "amplitude": {"rms_small_q": float(np.sqrt(np.mean(r[amp < 1 / 3] ** 2))) if np.any(amp < 1 / 3) else None,
                                "rms_large_q": float(np.sqrt(np.mean(r[amp > 2 / 3] ** 2))) if np.any(amp > 2 / 3) else None}},
        "_residual": r,
    }


#: The input's frequency at a window is read over at least this many periods of the band's bottom,
#: centred on the window: a window shorter than a period has no frequency to read (40 windows of a 4 s
#: record are 0.1 s, 75 samples at 2048 Hz: its FFT's first bin is 27.3 Hz, which is what it said).
PERIODS_FOR_FREQUENCY = 2
#: ... and its spectrum zero-padded to at least this many times that least stretch: bins of f_lo / 16
#: (a longer window, already finer, is not padded: a million-sample record's 40 windows cost 3.5x
#: their unpadded transforms padded 8-fold).
FREQUENCY_PADDING = 8


def excitation_hz(u: np.ndarray, a: int, b: int, fs_hz: float, f_lo_hz: float) -> float:
    """The input's dominant frequency (Hz) at rows [a, b) of u: the peak of the Hann-windowed, zero-padded
    spectrum of a stretch centred on them and at least PERIODS_FOR_FREQUENCY periods of f_lo long (the
    whole record when shorter). 0 for fewer than 3 samples."""
    return excitation_peak(u, a, b, fs_hz, f_lo_hz)[0]


def excitation_peak(u: np.ndarray, a: int, b: int, fs_hz: float, f_lo_hz: float) -> tuple[float, float]:
    """excitation_hz's frequency and the height of its spectral peak (the transform's magnitude, in the
    input's units x samples; (0, 0) for fewer than 3 samples): how strongly the input was driven there."""
    need = int(np.ceil(PERIODS_FOR_FREQUENCY * fs_hz / f_lo_hz)) if f_lo_hz > 0 else b - a
    mid, half = (a + b) // 2, max(b - a, need) // 2
    lo = max(0, min(mid - half, u.size - 2 * half))
    seg = u[lo:lo + 2 * half] if 2 * half <= u.size else u
    if seg.size < 3:
        return 0.0, 0.0
    seg = seg - seg.mean()
    n = max(seg.size, FREQUENCY_PADDING * min(need, seg.size))
    spec = np.abs(np.fft.rfft(seg * np.hanning(seg.size), n))
    k = int(np.argmax(spec[1:])) + 1
    return float(k * fs_hz / n), float(spec[k])


def _nan_to_none(a: np.ndarray) -> list:
    return [[None if not np.isfinite(x) else float(x) for x in row] for row in a]


def remaining(fitter, st, err: np.ndarray, top: int = 5) -> dict:
    """Where the explanation still misses: the shooting error along the record (segments with the most
    error, their time and excitation frequency, their share of the total), and, for a two-state model,
    the equation-error residual's localisation over the state space and frequency."""
    sig = fitter.sig0
    v = sig.valid
    total = float(np.nansum(err)) or 1.0
    order = np.argsort(np.nan_to_num(err))[::-1][:top]
    u = sig.input[v]
    segs = []
    for i in order:
        a, b = int(fitter.starts[i]), int(fitter.stops[i])
        segs.append({"t_start_s": (v.start + a) / sig.fs_hz, "t_end_s": (v.start + b) / sig.fs_hz,
                     "excitation_hz": excitation_hz(u, a, b, sig.fs_hz, sig.band_hz[0]),
                     "share_of_error": float(err[i] / total), "heldout": bool(fitter.seg_held[i])})
    out = {"segments": segs, "share_in_top_segments": float(sum(s["share_of_error"] for s in segs))}
    if st.hyst is None and not any("tau" in t for t in st.terms) and not any(st.p.values()):
        loc = localise(fitter.model(st), sig)
        out["state"] = loc["state"]
        out["frequency"] = loc["frequency"]
    return out
