"""The PLC over Modbus TCP (pymodbus client): the register map of protocol/modbus.py."""
from __future__ import annotations

from protocol.modbus import COMMAND_ADDR, DEVICE_ID, HEARTBEAT_ADDR, LIMITS, SETPOINTS, STATUS
from protocol.plc import PLCStatus

from ..devices import PLC, DeviceError, quiet


class ModbusPLC(PLC):
    def __init__(self, host: str, port: int, device_id: int = DEVICE_ID, timeout_s: float = 1.0):
        from pymodbus.client import ModbusTcpClient

        self.client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=1)
        self.device_id = device_id
        # a refused connection is ours to report (DeviceError, once, in words); pymodbus would also log it
        # ("Connection to (host, port) failed: [Errno 111] ...") through Python's last-resort handler
        with quiet("pymodbus"):
            connected = self.client.connect()
        if not connected:
            raise DeviceError(f"PLC at {host}:{port} (Modbus TCP) does not answer")

    @classmethod
    def from_config(cls, section: dict) -> ModbusPLC:
        """[plc] host (default 127.0.0.1), port (default 502, Modbus TCP's)."""
        return cls(section.get("host", "127.0.0.1"), int(section.get("port", 502)))

    def _call(self, fn, *args, **kw):
        try:
            r = fn(*args, device_id=self.device_id, **kw)
        except Exception as exc:  # pymodbus raises ConnectionException & co. on a lost link
            raise DeviceError(f"PLC link lost: {exc}") from None
        if r.isError():
            raise DeviceError(f"PLC answered with an error: {r}")
        return r

    def write_setpoints(self, values):
        self._call(self.client.write_registers, SETPOINTS.address, SETPOINTS.encode(values))

    def command(self, code):
        self._call(self.client.write_register, COMMAND_ADDR, int(code))

    def heartbeat(self, value):
        self._call(self.client.write_register, HEARTBEAT_ADDR, int(value) & 0xFFFF)

    def status(self):
        r = self._call(self.client.read_holding_registers, STATUS.address, count=STATUS.count).registers
        return PLCStatus(**STATUS.decode(r))

    def limits(self):
        return LIMITS.decode(self._call(self.client.read_holding_registers, LIMITS.address, count=LIMITS.count).registers)

    def close(self):
        self.client.close()
