"""Sweep orchestration: preflight, record, command, keep the heartbeat, follow, settle, finalise.

Preflight refuses unsafe parameters before anything is written to the PLC (the same `Limits.check` the
PLC runs again itself), and checks that the PLC answers and is idle and that the sensors stream. Every
exit (done, operator abort, PLC fault, lost PLC link, lost sensors) leaves the table commanded to stop
when the link allows it and the file closed with a status and the reason.
"""
from __future__ import annotations

import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identify.errors import ShakeidError
from protocol.plc import Command, Fault, Limits, State
from protocol.sweep import SineSweep

from .devices import PLC, DeviceError
from .preflight import RigResponse, Verdict, assess
from .realtime import HEARTBEAT_PRIORITY, make_realtime
from .sources import AccelerometerSource
from .recorder import DEFAULT_CHANNELS, DiskFull, Recorder, quality_summary


class SweepRefused(ShakeidError):
    """The sweep was not started: unsafe parameters or a rig that is not ready (nothing was written)."""


@dataclass
class SweepRequest:
    f_start_hz: float
    f_end_hz: float
    duration_s: float
    amplitude_mm: float
    settle_s: float = 2.0
    operator: str = ""
    note: str = ""

    def sine(self) -> SineSweep:
        """The table's motion this request asks for (ValueError for a sweep that is not one)."""
        return SineSweep(self.f_start_hz, self.f_end_hz, self.duration_s, self.amplitude_mm)


def limit_violation(limits: Limits, req: SweepRequest) -> str | None:
    """The message naming the first violated limit (the PLC's own check), or None for a safe sweep."""
    try:
        sweep = req.sine()
    except ValueError as exc:
        return str(exc)
    fault, message = limits.check(sweep)
    return message if fault != Fault.NONE else None


def predicted_verdict(response: RigResponse, req: SweepRequest, suggest: bool = True) -> Verdict:
    """The preflight's prediction of the sweep from the rig's model (daq/preflight.py): refused when the
    mass accelerometer would clip or the mass hit the end stops, warned near either. One path for the
    service's door, campaigns and `shakeid sweep/campaign --config`."""
    return assess(response, req.sine(), suggest)


def _ended_by(exc: BaseException) -> tuple[str, str]:
    """Final status and reason of a recording that an exception ended."""
    if isinstance(exc, KeyboardInterrupt):
        return "aborted", "operator abort (Ctrl-C)"
    if isinstance(exc, DeviceError):  # a lost PLC link or sensor stream
        return "aborted", str(exc)
    if isinstance(exc, DiskFull):
        return "fault", str(exc)
    return "fault", f"DAQ error: {type(exc).__name__}: {exc}"  # a recorder or other internal error


def plc_not_ready(status) -> str | None:
    """Why no sweep can start on a PLC in this status (protocol.plc.PLCStatus), in the operator's words
    and with what to do; None when it is idle or done. One wording for the DAQ and the service."""
    state = State(status.state)
    if state in (State.IDLE, State.DONE):
        return None
    if state == State.RUNNING:
        return "the table is moving (a sweep runs); wait for it to end"
    how = ("in emergency stop" if state == State.ESTOP else
           f"in fault ({Fault(status.fault_code).name.lower()})" if state == State.FAULT else state.name.lower())
    return (f"the PLC is {how}; reset it first: `shakeid rig reset --server URL` (through the service), "
            "`shakeid rig reset --config RIG.toml` (the PLC directly), or POST /api/rig/reset")


class SweepRunner:
    """plc, source: device backends; limits: the configured safety limits; sensitivity: counts per
    m/s^2; on_progress(fraction, status) is called about ten times a second; on_samples(first index,
    block (n, channels) in m/s^2) with every block recorded (live views); disk_reserve_mb: free space
    the recording must leave (a sweep that would not fit is refused, one that reaches it is stopped);
    response: the rig's model and limits for the preflight's prediction (predicted_verdict; None: the
    caller predicted already, as the service does at its door)."""

    def __init__(self, plc: PLC, source: AccelerometerSource, limits: Limits, sensitivity: float,
                 channels=DEFAULT_CHANNELS, heartbeat_s: float = 0.05, on_progress=None,
                 rig_config: dict | None = None, on_samples=None, disk_reserve_mb: float = 100.0,
                 heartbeat_plc: PLC | None = None, response: RigResponse | None = None):
        self.plc, self.source, self.limits = plc, source, limits
        self.response = response
        self.prediction: dict | None = None  # the preflight's prediction of the last sweep (with its warnings)
        self.sensitivity, self.channels = sensitivity, tuple(channels)
        self.heartbeat_s, self.on_progress, self.rig_config = heartbeat_s, on_progress, rig_config or {}
        self.on_samples = on_samples
        self.disk_reserve_bytes = int(disk_reserve_mb * 2**20)  # free space kept: refused below, stopped below
        self.recorder: Recorder | None = None  # the recording in progress
        self.abort_requested = threading.Event()
        self.abort_reason = "operator abort"
        self._lock = threading.Lock()
        # the heartbeat's own link (if given) shares no lock with status polls, so a slow poll cannot
        # delay a beat; intervals between beats (s) are kept: the watchdog is chosen from their jitter
        self.heartbeat_plc = heartbeat_plc
        self.heartbeat_intervals: list[float] = []
        self.heartbeat_write_max_s = 0.0
        self.heartbeat_realtime = False  # SCHED_FIFO granted to the heartbeat thread (daq/realtime.py)

    def expected_bytes(self, req: SweepRequest) -> int:
        """Disk space the recording will take: time (f8) + channels (f4) per sample, +10 % for chunks."""
        rows = (req.duration_s + req.settle_s + 2.0) * self.source.fs_hz
        return int(rows * (8 + 4 * len(self.channels)) * 1.1)

    def preflight(self, req: SweepRequest, out_path=None) -> None:
        problem = limit_violation(self.limits, req)
        if problem:
            raise SweepRefused(f"sweep refused: {problem}")
        if self.response is not None:
            verdict = predicted_verdict(self.response, req)
            if verdict.refusal:
                raise SweepRefused(f"sweep refused: {verdict.refusal}")
            self.prediction = verdict.record
        try:
            st = self.plc.status()
        except DeviceError as exc:
            raise SweepRefused(f"sweep refused: {exc}") from None
        problem = plc_not_ready(st)
        if problem:
            raise SweepRefused(f"sweep refused: {problem}")
        if out_path is not None:
            directory = Path(out_path).resolve().parent
            try:
                free = shutil.disk_usage(directory).free
            except OSError as exc:
                raise SweepRefused(f"sweep refused: cannot write recordings to {directory}: {exc}") from None
            need = self.expected_bytes(req) + self.disk_reserve_bytes
            if free < need:
                raise SweepRefused(f"sweep refused: the recording needs about {self.expected_bytes(req) / 2**20:.0f} MB "
                                   f"plus the {self.disk_reserve_bytes / 2**20:.0f} MB disk reserve; "
                                   f"{free / 2**20:.0f} MB free on {directory}")
        end = time.monotonic() + 2.0
        while not self.source.read():
            if time.monotonic() > end:
                raise SweepRefused(f"sweep refused: no accelerometer frames from {self.source.url} within 2 s")

    def run(self, req: SweepRequest, out_path) -> dict:
        self.preflight(req, out_path)
        self.source.reset_stats()
        rec = Recorder(out_path, self.channels, self.source.fs_hz, req.operator,
                       sweep={"f_start_hz": req.f_start_hz, "f_end_hz": req.f_end_hz, "duration_s": req.duration_s,
                              "amplitude_mm": req.amplitude_mm, "settle_s": req.settle_s, "note": req.note},
                       rig_config=self.rig_config,
                       sensors={c: {"sensitivity": self.sensitivity} for c in self.channels},
                       min_free_bytes=self.disk_reserve_bytes)
        self.recorder = rec
        status, reason = "complete", ""
        beat = threading.Thread(target=self._heartbeat, daemon=True)
        self._beating = True
        done_index = None
        try:
            with self._lock:
                self.plc.configure(req.f_start_hz, req.f_end_hz, req.duration_s, req.amplitude_mm)
                self.plc.command(Command.START)
            # where the reader is once START is acknowledged: the sweep cannot end before duration_s of
            # samples after it (a reader without lag is then at or past the sweep's first sample)
            self._drain(rec)
            start_index = rec.next_index
            beat.start()
            last_poll = 0.0
            while True:
                self._pump(rec)
                if time.monotonic() - last_poll >= 0.1:
                    last_poll = time.monotonic()
                    with self._lock:
                        st = self.plc.status()
                    # progress only while it means something: a PLC in estop or fault reports no elapsed
                    # time, and "0" would hide how far the sweep got (an estop at 26 % is not one at 0 %)
                    if self.on_progress and st.state in (State.RUNNING, State.DONE):
                        self.on_progress(min(st.elapsed_s / req.duration_s, 1.0) if st.state == State.RUNNING
                                         else 1.0, st)
                    if st.state == State.ESTOP:  # pressed anywhere: on the rig, in the service, by another client
                        status, reason = "aborted", "emergency stop (the PLC is in estop)"
                        break
                    if st.state == State.FAULT:
                        status, reason = "fault", f"PLC fault: {Fault(st.fault_code).name.lower()}"
                        break
                    if st.state == State.DONE and done_index is None:
                        # the settle counts from where the sweep ended, not from where a lagging reader
                        # happens to be: first read what the link already holds
                        self._drain(rec)
                        done_index = rec.next_index or 0
                        # and the sweep lasted duration_s from where the reader was at START: a reader
                        # that fell behind during the sweep without knowing it (a CAN relay under load
                        # reports no backlog; CI under load saw a 1 + 8 s recording come out 128 samples
                        # short, no frame lost) does not end the settle early. A lag it already had at
                        # START shortens it still: the PLC reports no clock in the sensors' time base.
                        start = start_index if start_index is not None else rec.first_index
                        if start is not None:
                            done_index = max(done_index, start + int(round(req.duration_s * self.source.fs_hz)))
                if done_index is not None and (rec.next_index or 0) - done_index >= req.settle_s * self.source.fs_hz:
                    break
                if self.abort_requested.is_set():
                    status, reason = "aborted", self.abort_reason
                    self._safe_stop()
                    break
        except (Exception, KeyboardInterrupt) as exc:  # every other way out: stop the table, say why
            status, reason = _ended_by(exc)
            self._safe_stop()
        finally:
            self._beating = False
            n_gaps = int(rec.gaps.shape[0])
            try:
                rec.close(status, reason, link_stats=self.source.stats)
            except Exception as exc:  # e.g. a full disk: the file keeps "running" and what its last flush held
                status = "fault"
                reason = ((reason + "; ") if reason else "") + (
                    f"the file could not be finalised ({type(exc).__name__}: {exc}); it holds the samples up to "
                    "its last flush and the next start (or `shakeid recordings --recover`) marks it aborted")
            quality = rec.quality or quality_summary(rec.quality_report())  # the flags, even if close failed
        return {"status": status, "reason": reason, "samples": rec.n, "gaps": n_gaps, "path": str(out_path),
                "quality": quality, **({"preflight": self.prediction} if self.prediction else {}),
                **self.heartbeat_stats(),
                **{f"link_{k}": v for k, v in self.source.stats.items()}}

    def _drain(self, rec: Recorder, limit_s: float = 2.0) -> None:
        """Read what the link already holds (while reads come back full; bounded, since a reader slower
        than the sensors never catches up)."""
        self._pump(rec)
        end = time.monotonic() + limit_s
        while self.source.backlog and time.monotonic() < end:
            self._pump(rec)

    def _pump(self, rec: Recorder) -> None:
        """Read what the source has, record it, feed the live view."""
        for index, counts in self.source.read():
            block = counts / self.sensitivity
            rec.append(index, block)
            if self.on_samples:
                try:
                    self.on_samples(index, block)
                except Exception:  # a broken live view must not end the recording
                    self.on_samples = None

    def abort(self, reason: str = "operator abort") -> None:
        """Ask the running sweep to stop the table and end its recording "aborted" with `reason`."""
        self.abort_reason = reason
        self.abort_requested.set()

    def _safe_stop(self):
        try:
            with self._lock:
                self.plc.command(Command.STOP)
        except DeviceError:
            pass  # the link is gone: the PLC's own watchdog stops the table

    def _heartbeat(self):
        """Beats on a grid of heartbeat_s: each is sent at its time however long the PLC took to answer the
        one before (a sleep of a whole period after each answer made every interval the period plus that
        answer, up to 14 ms under load); a beat already late goes at once and the grid restarts from it."""
        n, last = 0, None
        intervals = self.heartbeat_intervals
        self.heartbeat_realtime = make_realtime(HEARTBEAT_PRIORITY)
        due = time.monotonic()
        while self._beating:
            n += 1
            sent = time.monotonic()
            try:
                if self.heartbeat_plc is not None:
                    self.heartbeat_plc.heartbeat(n)
                else:
                    with self._lock:
                        self.plc.heartbeat(n)
            except DeviceError:
                return
            now = time.monotonic()
            self.heartbeat_write_max_s = max(self.heartbeat_write_max_s, now - sent)  # the PLC's answer time
            if last is not None and len(intervals) < 1_000_000:
                intervals.append(now - last)
            last = now
            due = max(due + self.heartbeat_s, now)
            time.sleep(max(0.0, due - time.monotonic()))

    def heartbeat_stats(self) -> dict:
        """Intervals between heartbeats written to the PLC (s): nominal, p99, largest."""
        gaps = np.asarray(self.heartbeat_intervals)
        if gaps.size == 0:
            return {}
        return {"heartbeat_nominal_s": self.heartbeat_s, "heartbeat_p99_s": round(float(np.quantile(gaps, 0.99)), 4),
                "heartbeat_max_s": round(float(gaps.max()), 4), "heartbeats": int(gaps.size + 1),
                "heartbeat_write_max_s": round(self.heartbeat_write_max_s, 4),
                "heartbeat_realtime": self.heartbeat_realtime}
