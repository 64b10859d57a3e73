"""The measured counterpart of the frequency response: from a sweep recording, the response envelope
against the table's instantaneous frequency and the jump, with its uncertainty from the sweep rate; and
the comparison with a model's predicted folds, with the sweep-rate bias stated.

    env = sweep_envelope(rec)                 # one row per table cycle: t_s, frequency_hz, response_mm, table_mm
    jump = measured_jump(env)                 # the up-sweep's drop / the down-sweep's rise, or None
    cmp = compare_sweep(model, rec)           # measured vs predicted jump, the bias, agreement

A sweep passes a fold at a finite rate: the response stays on its branch past the steady-state fold (the
slow passage through a saddle-node lags by ~ rate^(2/3)) and then needs the transient's decay time to
reach the other branch, so an up-sweep jumps down above the fold and a down-sweep jumps up below it. The
bias is the model's own: its free run driven by the recorded table acceleration, read by the same
detector, minus its steady-state fold (docs/frf.md gives figures).
"""
from __future__ import annotations

import numpy as np
from scipy.fft import next_fast_len
from scipy.signal import hilbert

from ..chain.states import reconstruct_states
from ..errors import IdentificationError
from ..simulation.simulate import simulate
from .response import frequency_response

#: A measured jump: the largest change of the per-cycle envelope from one cycle to the next in the sweep's
#: jump direction, in mm (not in ratio: after an up-sweep's jump the transient beats against the forcing, and
#: a beat's node, 5.4 -> 2.2 mm, is a larger ratio than the jump itself, 10.4 -> 4.4 mm: measured_jump's
#: docstring), its transition the cycles around it changing by >= TRANSITION_SHARE of that, by
#: >= MIN_JUMP_RATIO in all...
MIN_JUMP_RATIO = 1.3
TRANSITION_SHARE = 0.5
#: ... where the response is at least JUMP_LEVEL of its largest (not the sweep's quiet ends).
JUMP_LEVEL = 0.3
#: Cycles whose table amplitude is off the sweep's (steady_cycles) by more than this share are left out
#: (the fades, and the sensor noise of the table at rest before or after the sweep)...
STEADY_TABLE = 0.1
#: ... and the steady stretch must be at least this share of the time the table moves near its level
#: (within a factor DRIVEN_RANGE of it, at frequencies within that factor of the stretch's lowest, in one
#: stretch with it): the fades are short; a ramped or wandering amplitude is refused, not read at one end.
STEADY_SHARE = 0.5
DRIVEN_RANGE = 3.0
#: The steady cycles are one stretch of the record: up to this many cycles off the level inside it are
#: bridged, and a cycle of rest that happens to read the sweep's level is left out.
BRIDGE_CYCLES = 3
#: Cycles left out at each end of the valid rows (the analytic signal's edge).
EDGE_CYCLES = 3


def table_cycles(zdd: np.ndarray, fs_hz: float) -> dict:
    """The table's cycles (boundaries where its acceleration's analytic phase passes a multiple of 2 pi):
    "edges" (rows), and per cycle its mid time (s, from the first sample), frequency (Hz, 1 / the cycle's
    length) and the table's amplitude (mm; its acceleration's RMS x sqrt 2 / w^2). In double precision
    whatever the states' dtype: a float32 phase unwrapped over 1e6 rows keeps ~1e-3 rad of thousands of
    radians. A model's run over the same table acceleration has the same cycles (model_sweep_jump)."""
    zdd = np.asarray(zdd, np.float64)
    # zero-padded to a fast FFT length: a record's length can be a large prime's multiple (994,878 rows =
    # 2 x 171 x 2909: ~1 s of CPU against 0.1 s); the padding touches only the last cycles, which
    # EDGE_CYCLES leaves out anyway
    phase = np.unwrap(np.angle(hilbert(zdd, N=next_fast_len(zdd.size))[:zdd.size]))
    k = np.floor((phase - phase[0]) / (2 * np.pi))
    edges = np.flatnonzero(np.diff(k) != 0) + 1
    edges = edges[EDGE_CYCLES:-EDGE_CYCLES] if edges.size > 2 * EDGE_CYCLES + 2 else edges
    if edges.size < 3:
        raise IdentificationError("the recording holds fewer than 3 cycles of the table: no sweep to read")
    a, b = edges[:-1], edges[1:]
    freq = fs_hz * (phase[b] - phase[a]) / (2 * np.pi) / (b - a)
    # the table's amplitude from the cycle's RMS (x sqrt 2: it is a sine), not its peak-to-peak: noise
    # raises a peak-to-peak by ~2-3 noise std (0.2-0.5 % at 0.5 % noise), an RMS only by its variance
    mean_square = np.add.reduceat(np.square(zdd[a[0]:b[-1]]), a - a[0]) / (b - a)
    return {"edges": edges, "t_s": 0.5 * (a + b) / fs_hz, "frequency_hz": freq,
            "table_mm": np.sqrt(2.0 * mean_square) / (2 * np.pi * freq) ** 2 * 1e3,
            "energy": mean_square * (b - a)}


def cycle_envelope(q2: np.ndarray, zdd: np.ndarray | None, fs_hz: float, cycles: dict | None = None) -> dict:
    """Per table cycle (table_cycles of zdd, or `cycles` already read from it): mid time (s), frequency
    (Hz), the response's amplitude (mm, half its peak-to-peak) and the table's (mm)."""
    c = table_cycles(zdd, fs_hz) if cycles is None else cycles
    a = c["edges"][:-1]
    q2 = np.asarray(q2[a[0]:c["edges"][-1]], np.float64)
    resp = 0.5 * (np.maximum.reduceat(q2, a - a[0]) - np.minimum.reduceat(q2, a - a[0])) * 1e3
    return {"t_s": c["t_s"], "frequency_hz": c["frequency_hz"], "response_mm": resp, "table_mm": c["table_mm"]}


def sweep_envelope(rec, sig=None) -> dict:
    """The recording's per-cycle envelope (cycle_envelope) from the chain's relative displacement and
    band-limited table acceleration (identify.chain.states) on the sweep's own cycles (steady_cycles), plus
    the sweep's direction ("up" | "down"), rate (Hz/s) and table amplitude (mm, their median). `sig`: the
    recording's chain states when they are at hand (an identification's: the chain is not run twice on one
    record), else the chain is run here."""
    if rec.layout != "base":
        raise IdentificationError(f"{rec.source}: a measured frequency response needs the base layout (table "
                                  "and mass accelerations)")
    sig = reconstruct_states(rec, dtype=np.float64) if sig is None else sig
    rows = sig.valid
    cycles = table_cycles(sig.input[rows], rec.fs_hz)
    env = cycle_envelope(sig.q2[rows], None, rec.fs_hz, cycles)
    env["t_s"] = env["t_s"] + rows.start / rec.fs_hz
    keep = steady_cycles(cycles, rec.source)
    env = {k: v[keep] for k, v in env.items()}
    rate = float(np.polyfit(env["t_s"], env["frequency_hz"], 1)[0])
    env.update(direction="up" if rate > 0 else "down", rate_hz_per_s=rate,
               amplitude_mm=float(np.median(env["table_mm"])), signals=sig, cycles=cycles)
    return env


def steady_cycles(cycles: dict, source: str = "the recording") -> np.ndarray:
    """Which table cycles (table_cycles) are the sweep's: those within STEADY_TABLE of the level that holds
    the most of the table's acceleration energy, in the one stretch of the record (gaps of up to
    BRIDGE_CYCLES bridged, slow ends trimmed) that holds the most of it. Not the median of all cycles, as
    it was: a recording holds the table at rest too (the recorder started before the PLC's start, settle_s
    after its end), and there the "cycles" are sensor noise, many, short and of any level, a few of them at
    the sweep's (a 1-20 Hz, 30 s, 1.2 mm sweep with 5 s of settle read 0.68 mm, with 10 s 0.0001 mm).
    Weighed by energy, 10-60 s of rest at 0.5 % noise is 6e-7 - 2e-6 of that sweep. Refused
    (IdentificationError) where that stretch is less than STEADY_SHARE of the time the table moves within
    DRIVEN_RANGE of its level (a ramped amplitude) or fewer than 3 cycles are the sweep's."""
    table_mm, energy = np.asarray(cycles["table_mm"], np.float64), np.asarray(cycles["energy"], np.float64)
    finite = np.isfinite(table_mm) & (table_mm > 0) & np.isfinite(energy)
    level = np.log(np.where(finite, table_mm, 1.0))
    order = np.flatnonzero(finite)[np.argsort(level[finite])]
    if order.size < 3:
        raise IdentificationError(f"{source}: not a sine sweep: fewer than 3 cycles of the table")
    summed = np.concatenate([[0.0], np.cumsum(energy[order])])
    half = np.log1p(STEADY_TABLE)
    lo = np.searchsorted(level[order], level[order] - half, side="left")
    hi = np.searchsorted(level[order], level[order] + half, side="right")
    best = int(np.argmax(summed[hi] - summed[lo]))
    table = float(np.median(table_mm[order[lo[best]:hi[best]]]))
    freq = np.asarray(cycles["frequency_hz"], np.float64)
    on = finite & (freq > 0) & (np.abs(table_mm - table) < STEADY_TABLE * table)
    sweep = _trim_slow_ends(_longest_stretch(on, energy), freq)
    if sweep.size < 3:
        raise IdentificationError(f"{source}: not a sine sweep: fewer than 3 table cycles at one amplitude")
    near = (finite & (table_mm > table / DRIVEN_RANGE) & (table_mm < table * DRIVEN_RANGE)
            & (freq > freq[sweep].min() / DRIVEN_RANGE))  # not the rest's slow noise "cycles" (0.1 Hz: ~1 mm)
    driven = next(r for r in _stretches(near) if sweep[0] in r)
    rows = np.diff(cycles["edges"])
    share = rows[sweep].sum() / rows[driven[0]:driven[-1] + 1].sum()
    if share < STEADY_SHARE:
        raise IdentificationError(
            f"{source}: not a sine sweep at one amplitude: the table's amplitude is {table:.3g} mm for "
            f"{100 * share:.0f} % of the time it moves within {DRIVEN_RANGE:g}x of that (a sweep: all but its "
            f"fades; at least {100 * STEADY_SHARE:.0f} % needed to read a frequency response)")
    keep = np.zeros(table_mm.size, dtype=bool)
    keep[sweep] = True
    return keep


def _stretches(mask: np.ndarray) -> list[np.ndarray]:
    """The indices of mask's True cycles in stretches, gaps of up to BRIDGE_CYCLES bridged."""
    idx = np.flatnonzero(mask)
    return np.split(idx, np.flatnonzero(np.diff(idx) > BRIDGE_CYCLES + 1) + 1)


def _trim_slow_ends(stretch: np.ndarray, freq: np.ndarray) -> np.ndarray:
    """The stretch less the cycles at either end whose frequency is off the next five inner cycles' median
    by more than DRIVEN_RANGE: the rest's slow noise "cycles" at the sweep's level (0.1 Hz and ~10 s long
    beside a sweep ending at 4 Hz), bridged onto it, which would bend its rate."""
    while stretch.size > 3:
        f = freq[stretch]
        if not 1 / DRIVEN_RANGE < f[0] / np.median(f[1:6]) < DRIVEN_RANGE:
            stretch = stretch[1:]
        elif not 1 / DRIVEN_RANGE < f[-1] / np.median(f[-6:-1]) < DRIVEN_RANGE:
            stretch = stretch[:-1]
        else:
            break
    return stretch


def _longest_stretch(mask: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """The stretch of mask's cycles (_stretches) holding the most energy."""
    return max(_stretches(mask), key=lambda r: energy[r].sum())


def measured_jump(env: dict) -> dict | None:
    """The sweep's jump: an up-sweep's largest drop, a down-sweep's largest rise of the per-cycle response
    from one cycle to the next, in mm. {"frequency_hz" (at that cycle), "uncertainty_hz" (half the frequency
    span of the transition: the sweep moves on while the response changes branch), "t_s", "ratio",
    "cycles"} or None when nowhere the envelope changes by MIN_JUMP_RATIO. On a sweep a fold's jump and a
    fast passage of a steep resonance both change at the transient's rate: whether it is a jump is
    compare_sweep's question (the model's fold and its own run over the same sweep), not this one's.

    Not in log (ratio) steps, as it was: past an up-sweep's jump the free transient beats against the
    forcing, and a beat's node is a larger ratio than the jump itself. On the paper's sweep (1-20 Hz in 60 s
    at 1.3 mm, the Table 1 rig) the response falls 14.0 -> 10.4 -> 4.4 mm at 6.62-6.72 Hz and then beats
    3.4 -> 5.4 -> 2.2 mm; the ratio took the node at 6.88 Hz, 0.18 Hz late, and the model's own run,
    beating alike, "agreed" there (tests/identify/test_frf_measured.py)."""
    a, f = env["response_mm"], env["frequency_hz"]
    sign = -1.0 if env["direction"] == "up" else 1.0
    step = sign * np.diff(a)
    loud = np.maximum(a[:-1], a[1:]) >= JUMP_LEVEL * a.max()
    step = np.where(loud, step, -np.inf)
    i = int(np.argmax(step))
    if not step[i] > 0:
        return None
    s = e = i
    while s > 0 and step[s - 1] >= TRANSITION_SHARE * step[i]:
        s -= 1
    while e < step.size - 1 and step[e + 1] >= TRANSITION_SHARE * step[i]:
        e += 1
    ratio = float(a[s] / a[e + 1] if sign < 0 else a[e + 1] / a[s]) if min(a[s], a[e + 1]) > 0 else np.inf
    if ratio < MIN_JUMP_RATIO:
        return None
    return {"frequency_hz": float(0.5 * (f[i] + f[i + 1])), "uncertainty_hz": float(0.5 * abs(f[e + 1] - f[s])),
            "t_s": float(0.5 * (env["t_s"][i] + env["t_s"][i + 1])), "ratio": ratio, "cycles": int(e - s + 1)}


def model_sweep_jump(model, env: dict) -> dict | None:
    """The jump of the model's own free run driven by the recording's band-limited table acceleration,
    started from the measured state, read by measured_jump: what the model predicts this sweep shows."""
    sig = env["signals"]
    rows = sig.valid
    u = np.asarray(sig.input[rows], float)
    x0 = [float(sig.q1[rows][0]), float(sig.q2[rows][0])]
    scale = np.array([np.max(np.abs(sig.q1[rows])), np.max(np.abs(sig.q2[rows]))]) * 2
    res = simulate(model, 1.0 / sig.fs_hz, x0, u[:, None], state_scale=scale)
    if res.diverged:
        return None
    sim_env = cycle_envelope(res.states[:, 1], u, sig.fs_hz, env["cycles"])  # the same table cycles
    sim_env["direction"] = env["direction"]
    jump = measured_jump(sim_env)
    if jump is not None:
        jump["t_s"] += rows.start / sig.fs_hz
    return jump


def compare_sweep(model, rec, band_hz=None) -> dict:
    """Measured against predicted jump of one sweep recording: the measured jump (measured_jump), the
    model's steady-state fold at the recorded table amplitude, the sweep-rate bias (the model's own sweep
    jump minus its fold), and whether the measured jump lies between the fold and the fold + bias, give or
    take its uncertainty ("agrees"); a model that misses it by more is flagged."""
    env = sweep_envelope(rec)
    f = env["frequency_hz"]
    band = band_hz or (float(f.min()), float(f.max()))
    return compare_jump(model, env, frequency_response(model, env["amplitude_mm"], band))


def compare_jump(model, env: dict, resp) -> dict:
    """compare_sweep's judgement for an envelope already read (sweep_envelope) and the model's response
    already predicted (frequency_response at about its table amplitude): the side-by-side of
    identify.frf.side_by_side reuses both across models and directions."""
    jump = measured_jump(env)
    fold = resp.jump_down_hz if env["direction"] == "up" else resp.jump_up_hz
    model_jump = model_sweep_jump(model, env)
    out = {"direction": env["direction"], "rate_hz_per_s": env["rate_hz_per_s"], "amplitude_mm": env["amplitude_mm"],
           "measured": jump, "fold_hz": fold, "model_sweep_jump": model_jump, "bias_hz": None, "agrees": None,
           "response": resp}
    if fold is not None and model_jump is not None:
        out["bias_hz"] = model_jump["frequency_hz"] - fold
    if fold is None:  # no steady-state fold: the sweep may still show a steep passage; the model's own sweep says
        if jump is None or model_jump is None:
            out["agrees"] = jump is None and model_jump is None
        else:
            out["miss_hz"] = abs(jump["frequency_hz"] - model_jump["frequency_hz"])
            out["agrees"] = bool(out["miss_hz"] <= jump["uncertainty_hz"] + model_jump["uncertainty_hz"])
        return out
    if jump is None:
        out["agrees"] = False
        return out
    lo, hi = sorted((fold, fold + (out["bias_hz"] or 0.0)))
    out["miss_hz"] = max(lo - jump["frequency_hz"], jump["frequency_hz"] - hi, 0.0)
    out["agrees"] = bool(out["miss_hz"] <= jump["uncertainty_hz"])
    return out
