"""A campaign proposed from a model's predicted folds (issue 33 item 5): table amplitudes that bracket the
jump (one below its onset, the others between the onset and the largest amplitude the rig takes), a band
that brackets every predicted jump frequency, up and down sweeps at a slow rate, every sweep inside the
PLC's limits and predicted inside the rig's (the preflight, daq/preflight.py). One function for the
command (`shakeid plan-campaign MODEL.json`) and the service (POST /api/campaigns/proposal).

    proposal = propose_campaign(response, limits, name="levels")
    proposal["plan"]          # a plan for `shakeid campaign` / POST /api/campaigns (daq.campaign.parse_plan)
    proposal["amplitudes"]    # per amplitude: predicted jump-down / jump-up frequency, peak response, preflight

The onset is where the predicted response first folds (identify.frf, bisected to ONSET_RESOLUTION); the
largest amplitude is the largest whose steady-state response stays below preflight.WARN_SHARE of the
end-stop travel and inside the model's range of validity, then confirmed by the preflight's time-domain
run of each proposed sweep (stepped down by STEP_DOWN while it refuses or warns).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from identify.errors import ShakeidError
from identify.frf import frequency_response, natural_frequency_hz

from .campaign import parse_plan, plan_violation
from .preflight import WARN_SHARE, RigResponse
from .sweep import predicted_verdict

#: amplitudes scanned for the onset and the largest amplitude, geometric, as shares of the stroke limit
SCAN_SHARES = np.geomspace(0.02, 1.0, 7)
#: the band scanned for folds, in multiples of the model's linear natural frequency (a hardening rig's
#: jumps lie above it, a softening one's below; half the frf's default band, half its cost)
SCAN_BAND = (0.5, 2.5)
#: the onset and the largest amplitude are bisected until their bracket is this share of them
ONSET_RESOLUTION = 0.05
#: harmonics of the planning's responses: 3 put the Table 1 rig's fold within 6e-5 of the converged one
#: (docs/frf.md), far inside BRACKET_SHARE, at about half the cost
HARMONICS = 3
#: the amplitude without a jump, as a share of the onset
BELOW_ONSET = 0.8
#: the band reaches this share of each jump frequency beyond it (a sweep jumps after the steady-state fold
#: by its sweep-rate bias: 5-9 % at 0.3 Hz/s on the Table 1 rig, docs/frf.md)
BRACKET_SHARE = 0.15
#: the proposed sweep rate, Hz/s (slower than the paper's 0.317 Hz/s: a smaller sweep-rate bias)
RATE_HZ_PER_S = 0.1
#: the top amplitude is multiplied by this while the preflight refuses or warns about its sweeps
STEP_DOWN = 0.95
#: amplitudes are proposed to 0.01 mm, the band to 0.1 Hz
AMPLITUDE_STEP_MM, FREQUENCY_STEP_HZ = 0.01, 0.1
#: the proposed campaign's name when none is given (`shakeid plan-campaign --name`, the service's proposal)
PROPOSAL_NAME = "fold-bracket"
#: amplitudes with a predicted jump: the default and the range offered (CLI --jump-amplitudes, the service)
JUMP_AMPLITUDES, JUMP_AMPLITUDES_RANGE = 2, (1, 5)


def propose_campaign(response: RigResponse, limits, name: str = PROPOSAL_NAME, jump_amplitudes: int = JUMP_AMPLITUDES,
                     rate_hz_per_s: float = RATE_HZ_PER_S) -> dict:
    """The proposal for the rig of `response` (its model, accelerometer ranges and travel) under the
    PLC's `limits` (protocol.plc.Limits); ShakeidError saying why when the model predicts no jump within
    what the rig takes."""
    model = response.model
    f0 = natural_frequency_hz(model)
    scan_band = (max(SCAN_BAND[0] * f0, limits.f_min_hz), min(SCAN_BAND[1] * f0, limits.f_max_hz))
    travel = min(response.travel_mm)
    cache: dict[float, dict] = {}

    def state(a_mm: float) -> dict:
        if a_mm not in cache:
            cache[a_mm] = _state(model, a_mm, scan_band, travel)
        return cache[a_mm]

    scan = [float(s * limits.max_stroke_mm) for s in SCAN_SHARES]
    safe = []
    for a in scan:  # upwards, to the first amplitude the rig does not take (the larger ones take less)
        if not state(a)["safe"]:
            break
        safe.append(a)
    if not safe:
        raise ShakeidError(f"no amplitude from {scan[0]:.3g} mm is predicted inside the rig's limits: "
                           f"{state(scan[0])['why']}")
    unsafe = [a for a in scan if a > safe[-1]][:1]
    largest = safe[-1] if not unsafe else _bracket(safe[-1], unsafe[0], lambda a: not state(a)["safe"])[0]
    if not state(largest)["jumps"]:
        why = state(unsafe[0])["why"] if unsafe else "the stroke limit"
        raise ShakeidError(f"the model predicts no jump up to {largest:.3g} mm, the largest table amplitude predicted "
                           f"inside the rig's limits ({why}): nothing to bracket; plan the campaign by hand")
    first = min(a for a in [*safe, largest] if state(a)["jumps"])
    below = max([a for a in scan if a < first], default=first / 2)
    onset = _bracket(below, first, lambda a: state(a)["jumps"])[1]  # the first that folds
    jumps = list(np.linspace(onset, largest, jump_amplitudes + 1)[1:])
    plan, picked, notes = _fit_to_preflight(response, limits, name, [BELOW_ONSET * onset] + jumps, state, rate_hz_per_s)
    return {"plan": plan, "onset_mm": onset, "largest_mm": largest, "amplitudes": picked, "notes": notes,
            "model_source": response.source}


def _state(model, a_mm: float, band: tuple, travel_mm: float) -> dict:
    """The steady-state response at one table amplitude: its jumps, peak and whether the rig takes it."""
    resp = frequency_response(model, a_mm, band, harmonics=HARMONICS)
    stable = [a for b in resp.branches for a, s in zip(b["amplitude_mm"], b["stable"]) if s]
    peak = max(stable, default=0.0)
    out = {"amplitude_mm": a_mm, "jump_down_hz": resp.jump_down_hz, "jump_up_hz": resp.jump_up_hz,
           "peak_response_mm": peak, "jumps": resp.jump_down_hz is not None and resp.jump_up_hz is not None,
           "peak_frequency_hz": _peak_frequency(resp), "safe": True, "why": ""}
    ends = [b["end"] for b in resp.branches if b["end"]["reason"] != "band"]
    if ends:
        out.update(safe=False, why=f"at {a_mm:.3g} mm the response leaves the model's range ({ends[0]['detail']})")
    elif math.isfinite(travel_mm) and peak > WARN_SHARE * travel_mm:
        out.update(safe=False, why=f"at {a_mm:.3g} mm the predicted response {peak:.3g} mm is above "
                                   f"{100 * WARN_SHARE:.0f} % of the end-stop travel {travel_mm:g} mm")
    return out


def _peak_frequency(resp) -> float:
    best = max(((a, f) for b in resp.branches for f, a, s in zip(b["frequency_hz"], b["amplitude_mm"], b["stable"])
                if s), default=(0.0, resp.band_hz[0]))
    return best[1]


def _bracket(lo: float, hi: float, is_hi) -> tuple[float, float]:
    """(lo, hi) narrowed to ONSET_RESOLUTION around where is_hi turns true (lo: false, hi: true)."""
    while hi - lo > ONSET_RESOLUTION * hi:
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if is_hi(mid) else (mid, hi)
    return lo, hi


def _fit_to_preflight(response, limits, name, amplitudes, state, rate):
    """The plan around `amplitudes` (the band from their jumps), its top amplitude stepped down until the
    PLC's limits and the preflight pass every sweep without a warning."""
    notes = []
    for _ in range(40):
        amps = sorted({math.floor(a / AMPLITUDE_STEP_MM) * AMPLITUDE_STEP_MM for a in amplitudes})
        amps = [round(a, 2) for a in amps if a > 0]
        picked = [state(a) for a in amps]
        f_lo, f_hi = _band(picked, limits)
        duration = min(max((f_hi - f_lo) / rate, 1.0), limits.max_duration_s)
        plan = {"name": name, "amplitudes_mm": amps, "directions": ["up", "down"], "repeats": 1,
                "rest_between_s": 5.0, "note": "proposed from the model's predicted folds (shakeid plan-campaign)",
                "sweep": {"f_start_hz": f_lo, "f_end_hz": f_hi, "duration_s": round(duration, 1), "settle_s": 2.0}}
        problem = _preflight(response, limits, plan, picked)
        if problem is None:
            return plan, picked, notes
        notes.append(f"{amplitudes[-1]:.3g} mm stepped down: {problem}")
        amplitudes = amplitudes[:-1] + [amplitudes[-1] * STEP_DOWN]
        if amplitudes[-1] <= amplitudes[0]:
            break
    raise ShakeidError(f"no proposal passes the rig's limits and the preflight: {notes[-1] if notes else ''}")


def _preflight(response, limits, plan: dict, picked: list[dict]) -> str | None:
    """The first of the plan's sweeps (up and down: each direction has its own peaks, a softening rig's
    larger on the way down) that breaks a PLC limit or that the preflight refuses or warns about, named; None
    when all pass. Each picked amplitude keeps the prediction of its sweep that travels furthest."""
    parsed = parse_plan(plan)  # the plan as the campaign reads it: refused here, not at the rig
    problem = plan_violation(limits, parsed)
    if problem:
        return problem
    sweeps = parsed.sweeps()
    records: dict[float, dict] = {}
    for s in sweeps:
        verdict = predicted_verdict(response, s.request(), suggest=False)
        problem = verdict.refusal or ("; ".join(verdict.warnings) or None)
        if problem:
            return f"{s.label(len(sweeps))}: {problem}"
        best = records.get(s.amplitude_mm)
        if best is None or verdict.record["travel_peak_mm"] > best["travel_peak_mm"]:
            records[s.amplitude_mm] = verdict.record
    for p in picked:
        p["preflight"] = records[p["amplitude_mm"]]
    return None


def _band(picked: list[dict], limits) -> tuple[float, float]:
    """From BRACKET_SHARE below the lowest jump-up (or peak) to BRACKET_SHARE above the highest jump-down."""
    low = [p["jump_up_hz"] or p["peak_frequency_hz"] for p in picked]
    high = [p["jump_down_hz"] or p["peak_frequency_hz"] for p in picked]
    f_lo = math.floor(min(low) * (1 - BRACKET_SHARE) / FREQUENCY_STEP_HZ) * FREQUENCY_STEP_HZ
    f_hi = math.ceil(max(high) * (1 + BRACKET_SHARE) / FREQUENCY_STEP_HZ) * FREQUENCY_STEP_HZ
    return round(max(f_lo, limits.f_min_hz), 1), round(min(f_hi, limits.f_max_hz), 1)


def with_model(response: RigResponse, model, source: str) -> RigResponse:
    """The rig's limits (ranges, travel) with another model of it (MODEL.json, a recording's model)."""
    return dataclasses.replace(response, model=model, source=source)


def plan_toml(plan: dict) -> str:
    """The plan as the TOML `shakeid campaign PLAN.toml` reads (daq.campaign.load_plan)."""
    def value(v):
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    top = [f"{k} = {value(v)}" for k, v in plan.items() if not isinstance(v, dict)]
    tables = [f"\n[{k}]\n" + "\n".join(f"{kk} = {value(vv)}" for kk, vv in v.items())
              for k, v in plan.items() if isinstance(v, dict)]
    return "\n".join(top) + "\n" + "".join(tables) + "\n"
