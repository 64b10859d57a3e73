"""The rig as the controller process runs it (server/controller.py): one sweep at a time, progress, a
live view, emergency stop.

A sweep runs in its own thread with its own PLC and accelerometer connections (daq.SweepRunner, the
same code as `shakeid sweep`), so the HDF5 file it writes is as crash-safe as the CLI's; its heartbeat
has a PLC connection of its own, so a slow status poll never delays a beat. Two more PLC connections,
each behind its own lock, serve status/reset and the emergency stop, so a stop is never queued behind
the sweep's traffic or a status poll. With no rig configuration an embedded simulated rig
(sim.server.SimulatedRig) plays the hardware over loopback Modbus and the TCP stream.
"""
from __future__ import annotations

import dataclasses
import itertools
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from daq.plc import open_plc
from daq.devices import DeviceError
from daq.sources import open_source
from daq.sweep import SweepRefused, SweepRequest, SweepRunner, limit_violation, plc_not_ready
from sim.config import RigConfig
from protocol.plc import Command, Fault, State
from sim.plc import PLCConfig

#: the PLC status served to pollers is at most this old, s (the dashboard refreshes every second)
STATUS_MAX_AGE_S = 0.1
#: samples per second kept for the live view (decimated by block means; enough for a browser plot)
LIVE_RATE_HZ = 200.0


class RigBusy(Exception):
    """Another sweep is queued or running."""


class LiveBuffer:
    """Decimated samples of the running recording, numbered so each SSE client can follow on; t is the
    time into the sweep (s since the recording's first sample), not the accelerometers' clock."""

    def __init__(self, recording_id: str, channels, fs_hz: float, maxlen: int = 20000):
        self.recording_id, self.channels, self.fs_hz = recording_id, list(channels), fs_hz
        self.step = max(1, int(round(fs_hz / LIVE_RATE_HZ)))
        self.points: deque = deque(maxlen=maxlen)  # (seq, t_s, values...)
        self.seq = 0
        self.done = False
        self.first_index: int | None = None  # the recording's first sample on the accelerometers' clock

    def add(self, first_index: int, block: np.ndarray) -> None:
        # keep every step-th sample (aligned to the sample index, so decimation is the same across blocks)
        if self.first_index is None:
            self.first_index = first_index
        k0 = (-first_index) % self.step
        for k in range(k0, block.shape[0], self.step):
            self.seq += 1
            self.points.append((self.seq, (first_index + k - self.first_index) / self.fs_hz, *map(float, block[k])))

    def since(self, seq: int) -> list[tuple]:
        """Points numbered above seq: the numbers are consecutive, so skip straight to them."""
        points = self.points
        if not points:
            return []
        return list(itertools.islice(points, max(seq - points[0][0] + 1, 0), None))


class RigService:
    """rig: the rig configuration, or None for an embedded simulated rig running at sim_speed."""

    def __init__(self, rig: RigConfig | None, sim_speed: float = 1.0):
        self.cfg = rig or RigConfig()
        self.sim = None
        if rig is None:
            from sim.server import SimulatedRig

            # the client heartbeat is every 50 ms of wall time: the watchdog allows that in rig time
            watchdog = max(self.cfg.limits.watchdog_s, 0.5 * sim_speed)
            self.cfg.limits = dataclasses.replace(self.cfg.limits, watchdog_s=watchdog)
            self.sim = SimulatedRig(PLCConfig(limits=self.cfg.limits), speed=sim_speed)
        # two PLC connections besides the sweep's: one for status/reset, one that only ever sends the
        # emergency stop, so a stop never waits behind status polls
        self._links = {"control": [threading.Lock(), None], "estop": [threading.Lock(), None]}
        self.active: dict | None = None  # {"id", "runner", "thread", "live"}
        self.last_live: LiveBuffer | None = None
        self._status: tuple[float, object] | None = None  # (monotonic time, PLCStatus) of the last read
        self._lock = threading.Lock()

    # -- lifecycle ----------------------------------------------------------------------------------
    def start(self) -> None:
        if self.sim is not None:
            self.sim.start()
            host, port = self.sim.endpoints["modbus"]
            self.cfg.plc = {"transport": "modbus", "host": host, "port": port}
            self.cfg.stream = {**self.cfg.stream, "url": self.sim.endpoints["stream"]}

    def stop(self, reason: str = "the service is shutting down") -> None:
        """Abort a running sweep (the table is commanded to stop, the file closed with `reason`), wait
        for it, then close the links and the simulated rig."""
        act = self.active
        if act is not None:
            act["runner"].abort(reason)
            act["thread"].join(15)
        for _, plc in self._links.values():
            if plc is not None:
                plc.close()
        if self.sim is not None:
            self.sim.stop()

    def _with_control(self, fn, link: str = "control"):
        """Run fn(plc) on one of the service's own PLC connections, reconnecting once if it dropped."""
        entry = self._links[link]
        with entry[0]:
            for attempt in (0, 1):
                try:
                    if entry[1] is None:
                        entry[1] = open_plc(self.cfg.plc)
                    return fn(entry[1])
                except DeviceError:
                    if entry[1] is not None:
                        entry[1].close()
                    entry[1] = None
                    if attempt:
                        raise

    # -- what the API offers -------------------------------------------------------------------------
    def _plc_status(self):
        """The PLC's status, read at most every STATUS_MAX_AGE_S: fifty dashboards polling must not
        become fifty Modbus reads a poll (a PLC has better things to do; the simulated one shares the
        machine). Commands (reset, estop, sweeps) always read it afresh."""
        cached = self._status
        if cached is not None and time.monotonic() - cached[0] < STATUS_MAX_AGE_S:
            return cached[1]
        st = self._with_control(lambda plc: plc.status())
        self._status = (time.monotonic(), st)
        return st

    def status(self) -> dict:
        try:
            st = self._plc_status()
            plc = {"reachable": True, "state": State(st.state).name.lower(), "fault": Fault(st.fault_code).name.lower(),
                   "elapsed_s": st.elapsed_s, "frequency_hz": st.frequency_hz, "position_mm": st.position_mm}
        except DeviceError as exc:
            plc = {"reachable": False, "error": str(exc)}
        return {"plc": plc, "simulated": self.sim is not None, "transport": self.cfg.plc.get("transport", "modbus"),
                "accelerometers": {"source": self.cfg.accelerometers, "fs_hz": self.cfg.fs_hz,
                                   "channels": list(self.cfg.channels)},
                "limits": dataclasses.asdict(self.cfg.limits),
                "active_sweep": self.active["id"] if self.active else None}

    def check(self, req: SweepRequest) -> str | None:
        """The violated limit's message, or None: the same check the PLC runs, before anything is sent."""
        return limit_violation(self.cfg.limits, req)

    def emergency_stop(self) -> dict:
        act = self.active
        try:
            self._with_control(lambda plc: plc.command(Command.ESTOP), "estop")  # the table first, bookkeeping after
        finally:
            self._status = None
            if act is not None:
                act["runner"].abort("emergency stop")
        return {"state": "estop", "aborted_sweep": act["id"] if act else None}

    def reset(self):
        """RESET, then the PLC's status read back (still FAULT/ESTOP if the table was not at rest)."""
        def reset_and_read(plc):
            plc.command(Command.RESET)
            return plc.status()
        self._status = None
        return self._with_control(reset_and_read)

    def not_ready(self) -> str | None:
        """Why a sweep cannot start now (the PLC in estop, fault or running), or None: asked before a
        sweep is accepted, so the caller hears it at once instead of from a failed sweep later."""
        return plc_not_ready(self._with_control(lambda plc: plc.status()))

    def begin_sweep(self, sweep_id: str, req: SweepRequest, out_path: Path, on_progress, on_end) -> LiveBuffer:
        """Start a sweep thread. Raises RigBusy if one is active. on_end(result | None, error | None)."""
        with self._lock:
            if self.active is not None:
                raise RigBusy(self.active["id"])
            live = LiveBuffer(out_path.stem, self.cfg.channels, self.cfg.fs_hz)
            devices = []  # the sweep's own PLC link, its heartbeat's link, the accelerometers
            try:
                devices.append(open_plc(self.cfg.plc))
                devices.append(open_plc(self.cfg.plc))
                devices.append(open_source(self.cfg.stream, self.cfg.can, self.cfg.fs_hz, self.cfg.accelerometers))
            except DeviceError:
                for dev in devices:
                    dev.close()
                raise
            plc, beat_plc, source = devices
            runner = SweepRunner(plc, source, self.cfg.limits, float(self.cfg.stream["sensitivity_counts_per_ms2"]),
                                 self.cfg.channels, on_progress=on_progress, on_samples=live.add,
                                 rig_config={**self.cfg.recording_metadata(), "simulated": self.sim is not None,
                                             # the embedded simulated rig's mass is known: its own
                                             **({"moving_mass_kg": self.sim.plc.config.rig.mass_kg}
                                                if self.sim is not None else {})}, heartbeat_plc=beat_plc)
            thread = threading.Thread(target=self._run, args=(runner, devices, req, out_path, live, on_end),
                                      name=f"sweep-{sweep_id}", daemon=True)
            self.active = {"id": sweep_id, "runner": runner, "thread": thread, "live": live}
            thread.start()
            return live

    def _run(self, runner, devices, req, out_path, live, on_end) -> None:
        result, error = None, None
        try:
            result = runner.run(req, out_path)
        except SweepRefused as exc:
            error = str(exc)
        except Exception as exc:  # reported on the sweep, never lost in a thread
            error = f"internal error: {type(exc).__name__}: {exc}"
        finally:
            if self.active is not None:
                self.active["ending"] = True  # what is left: bookkeeping, closing the connections
            try:
                # the catalog first (the file is closed already): a live client that sees the end finds the
                # status, and identification does not wait for pyserial's socket close (it sleeps 0.3 s)
                on_end(result, error)
            finally:
                live.done = True
                with self._lock:
                    self.last_live = live  # late live clients still get the tail and the end
                    self.active = None  # the rig takes the next sweep now; these connections are this sweep's
                for dev in devices:
                    try:
                        dev.close()
                    except Exception:
                        pass

    def abort(self, sweep_id: str) -> bool:
        act = self.active
        if act is None or act["id"] != sweep_id:
            return False
        act["runner"].abort("operator abort (HTTP)")
        return True

    def live(self, recording_id: str) -> LiveBuffer | None:
        """The live view of the running recording, or of the one that just ended."""
        act = self.active
        for live in (act["live"] if act else None, self.last_live):
            if live is not None and live.recording_id == recording_id:
                return live
        return None
