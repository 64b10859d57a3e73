"""The PLC's ADS symbols (TwinCAT variables on AMS port AMS_PORT): one table, SYMBOLS, that the simulated
PLC's ADS server (sim/ads.py) registers and the DAQ's client (daq/plc/ads.py) reads and writes.

    symbol                 type  access  field
    MAIN.fStartFreq        REAL  rw      f_start_hz
    MAIN.fEndFreq          REAL  rw      f_end_hz
    MAIN.fDuration         REAL  rw      duration_s
    MAIN.fAmplitude        REAL  rw      amplitude_mm
    MAIN.nCommand          UINT  w       1 start, 2 stop, 3 reset, 4 emergency stop (reset to 0 once executed)
    MAIN.nHeartbeat        UINT  rw      changed by the client at least every watchdog period
    MAIN.nState            UINT  r       State
    MAIN.nFaultCode        UINT  r       Fault
    MAIN.fElapsed          REAL  r       sweep time, s
    MAIN.fFrequency        REAL  r       current sweep frequency, Hz
    MAIN.fPosition         REAL  r       table position, mm
    MAIN.fMaxStroke ...    REAL  r       the fields of Limits: fMaxStroke (mm), fMaxVelocity (m/s),
                                         fMaxAcceleration (m/s^2), fMinFreq, fMaxFreq (Hz), fMaxDuration, fWatchdog (s)
"""
from __future__ import annotations

from dataclasses import dataclass

from .plc import LIMIT_NAMES, SETPOINT_NAMES, STATUS_NAMES

AMS_PORT = 851
REAL, UINT = "REAL", "UINT"
#: struct format of each type's value (little-endian, as ADS carries it)
STRUCT_FORMAT = {REAL: "<f", UINT: "<H"}


def default_net_id(ip: str) -> str:
    """The AMS net id of a PLC at `ip` when the configuration names none (TwinCAT's default: ip + .1.1)."""
    return f"{ip}.1.1"


@dataclass(frozen=True)
class Symbol:
    name: str   # the PLC variable
    field: str  # the protocol's name for it (SETPOINT_NAMES, STATUS_NAMES, LIMIT_NAMES, command, heartbeat)
    type: str   # REAL or UINT

    @property
    def struct_format(self) -> str:
        return STRUCT_FORMAT[self.type]


SETPOINT_SYMBOLS = tuple(Symbol(s, f, REAL) for s, f in zip(
    ("MAIN.fStartFreq", "MAIN.fEndFreq", "MAIN.fDuration", "MAIN.fAmplitude"), SETPOINT_NAMES, strict=True))
COMMAND = Symbol("MAIN.nCommand", "command", UINT)
HEARTBEAT = Symbol("MAIN.nHeartbeat", "heartbeat", UINT)
STATUS_SYMBOLS = tuple(Symbol(s, f, t) for (s, t), f in zip(
    (("MAIN.nState", UINT), ("MAIN.nFaultCode", UINT), ("MAIN.fElapsed", REAL), ("MAIN.fFrequency", REAL),
     ("MAIN.fPosition", REAL)), STATUS_NAMES, strict=True))
LIMIT_SYMBOLS = tuple(Symbol(s, f, REAL) for s, f in zip(
    ("MAIN.fMaxStroke", "MAIN.fMaxVelocity", "MAIN.fMaxAcceleration", "MAIN.fMinFreq", "MAIN.fMaxFreq",
     "MAIN.fMaxDuration", "MAIN.fWatchdog"), LIMIT_NAMES, strict=True))
#: Every symbol the PLC has (a client may touch only these: pyads' test server drops the link on another name).
SYMBOLS = (*SETPOINT_SYMBOLS, COMMAND, HEARTBEAT, *STATUS_SYMBOLS, *LIMIT_SYMBOLS)
