"""Preflight that predicts: the mass acceleration and relative travel a sweep will cause, from the rig's
model, before the table moves (issue 31 item 5).

The sweep's table motion (the sweep's own analytic z'') drives the rig model (identify.simulation.simulate's RK4 kernel,
the rig's smooth model: q1 = q', q2 = q = x - z) at PREDICTION_SAMPLES_PER_PERIOD samples per period of the
sweep's top frequency, one RK4 step per sample; peaks are refined by a parabola through the three samples
around the largest. Against the same model run as the rig simulator runs it (2048 Hz, RK4 steps of
h omega <= 0.1) the peaks agree within 0.12 % (1-20 Hz, 20-300 s, 1.0-1.3 mm on the Table 1 rig;
tests/daq/test_preflight.py), and a 300 s sweep predicts in 0.15-0.33 s on a 2-core machine at load 6-21.

A predicted peak above a limit refuses the sweep (the mass accelerometer's range: its samples would clip;
the end-stop travel: the mass would hit the stops, whose impacts clip it too); above WARN_SHARE of a limit
it is accepted with a warning. The smooth model has no end stops: past the travel it is no longer the rig,
which is why reaching the travel refuses (the first crossing's frequency is named) whatever follows.
A refusal says what would pass: the largest amplitude that stays below WARN_SHARE of every limit, and the
band (at the same sweep rate) up to where the response first reaches WARN_SHARE.

One function for every front end: `assess` (service door for sweeps and campaigns, the campaign's check
before each of its sweeps, `shakeid sweep --config` and `shakeid campaign --config` through SweepRunner).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from identify.errors import ModelError
from identify.model import SparseModel
from identify.data.quality import clip_level
from identify.simulation.simulate import equation_rows, simulate
from protocol.plc import RIG_STATE_BOUND

#: share of a limit (accelerometer range, end-stop travel) above which a predicted peak is warned about
#: (the sweep runs; the warning is kept in its record): the margin for a model that is off by a few percent
#: (an identified model's peak response differs from the rig's by its identification error; the jump of a
#: hardening rig moves with it)
WARN_SHARE = 0.9
#: prediction samples per period of the sweep's top frequency (one RK4 step each; the module docstring
#: gives the accuracy this buys)
PREDICTION_SAMPLES_PER_PERIOD = 16
#: the lowest prediction rate (Hz): slow sweeps still resolve the rig's own resonance (a few Hz, its upper
#: branch up to ~12 Hz on the Table 1 rig)
MIN_PREDICTION_RATE_HZ = 256.0
#: rig state bound of the prediction (m, m/s), the rig simulator's: beyond it the model has run away
RUNAWAY_BOUND = RIG_STATE_BOUND
#: the amplitude search of a refusal's suggestion stops within this share of the asked amplitude
AMPLITUDE_RESOLUTION = 0.02


@dataclass(frozen=True)
class RigResponse:
    """What the prediction needs of a rig: its model (states q1, q2, input zdd), where the model comes
    from (said in messages), the mass accelerometer's range (m/s^2) and the end-stop travel per side (mm,
    (q < 0, q > 0); inf: none)."""

    model: SparseModel
    source: str
    mass_range_ms2: float
    table_range_ms2: float
    travel_mm: tuple[float, float]

    def __post_init__(self):
        if self.model.states != ("q1", "q2") or self.model.inputs != ("zdd",):
            raise ModelError(f"the preflight needs a base-excited rig model (states q1, q2; input zdd); "
                             f"{self.source} has states {self.model.states} and inputs {self.model.inputs}")


def nominal_response(cfg) -> RigResponse:
    """The rig of a configuration (sim.config.RigConfig) from its nominal parameters ([rig]): its smooth
    model, its accelerometers' range (int16 full scale at the stream's sensitivity), its end-stop travel."""
    level = clip_level(float(cfg.stream["sensitivity_counts_per_ms2"]))
    return RigResponse(cfg.rig.model(), "the rig's nominal parameters", level, level, tuple(cfg.rig.travels_mm))


@dataclass
class Prediction:
    """Predicted peaks of one sweep: mass acceleration (m/s^2), relative travel |q| (mm, and per side),
    table acceleration (m/s^2), each with the sweep frequency (Hz) where it occurs; `first_over` the
    frequency where a response first exceeds `share` of its limit (None: never)."""

    mass_peak_ms2: float
    mass_peak_hz: float
    travel_peak_mm: float
    travel_peak_hz: float
    table_peak_ms2: float
    runaway_hz: float | None  # where the model ran away (left RUNAWAY_BOUND), None if it did not
    rate_hz: float
    compute_s: float


def _peak(x: np.ndarray) -> tuple[float, int]:
    """|x|'s largest value refined by a parabola through the three samples around it, and its index."""
    a = np.abs(x)
    i = int(np.argmax(a))
    if 0 < i < len(a) - 1:
        y0, y1, y2 = a[i - 1], a[i], a[i + 1]
        curv = y0 - 2 * y1 + y2
        if curv < 0:
            return float(y1 - 0.125 * (y0 - y2) ** 2 / curv), i
    return float(a[i]), i


@dataclass
class _Run:
    """The sweep through the model: prediction rate (Hz), sample times (s), states (n, 2), mass and table
    acceleration (m/s^2), and whether the model ran away (left RUNAWAY_BOUND) before the sweep's end."""

    rate_hz: float
    t: np.ndarray
    states: np.ndarray
    mass: np.ndarray
    zdd: np.ndarray
    ran_away: bool


def _run(rig: RigResponse, sweep) -> _Run:
    """The sweep's table motion through the rig model (one RK4 step per prediction sample)."""
    f_top = max(sweep.f_start_hz, sweep.f_end_hz)
    rate = max(PREDICTION_SAMPLES_PER_PERIOD * f_top, MIN_PREDICTION_RATE_HZ)
    n = int(math.ceil(sweep.duration_s * rate)) + 1
    t_half = np.arange(2 * (n - 1) + 1) / (2 * rate)  # RK4 reads the input every half step
    zdd_half = sweep.kinematics(t_half)[2]
    res = simulate(rig.model, 1 / rate, np.zeros(2), inputs_fine=zdd_half[:, None], substeps=1, n_samples=n,
                   bound=RUNAWAY_BOUND)
    zdd = zdd_half[::2]
    states = res.states[:res.n_valid]
    mass = equation_rows(rig.model, states, zdd[:res.n_valid]) + zdd[:res.n_valid]
    return _Run(rate, t_half[::2], states, mass, zdd, res.n_valid < n)


def _peaks(sweep, run: _Run, compute_s: float) -> Prediction:
    """The run's peaks, each with the sweep frequency where it occurs."""
    m_peak, m_i = _peak(run.mass) if run.mass.size else (0.0, 0)
    q_peak, q_i = _peak(run.states[:, 1]) if run.mass.size else (0.0, 0)
    z_peak, _ = _peak(run.zdd)
    freq = lambda i: float(sweep.frequency_hz(run.t[min(i, len(run.t) - 1)]))  # noqa: E731
    return Prediction(m_peak, freq(m_i), 1e3 * q_peak, freq(q_i), z_peak,
                      freq(run.states.shape[0]) if run.ran_away else None, run.rate_hz, compute_s)


def predict(rig: RigResponse, sweep) -> Prediction:
    """The sweep's predicted peaks (sweep: protocol's SineSweep: f_start_hz, f_end_hz, duration_s,
    amplitude_mm, kinematics(t), frequency_hz(t))."""
    start = time.perf_counter()
    run = _run(rig, sweep)
    return _peaks(sweep, run, time.perf_counter() - start)


def _first_over(rig: RigResponse, run: _Run, share: float) -> float | None:
    """Sweep time (s) where the run's response first exceeds `share` of a limit (None: never)."""
    lower, upper = rig.travel_mm
    q_mm = 1e3 * run.states[:, 1]
    over = ((np.abs(run.mass) > share * rig.mass_range_ms2) | (q_mm > share * upper) | (-q_mm > share * lower)
            | (np.abs(run.zdd[:len(run.mass)]) > share * rig.table_range_ms2))
    if over.any():
        return float(run.t[int(np.argmax(over))])
    return float(run.t[len(run.mass)]) if run.ran_away else None


def _shares(rig: RigResponse, p: Prediction) -> dict:
    """Each predicted peak as a share of its limit."""
    travel = min(rig.travel_mm)
    return {"mass": p.mass_peak_ms2 / rig.mass_range_ms2, "travel": p.travel_peak_mm / travel,
            "table": p.table_peak_ms2 / rig.table_range_ms2}


def _passes(rig: RigResponse, sweep, share: float) -> bool:
    p = predict(rig, sweep)
    return p.runaway_hz is None and max(_shares(rig, p).values()) <= share


@dataclass
class Verdict:
    """refusal: the message (None: the sweep may run); warnings: messages kept in the sweep's record;
    record: the prediction as stored with the sweep (JSON)."""

    refusal: str | None
    warnings: list[str]
    record: dict


def assess(rig: RigResponse, sweep, suggest: bool = True) -> Verdict:
    """Predict the sweep and judge it against the rig's limits: refuse above a limit (saying what would
    pass when `suggest`), warn above WARN_SHARE of one. The sweep runs through the model once: its peaks,
    where it first crosses a limit and where it first reaches WARN_SHARE (a refusal's band) are of that run."""
    start = time.perf_counter()
    run = _run(rig, sweep)
    p = _peaks(sweep, run, time.perf_counter() - start)
    lower, upper = rig.travel_mm
    travel = min(lower, upper)
    shares = _shares(rig, p)
    record = {"source": rig.source, "mass_peak_ms2": round(p.mass_peak_ms2, 3),
              "mass_peak_hz": round(p.mass_peak_hz, 2),
              "mass_range_ms2": round(rig.mass_range_ms2, 3), "travel_peak_mm": round(p.travel_peak_mm, 3),
              "travel_peak_hz": round(p.travel_peak_hz, 2), "travel_mm": None if math.isinf(travel) else travel,
              "table_peak_ms2": round(p.table_peak_ms2, 3), "warn_share": WARN_SHARE,
              "rate_hz": p.rate_hz, "compute_s": round(p.compute_s, 4), "warnings": []}
    problems = []
    if p.runaway_hz is not None or shares["travel"] > 1:
        at = _first_over(rig, run, 1.0)
        f = float(sweep.frequency_hz(at)) if at is not None else p.travel_peak_hz
        peak = "runs away beyond it" if p.runaway_hz is not None else f"peaks at {p.travel_peak_mm:.3g} mm"
        problems.append(f"the mass would hit the end stops: predicted relative travel reaches the {travel:g} mm "
                        f"travel at {f:.2f} Hz ({at or 0:.0f} s into the sweep) and {peak} (the impacts clip "
                        f"the mass accelerometer)" if math.isfinite(travel) else
                        f"the predicted response runs away at {f:.2f} Hz ({at or 0:.0f} s into the sweep)")
    if shares["mass"] > 1 and not problems:  # past the travel the smooth model is no longer the rig
        problems.append(f"predicted mass acceleration {p.mass_peak_ms2:.3g} m/s^2 at {p.mass_peak_hz:.2f} Hz is above "
                        f"the accelerometer's range {rig.mass_range_ms2:.3g} m/s^2 (its samples would clip)")
    if shares["table"] > 1:
        problems.append(f"table acceleration {p.table_peak_ms2:.3g} m/s^2 is above the accelerometer's range "
                        f"{rig.table_range_ms2:.3g} m/s^2")
    if problems:
        hint = _what_passes(rig, sweep, run) if suggest else ""
        return Verdict(f"{'; '.join(problems)}; predicted from {rig.source}{hint}", [], record)
    warnings = []
    if shares["mass"] > WARN_SHARE:
        warnings.append(f"predicted mass acceleration {p.mass_peak_ms2:.3g} m/s^2 at {p.mass_peak_hz:.2f} Hz is "
                        f"{100 * shares['mass']:.0f} % of the accelerometer's range {rig.mass_range_ms2:.3g} m/s^2")
    if shares["travel"] > WARN_SHARE:
        warnings.append(f"predicted relative travel {p.travel_peak_mm:.3g} mm at {p.travel_peak_hz:.2f} Hz is "
                        f"{100 * shares['travel']:.0f} % of the end-stop travel {travel:g} mm")
    if shares["table"] > WARN_SHARE:
        warnings.append(f"table acceleration {p.table_peak_ms2:.3g} m/s^2 is {100 * shares['table']:.0f} % of the "
                        f"accelerometer's range {rig.table_range_ms2:.3g} m/s^2")
    warnings = [f"{w} (warned above {100 * WARN_SHARE:.0f} %; predicted from {rig.source})" for w in warnings]
    record["warnings"] = warnings
    return Verdict(None, warnings, record)


def _what_passes(rig: RigResponse, sweep, run: _Run) -> str:
    """'; passes: ...' naming the largest amplitude and the band (same sweep rate) whose predicted peaks
    stay below WARN_SHARE of every limit, or '' when neither is found (run: the sweep's own run)."""
    options = []
    lo, hi = 0.0, sweep.amplitude_mm
    while hi - lo > AMPLITUDE_RESOLUTION * sweep.amplitude_mm:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _passes(rig, dataclasses.replace(sweep, amplitude_mm=mid), WARN_SHARE) else (lo, mid)
    amplitude = math.floor(lo * 100) / 100
    if amplitude > 0:
        options.append(f"amplitude {amplitude:g} mm or less")
    at = _first_over(rig, run, WARN_SHARE)
    if at is not None:
        f0, f1 = sweep.f_start_hz, sweep.f_end_hz
        f_stop = float(sweep.frequency_hz(at))
        f_stop = (math.floor if f1 > f0 else math.ceil)(f_stop * 10) / 10
        duration = sweep.duration_s * (f_stop - f0) / (f1 - f0) if f1 != f0 else 0.0
        if duration >= 1.0 and abs(f_stop - f0) >= 0.5:
            band = dataclasses.replace(sweep, f_end_hz=f_stop, duration_s=duration)
            if _passes(rig, band, WARN_SHARE):
                options.append(f"the band {f0:g}-{f_stop:g} Hz over {duration:.0f} s (the same sweep rate)")
    return ("; passes: " + ", or ".join(options)) if options else ""
