"""The live view of a recording: server-sent events while it is being recorded.

Every viewer of a recording is served from one shared feed (server/livefeed.py): one reader of the rig
controller's samples per recording, each batch encoded once, a bounded queue per viewer that drops for a
slow reader. The streams are async generators on the event loop: none of them holds a worker of the
thread pool, and however many viewers there are, the controller is asked ten times a second.
"""
from __future__ import annotations

from fastapi import APIRouter, Depends, Query
from fastapi.responses import StreamingResponse

from .. import schemas
from ..controller import LIVE_BATCH
from ..deps import ERRORS, Id, Services, services, viewer
from ..livefeed import LiveFeeds, end_event

router = APIRouter(tags=["recordings"])


def feeds(svc: Services) -> LiveFeeds:
    """The service's live feeds, made on first use (on the event loop: no race)."""
    if svc.live_feeds is None:
        client, catalog = svc.link.client, svc.catalog
        svc.live_feeds = LiveFeeds(
            lambda rec_id, after: client.call("live", recording_id=rec_id, after=after),
            lambda rec_id: (catalog.get("recordings", rec_id) or {}).get("status", "unknown"),
            svc.shutting_down, batch_limit=LIVE_BATCH)
    return svc.live_feeds


@router.get("/api/recordings/{rec_id}/live", dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}, 200: {"content": {"text/event-stream": {}}}})
async def live(rec_id: str = Id(), after: int = Query(0, ge=0, description="last sequence number seen"),
               svc: Services = Depends(services)):
    """Server-sent events while recording: `samples` events with decimated samples (about 200 per second:
    `first` and `seq` the numbers of the first and last sample, t in s into the sweep, one list per channel
    in m/s^2), `missed` when this client fell behind and the oldest of its queued samples were dropped
    (`missed_samples`, `resume_seq`), then `end` with the recording's status."""
    rec = svc.recording_or_404(rec_id)
    if rec["status"] != "running":
        async def ended():
            yield end_event(rec_id, rec["status"])
        stream = ended()
    else:
        stream = feeds(svc).stream(rec_id, after)
    return StreamingResponse(stream, media_type="text/event-stream", headers={"Cache-Control": "no-cache"})


@router.get("/api/live", dependencies=[viewer], responses=ERRORS)
async def live_streams(svc: Services = Depends(services)) -> dict:
    """The live streams being served, per recording: viewers, reads of the rig controller so far (one
    reader per recording, whatever the number of viewers), the longest viewer queue (frames) and the
    frames dropped for slow viewers."""
    return {"recordings": svc.live_feeds.stats() if svc.live_feeds is not None else {}}
