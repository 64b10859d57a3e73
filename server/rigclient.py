"""The web server's side of the rig controller (server/controller.py): start it or attach to it, hold
the session, and come back after either side restarts.

`shakeid serve` starts the controller as a child process (its own session, so a Ctrl-C meant for the
web server reaches the controller only through the orderly shutdown) unless `--controller ADDRESS`
names one that runs on its own. The session connection tells the controller the web server is alive;
its end (a crash, a SIGKILL) makes the controller stop the table. If the controller goes away, requests
answer 503 and the link retries: a child that died is started again.
"""
from __future__ import annotations

import os
import subprocess
import sys
import threading

from .controller import default_address, key_path
from .ipc import ControllerClient, ControllerUnavailable, connect, read_key
from .settings import Settings


class RigLink:
    """address: an existing controller's, or None to start one as a child; on_event(dict) for pushed
    events (e.g. {"event": "recording_complete", "recording_id": ...})."""

    def __init__(self, settings: Settings, address: str | None = None, on_event=None):
        self.settings, self.on_event = settings, on_event
        self.child = address is None
        self.address = address or default_address(settings.data_dir)
        # the controller writes its key into the data directory both share (catalog, recordings)
        self.key_file = key_path(settings.data_dir)
        self.client = ControllerClient(self.address, self.key_file)
        self.proc: subprocess.Popen | None = None
        self.attached = threading.Event()
        self.stop_port: int | None = None  # the controller's stop listener (server/stoplistener.py), if any
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._keep_session, name="controller-session", daemon=True)
        self._log = None

    # -- lifecycle ------------------------------------------------------------------------------------
    def start(self, timeout_s: float = 60.0) -> None:
        if self.child:
            self._spawn()
        self._thread.start()
        if not self.child:  # one of its own may come later: until then the rig answers 503, the rest works
            if not self.attached.wait(min(timeout_s, 10.0)):
                print(f"shakeid serve: no rig controller at {self.address} yet; rig requests answer 503 until it "
                      "comes (`shakeid controller`)", flush=True)
                return
        elif not self.attached.wait(timeout_s):
            raise ControllerUnavailable(f"the rig controller at {self.address} did not answer within "
                                        f"{timeout_s:g} s: {self._log_tail()}")
        try:
            self.client.connect_estop()  # opened now: the first stop does not pay for a connection
        except ControllerUnavailable:
            pass

    def _spawn(self) -> None:
        key_path(self.settings.data_dir).unlink(missing_ok=True)  # a dead controller's: wait for the new one
        cmd = [sys.executable, "-m", "server.run_controller", "--data-dir", str(self.settings.data_dir),
               "--address", self.address, "--parent-pid", str(os.getpid())]
        if self.settings.config_path:
            cmd += ["--config", str(self.settings.config_path)]
        else:
            cmd += ["--sim-speed", repr(self.settings.sim_speed)]
        if self._log is None:
            self._log = open(self.settings.data_dir / "controller.log", "a")
        # its stop listener where this web server's settings put it (`shakeid serve` resolved them from
        # --host/--port); none when they were not resolved (an app made in a test, say)
        env = {**os.environ, "SHAKEID_STOP_PORT": str(self.settings.stop_port or 0)}
        if self.settings.stop_host:
            env["SHAKEID_STOP_HOST"] = self.settings.stop_host
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     start_new_session=True, env=env)

    def _log_tail(self) -> str:
        try:
            return (self.settings.data_dir / "controller.log").read_text()[-2000:].strip()
        except OSError:
            return ""

    def _keep_session(self) -> None:
        """Hold the session; when it ends, reattach (restarting a dead child) until stopped."""
        while not self._stop.is_set():
            if self.child and self.proc is not None and self.proc.poll() is not None:
                print(f"shakeid serve: the rig controller exited (code {self.proc.returncode}); starting it again",
                      flush=True)
                self._spawn()
            try:
                line = connect(self.address, read_key(self.key_file, wait_s=0.5), "session")
            except ControllerUnavailable:
                self._stop.wait(0.2)
                continue
            line.sock.settimeout(None)  # a session is quiet for hours; only its end means something
            self.stop_port = line.hello.get("stop_port")
            self.attached.set()
            self._session = line
            try:
                while (event := line.recv()) is not None:
                    if self.on_event:
                        self.on_event(event)
            except (OSError, ValueError):
                pass
            finally:
                self.attached.clear()
                line.close()
            if not self._stop.is_set():
                print("shakeid serve: lost the rig controller; reattaching", flush=True)

    def stop(self, reason: str = "the service is shutting down", timeout_s: float = 20.0) -> None:
        """A child controller is asked to stop the table and exit (waited for); an attached one only
        loses this web server (it stops a running sweep itself, as for any web server that goes away)."""
        self._stop.set()
        if self.child and self.proc is not None and self.proc.poll() is None:
            try:
                self.client.call("shutdown", reason=reason)
            except Exception:
                self.proc.terminate()  # SIGTERM: the controller's own orderly stop
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        session = getattr(self, "_session", None)
        if session is not None:
            session.close()
        self.client.close()
        self._thread.join(2)
        if self._log is not None:
            self._log.close()

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None
