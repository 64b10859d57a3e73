"""The service's preflight that predicts (daq/preflight.py): which model of the rig it predicts with, and the
check of a sweep body at the door (POST /api/sweeps, every sweep of POST /api/campaigns, and each campaign
sweep again right before it starts, when a newer model may be known).

The model is the latest identified model of this rig: the newest complete recording the service's own rig
made (origin "sweep", not archived) whose identification delivered a model.json with a base-excited model;
else the rig's nominal parameters (the rig configuration's [rig], or the embedded simulated rig's).
"""
from __future__ import annotations

import dataclasses
import datetime
import json
from pathlib import Path

from daq.preflight import RigResponse, Verdict, assess, nominal_response
from daq.sweep import SineSweep, SweepRequest, limit_violation
from identify.errors import ModelError
from identify.model import SparseModel
from sim.config import RigConfig

#: recordings looked at (newest first) for a delivered model before the nominal parameters are used
MODEL_LOOKBACK = 20


def rig_response(catalog, rig: RigConfig | None) -> RigResponse:
    """The rig's response model: its latest identified model, else its nominal parameters."""
    nominal = nominal_response(rig or RigConfig())
    where = ("origin = 'sweep' AND status = 'complete' AND archived IS NULL "
             "AND json_extract(info, '$.last_identify_job') IS NOT NULL")
    for rec in catalog.list("recordings", where, limit=MODEL_LOOKBACK):
        job = catalog.get("jobs", rec["info"]["last_identify_job"])
        if not job or job.get("state") != "completed" or not job.get("result_dir"):
            continue
        try:
            doc = json.loads((Path(job["result_dir"]) / "model.json").read_text())
            if doc.get("status") == "failed":
                continue
            when = datetime.datetime.fromtimestamp(rec["created"], datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
            return dataclasses.replace(nominal, model=SparseModel.from_dict(doc),
                                       source=f"the model identified from recording {rec['id']} ({when})")
        except (OSError, ValueError, ModelError):
            continue  # being written, removed, or not a base-excited rig model: the next one
    return nominal


def request_of(body: dict) -> SweepRequest:
    return SweepRequest(float(body["f_start_hz"]), float(body["f_end_hz"]), float(body["duration_s"]),
                        float(body["amplitude_mm"]), float(body.get("settle_s", 2.0)))


def check_sweep(response: RigResponse, rig: RigConfig | None, body: dict, suggest: bool = True) -> Verdict | None:
    """The prediction's verdict on one sweep body, or None when the sweep breaks a PLC limit (the rig
    controller's check names it; nothing is predicted for a sweep that cannot run)."""
    req = request_of(body)
    if limit_violation((rig or RigConfig()).limits, req):
        return None
    return assess(response, SineSweep(req.f_start_hz, req.f_end_hz, req.duration_s, req.amplitude_mm), suggest)


def check_plan(response: RigResponse, rig: RigConfig | None, plan) -> tuple[str | None, dict[str, list[str]]]:
    """Every sweep of a campaign plan (daq.campaign.CampaignPlan) predicted: the first refused one named
    with its prediction and what would pass ('sweep 3 of 6 (1.3 mm, up): ...'), or None; and the warnings
    by sweep label. Sweeps of the same parameters (repeats) are predicted once."""
    sweeps = plan.sweeps()
    seen: dict[tuple, Verdict | None] = {}
    warnings: dict[str, list[str]] = {}
    for s in sweeps:
        body = s.body()
        key = (s.f_start_hz, s.f_end_hz, s.duration_s, s.amplitude_mm)
        if key not in seen:
            seen[key] = check_sweep(response, rig, body, suggest=False)
        verdict = seen[key]
        if verdict is not None and verdict.refusal:
            verdict = check_sweep(response, rig, body)  # again, with what would pass
            return f"{s.label(len(sweeps))}: {verdict.refusal}", warnings
        if verdict is not None and verdict.warnings:
            warnings[s.label(len(sweeps))] = verdict.warnings
    return None, warnings
