"""Health and the rig: PLC status, emergency stop, reset (all through the rig controller)."""
from __future__ import annotations

import time

from fastapi import APIRouter, Depends, HTTPException, Request

from daq.recorder import software_version

from .. import schemas
from ..deps import ERRORS, Services, operator, services, viewer
from ..ipc import ControllerRefused, ControllerUnavailable
from ..stoplistener import ESTOP_PATH, not_delivered

#: GET /api/rig answers from a copy at most this old, s: pollers never become load on the rig controller
RIG_STATUS_MAX_AGE_S = 0.1

router = APIRouter()


@router.get("/api/health", response_model=schemas.Health, tags=["service"])
def health(request: Request, svc: Services = Depends(services)):
    """Liveness, without a token (for supervisors and compose health checks); stop_url: where the
    emergency stop is served apart from the viewers (the rig controller's stop listener), if anywhere."""
    origin = svc.stop_origin(request.headers.get("host"))
    return {"status": "ok", "version": software_version(), "rig_simulated": svc.settings.rig is None,
            "controller": "attached" if svc.link.attached.is_set() else "unreachable",
            "jobs_queued": svc.catalog.count("jobs", "state = 'queued'"),
            "stop_url": origin + ESTOP_PATH if origin else None}


@router.get("/api/rig", tags=["rig"], responses={**ERRORS, 503: {"model": schemas.Problem}}, dependencies=[viewer])
async def rig_status(svc: Services = Depends(services)) -> dict:
    """PLC state, accelerometers, safety limits, the active sweep (from the rig controller, at most
    RIG_STATUS_MAX_AGE_S old: however many clients poll, the controller answers ten times a second)."""
    cache = svc.rig_cache
    async with cache["lock"]:
        if time.monotonic() - cache["t"] >= RIG_STATUS_MAX_AGE_S:
            cache["value"] = await svc.controller("status")
            cache["t"] = time.monotonic()
        return cache["value"]


@router.post(ESTOP_PATH, response_model=schemas.EstopOut, tags=["rig"], dependencies=[operator],
             responses={**ERRORS, 503: {"model": schemas.Problem}})
async def estop(svc: Services = Depends(services)):
    """Emergency stop: the table ramps to rest at once; an active sweep ends aborted. The same stop is
    served where no viewer traffic waits: /api/health's stop_url (the rig controller's stop listener)."""
    # sent from the event loop itself, not via a thread: under load every hop through the loop's queue
    # waits behind the other requests (~15 ms each with 50 pollers). The call is one message on the
    # connection kept for stops to a real-time thread of the controller (a few ms; at most
    # ESTOP_TIMEOUT_S if the controller hangs, and at once if it is gone)
    try:
        return svc.link.client.emergency_stop()
    except (ControllerRefused, ControllerUnavailable) as exc:
        raise HTTPException(503, not_delivered(exc)) from None
    finally:
        svc.rig_cache["t"] = -1e9  # the next GET /api/rig shows the stop


@router.post("/api/rig/reset", response_model=schemas.ResetOut, tags=["rig"], dependencies=[operator],
             responses={**ERRORS, 409: {"model": schemas.Problem}, 503: {"model": schemas.Problem}})
async def reset(svc: Services = Depends(services)):
    """Clear a fault or an emergency stop once the table is at rest; 409 if the PLC stays in it."""
    try:
        return await svc.controller("reset")
    finally:
        svc.rig_cache["t"] = -1e9
