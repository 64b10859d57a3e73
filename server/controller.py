"""The rig controller: the one process that drives the rig, apart from the web server.

Sweep runner, heartbeat, PLC and accelerometer connections, the emergency stop and the embedded
simulated rig live here (server/rig.py's RigService), so nothing the web server does (parsing a
200 MB upload, serialising JSON for fifty pollers, a crash) can delay a heartbeat or a stop: the
pattern of Bluesky's queueserver, whose run-engine manager is a process apart from its HTTP server.
The web server talks to it over server/ipc.py (a Unix socket in the data directory by default).

The controller owns the sweeps and the recordings they make (their rows in the SQLite catalog, the
HDF5 files) and says when one completes (an event); the web server owns jobs (it queues the
identification) and uploads: each table has one writer, apart from `recordings.info`, whose keys each side
sets in one statement (Catalog.set_info).

Lifecycle:
- `shakeid serve` starts it as a child (`python -m server.run_controller --parent-pid PID`) and it lives
  as long as the web server: if the web server dies (its session connection ends, or its PID is gone) the running
  sweep is aborted, the table stopped, the file closed, and the controller exits.
- `shakeid controller --config RIG.toml` runs it on its own (a compose service); a web server attaches
  with `shakeid serve --controller ADDRESS`. If that web server dies the table is stopped the same way,
  and the controller waits for it to come back.
Every request is served on its own connection thread; the emergency stop has a PLC connection of its own.
The stop listener (server/stoplistener.py) serves `POST /api/rig/estop` over HTTP on settings.stop_port
from this process, where no viewer traffic is queued.
"""
from __future__ import annotations

import gc
import hmac
import os
import secrets
import signal
import socket
import sys
import threading
import time
from pathlib import Path

from daq.devices import DeviceError
from daq.realtime import CONTROLLER_PRIORITY, ESTOP_PRIORITY, make_realtime
from daq.recorder import recover_directory
from protocol.plc import State

from .campaign import CampaignService
from .catalog import Catalog
from .ipc import Line, parse_address
from .rig import RigService
from .settings import Settings
from .stoplistener import StopListener, open_listener
from .sweep_launch import Refused, SweepLauncher

#: why a sweep ended when its web server died (session ended or its process gone, whichever is seen first)
WEB_SERVER_GONE = "the web server went away during the sweep; the rig controller stopped the table"
#: decimated points one live request returns at the most (~10 s at the live view's 200 per second)
LIVE_BATCH = 2000


def default_address(data_dir: Path) -> str:
    return f"unix:{Path(data_dir).resolve() / 'controller.sock'}"


def key_path(data_dir: Path) -> Path:
    return Path(data_dir) / "controller.key"


class RigController:
    def __init__(self, settings: Settings, address: str | None = None, parent_pid: int | None = None):
        settings.prepare()
        self.settings, self.parent_pid = settings, parent_pid
        self.address = address or default_address(settings.data_dir)
        self.catalog = Catalog(settings.data_dir / "catalog.sqlite")
        self.rig = RigService(settings.rig, settings.sim_speed)
        self.key = secrets.token_urlsafe(32)
        self.sessions: set[Line] = set()
        self.stopping = threading.Event()
        self.stop_reason = "the rig controller is stopping"
        self._lock = threading.Lock()
        self._listener: socket.socket | None = None
        self.sweeps = SweepLauncher(self.rig, self.catalog, settings.data_dir / "recordings", self.notify)
        self.campaigns = CampaignService(self)
        settings.resolve_stop()  # a web server that started this controller has filled it in already
        self.stop_listener: StopListener | None = None

    # -- lifecycle ------------------------------------------------------------------------------------
    def start(self) -> "RigController":
        self._recover()
        self.rig.start()
        family, addr = parse_address(self.address)
        sock = socket.socket(family, socket.SOCK_STREAM)
        if family == socket.AF_UNIX:
            Path(addr).unlink(missing_ok=True)  # a socket file a dead controller left behind
        else:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(addr)
        if family == socket.AF_UNIX:
            os.chmod(addr, 0o600)
        sock.listen(64)
        self._listener = sock
        # the stop listener before the key: every hello names its port (a web server that attached while it
        # was still opening, under load, held a session without it and /api/health never named stop_url)
        self.stop_listener = open_listener(self.settings.stop_host, self.settings.stop_port, self.settings.tokens,
                                           lambda: self.handle({"op": "estop"}))
        path = key_path(self.settings.data_dir)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(self.key + "\n")
        tmp.chmod(0o600)
        os.replace(tmp, path)  # written last: a client that reads the key finds the socket listening
        threading.Thread(target=self._accept, name="controller-accept", daemon=True).start()
        if self.parent_pid:
            threading.Thread(target=self._watch_parent, name="controller-parent", daemon=True).start()
        return self

    def stop(self, reason: str) -> None:
        self.stop_reason = reason
        self.stopping.set()

    def run(self) -> None:
        """Serve until stopped; then stop the table, close the recording, and release everything."""
        self.stopping.wait()
        self.campaigns.halt(self.stop_reason)  # no next sweep; the catalog says paused (resumable)
        self.sweeps.close(self.stop_reason)  # a sweep being started right now is active once this returns
        self.rig.stop(self.stop_reason)  # aborts a running sweep (the table is commanded to stop) and waits
        self.campaigns.join()
        if self.stop_listener is not None:
            self.stop_listener.stop()
        if self._listener is not None:
            self._listener.close()
        family, addr = parse_address(self.address)
        if family == socket.AF_UNIX:
            Path(addr).unlink(missing_ok=True)
        key_path(self.settings.data_dir).unlink(missing_ok=True)
        self.catalog.close()

    def _recover(self) -> None:
        """What a dead controller left: recordings marked running become aborted (their data kept)."""
        for note in self.catalog.abort_interrupted_sweeps() + self.campaigns.recover():
            print(f"shakeid controller: {note}", flush=True)
        for path in recover_directory(self.settings.data_dir / "recordings"):
            self.catalog.update("recordings", path.stem, status="aborted")
            print(f"shakeid controller: recording {path.stem}: was left running; marked aborted, data kept", flush=True)
        for rec in self.catalog.list("recordings", "status = 'running'", limit=100_000):
            if not Path(rec["path"]).exists():  # died before its recorder created the file
                self.catalog.delete("recordings", rec["id"])

    def _watch_parent(self) -> None:
        while not self.stopping.wait(0.2):
            if os.getppid() != self.parent_pid:
                self.stop(WEB_SERVER_GONE)

    # -- connections ----------------------------------------------------------------------------------
    def _accept(self) -> None:
        while not self.stopping.is_set():
            try:
                sock, _ = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(sock,), name="controller-conn", daemon=True).start()

    def _serve(self, sock: socket.socket) -> None:
        sock.settimeout(5.0)  # for the hello only
        line = Line(sock)
        try:
            hello = line.recv()
            if not hello or hello.get("op") != "hello" or not hmac.compare_digest(
                    str(hello.get("key", "")).encode(), self.key.encode()):
                line.send({"ok": False, "status": 401, "detail": "wrong or missing controller key"})
                return
            sock.settimeout(None)
            stop_port = self.stop_listener.port if self.stop_listener is not None else None
            line.send({"ok": True, "result": {"pid": os.getpid(), "simulated": self.rig.sim is not None,
                                              "stop_port": stop_port}})
            if hello.get("role") == "session":
                return self._session(line)
            if hello.get("role") == "estop":  # this connection only ever carries the stop: it runs first
                make_realtime(ESTOP_PRIORITY)
            while (msg := line.recv()) is not None:
                line.send(self.handle(msg))
        except (OSError, ValueError):
            pass  # the peer went away mid-message: nothing to answer
        finally:
            line.close()

    def _session(self, line: Line) -> None:
        with self._lock:
            self.sessions.add(line)
        try:
            while line.recv() is not None:  # the web server's keep-alives; the end means it is gone
                pass
        except (OSError, ValueError):
            pass
        finally:
            with self._lock:
                self.sessions.discard(line)
                alone = not self.sessions
            if alone and not self.stopping.is_set():
                self._web_server_gone()

    def _web_server_gone(self) -> None:
        self.campaigns.halt(WEB_SERVER_GONE)  # a campaign pauses: no sweep starts without a web server
        act = self.rig.active
        if act is not None:
            print(f"shakeid controller: {WEB_SERVER_GONE} (sweep {act['id']})", flush=True)
            act["runner"].abort(WEB_SERVER_GONE)
        if self.parent_pid and os.getppid() != self.parent_pid:
            self.stop(WEB_SERVER_GONE)

    def notify(self, event: dict) -> None:
        with self._lock:
            sessions = list(self.sessions)
        for line in sessions:
            try:
                line.send(event)
            except OSError:
                pass

    # -- requests -------------------------------------------------------------------------------------
    def handle(self, msg: dict) -> dict:
        op = msg.get("op")
        fn = getattr(self, f"op_{op}", None) if isinstance(op, str) else None
        if fn is None:
            return {"ok": False, "status": 400, "detail": f"unknown request {op!r}"}
        try:
            return {"ok": True, "result": fn(**{k: v for k, v in msg.items() if k != "op"})}
        except Refused as exc:
            return {"ok": False, "status": exc.status, "detail": exc.detail}
        except DeviceError as exc:
            return {"ok": False, "status": 503, "detail": f"rig not reachable: {exc}"}
        except TypeError as exc:
            return {"ok": False, "status": 400, "detail": f"bad request {op!r}: {exc}"}
        except Exception as exc:  # said to the caller, never a dead connection thread
            return {"ok": False, "status": 500, "detail": f"controller error: {type(exc).__name__}: {exc}"}

    def op_ping(self) -> dict:
        return {"pid": os.getpid(), "active_sweep": self.rig.active["id"] if self.rig.active else None}

    def op_status(self) -> dict:
        act = self.campaigns.active
        return {**self.rig.status(), "active_campaign": act["id"] if act else None}

    def op_estop(self) -> dict:
        # a running campaign is halted first: a few attribute writes (no lock, no I/O, microseconds), so
        # that no next sweep can start between the stop reaching the PLC and the bookkeeping after it
        self.campaigns.halt("emergency stop")
        return self.rig.emergency_stop()

    def op_reset(self) -> dict:
        if self.rig.active is not None:  # nothing to reset while a sweep runs (RESET would not take)
            raise Refused(409, f"sweep {self.rig.active['id']} is running: there is nothing to reset (to stop it: "
                               f"POST /api/sweeps/{self.rig.active['id']}/abort, or POST /api/rig/estop)")
        st = self.rig.reset()
        if st.state == State.RUNNING:
            raise Refused(409, "the PLC is running a sweep it was given outside this service: there is nothing to "
                               "reset (POST /api/rig/estop stops it)")
        if st.state not in (State.IDLE, State.DONE):
            raise Refused(409, f"the PLC stayed in {State(st.state).name.lower()} (fault code {st.fault_code}): "
                               "the table is not at rest yet, or the fault is still there; try again")
        return {"state": State(st.state).name.lower()}

    def op_shutdown(self, reason: str = "the service is shutting down") -> dict:
        self.stop(reason)
        return {"stopping": True}

    def op_abort(self, sweep_id: str) -> bool:
        return self.rig.abort(sweep_id)

    def op_live(self, recording_id: str, after: int = 0) -> dict:
        buffer = self.rig.live(recording_id)
        if buffer is None:
            return {"active": False}
        points = buffer.since(int(after))[:LIVE_BATCH]
        return {"active": True, "channels": buffer.channels, "points": points,
                "done": buffer.done and len(points) < LIVE_BATCH}

    def op_start_sweep(self, body: dict, operator: str = "") -> dict:
        """Checked here, synchronously: limits (422), another sweep, a running campaign or a PLC in
        estop/fault (409)."""
        with self.sweeps.starting:
            busy = self.campaigns.busy()
            if busy:
                raise Refused(409, f"sweep refused: {busy}")
            return self.sweeps.launch(body, operator)

    # campaigns: server/campaign.py
    def op_start_campaign(self, plan: dict, operator: str = "") -> dict:
        return self.campaigns.start(plan, operator)

    def op_pause_campaign(self, campaign_id: str, operator: str = "") -> dict:
        return self.campaigns.pause(campaign_id, operator)

    def op_resume_campaign(self, campaign_id: str, operator: str = "") -> dict:
        return self.campaigns.resume(campaign_id, operator)

    def op_abort_campaign(self, campaign_id: str, operator: str = "") -> dict:
        return self.campaigns.abort(campaign_id, operator)


def main(settings: Settings, address: str | None = None, parent_pid: int | None = None) -> int:
    """`shakeid controller`: run until SIGTERM/SIGINT (or, as a child, until the web server is gone)."""
    # the rig's heartbeat and emergency stop come first: the whole process real-time where allowed (root,
    # CAP_SYS_NICE; daq/realtime.py says why all of it), else a higher CPU priority if that is allowed
    realtime = make_realtime(CONTROLLER_PRIORITY, round_robin=True)
    if not realtime:
        try:
            os.nice(-5)
        except OSError:
            pass
    # a thread that waited on the PLC or a socket gets the interpreter back within 1 ms, not 5 ms, of a
    # busy one (the sweep's decoding and HDF5 writes): the heartbeat and the stop are such threads
    sys.setswitchinterval(0.001)
    ctl = RigController(settings, address, parent_pid)
    signal.signal(signal.SIGTERM, lambda *_: ctl.stop("the rig controller was stopped (SIGTERM)"))
    signal.signal(signal.SIGINT, lambda *_: ctl.stop("the rig controller was stopped (SIGINT)"))
    ctl.start()
    # the heartbeat needs this interpreter's lock, and a full garbage collection holds it for the whole pass
    # over every object (~76k once numpy, h5py and pymodbus are in): 65-70 ms of CPU under the viewer flood,
    # in the sweep thread, and each heartbeat interval over 75 ms there was one (gc.callbacks). Whatever
    # exists once the controller is up lives as long as it: out of the collector's passes
    gc.freeze()
    print(f"shakeid controller: pid {os.getpid()}, {'real-time (SCHED_RR)' if realtime else 'normal'} scheduling, "
          f"listening on {ctl.address}"
          f" ({f'embedded simulated rig, sensor-noise seed {ctl.rig.sim.plc.seed}' if ctl.rig.sim is not None else 'rig of ' + str(settings.rig.source)})"
          + (f"; stop listener on {settings.stop_host}:{ctl.stop_listener.port}" if ctl.stop_listener else ""),
          flush=True)
    ctl.run()
    print(f"shakeid controller: stopped ({ctl.stop_reason})", flush=True)
    return 0
