"""The simulated rig's servers and the ports they are given: one taken by another process is an error."""
import socket

import pytest

from sim.plc import PLCConfig
from sim.server import SimulatedRig


@pytest.mark.parametrize("taken", ["modbus", "stream"])
def test_a_port_already_taken_is_an_error_not_a_rig_that_claims_it(taken):
    """Another process listening on the PLC's or the stream's port: start() fails naming the server and the
    port (pymodbus only logged its bind failure from a task nobody awaited, and the rig said it served
    Modbus on a port something else answered on); the other port is left free for a second try."""
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen()
    port = holder.getsockname()[1]
    other = SimulatedRig(PLCConfig(), speed=1.0)  # a free port for the server not under test
    ports = dict(modbus_port=port, stream_port=other.stream_port) if taken == "modbus" else \
        dict(modbus_port=other.modbus_port, stream_port=port)
    rig = SimulatedRig(PLCConfig(), speed=1.0, **ports)
    try:
        name = "the PLC's Modbus TCP server" if taken == "modbus" else "the accelerometer stream"
        with pytest.raises(RuntimeError, match=f"did not start: {name} cannot listen on 127.0.0.1:{port}"):
            rig.start()
        free = ports["stream_port" if taken == "modbus" else "modbus_port"]
        probe = socket.socket()
        probe.bind(("127.0.0.1", free))  # released: nothing of the failed rig holds it
        probe.close()
    finally:
        rig.stop()
        holder.close()
