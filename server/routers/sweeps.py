"""Sine sweeps: start (through the rig controller), list, follow, abort."""
from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException, Query

from .. import schemas
from ..deps import ERRORS, Id, Services, operator, services, viewer

router = APIRouter(tags=["sweeps"])


@router.post("/api/sweeps", status_code=202, response_model=schemas.Accepted,
             responses={**ERRORS, 409: {"model": schemas.Problem}, 422: {"model": schemas.Problem},
                        503: {"model": schemas.Problem}})
async def start_sweep(body: schemas.SweepIn, who: str = operator, svc: Services = Depends(services)):
    """Start a sweep: refused with 422 naming the limit when unsafe, 409 while another runs or while the
    PLC is in emergency stop or fault (with the reason), 503 when the rig cannot be reached."""
    started = await svc.controller("start_sweep", body=body.model_dump(), operator=who)
    return {"id": started["id"], "state": started["state"]}


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
