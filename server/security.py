"""Security headers on every response: a Content-Security-Policy, no framing, no type sniffing.

A pure ASGI middleware (it only adds headers to the response's start message), so streamed responses
(the live view's server-sent events, file downloads) pass through unbuffered. A route that needs another
policy (the interactive API docs, a report page) sets its own Content-Security-Policy header; the
middleware never overrides one.
"""
from __future__ import annotations

import base64
import hashlib

from reports.html import STYLE

#: the reports' one inline style, allowed by its hash: a report the dashboard opens from memory (a blob:
#: page, which keeps the dashboard's policy) keeps its layout, and no other inline style is allowed
REPORT_STYLE = "'sha256-" + base64.b64encode(hashlib.sha256(STYLE.encode()).digest()).decode() + "'"
#: the dashboard's policy: its own scripts and styles only, figures as blob: URLs (fetched with the token
#: in a header), never inside a frame (frame-ancestors; X-Frame-Options for browsers without CSP 2); it
#: connects to its own origin and to the rig controller's stop listener ({stop}: its origin, if any)
DASHBOARD_CSP = ("default-src 'self'; script-src 'self'; style-src 'self' " + REPORT_STYLE + "; "
                 "img-src 'self' blob: data:; connect-src 'self'{stop}; object-src 'none'; base-uri 'none'; "
                 "form-action 'self'; frame-ancestors 'none'")
#: FastAPI's /docs and /redoc load their script and style from a CDN and start with an inline script
DOCS_CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net; "
            "style-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net; img-src 'self' data: https:; "
            "worker-src blob:; object-src 'none'; base-uri 'none'; frame-ancestors 'none'")
DOCS_PATHS = ("/docs", "/redoc")
#: set on every response (a route's own value wins)
HEADERS = {"X-Frame-Options": "DENY", "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer"}


def _stop(scope: dict) -> str:
    """ ' http://HOST:PORT' of the stop listener as this request's host reaches it, or '' (none, or not a
    shakeid app: the middleware alone)."""
    svc = getattr(getattr(scope.get("app"), "state", None), "services", None)
    if svc is None:
        return ""
    host = next((v.decode("latin-1") for k, v in scope.get("headers", []) if k == b"host"), None)
    origin = svc.stop_origin(host)
    return " " + origin if origin else ""


class SecurityHeaders:
    """app = SecurityHeaders(app), or `app.add_middleware(SecurityHeaders)`."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope: dict, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        csp = DOCS_CSP if scope.get("path", "").startswith(DOCS_PATHS) else DASHBOARD_CSP.format(stop=_stop(scope))
        extra = [(name.lower().encode(), value.encode())
                 for name, value in {"Content-Security-Policy": csp, **HEADERS}.items()]

        async def send_with_headers(message: dict) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {name.lower() for name, _ in headers}
                message["headers"] = headers + [(n, v) for n, v in extra if n not in present]
            await send(message)

        await self.app(scope, receive, send_with_headers)
