"""The rig controller as a process of its own: the web server can die, be busy or restart, and the table
still stops; nothing of a killed service lives on. Real processes on loopback: `shakeid sim`, `shakeid
serve`, `shakeid controller`, a Modbus client reading the PLC."""
from __future__ import annotations

import os
import signal
import subprocess
import threading
from pathlib import Path

import h5py
import httpx
import numpy as np
import pytest

from daq.plc import ModbusPLC
from protocol.plc import Fault, State

from .conftest import SHAKEID, Service, wait_for
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

#: a long sweep to stop or abort: 1 mm (at 1.3 mm a 120-300 s sweep hits the end stops: the preflight refuses it)
SWEEP = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 300.0, "amplitude_mm": 1.0, "settle_s": 1.0}


def _descendants(pid: int) -> set[int]:
    """Every process below pid (read from /proc), so they can be followed after pid itself is gone."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.add(child)
            todo.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited; only its parent's bookkeeping is left


def test_killing_the_service_stops_the_table_and_leaves_no_process(tmp_path, sim_rig):
    """SIGKILL of `shakeid serve` mid-sweep: its controller stops the table (a commanded stop, state DONE,
    not the PLC's watchdog), closes the file 'aborted' with the reason, and every process of the
    service's tree (controller, job worker, resource tracker) exits."""
    cfg, modbus = sim_rig
    svc = Service(tmp_path / "data", args=("--config", str(cfg))).start()
    op = svc.client()
    sweep_id = op.post("/api/sweeps", json=SWEEP).json()["id"]
    wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.05, 60, "progress")
    rec_id = op.get(f"/api/sweeps/{sweep_id}").json()["recording_id"]
    tree = _descendants(svc.proc.pid)
    assert len(tree) >= 3, tree  # the controller, a job worker, multiprocessing's resource tracker
    controller = next(p for p in tree if b"controller" in Path(f"/proc/{p}/cmdline").read_bytes())
    if os.geteuid() == 0:  # where allowed, the controller is real-time (daq/realtime.py)
        assert os.sched_getscheduler(controller) == os.SCHED_RR
    svc.stop(signal.SIGKILL)
    wait_for(lambda: not any(_alive(p) for p in tree), 30, f"the service's processes {tree} to exit")
    plc = ModbusPLC("127.0.0.1", modbus)
    try:
        st = wait_for(lambda: (s := plc.status()).state != State.RUNNING and abs(s.position_mm) < 1e-9 and s, 10,
                      "the table at rest")
        assert st.state == State.DONE and st.fault_code == Fault.NONE, st  # stopped by the controller
    finally:
        plc.close()
    with h5py.File(svc.data_dir / "recordings" / f"{rec_id}.h5") as f:
        assert f["entry"].attrs["status"] == "aborted" and f["entry/data/time"].shape[0] > 2048
        assert "web server went away" in f["entry"].attrs["status_reason"]


def test_a_controller_of_its_own_outlives_its_web_server(tmp_path):
    """`shakeid controller` run alone, `shakeid serve --controller`: the web server dies mid-sweep, the
    controller stops the sweep and stays; a new web server attaches and runs the next sweep."""
    data = tmp_path / "data"
    address = f"unix:{data.resolve() / 'controller.sock'}"
    log = open(tmp_path / "controller.log", "w")
    ctl = subprocess.Popen([SHAKEID, "controller", "--data-dir", str(data), "--sim-speed", "10"], stdout=log,
                           stderr=subprocess.STDOUT)
    try:
        svc = Service(data, args=("--controller", address)).start()
        op = svc.client()
        assert op.get("/api/health").json()["controller"] == "attached"
        sweep_id = op.post("/api/sweeps", json=SWEEP).json()["id"]
        wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.05, 60, "progress")
        svc.stop(signal.SIGKILL)
        svc.start()  # a new web server on the same data directory attaches to the same controller
        op = svc.client()
        sweep = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep_id}").json())["state"] != "running" and s, 30,
                         "the sweep to end")
        assert sweep["state"] == "aborted" and "web server went away" in sweep["error"]
        assert ctl.poll() is None  # the controller stayed
        again = op.post("/api/sweeps", json={**SWEEP, "duration_s": 20.0})
        assert again.status_code == 202, again.text
        done = wait_for(lambda: (s := op.get(f"/api/sweeps/{again.json()['id']}").json())["state"] not in
                        ("queued", "running") and s, 60, "the second sweep")
        assert done["state"] == "completed", done
        svc.stop()
        assert ctl.poll() is None  # an orderly stop of the web server does not stop a controller of its own
    finally:
        ctl.send_signal(signal.SIGTERM)
        assert ctl.wait(20) == 0
        log.close()
    assert "stopped (the rig controller was stopped (SIGTERM))" in (tmp_path / "controller.log").read_text()


def test_a_dead_controller_is_restarted_and_the_service_reattaches(service):
    op = service.client()
    pid = next(p for p in _descendants(service.proc.pid) if b"controller" in Path(f"/proc/{p}/cmdline").read_bytes())
    os.kill(pid, signal.SIGKILL)
    wait_for(lambda: not _alive(pid), 10, "the controller to die")
    wait_for(lambda: op.get("/api/health").json()["controller"] == "attached" and
             op.get("/api/rig").status_code == 200, 60, "a new controller")
    assert "starting it again" in service.output()
    r = op.post("/api/rig/estop")
    assert r.status_code == 200 and op.get("/api/rig").json()["plc"]["state"] == "estop"
    assert op.post("/api/rig/reset").json()["state"] == "idle"


@pytest.fixture(scope="module")
def big_csv(tmp_path_factory) -> Path:
    """A valid recording of >= 100 MB (3.5 M rows at 2048 Hz: a 1 Hz table motion and a noisy response)."""
    path = tmp_path_factory.mktemp("upload") / "big.csv"
    rng = np.random.default_rng(0)
    n, rows_per_block = 3_500_000, 500_000
    with open(path, "w") as f:
        f.write("t,table_acc,mass_acc\n")
        for a in range(0, n, rows_per_block):
            k = np.arange(a, min(n, a + rows_per_block))
            t = k / 2048.0
            table = np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(k.size)
            mass = 1.2 * np.sin(2 * np.pi * t - 0.3) + 0.01 * rng.standard_normal(k.size)
            np.savetxt(f, np.column_stack([t, table, mass]), fmt="%.9f,%.7f,%.7f")
    assert path.stat().st_size >= 100 * 2**20
    return path


def _upload(url: str, path: Path, result: dict, started: threading.Event):
    def body():
        with open(path, "rb") as f:
            while chunk := f.read(2**20):
                started.set()
                yield chunk
    headers = {"Authorization": "Bearer operator-token-for-tests", "Content-Length": str(path.stat().st_size)}
    try:
        r = httpx.post(f"{url}/api/recordings", params={"filename": "big.csv"}, content=body(), headers=headers,
                       timeout=600)
        result.update(status=r.status_code, body=r.json())
    except httpx.HTTPError as exc:
        result.update(status=None, error=str(exc))
    result["done"] = True


def test_a_large_upload_delays_neither_the_sweep_nor_the_emergency_stop(service, big_csv):
    """A >= 100 MB CSV uploaded and checked while sweeping: the sweep completes (heartbeats did not
    starve), the upload is stored. Then with a second upload in flight, the emergency stop answers and
    reaches the PLC: the table comes to rest."""
    op = service.client()
    sweep_id = op.post("/api/sweeps", json={**SWEEP, "duration_s": 120.0}).json()["id"]
    result, started = {}, threading.Event()
    uploader = threading.Thread(target=_upload, args=(service.url, big_csv, result, started))
    uploader.start()
    sweep = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep_id}").json())["state"] not in ("queued", "running")
                     and s, 120, "the sweep")
    uploader.join(600)
    assert sweep["state"] == "completed", sweep
    assert result["status"] == 201, result
    assert result["body"]["info"]["samples"] == 3_500_000

    sweep_id = op.post("/api/sweeps", json=SWEEP).json()["id"]
    wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.02, 60, "progress")
    result, started = {}, threading.Event()
    uploader = threading.Thread(target=_upload, args=(service.url, big_csv, result, started))
    uploader.start()
    assert started.wait(30)
    r = op.post("/api/rig/estop")
    in_flight = not result.get("done")
    assert r.status_code == 200 and r.json()["aborted_sweep"] == sweep_id
    rig = wait_for(lambda: (p := op.get("/api/rig").json()["plc"])["position_mm"] == 0.0 and p, 10, "table at rest")
    assert rig["state"] == "estop"
    uploader.join(600)
    assert in_flight and result["status"] == 201, result  # the stop went through while the upload was running
    assert op.post("/api/rig/reset").json()["state"] == "idle"


def test_upload_over_the_limit_is_refused_before_it_is_read(tmp_path):
    svc = Service(tmp_path / "data", env={"SHAKEID_MAX_UPLOAD_MB": "1"}).start()
    try:
        r = svc.client().post("/api/recordings", params={"filename": "x.csv"}, content=b"t,a\n" * 300_000)
        assert r.status_code == 413 and "limit of 1 MB" in r.json()["detail"]
        assert not list((svc.data_dir / "recordings").iterdir())  # nothing kept, not even a partial file
    finally:
        svc.stop()
