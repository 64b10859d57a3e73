"""The live view of a recording: server-sent events while it is being recorded."""
from __future__ import annotations

import asyncio
import json
import time

from fastapi import APIRouter, Depends, Query
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import StreamingResponse

from .. import schemas
from ..deps import ERRORS, Id, Services, services, viewer
from ..ipc import ControllerRefused, ControllerUnavailable

router = APIRouter(tags=["recordings"])


@router.get("/api/recordings/{rec_id}/live", dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}, 200: {"content": {"text/event-stream": {}}}})
async def live(rec_id: str = Id(), after: int = Query(0, ge=0, description="last sequence number seen"),
               svc: Services = Depends(services)):
    """Server-sent events while recording: `samples` events with decimated samples (about 200 per
    second: t in s, one list per channel in m/s^2), then `end` with the recording's status."""
    rec = svc.recording_or_404(rec_id)
    client = svc.link.client

    async def events():
        seq, quiet_since = after, time.monotonic()
        while rec["status"] == "running" and not svc.shutting_down.is_set():
            try:
                view = await run_in_threadpool(client.call, "live", recording_id=rec_id, after=seq)
            except (ControllerRefused, ControllerUnavailable):
                view = {"active": False}
            points = view.get("points") or []
            if not points and time.monotonic() - quiet_since > 10:
                quiet_since = time.monotonic()
                yield ": keep-alive\n\n"  # a comment line: keeps proxies from closing a quiet stream
            if points:
                quiet_since = time.monotonic()
                seq = points[-1][0]
                cols = list(zip(*points))
                payload = {"seq": seq, "t": cols[1], **{c: cols[2 + j] for j, c in enumerate(view["channels"])}}
                yield f"event: samples\nid: {seq}\ndata: {json.dumps(payload)}\n\n"
            elif not view.get("active") or view.get("done"):
                break
            await asyncio.sleep(0.1)
        status = (svc.catalog.get("recordings", rec_id) or rec)["status"]
        yield f"event: end\ndata: {json.dumps({'recording_id': rec_id, 'status': status})}\n\n"

    return StreamingResponse(events(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"})
