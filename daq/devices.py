"""Device interfaces of the DAQ: one small interface per kind, real protocol backends behind it.

PLC (configure sweep, start, stop, emergency stop, status, heartbeat, limits): the interface here, the
backends in daq/plc/ (one module per transport, registered in daq.plc.BACKENDS; `daq.plc.open_plc` opens
the one a rig configuration names). They speak the rig protocol of protocol/ (docs/rig-protocols.md),
which the simulated rig serves too. The accelerometer sources are in daq/sources.py.
"""
from __future__ import annotations

import contextlib
import logging

from identify.errors import ShakeidError
from protocol.plc import SETPOINT_NAMES, PLCStatus


class DeviceError(ShakeidError):
    """A device did not answer or answered with an error."""


class PLC:
    """Interface: what a sweep needs from the table's controller. A backend writes the setpoints
    (`write_setpoints`) and has `from_config(section)`, which opens it from a rig configuration's [plc] section."""

    @classmethod
    def from_config(cls, section: dict) -> PLC: ...
    def write_setpoints(self, values: dict[str, float]) -> None: ...

    def configure(self, f_start_hz: float, f_end_hz: float, duration_s: float, amplitude_mm: float) -> None:
        """Write a sweep's setpoints, by their protocol names (protocol.plc.SETPOINT_NAMES)."""
        self.write_setpoints(dict(zip(SETPOINT_NAMES, (f_start_hz, f_end_hz, duration_s, amplitude_mm), strict=True)))

    def command(self, code: int) -> None: ...
    def heartbeat(self, value: int) -> None: ...
    def status(self) -> PLCStatus: ...
    def limits(self) -> dict: ...
    def close(self) -> None: ...


@contextlib.contextmanager
def quiet(logger: str):
    """Silence a library's logger below CRITICAL for the duration (its level restored after)."""
    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)
