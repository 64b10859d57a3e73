"""ADS front end of the simulated PLC (pyads' AdsTestServer, a real ADS/AMS server).

It serves the symbols of protocol/ads.py (SYMBOLS: the same variables as the Modbus map). Like a real PLC
task, the simulated PLC scans its symbols once per cycle (every physics tick): client writes are applied
at the next cycle, a command is executed once and reset to 0, status symbols are refreshed.

Every symbol is registered up front: pyads' test server kills the connection on an unknown name.
The ADS client always dials TCP 48898, so a second server needs another loopback address (127.0.0.5;
sim.server.free_ads_address draws a free one, as the tests do).
"""
from __future__ import annotations

import struct

from pyads import constants
from pyads.testserver import AdsTestServer, AdvancedHandler, PLCVariable

from protocol.ads import (COMMAND, HEARTBEAT, LIMIT_SYMBOLS, REAL, SETPOINT_SYMBOLS, STATUS_SYMBOLS, UINT, Symbol,
                          default_net_id)
from protocol.plc import Command

from .plc import RigPLC

#: the protocol's types as pyads' test server declares them
ADS_TYPE = {REAL: constants.ADST_REAL32, UINT: constants.ADST_UINT16}


class AdsFrontEnd:
    def __init__(self, plc: RigPLC, ip_address: str):
        self.plc = plc
        self.ip_address = ip_address
        self.net_id = default_net_id(ip_address)
        self.handler = AdvancedHandler()
        for s in SETPOINT_SYMBOLS:
            self._add(s, plc.setpoints[s.field])
        self._add(COMMAND, 0)
        self._add(HEARTBEAT, 0)
        for s in STATUS_SYMBOLS:
            self._add(s, 0)
        for s in LIMIT_SYMBOLS:
            self._add(s, getattr(plc.config.limits, s.field))
        self.seen = {s.name: self._raw(s) for s in (*SETPOINT_SYMBOLS, HEARTBEAT)}
        self.server = AdsTestServer(handler=self.handler, ip_address=ip_address, logging=False)

    def _add(self, symbol: Symbol, value) -> None:
        self.handler.add_variable(PLCVariable(symbol.name, value, ADS_TYPE[symbol.type], symbol.type))

    def _raw(self, symbol: Symbol) -> bytes:
        return self.handler.get_variable_by_name(symbol.name).value

    def _get(self, symbol: Symbol):
        return struct.unpack(symbol.struct_format, self._raw(symbol))[0]

    def _set(self, symbol: Symbol, value) -> None:
        self.handler.get_variable_by_name(symbol.name).value = struct.pack(symbol.struct_format, value)

    def start(self) -> None:
        self.server.start()

    def stop(self) -> None:
        self.server.stop()
        self.server.join(5)

    def cycle(self) -> None:
        """One PLC scan: apply what clients changed, execute a command, refresh the status symbols."""
        for s in SETPOINT_SYMBOLS:
            raw = self._raw(s)
            if raw != self.seen[s.name]:
                self.seen[s.name] = raw
                self.plc.set_setpoint(s.field, self._get(s))
            else:  # keep in step with writes from the other front end
                self._set(s, self.plc.setpoints[s.field])
                self.seen[s.name] = self._raw(s)
        hb = self._raw(HEARTBEAT)
        if hb != self.seen[HEARTBEAT.name]:
            self.seen[HEARTBEAT.name] = hb
            self.plc.set_heartbeat(self._get(HEARTBEAT))
        cmd = self._get(COMMAND)
        if cmd:
            self._set(COMMAND, 0)
            if cmd in Command._value2member_map_:
                self.plc.command(Command(cmd))
        st = self.plc.status()
        for s in STATUS_SYMBOLS:
            self._set(s, st[s.field])
