"""`shakeid rig status|reset|estop --server URL` and `shakeid recordings --server URL`: the real CLI against a
real `shakeid serve` with its embedded simulated rig (which has no --config to reach it by)."""
import pytest
import json
import subprocess

from .conftest import OPERATOR, VIEWER
from .test_remote_cli import SHAKEID
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def _cli(*args, token=OPERATOR):
    return subprocess.run([SHAKEID, *args, "--token", token], capture_output=True, text=True, timeout=120)


def test_the_embedded_rig_is_stopped_and_reset_from_the_command_line(service):
    status = _cli("rig", "status", "--server", service.url, "--json", token=VIEWER)
    assert status.returncode == 0, status.stderr
    assert json.loads(status.stdout)["state"] in ("idle", "done")
    stop = _cli("rig", "estop", "--server", service.url)
    assert stop.returncode == 0 and "emergency stop: the PLC is in estop" in stop.stdout, stop.stdout + stop.stderr
    with service.client() as op:
        refused = op.post("/api/sweeps", json={"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 30.0,
                                               "amplitude_mm": 1.0})
        assert refused.status_code == 409
        # the message points to a command that works here: the one run next
        assert "`shakeid rig reset --server URL`" in refused.json()["detail"], refused.text
    viewer = _cli("rig", "reset", "--server", service.url, token=VIEWER)
    assert viewer.returncode == 2 and "403" in viewer.stderr and "operator role" in viewer.stderr
    reset = _cli("rig", "reset", "--server", service.url)
    assert reset.returncode == 0 and "reset: the PLC is idle" in reset.stdout, reset.stdout + reset.stderr
    assert "state idle" in _cli("rig", "status", "--server", service.url, token=VIEWER).stdout
    with service.client() as op:
        started = op.post("/api/sweeps", json={"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 30.0,
                                               "amplitude_mm": 1.0})
        assert started.status_code == 202, started.text
        op.post(f"/api/sweeps/{started.json()['id']}/abort")


def test_each_rig_action_has_its_own_help_and_needs_a_server_or_a_config():
    helps = {a: subprocess.run([SHAKEID, "rig", a, "--help"], capture_output=True, text=True).stdout
             for a in ("status", "reset", "estop")}
    top = subprocess.run([SHAKEID, "rig", "--help"], capture_output=True, text=True).stdout
    assert len({*helps.values(), top}) == 4
    assert "emergency stop" in helps["estop"] and "clear a fault" in helps["reset"] and "read the PLC" in helps["status"]
    neither = subprocess.run([SHAKEID, "rig", "status"], capture_output=True, text=True)
    assert neither.returncode == 2 and "one of the arguments --server --config is required" in neither.stderr


def test_recordings_lists_the_service_s_recordings(service, tmp_path, table1_run):
    from identify.data.recording import write_csv

    empty = _cli("recordings", "--server", service.url, token=VIEWER)
    assert empty.returncode == 0 and "0 recording(s) on" in empty.stdout, empty.stdout + empty.stderr
    csv = tmp_path / "r.csv"
    write_csv(csv, table1_run.recording)
    with service.client() as op:
        rec_id = op.post("/api/recordings?filename=r.csv", content=csv.read_bytes()).json()["id"]
    listed = _cli("recordings", "--server", service.url, token=VIEWER)
    assert listed.returncode == 0 and rec_id in listed.stdout and "upload" in listed.stdout and "r.csv" in listed.stdout
    assert "1 recording(s) on" in listed.stdout
    as_json = _cli("recordings", "--server", service.url, "--json", token=VIEWER)
    assert json.loads(as_json.stdout.splitlines()[0])["id"] == rec_id
