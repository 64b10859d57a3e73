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

from daq.preflight import RigResponse, Verdict, nominal_response
from daq.sweep import SweepRequest, limit_violation, predicted_verdict
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
    return predicted_verdict(response, req, suggest)

