"""The FastAPI application: `create_app(settings)`; served by uvicorn (`shakeid serve`).

Sync route functions run in the server's thread pool, async ones on the event loop; nothing here
computes or drives the rig: identification runs in the job pool (server/jobs.py), uploads are checked
in a process of their own (server/uploads.py), and the rig (sweeps, heartbeat, emergency stop) is the
rig controller's, a separate process reached over server/ipc.py (server/controller.py). The emergency
stop has a thread and a controller connection of its own, so it never waits behind other requests.
"""
from __future__ import annotations

import asyncio
import json
import threading
import time
from contextlib import asynccontextmanager
from pathlib import Path as FsPath
from typing import Literal

from fastapi import Depends, FastAPI, HTTPException, Path, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, StreamingResponse

from daq.recorder import software_version
from identify.quality import with_status

from . import schemas
from .auth import require
from .catalog import ID_PATTERN, Catalog, new_id
from .dashboard import dashboard_router
from .ipc import ControllerRefused, ControllerUnavailable
from .jobs import JobQueue
from .rigclient import RigLink
from .settings import Settings
from .uploads import store_upload

PLOT_NAME = r"^[a-z0-9_]{1,40}\.png$"
#: GET /api/rig answers from a copy at most this old, s: pollers never become load on the rig controller
RIG_STATUS_MAX_AGE_S = 0.1


def Id():  # noqa: N802 - a fresh parameter object per route (FastAPI binds each to its own name)
    return Path(pattern=ID_PATTERN, description="12 hex digits")


def create_app(settings: Settings) -> FastAPI:
    settings.prepare()
    state: dict = {}

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        catalog = Catalog(settings.data_dir / "catalog.sqlite")
        for note in catalog.recover_after_restart():
            print(f"shakeid serve: {note}", flush=True)
        jobs = JobQueue(catalog, settings.data_dir / "results", settings.identify_workers,
                        settings.scheduler, settings.connect_timeout_s)
        jobs.start()
        link = RigLink(settings, settings.controller,
                       on_event=lambda event: jobs.wake() if event.get("event") == "job_queued" else None)
        await run_in_threadpool(link.start)  # waits for a child controller to listen (it recovers the rig's files)
        state.update(catalog=catalog, jobs=jobs, link=link)
        yield
        await run_in_threadpool(link.stop)
        jobs.stop()
        catalog.close()

    app = FastAPI(title="shakeid", version=software_version(), lifespan=lifespan,
                  responses={400: {"model": schemas.Problem}, 422: {"model": schemas.Problem}},
                  description="Sine sweeps on the shaker rig, HDF5 recordings, sparse nonlinear models.")
    app.state.shutting_down = threading.Event()  # set by `shakeid serve` on SIGTERM/SIGINT
    viewer, operator = Depends(require(settings, "viewer")), Depends(require(settings, "operator"))
    errors = {401: {"model": schemas.Problem}, 403: {"model": schemas.Problem}}

    def catalog() -> Catalog:
        return state["catalog"]

    rig_cache: dict = {"t": -1e9, "value": None, "lock": asyncio.Lock()}

    async def controller(op: str, **params):
        """One request to the rig controller, off the event loop; its refusals keep their status."""
        try:
            return await run_in_threadpool(state["link"].client.call, op, **params)
        except ControllerRefused as exc:
            raise HTTPException(exc.status, exc.detail) from None
        except ControllerUnavailable as exc:
            raise HTTPException(503, f"{exc} (restarting? the hardware stop and `shakeid rig estop` work without "
                                     "it)") from None

    @app.exception_handler(RequestValidationError)
    async def invalid_request(request: Request, exc: RequestValidationError):
        """422 naming each field; inputs echoed only as text, so NaN, Infinity or 1e400 in a body get a
        422 like any other bad value (JSON cannot carry them back, and a 500 would drop the connection)."""
        detail = [{"loc": list(err.get("loc", ())), "msg": schemas.in_words(err), "type": err.get("type", ""),
                   **({"input": _text(err["input"])} if "input" in err else {})} for err in exc.errors()]
        return JSONResponse({"detail": detail}, status_code=422)

    def recording_or_404(rec_id: str) -> dict:
        rec = catalog().get("recordings", rec_id)
        if rec is None:
            raise HTTPException(404, f"no recording {rec_id}")
        return rec

    def with_verdict(rec: dict) -> dict:
        """The recording as served: its quality verdict says unusable when its status does (an aborted
        sweep's signals may be clean; identify refuses it all the same)."""
        info = rec.get("info") or {}
        if not isinstance(info.get("quality"), dict):
            return rec
        quality = with_status(info["quality"], rec.get("status"), info.get("reason"))
        return {**rec, "info": {**info, "quality": quality}}

    # -- health, rig ----------------------------------------------------------------------------------
    @app.get("/api/health", response_model=schemas.Health, tags=["service"])
    def health():
        """Liveness, without a token (for supervisors and compose health checks)."""
        link = state["link"]
        return {"status": "ok", "version": software_version(), "rig_simulated": settings.rig is None,
                "controller": "attached" if link.attached.is_set() else "unreachable",
                "jobs_queued": catalog().count("jobs", "state = 'queued'")}

    @app.get("/api/rig", tags=["rig"], responses={**errors, 503: {"model": schemas.Problem}},
             dependencies=[viewer])
    async def rig_status() -> dict:
        """PLC state, accelerometers, safety limits, the active sweep (from the rig controller, at most
        RIG_STATUS_MAX_AGE_S old: however many clients poll, the controller answers ten times a second)."""
        async with rig_cache["lock"]:
            if time.monotonic() - rig_cache["t"] >= RIG_STATUS_MAX_AGE_S:
                rig_cache["value"] = await controller("status")
                rig_cache["t"] = time.monotonic()
            return rig_cache["value"]

    @app.post("/api/rig/estop", response_model=schemas.EstopOut, tags=["rig"], dependencies=[operator],
              responses={**errors, 503: {"model": schemas.Problem}})
    async def estop():
        """Emergency stop: the table ramps to rest at once; an active sweep ends aborted."""
        # sent from the event loop itself, not via a thread: under load every hop through the loop's queue
        # waits behind the other requests (~15 ms each with 50 pollers). The call is one message on the
        # connection kept for stops to a real-time thread of the controller (a few ms; at most
        # ESTOP_TIMEOUT_S if the controller hangs, and at once if it is gone)
        try:
            return state["link"].client.emergency_stop()
        except (ControllerRefused, ControllerUnavailable) as exc:
            raise HTTPException(503, f"emergency stop not delivered: {exc}; use the hardware stop") from None
        finally:
            rig_cache["t"] = -1e9  # the next GET /api/rig shows the stop

    @app.post("/api/rig/reset", response_model=schemas.ResetOut, tags=["rig"], dependencies=[operator],
              responses={**errors, 409: {"model": schemas.Problem}, 503: {"model": schemas.Problem}})
    async def reset():
        """Clear a fault or an emergency stop once the table is at rest; 409 if the PLC stays in it."""
        try:
            return await controller("reset")
        finally:
            rig_cache["t"] = -1e9

    # -- sweeps -----------------------------------------------------------------------------------------
    @app.post("/api/sweeps", status_code=202, response_model=schemas.Accepted, tags=["sweeps"],
              responses={**errors, 409: {"model": schemas.Problem}, 422: {"model": schemas.Problem},
                         503: {"model": schemas.Problem}})
    async def start_sweep(body: schemas.SweepIn, who: str = operator):
        """Start a sweep: refused with 422 naming the limit when unsafe, 409 while another runs or while the
        PLC is in emergency stop or fault (with the reason), 503 when the rig cannot be reached."""
        started = await controller("start_sweep", body=body.model_dump(), operator=who)
        return {"id": started["id"], "state": started["state"]}

    @app.get("/api/sweeps", response_model=list[schemas.SweepOut], tags=["sweeps"], dependencies=[viewer],
             responses=errors)
    def list_sweeps(limit: int = Query(50, ge=1, le=500)):
        return catalog().list("sweeps", limit=limit)

    @app.get("/api/sweeps/{sweep_id}", response_model=schemas.SweepOut, tags=["sweeps"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    async def get_sweep(sweep_id: str = Id()):
        """Polled by dashboards: answered on the event loop (one indexed SQLite read, no thread hop)."""
        sweep = catalog().get("sweeps", sweep_id)
        if sweep is None:
            raise HTTPException(404, f"no sweep {sweep_id}")
        return sweep

    @app.post("/api/sweeps/{sweep_id}/abort", status_code=202, response_model=schemas.Accepted, tags=["sweeps"],
              dependencies=[operator], responses={**errors, 404: {"model": schemas.Problem},
                                                   409: {"model": schemas.Problem}})
    async def abort_sweep(sweep_id: str = Id()):
        """Operator abort: the table is commanded to stop, the recording ends 'aborted'."""
        sweep = catalog().get("sweeps", sweep_id)
        if sweep is None:
            raise HTTPException(404, f"no sweep {sweep_id}")
        if not await controller("abort", sweep_id=sweep_id):
            raise HTTPException(409, f"sweep {sweep_id} is {sweep['state']}, not running")
        return {"id": sweep_id, "state": "aborting"}

    # -- campaigns ------------------------------------------------------------------------------------------
    campaign_errors = {**errors, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem},
                       503: {"model": schemas.Problem}}

    @app.post("/api/campaigns", status_code=202, response_model=schemas.Accepted, tags=["campaigns"],
              responses={**campaign_errors, 422: {"model": schemas.Problem}})
    async def start_campaign(body: schemas.CampaignIn, who: str = operator):
        """Start a campaign: its sweeps one after another in the rig controller. Every sweep is checked
        against the limits first (422 naming the sweep and the limit, nothing moves); 409 while a sweep or a
        campaign runs or the PLC is in emergency stop or fault."""
        return await controller("start_campaign", plan=body.model_dump(), operator=who)

    @app.get("/api/campaigns", response_model=list[schemas.CampaignOut], tags=["campaigns"],
             dependencies=[viewer], responses=errors)
    def list_campaigns(limit: int = Query(50, ge=1, le=500)):
        """The newest campaigns, each with its latest joint identification job (or null)."""
        joint = latest_joint_jobs()
        return [{**c, "joint_identification": joint.get(c["id"])} for c in catalog().list("campaigns", limit=limit)]

    def latest_joint_jobs() -> dict:
        """{campaign id: its newest identify_joint job}."""
        out = {}
        for j in catalog().list("jobs", "kind = 'identify_joint'", limit=10_000):
            cid = j["options"].get("campaign_id")
            if cid and (cid not in out or j["created"] > out[cid]["created"]):
                out[cid] = j
        return out

    @app.get("/api/campaigns/{campaign_id}", response_model=schemas.CampaignOut, tags=["campaigns"],
             dependencies=[viewer], responses={**errors, 404: {"model": schemas.Problem}})
    async def get_campaign(campaign_id: str = Id()):
        """State, plan, each sweep with its recording and status, progress, and why it paused or aborted."""
        campaign = catalog().get("campaigns", campaign_id)
        if campaign is None:
            raise HTTPException(404, f"no campaign {campaign_id}")
        return {**campaign, "joint_identification": latest_joint_jobs().get(campaign_id)}

    @app.post("/api/campaigns/{campaign_id}/{action}", status_code=202, response_model=schemas.Accepted,
              tags=["campaigns"], responses=campaign_errors)
    async def campaign_action(action: Literal["pause", "resume", "abort"], campaign_id: str = Id(),
                              who: str = operator):
        """pause: no next sweep (the running one finishes; state pausing, then paused). resume: re-run the
        sweep that failed and go on (409 while the PLC is in emergency stop or fault: reset it first).
        abort: the running sweep is stopped and the campaign ends aborted."""
        return await controller(f"{action}_campaign", campaign_id=campaign_id, operator=who)

    # -- recordings -------------------------------------------------------------------------------------
    @app.get("/api/recordings", response_model=list[schemas.RecordingOut], tags=["recordings"],
             dependencies=[viewer], responses=errors)
    def list_recordings(limit: int = Query(50, ge=1, le=500)):
        return [with_verdict(rec) for rec in catalog().list("recordings", limit=limit)]

    @app.get("/api/recordings/{rec_id}", response_model=schemas.RecordingOut, tags=["recordings"],
             dependencies=[viewer], responses={**errors, 404: {"model": schemas.Problem}})
    def get_recording(rec_id: str = Id()):
        return with_verdict(recording_or_404(rec_id))

    @app.get("/api/recordings/{rec_id}/file", tags=["recordings"], dependencies=[viewer],
             response_class=FileResponse, responses={**errors, 404: {"model": schemas.Problem},
                                                      409: {"model": schemas.Problem}})
    def recording_file(rec_id: str = Id()):
        """The recording as stored (HDF5 from sweeps; CSV, MAT or HDF5 as uploaded); 409 while it is being
        recorded (a copy taken between two flushes could be torn: follow /live instead)."""
        rec = recording_or_404(rec_id)
        if rec["status"] == "running":
            raise HTTPException(409, f"recording {rec_id} is still being recorded; follow /live, fetch it after")
        return FileResponse(rec["path"], filename=rec["filename"], media_type="application/octet-stream")

    @app.post("/api/recordings", status_code=201, response_model=schemas.RecordingOut, tags=["recordings"],
              responses={**errors, 413: {"model": schemas.Problem}, 422: {"model": schemas.Problem}})
    async def upload_recording(request: Request, who: str = operator,
                               filename: str = Query(..., pattern=r"^[\w.\-]{1,100}\.(csv|mat|h5|hdf5)$",
                                                     description="name with its type: .csv, .mat, .h5"),
                               layout: str = Query("base", pattern="^(base|force)$"),
                               input: str | None = Query(None, max_length=64),
                               output: str | None = Query(None, max_length=64),
                               time_column: str | None = Query(None, max_length=64),
                               fs_hz: float | None = Query(None, gt=0, le=1e7)):
        """Upload a recording from elsewhere as the request body (raw bytes); it is read once to check it,
        and refused with 422 naming the problem if it is not a usable recording."""
        options = {k: v for k, v in {"layout": layout, "input": input, "output": output, "time": time_column,
                                     "fs_hz": fs_hz}.items() if v is not None}
        rec_id = new_id()
        path, info = await store_upload(request, settings.data_dir / "recordings", rec_id, filename, options,
                                        int(settings.max_upload_mb * 2**20))
        return catalog().insert("recordings", id=rec_id, created=time.time(), origin="upload", filename=filename,
                                path=str(path), status="complete", sweep_id=None,
                                info={"read_options": options, "uploaded_by": who, **info})

    @app.get("/api/recordings/{rec_id}/live", tags=["recordings"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}, 200: {"content": {"text/event-stream": {}}}})
    async def live(rec_id: str = Id(), after: int = Query(0, ge=0, description="last sequence number seen")):
        """Server-sent events while recording: `samples` events with decimated samples (about 200 per
        second: t in s, one list per channel in m/s^2), then `end` with the recording's status."""
        rec = recording_or_404(rec_id)
        client = state["link"].client

        async def events():
            seq, quiet_since = after, time.monotonic()
            while rec["status"] == "running" and not app.state.shutting_down.is_set():
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
            status = (catalog().get("recordings", rec_id) or rec)["status"]
            yield f"event: end\ndata: {json.dumps({'recording_id': rec_id, 'status': status})}\n\n"

        return StreamingResponse(events(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"})

    # -- jobs, models, plots ------------------------------------------------------------------------------
    def _submit(kind: str, rec_id: str, options: dict):
        rec = recording_or_404(rec_id)
        if rec["status"] == "running":
            raise HTTPException(409, f"recording {rec_id} is still being recorded")
        return state["jobs"].submit(kind, rec_id, {**rec["info"].get("read_options", {}), **options})

    @app.post("/api/recordings/{rec_id}/identify", status_code=202, response_model=schemas.JobOut,
              tags=["jobs"], dependencies=[operator],
              responses={**errors, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem}})
    def identify(body: schemas.IdentifyIn | None = None, rec_id: str = Id()):
        """Queue an identification with the CLI's options (no body: its defaults, as explain); poll
        GET /api/jobs/{id}."""
        return _submit("identify", rec_id, body.model_dump(exclude_none=True) if body is not None else {})

    @app.post("/api/identify", status_code=202, response_model=schemas.JobOut, tags=["jobs"],
              dependencies=[operator], responses={**errors, 404: {"model": schemas.Problem},
                                                  409: {"model": schemas.Problem}})
    def identify_joint(body: schemas.JointIdentifyIn):
        """Queue one model of several recordings (job kind identify_joint); poll GET /api/jobs/{id}, then
        GET /api/jobs/{id}/joint for the result (the JSON of `shakeid identify A.h5 B.h5 --json`)."""
        ids = list(body.recording_ids)
        twice = sorted({r for r in ids if ids.count(r) > 1})
        if twice:  # one recording counted twice would shrink every standard error by sqrt(2)
            raise HTTPException(422, f"recording(s) {', '.join(twice)} given more than once: a joint fit takes "
                                     "each recording once")
        recs = [recording_or_404(rec_id) for rec_id in ids]
        for rec_id, rec in zip(ids, recs):
            if rec["status"] == "running":
                raise HTTPException(409, f"recording {rec_id} is still being recorded")
        options = body.model_dump(exclude_none=True, exclude={"recording_ids"})
        # each recording read as it was uploaded (its stored read options: layout, columns, rate), the
        # body's read options over them, as for one recording (_submit)
        stored = [rec["info"].get("read_options", {}) for rec in recs]
        return state["jobs"].submit("identify_joint", ids[0], {**options, "recording_ids": ids,
                                                               "read_options_by_recording": stored})

    @app.get("/api/jobs/{job_id}/joint", tags=["jobs"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    def joint_result(job_id: str = Id()) -> dict:
        """A joint identification's result (joint.json: the joint model, `recordings` per recording),
        whether or not one model explained them all."""
        job = catalog().get("jobs", job_id)
        path = FsPath(job["result_dir"]) / "joint.json" if job and job["kind"] == "identify_joint" else None
        if path is None or not path.exists():
            raise HTTPException(404, f"no joint identification result for job {job_id}")
        return json.loads(path.read_text())

    @app.post("/api/recordings/{rec_id}/explain", status_code=202, response_model=schemas.JobOut,
              tags=["jobs"], dependencies=[operator],
              responses={**errors, 404: {"model": schemas.Problem}, 409: {"model": schemas.Problem}})
    def explain(body: schemas.ExplainIn | None = None, rec_id: str = Id()):
        """Queue a discrepancy analysis (`shakeid explain`): missing effect, gap before/after."""
        return _submit("explain", rec_id, body.model_dump(exclude_none=True) if body is not None else {})

    @app.get("/api/jobs", response_model=list[schemas.JobOut], tags=["jobs"], dependencies=[viewer],
             responses=errors)
    def list_jobs(limit: int = Query(50, ge=1, le=500)):
        return catalog().list("jobs", limit=limit)

    @app.get("/api/jobs/{job_id}", response_model=schemas.JobOut, tags=["jobs"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    async def get_job(job_id: str = Id()):  # polled: on the event loop, like get_sweep
        job = catalog().get("jobs", job_id)
        if job is None:
            raise HTTPException(404, f"no job {job_id}")
        return job

    def _latest_result(rec_id: str, kind: str, name: str) -> FsPath:
        rec = recording_or_404(rec_id)
        for job in catalog().list("jobs", "recording_id = ? AND kind = ? AND state IN ('running', 'completed')",
                                  (rec_id, kind)):
            path = FsPath(job["result_dir"]) / name
            if path.exists():
                return path
        raise HTTPException(404, _why_no_result(rec, kind))

    def _why_no_result(rec: dict, kind: str) -> str:
        """Why a recording has no result of `kind`: its latest job's state (failed: with the reason), or,
        with no job, whether one will come by itself (a completed sweep is identified automatically)."""
        rec_id = rec["id"]
        latest = catalog().list("jobs", "recording_id = ? AND kind = ?", (rec_id, kind), limit=1)
        if latest:
            job = latest[0]
            if job["state"] == "failed":
                return f"no {kind} result for recording {rec_id}: its latest {kind} job {job['id']} failed: {job['error']}"
            return f"no {kind} result for recording {rec_id} yet: job {job['id']} is {job['state']}"
        auto = kind == "identify" and rec.get("origin") == "sweep" and rec.get("status") in ("complete", "running")
        return (f"no {kind} result for recording {rec_id} yet: it is identified when its sweep completes" if auto else
                f"no {kind} result for recording {rec_id}: none was asked for (POST /api/recordings/{rec_id}/{kind})")

    @app.get("/api/recordings/{rec_id}/model", tags=["jobs"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    def model(rec_id: str = Id()) -> dict:
        """The latest identified model: the same JSON as `shakeid identify --json`."""
        return json.loads(_latest_result(rec_id, "identify", "model.json").read_text())

    @app.get("/api/recordings/{rec_id}/explanation", tags=["jobs"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    def explanation(rec_id: str = Id()) -> dict:
        """The latest discrepancy analysis: the same JSON as `shakeid explain --json`."""
        return json.loads(_latest_result(rec_id, "explain", "explain.json").read_text())

    @app.get("/api/recordings/{rec_id}/plots", tags=["jobs"], dependencies=[viewer],
             responses={**errors, 404: {"model": schemas.Problem}})
    def plots(rec_id: str = Id(), kind: Literal["identify", "explain"] = "identify") -> list[str]:
        """Names of the report's figures (PNG) of the latest identification (or explanation)."""
        report = _latest_result(rec_id, kind, "report")
        return sorted(p.name for p in report.glob("*.png"))

    @app.get("/api/recordings/{rec_id}/plots/{name}", tags=["jobs"], dependencies=[viewer],
             response_class=FileResponse, responses={**errors, 404: {"model": schemas.Problem}})
    def plot(rec_id: str = Id(), name: str = Path(pattern=PLOT_NAME),
             kind: Literal["identify", "explain"] = "identify"):
        report = _latest_result(rec_id, kind, "report")
        if name not in {p.name for p in report.glob("*.png")}:  # only files that are there, by exact name
            raise HTTPException(404, f"no figure {name}")
        return FileResponse(report / name, media_type="image/png")

    app.include_router(dashboard_router(catalog, viewer))  # the page, its script, and the JSON it shows

    return app


def _text(value) -> str | int | bool | None:
    """An input echoed in a 422: text for anything that JSON might not carry (non-finite floats)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value if not isinstance(value, str) else value[:200]
    return repr(value)[:200]
