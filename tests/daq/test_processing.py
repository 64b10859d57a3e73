"""Processed signals added to a finished recording, checked against the simulated rig's true motion."""
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.processing import add_processed
from daq.recorder import Recorder, describe, read_h5_recording
from identify.errors import RecordingError

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


@pytest.fixture
def recording_with_gap(tmp_path, table1_run):
    """The Table 1 sweep recorded with one frame (64 samples) lost half way: (path, true states, cut row)."""
    rec = table1_run.recording
    block = np.column_stack([rec.input, rec.output])
    cut = block.shape[0] // 2
    path = tmp_path / "gap.h5"
    r = Recorder(path, fs_hz=rec.fs_hz)
    r.append(0, block[:cut])
    r.append(cut + 64, block[cut + 64:])
    r.close()
    states = np.concatenate([table1_run.states[:cut], table1_run.states[cut + 64:]])
    return path, states, cut


def test_relative_motion_matches_the_true_states_per_segment(recording_with_gap):
    path, states, cut = recording_with_gap
    raw_before = read_h5_recording(path, samples=(0, cut)).output.copy()
    info = add_processed(path)
    assert info["segments"] == 2  # integrated on each side of the gap, never across it
    with h5py.File(path) as f:
        g = f["entry/processed"]
        assert g.attrs["NX_class"] == "NXdata" and g["relative_disp"].attrs["units"] == "m"
        assert g["relative_vel"].attrs["units"] == "m/s" and g["relative_acc"].attrs["units"] == "m/s^2"
        disp, vel, ok = g["relative_disp"][()], g["relative_vel"][()], g["valid"][()].astype(bool)
        assert g["time"].shape == f["entry/data/time"].shape
    assert 0.85 < ok.mean() < 1 and not ok[cut - 1] and not ok[cut]  # the edges at the gap are guarded
    # 0.5 % sensor noise; band-limited integration measured at 0.35 % (displacement), 0.1 % (velocity)
    for x, truth in ((disp, states[:, 1]), (vel, states[:, 0])):
        err = np.sqrt(np.mean((x[ok] - truth[ok]) ** 2)) / np.sqrt(np.mean(truth[ok] ** 2))
        assert err < 0.01
    np.testing.assert_array_equal(read_h5_recording(path, samples=(0, cut)).output, raw_before)  # raw untouched
    assert describe(path)["processed"] == ["relative_acc", "relative_disp", "relative_vel", "valid"]
    add_processed(path)  # again: replaces, does not duplicate
    with h5py.File(path) as f:
        assert sorted(f["entry"]) == ["data", "gaps", "instrument", "processed", "quality", "sweep"]


def test_a_running_recording_is_not_processed(tmp_path):
    r = Recorder(tmp_path / "live.h5", fs_hz=100.0)
    r.append(0, np.ones((500, 2)))
    r.flush()
    with pytest.raises(RecordingError, match="still recording"):
        add_processed(tmp_path / "live.h5")
    r.close()


@pytest.mark.slow
def test_cli_processes_and_identifies_a_gap_free_stretch(recording_with_gap):
    path, _, cut = recording_with_gap
    p = subprocess.run([SHAKEID, "recordings", str(path), "--process"], capture_output=True, text=True)
    assert p.returncode == 0 and "processed signals added" in p.stdout and "2 segment(s)" in p.stdout, p.stderr
    spanning = subprocess.run([SHAKEID, "identify", str(path)], capture_output=True, text=True)
    assert spanning.returncode != 0 and f"longest: rows 0 {cut})" in spanning.stderr
    ok = subprocess.run([SHAKEID, "identify", str(path), "--samples", "0", str(cut), "--json"],
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
