"""The PLC over ADS (pyads, Beckhoff TwinCAT): the symbols of protocol/ads.py."""
from __future__ import annotations

from protocol.ads import (AMS_PORT, COMMAND, HEARTBEAT, LIMIT_SYMBOLS, REAL, SETPOINT_SYMBOLS, STATUS_SYMBOLS, UINT,
                          Symbol, default_net_id)
from protocol.plc import PLCStatus

from ..devices import PLC, DeviceError


class AdsPLC(PLC):
    def __init__(self, ams_net_id: str, ip: str, ams_port: int = AMS_PORT, timeout_ms: int = 1000):
        import pyads

        self.plc_type = {REAL: pyads.PLCTYPE_REAL, UINT: pyads.PLCTYPE_UINT}
        self.conn = pyads.Connection(ams_net_id, ams_port, ip)
        try:
            self.conn.open()
            self.conn.set_timeout(timeout_ms)
            self._read(STATUS_SYMBOLS[0])
        except Exception as exc:
            raise DeviceError(f"PLC {ams_net_id} at {ip} (ADS) does not answer: {exc}") from None

    @classmethod
    def from_config(cls, section: dict) -> AdsPLC:
        """[plc] host (default 127.0.0.1), ams_net_id (default host + .1.1), ams_port (default AMS_PORT)."""
        host = section.get("host", "127.0.0.1")
        return cls(section.get("ams_net_id", default_net_id(host)), host, int(section.get("ams_port", AMS_PORT)))

    def _read(self, symbol: Symbol):
        return self.conn.read_by_name(symbol.name, self.plc_type[symbol.type])

    def _write(self, symbol: Symbol, value) -> None:
        self.conn.write_by_name(symbol.name, value, self.plc_type[symbol.type])

    def _rw(self, fn, *args):
        try:
            return fn(*args)
        except Exception as exc:
            raise DeviceError(f"PLC link lost: {exc}") from None

    def write_setpoints(self, values):
        for s in SETPOINT_SYMBOLS:
            self._rw(self._write, s, float(values[s.field]))

    def command(self, code):
        self._rw(self._write, COMMAND, int(code))

    def heartbeat(self, value):
        self._rw(self._write, HEARTBEAT, int(value) & 0xFFFF)

    def status(self):
        return PLCStatus(**{s.field: self._rw(self._read, s) for s in STATUS_SYMBOLS})

    def limits(self):
        return {s.field: self._rw(self._read, s) for s in LIMIT_SYMBOLS}

    def close(self):
        self.conn.close()
