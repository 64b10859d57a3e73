"""The local channel between the web server and the rig controller: JSON lines over a socket.

One request per line, one answer per line, in order, on each connection:

    -> {"op": "status"}                 <- {"ok": true, "result": {...}}
    -> {"op": "start_sweep", ...}       <- {"ok": false, "status": 409, "detail": "the PLC is in estop ..."}

A connection opens with `{"op": "hello", "key": ..., "role": ...}`; the key is a random secret the
controller writes (mode 0600) beside its socket, so only processes that can read the data directory
talk to the rig. Roles: "client" (requests), "estop" (a connection the web server keeps for the
emergency stop alone, so a stop never queues behind another request), "session" (the web server's
attachment: the controller pushes events on it, e.g. `{"event": "recording_complete", ...}`, and treats its end as
the web server's death). Addresses: `unix:/path/controller.sock` (default, in the data directory) or
`tcp:127.0.0.1:PORT` (e.g. between containers).
"""
from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

from identify.errors import ShakeidError

from .text import finite

#: longest wait for the controller's answer to an emergency stop, s (it answers in milliseconds from a
#: real-time thread; past this the caller is told to use the hardware stop)
ESTOP_TIMEOUT_S = 2.0
#: longest line either side sends (a live-view answer with ~2 s of decimated samples is ~100 kB)
MAX_LINE = 8 * 2**20


class ControllerUnavailable(ShakeidError):
    """The rig controller cannot be reached (not started yet, restarting, or dead)."""


class ControllerRefused(ShakeidError):
    """The controller answered with a refusal: `status` is the HTTP status it maps to."""

    def __init__(self, status: int, detail: str):
        super().__init__(detail)
        self.status, self.detail = status, detail


def parse_address(address: str) -> tuple[int, object]:
    """'unix:/path' or 'tcp:host:port' -> (socket family, address)."""
    kind, _, rest = address.partition(":")
    if kind == "unix" and rest:
        return socket.AF_UNIX, rest
    if kind == "tcp" and ":" in rest:
        host, port = rest.rsplit(":", 1)
        return socket.AF_INET, (host, int(port))
    raise ShakeidError(f"controller address {address!r}: expected unix:/path/to/socket or tcp:HOST:PORT")


class Line:
    """A connected socket read and written as JSON lines (one writer at a time)."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.reader = sock.makefile("rb")
        self.write_lock = threading.Lock()
        self.hello: dict = {}

    def send(self, obj) -> None:
        data = json.dumps(finite(obj), separators=(",", ":"), allow_nan=False).encode() + b"\n"
        with self.write_lock:
            self.sock.sendall(data)

    def recv(self):
        """The next message, or None at the end of the stream."""
        line = self.reader.readline(MAX_LINE + 1)
        if not line:
            return None
        if len(line) > MAX_LINE:
            raise ConnectionError("message longer than the channel's limit")
        return json.loads(line)

    def close(self) -> None:
        for closer in (self.reader.close, lambda: self.sock.shutdown(socket.SHUT_RDWR), self.sock.close):
            try:
                closer()
            except OSError:
                pass


def connect(address: str, key: str, role: str = "client", timeout_s: float = 5.0) -> Line:
    family, addr = parse_address(address)
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.settimeout(timeout_s)
    try:
        sock.connect(addr)
        if family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        line = Line(sock)
        line.send({"op": "hello", "key": key, "role": role})
        answer = line.recv()
    except (OSError, ValueError) as exc:
        sock.close()
        raise ControllerUnavailable(f"rig controller at {address} not reachable: {exc}") from None
    if not answer or not answer.get("ok"):
        sock.close()
        raise ControllerUnavailable(f"rig controller at {address} refused the connection: "
                                    f"{(answer or {}).get('detail', 'no answer')}")
    line.hello = answer.get("result") or {}  # the controller's pid, its rig, its stop listener's port
    return line


def read_key(path: Path, wait_s: float = 0.0) -> str:
    """The controller's key file (waits up to wait_s for a controller that is starting)."""
    end = time.monotonic() + wait_s
    while True:
        try:
            key = Path(path).read_text().strip()
            if key:
                return key
        except OSError:
            pass
        if time.monotonic() >= end:
            raise ControllerUnavailable(f"no controller key at {path}: is the rig controller running?")
        time.sleep(0.05)


class ControllerClient:
    """Requests to the rig controller from many threads: a small pool of "client" connections, plus one
    connection of its own for the emergency stop.

    call() raises ControllerUnavailable when the controller cannot be reached (after one reconnect) and
    ControllerRefused with the HTTP status the controller chose (409, 422, 503)."""

    def __init__(self, address: str, key_path: Path, timeout_s: float = 10.0):
        self.address, self.key_path, self.timeout_s = address, Path(key_path), timeout_s
        self._idle: list[Line] = []
        self._pool_lock = threading.Lock()
        self._estop: Line | None = None
        self._estop_lock = threading.Lock()

    def _open(self, role: str) -> Line:
        return connect(self.address, read_key(self.key_path), role, self.timeout_s)

    def _exchange(self, line: Line, request: dict):
        line.send(request)
        answer = line.recv()
        if answer is None:
            raise ConnectionError("the controller closed the connection")
        return answer

    @staticmethod
    def _result(answer: dict):
        if answer.get("ok"):
            return answer.get("result")
        raise ControllerRefused(int(answer.get("status", 500)), str(answer.get("detail", "refused")))

    def call(self, op: str, **params):
        request = {"op": op, **params}
        for attempt in (0, 1):
            with self._pool_lock:
                line = self._idle.pop() if self._idle else None
            try:
                line = line or self._open("client")
                answer = self._exchange(line, request)
            except (OSError, ValueError, ConnectionError) as exc:
                if line is not None:
                    line.close()
                if attempt:
                    raise ControllerUnavailable(f"rig controller at {self.address}: {exc}") from None
                continue
            with self._pool_lock:
                if len(self._idle) < 8:
                    self._idle.append(line)
                    line = None
            if line is not None:
                line.close()
            return self._result(answer)

    def emergency_stop(self) -> dict:
        """On the estop connection only (opened ahead of time by connect_estop): never behind a request;
        an answer within ESTOP_TIMEOUT_S or ControllerUnavailable."""
        with self._estop_lock:
            for attempt in (0, 1):
                try:
                    if self._estop is None:
                        self._estop = self._open("estop")
                        self._estop.sock.settimeout(ESTOP_TIMEOUT_S)
                    return self._result(self._exchange(self._estop, {"op": "estop"}))
                except (OSError, ValueError, ConnectionError) as exc:
                    if self._estop is not None:
                        self._estop.close()
                    self._estop = None
                    if attempt:
                        raise ControllerUnavailable(f"rig controller at {self.address}: {exc}") from None

    def connect_estop(self) -> None:
        with self._estop_lock:
            if self._estop is None:
                self._estop = self._open("estop")
                self._estop.sock.settimeout(ESTOP_TIMEOUT_S)

    def close(self) -> None:
        with self._pool_lock:
            idle, self._idle = self._idle, []
        for line in idle:
            line.close()
        with self._estop_lock:
            if self._estop is not None:
                self._estop.close()
                self._estop = None
