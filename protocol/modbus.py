"""The PLC's Modbus TCP register map (holding registers, device id DEVICE_ID): one table, REGISTER_MAP, from
which the simulated PLC's server (sim/modbus.py) and the DAQ's client (daq/plc/modbus.py) derive every address.

float32 values use two registers, big-endian word order (pymodbus' `convert_to_registers(..., FLOAT32)`
default); u16 values one. Unmapped addresses answer exception 2.

    block      addr  fields                                                    access
    SETPOINTS  0     f_start_hz, f_end_hz, duration_s, amplitude_mm (f32)      rw
    CONTROL    10    command (u16: 1 start, 2 stop, 3 reset, 4 estop; reads 0)  w
                     heartbeat (u16: changed at least every watchdog_s)         rw
    STATUS     20    state, fault_code (u16), elapsed_s, frequency_hz,          r
                     position_mm (f32)
    LIMITS     30    the fields of Limits, in order (f32)                       r
"""
from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

from .plc import LIMIT_NAMES, SETPOINT_NAMES, PLCStatus

DEVICE_ID = 1
F32, U16 = "f32", "u16"
_SIZE = {F32: 2, U16: 1}


def f32_to_regs(x: float) -> list[int]:
    """A float32 as two registers, high word first."""
    return list(struct.unpack(">HH", struct.pack(">f", x)))


def regs_to_f32(hi: int, lo: int) -> float:
    return struct.unpack(">f", struct.pack(">HH", hi, lo))[0]


@dataclass(frozen=True)
class Block:
    """Consecutive holding registers from `address`: named fields of type F32 (two registers) or U16 (one)."""

    address: int
    fields: tuple[tuple[str, str], ...]

    @property
    def count(self) -> int:
        """Registers the block spans."""
        return sum(_SIZE[kind] for _, kind in self.fields)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.fields)

    def address_of(self, name: str) -> int:
        a = self.address
        for field, kind in self.fields:
            if field == name:
                return a
            a += _SIZE[kind]
        raise KeyError(name)

    def encode(self, values: Mapping[str, float]) -> list[int]:
        """The block's registers holding `values` (every field named)."""
        regs: list[int] = []
        for name, kind in self.fields:
            regs += f32_to_regs(float(values[name])) if kind == F32 else [int(values[name]) & 0xFFFF]
        return regs

    def decode(self, registers: Sequence[int]) -> dict[str, float]:
        """{field: value} of the block's `count` registers (u16 as int, f32 as float)."""
        out, i = {}, 0
        for name, kind in self.fields:
            out[name] = regs_to_f32(registers[i], registers[i + 1]) if kind == F32 else int(registers[i])
            i += _SIZE[kind]
        return out

    def image(self, values: Mapping[str, float]) -> dict[int, int]:
        """{address: register} of the block holding `values`."""
        return {self.address + i: r for i, r in enumerate(self.encode(values))}

    def fields_written(self, first: int, count: int) -> list[str]:
        """The fields a write of `count` registers from address `first` touches."""
        return [name for name, kind in self.fields
                if first < self.address_of(name) + _SIZE[kind] and self.address_of(name) < first + count]


_WIRE_TYPE = {"int": U16, "float": F32}  # PLCStatus' field types on the wire

SETPOINTS = Block(0, tuple((name, F32) for name in SETPOINT_NAMES))
CONTROL = Block(10, (("command", U16), ("heartbeat", U16)))
STATUS = Block(20, tuple((f.name, _WIRE_TYPE[f.type]) for f in fields(PLCStatus)))
LIMITS = Block(30, tuple((name, F32) for name in LIMIT_NAMES))
#: The whole map: every block the PLC serves.
REGISTER_MAP = (SETPOINTS, CONTROL, STATUS, LIMITS)
COMMAND_ADDR = CONTROL.address_of("command")
HEARTBEAT_ADDR = CONTROL.address_of("heartbeat")
