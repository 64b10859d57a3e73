"""Sine sweeps: start (through the rig controller), list, follow, abort."""
from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.concurrency import run_in_threadpool
from pydantic import Field

from daq.sweep import SweepRefused

from .. import schemas
from ..deps import ERRORS, Id, Services, operator, services, viewer
from ..preflight import predicted_body

router = APIRouter(tags=["sweeps"])


class SweepAccepted(schemas.Accepted):
    preflight: dict | None = Field(None, description="the predicted peaks of the sweep (mass acceleration, relative "
                                                     "travel, each with its frequency and limit) and the warnings "
                                                     "above daq.preflight.WARN_SHARE of a limit")


@router.post("/api/sweeps", status_code=202, response_model=SweepAccepted,
             responses={**ERRORS, 409: {"model": schemas.Problem}, 422: {"model": schemas.Problem},
                        503: {"model": schemas.Problem}})
async def start_sweep(body: schemas.SweepIn, who: str = operator, svc: Services = Depends(services)):
    """Start a sweep: refused with 422 naming the limit when unsafe or when the rig's model predicts that
    the mass accelerometer would clip or the mass hit the end stops (the predicted peak, the limit, the
    frequency and what would pass), 409 while another runs or while the PLC is in emergency stop or fault
    (with the reason), 503 when the rig cannot be reached. The prediction (and its warnings above
    WARN_SHARE of a limit) is kept in the sweep's request and answered here."""
    try:  # ~0.2 s for 300 s: off the event loop
        sweep = await run_in_threadpool(predicted_body, svc.catalog, svc.settings.rig, body.model_dump())
    except SweepRefused as exc:
        raise HTTPException(422, str(exc)) from None
    started = await svc.controller("start_sweep", body=sweep, operator=who)
    return {"id": started["id"], "state": started["state"], "preflight": sweep.get("preflight")}


@router.get("/api/sweeps", response_model=list[schemas.SweepOut], dependencies=[viewer], responses=ERRORS)
def list_sweeps(limit: int = Query(50, ge=1, le=500), svc: Services = Depends(services)):
    return svc.catalog.list("sweeps", limit=limit)


@router.get("/api/sweeps/{sweep_id}", response_model=schemas.SweepOut, dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
async def get_sweep(sweep_id: str = Id(), svc: Services = Depends(services)):
    """Polled by dashboards: answered on the event loop (one indexed SQLite read, no thread hop)."""
    sweep = svc.catalog.get("sweeps", sweep_id)
    if sweep is None:
        raise HTTPException(404, f"no sweep {sweep_id}")
    return sweep


@router.post("/api/sweeps/{sweep_id}/abort", status_code=202, response_model=schemas.Accepted,
             dependencies=[operator], responses={**ERRORS, 404: {"model": schemas.Problem},
                                                  409: {"model": schemas.Problem}})
async def abort_sweep(sweep_id: str = Id(), svc: Services = Depends(services)):
    """Operator abort: the table is commanded to stop, the recording ends 'aborted'."""
    sweep = svc.catalog.get("sweeps", sweep_id)
    if sweep is None:
        raise HTTPException(404, f"no sweep {sweep_id}")
    if not await svc.controller("abort", sweep_id=sweep_id):
        raise HTTPException(409, f"sweep {sweep_id} is {sweep['state']}, not running")
    return {"id": sweep_id, "state": "aborting"}
