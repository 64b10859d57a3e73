"""`shakeid campaign PLAN.toml --config RIG.toml --out DIR` against `shakeid sim` on loopback (Modbus and
the accelerometer stream): real processes, the table's state read from the PLC. States are polled."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from daq.plc import ModbusPLC
from protocol.plc import Command, State
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


@pytest.fixture
def rig(sim_rig):
    """The shared `shakeid sim` fixture (tests/conftest.py) and a Modbus link to its PLC."""
    cfg, modbus = sim_rig
    plc = ModbusPLC("127.0.0.1", modbus)
    yield cfg, plc
    plc.close()


def _plan(tmp_path, name: str, duration_s: float, amplitudes=(0.8, 1.2)) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'name = "{name}"\namplitudes_mm = {list(amplitudes)}\ndirections = ["up", "down"]\n'
                    f'rest_between_s = 0.2\n[sweep]\nf_start_hz = 3.0\nf_end_hz = 15.0\n'
                    f'duration_s = {duration_s}\nsettle_s = 0.5\n')
    return path


def _campaign(plan, cfg, out, *extra, **kw):
    return subprocess.run([SHAKEID, "campaign", str(plan), "--config", str(cfg), "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=300, **kw)


def _state(out: Path, name: str) -> dict:
    return json.loads((out / f"{name}.campaign.json").read_text())


def _wait(fn, timeout_s: float, what: str):
    end = time.monotonic() + timeout_s
    while not (value := fn()):
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.1)
    return value


def test_a_campaign_writes_one_file_per_sweep_in_order(rig, tmp_path):
    cfg, plc = rig
    out = tmp_path / "out"
    p = _campaign(_plan(tmp_path, "levels", 3.0), cfg, out)
    assert p.returncode == 0, p.stdout + p.stderr
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("sweep ")]
    assert lines == [f"sweep 1 of 4 (0.8 mm, up): 3 -> 15 Hz over 3 s -> {out}/levels-1.h5",
                     f"sweep 2 of 4 (0.8 mm, down): 15 -> 3 Hz over 3 s -> {out}/levels-2.h5",
                     f"sweep 3 of 4 (1.2 mm, up): 3 -> 15 Hz over 3 s -> {out}/levels-3.h5",
                     f"sweep 4 of 4 (1.2 mm, down): 15 -> 3 Hz over 3 s -> {out}/levels-4.h5"]
    assert "campaign levels: completed, 4 of 4 sweeps complete" in p.stdout
    for k, (amp, f0, f1) in enumerate([(0.8, 3, 15), (0.8, 15, 3), (1.2, 3, 15), (1.2, 15, 3)], 1):
        with h5py.File(out / f"levels-{k}.h5") as f:
            s = f["entry/sweep"].attrs
            assert f["entry"].attrs["status"] == "complete"
            assert (s["amplitude_mm"], s["f_start_hz"], s["f_end_hz"]) == (amp, f0, f1)
            assert s["note"].startswith(f"campaign levels: sweep {k} of 4")
    state = _state(out, "levels")
    assert state["state"] == "completed" and [it["path"] for it in state["sweeps"]] == [
        str(out / f"levels-{k}.h5") for k in range(1, 5)]
    again = _campaign(_plan(tmp_path, "levels", 3.0), cfg, out)  # the same name again: refused, nothing moves
    assert again.returncode == 2 and "already in" in again.stderr and "completed, 4 of 4" in again.stderr
    # a completed campaign has nothing to resume: the refusal does not send the operator to --resume
    assert "another name or another --out" in again.stderr and "--resume" not in again.stderr


def test_an_estop_pauses_the_campaign_resume_goes_on_and_ctrl_c_aborts(rig, tmp_path):
    cfg, plc = rig
    out = tmp_path / "out"
    plan = _plan(tmp_path, "stops", 30.0, amplitudes=(1.0,))
    proc = subprocess.Popen([SHAKEID, "campaign", str(plan), "--config", str(cfg), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    _wait(lambda: (st := plc.status()).state == State.RUNNING and st.elapsed_s > 3.0, 120, "sweep 1 to run")
    plc.command(Command.ESTOP)  # the hardware stop (or `shakeid rig estop`): the campaign only reads it
    assert proc.wait(120) == 1
    state = _state(out, "stops")
    assert state["state"] == "paused" and state["reason"].startswith(
        "sweep 1 of 2 (1 mm, up) ended aborted: emergency stop"), state
    assert [it["status"] for it in state["sweeps"]] == ["failed", "planned"]
    st = plc.status()
    assert st.state == State.ESTOP and st.position_mm == 0.0  # at rest; no next sweep started
    assert "--resume" in proc.stdout.read()

    refused = _campaign(plan, cfg, out, "--resume")  # not reset: the sweep is refused, nothing moves
    assert refused.returncode == 1 and "not started: sweep refused: the PLC is in emergency stop; reset it first" in refused.stdout
    plc.command(Command.RESET)
    assert plc.status().state == State.IDLE
    # resume: sweep 1 again (the stopped file kept aside), then sweep 2; Ctrl-C during sweep 2
    proc = subprocess.Popen([SHAKEID, "campaign", str(plan), "--config", str(cfg), "--out", str(out), "--resume"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    _wait(lambda: (out / "stops-2.h5").exists() and plc.status().state == State.RUNNING, 180, "sweep 2 to run")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(60) == 130
    state = _state(out, "stops")
    assert (state["state"], state["reason"]) == ("aborted", "operator abort (Ctrl-C)")
    assert [it["status"] for it in state["sweeps"]] == ["complete", "failed"]
    stopped, refused_attempt = state["sweeps"][0]["attempts"]  # the estop's, then the one the PLC refused
    assert stopped["path"] == str(out / "stops-1.attempt-1.h5") and "emergency stop" in stopped["reason"]
    assert refused_attempt["path"] is None and "PLC is in emergency stop" in refused_attempt["reason"]
    with h5py.File(out / "stops-1.attempt-1.h5") as f:
        assert f["entry"].attrs["status"] == "aborted"
    with h5py.File(out / "stops-1.h5") as f:
        assert f["entry"].attrs["status"] == "complete"
    with h5py.File(out / "stops-2.h5") as f:
        assert (f["entry"].attrs["status"], f["entry"].attrs["status_reason"]) == ("aborted", "operator abort (Ctrl-C)")
    st = _wait(lambda: (s := plc.status()).state != State.RUNNING and s, 30, "the table to stop")
    assert st.state == State.DONE and st.position_mm == 0.0  # a commanded stop, not the watchdog
    ended = _campaign(plan, cfg, out, "--resume")
    assert ended.returncode == 2 and "is aborted: nothing to resume" in ended.stderr
