"""Modbus TCP front end of the simulated PLC (pymodbus server, its simulator API with an action hook).

Holding registers (device id 1). float32 values use two registers, big-endian word order (pymodbus'
`convert_to_registers(..., DATATYPE.FLOAT32)` default); unmapped addresses answer exception 2.

    addr  type  access  name
    0     f32   rw      f_start_hz
    2     f32   rw      f_end_hz
    4     f32   rw      duration_s
    6     f32   rw      amplitude_mm
    10    u16   w       command: 1 start, 2 stop, 3 reset, 4 emergency stop (reads back 0)
    11    u16   rw      heartbeat: the client changes it at least every watchdog_s during a sweep
    20    u16   r       state: 0 idle, 1 running, 2 done, 3 fault, 4 estop
    21    u16   r       fault code (sim.plc.Fault): 1 stroke, 2 velocity, 3 acceleration, 4 frequency,
                        5 duration, 6 watchdog, 7 drive fault, 8 not ready
    22    f32   r       elapsed_s (sweep time)
    24    f32   r       frequency_hz (current sweep frequency)
    26    f32   r       position_mm (table position)
    30    f32   r       limits: max_stroke_mm, max_velocity_ms, max_acceleration_ms2, f_min_hz,
                        f_max_hz, max_duration_s, watchdog_s (30, 32, ..., 42)
"""
from __future__ import annotations

import struct

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from .plc import Command, RigPLC

DEVICE_ID = 1
SETPOINT_ADDR = {"f_start_hz": 0, "f_end_hz": 2, "duration_s": 4, "amplitude_mm": 6}
COMMAND_ADDR, HEARTBEAT_ADDR = 10, 11
STATUS_ADDR = 20
LIMITS_ADDR = 30
LIMIT_NAMES = ("max_stroke_mm", "max_velocity_ms", "max_acceleration_ms2", "f_min_hz", "f_max_hz",
               "max_duration_s", "watchdog_s")


def f32_to_regs(x: float) -> list[int]:
    hi, lo = struct.unpack(">HH", struct.pack(">f", x))
    return [hi, lo]


def regs_to_f32(hi: int, lo: int) -> float:
    return struct.unpack(">f", struct.pack(">HH", hi, lo))[0]


def _image(plc: RigPLC) -> dict[int, int]:
    """Register address -> value, as the PLC stands now."""
    regs: dict[int, int] = {COMMAND_ADDR: 0, HEARTBEAT_ADDR: plc.heartbeat & 0xFFFF}
    for name, a in SETPOINT_ADDR.items():
        regs[a], regs[a + 1] = f32_to_regs(plc.setpoints[name])
    st = plc.status()
    regs[STATUS_ADDR], regs[STATUS_ADDR + 1] = st["state"], st["fault_code"]
    for k, name in enumerate(("elapsed_s", "frequency_hz", "position_mm")):
        regs[22 + 2 * k], regs[23 + 2 * k] = f32_to_regs(st[name])
    for k, name in enumerate(LIMIT_NAMES):
        regs[LIMITS_ADDR + 2 * k], regs[LIMITS_ADDR + 2 * k + 1] = f32_to_regs(getattr(plc.config.limits, name))
    return regs


def make_server(plc: RigPLC, host: str, port: int, on_access=None) -> ModbusTcpServer:
    """A Modbus TCP server for `plc` (build it inside the running event loop). `on_access` sees every
    request first; returning True drops it (fault injection: a cut PLC link)."""

    async def action(fc, start, address, count, current, set_values):
        if on_access is not None and on_access(fc, address, count):
            return ExcCodes.DEVICE_BUSY
        if set_values is not None:  # a write: apply it to the PLC (the registers update from the image)
            new = dict(_image(plc))
            for i, v in enumerate(set_values):
                new[address + i] = int(v)
            for name, a in SETPOINT_ADDR.items():
                if address <= a + 1 and a < address + len(set_values):
                    plc.set_setpoint(name, regs_to_f32(new[a], new[a + 1]))
            if address <= HEARTBEAT_ADDR < address + len(set_values):
                plc.set_heartbeat(new[HEARTBEAT_ADDR])
            if address <= COMMAND_ADDR < address + len(set_values) and new[COMMAND_ADDR]:
                try:
                    plc.command(Command(new[COMMAND_ADDR]))
                except ValueError:
                    return ExcCodes.ILLEGAL_VALUE
            set_values[:] = [_image(plc).get(address + i, 0) for i in range(len(set_values))]
            return None
        image = _image(plc)
        for i in range(len(current)):
            if start + i in image:
                current[i] = image[start + i]
        return None

    blocks = [SimData(0, count=8, datatype=DataType.REGISTERS), SimData(10, count=2, datatype=DataType.REGISTERS),
              SimData(20, count=8, datatype=DataType.REGISTERS),
              SimData(30, count=2 * len(LIMIT_NAMES), datatype=DataType.REGISTERS)]
    return ModbusTcpServer(SimDevice(DEVICE_ID, blocks, action=action), address=(host, port))
