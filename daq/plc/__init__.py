"""The DAQ's PLC backends, one module per transport, and the registry a rig configuration picks from.

A new PLC (another transport or gateway) is one module here with a `PLC` subclass (daq/devices.py: the
interface, and `from_config(section)`) and one line in BACKENDS.
"""
from __future__ import annotations

from protocol import PLC_TRANSPORTS

from ..devices import PLC, DeviceError
from .ads import AdsPLC
from .modbus import ModbusPLC

#: [plc] transport of a rig configuration -> the backend that speaks it (one per protocol.PLC_TRANSPORTS)
BACKENDS: dict[str, type[PLC]] = {
    "modbus": ModbusPLC,
    "ads": AdsPLC,
}


def open_plc(section: dict) -> PLC:
    """The PLC backend a rig configuration's [plc] section names (`transport`, default "modbus"), connected."""
    transport = section.get("transport", PLC_TRANSPORTS[0])
    if transport not in BACKENDS:
        raise DeviceError(f"[plc] transport {transport!r} is not one the DAQ speaks: {', '.join(BACKENDS)}")
    return BACKENDS[transport].from_config(section)
