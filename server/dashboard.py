"""The operator's dashboard: the page, its static script and style, and the JSON it needs beyond the API.

The page (server/dashboard.html with server/static/) is plain HTML and JavaScript: no build step. What
it shows beyond the API's own resources is composed here, on the server, so that the browser does not
join tables itself: a recordings overview (each recording with its sweep parameters, status reason,
quality flags and where its identification stands: not yet, queued, running, failed with why, or its fit)
and the rig history (the physical parameters c, k, k3, b with standard errors, one point per identified
recording: is the rig drifting?).
"""
from __future__ import annotations

import json
from pathlib import Path as FsPath
from typing import Callable

from fastapi import APIRouter, HTTPException, Path, Query
from fastapi.responses import FileResponse, HTMLResponse

from .catalog import ID_PATTERN, Catalog
from .schemas import Problem

HERE = FsPath(__file__).parent
STATIC = HERE / "static"
#: the physical parameters the rig history plots: key in the model's "physical" object (SI) -> (symbol,
#: unit shown, factor from SI to it): b in mm, as the CLI and the report print it
HISTORY_PARAMETERS = {
    "damping_ns_per_m": ("c", "N s/m", 1.0),
    "stiffness_n_per_m": ("k", "N/m", 1.0),
    "cubic_stiffness_n_per_m3": ("k3", "N/m³", 1.0),
    "prestress_b_m": ("b", "mm", 1e3),
}


def dashboard_router(catalog: Callable[[], Catalog], viewer) -> APIRouter:
    """Routes of the dashboard; `catalog` returns the service's catalog, `viewer` is the auth dependency
    (it returns who calls: role and token fingerprint)."""
    router = APIRouter()
    errors = {401: {"model": Problem}, 403: {"model": Problem}, 422: {"model": Problem}}

    @router.get("/", response_class=HTMLResponse, include_in_schema=False)
    def page():
        return (HERE / "dashboard.html").read_text()

    @router.get("/static/{name}", include_in_schema=False)
    def static(name: str = Path(pattern=r"^[a-z0-9_\-]{1,40}\.(js|css)$")):
        path = STATIC / name
        if not path.is_file():  # only the files shipped beside this module, by exact name
            raise HTTPException(404, f"no file {name}")
        return FileResponse(path, media_type="text/javascript" if name.endswith(".js") else "text/css",
                            headers={"Cache-Control": "no-cache"})

    @router.get("/api/session", tags=["dashboard"], responses=errors)
    def session(who: str = viewer) -> dict:
        """Who the token is: its role and a fingerprint (never the token itself)."""
        role, fingerprint = who.split(" ", 1)
        return {"role": role, "fingerprint": fingerprint}

    @router.get("/api/dashboard/recordings", tags=["dashboard"], dependencies=[viewer], responses=errors)
    def recordings_overview(limit: int = Query(50, ge=1, le=500)) -> list[dict]:
        """Recordings, newest first, each with its sweep's parameters and state, and where its latest
        identification and explanation stand ({state: none|queued|running|completed|failed, error})."""
        cat = catalog()
        return [_overview(cat, rec) for rec in cat.list("recordings", limit=limit)]

    @router.get("/api/dashboard/recordings/{rec_id}", tags=["dashboard"], dependencies=[viewer],
                responses={**errors, 404: {"model": Problem}})
    def recording_overview(rec_id: str = Path(pattern=ID_PATTERN)) -> dict:
        """One recording as in the overview (its page polls this while its jobs run)."""
        cat = catalog()
        rec = cat.get("recordings", rec_id)
        if rec is None:
            raise HTTPException(404, f"no recording {rec_id}")
        return _overview(cat, rec)

    @router.get("/api/dashboard/history", tags=["dashboard"], dependencies=[viewer], responses=errors)
    def rig_history(limit: int = Query(200, ge=1, le=2000)) -> dict:
        """The rig's physical parameters over recordings (oldest first): for each recording with a
        completed identification, each parameter's value and standard error (SI units, as in the
        model's "physical" object; the standard error is null when the model has none), and why the
        data were identified although refused at first (accepted_faulty: the plot marks those)."""
        cat = catalog()
        points = []
        for rec in reversed(cat.list("recordings", limit=limit)):
            job_id = rec["info"].get("last_identify_job")
            job = cat.get("jobs", job_id) if job_id else None
            if job is None:
                continue
            try:
                physical = json.loads((FsPath(job["result_dir"]) / "model.json").read_text()).get("physical")
            except (OSError, ValueError):
                continue  # result removed or being rewritten: the point is left out, not invented
            if not physical:
                continue  # a force-layout model has no physical parameters of the base-excited rig
            params = {key: {"value": (physical.get(key) or {}).get("value"),
                            "std_error": (physical.get(key) or {}).get("std_error")} for key in HISTORY_PARAMETERS}
            sweep = rec["info"].get("sweep") or {}
            summary = rec["info"].get("identify") or {}
            points.append({"recording_id": rec["id"], "created": rec["created"], "origin": rec["origin"],
                           "amplitude_mm": sweep.get("amplitude_mm"), "fit_percent": summary.get("fit_percent"),
                           # reasons the data were refused and identified anyway (an aborted sweep, say)
                           "accepted_faulty": summary.get("accepted_faulty") or [], **params})
        return {"parameters": {k: {"symbol": s, "unit": u, "scale": f} for k, (s, u, f) in HISTORY_PARAMETERS.items()},
                "points": points}

    return router


def _overview(cat: Catalog, rec: dict) -> dict:
    """A recording for the dashboard: as GET /api/recordings lists it (no server path: the file is
    GET /api/recordings/{id}/file), its sweep and its latest jobs."""
    sweep = cat.get("sweeps", rec["sweep_id"]) if rec.get("sweep_id") else None
    rec = {k: v for k, v in rec.items() if k != "path"}
    return {**rec, "sweep": sweep and {k: sweep[k] for k in ("state", "progress", "error", "request", "operator")},
            "jobs": {kind: _latest_job(cat, rec["id"], kind) for kind in ("identify", "explain")}}


def _latest_job(cat: Catalog, rec_id: str, kind: str) -> dict:
    jobs = cat.list("jobs", "recording_id = ? AND kind = ?", (rec_id, kind), limit=1)
    if not jobs:
        return {"state": "none"}
    job = jobs[0]
    return {"state": job["state"], "id": job["id"], "error": job["error"], "updated": job["updated"]}
