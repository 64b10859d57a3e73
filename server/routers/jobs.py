"""Identification and explanation jobs: queue them (one recording or several), follow them."""
from __future__ import annotations

import json
import re
from pathlib import Path as FsPath

from fastapi import APIRouter, Depends, HTTPException, Query

from .. import schemas
from ..deps import ERRORS, Id, Services, operator, services, viewer

router = APIRouter(tags=["jobs"])
QUEUE_ERRORS = {**ERRORS, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem}}


#: the highest degree of a term (the sum of its factors' powers) a request may add: the library's own bound
#: (IdentifyIn's degree <= 8, as the CLI's)
MAX_TERM_DEGREE = next(int(m.le) for m in schemas.IdentifyIn.model_fields["degree"].metadata
                       if getattr(m, "le", None) is not None)
_POWER = re.compile(r"\^(\d{1,6})")


def refused(field: str, msg: str) -> HTTPException:
    """A 422 naming the body field, as the schema's own refusals do."""
    return HTTPException(422, [{"loc": ["body", field], "msg": msg, "type": "value_error"}])


def check_at_the_door(rec: dict, options: dict) -> None:
    """What the schema cannot see, checked before a job is queued: the band against the recording's
    Nyquist frequency (where the recording's rate is known) and each extra term's size."""
    fs_hz = options.get("fs_hz") or rec["info"].get("fs_hz")
    band = options.get("band_hz")
    if band and fs_hz and band[1] > fs_hz / 2:
        raise refused("band_hz", f"the band's upper edge {band[1]:g} Hz is above the Nyquist frequency "
                                 f"{fs_hz / 2:g} Hz of recording {rec['id']} (sampled at {fs_hz:g} Hz)")
    for term in options.get("extra_terms") or ():
        factors = term.split("*")
        degree = sum(int(m.group(1)) if (m := _POWER.search(f)) else 1 for f in factors)
        if degree > MAX_TERM_DEGREE:
            raise refused("extra_terms", f"term {term[:40]!r}{'...' if len(term) > 40 else ''} has degree {degree}; "
                                         f"a term's degree (its factors' powers added) is at most {MAX_TERM_DEGREE}")


def submit(svc: Services, kind: str, rec_id: str, options: dict) -> dict:
    """Queue a job of one recording, with the recording's stored read options under the request's."""
    rec = svc.recording_or_404(rec_id)
    if rec["status"] == "running":
        raise HTTPException(409, f"recording {rec_id} is still being recorded")
    options = {**rec["info"].get("read_options", {}), **options}
    check_at_the_door(rec, options)
    return svc.jobs.submit(kind, rec_id, options)


@router.post("/api/recordings/{rec_id}/identify", status_code=202, response_model=schemas.JobOut,
             dependencies=[operator], responses=QUEUE_ERRORS)
def identify(body: schemas.IdentifyIn | None = None, rec_id: str = Id(), svc: Services = Depends(services)):
    """Queue an identification with the CLI's options (no body: its defaults, as explain); poll
    GET /api/jobs/{id}."""
    return submit(svc, "identify", rec_id, body.model_dump(exclude_none=True) if body is not None else {})


@router.post("/api/identify", status_code=202, response_model=schemas.JobOut, dependencies=[operator],
             responses=QUEUE_ERRORS)
def identify_joint(body: schemas.JointIdentifyIn, svc: Services = Depends(services)):
    """Queue one model of several recordings (job kind identify_joint); poll GET /api/jobs/{id}, then
    GET /api/jobs/{id}/joint for the result (the JSON of `shakeid identify A.h5 B.h5 --json`)."""
    ids = list(body.recording_ids)
    twice = sorted({r for r in ids if ids.count(r) > 1})
    if twice:  # one recording counted twice would shrink every standard error by sqrt(2)
        raise HTTPException(422, f"recording(s) {', '.join(twice)} given more than once: a joint fit takes "
                                 "each recording once")
    recs = [svc.recording_or_404(rec_id) for rec_id in ids]
    for rec_id, rec in zip(ids, recs):
        if rec["status"] == "running":
            raise HTTPException(409, f"recording {rec_id} is still being recorded")
    options = body.model_dump(exclude_none=True, exclude={"recording_ids"})
    # each recording read as it was uploaded (its stored read options: layout, columns, rate), the
    # body's read options over them, as for one recording (submit)
    stored = [rec["info"].get("read_options", {}) for rec in recs]
    for rec, own in zip(recs, stored):
        check_at_the_door(rec, {**own, **options})
    return svc.jobs.submit("identify_joint", ids[0], {**options, "recording_ids": ids,
                                                      "read_options_by_recording": stored})


@router.get("/api/jobs/{job_id}/joint", dependencies=[viewer], responses={**ERRORS, 404: {"model": schemas.Problem}})
def joint_result(job_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """A joint identification's result (joint.json: the joint model, `recordings` per recording),
    whether or not one model explained them all."""
    job = svc.catalog.get("jobs", job_id)
    path = FsPath(job["result_dir"]) / "joint.json" if job and job["kind"] == "identify_joint" else None
    if path is None or not path.exists():
        raise HTTPException(404, f"no joint identification result for job {job_id}")
    return json.loads(path.read_text())


@router.post("/api/recordings/{rec_id}/explain", status_code=202, response_model=schemas.JobOut,
             dependencies=[operator], responses=QUEUE_ERRORS)
def explain(body: schemas.ExplainIn | None = None, rec_id: str = Id(), svc: Services = Depends(services)):
    """Queue a discrepancy analysis (`shakeid explain`): missing effect, gap before/after."""
    return submit(svc, "explain", rec_id, body.model_dump(exclude_none=True) if body is not None else {})


@router.get("/api/jobs", response_model=list[schemas.JobOut], dependencies=[viewer], responses=ERRORS)
def list_jobs(limit: int = Query(50, ge=1, le=500), svc: Services = Depends(services)):
    return svc.catalog.list("jobs", limit=limit)


@router.get("/api/jobs/{job_id}", response_model=schemas.JobOut, dependencies=[viewer],
            responses={**ERRORS, 404: {"model": schemas.Problem}})
async def get_job(job_id: str = Id(), svc: Services = Depends(services)):  # polled: on the event loop, like get_sweep
    job = svc.catalog.get("jobs", job_id)
    if job is None:
        raise HTTPException(404, f"no job {job_id}")
    return job
