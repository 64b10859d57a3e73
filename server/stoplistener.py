"""The stop listener: `POST /api/rig/estop` served by the rig controller, on a port of its own.

The web server's one event loop serves every viewer (live streams, pollers, uploads), and any request
on its port waits behind them: with 200 live viewers a stop took 0.6-2.4 s there (issue 31). This
listener runs in the rig controller process (its own interpreter and lock, no viewer traffic), each
connection in a thread of its own at the stop's real-time priority (daq.realtime.ESTOP_PRIORITY), and
does one thing: the emergency stop, through the same call as the web server's route (the controller's
"estop" request: campaign halted, ESTOP to the PLC on its own connection, the sweep aborted), with the
same operator tokens and the same JSON answer ({"state": "estop", "aborted_sweep": ...}).

A browser page may post here from the dashboard (another port of the same host, so another origin): the
listener answers CORS for an origin on the host the stop was sent to (preflight: POST, the
Authorization header). The bearer token is what authorizes; no cookie is ever read.
Standard library only (http.server): the controller stays free of the web stack.
"""
from __future__ import annotations

import http.server
import json
import socket
import threading
from urllib.parse import urlsplit

from daq.realtime import ESTOP_PRIORITY, make_realtime

from .settings import token_refusal, token_role

#: the one path served (the web server's route of the same name does the same)
ESTOP_PATH = "/api/rig/estop"
#: a connection that sends nothing for this long is closed, s: a slow or idle client holds no thread
CLIENT_TIMEOUT_S = 5.0
#: the largest request body read (a stop takes none): larger is refused, 413
MAX_BODY_BYTES = 64 * 1024
#: how long a browser may keep a preflight's answer, s
PREFLIGHT_MAX_AGE_S = 600


def not_delivered(reason) -> str:
    """The answer (503) when the stop did not reach the PLC: both ports say the same."""
    return f"emergency stop not delivered: {reason}; use the hardware stop"


def allowed_origin(origin: str | None, host: str | None) -> str | None:
    """The Origin to allow (echoed), or None: a page served from the same host name as the one the
    stop was sent to (the dashboard on the web port of this host), http or https."""
    if not origin or not host:
        return None
    try:
        page = urlsplit(origin)
        here = urlsplit("//" + host)
        if page.scheme in ("http", "https") and page.hostname and page.hostname == here.hostname:
            return origin
    except ValueError:
        pass
    return None


class StopHandler(http.server.BaseHTTPRequestHandler):
    """One connection (HTTP/1.1, kept alive up to CLIENT_TIMEOUT_S between requests)."""

    protocol_version = "HTTP/1.1"
    timeout = CLIENT_TIMEOUT_S
    server_version = "shakeid-stop"
    server: "StopListener"

    def setup(self) -> None:
        make_realtime(ESTOP_PRIORITY)  # this connection's thread runs as soon as the stop arrives
        super().setup()
        try:
            self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            pass

    def version_string(self) -> str:
        return self.server_version

    def log_message(self, format, *args) -> None:  # noqa: A002 - the base class's name
        pass  # no line per request: the controller's log is for the rig

    def _answer(self, status: int, body: dict | None, extra: dict | None = None) -> None:
        data = json.dumps(body).encode() if body is not None else b""
        self.send_response(status)
        headers = {"Content-Type": "application/json", "Content-Length": str(len(data)), "Cache-Control": "no-store",
                   "X-Content-Type-Options": "nosniff", **(extra or {})}
        origin = allowed_origin(self.headers.get("Origin"), self.headers.get("Host"))
        if origin:
            headers.update({"Access-Control-Allow-Origin": origin, "Vary": "Origin"})
        for name, value in headers.items():
            self.send_header(name, value)
        self.end_headers()
        self.wfile.write(data)

    def _drain_body(self) -> bool:
        """Read (and drop) the request body; False (answered 411/413) if it is chunked or too large."""
        if self.headers.get("Transfer-Encoding", "").lower() == "chunked":
            self.close_connection = True
            self._answer(411, {"detail": "send the stop without a body, or with a Content-Length"})
            return False
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1
        if not 0 <= length <= MAX_BODY_BYTES:
            self.close_connection = True
            self._answer(413, {"detail": f"the stop takes no body (at most {MAX_BODY_BYTES} bytes are read)"})
            return False
        if length:
            self.rfile.read(length)
        return True

    def do_OPTIONS(self) -> None:  # noqa: N802 - http.server's naming
        """CORS preflight of the dashboard's POST (its Authorization header makes one)."""
        if self.path.split("?", 1)[0] != ESTOP_PATH:
            return self._answer(404, {"detail": f"only {ESTOP_PATH} is served on this port"})
        if not allowed_origin(self.headers.get("Origin"), self.headers.get("Host")):
            return self._answer(403, {"detail": "a page of another host may not post the stop here"})
        extra = {"Access-Control-Allow-Methods": "POST", "Access-Control-Allow-Headers": "Authorization, Content-Type",
                 "Access-Control-Max-Age": str(PREFLIGHT_MAX_AGE_S)}
        if self.headers.get("Access-Control-Request-Private-Network"):
            extra["Access-Control-Allow-Private-Network"] = "true"
        self._answer(204, None, extra)

    def do_POST(self) -> None:  # noqa: N802
        if not self._drain_body():
            return
        if self.path.split("?", 1)[0] != ESTOP_PATH:
            return self._answer(404, {"detail": f"only POST {ESTOP_PATH} is served on this port"})
        scheme, _, token = self.headers.get("Authorization", "").partition(" ")
        role = token_role(self.server.tokens, token.strip()) if scheme.lower() == "bearer" else None
        refused = token_refusal(role, "operator")  # the web server's route's check and words
        if refused:
            status, detail = refused
            return self._answer(status, {"detail": detail}, {"WWW-Authenticate": "Bearer"} if status == 401 else None)
        answer = self.server.estop()
        if answer.get("ok"):
            return self._answer(200, answer["result"])
        self._answer(503, {"detail": not_delivered(answer.get("detail", "refused"))})

    def _not_here(self) -> None:
        if self._drain_body():
            self._answer(405, {"detail": f"only POST {ESTOP_PATH} is served on this port"}, {"Allow": "POST, OPTIONS"})

    do_GET = do_PUT = do_DELETE = do_PATCH = do_HEAD = _not_here


class StopListener(http.server.ThreadingHTTPServer):
    """estop() -> the controller's answer ({"ok": true, "result": ...} or {"ok": false, "detail": ...});
    tokens: token -> role, the service's."""

    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 64

    def __init__(self, host: str, port: int, tokens: dict[str, str], estop):
        self.address_family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.tokens, self.estop = tokens, estop
        super().__init__((host, port), StopHandler)

    @property
    def port(self) -> int:
        return self.server_address[1]

    def start(self) -> "StopListener":
        def serve():
            make_realtime(ESTOP_PRIORITY)  # the accepting thread too: a connection is taken at once
            self.serve_forever(poll_interval=0.5)

        threading.Thread(target=serve, name="stop-listener", daemon=True).start()  # ends with stop()'s shutdown
        return self

    def stop(self) -> None:
        self.shutdown()
        self.server_close()


def open_listener(host: str, port: int, tokens: dict[str, str], estop) -> StopListener | None:
    """The rig controller's stop listener on host:port, serving; None for port 0 (none) or a port that
    cannot be had (said, not fatal: the web server's route stays, and /api/health then names no stop_url)."""
    if not port:
        return None
    try:
        return StopListener(host, port, tokens, estop).start()
    except OSError as exc:
        print(f"shakeid controller: no stop listener on {host}:{port} ({exc}); the emergency stop is served "
              "by the web server's port only", flush=True)
        return None
