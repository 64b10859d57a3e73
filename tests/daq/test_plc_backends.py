"""The DAQ's PLC registry (daq.plc.BACKENDS): each transport opens from a rig configuration's [plc] section
and reads the simulated PLC's status and limits through the protocol's tables; an unknown transport is
refused by name. Real servers on loopback (Modbus TCP, ADS)."""
import dataclasses
import time

import pytest

from daq.devices import DeviceError
from daq.plc import BACKENDS, open_plc
from protocol import PLC_TRANSPORTS
from protocol.plc import Command, Limits, State
from sim.plc import PLCConfig
from sim.server import SimulatedRig, free_ads_address

LIMITS = Limits(max_stroke_mm=4.0, max_velocity_ms=0.25, max_acceleration_ms2=30.0, f_min_hz=0.5, f_max_hz=40.0,
                max_duration_s=300.0, watchdog_s=2.0)  # all unlike the defaults, so a field read from the wrong register shows


@pytest.fixture(scope="module")
def rig():
    r = SimulatedRig(PLCConfig(limits=LIMITS), speed=1.0, ads_address=free_ads_address()).start()
    yield r
    r.stop()


def _until(predicate, timeout_s: float = 5.0):
    """Poll until predicate() holds (ADS writes reach the PLC at its next 10 ms cycle); its last value."""
    end = time.monotonic() + timeout_s
    while not (ok := predicate()) and time.monotonic() < end:
        time.sleep(0.01)
    return ok


def _sections(rig):
    host, port = rig.endpoints["modbus"]
    net_id, ams_port, ip = rig.endpoints["ads"]
    return {"modbus": {"transport": "modbus", "host": host, "port": port},
            "ads": {"transport": "ads", "host": ip, "ams_net_id": net_id, "ams_port": ams_port}}


@pytest.mark.parametrize("transport", ["modbus", "ads"])
def test_each_backend_opens_from_its_section_and_reads_status_and_limits(rig, transport):
    assert set(BACKENDS) == {"modbus", "ads"}
    assert tuple(BACKENDS) == PLC_TRANSPORTS  # a backend for every transport a rig configuration may name
    plc = open_plc(_sections(rig)[transport])
    try:
        assert isinstance(plc, BACKENDS[transport])
        limits = plc.limits()
        assert limits == pytest.approx(dataclasses.asdict(LIMITS), rel=1e-6)  # float32 on the wire
        wanted = {"f_start_hz": 2.0, "f_end_hz": 7.5, "duration_s": 30.0, "amplitude_mm": 0.8}
        plc.configure(*wanted.values())
        assert _until(lambda: rig.call(lambda: dict(rig.plc.setpoints)) == pytest.approx(wanted))
        plc.command(Command.ESTOP)
        assert _until(lambda: plc.status().state == State.ESTOP)
        st = plc.status()
        assert st.fault_code == 0 and st.elapsed_s == 0.0 and st.position_mm == 0.0
        plc.command(Command.RESET)
        assert _until(lambda: plc.status().state == State.IDLE)
    finally:
        plc.close()


def test_an_unknown_transport_is_refused_naming_the_known_ones():
    with pytest.raises(DeviceError, match=r"\[plc\] transport 'opcua' is not one the DAQ speaks: modbus, ads"):
        open_plc({"transport": "opcua", "host": "127.0.0.1"})
