"""Modbus TCP front end of the simulated PLC (pymodbus server, its simulator API with an action hook).

It serves the register map of protocol/modbus.py (REGISTER_MAP: every address derives from it); unmapped
addresses answer exception 2.
"""
from __future__ import annotations

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from protocol.modbus import (COMMAND_ADDR, CONTROL, DEVICE_ID, HEARTBEAT_ADDR, LIMITS, REGISTER_MAP, SETPOINTS,
                             STATUS)
from protocol.plc import LIMIT_NAMES, Command

from .plc import RigPLC


def _image(plc: RigPLC) -> dict[int, int]:
    """Register address -> value, as the PLC stands now."""
    limits = {name: getattr(plc.config.limits, name) for name in LIMIT_NAMES}
    return {**SETPOINTS.image(plc.setpoints), **CONTROL.image({"command": 0, "heartbeat": plc.heartbeat}),
            **STATUS.image(plc.status()), **LIMITS.image(limits)}


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
            setpoints = SETPOINTS.decode([new[SETPOINTS.address + i] for i in range(SETPOINTS.count)])
            for name in SETPOINTS.fields_written(address, len(set_values)):
                plc.set_setpoint(name, setpoints[name])
            written = CONTROL.fields_written(address, len(set_values))
            if "heartbeat" in written:
                plc.set_heartbeat(new[HEARTBEAT_ADDR])
            if "command" in written and new[COMMAND_ADDR]:
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

    blocks = [SimData(block.address, count=block.count, datatype=DataType.REGISTERS) for block in REGISTER_MAP]
    return ModbusTcpServer(SimDevice(DEVICE_ID, blocks, action=action), address=(host, port))
