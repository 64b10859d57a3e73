"""Campaigns: a named plan of sweeps (several amplitudes, up and down, repeated) run one after another,
unattended, that stops safely at the first sweep that does not end complete.

A lab does not run one sweep: it runs the same sweep at several table amplitudes, upward and downward
in frequency (a hardening Duffing rig jumps down from its upper branch at a higher frequency on an
upward sweep than it jumps up on a downward one, so both directions see a different part of the
response), and repeats it. This module is the part the command line (`shakeid campaign --config`) and
the rig controller (server/campaign.py) share: the plan, its expansion into sweeps, the check of every
sweep against the rig's limits before anything moves, what counts as a sweep done, and the loop that
runs the sweeps and pauses or aborts.

The plan (TOML for the command line, the same keys as JSON for the service):

    name = "levels-2024-06"            # letters, digits, . _ -: names the files and the campaign
    amplitudes_mm = [0.4, 0.8, 1.2]    # or { start = 0.4, stop = 1.6, step = 0.4 } (stop included)
    directions = ["up", "down"]        # up: f_start_hz -> f_end_hz; down: f_end_hz -> f_start_hz
    repeats = 1                        # the whole list again, this many times
    rest_between_s = 30.0              # the table at rest between two sweeps, s (wall time)
    note = ""
    [sweep]                            # every sweep's defaults
    f_start_hz = 1.0                   # the lower frequency (f_start_hz < f_end_hz), Hz
    f_end_hz = 20.0
    duration_s = 120.0
    settle_s = 2.0                     # recorded after the sweep ends, s

Order: for each repeat, for each amplitude (as listed), for each direction (as listed). So the default
"up", "down" runs 0.4 up, 0.4 down, 0.8 up, ... and the table never changes amplitude mid-pair.

A sweep counts as done when its recording ends "complete" and the recorder's quality flags do not make
it unusable for identification; anything else (a PLC fault, an emergency stop, a lost link, an
operator abort, a refused start) pauses the campaign with the reason. Resuming re-runs that sweep and
goes on; aborting ends the campaign. A campaign never starts a sweep on its own after a pause.
"""
from __future__ import annotations

import math
import re
import threading
import time
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

from identify.errors import ShakeidError
from protocol.plc import Limits

from .preflight import RigResponse, Verdict
from .sweep import SweepRequest, limit_violation, predicted_verdict

#: more sweeps than this in one plan is refused (a step of 0.001 mm over 1 mm is a typo, not a plan)
MAX_SWEEPS = 500
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
DIRECTIONS = ("up", "down")
PLAN_KEYS = {"name", "sweep", "amplitudes_mm", "directions", "repeats", "rest_between_s", "note"}
SWEEP_KEYS = {"f_start_hz", "f_end_hz", "duration_s", "settle_s"}
#: campaign states; "pausing": a pause was asked for and the running sweep finishes first
STATES = ("running", "pausing", "paused", "completed", "aborted")


class PlanError(ShakeidError):
    """The plan cannot be run as written (the key and the problem named)."""


@dataclass(frozen=True)
class PlannedSweep:
    """One sweep of a campaign: index counts from 1 in run order; repeat from 1."""
    index: int
    amplitude_mm: float
    direction: str
    repeat: int
    f_start_hz: float  # where this sweep starts (the plan's f_end_hz for a downward sweep)
    f_end_hz: float
    duration_s: float
    settle_s: float

    def label(self, total: int) -> str:
        return f"sweep {self.index} of {total} ({self.amplitude_mm:g} mm, {self.direction})"

    def body(self, note: str = "") -> dict:
        """The sweep as the service's POST /api/sweeps body (and SweepRequest's fields)."""
        return {"f_start_hz": self.f_start_hz, "f_end_hz": self.f_end_hz, "duration_s": self.duration_s,
                "amplitude_mm": self.amplitude_mm, "settle_s": self.settle_s, "note": note}

    def request(self, operator: str = "", note: str = "") -> SweepRequest:
        return SweepRequest(self.f_start_hz, self.f_end_hz, self.duration_s, self.amplitude_mm, self.settle_s,
                            operator=operator, note=note)


@dataclass(frozen=True)
class CampaignPlan:
    name: str
    f_start_hz: float
    f_end_hz: float
    duration_s: float
    amplitudes_mm: tuple[float, ...]
    settle_s: float = 2.0
    directions: tuple[str, ...] = ("up",)
    repeats: int = 1
    rest_between_s: float = 0.0
    note: str = ""

    def sweeps(self) -> list[PlannedSweep]:
        out = []
        for r in range(1, self.repeats + 1):
            for a in self.amplitudes_mm:
                for d in self.directions:
                    f0, f1 = (self.f_start_hz, self.f_end_hz) if d == "up" else (self.f_end_hz, self.f_start_hz)
                    out.append(PlannedSweep(len(out) + 1, a, d, r, f0, f1, self.duration_s, self.settle_s))
        return out

    def to_dict(self) -> dict:
        """The plan in the shape it is written in (amplitudes as a list), for the catalog and the API."""
        return {"name": self.name, "amplitudes_mm": list(self.amplitudes_mm), "directions": list(self.directions),
                "repeats": self.repeats, "rest_between_s": self.rest_between_s, "note": self.note,
                "sweep": {"f_start_hz": self.f_start_hz, "f_end_hz": self.f_end_hz, "duration_s": self.duration_s,
                          "settle_s": self.settle_s}}


def _number(value, key: str, *, low: float = 0.0, low_ok: bool = False, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PlanError(f"{key}: expected a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < low or (v == low and not low_ok) or v > high:
        bound = f"{'>=' if low_ok else '>'} {low:g}" + (f" and <= {high:g}" if math.isfinite(high) else "")
        raise PlanError(f"{key}: {value!r} must be finite and {bound}")
    return v


def _amplitudes(value) -> tuple[float, ...]:
    if isinstance(value, dict):
        unknown = set(value) - {"start", "stop", "step"}
        missing = {"start", "stop", "step"} - set(value)
        if unknown or missing:
            raise PlanError("amplitudes_mm: a range is { start = ..., stop = ..., step = ... }"
                            + (f"; unknown: {', '.join(sorted(unknown))}" if unknown else "")
                            + (f"; missing: {', '.join(sorted(missing))}" if missing else ""))
        start = _number(value["start"], "amplitudes_mm.start")
        stop = _number(value["stop"], "amplitudes_mm.stop")
        step = _number(value["step"], "amplitudes_mm.step")
        if stop < start:
            raise PlanError(f"amplitudes_mm: stop {stop:g} below start {start:g}")
        n = math.floor((stop - start) / step + 1e-9) + 1  # stop itself is included when it is on the grid
        if n > MAX_SWEEPS:
            raise PlanError(f"amplitudes_mm: {n} amplitudes from {start:g} to {stop:g} in steps of {step:g}; "
                            f"a campaign has at most {MAX_SWEEPS} sweeps")
        return tuple(round(start + k * step, 9) for k in range(n))
    if not isinstance(value, (list, tuple)) or not value:
        raise PlanError("amplitudes_mm: a non-empty list of amplitudes in mm, or { start, stop, step }")
    return tuple(_number(v, f"amplitudes_mm[{k}]") for k, v in enumerate(value))


def _known_keys(table: dict, known, where: str) -> None:
    unknown = set(table) - set(known)
    if unknown:
        raise PlanError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; known: {', '.join(sorted(known))}")


def parse_plan(plan: dict, where: str = "plan") -> CampaignPlan:
    """A plan from its dict form (a TOML file's tables or the API's JSON), checked key by key: unknown
    keys, missing keys, non-finite or out-of-range numbers and an unsafe name are refused by name."""
    if not isinstance(plan, dict):
        raise PlanError(f"{where}: expected a table of keys")
    _known_keys(plan, PLAN_KEYS, where)
    for key in ("name", "sweep", "amplitudes_mm"):
        if key not in plan:
            raise PlanError(f"{where}: {key} is missing")
    name = plan["name"]
    if not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        raise PlanError(f"name: {name!r} must be 1-64 letters, digits, '.', '_' or '-' (it names the files)")
    sweep = plan["sweep"]
    if not isinstance(sweep, dict):
        raise PlanError("sweep: expected a table with f_start_hz, f_end_hz, duration_s (and settle_s)")
    _known_keys(sweep, SWEEP_KEYS, "sweep")
    for key in ("f_start_hz", "f_end_hz", "duration_s"):
        if key not in sweep:
            raise PlanError(f"sweep.{key} is missing")
    f0, f1 = _number(sweep["f_start_hz"], "sweep.f_start_hz"), _number(sweep["f_end_hz"], "sweep.f_end_hz")
    if not f0 < f1:
        raise PlanError(f"sweep: f_start_hz {f0:g} must be below f_end_hz {f1:g} (directions = [\"down\"] "
                        "sweeps from f_end_hz to f_start_hz)")
    directions = plan.get("directions", ["up"])
    if (not isinstance(directions, (list, tuple)) or not directions or any(d not in DIRECTIONS for d in directions)
            or len(set(directions)) != len(directions)):
        raise PlanError(f"directions: {directions!r} must list \"up\" and/or \"down\", each once")
    repeats = plan.get("repeats", 1)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= MAX_SWEEPS:
        raise PlanError(f"repeats: {repeats!r} must be a whole number from 1 to {MAX_SWEEPS}")
    note = plan.get("note", "")
    if not isinstance(note, str) or len(note) > 500:
        raise PlanError("note: text of at most 500 characters")
    out = CampaignPlan(name=name, f_start_hz=f0, f_end_hz=f1, duration_s=_number(sweep["duration_s"], "sweep.duration_s"),
                       settle_s=_number(sweep.get("settle_s", 2.0), "sweep.settle_s", low_ok=True, high=60.0),
                       amplitudes_mm=_amplitudes(plan["amplitudes_mm"]), directions=tuple(directions),
                       repeats=repeats, rest_between_s=_number(plan.get("rest_between_s", 0.0), "rest_between_s",
                                                               low_ok=True, high=86400.0), note=note)
    n = len(out.amplitudes_mm) * len(out.directions) * out.repeats
    if n > MAX_SWEEPS:
        raise PlanError(f"{where}: {n} sweeps; a campaign has at most {MAX_SWEEPS}")
    return out


def load_plan(path) -> CampaignPlan:
    """A plan from a TOML file (PlanError naming the file and the problem)."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise PlanError(f"{path}: {exc}") from None
    try:
        return parse_plan(data, str(path))
    except PlanError as exc:  # the file named once (its top level's errors name it as their `where`)
        message = str(exc)
        raise PlanError(message if message.startswith(f"{path}:") else f"{path}: {message}") from None


def plan_violation(limits: Limits, plan: CampaignPlan) -> str | None:
    """The first sweep of the plan that breaks a limit, named with the limit (the PLC's own check), or None."""
    sweeps = plan.sweeps()
    for s in sweeps:
        problem = limit_violation(limits, s.request())
        if problem:
            return f"{s.label(len(sweeps))}: {problem}"
    return None


def plan_prediction(response: RigResponse, limits: Limits, plan: CampaignPlan) -> tuple[str | None, dict]:
    """Every sweep of the plan through the preflight's prediction (daq/preflight.py): the first refused one
    named with its prediction and what would pass ('sweep 3 of 6 (1.3 mm, up): ...') or None, and the
    warnings {sweep label: [...]}. Sweeps that break a limit are left to plan_violation; repeats are
    predicted once (what would pass is searched for a refused sweep only: assess's `suggest`)."""
    sweeps = plan.sweeps()
    seen: dict[tuple, Verdict] = {}
    warnings: dict[str, list[str]] = {}
    for s in sweeps:
        if limit_violation(limits, s.request()):
            continue
        key = (s.f_start_hz, s.f_end_hz, s.duration_s, s.amplitude_mm)
        if key not in seen:
            seen[key] = predicted_verdict(response, s.request())
        if seen[key].refusal:
            return f"{s.label(len(sweeps))}: {seen[key].refusal}", warnings
        if seen[key].warnings:
            warnings[s.label(len(sweeps))] = seen[key].warnings
    return None, warnings


def sweep_problem(outcome: dict) -> str | None:
    """Why a sweep's outcome does not count as done, or None: the recording ended complete and its
    quality flags do not make it unusable (a verdict the recorder already computed: free to read)."""
    status = outcome.get("status")
    if status != "complete":
        reason = outcome.get("reason") or "no reason given"
        return f"ended {status}: {reason}" if status not in (None, "refused") else f"not started: {reason}"
    quality = outcome.get("quality") or {}
    if quality.get("usable_for_identification") is False:
        return "recorded, but not usable for identification: " + ("; ".join(quality.get("reasons") or []) or
                                                                   "quality flags")
    return None


@dataclass
class Campaign:
    """A campaign's progress: the plan's sweeps, each with its attempts, the state and why it is so."""
    plan: CampaignPlan
    state: str = "paused"
    reason: str | None = None
    items: list[dict] = field(default_factory=list)

    def __post_init__(self):
        if not self.items:
            self.items = [{**asdict(s), "status": "planned", "sweep_id": None, "recording_id": None, "path": None,
                           "reason": None, "attempts": []} for s in self.plan.sweeps()]

    @property
    def total(self) -> int:
        return len(self.items)

    @property
    def done(self) -> int:
        return sum(1 for it in self.items if it["status"] == "complete")

    def next_item(self) -> dict | None:
        return next((it for it in self.items if it["status"] != "complete"), None)

    def planned(self, item: dict) -> PlannedSweep:
        return PlannedSweep(**{k: item[k] for k in PlannedSweep.__dataclass_fields__})

    def recording_ids(self) -> list[str]:
        """The complete recordings in plan order: what a joint identification of the campaign reads."""
        return [it["recording_id"] for it in self.items if it["status"] == "complete" and it["recording_id"]]

    def progress(self) -> dict:
        running = next((it["index"] for it in self.items if it["status"] == "running"), None)
        return {"done": self.done, "total": self.total, "current": running}

    def begin(self, item: dict, **ids) -> None:
        if item["status"] not in ("planned", "running"):  # an earlier attempt: kept, the new one replaces it
            item["attempts"].append({k: item[k] for k in ("status", "sweep_id", "recording_id", "path", "reason")})
            item.update(reason=None, sweep_id=None, recording_id=None, path=None)
        item.update(status="running", **ids)

    def end(self, item: dict, outcome: dict) -> str | None:
        """Record a sweep's outcome; returns why it does not count (sweep_problem), or None. A sweep
        "held" (not started because a pause or abort came first) goes back to planned."""
        if outcome.get("status") == "held":
            item.update(status="planned", reason=None)
            return None
        problem = sweep_problem(outcome)
        item.update(status="complete" if problem is None else "failed", reason=problem,
                    **{k: outcome[k] for k in ("sweep_id", "recording_id", "path") if outcome.get(k)})
        return problem

    def to_dict(self) -> dict:
        return {"state": self.state, "reason": self.reason, "plan": self.plan.to_dict(), "sweeps": self.items,
                "progress": self.progress(), "recording_ids": self.recording_ids()}


class CampaignControl:
    """Requests to a running campaign from other threads: plain attributes and one Event, no lock that
    anyone holds for long (an emergency stop sets `pause_reason` and must never wait for a campaign)."""

    def __init__(self):
        self.pause_reason: str | None = None
        self.abort_reason: str | None = None
        self.halted = False  # an emergency stop (or the like): the running sweep is aborted too
        self.wake = threading.Event()

    def held(self) -> str | None:
        """Why no sweep may start now (an abort, a pause, a halt), or None."""
        return self.abort_reason or self.pause_reason

    def pause(self, reason: str) -> None:
        if self.pause_reason is None:
            self.pause_reason = reason
        self.wake.set()

    def abort(self, reason: str) -> None:
        if self.abort_reason is None:
            self.abort_reason = reason
        self.wake.set()

    def halt(self, reason: str) -> None:
        """Pause, and the running sweep is to be aborted (an emergency stop, a lost web server)."""
        self.halted = True
        self.pause(reason)


def rest(control: CampaignControl, seconds: float, check=None, poll_s: float = 0.5) -> str | None:
    """Wait `seconds` between two sweeps, cut short by a pause or an abort; check() (e.g. the PLC's
    state) is asked every poll_s and a reason it returns ends the rest: the reason to pause."""
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        if control.pause_reason or control.abort_reason:
            return None
        control.wake.wait(min(left, poll_s))
        if check is not None and (problem := check()):
            return problem
    return None


def run_campaign(campaign: Campaign, run_sweep, control: CampaignControl, save, check=None) -> Campaign:
    """Run the sweeps not yet done, in order, until all are done (completed), one does not count or a
    pause is asked for (paused, with the reason), or an abort (aborted, with the reason).

    run_sweep(planned, item) runs one sweep to its end and returns its outcome {status, reason, quality,
    and sweep_id/recording_id/path where there are}, status "held" if it did not start because
    control.held() said so at the last moment (the loop then pauses or aborts); it may call campaign.begin(item, ...) itself to
    publish ids while the sweep runs (else it is called here first). save(campaign) is called at every
    change. check() -> reason or None: asked between sweeps (rest and before a start)."""
    if campaign.state not in ("running", "pausing"):  # "pausing": a pause came before this thread ran
        campaign.state = "running"
    campaign.reason = None
    save(campaign)
    first = True
    while True:
        if control.abort_reason:
            campaign.state, campaign.reason = "aborted", control.abort_reason
            break
        item = campaign.next_item()
        if item is None:
            campaign.state, campaign.reason = "completed", None
            break
        if control.pause_reason:
            campaign.state, campaign.reason = "paused", control.pause_reason
            break
        if not first and campaign.plan.rest_between_s > 0:
            problem = rest(control, campaign.plan.rest_between_s, check)
            if problem:
                control.pause(f"before sweep {item['index']} of {campaign.total}: {problem}")
            if control.pause_reason or control.abort_reason:
                continue
        first = False
        planned = campaign.planned(item)
        campaign.begin(item)
        save(campaign)
        outcome = run_sweep(planned, item)
        problem = campaign.end(item, outcome)
        if problem:
            campaign.state = "aborted" if control.abort_reason else "paused"
            campaign.reason = control.abort_reason or f"{planned.label(campaign.total)} {problem}"
            break
        save(campaign)
    save(campaign)
    return campaign
