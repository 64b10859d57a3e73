"""Recordings: list, read, download, upload (the live stream is server/routers/live.py)."""
from __future__ import annotations

import time

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import FileResponse

from identify.data.quality import with_status

from .. import schemas
from ..catalog import new_id
from ..deps import ERRORS, Id, Services, operator, services, viewer
from ..uploads import FILENAME_PATTERN, FILENAME_WORDS, store_upload

router = APIRouter(tags=["recordings"])


def with_verdict(rec: dict) -> dict:
    """The recording as served: its quality verdict says unusable when its status does (an aborted
    sweep's signals may be clean; identify refuses it all the same)."""
    info = rec.get("info") or {}
    if not isinstance(info.get("quality"), dict):
        return rec
    quality = with_status(info["quality"], rec.get("status"), info.get("reason"))
    return {**rec, "info": {**info, "quality": quality}}


@router.get("/api/recordings", response_model=list[schemas.RecordingOut], dependencies=[viewer], responses=ERRORS)
def list_recordings(limit: int = Query(50, ge=1, le=500), svc: Services = Depends(services)):
    return [with_verdict(rec) for rec in svc.catalog.list("recordings", limit=limit)]


@router.get("/api/recordings/{rec_id}", response_model=schemas.RecordingOut, dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
def get_recording(rec_id: str = Id(), svc: Services = Depends(services)):
    return with_verdict(svc.recording_or_404(rec_id))


@router.get("/api/recordings/{rec_id}/file", dependencies=[viewer], response_class=FileResponse,
            responses={**ERRORS, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem}})
def recording_file(rec_id: str = Id(), svc: Services = Depends(services)):
    """The recording as stored (HDF5 from sweeps; CSV, MAT or HDF5 as uploaded); 409 while it is being
    recorded (a copy taken between two flushes could be torn: follow /live instead)."""
    rec = svc.recording_or_404(rec_id)
    if rec["status"] == "running":
        raise HTTPException(409, f"recording {rec_id} is still being recorded; follow /live, fetch it after")
    return FileResponse(rec["path"], filename=rec["filename"], media_type="application/octet-stream")


@router.post("/api/recordings", status_code=201, response_model=schemas.RecordingOut,
             responses={**ERRORS, 413: {"model": schemas.Problem}, 422: {"model": schemas.Problem}})
async def upload_recording(request: Request, who: str = operator, svc: Services = Depends(services),
                           filename: str = Query(..., pattern=FILENAME_PATTERN,
                                                 description=FILENAME_WORDS),
                           layout: str = Query("base", pattern="^(base|force)$"),
                           input: str | None = Query(None, max_length=64),
                           output: str | None = Query(None, max_length=64),
                           time_column: str | None = Query(None, max_length=64),
                           fs_hz: float | None = Query(None, gt=0, le=1e7)):
    """Upload a recording from elsewhere as the request body (raw bytes); it is read once to check it,
    and refused with 422 naming the problem if it is not a usable recording."""
    options = {k: v for k, v in {"layout": layout, "input": input, "output": output, "time": time_column,
                                 "fs_hz": fs_hz}.items() if v is not None}
    rec_id, settings = new_id(), svc.settings
    path, info = await store_upload(request, settings.data_dir / "recordings", rec_id, filename, options,
                                    int(settings.max_upload_mb * 2**20))
    return svc.catalog.insert("recordings", id=rec_id, created=time.time(), origin="upload", filename=filename,
                              path=str(path), status="complete", sweep_id=None,
                              info={"read_options": options, "uploaded_by": who, **info})
