"""The predicted frequency response beside the measured sweeps (identify.frf.side_by_side), as each
identification stored it: a recording's (its latest identify job) and a campaign's (its joint job, every
table amplitude of the campaign). docs/frf.md, docs/service.md."""
from __future__ import annotations

import asyncio
import dataclasses
import json
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path as FsPath

from fastapi import APIRouter, Depends, HTTPException
from fastapi.responses import FileResponse, JSONResponse
from pydantic import Field

from daq.campaign import NAME_PATTERN
from daq.plan import JUMP_AMPLITUDES, JUMP_AMPLITUDES_RANGE, PROPOSAL_NAME, propose_campaign, with_model
from identify.errors import ShakeidError
from identify.model import SparseModel
from reports.frf_overlay import OVERLAY_FIGURE as OVERLAY  # drawn by the worker, served from its report

from .. import schemas
from ..catalog import ID_PATTERN
from ..deps import ERRORS, Id, Services, services, viewer
from ..preflight import rig_limits, rig_response
from ..worker import FRF_FILE
from .campaigns import newest_campaign_jobs
from .results import latest_result

router = APIRouter(tags=["frequency response"], dependencies=[viewer],
                   responses={**ERRORS, 404: {"model": schemas.Problem}})


@router.get("/api/recordings/{rec_id}/frf")
def recording_frf(rec_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """The latest identification's frequency response beside the recording's sweep: per table amplitude
    the predicted branches and folds, the measured per-cycle envelope and jump, `jumps` (measured vs
    predicted, `agrees`), `flagged` with `flags`; `status` not "ok" with the `reason` when there is none
    (not a sweep, not a base-excited model, or the computation failed: the model stands without it)."""
    return json.loads(latest_result(svc, rec_id, "identify", FRF_FILE).read_text())


@router.get("/api/campaigns/{campaign_id}/frf")
def campaign_frf(campaign_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """The campaign's joint model's frequency response beside every sweep of the campaign, one entry per
    table amplitude (the same document as a recording's)."""
    return json.loads(_campaign_file(svc, campaign_id, FRF_FILE).read_text())


@router.get("/api/campaigns/{campaign_id}/frf.png", response_class=FileResponse)
def campaign_frf_figure(campaign_id: str = Id(), svc: Services = Depends(services)):
    """The campaign's overlay figure (a panel per table amplitude); a recording's is its report's
    frf_overlay.png (GET /api/recordings/{id}/plots/frf_overlay.png)."""
    return FileResponse(_campaign_file(svc, campaign_id, f"report/{OVERLAY}"), media_type="image/png")


def _campaign_file(svc: Services, campaign_id: str, name: str) -> FsPath:
    """`name` in the result folder of the campaign's newest joint identification; 404 saying why not."""
    if svc.catalog.get("campaigns", campaign_id) is None:
        raise HTTPException(404, f"no campaign {campaign_id}")
    job = newest_campaign_jobs(svc.catalog, [campaign_id], "identify_joint").get(campaign_id)
    if job is None:
        raise HTTPException(404, f"no frequency response for campaign {campaign_id} yet: its joint identification "
                                 "is queued when the campaign completes")
    path = FsPath(job["result_dir"]) / name
    if not path.is_file():
        why = f"failed: {job['error']}" if job["state"] == "failed" else f"is {job['state']}"
        if job["state"] == "completed":
            frf = FsPath(job["result_dir"]) / FRF_FILE
            why = ("has no overlay: " + json.loads(frf.read_text()).get("reason", "")) if frf.is_file() else \
                "has no frequency response (identified before the service computed one)"
        raise HTTPException(404, f"no frequency response for campaign {campaign_id}: its joint identification "
                                 f"{job['id']} {why}")
    return path


class ProposalIn(schemas.Strict):
    """What to propose a campaign from: a recording's latest identified model (default: the rig's latest,
    as the preflight predicts with, or its nominal parameters)."""
    recording_id: str | None = Field(None, pattern=ID_PATTERN, description="whose model (default: the rig's latest)")
    name: str = Field(PROPOSAL_NAME, pattern=NAME_PATTERN, description="the proposed campaign's name")
    jump_amplitudes: int = Field(JUMP_AMPLITUDES, ge=JUMP_AMPLITUDES_RANGE[0], le=JUMP_AMPLITUDES_RANGE[1],
                                 description="amplitudes with a predicted jump (one more below its onset)")


@router.post("/api/campaigns/proposal", responses={202: {"model": schemas.Problem}, 422: {"model": schemas.Problem}})
async def propose(body: ProposalIn, svc: Services = Depends(services)):
    """A campaign proposed from the model's predicted folds (daq.plan, `shakeid plan-campaign`): `plan`
    (for POST /api/campaigns) whose amplitudes and band bracket each predicted jump, every sweep inside
    the PLC's limits and predicted inside the rig's; `amplitudes` with the predicted jumps and peaks.
    Nothing moves. A proposal costs seconds: when it is not ready within PROPOSAL_WAIT_S the answer is 202
    (`detail`: ask again), and the same request later answers from the finished one. 422 when the model
    predicts no jump within what the rig takes."""
    rig = rig_response(svc.catalog, svc.settings.rig)
    if body.recording_id:
        doc = json.loads(latest_result(svc, body.recording_id, "identify", "model.json").read_text())
        rig = with_model(rig, SparseModel.from_dict(doc), f"the model identified from recording {body.recording_id}")
    limits = rig_limits(svc.settings.rig)
    key = json.dumps([rig.model.to_dict(), rig.source, rig.mass_range_ms2, rig.table_range_ms2, list(rig.travel_mm),
                      dataclasses.asdict(limits), body.jump_amplitudes], sort_keys=True)
    fut = _PROPOSALS.get(key)
    if fut is None or fut.cancelled():  # the same model and rig propose the same campaign: computed once
        fut = _PROPOSALS[key] = _COMPUTE.submit(_propose, rig, limits, body.jump_amplitudes)
        for old in [k for k, f in _PROPOSALS.items() if f.done()][:max(0, len(_PROPOSALS) - PROPOSALS_KEPT)]:
            _PROPOSALS.pop(old)
    try:
        out = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)), PROPOSAL_WAIT_S)
    except asyncio.TimeoutError:
        return JSONResponse({"detail": f"computing the proposal from {rig.source}: ask again in a few seconds"},
                            status_code=202)
    if isinstance(out, str):
        raise HTTPException(422, out)
    return {**out, "plan": {**out["plan"], "name": body.name}}


def _propose(rig, limits, jump_amplitudes: int):
    """The proposal, or the refusal's message (kept like a proposal: the same request is refused at once)."""
    try:
        return propose_campaign(rig, limits, "proposal", jump_amplitudes)
    except ShakeidError as exc:
        return f"no campaign proposed from {rig.source}: {exc}"


#: proposals kept (a proposal costs seconds of CPU; the dashboard asks again for the same rig), computed one
#: at a time off the event loop; an answer waits for one at most PROPOSAL_WAIT_S, then says to ask again
PROPOSALS_KEPT = 16
PROPOSAL_WAIT_S = 8.0
_PROPOSALS: dict[str, Future] = {}
_COMPUTE = ThreadPoolExecutor(max_workers=1, thread_name_prefix="campaign-proposal")
