"""The simulated PLC's clock when its own process stalls: a stall is not a silent client.

The rig runs in rig time (speed x wall time) and its watchdog counts rig time. When the simulator's loop
(or its whole process, heartbeat thread and all) is not scheduled for a while, the first tick after
it must not simulate the whole stall at once: the next one would find the heartbeat silent for that
long, though the client's beat was only late with the simulator. A real PLC's scan does not stall that
way, so the fault would be an artefact of the simulation. With the demo's 2 s rig-time watchdog at 10x,
a 0.2 s wall-clock stall would be enough. Such a stall is the suspected, unproven cause of one CI failure
of the streamed-sweep test in tests/sim/test_rig_server.py.
"""
import pytest
import threading
import time

from pymodbus.client import ModbusTcpClient

from protocol.plc import Fault, Limits, State
from sim.plc import PLCConfig
from sim.server import SimulatedRig

SPEED = 10.0


class BeatingClient:
    """A Modbus TCP client of the simulated PLC with a heartbeat thread (20 ms) that the test can hold."""

    def __init__(self, rig):
        host, port = rig.endpoints["modbus"]
        self.mb = ModbusTcpClient(host, port=port, timeout=2)
        assert self.mb.connect()
        self.lock = threading.Lock()  # held by the test: the beat waits, as a stalled process's would
        self.beating = True
        self.F = self.mb.DATATYPE.FLOAT32

    def write(self, addr, value):
        with self.lock:
            self.mb.write_register(addr, value, device_id=1)

    def state(self):
        with self.lock:
            r = self.mb.read_holding_registers(20, count=2, device_id=1).registers
        return r[0], r[1]

    def start_sweep(self, f0, f1, duration_s, amplitude_mm):
        """Set the sweep, start beating and START; return once the PLC reports RUNNING."""
        with self.lock:
            for addr, v in ((0, f0), (2, f1), (4, duration_s), (6, amplitude_mm)):
                self.mb.write_registers(addr, self.mb.convert_to_registers([v], self.F), device_id=1)
        self.thread = threading.Thread(target=self._beat, daemon=True)
        self.thread.start()
        self.write(10, 1)
        deadline = time.time() + 10
        while self.state()[0] != State.RUNNING:
            assert time.time() < deadline, self.state()
            time.sleep(0.02)

    def _beat(self):
        n = 0
        while self.beating:
            n = (n + 1) & 0xFFFF
            self.write(11, n)
            time.sleep(0.02)

    def close(self):
        self.beating = False
        self.thread.join()
        self.mb.close()


@pytest.mark.slow
def test_a_stall_of_the_simulator_and_its_client_is_not_a_silent_heartbeat():
    """The rig's loop blocked for 1.5 s of wall time (15 s of rig time, about twice the 8 s watchdog), the
    client's beat held until 0.2 s after it: the sweep goes on and ends DONE, and the rig time that was not
    simulated is counted. Before max_step_s the tick after the stall simulated 15 s at once (~70 ms of
    physics) and the next one faulted WATCHDOG before the held beat arrived (measured: this test failed
    with "heartbeat silent for 15.27 s"). Now a tick simulates at most 0.2 s of rig time and ticks
    are >= 10 ms apart, so the beat may come up to ~0.39 s of wall time after the stall before this fails.
    """
    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=8.0)), speed=SPEED).start()
    cli = BeatingClient(rig)
    try:
        cli.start_sweep(3.0, 6.0, 30.0, 1.0)
        time.sleep(0.3)
        with cli.lock:
            rig._loop.call_soon_threadsafe(time.sleep, 1.5)  # the simulator's whole loop stalls
            time.sleep(1.7)
        deadline = time.time() + 10
        while (st := cli.state())[0] == State.RUNNING:
            assert time.time() < deadline, st
            time.sleep(0.05)
        assert st == (State.DONE, Fault.NONE), rig.call(lambda: rig.plc.fault_message)
        assert rig.lost_rig_s > 10.0  # most of the 15 s stall was not simulated
    finally:
        cli.close()
        rig.stop()


def test_a_silent_client_still_faults_the_watchdog_on_time():
    """A client whose beat stops while the simulator runs normally: the watchdog (5 s of rig time, 0.5 s
    wall) still faults the sweep: bounding a tick's rig time does not hide a real silence."""
    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=5.0)), speed=SPEED).start()
    cli = BeatingClient(rig)
    try:
        cli.start_sweep(3.0, 6.0, 60.0, 1.0)
        cli.beating = False
        cli.thread.join()
        t0 = time.time()
        while (st := cli.state())[0] == State.RUNNING:
            assert time.time() - t0 < 10, st
            time.sleep(0.02)
        assert st == (State.FAULT, Fault.WATCHDOG)
        assert "heartbeat silent" in rig.call(lambda: rig.plc.fault_message)
    finally:
        cli.close()
        rig.stop()
