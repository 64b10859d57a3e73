"""A recording's results: the latest model, explanation and the report's figures."""
from __future__ import annotations

import json
from pathlib import Path as FsPath
from typing import Literal

from fastapi import APIRouter, Depends, HTTPException, Path
from fastapi.responses import FileResponse

from .. import schemas
from ..deps import ERRORS, Id, Services, services, viewer

PLOT_NAME = r"^[a-z0-9_]{1,40}\.png$"
router = APIRouter(tags=["jobs"], dependencies=[viewer], responses={**ERRORS, 404: {"model": schemas.Problem}})


def latest_result(svc: Services, rec_id: str, kind: str, name: str) -> FsPath:
    """The file or folder `name` of the recording's newest job of `kind` that has one; 404 saying why not."""
    rec = svc.recording_or_404(rec_id)
    jobs = svc.catalog.list("jobs", "recording_id = ? AND kind = ?", (rec_id, kind))
    auto = kind == "identify" and rec.get("origin") == "sweep" and rec.get("status") in ("complete", "running")
    return newest_result(jobs, name, f"no {kind} result for recording {rec_id}", kind,
                         " yet: it is identified when its sweep completes" if auto else
                         f": none was asked for (POST /api/recordings/{rec_id}/{kind})")


def newest_result(jobs: list[dict], name: str, what: str, kind: str, none_yet: str) -> FsPath:
    """The file or folder `name` of the newest of `jobs` (newest first) that has it, for a recording's or a
    campaign's results alike; else 404 saying why: "{what}" and the newest job's state (failed: with its
    reason), or, with no job, none_yet (whether one will come by itself)."""
    for job in jobs:  # a queued job may hold a delivered result too (parked by a stop, or re-queued to adopt it)
        path = FsPath(job["result_dir"] or "") / name
        if job["state"] != "failed" and job["result_dir"] and path.exists():
            return path
    if not jobs:
        raise HTTPException(404, what + none_yet)
    job = jobs[0]
    if job["state"] == "failed":
        raise HTTPException(404, f"{what}: its latest {kind} job {job['id']} failed: {job['error']}")
    raise HTTPException(404, f"{what} yet: job {job['id']} is {job['state']}")


@router.get("/api/recordings/{rec_id}/model")
def model(rec_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """The latest identified model: the same JSON as `shakeid identify --json`."""
    return json.loads(latest_result(svc, rec_id, "identify", "model.json").read_text())


@router.get("/api/recordings/{rec_id}/explanation")
def explanation(rec_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """The latest discrepancy analysis: the same JSON as `shakeid explain --json`."""
    return json.loads(latest_result(svc, rec_id, "explain", "explain.json").read_text())


@router.get("/api/recordings/{rec_id}/plots")
def plots(rec_id: str = Id(), kind: Literal["identify", "explain"] = "identify",
          svc: Services = Depends(services)) -> list[str]:
    """Names of the report's figures (PNG) of the latest identification (or explanation)."""
    report = latest_result(svc, rec_id, kind, "report")
    return sorted(p.name for p in report.glob("*.png"))


@router.get("/api/recordings/{rec_id}/plots/{name}", response_class=FileResponse)
def plot(rec_id: str = Id(), name: str = Path(pattern=PLOT_NAME), kind: Literal["identify", "explain"] = "identify",
         svc: Services = Depends(services)):
    report = latest_result(svc, rec_id, kind, "report")
    if name not in {p.name for p in report.glob("*.png")}:  # only files that are there, by exact name
        raise HTTPException(404, f"no figure {name}")
    return FileResponse(report / name, media_type="image/png")
