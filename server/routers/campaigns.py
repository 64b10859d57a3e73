"""Campaigns: several sweeps one after another in the rig controller, then one joint identification."""
from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.concurrency import run_in_threadpool
from pydantic import Field

from .. import schemas
from ..catalog import Catalog
from ..deps import ERRORS, Id, Services, operator, services, viewer
from ..preflight import plan_refusal

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
    """The newest campaigns, each with its latest joint identification job (or null)."""
    campaigns = svc.catalog.list("campaigns", limit=limit)
    joint = latest_joint_jobs(svc.catalog, [c["id"] for c in campaigns])
    return [{**c, "joint_identification": joint.get(c["id"])} for c in campaigns]


def latest_joint_jobs(catalog: Catalog, campaign_ids: list[str]) -> dict:
    """{campaign id: its newest identify_joint job}, for these campaigns only (one query; every campaign's
    jobs had been read for each list and each single campaign)."""
    if not campaign_ids:
        return {}
    marks = ", ".join("?" * len(campaign_ids))
    out = {}
    for j in catalog.list("jobs", f"kind = 'identify_joint' AND json_extract(options, '$.campaign_id') IN ({marks})",
                          tuple(campaign_ids), limit=10_000):
        out.setdefault(j["options"]["campaign_id"], j)  # newest first
    return out


@router.get("/api/campaigns/{campaign_id}", response_model=schemas.CampaignOut, dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
async def get_campaign(campaign_id: str = Id(), svc: Services = Depends(services)):
    """State, plan, each sweep with its recording and status, progress, and why it paused or aborted."""
    campaign = svc.catalog.get("campaigns", campaign_id)
    if campaign is None:
        raise HTTPException(404, f"no campaign {campaign_id}")
    return {**campaign, "joint_identification": latest_joint_jobs(svc.catalog, [campaign_id]).get(campaign_id)}


@router.post("/api/campaigns/{campaign_id}/{action}", status_code=202, response_model=schemas.Accepted,
             responses=CAMPAIGN_ERRORS)
async def campaign_action(action: Literal["pause", "resume", "abort"], campaign_id: str = Id(),
                          who: str = operator, svc: Services = Depends(services)):
    """pause: no next sweep (the running one finishes; state pausing, then paused). resume: re-run the
    sweep that failed and go on (409 while the PLC is in emergency stop or fault: reset it first).
    abort: the running sweep is stopped and the campaign ends aborted."""
    return await svc.controller(f"{action}_campaign", campaign_id=campaign_id, operator=who)
