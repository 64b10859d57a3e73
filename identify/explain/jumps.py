"""The resonance's jump as its own observable: when it happens, measured and as a model predicts it.

A hardening rig swept through its resonance jumps between the two branches of its response at a fold,
and the fold's time is a bifurcation: a coefficient change of a percent moves it by periods. Comparing
trajectories across it compares fold positions, which is why no single segment may decide the gap
(identify.simulation.shooting.trimmed_total). What the fold position says is read here instead: the time and
excitation frequency of the largest jump of the response, relative to the input (the sweep's fades
change both alike), measured and in a model's free run, reported side by side, not scored.
"""
from __future__ import annotations

import numpy as np

#: A jump is the steepest change of the response's envelope relative to the input's over this many
#: resonance periods...
JUMP_SPAN_PERIODS = 3.0
#: ... by at least this factor, where the response's envelope is above JUMP_LEVEL of its peak.
JUMP_RATIO = 2.5
JUMP_LEVEL = 0.3


def envelope(signal: np.ndarray, period_n: int) -> np.ndarray:
    """RMS over a sliding window of one period (same length as `signal`; NaN counts as 0)."""
    x = np.nan_to_num(np.asarray(signal, float)) ** 2
    c = np.concatenate([[0.0], np.cumsum(x)])
    n, w = x.size, max(int(period_n), 1)
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(lo + w, 0, n)
    return np.sqrt((c[hi] - c[lo]) / np.maximum(hi - lo, 1))


def jump_time(response: np.ndarray, inp: np.ndarray, fs_hz: float, f_res_hz: float) -> dict | None:
    """The largest jump of `response` relative to `inp`: {"row", "direction" ("down" | "up"), "ratio"},
    or None when the ratio of their envelopes nowhere changes by JUMP_RATIO within JUMP_SPAN_PERIODS."""
    period = max(int(round(fs_hz / max(f_res_hz, 1e-3))), 1)
    env = envelope(response, period)
    gain = env / np.maximum(envelope(inp, period), 1e-300)
    lag = max(int(round(JUMP_SPAN_PERIODS * period)), 1)
    if env.size <= 2 * lag or not np.max(env) > 0:
        return None
    loud = np.maximum(env[:-lag], env[lag:]) > JUMP_LEVEL * np.max(env)
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.where(loud, np.abs(np.log(np.maximum(gain[lag:], 1e-300) / np.maximum(gain[:-lag], 1e-300))), 0.0)
    step = np.nan_to_num(step)
    i = int(np.argmax(step))
    if not step[i] >= np.log(JUMP_RATIO):
        return None
    return {"row": i + lag // 2, "direction": "down" if gain[i + lag] < gain[i] else "up",
            "ratio": float(np.exp(step[i]))}
