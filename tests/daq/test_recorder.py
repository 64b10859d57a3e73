"""HDF5 recorder: layout and units, gaps, and survival of a SIGKILL mid-recording (real files, a real
killed process)."""
import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.recorder import Recorder, describe, read_h5_recording, recover
from identify.errors import RecordingError

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def test_layout_units_and_round_trip(tmp_path, table1_run):
    path = tmp_path / "r.h5"
    rec = table1_run.recording
    block = np.column_stack([rec.input, rec.output])
    r = Recorder(path, fs_hz=rec.fs_hz, operator="lab", sweep={"f_start_hz": 1.0, "amplitude_mm": 1.3},
                 sensors={"mass_acc": {"sensitivity": 655.34, "position": "mass"}})
    for a in range(0, block.shape[0], 1000):
        r.append(a, block[a:a + 1000])
    r.close()
    with h5py.File(path) as f:
        assert f["entry"].attrs["NX_class"] == "NXentry" and f["entry/data"].attrs["NX_class"] == "NXdata"
        assert f["entry/instrument/mass_acc"].attrs["NX_class"] == "NXsensor"
        assert f["entry/instrument/mass_acc"].attrs["sensitivity"] == pytest.approx(655.34)
        assert f["entry/data/time"].attrs["units"] == "s" and f["entry/data/mass_acc"].attrs["units"] == "m/s^2"
    info = describe(path)
    assert info["status"] == "complete" and info["samples"] == rec.n_samples and info["gaps"] == []
    back = read_h5_recording(path)
    np.testing.assert_allclose(back.output, rec.output, rtol=1e-6, atol=1e-6)  # float32 storage
    assert back.fs_hz == rec.fs_hz
    with pytest.raises(RecordingError, match="never overwritten"):
        Recorder(path)


def test_gaps_are_listed_never_spliced(tmp_path):
    path = tmp_path / "g.h5"
    r = Recorder(path, fs_hz=100.0)
    r.append(0, np.ones((300, 2)))
    r.append(364, np.ones((300, 2)))  # 64 samples (one frame) lost
    r.close("aborted", "sensor link lost")
    info = describe(path)
    assert info["gaps"] == [[300, 64]] and info["status"] == "aborted" and info["status_reason"] == "sensor link lost"
    # the verdict carries the status: an aborted recording is not usable, whatever its signals
    assert info["quality"]["usable_for_identification"] is False
    assert info["quality"]["reasons"][0] == "status is aborted (sensor link lost), not complete"
    with h5py.File(path) as f:
        t = f["entry/data/time"][()]
    assert t[300] - t[299] == pytest.approx(65 / 100.0)  # the time axis jumps over the gap
    with pytest.raises(RecordingError, match="1 gap.*64 samples missing at sample 300"):
        read_h5_recording(path)


WRITER = textwrap.dedent("""
    import sys, time, numpy as np
    from daq.recorder import Recorder
    r = Recorder(sys.argv[1], fs_hz=1000.0)
    k = 0
    print("started", flush=True)
    while True:  # 1000 samples/s in 100-sample blocks, values = sample index
        idx = k + np.arange(100)
        r.append(k, np.column_stack([idx, -idx]).astype(float))
        k += 100
        time.sleep(0.1)
""")


@pytest.mark.slow
def test_sigkill_mid_recording_leaves_a_readable_file(tmp_path):
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "started"
    time.sleep(2.6)
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    with h5py.File(path) as f:  # a plain open, no special mode
        assert f["entry"].attrs["status"] == "running"
        t = f["entry/data/time"][()]
        table = f["entry/data/table_acc"][()]
    assert t.size >= 1000  # flushed at least every second: no more than ~1 s of the 2.6 s lost
    np.testing.assert_array_equal(table, np.arange(t.size))  # every flushed row intact
    copy = path.with_name("copy.h5")
    copy.write_bytes(path.read_bytes())
    assert recover(path) and describe(path)["status"] == "aborted"
    assert not recover(path)  # a second start finds nothing to do
    # by hand, for a script: stdout is the JSON alone, what was done goes to stderr
    scripted = subprocess.run([SHAKEID, "recordings", "--recover", "--json", str(copy)], capture_output=True,
                              text=True, timeout=60)
    assert scripted.returncode == 0 and "marked aborted" in scripted.stderr, scripted.stderr
    doc = json.loads(scripted.stdout)  # one object, nothing before it
    assert doc["status"] == "aborted" and doc["identification"]["usable"] is False
    assert doc["quality"]["usable_for_identification"] is False
    out = subprocess.run([SHAKEID, "recordings", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "aborted" in out.stdout and "found running" in out.stdout


@pytest.mark.slow
def test_identify_reads_hdf5_directly(tmp_path, table1_run, table1_truth):
    path = tmp_path / "sweep.h5"
    rec = table1_run.recording
    # a rig configuration with [rig] mass_kg = 0.98 recorded it (sim.config.RigConfig.recording_metadata)
    r = Recorder(path, fs_hz=rec.fs_hz, rig_config={"source": "lab.toml", "moving_mass_kg": 0.98})
    r.append(0, np.column_stack([rec.input, rec.output]))
    r.close()
    proc = subprocess.run([SHAKEID, "identify", str(path), "--json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert set(doc["model"]["q1_dot"]) == set(table1_truth["q1_dot"])
    # forces are the recorded mass times the fitted accelerations (k/m = 971.0 is the simulated rig's)
    phys = doc["physical"]
    assert phys["mass_kg"] == 0.98 and phys["mass_source"] == "recording"
    assert phys["stiffness_n_per_m"]["value"] == pytest.approx(0.98 * -table1_truth["q1_dot"]["q2"], rel=0.01)
    given = subprocess.run([SHAKEID, "identify", str(path), "--mass-kg", "0.49", "--placements", "0",
                            "--bias-replicates", "0"], capture_output=True, text=True, timeout=300)
    assert given.returncode == 0 and "physical (m = 0.49 kg, given, --mass-kg)" in given.stdout, given.stderr
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not hdf5 at all" * 10)
    proc = subprocess.run([SHAKEID, "identify", str(bad)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stderr.startswith("shakeid: error:") and "Traceback" not in proc.stderr


def test_a_recording_being_written_is_said_to_be_in_use(tmp_path):
    """While a sweep writes its file (HDF5 locks it), reading it says so: it is not 'not a shakeid
    recording'. Once closed it reads."""
    path = tmp_path / "live.h5"
    rec = Recorder(path, fs_hz=100.0)
    rec.append(0, np.ones((50, 2)))
    script = f"from daq.recorder import describe\ndescribe({str(path)!r})"
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert "is open for writing by another process (a sweep still recording it?)" in proc.stderr, proc.stderr
    rec.close("complete")
    assert describe(path)["status"] == "complete"


def test_recovery_touches_only_shakeid_recordings_left_running(tmp_path):
    """A sweep's folder may hold the operator's own files and a recording another sweep is writing: the
    start-up recovery marks the crashed recording aborted and opens nothing else for writing (it had
    opened every .h5 read-write: a junk .h5 stopped every sweep into the folder, another HDF5 file gave a
    KeyError traceback)."""
    from daq.recorder import recover_directory

    crashed = tmp_path / "crashed.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(crashed)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "started"
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with h5py.File(tmp_path / "mine.h5", "w") as f:  # the operator's own HDF5 file, no /entry
        f["x"] = np.arange(5)
    with h5py.File(tmp_path / "theirs.h5", "w") as f:  # someone's file with an /entry that says running
        f.create_group("entry").attrs["status"] = "running"
    done = tmp_path / "done.h5"
    r = Recorder(done, fs_hz=100.0)
    r.append(0, np.ones((100, 2)))
    r.close()
    live = tmp_path / "live.h5"
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(live)], stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "started"
        before = {p.name: p.read_bytes() for p in tmp_path.glob("*.h5") if p.name not in ("crashed.h5", "live.h5")}
        assert recover_directory(tmp_path) == [crashed]
        assert {p.name: p.read_bytes() for p in tmp_path.glob("*.h5") if p.name in before} == before
        assert describe(crashed)["status"] == "aborted"
        assert writer.poll() is None  # the live sweep still writes
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait(10)
    assert describe(live)["status"] == "running"  # not marked by the recovery; the next one will
