"""ADS front end of the simulated PLC (pyads' AdsTestServer, a real ADS/AMS server).

The same variables as the Modbus map, as PLC symbols. Like a real PLC task, the simulated PLC scans its
symbols once per cycle (every physics tick): client writes are applied at the next cycle, a command is
executed once and reset to 0, status symbols are refreshed.

    symbol                 type  access  meaning
    MAIN.fStartFreq        REAL  rw      f_start_hz
    MAIN.fEndFreq          REAL  rw      f_end_hz
    MAIN.fDuration         REAL  rw      duration_s
    MAIN.fAmplitude        REAL  rw      amplitude_mm
    MAIN.nCommand          UINT  w       1 start, 2 stop, 3 reset, 4 emergency stop (reset to 0)
    MAIN.nHeartbeat        UINT  rw      changed by the client at least every watchdog period
    MAIN.nState            UINT  r       0 idle, 1 running, 2 done, 3 fault, 4 estop
    MAIN.nFaultCode        UINT  r       sim.plc.Fault
    MAIN.fElapsed          REAL  r       sweep time, s
    MAIN.fFrequency        REAL  r       current sweep frequency, Hz
    MAIN.fPosition         REAL  r       table position, mm
    MAIN.fMaxStroke ...    REAL  r       limits: fMaxStroke (mm), fMaxVelocity (m/s), fMaxAcceleration
                                         (m/s^2), fMinFreq, fMaxFreq (Hz), fMaxDuration, fWatchdog (s)

Every symbol is registered up front: pyads' test server kills the connection on an unknown name.
The ADS client always dials TCP 48898, so a second server needs another loopback address (127.0.0.5;
sim.server.free_ads_address draws a free one, as the tests do).
"""
from __future__ import annotations

import struct

from pyads import constants
from pyads.testserver import AdsTestServer, AdvancedHandler, PLCVariable

from .plc import Command, RigPLC

REAL, UINT = (constants.ADST_REAL32, "REAL", "<f"), (constants.ADST_UINT16, "UINT", "<H")
SETPOINTS = {"MAIN.fStartFreq": "f_start_hz", "MAIN.fEndFreq": "f_end_hz", "MAIN.fDuration": "duration_s",
             "MAIN.fAmplitude": "amplitude_mm"}
STATUS = {"MAIN.nState": ("state", UINT), "MAIN.nFaultCode": ("fault_code", UINT),
          "MAIN.fElapsed": ("elapsed_s", REAL), "MAIN.fFrequency": ("frequency_hz", REAL),
          "MAIN.fPosition": ("position_mm", REAL)}
LIMITS = {"MAIN.fMaxStroke": "max_stroke_mm", "MAIN.fMaxVelocity": "max_velocity_ms",
          "MAIN.fMaxAcceleration": "max_acceleration_ms2", "MAIN.fMinFreq": "f_min_hz", "MAIN.fMaxFreq": "f_max_hz",
          "MAIN.fMaxDuration": "max_duration_s", "MAIN.fWatchdog": "watchdog_s"}
AMS_PORT = 851


class AdsFrontEnd:
    def __init__(self, plc: RigPLC, ip_address: str):
        self.plc = plc
        self.ip_address = ip_address
        self.net_id = f"{ip_address}.1.1"
        self.handler = AdvancedHandler()
        self.kinds = {}
        for name, key in SETPOINTS.items():
            self._add(name, plc.setpoints[key], REAL)
        self._add("MAIN.nCommand", 0, UINT)
        self._add("MAIN.nHeartbeat", 0, UINT)
        for name, (_, kind) in STATUS.items():
            self._add(name, 0, kind)
        for name, key in LIMITS.items():
            self._add(name, getattr(plc.config.limits, key), REAL)
        self.seen = {n: self.handler.get_variable_by_name(n).value for n in (*SETPOINTS, "MAIN.nHeartbeat")}
        self.server = AdsTestServer(handler=self.handler, ip_address=ip_address, logging=False)

    def _add(self, name, value, kind):
        ads_type, symbol_type, fmt = kind
        self.kinds[name] = fmt
        self.handler.add_variable(PLCVariable(name, value, ads_type, symbol_type))

    def _get(self, name):
        return struct.unpack(self.kinds[name], self.handler.get_variable_by_name(name).value)[0]

    def _set(self, name, value):
        self.handler.get_variable_by_name(name).value = struct.pack(self.kinds[name], value)

    def start(self) -> None:
        self.server.start()

    def stop(self) -> None:
        self.server.stop()
        self.server.join(5)

    def cycle(self) -> None:
        """One PLC scan: apply what clients changed, execute a command, refresh the status symbols."""
        for name, key in SETPOINTS.items():
            raw = self.handler.get_variable_by_name(name).value
            if raw != self.seen[name]:
                self.seen[name] = raw
                self.plc.set_setpoint(key, self._get(name))
            else:  # keep in step with writes from the other front end
                self._set(name, self.plc.setpoints[key])
                self.seen[name] = self.handler.get_variable_by_name(name).value
        hb = self.handler.get_variable_by_name("MAIN.nHeartbeat").value
        if hb != self.seen["MAIN.nHeartbeat"]:
            self.seen["MAIN.nHeartbeat"] = hb
            self.plc.set_heartbeat(self._get("MAIN.nHeartbeat"))
        cmd = self._get("MAIN.nCommand")
        if cmd:
            self._set("MAIN.nCommand", 0)
            if cmd in Command._value2member_map_:
                self.plc.command(Command(cmd))
        st = self.plc.status()
        for name, (key, _) in STATUS.items():
            self._set(name, st[key])
