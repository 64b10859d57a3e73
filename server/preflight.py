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
import functools
import json
from pathlib import Path

from daq.campaign import PlanError, parse_plan, plan_prediction
from daq.preflight import RigResponse, nominal_response
from daq.sweep import SweepRefused, SweepRequest, limit_violation, predicted_verdict
from identify.errors import ModelError
from identify.model import SparseModel
from protocol.plc import Limits
from sim.config import RigConfig

#: recordings looked at (newest first) for a delivered model before the nominal parameters are used
MODEL_LOOKBACK = 20


def rig_limits(rig: RigConfig | None) -> Limits:
    """The PLC's limits of the service's rig (the embedded simulated rig's when there is no configuration)."""
    return (rig or RigConfig()).limits


def rig_response(catalog, rig: RigConfig | None) -> RigResponse:
    """The rig's response model: its latest identified model, else its nominal parameters. One catalog
    statement (NamedQueries.identified); each model.json is read once per process (_delivered_model)."""
    nominal = nominal_response(rig or RigConfig())
    for rec, result_dir in catalog.queries.identified(MODEL_LOOKBACK, rig_sweeps=True):
        model = _delivered_model(result_dir)
        if model is None:
            continue
        when = datetime.datetime.fromtimestamp(rec["created"], datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        try:
            return dataclasses.replace(nominal, model=model,
                                       source=f"the model identified from recording {rec['id']} ({when})")
        except ModelError:
            continue  # not a base-excited rig model: the next one
    return nominal


@functools.lru_cache(maxsize=4 * MODEL_LOOKBACK)
def _delivered_model(result_dir: str) -> SparseModel | None:
    """The model a completed identification delivered in its result folder, or None (none delivered, or
    not a model). A completed job's folder never changes: read and parsed once, not at every sweep."""
    try:
        doc = json.loads((Path(result_dir) / "model.json").read_text())
        return None if doc.get("status") == "failed" else SparseModel.from_dict(doc)
    except (OSError, ValueError, ModelError):
        return None


def request_of(body: dict) -> SweepRequest:
    return SweepRequest(float(body["f_start_hz"]), float(body["f_end_hz"]), float(body["duration_s"]),
                        float(body["amplitude_mm"]), float(body.get("settle_s", 2.0)))


def predicted_body(catalog, rig: RigConfig | None, body: dict) -> dict:
    """The sweep body with the prediction's record (and its warnings) under "preflight"; SweepRefused
    ("sweep refused: ...") when the prediction refuses it. A sweep that breaks a PLC limit is returned
    as it is: the rig controller's check names the limit, nothing is predicted for it."""
    req = request_of(body)
    if limit_violation(rig_limits(rig), req):
        return body
    verdict = predicted_verdict(rig_response(catalog, rig), req)
    if verdict.refusal:
        raise SweepRefused(f"sweep refused: {verdict.refusal}")
    return {**body, "preflight": verdict.record}


def plan_refusal(catalog, rig: RigConfig | None, plan: dict) -> tuple[str | None, dict]:
    """Every sweep of a campaign plan predicted (daq.campaign.plan_prediction): the first refused one named,
    or None, and the warnings by sweep; (None, {}) for a plan the controller refuses anyway (it names the
    key or the limit)."""
    try:
        parsed = parse_plan(plan)
    except PlanError:
        return None, {}
    return plan_prediction(rig_response(catalog, rig), rig_limits(rig), parsed)
