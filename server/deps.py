"""What the routers share: the service's parts (catalog, job queue, rig controller link) as one object on
`app.state.services`, the auth dependencies, and small lookups used by several routers.

The parts are made in create_app's lifespan (server/app.py); routes get them through the `services`
dependency (async: it runs on the event loop, no thread hop), so the routers are module-level
APIRouters in the FastAPI "bigger applications" layout and create_app only composes them.
"""
from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass, field

from fastapi import Depends, HTTPException, Path, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError

from . import schemas
from .auth import require_role
from .catalog import ID_PATTERN, Catalog
from .ipc import ControllerRefused, ControllerUnavailable
from .jobs import JobQueue
from .livefeed import LiveFeeds
from .rigclient import RigLink
from .settings import Settings
from .text import first_problem

#: who calls, as a route parameter or in `dependencies=[...]`: a token with this role (or above)
viewer = Depends(require_role("viewer"))
operator = Depends(require_role("operator"))
#: the auth answers every protected route documents
ERRORS = {401: {"model": schemas.Problem}, 403: {"model": schemas.Problem}}


def Id():  # noqa: N802 - a fresh parameter object per route (FastAPI binds each to its own name)
    return Path(pattern=ID_PATTERN, description="12 hex digits")


@dataclass
class Services:
    """The service's parts, filled in by the lifespan; one per app."""
    settings: Settings
    catalog: Catalog | None = None
    jobs: JobQueue | None = None
    link: RigLink | None = None
    shutting_down: threading.Event = field(default_factory=threading.Event)  # set by `shakeid serve` on SIGTERM
    #: GET /api/rig's copy of the controller's status (server/routers/rig.py)
    rig_cache: dict = field(default_factory=lambda: {"t": -1e9, "value": None, "lock": asyncio.Lock()})
    #: the live view's shared feeds, one per recording being watched (server/routers/live.py makes it)
    live_feeds: LiveFeeds | None = None

    def recording_or_404(self, rec_id: str) -> dict:
        rec = self.catalog.get("recordings", rec_id)
        if rec is None:
            raise HTTPException(404, f"no recording {rec_id}")
        return rec

    def stop_origin(self, host_header: str | None) -> str | None:
        """http://HOST:PORT of the rig controller's stop listener as the caller reaches it (the host it asked
        this server by, the port the controller reported), or None when there is none (or no usable Host):
        /api/health's stop_url and the dashboard's CSP (server/security.py)."""
        port = self.link.stop_port if self.link is not None and self.link.attached.is_set() else None
        if not port or not host_header:
            return None
        host = host_header.rsplit(":", 1)[0] if not host_header.endswith("]") else host_header
        if not host or not all(c.isalnum() or c in ".-[]:" for c in host):
            return None
        return f"http://{host}:{port}"

    async def controller(self, op: str, **params):
        """One request to the rig controller, off the event loop; its refusals keep their status."""
        try:
            return await run_in_threadpool(self.link.client.call, op, **params)
        except ControllerRefused as exc:
            raise HTTPException(exc.status, exc.detail) from None
        except ControllerUnavailable as exc:
            raise HTTPException(503, f"{exc} (restarting? the hardware stop and `shakeid rig estop` work without "
                                     "it)") from None


async def services(request: Request) -> Services:
    """The app's Services (a dependency: `svc: Services = Depends(services)`)."""
    return request.app.state.services


async def valid_text(request: Request) -> None:
    """Every route's first dependency (create_app): a JSON body with a string that is not text (a lone
    surrogate, a control character; server/text.py) anywhere, keys included, is refused with 422 naming
    the field, before anything reads or stores it. The body as FastAPI parsed it for the route (Starlette
    keeps it on the request); a route without a JSON body (an upload's raw bytes) is not read here."""
    body = getattr(request, "_json", None)
    found = first_problem(body, ("body",)) if body is not None else None
    if found:
        loc, why = found
        raise RequestValidationError([{"loc": loc, "msg": why, "type": "invalid_text"}])
