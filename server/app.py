"""The FastAPI application: `create_app(settings)`; served by uvicorn (`shakeid serve`).

Sync route functions run in the server's thread pool, async ones on the event loop; nothing here
computes or drives the rig: identification runs in the job pool (server/jobs.py), uploads are checked
in a process of their own (server/uploads.py), and the rig (sweeps, heartbeat, emergency stop) is the
rig controller's, a separate process reached over server/ipc.py (server/controller.py). The emergency
stop has a thread and a controller connection of its own, so it never waits behind other requests.

The routes live in server/routers/, one module per concern; what they share (catalog, job queue, rig
controller link, auth) is server/deps.py's Services on `app.state.services`. create_app composes them.
"""
from __future__ import annotations

from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from daq.recorder import software_version

from . import dashboard, schemas
from .catalog import Catalog
from .deps import Services, valid_text
from .jobs import JobQueue
from .memory import fix_malloc_thresholds
from .rigclient import RigLink
from .routers import campaigns, export, frf, jobs, live, recordings, results, rig, sweeps
from .security import SecurityHeaders
from .settings import Settings
from .text import cleaned

#: the routers, in the order their routes are matched and documented
ROUTERS = (rig.router, sweeps.router, campaigns.router, recordings.router, live.router, jobs.router, results.router,
           export.router, frf.router)


def create_app(settings: Settings) -> FastAPI:
    settings.prepare()
    svc = Services(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if not fix_malloc_thresholds():  # before any load: freed memory goes back (server/memory.py)
            print("shakeid serve: not glibc: memory freed after a load may stay with the process", flush=True)
        svc.catalog = Catalog(settings.data_dir / "catalog.sqlite")
        for note in svc.catalog.recover_after_restart():
            print(f"shakeid serve: {note}", flush=True)
        svc.jobs = JobQueue(svc.catalog, settings.data_dir / "results", settings.identify_workers,
                            settings.scheduler, settings.connect_timeout_s, settings.auto_identify)
        svc.jobs.start()
        svc.link = RigLink(settings, settings.controller, on_event=lambda event: svc.jobs.recording_completed()
                           if event.get("event") in ("recording_complete", "campaign_complete") else None)
        await run_in_threadpool(svc.link.start)  # waits for a child controller to listen (it recovers the rig's files)
        yield
        await run_in_threadpool(svc.link.stop)
        svc.jobs.stop()
        svc.catalog.close()

    app = FastAPI(title="shakeid", version=software_version(), lifespan=lifespan,
                  dependencies=[Depends(valid_text)],  # a body's text checked before any route reads it
                  responses={400: {"model": schemas.Problem}, 422: {"model": schemas.Problem}},
                  description="Sine sweeps on the shaker rig, HDF5 recordings, sparse nonlinear models.")
    app.state.services = svc
    app.state.shutting_down = svc.shutting_down  # set by `shakeid serve` on SIGTERM/SIGINT
    app.add_exception_handler(RequestValidationError, invalid_request)
    for router in ROUTERS:
        app.include_router(router)
    app.include_router(dashboard.router)  # the page, its scripts, the JSON it shows, archiving, reports
    app.add_middleware(SecurityHeaders)  # Content-Security-Policy, X-Frame-Options on every response
    return app


async def invalid_request(request: Request, exc: RequestValidationError):
    """422 naming each field; inputs echoed only as text, so NaN, Infinity or 1e400 in a body get a
    422 like any other bad value (JSON cannot carry them back, and a 500 would drop the connection)."""
    detail = [{"loc": cleaned(list(err.get("loc", ()))), "msg": cleaned(schemas.in_words(err)),
               "type": err.get("type", ""), **({"input": _text(err["input"])} if "input" in err else {})}
              for err in exc.errors()]
    return JSONResponse({"detail": detail}, status_code=422)


def _text(value) -> str | int | bool | None:
    """An input echoed in a 422: text for anything that JSON might not carry (non-finite floats)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value if not isinstance(value, str) else cleaned(value[:200])  # a lone surrogate cannot be sent
    return repr(value)[:200]
