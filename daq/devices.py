"""Device interfaces of the DAQ: one small interface per kind, real protocol backends behind it.

PLC (configure sweep, start, stop, emergency stop, status, heartbeat, limits): ModbusPLC (pymodbus
client) and AdsPLC (pyads), both for the register map / symbols of docs/rig-protocols.md, which the
simulated rig serves too. The accelerometer sources are in daq/sources.py.
"""
from __future__ import annotations

import contextlib
import logging
import struct
from dataclasses import dataclass

from identify.errors import ShakeidError


class DeviceError(ShakeidError):
    """A device did not answer or answered with an error."""


@dataclass
class PLCStatus:
    state: int
    fault_code: int
    elapsed_s: float
    frequency_hz: float
    position_mm: float


class PLC:
    """Interface: what a sweep needs from the table's controller."""

    def configure(self, f_start_hz: float, f_end_hz: float, duration_s: float, amplitude_mm: float) -> None: ...
    def command(self, code: int) -> None: ...
    def heartbeat(self, value: int) -> None: ...
    def status(self) -> PLCStatus: ...
    def limits(self) -> dict: ...
    def close(self) -> None: ...


LIMIT_NAMES = ("max_stroke_mm", "max_velocity_ms", "max_acceleration_ms2", "f_min_hz", "f_max_hz",
               "max_duration_s", "watchdog_s")


@contextlib.contextmanager
def _quiet(logger: str):
    """Silence a library's logger below CRITICAL for the duration (its level restored after)."""
    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)


class ModbusPLC(PLC):
    def __init__(self, host: str, port: int, device_id: int = 1, timeout_s: float = 1.0):
        from pymodbus.client import ModbusTcpClient

        self.client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=1)
        self.device_id = device_id
        # a refused connection is ours to report (DeviceError, once, in words); pymodbus would also log it
        # ("Connection to (host, port) failed: [Errno 111] ...") through Python's last-resort handler
        with _quiet("pymodbus"):
            connected = self.client.connect()
        if not connected:
            raise DeviceError(f"PLC at {host}:{port} (Modbus TCP) does not answer")

    def _call(self, fn, *args, **kw):
        try:
            r = fn(*args, device_id=self.device_id, **kw)
        except Exception as exc:  # pymodbus raises ConnectionException & co. on a lost link
            raise DeviceError(f"PLC link lost: {exc}") from None
        if r.isError():
            raise DeviceError(f"PLC answered with an error: {r}")
        return r

    def _f32(self, value: float) -> list[int]:
        return list(struct.unpack(">HH", struct.pack(">f", value)))

    def configure(self, f_start_hz, f_end_hz, duration_s, amplitude_mm):
        regs = sum((self._f32(v) for v in (f_start_hz, f_end_hz, duration_s, amplitude_mm)), [])
        self._call(self.client.write_registers, 0, regs)

    def command(self, code):
        self._call(self.client.write_register, 10, int(code))

    def heartbeat(self, value):
        self._call(self.client.write_register, 11, int(value) & 0xFFFF)

    def status(self):
        r = self._call(self.client.read_holding_registers, 20, count=8).registers
        f = [struct.unpack(">f", struct.pack(">HH", r[i], r[i + 1]))[0] for i in (2, 4, 6)]
        return PLCStatus(r[0], r[1], *f)

    def limits(self):
        r = self._call(self.client.read_holding_registers, 30, count=14).registers
        return {n: struct.unpack(">f", struct.pack(">HH", r[2 * k], r[2 * k + 1]))[0] for k, n in enumerate(LIMIT_NAMES)}

    def close(self):
        self.client.close()


class AdsPLC(PLC):
    SYMBOLS = ("MAIN.fMaxStroke", "MAIN.fMaxVelocity", "MAIN.fMaxAcceleration", "MAIN.fMinFreq", "MAIN.fMaxFreq",
               "MAIN.fMaxDuration", "MAIN.fWatchdog")

    def __init__(self, ams_net_id: str, ip: str, ams_port: int = 851, timeout_ms: int = 1000):
        import pyads

        self.pyads = pyads
        self.conn = pyads.Connection(ams_net_id, ams_port, ip)
        try:
            self.conn.open()
            self.conn.set_timeout(timeout_ms)
            self.conn.read_by_name("MAIN.nState", pyads.PLCTYPE_UINT)
        except Exception as exc:
            raise DeviceError(f"PLC {ams_net_id} at {ip} (ADS) does not answer: {exc}") from None

    def _rw(self, fn, *args):
        try:
            return fn(*args)
        except Exception as exc:
            raise DeviceError(f"PLC link lost: {exc}") from None

    def configure(self, f_start_hz, f_end_hz, duration_s, amplitude_mm):
        for name, v in zip(("MAIN.fStartFreq", "MAIN.fEndFreq", "MAIN.fDuration", "MAIN.fAmplitude"),
                           (f_start_hz, f_end_hz, duration_s, amplitude_mm)):
            self._rw(self.conn.write_by_name, name, float(v), self.pyads.PLCTYPE_REAL)

    def command(self, code):
        self._rw(self.conn.write_by_name, "MAIN.nCommand", int(code), self.pyads.PLCTYPE_UINT)

    def heartbeat(self, value):
        self._rw(self.conn.write_by_name, "MAIN.nHeartbeat", int(value) & 0xFFFF, self.pyads.PLCTYPE_UINT)

    def status(self):
        R, U = self.pyads.PLCTYPE_REAL, self.pyads.PLCTYPE_UINT
        get = lambda n, t: self._rw(self.conn.read_by_name, n, t)  # noqa: E731
        return PLCStatus(get("MAIN.nState", U), get("MAIN.nFaultCode", U), get("MAIN.fElapsed", R),
                         get("MAIN.fFrequency", R), get("MAIN.fPosition", R))

    def limits(self):
        return {n: self._rw(self.conn.read_by_name, s, self.pyads.PLCTYPE_REAL)
                for n, s in zip(LIMIT_NAMES, self.SYMBOLS)}

    def close(self):
        self.conn.close()


def open_plc(plc: dict) -> PLC:
    """The PLC backend a rig configuration's [plc] section names (transport "modbus" or "ads")."""
    if plc.get("transport", "modbus") == "ads":
        host = plc.get("host", "127.0.0.1")
        return AdsPLC(plc.get("ams_net_id", f"{host}.1.1"), host, int(plc.get("ams_port", 851)))
    return ModbusPLC(plc.get("host", "127.0.0.1"), int(plc.get("port", 502)))
