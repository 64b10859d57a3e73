"""Starting a sweep in the rig controller, and its rows in the catalog: the sweep and the recording it makes.

One path for a single sweep and a campaign's (server/campaign.py): the request checked against the limits
and the rig's state, both rows inserted before the sweep thread exists (so its end always finds them),
progress written as it runs, the outcome and the heartbeat's intervals stored when it ends, and a
`recording_complete` event for the web server, which queues the identification (server/jobs.py).
"""
from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path

from daq.devices import DeviceError
from daq.sweep import SweepRequest

from .catalog import Catalog, new_id
from .rig import RigBusy, RigService

#: a sweep's heartbeat intervals in recordings.info as counts per bin of this width (`heartbeat_histogram_ms`:
#: {lower edge in ms: count}): those of many sweeps pool into one p99 (a short sweep's own p99 is its largest)
HEARTBEAT_BIN_MS = 1
#: shortest time between two progress writes of a running sweep, s
PROGRESS_EVERY_S = 0.2


class Refused(Exception):
    """A request the controller turns down; status is the HTTP status the web server answers with."""

    def __init__(self, status: int, detail: str):
        super().__init__(detail)
        self.status, self.detail = status, detail


class SweepLauncher:
    """Starts sweeps in `rig` and keeps their rows in `catalog`; notify(event) tells the web server."""

    def __init__(self, rig: RigService, catalog: Catalog, recordings_dir: Path, notify):
        self.rig, self.catalog, self.recordings_dir, self.notify = rig, catalog, recordings_dir, notify
        # held while a sweep or a campaign is being started (checks, then the start): never by the estop path
        self.starting = threading.RLock()
        self.closed_reason: str | None = None  # set once stopping: no sweep starts after the rig was stopped

    def close(self, reason: str) -> None:
        """No sweep starts from now on; one being started right now is active once this returns."""
        with self.starting:
            self.closed_reason = reason

    def launch(self, body: dict, operator: str = "", after_end=None, held=None) -> dict | None:
        """Start one sweep (single or a campaign's): limits (422), another sweep or a PLC in estop/fault
        (409), the rig unreachable or the controller stopping (503). after_end(result, error) is called after
        the catalog has the sweep's end; held() -> reason, asked last before the start: None is returned
        (nothing started) if it gives one (a campaign paused or halted meanwhile)."""
        with self.starting:
            req = SweepRequest(float(body["f_start_hz"]), float(body["f_end_hz"]), float(body["duration_s"]),
                               float(body["amplitude_mm"]), float(body.get("settle_s", 2.0)), operator=operator,
                               note=str(body.get("note", "")))
            self._check(req)
            if held is not None and held():
                return None
            return self._start(req, body, operator, after_end)

    def _check(self, req: SweepRequest) -> None:
        problem = self.rig.check(req)
        if problem:
            raise Refused(422, f"sweep refused: {problem}")
        act = self.rig.active
        if act is not None and act.get("ending"):  # its end is in the catalog; its connections are closing
            act["thread"].join(5.0)
        if self.rig.active is not None:
            raise Refused(409, f"another sweep is running ({self.rig.active['id']}); abort it or wait")
        refusal = self.rig.not_ready()
        if refusal:
            raise Refused(409, f"sweep refused: {refusal}")
        if self.closed_reason is not None:
            raise Refused(503, f"sweep refused: {self.closed_reason or 'the rig controller is stopping'}")

    def _start(self, req: SweepRequest, body: dict, operator: str, after_end) -> dict:
        sweep_id, rec_id = new_id(), new_id()
        path = self.recordings_dir / f"{rec_id}.h5"
        now = time.time()
        last = {"t": 0.0}
        cat = self.catalog

        def on_progress(frac, st):
            if time.monotonic() - last["t"] >= PROGRESS_EVERY_S or frac >= 1.0:
                last["t"] = time.monotonic()
                cat.update("sweeps", sweep_id, state="running", progress=round(frac, 4))

        cat.insert("sweeps", id=sweep_id, created=now, updated=now, state="queued", progress=0.0, request=body,
                   recording_id=rec_id, error=None, operator=operator)
        # in the catalog before the sweep thread exists, so its end always finds both rows
        cat.insert("recordings", id=rec_id, created=now, origin="sweep", filename=path.name, path=str(path),
                   status="running", sweep_id=sweep_id, info={"sweep": body})
        started: dict = {}  # the sweep's runner, for its heartbeat intervals

        def on_end(result, error):
            try:
                runner = started.get("runner")
                if result is not None and runner is not None:
                    result = {**result, "heartbeat_histogram_ms": heartbeat_histogram(runner.heartbeat_intervals)}
                self._ended(sweep_id, rec_id, path, result, error)
            finally:
                if after_end is not None:
                    after_end(result, error)

        try:
            self.rig.begin_sweep(sweep_id, req, path, on_progress, on_end)
        except RigBusy as busy:  # lost a race with another request: as if it had come first
            cat.delete("recordings", rec_id)
            cat.delete("sweeps", sweep_id)
            raise Refused(409, f"another sweep is running ({busy}); abort it or wait") from None
        except DeviceError as exc:
            cat.delete("recordings", rec_id)
            cat.update("sweeps", sweep_id, state="failed", error=str(exc), recording_id=None)
            raise Refused(503, f"rig not reachable: {exc}") from None
        started["runner"] = (self.rig.active or {}).get("runner")  # ours: no other starts while `starting` is held
        return {"id": sweep_id, "state": "queued", "recording_id": rec_id}

    def _ended(self, sweep_id, rec_id, path, result, error) -> None:
        cat = self.catalog
        if result is None:  # refused at preflight (nothing recorded, no file) or failed before recording
            if path.exists():  # an internal error after the file was opened: keep what it holds
                cat.update("sweeps", sweep_id, state="failed", error=error)
                cat.update("recordings", rec_id, status="failed")
            else:
                cat.update("sweeps", sweep_id, state="failed", error=error, recording_id=None)
                cat.delete("recordings", rec_id)
            return
        sweep_state = {"complete": "completed"}.get(result["status"], "aborted")
        cat.update("sweeps", sweep_id, state=sweep_state, error=result["reason"] or None,
                   **({"progress": 1.0} if sweep_state == "completed" else {}))
        # the outcome's keys added to info in one statement (the web server sets its own keys meanwhile),
        # then the status: whoever sees the recording complete finds its outcome there
        cat.set_info(rec_id, **{k: v for k, v in result.items() if k != "path"})
        cat.update("recordings", rec_id, status=result["status"])
        if sweep_state == "completed":  # the web server queues its identification (server/jobs.py)
            self.notify({"event": "recording_complete", "recording_id": rec_id})


def heartbeat_histogram(intervals_s) -> dict:
    """{lower bin edge in ms (a string, for JSON): count} of a sweep's heartbeat intervals (HEARTBEAT_BIN_MS)."""
    return dict(Counter(str(int(gap * 1000 // HEARTBEAT_BIN_MS) * HEARTBEAT_BIN_MS) for gap in intervals_s))
