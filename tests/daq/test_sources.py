"""Accelerometer sources against the simulated rig: the framed TCP stream through pyserial socket:// and
CAN through a python-can bus. Lost and corrupted frames must arrive in the file as counted gaps."""
import numpy as np
import pytest

from daq.plc import ModbusPLC
from daq.recorder import describe, read_h5_recording
from daq.sources import CanSource, SerialSource
from daq.sweep import SweepRequest, SweepRunner
from identify.errors import RecordingError
from identify.identifier import SparseIdentifier
from protocol.plc import Limits
from sim.plc import PLCConfig
from sim.server import SENSITIVITY, SimulatedRig

FRAME = 64  # samples per stream frame (the simulated rig's default)


@pytest.fixture
def can_rig(request):
    channel = f"shakeid-{request.node.name}"
    r = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=3.0)), speed=10.0, can_interface="virtual",
                     can_channel=channel).start()
    r.test_can_channel = channel
    yield r
    r.stop()


@pytest.mark.slow
def test_sweep_recorded_over_can_identifies_the_rig(can_rig, tmp_path):
    plc = ModbusPLC(*can_rig.endpoints["modbus"])
    source = CanSource("virtual", can_rig.test_can_channel, 2048.0)
    try:
        result = SweepRunner(plc, source, Limits(), SENSITIVITY).run(SweepRequest(1.0, 20.0, 40.0, 1.3, 3.0),
                                                                      tmp_path / "can.h5")
    finally:
        plc.close()
        source.close()
    why = {k: v for k, v in result.items() if "heart" in k or k in ("status", "reason", "gaps")}
    assert result["status"] == "complete" and result["gaps"] == 0, why
    assert result["link_frames"] == result["samples"] and result["link_frames_lost"] == 0
    info = describe(tmp_path / "can.h5")
    assert info["link_frames"] == info["samples"] > 40 * 2048
    model = SparseIdentifier(validate=False).fit(read_h5_recording(tmp_path / "can.h5")).model_
    truth = can_rig.plc.model.equations["q1_dot"]
    assert set(model.equations["q1_dot"]) == set(truth)
    for term, c in truth.items():
        assert abs(model.coefficient("q1_dot", term) / c - 1) < 0.03, term


def _sweep_with_faults(rig, source, tmp_path, faults: list[dict]):
    """Run a short sweep; inject faults[k] at successive progress points; return (result, describe)."""
    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = SweepRunner(plc, source, Limits(), SENSITIVITY)
    pending = list(faults)

    def progress(frac, st):
        if pending and frac > 0.2 * (len(faults) - len(pending) + 1):
            rig.call(rig.fault_injection.update, pending.pop(0))

    runner.on_progress = progress
    try:
        result = runner.run(SweepRequest(2.0, 10.0, 20.0, 1.0, 1.0), tmp_path / "faults.h5")
    finally:
        plc.close()
        source.close()
    assert not pending
    return result, describe(tmp_path / "faults.h5")


@pytest.mark.slow
def test_dropped_and_corrupted_stream_frames_are_counted_gaps(tmp_path):
    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=3.0)), speed=10.0).start()
    try:
        result, info = _sweep_with_faults(rig, SerialSource(rig.endpoints["stream"], 2048.0), tmp_path,
                                          [{"drop_frames": 3}, {"corrupt_frames": 2}])
    finally:
        rig.stop()
    assert result["status"] == "complete"
    assert [count for _, count in info["gaps"]] == [3 * FRAME, 2 * FRAME]  # two gaps, exact lengths
    assert info["link_frames_lost"] == 5 and info["link_frames_corrupt"] == 2
    assert info["gaps"][0][0] < info["gaps"][1][0]  # listed in order
    with pytest.raises(RecordingError, match="2 gap"):
        read_h5_recording(tmp_path / "faults.h5")  # never spliced into one record
    import subprocess
    import sys
    from pathlib import Path

    shown = subprocess.run([str(Path(sys.executable).with_name("shakeid")), "recordings", str(tmp_path / "faults.h5")],
                           capture_output=True, text=True)
    assert "2 gap(s)" in shown.stdout and "5 lost, 2 corrupt" in shown.stdout
    assert f"gap: {3 * FRAME} samples missing from sample {info['gaps'][0][0]}" in shown.stdout


@pytest.mark.slow
def test_lost_can_frames_are_counted_gaps(can_rig, tmp_path):
    source = CanSource("virtual", can_rig.test_can_channel, 2048.0)
    result, info = _sweep_with_faults(can_rig, source, tmp_path, [{"drop_can_frames": 100}])
    assert result["status"] == "complete"
    assert [count for _, count in info["gaps"]] == [100] and info["link_frames_lost"] == 100
    assert info["samples"] == info["link_frames"]


@pytest.mark.slow
def test_can_counter_wraps_without_a_false_gap(can_rig):
    """The 16-bit counter wraps every 32 s at 2048 Hz: the index keeps counting up."""
    source = CanSource("virtual", can_rig.test_can_channel, 2048.0)
    try:
        blocks, n = [], 0
        while n < 70000:  # ~3.5 s of wall time at 10x: more than one full turn of the counter
            got = source.read()
            blocks += got
            n += sum(b.shape[0] for _, b in got)
    finally:
        source.close()
    index = np.concatenate([first + np.arange(b.shape[0]) for first, b in blocks])
    assert index[-1] >= 65536  # the counter wrapped during the run
    assert np.all(np.diff(index) == 1) and source.stats["frames_lost"] == 0


def test_missing_can_bus_is_a_clear_error():
    from daq.devices import DeviceError

    with pytest.raises(DeviceError, match="accelerometers on CAN nosuchinterface"):
        CanSource("nosuchinterface", "x", 2048.0)


def test_each_configured_source_opens_from_its_own_section():
    """The registry (daq.sources.SOURCES) has a class for every [sampling] source a rig configuration may
    name; each opens from its own section (pyserial's loop:// and python-can's virtual bus: real links in
    this process); an unknown source and a CAN source without an interface are refused by name."""
    from daq.devices import DeviceError
    from daq.sources import SOURCES, open_source
    from protocol import ACCELEROMETER_SOURCES

    assert tuple(SOURCES) == ACCELEROMETER_SOURCES
    serial = open_source({"url": "loop://"}, {}, 2048.0)
    can = open_source({"url": "unused"}, {"interface": "virtual", "channel": "src-registry", "node": 3}, 1000.0, "can")
    try:
        assert type(serial) is SerialSource and serial.url == "loop://" and serial.fs_hz == 2048.0
        assert type(can) is CanSource and can.url == "CAN virtual src-registry node 3" and can.fs_hz == 1000.0
    finally:
        serial.close()
        can.close()
    with pytest.raises(DeviceError, match=r"\[sampling\] source 'usb' is not one the DAQ reads: stream, can"):
        open_source({"url": "loop://"}, {}, 2048.0, "usb")
    with pytest.raises(DeviceError, match=r"needs a \[can\] section with interface"):
        open_source({"url": "loop://"}, {}, 2048.0, "can")


@pytest.mark.slow
def test_shakeid_sweep_over_can_across_processes(tmp_path, can_relay):
    """Three real processes on loopback: a python-can-remote relay, `shakeid sim` sending the samples as
    CAN frames through it, and `shakeid sweep` with [sampling] source = "can" recording them."""
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from sim.server import free_port

    exe = str(Path(sys.executable).with_name("shakeid"))
    mb, st = free_port(), free_port()
    cfg = tmp_path / "rig.toml"
    # 4x: 8192 frames/s, inside the relay's measured lossless range (shared notes: 2-10 kHz)
    cfg.write_text(f'[plc]\nport = {mb}\n[stream]\nurl = "socket://127.0.0.1:{st}"\n'
                   f'[can]\ninterface = "remote"\nchannel = "ws://127.0.0.1:{can_relay}/"\n'
                   f'[sampling]\nsource = "can"\n[limits]\nwatchdog_s = 1.0\n[sim]\nspeed = 4\n')
    sim = subprocess.Popen([exe, "sim", "--config", str(cfg)], stdout=subprocess.PIPE, text=True)
    try:
        assert "CAN remote" in sim.stdout.readline()
        out = tmp_path / "can.h5"
        p = subprocess.run([exe, "sweep", "--config", str(cfg), "--f-start-hz", "2", "--f-end-hz", "10",
                            "--duration-s", "8", "--amplitude-mm", "1", "--settle-s", "1", "--out", str(out)],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 0 and "complete" in p.stdout and "0 gap(s)" in p.stdout, p.stdout + p.stderr
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.communicate(timeout=20)
    info = describe(out)
    assert info["link_frames"] == info["samples"] >= 9 * 2048 - 64 and info["link_frames_lost"] == 0


def test_a_read_capped_at_its_limit_drops_no_frame():
    """More frames queued than one read() takes: the rest come with the next read, none lost between."""
    import can

    from protocol import can_frames

    source = CanSource("virtual", "shakeid-cap", 2048.0)
    source.MAX_FRAMES_PER_READ = 100
    sender = can.Bus(interface="virtual", channel="shakeid-cap")
    counts = np.arange(500).repeat(2).reshape(500, 2).astype(np.int16)
    for payload in can_frames.encode(7, counts):
        sender.send(can.Message(arbitration_id=can_frames.BASE_ID, data=payload, is_extended_id=False))
    got = []
    try:
        while sum(b.shape[0] for _, b in got) < 500:
            blocks = source.read()
            assert blocks, "frames went missing"
            if sum(b.shape[0] for _, b in got + blocks) < 500:
                assert source.backlog  # it says more is waiting (it may also say so when exactly the limit was)
            got += blocks
    finally:
        source.close()
        sender.shutdown()
    index = np.concatenate([first + np.arange(b.shape[0]) for first, b in got])
    np.testing.assert_array_equal(index, 7 + np.arange(500))
    np.testing.assert_array_equal(np.concatenate([b for _, b in got]), counts)
    assert source.stats["frames_lost"] == 0
