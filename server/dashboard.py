"""The operator's dashboard: the page, its static script and style, and the JSON it needs beyond the API.

The page (server/dashboard.html with server/static/) is plain HTML and JavaScript: no build step. What
it shows beyond the API's own resources is composed here, on the server, so that the browser does not
join tables itself: pages of recordings (filtered by date, origin, status, campaign and a search, each
with its sweep, status, quality verdict and where its identification stands; one catalog statement per
page, server/catalog.py's NamedQueries), archiving (files moved to `<data_dir>/archive/`, never
deleted), a report as one self-contained page, and the rig history (c, k, k3, b with standard errors,
one point per identified recording: is the rig drifting?).
"""
from __future__ import annotations

import base64
import json
import os
import re
import time
from pathlib import Path as FsPath
from typing import Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Query
from fastapi.responses import FileResponse, HTMLResponse

from identify.data.quality import with_status

from .catalog import ID_PATTERN
from .deps import ERRORS, Id, Services, operator, services, viewer
from .routers.results import latest_result
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
#: where archived recordings' files go, under the data directory (moved, never deleted)
ARCHIVE_DIR = "archive"
#: recording statuses the list can be filtered by (the recorder's and the catalog's)
STATUSES = Literal["running", "complete", "aborted", "failed", "fault"]
#: a report page's own policy: its inline style, its figures inlined as data: URLs, nothing else; sandboxed
REPORT_CSP = "default-src 'none'; style-src 'unsafe-inline'; img-src data:; frame-ancestors 'none'; sandbox"
_IMG_SRC = re.compile(r"""src=(["'])([a-z0-9_]{1,40}\.png)\1""")  # reports/html.py writes src='name.png'

router = APIRouter()
ANSWERS = {**ERRORS, 422: {"model": Problem}}


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


@router.get("/api/session", tags=["dashboard"], responses=ANSWERS)
def session(who: str = viewer) -> dict:
    """Who the token is: its role and a fingerprint (never the token itself)."""
    role, fingerprint = who.split(" ", 1)
    return {"role": role, "fingerprint": fingerprint}


@router.get("/api/dashboard/recordings", tags=["dashboard"], dependencies=[viewer], responses=ANSWERS)
def recordings_page(
        offset: int = Query(0, ge=0, le=10**9, description="recordings to skip (newest first)"),
        limit: int = Query(50, ge=1, le=500),
        since: float | None = Query(None, ge=0, le=1e11, allow_inf_nan=False, description="created at or after (Unix s)"),
        until: float | None = Query(None, ge=0, le=1e11, allow_inf_nan=False, description="created before (Unix s)"),
        origin: Literal["sweep", "upload"] | None = None, status: STATUSES | None = None,
        campaign: str | None = Query(None, pattern=ID_PATTERN, description="a campaign's recordings"),
        q: str | None = Query(None, max_length=100, description="in the id, file name, note, operator"),
        archived: bool = Query(False, description="the archived recordings instead"),
        svc: Services = Depends(services)) -> dict:
    """A page of recordings, newest first: {total (matching the filters), offset, limit, items}; each item
    with its sweep's parameters and state, its quality verdict (unusable when aborted or failed) and where
    its latest identification and explanation stand ({state: none|queued|running|completed|failed, error})."""
    items, total = svc.catalog.queries.recordings_page(offset, limit, since=since, until=until, origin=origin,
                                                       status=status, campaign=campaign, search=q or None,
                                                       archived=archived)
    return {"total": total, "offset": offset, "limit": limit, "items": [_verdict(r) for r in items]}


@router.get("/api/dashboard/recordings/{rec_id}", tags=["dashboard"], dependencies=[viewer],
            responses={**ANSWERS, 404: {"model": Problem}})
def recording_overview(rec_id: str = Id(), svc: Services = Depends(services)) -> dict:
    """One recording as in the list (its page polls this while its jobs run), archived or not."""
    rec = svc.catalog.queries.recording(rec_id)
    if rec is None:
        raise HTTPException(404, f"no recording {rec_id}")
    return _verdict(rec)


def _verdict(rec: dict) -> dict:
    """The quality verdict as served everywhere: unusable when the status says so (an aborted sweep's
    signals may be clean, and identify refuses it all the same)."""
    quality = rec["info"].get("quality")
    if isinstance(quality, dict):
        rec["info"] = {**rec["info"], "quality": with_status(quality, rec["status"], rec["info"].get("reason"))}
    return rec


@router.post("/api/recordings/{rec_id}/archive", tags=["recordings"],
             responses={**ANSWERS, 404: {"model": Problem}, 409: {"model": Problem}})
def archive(rec_id: str = Id(), who: str = operator, svc: Services = Depends(services)) -> dict:
    """Archive a recording: its file moves to the data directory's archive/ folder (never deleted), the
    catalog marks it archived, and the lists leave it out (`?archived=true` shows it; restore undoes it).
    409 while it is recorded or one of its jobs is queued or running."""
    rec = svc.recording_or_404(rec_id)
    if rec.get("archived"):
        raise HTTPException(409, f"recording {rec_id} is archived already")
    if rec["status"] == "running":
        raise HTTPException(409, f"recording {rec_id} is still being recorded: abort its sweep or wait for it")
    if svc.catalog.count("jobs", "recording_id = ? AND state IN ('queued', 'running')", (rec_id,)):
        raise HTTPException(409, f"recording {rec_id} has a job queued or running: archive it when that has ended")
    dest = _move(FsPath(rec["path"]), svc.settings.data_dir / ARCHIVE_DIR)
    now = time.time()
    svc.catalog.update("recordings", rec_id, path=str(dest), archived=now,
                       info={**rec["info"], "archived_by": who})
    return {"id": rec_id, "archived": now, "file": f"{ARCHIVE_DIR}/{dest.name}"}


@router.post("/api/recordings/{rec_id}/restore", tags=["recordings"],
             responses={**ANSWERS, 404: {"model": Problem}, 409: {"model": Problem}})
def restore(rec_id: str = Id(), who: str = operator, svc: Services = Depends(services)) -> dict:
    """Bring an archived recording back into the lists (its file back among the recordings)."""
    rec = svc.recording_or_404(rec_id)
    if not rec.get("archived"):
        raise HTTPException(409, f"recording {rec_id} is not archived")
    dest = _move(FsPath(rec["path"]), svc.settings.data_dir / "recordings")
    info = {k: v for k, v in rec["info"].items() if k != "archived_by"}
    svc.catalog.update("recordings", rec_id, path=str(dest), archived=None, info=info)
    return {"id": rec_id, "archived": None, "file": f"recordings/{dest.name}"}


def _move(src: FsPath, folder: FsPath) -> FsPath:
    """Move a recording's file into folder (same file system: a rename); a file already gone stays gone."""
    folder.mkdir(parents=True, exist_ok=True)
    dest = folder / src.name
    if src.exists():
        if dest.exists():
            raise HTTPException(409, f"{folder.name}/{dest.name} exists already; nothing was moved")
        os.replace(src, dest)
    return dest


#: the page route answers HTML, its errors JSON: FastAPI would document a `model` under the route's text/html
HTML_ROUTE_ERRORS = {code: {"description": "a Problem", "content": {"application/json": {
    "schema": {"$ref": "#/components/schemas/Problem"}}}} for code in (401, 403, 404, 422)}


@router.get("/api/recordings/{rec_id}/report", tags=["jobs"], dependencies=[viewer], response_class=HTMLResponse,
            responses=HTML_ROUTE_ERRORS)
def report(rec_id: str = Id(), kind: Literal["identify", "explain"] = "identify", svc: Services = Depends(services)):
    """The latest report's index.html as one self-contained page (its figures inlined), to open as is."""
    folder = latest_result(svc, rec_id, kind, "report")
    try:
        html = (folder / "index.html").read_text()
    except OSError:
        raise HTTPException(404, f"the {kind} report of recording {rec_id} has no page (yet)") from None

    def inline(m: re.Match) -> str:
        png = folder / m.group(2)
        return f'src="data:image/png;base64,{base64.b64encode(png.read_bytes()).decode()}"' if png.is_file() else m.group(0)

    return HTMLResponse(_IMG_SRC.sub(inline, html), headers={"Content-Security-Policy": REPORT_CSP})


@router.get("/api/dashboard/history", tags=["dashboard"], dependencies=[viewer], responses=ANSWERS)
def rig_history(limit: int = Query(200, ge=1, le=2000), svc: Services = Depends(services)) -> dict:
    """The rig's physical parameters over recordings (oldest first; archived ones left out): for each
    recording with a completed identification, each parameter's value and standard error (SI units, as in
    the model's "physical" object; the standard error is null when the model has none), and why the data
    were identified although refused at first (accepted_faulty: the plot marks those)."""
    points = []
    for rec, result_dir in reversed(svc.catalog.queries.identified(limit)):
        try:
            physical = json.loads((FsPath(result_dir) / "model.json").read_text()).get("physical")
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
