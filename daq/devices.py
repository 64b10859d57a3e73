"""Device interfaces of the DAQ: one small interface per kind, real protocol backends behind it.

PLC (configure sweep, start, stop, emergency stop, status, heartbeat, limits): ModbusPLC (pymodbus
client) and AdsPLC (pyads), both for the register map / symbols of docs/rig-protocols.md, which the
simulated rig serves too. Accelerometers: SerialSource (any pyserial URL: a device path or socket://)
decoding the documented frames. A sensor with another format is one more small class with `read()`.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from identify.errors import ShakeidError
from sim.frames import FrameDecoder


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


class ModbusPLC(PLC):
    def __init__(self, host: str, port: int, device_id: int = 1, timeout_s: float = 1.0):
        from pymodbus.client import ModbusTcpClient

        self.client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=1)
        self.device_id = device_id
        if not self.client.connect():
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


class SerialSource:
    """Accelerometer frames from any pyserial URL. read() -> list of (first sample index, counts (n, c))
    for the frames received since the last call; lost frames show as jumps of the sample index."""

    def __init__(self, url: str, fs_hz: float, timeout_s: float = 0.05):
        import serial

        self.serial_mod = serial
        try:
            self.port = serial.serial_for_url(url, timeout=timeout_s)
        except (serial.SerialException, ValueError) as exc:
            raise DeviceError(f"accelerometers at {url}: {exc}") from None
        self.fs_hz = fs_hz
        self.decoder = FrameDecoder()
        self.url = url

    def read(self) -> list[tuple[int, np.ndarray]]:
        try:
            data = self.port.read(65536)
        except self.serial_mod.SerialException as exc:
            raise DeviceError(f"accelerometer stream {self.url} lost: {exc}") from None
        return [(int(round(f.timestamp_us * self.fs_hz / 1e6)), f.counts) for f in self.decoder.feed(data)]

    def close(self):
        self.port.close()
