"""Campaigns: several sweeps one after another in the rig controller, then one joint identification; on
request one explanation of their recordings together."""
from __future__ import annotations

import json
from pathlib import Path as FsPath
from typing import Literal

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.concurrency import run_in_threadpool
from pydantic import Field

from .. import schemas
from ..catalog import RESULT_FILES, Catalog
from ..deps import ERRORS, Id, Services, operator, services, viewer
from ..preflight import plan_refusal
from .jobs import check_at_the_door
from .results import newest_result

router = APIRouter(tags=["campaigns"])
CAMPAIGN_ERRORS = {**ERRORS, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem},
                   503: {"model": schemas.Problem}}


class CampaignAccepted(schemas.Accepted):
    preflight: dict | None = Field(None, description="warnings of the predicted peaks above "
                                                     "daq.preflight.WARN_SHARE of a limit, by sweep")


@router.post("/api/campaigns", status_code=202, response_model=CampaignAccepted,
             responses={**CAMPAIGN_ERRORS, 422: {"model": schemas.Problem}})
async def start_campaign(body: schemas.CampaignIn, who: str = operator, svc: Services = Depends(services)):
    """Start a campaign: its sweeps one after another in the rig controller. Every sweep is checked
    against the limits and predicted from the rig's model first (422 naming the sweep and the limit, or the
    predicted peak, where and what would pass; nothing moves); 409 while a sweep or a campaign runs or the
    PLC is in emergency stop or fault. Each sweep is predicted again right before it starts (a newer model
    may be known by then): a refusal there pauses the campaign."""
    plan = body.model_dump()
    refusal, warnings = await run_in_threadpool(plan_refusal, svc.catalog, svc.settings.rig, plan)
    if refusal:
        raise HTTPException(422, f"campaign refused: {refusal}")
    started = await svc.controller("start_campaign", plan=plan, operator=who)
    return {**started, "preflight": {"warnings": warnings}}


@router.get("/api/campaigns", response_model=list[schemas.CampaignOut], dependencies=[viewer], responses=ERRORS)
def list_campaigns(limit: int = Query(50, ge=1, le=500), svc: Services = Depends(services)):
    """The newest campaigns, each with its latest joint identification job and explanation job (or null)."""
    campaigns = svc.catalog.list("campaigns", limit=limit)
    return [{**c, **jobs} for c, jobs in zip(campaigns, campaign_jobs(svc.catalog, [c["id"] for c in campaigns]))]


#: CampaignOut's job fields and the job kind of each
CAMPAIGN_JOBS = {"joint_identification": "identify_joint", "explanation": "explain_campaign"}


def campaign_jobs(catalog: Catalog, campaign_ids: list[str]) -> list[dict]:
    """Each campaign's CAMPAIGN_JOBS fields: its newest job of each kind (or None), in campaign_ids' order."""
    latest = {field: newest_campaign_jobs(catalog, campaign_ids, kind) for field, kind in CAMPAIGN_JOBS.items()}
    return [{field: latest[field].get(cid) for field in CAMPAIGN_JOBS} for cid in campaign_ids]


def newest_campaign_jobs(catalog: Catalog, campaign_ids: list[str], kind: str) -> dict:
    """{campaign id: its newest job of kind (CAMPAIGN_JOBS: its joint model, its explanation)}, for these
    campaigns only (one query; every campaign's jobs had been read for each list and each single campaign)."""
    if not campaign_ids:
        return {}
    marks = ", ".join("?" * len(campaign_ids))
    out = {}
    for j in catalog.list("jobs", f"kind = ? AND json_extract(options, '$.campaign_id') IN ({marks})",
                          (kind, *campaign_ids), limit=10_000):
        out.setdefault(j["options"]["campaign_id"], j)  # newest first
    return out


@router.get("/api/campaigns/{campaign_id}", response_model=schemas.CampaignOut, dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
async def get_campaign(campaign_id: str = Id(), svc: Services = Depends(services)):
    """State, plan, each sweep with its recording and status, progress, why it paused or aborted, and its
    latest joint identification and explanation jobs."""
    campaign = svc.catalog.get("campaigns", campaign_id)
    if campaign is None:
        raise HTTPException(404, f"no campaign {campaign_id}")
    return {**campaign, **campaign_jobs(svc.catalog, [campaign_id])[0]}


def usable_recordings(svc: Services, campaign: dict, accept_faulty: bool) -> tuple[list[dict], list[str]]:
    """The campaign's recordings an explanation can use (in the catalog, complete, and not flagged
    unusable unless accept_faulty), in plan order, and why each other one is left out."""
    usable, left_out = [], []
    for rec_id in campaign["recording_ids"]:
        rec = svc.catalog.get("recordings", rec_id)
        quality = (rec or {}).get("info", {}).get("quality") or {}
        if rec is None:
            left_out.append(f"{rec_id}: no longer in the catalog")
        elif rec["status"] != "complete":
            left_out.append(f"{rec_id}: {rec['status']}")
        elif quality.get("usable_for_identification") is False and not accept_faulty:
            left_out.append(f"{rec_id}: unusable ({'; '.join(quality.get('reasons') or []) or 'quality flags'})")
        else:
            usable.append(rec)
    return usable, left_out


@router.post("/api/campaigns/{campaign_id}/explain", status_code=202, response_model=schemas.JobOut,
             dependencies=[operator], responses={**CAMPAIGN_ERRORS, 422: {"model": schemas.Problem}})
def explain_campaign(body: schemas.ExplainIn | None = None, campaign_id: str = Id(),
                     svc: Services = Depends(services)):
    """Queue one discrepancy analysis of a completed campaign's recordings together (`shakeid explain A.h5
    B.h5 ...`; job kind explain_campaign); the read options apply to every recording. 409 while the campaign
    is not completed or has fewer than two usable recordings. Then GET /api/campaigns/{id}/explanation."""
    campaign = svc.catalog.get("campaigns", campaign_id)
    if campaign is None:
        raise HTTPException(404, f"no campaign {campaign_id}")
    if campaign["state"] != "completed":
        raise HTTPException(409, f"campaign {campaign_id} is {campaign['state']}: a campaign is explained once it "
                                 "has completed" + (f" ({campaign['reason']})" if campaign.get("reason") else ""))
    options = body.model_dump(exclude_none=True) if body is not None else {}
    recs, left_out = usable_recordings(svc, campaign, bool(options.get("accept_faulty")))
    if len(recs) < 2:
        raise HTTPException(409, f"campaign {campaign_id} has {len(recs)} usable recording(s); one explanation "
                                 "over a campaign needs two or more (a single recording is explained by POST "
                                 "/api/recordings/{id}/explain)" + (f"; left out: {', '.join(left_out)}" if left_out else ""))
    stored = [rec["info"].get("read_options", {}) for rec in recs]
    for rec, own in zip(recs, stored):
        check_at_the_door(rec, {**own, **options})
    ids = [rec["id"] for rec in recs]
    return svc.jobs.submit("explain_campaign", ids[0], {**options, "recording_ids": ids, "campaign_id": campaign_id,
                                                        "read_options_by_recording": stored, "left_out": left_out})


@router.get("/api/campaigns/{campaign_id}/explanation", dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
def campaign_explanation(campaign_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """The campaign's latest explanation: the JSON of `shakeid explain A.h5 B.h5 ... --json` (its
    `recordings` section, one entry per recording). 404 saying why there is none (yet)."""
    if svc.catalog.get("campaigns", campaign_id) is None:
        raise HTTPException(404, f"no campaign {campaign_id}")
    jobs = svc.catalog.list("jobs", "kind = 'explain_campaign' AND json_extract(options, '$.campaign_id') = ?",
                            (campaign_id,))
    path = newest_result(jobs, RESULT_FILES["explain_campaign"], f"no explanation of campaign {campaign_id}", "explain",
                         f": none was asked for (POST /api/campaigns/{campaign_id}/explain)")
    return json.loads(path.read_text())


@router.post("/api/campaigns/{campaign_id}/{action}", status_code=202, response_model=schemas.Accepted,
             responses=CAMPAIGN_ERRORS)
async def campaign_action(action: Literal["pause", "resume", "abort"], campaign_id: str = Id(),
                          who: str = operator, svc: Services = Depends(services)):
    """pause: no next sweep (the running one finishes; state pausing, then paused). resume: re-run the
    sweep that failed and go on (409 while the PLC is in emergency stop or fault: reset it first).
    abort: the running sweep is stopped and the campaign ends aborted."""
    return await svc.controller(f"{action}_campaign", campaign_id=campaign_id, operator=who)
