"""A sweep run by the DAQ against the simulated rig over loopback: Modbus PLC, pyserial socket:// stream."""
import numpy as np
import pytest

from daq.plc import AdsPLC, ModbusPLC
from daq.sources import SerialSource
from daq.recorder import describe, read_h5_recording
from daq.sweep import SweepRefused, SweepRequest, SweepRunner
from identify.identifier import SparseIdentifier
from protocol.plc import Limits, State
from sim.plc import PLCConfig
from sim.server import SENSITIVITY, SimulatedRig, free_ads_address

SPEED = 10.0


@pytest.fixture
def rig():
    r = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=3.0)), speed=SPEED, ads_address=free_ads_address()).start()
    yield r
    r.stop()


def _runner(rig, plc):
    return SweepRunner(plc, SerialSource(rig.endpoints["stream"], 2048.0), Limits(), SENSITIVITY)


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["modbus", "ads"])
def test_sweep_gives_a_complete_recording_that_identifies_the_rig(rig, tmp_path, transport):
    if transport == "modbus":
        plc = ModbusPLC(*rig.endpoints["modbus"])
    else:
        net_id, port, ip = rig.endpoints["ads"]
        plc = AdsPLC(net_id, ip, port)
    progress = []
    runner = _runner(rig, plc)
    runner.on_progress = lambda frac, st: progress.append(frac)
    out = tmp_path / f"{transport}.h5"
    result = runner.run(SweepRequest(1.0, 20.0, 40.0, 1.3, settle_s=3.0, operator="test"), out)
    assert result["status"] == "complete" and result["gaps"] == 0, result
    assert progress and max(progress) == 1.0
    info = describe(out)
    assert info["status"] == "complete" and info["sweep"]["amplitude_mm"] == 1.3
    model = SparseIdentifier(validate=False).fit(read_h5_recording(out)).model_
    truth = rig.plc.model.equations["q1_dot"]
    assert set(model.equations["q1_dot"]) == set(truth)
    for term, c in truth.items():
        assert abs(model.coefficient("q1_dot", term) / c - 1) < 0.03, term


def test_unsafe_parameters_are_refused_before_any_plc_write(rig, tmp_path):
    plc = ModbusPLC(*rig.endpoints["modbus"])
    before = rig.call(lambda: dict(rig.plc.setpoints))
    with pytest.raises(SweepRefused, match="amplitude 9 mm above the stroke limit 5 mm"):
        _runner(rig, plc).run(SweepRequest(1.0, 20.0, 60.0, 9.0), tmp_path / "x.h5")
    with pytest.raises(SweepRefused, match="peak acceleration"):
        _runner(rig, plc).run(SweepRequest(1.0, 45.0, 60.0, 0.6), tmp_path / "y.h5")
    assert rig.call(lambda: dict(rig.plc.setpoints)) == before  # the PLC saw no write
    assert not (tmp_path / "x.h5").exists()


def test_cut_plc_link_ends_the_recording_with_the_reason(rig, tmp_path):
    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = _runner(rig, plc)
    cut = {"done": False}

    def progress(frac, st):
        if frac > 0.1 and not cut["done"]:
            cut["done"] = True
            rig.call(rig.fault_injection.update, {"cut_plc_link_s": 30.0})

    runner.on_progress = progress
    result = runner.run(SweepRequest(2.0, 10.0, 30.0, 1.0), tmp_path / "cut.h5")
    assert result["status"] == "aborted" and "PLC link lost" in result["reason"]
    info = describe(tmp_path / "cut.h5")
    assert info["status"] == "aborted" and "PLC link lost" in info["status_reason"] and info["samples"] > 0


@pytest.mark.slow
def test_shakeid_sweep_against_shakeid_sim(tmp_path):
    """Two real processes: `shakeid sim` (the rig) and `shakeid sweep` (the DAQ) on loopback."""
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from sim.server import free_port

    exe = str(Path(sys.executable).with_name("shakeid"))
    mb, st = free_port(), free_port()
    cfg = tmp_path / "rig.toml"
    cfg.write_text(f'[plc]\nport = {mb}\n[stream]\nurl = "socket://127.0.0.1:{st}"\n[limits]\nwatchdog_s = 2.0\n')
    from daq.recorder import Recorder, describe

    crashed = Recorder(tmp_path / "crashed.h5", fs_hz=100.0)  # left "running", as after a crash
    crashed.append(0, [[1.0, 2.0]] * 10)
    crashed.flush()
    crashed.f.close()
    sim = subprocess.Popen([exe, "sim", "--config", str(cfg), "--speed", "10"], stdout=subprocess.PIPE, text=True)
    try:
        assert "Modbus" in sim.stdout.readline()
        out = tmp_path / "sweep.h5"
        proc = subprocess.run([exe, "sweep", "--config", str(cfg), "--f-start-hz", "2", "--f-end-hz", "10",
                               "--duration-s", "10", "--amplitude-mm", "1", "--out", str(out)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert "complete" in proc.stdout and "0 gap(s)" in proc.stdout and "sweep 100 % (10.0 s of 10 s)  done" in proc.stderr  # no TTY: plain progress lines
        assert "crashed.h5: was left running" in proc.stdout and describe(tmp_path / "crashed.h5")["status"] == "aborted"
        bad = subprocess.run([exe, "sweep", "--config", str(cfg), "--f-start-hz", "2", "--f-end-hz", "10",
                              "--duration-s", "10", "--amplitude-mm", "7", "--out", str(tmp_path / "no.h5")],
                             capture_output=True, text=True, timeout=60)
        assert bad.returncode == 2 and "stroke limit" in bad.stderr and not (tmp_path / "no.h5").exists()
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.communicate(timeout=20)


@pytest.mark.slow
def test_sigkill_of_the_sweep_process_the_watchdog_stops_the_table(tmp_path):
    """`shakeid sweep` killed with SIGKILL mid-sweep: the PLC's watchdog stops the table (no client is left
    to do it), the file opens with its samples up to the last flush, and the next start marks it."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    import h5py

    from protocol.plc import Fault, State

    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=2.0)), speed=SPEED).start()
    exe = str(Path(sys.executable).with_name("shakeid"))
    cfg = tmp_path / "rig.toml"
    host, port = rig.endpoints["modbus"]
    cfg.write_text(f'[plc]\nport = {port}\n[stream]\nurl = "{rig.endpoints["stream"]}"\n')
    out = tmp_path / "killed.h5"
    proc = subprocess.Popen([exe, "sweep", "--config", str(cfg), "--f-start-hz", "1", "--f-end-hz", "20",
                             "--duration-s", "120", "--amplitude-mm", "1.0", "--out", str(out)],  # 1.3: refused by the preflight
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 60
        while rig.call(lambda: rig.plc.status()["elapsed_s"]) < 30.0:  # 30 s of rig time into the sweep
            assert proc.poll() is None and time.monotonic() < end, proc.stderr.read() if proc.poll() else "timeout"
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        killed_at = rig.call(lambda: rig.plc.time_s)
        assert rig.call(lambda: rig.plc.state) == State.RUNNING  # nobody stopped it yet
        while not rig.call(lambda: rig.plc.state == State.FAULT and rig.plc._table_at_rest()):
            assert rig.call(lambda: rig.plc.time_s) - killed_at < 10.0, "the watchdog did not stop the table"
            time.sleep(0.05)
        assert rig.call(lambda: rig.plc.fault) == Fault.WATCHDOG
        # heartbeat silent > 2 s, then the 0.2 s ramp: the table is at rest within 2 s + ramp + ticks
        stopped = rig.call(lambda: rig.plc.stop_t + rig.plc.stop_ramp) - killed_at
        assert stopped < 2.0 + 0.2 + 1.0 + 0.1 * SPEED, stopped
    finally:
        if proc.poll() is None:
            proc.kill()
        rig.stop()
    with h5py.File(out, "r") as f:  # a plain open, no recovery needed
        assert f["entry"].attrs["status"] == "running"
        n = f["entry/data/time"].shape[0]
        # 30 s of rig time had been recorded at the kill; at 10x one flush interval (1 s wall) is 10 s of
        # rig time, so >= 10 s must be on disk even with a lagging reader (the precise bound is
        # tests/daq/test_recorder.py's SIGKILL test)
        assert n >= 10 * 2048
        t = f["entry/data/time"][()]
        assert np.allclose(np.diff(t), 1 / 2048) and np.all(np.isfinite(f["entry/data/mass_acc"][()]))
    p = subprocess.run([exe, "recordings", "--recover", str(out)], capture_output=True, text=True)
    assert p.returncode == 0 and "marked aborted" in p.stdout and describe(out)["status"] == "aborted"
    again = subprocess.run([exe, "recordings", "--recover", str(out)], capture_output=True, text=True)
    assert again.returncode == 0 and f"{out}: not left running by a crash; nothing to recover" in again.stdout


@pytest.mark.parametrize("event,status,reason", [
    ("drive_fault", "fault", "PLC fault: injected"),
    ("estop_on_the_rig", "aborted", "emergency stop"),
    ("sensor_loss", "aborted", "accelerometer stream"),
])
@pytest.mark.slow
def test_abort_paths_leave_the_table_stopped_and_the_file_valid(rig, tmp_path, event, status, reason):
    """A drive fault, an emergency stop pressed at the rig, and a lost sensor stream mid-sweep: each ends
    the recording with its status and reason, the samples so far intact, and the table at rest."""
    import time

    from protocol.plc import Command, State

    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = _runner(rig, plc)
    fired, fractions = {"done": False}, []
    actions = {"drive_fault": lambda: rig.plc.inject_fault(),
               "estop_on_the_rig": lambda: rig.plc.command(Command.ESTOP),
               "sensor_loss": lambda: rig.fault_injection.update({"disconnect_s": 60.0})}

    def progress(frac, st):
        fractions.append(frac)
        if frac > 0.1 and not fired["done"]:
            fired["done"] = True
            rig.call(actions[event])

    runner.on_progress = progress
    result = runner.run(SweepRequest(2.0, 10.0, 60.0, 1.0), tmp_path / f"{event}.h5")
    plc.close()
    assert result["status"] == status and reason in result["reason"], result
    # the last progress reported is how far the sweep got, not a 0 from a PLC in estop or fault
    assert fractions[-1] > 0.1, fractions[-5:]
    info = describe(tmp_path / f"{event}.h5")
    assert info["status"] == status and reason in info["status_reason"] and info["samples"] > 2048
    end = time.monotonic() + 10
    while not rig.call(lambda: rig.plc._table_at_rest()):  # stopped by the PLC or by the runner's STOP
        assert time.monotonic() < end, "the table kept moving"
        time.sleep(0.05)
    assert rig.call(lambda: rig.plc.state) != State.RUNNING


def test_a_sweep_that_would_not_fit_on_the_disk_is_refused_before_any_plc_write(rig, tmp_path):
    import shutil

    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = _runner(rig, plc)
    runner.disk_reserve_bytes = shutil.disk_usage(tmp_path).free  # what is left cannot hold a recording
    before = rig.call(lambda: dict(rig.plc.setpoints))
    with pytest.raises(SweepRefused, match=r"needs about \d+ MB plus the \d+ MB disk reserve; \d+ MB free"):
        runner.run(SweepRequest(1.0, 20.0, 60.0, 1.3), tmp_path / "big.h5")
    assert rig.call(lambda: dict(rig.plc.setpoints)) == before and not (tmp_path / "big.h5").exists()
    plc.close()


@pytest.mark.slow
def test_disk_reaching_its_reserve_mid_sweep_stops_the_table_and_keeps_the_file_whole(rig, tmp_path):
    """HDF5 that runs out of space mid-write can leave a file no reader opens (seen here with a file-size
    limit: 'truncated file'), so the recorder checks the reserve at each flush and the sweep stops first."""
    import time

    import h5py

    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = _runner(rig, plc)

    def progress(frac, st):
        if frac > 0.2 and runner.recorder is not None:
            runner.recorder.min_free_bytes = 10**18  # as if the disk had filled up to the reserve

    runner.on_progress = progress
    result = runner.run(SweepRequest(2.0, 10.0, 60.0, 1.0), tmp_path / "full.h5")
    plc.close()
    assert result["status"] == "fault" and "disk nearly full" in result["reason"], result
    with h5py.File(tmp_path / "full.h5") as f:  # whole: opens, closed with the reason, samples kept
        assert f["entry"].attrs["status"] == "fault" and f["entry/data/time"].shape[0] > 2048
    end = time.monotonic() + 10
    while not rig.call(lambda: rig.plc._table_at_rest()):
        assert time.monotonic() < end, "the table kept moving"
        time.sleep(0.05)


class _FallingBehindSource(SerialSource):
    """A real socket:// reader that falls behind the sensors without knowing it once the sweep runs, as
    a relay in between does under the sweep's load (the CAN remote, where CI saw a recording end 128
    samples short): caught up while `running()` is false, then it hands over frames at `rate` of the
    pace they are sensed, never reports a backlog, and loses none (every frame comes, in order, later)."""

    def __init__(self, url: str, fs_hz: float, rate: float, running):
        super().__init__(url, fs_hz)
        self.rate, self.running, self._held, self._since = rate, running, [], None

    def read(self):
        self._held += super().read()
        self.backlog = False
        if not self._held:
            return []
        newest = self._held[-1][0] + len(self._held[-1][1])
        if self._since is None or not self.running():
            self._since = newest  # caught up: everything held is handed over
        upto = self._since + self.rate * (newest - self._since)
        out = []
        while self._held and self._held[0][0] + len(self._held[0][1]) <= upto:
            out.append(self._held.pop(0))
        return out


@pytest.mark.slow
def test_a_reader_falling_behind_without_knowing_it_still_records_the_whole_settle(rig, tmp_path):
    """The settle after the sweep is recorded in full when the reader falls behind during the sweep
    and cannot tell (delivering at 70 % of the sensors' pace from START, ~2 s behind by its end):
    the table is at rest for settle_s in the file after its last motion. Before, the settle counted
    from where the reader was when the PLC said DONE, and the file ended with the table still moving;
    now it counts from no earlier than duration_s after where the reader was once START was acknowledged."""
    fs, settle = 2048.0, 1.0
    source = _FallingBehindSource(rig.endpoints["stream"], fs, 0.7,
                                  running=lambda: rig.call(lambda: rig.plc.state) != State.IDLE)
    runner = SweepRunner(ModbusPLC(*rig.endpoints["modbus"]), source, Limits(), SENSITIVITY)
    out = tmp_path / "behind.h5"
    result = runner.run(SweepRequest(2.0, 10.0, 6.0, 1.0, settle_s=settle, operator="test"), out)
    assert result["status"] == "complete" and result["gaps"] == 0, result
    rec = read_h5_recording(out)
    table = np.abs(rec.input)
    moving = np.flatnonzero(table > 0.1 * table.max())
    after = (rec.n_samples - 1 - moving[-1]) / fs  # s of the file after the table's last motion
    assert after >= settle - 0.05, f"{after:.3f} s recorded after the sweep, settle {settle} s"
