"""End to end over loopback: `shakeid serve` (uvicorn, embedded simulated rig at 10x) and HTTP clients."""
from __future__ import annotations
import pytest

import json
import os
import signal
import threading

import h5py
import httpx
import numpy as np

from sim.rig import RigParameters

from .conftest import VIEWER, Service, jobs_seen, wait_for, wait_for_job, wait_while_moving
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SWEEP = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 40.0, "amplitude_mm": 1.3, "settle_s": 2.0}
#: a long sweep to stop or abort: 1 mm (at 1.3 mm a 120-300 s sweep hits the end stops: the preflight refuses it)
LONG = {**SWEEP, "amplitude_mm": 1.0}


def _read_live(url: str, rec_id: str, out: list, stop: threading.Event):
    try:
        _follow_live(url, rec_id, out, stop)
    except httpx.HTTPError as exc:  # the service went away: recorded, for the tests that expect it
        out.append(("error", str(exc)))


def _follow_live(url: str, rec_id: str, out: list, stop: threading.Event):
    with httpx.stream("GET", f"{url}/api/recordings/{rec_id}/live", headers={"Authorization": f"Bearer {VIEWER}"},
                      timeout=30) as r:
        event = None
        for line in r.iter_lines():
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: "):
                out.append((event, json.loads(line[6:])))
                if event == "end" or stop.is_set():
                    return


def test_sweep_live_model_and_the_rules_around_it(service):
    op, viewer, anon = service.client(), service.client(VIEWER), service.client(None)
    assert anon.get("/api/rig").status_code == 401
    assert viewer.post("/api/sweeps", json=SWEEP).status_code == 403
    unsafe = op.post("/api/sweeps", json={**SWEEP, "amplitude_mm": 9.0})
    assert unsafe.status_code == 422 and "stroke limit 5 mm" in unsafe.json()["detail"]
    # a request that moves the table takes JSON numbers only: true and "1" were read as 1.0 and a sweep ran
    for loose in (True, "1"):
        r = op.post("/api/sweeps", json={**SWEEP, "amplitude_mm": loose})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "amplitude_mm"], r.text
    r = op.post("/api/sweeps", json=SWEEP)
    assert r.status_code == 202, r.text
    sweep_id = r.json()["id"]
    busy = op.post("/api/sweeps", json=SWEEP)
    assert busy.status_code == 409 and sweep_id in busy.json()["detail"]
    # a reset while the sweep runs: nothing to reset, said so (not "the fault is still there; try again")
    reset = op.post("/api/rig/reset")
    assert reset.status_code == 409 and reset.json()["detail"].startswith(f"sweep {sweep_id} is running: there is "
                                                                          "nothing to reset"), reset.text
    rec_id = viewer.get(f"/api/sweeps/{sweep_id}").json()["recording_id"]
    assert viewer.get(f"/api/recordings/{rec_id}/file").status_code == 409  # not while it is written
    events, stop = [], threading.Event()
    reader = threading.Thread(target=_read_live, args=(service.url, rec_id, events, stop))
    reader.start()
    progress = wait_for(lambda: viewer.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.3, 60, "progress")
    assert progress
    reader.join(60)
    samples = [d for e, d in events if e == "samples"]
    assert samples and events[-1][0] == "end" and events[-1][1]["status"] == "complete"
    t = np.concatenate([d["t"] for d in samples])
    assert t.size > 40 * 150 and np.all(np.diff(t) > 0)  # ~200 points per second, in order, none twice
    assert max(abs(v) for d in samples for v in d["mass_acc"]) > 1.0  # the mass moves
    sweep = viewer.get(f"/api/sweeps/{sweep_id}").json()
    assert sweep["state"] == "completed" and sweep["progress"] == 1.0
    # the model appears with no further call: identification runs after every completed sweep
    model = wait_while_moving(lambda: (m := viewer.get(f"/api/recordings/{rec_id}/model")).status_code == 200
                              and m.json(), lambda: jobs_seen(viewer), what="model")
    truth = RigParameters.paper_table1().model().equations["q1_dot"]
    assert set(model["model"]["q1_dot"]) == set(truth)
    # the simulated rig's moving mass, recorded with the sweep, scales the physical parameters
    assert model["physical"]["mass_kg"] == RigParameters.paper_table1().mass_kg
    assert model["physical"]["mass_source"] == "recording"
    for term, c in truth.items():
        assert abs(model["model"]["q1_dot"][term] / c - 1) < 0.03, term
    plots = wait_while_moving(lambda: (p := viewer.get(f"/api/recordings/{rec_id}/plots")).status_code == 200 and
                              "validation.png" in p.json() and p.json(), lambda: jobs_seen(viewer), what="plots")
    png = viewer.get(f"/api/recordings/{rec_id}/plots/validation.png")
    assert png.headers["content-type"] == "image/png" and png.content[:8] == b"\x89PNG\r\n\x1a\n" and plots
    f = viewer.get(f"/api/recordings/{rec_id}/file")
    assert f.status_code == 200 and f.content[:8] == b"\x89HDF\r\n\x1a\n"
    assert viewer.get("/api/recordings/zzz/model").status_code == 422  # ids are checked before any lookup
    assert viewer.get("/api/recordings/0123456789ab").status_code == 404


def test_abort_mid_sweep_leaves_an_aborted_recording(service):
    op = service.client()
    sweep_id = op.post("/api/sweeps", json={**LONG, "duration_s": 120.0}).json()["id"]
    wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.1, 60, "progress")
    assert op.post(f"/api/sweeps/{sweep_id}/abort").status_code == 202
    sweep = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep_id}").json())["state"] != "running" and s, 30, "end")
    assert sweep["state"] == "aborted" and "operator abort" in sweep["error"]
    rec = op.get(f"/api/recordings/{sweep['recording_id']}").json()
    assert rec["status"] == "aborted" and rec["info"]["samples"] > 0
    assert op.post(f"/api/sweeps/{sweep_id}/abort").status_code == 409  # nothing left to abort
    none = op.get(f"/api/recordings/{rec['id']}/model")  # aborted: not identified, and the 404 says so
    assert none.status_code == 404 and none.json()["detail"] == (
        f"no identify result for recording {rec['id']}: none was asked for (POST /api/recordings/{rec['id']}/identify)")
    # no body: the CLI's defaults, as explain takes them (a 422 "Field required" before)
    job = op.post(f"/api/recordings/{rec['id']}/identify").json()  # refused data: the job fails ...
    assert rec["info"]["quality"]["usable_for_identification"] is False  # as the job will find
    assert rec["info"]["quality"]["reasons"][0].startswith("status is aborted")
    assert wait_for_job(op, lambda: op.get(f"/api/jobs/{job['id']}").json())["state"] == "failed"
    failed = op.get(f"/api/recordings/{rec['id']}/model").json()["detail"]  # ... and the 404 gives its reason
    assert failed.startswith(f"no identify result for recording {rec['id']}: its latest identify job {job['id']} "
                             "failed: ") and "status is aborted" in failed, failed


def test_emergency_stop_stops_the_simulated_table(service):
    op, viewer = service.client(), service.client(VIEWER)
    sweep_id = op.post("/api/sweeps", json={**LONG, "duration_s": 120.0}).json()["id"]
    wait_for(lambda: op.get("/api/rig").json()["plc"]["state"] == "running", 30, "running")
    assert viewer.post("/api/rig/estop").status_code == 403
    # emergency stop while other requests keep the service busy
    busy = [threading.Thread(target=lambda: [viewer.get("/api/rig") for _ in range(20)]) for _ in range(4)]
    for b in busy:
        b.start()
    r = op.post("/api/rig/estop")
    assert r.status_code == 200 and r.json()["aborted_sweep"] == sweep_id
    for b in busy:
        b.join()
    rig = wait_for(lambda: (p := op.get("/api/rig").json()["plc"])["position_mm"] == 0.0 and p, 10, "table at rest")
    assert rig["state"] == "estop"
    sweep = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep_id}").json())["state"] != "running" and s, 30, "end")
    assert sweep["state"] == "aborted" and "emergency stop" in sweep["error"]
    # a sweep while the PLC is in emergency stop: refused at once with the reason (409), nothing recorded
    n_sweeps = len(op.get("/api/sweeps").json())
    refused = op.post("/api/sweeps", json=SWEEP)
    assert refused.status_code == 409, refused.text
    assert "emergency stop" in refused.json()["detail"] and "reset it first" in refused.json()["detail"]
    assert len(op.get("/api/sweeps").json()) == n_sweeps
    reset = op.post("/api/rig/reset")
    assert reset.status_code == 200 and reset.json()["state"] == "idle"
    assert op.get("/api/rig").json()["plc"]["state"] == "idle"


def test_uploads_jobs_and_clear_errors(service, tmp_path, table1_run):
    from identify.data.recording import write_csv

    op, viewer = service.client(), service.client(VIEWER)
    csv = tmp_path / "sweep.csv"
    write_csv(csv, table1_run.recording)
    assert viewer.post("/api/recordings", params={"filename": "sweep.csv"}, content=csv.read_bytes()).status_code == 403
    r = op.post("/api/recordings", params={"filename": "sweep.csv"}, content=csv.read_bytes())
    assert r.status_code == 201, r.text
    rec = r.json()
    assert rec["origin"] == "upload" and rec["info"]["samples"] == table1_run.recording.n_samples
    job = op.post(f"/api/recordings/{rec['id']}/identify", json={"selection": "heldout", "max_terms": 8}).json()
    done = wait_for_job(viewer, lambda: viewer.get(f"/api/jobs/{job['id']}").json(), what="job")
    assert done["state"] == "completed", done
    model = viewer.get(f"/api/recordings/{rec['id']}/model").json()
    assert set(model["model"]["q1_dot"]) == {"q1", "q2", "q1*q2^2", "q2^3", "zdd"}
    bad = op.post("/api/recordings", params={"filename": "junk.csv"}, content=b"t,foo\n0,1\n1,2\n")
    assert bad.status_code == 422 and "junk.csv" in bad.json()["detail"]
    assert op.post("/api/recordings", params={"filename": "../etc/passwd.csv"}, content=b"x").status_code == 422
    # a file name the service does not take is said in words, not as pydantic's regex
    txt = op.post("/api/recordings", params={"filename": "notes.xlsx"}, content=b"x")
    assert txt.status_code == 422 and "ending in .h5, .hdf5, .csv, .txt, .mat, .tdms" in txt.json()["detail"][0]["msg"]
    assert "^[" not in txt.text
    assert op.post(f"/api/recordings/{rec['id']}/identify", json={"selection": "magic"}).status_code == 422
    assert op.post(f"/api/recordings/{rec['id']}/identify", json={"budget_refit": "heldout"}).status_code == 422
    failing = op.post(f"/api/recordings/{rec['id']}/identify", json={"extra_terms": ["warp(q1)"]}).json()
    failed = wait_for_job(viewer, lambda: viewer.get(f"/api/jobs/{failing['id']}").json(), what="job")
    assert failed["state"] == "failed" and "warp" in failed["error"]  # the user's mistake, named
    assert failed["error"].startswith(f"sweep.csv (recording {rec['id']}): "), failed["error"]  # and whose job
    # a read option that does not fit the file: the job names the recording as it was uploaded, with its
    # id, not by the server's own path to its store
    wrong = op.post(f"/api/recordings/{rec['id']}/identify", json={"input": "acc_base"}).json()
    wrong = wait_for_job(viewer, lambda: viewer.get(f"/api/jobs/{wrong['id']}").json(), what="job")
    assert wrong["state"] == "failed" and wrong["error"].startswith(f"sweep.csv (recording {rec['id']}): missing "
                                                                    "column"), wrong
    assert str(service.data_dir) not in wrong["error"]
    listed = {r["id"] for r in viewer.get("/api/recordings").json()}
    assert rec["id"] in listed and len(listed) == 1  # refused uploads left nothing behind
    assert sorted(p.name for p in (service.data_dir / "recordings").iterdir()) == [f"{rec['id']}.csv"]


def test_service_killed_mid_sweep_loses_nothing_and_recovers(tmp_path):
    """SIGKILL of `shakeid serve` mid-sweep: its rig controller sees the web server gone, stops the table,
    closes the file 'aborted' with the reason and exits; a restart finds everything in order."""
    svc = Service(tmp_path / "data").start()
    op = svc.client()
    sweep_id = op.post("/api/sweeps", json={**LONG, "duration_s": 120.0}).json()["id"]
    wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["progress"] > 0.2, 60, "progress")
    rec_id = op.get(f"/api/sweeps/{sweep_id}").json()["recording_id"]
    svc.stop(signal.SIGKILL)
    path = svc.data_dir / "recordings" / f"{rec_id}.h5"
    wait_for(lambda: not (svc.data_dir / "controller.sock").exists(), 30, "the controller to exit")
    with h5py.File(path) as f:
        assert f["entry"].attrs["status"] == "aborted" and f["entry/data/time"].shape[0] > 2048
        assert "web server went away" in f["entry"].attrs["status_reason"]
    svc.start()  # restart on the same data directory
    try:
        op = svc.client()
        sweep = op.get(f"/api/sweeps/{sweep_id}").json()
        assert sweep["state"] == "aborted" and "web server went away" in sweep["error"]
        rec = op.get(f"/api/recordings/{rec_id}").json()
        assert rec["status"] == "aborted"
        with h5py.File(path) as f:
            assert f["entry"].attrs["status"] == "aborted" and f["entry/data/time"].shape[0] > 2048
        assert op.post("/api/sweeps", json={**SWEEP, "duration_s": 5.0}).status_code == 202  # usable again
    finally:
        svc.stop()


def test_queued_and_interrupted_jobs_run_after_a_restart(tmp_path, table1_run):
    """Jobs live in the catalog: one queued and one left 'running' by a dead service both complete."""
    import time

    from identify.data.recording import write_csv
    from server.catalog import Catalog

    svc = Service(tmp_path / "data").start()
    csv = tmp_path / "s.csv"
    write_csv(csv, table1_run.recording)
    rec = svc.client().post("/api/recordings", params={"filename": "s.csv"}, content=csv.read_bytes()).json()
    svc.stop()
    cat = Catalog(svc.data_dir / "catalog.sqlite")
    for jid, st in (("00000000000a", "queued"), ("00000000000b", "running")):
        cat.insert("jobs", id=jid, created=time.time(), updated=time.time(), kind="identify", recording_id=rec["id"],
                   options={}, state=st, attempts=int(st == "running"), error=None,
                   result_dir=str(svc.data_dir / "results" / jid))
    cat.close()
    svc.start()
    try:
        op = svc.client()
        for jid in ("00000000000a", "00000000000b"):
            job = wait_for_job(op, lambda: op.get(f"/api/jobs/{jid}").json(), what=f"job {jid}")
            assert job["state"] == "completed", job
        assert op.get("/api/jobs/00000000000b").json()["attempts"] == 2  # re-run, counted
        assert "re-queued" in svc.output()
    finally:
        svc.stop()


def test_sigterm_mid_sweep_ends_the_recording_aborted_with_the_reason(tmp_path):
    """A supervisor stopping the service (SIGTERM) while a sweep runs and a live client listens: the
    table is stopped, the file closed 'aborted' with the reason, and the process exits promptly."""
    svc = Service(tmp_path / "data").start()
    op = svc.client()
    sweep_id = op.post("/api/sweeps", json={**LONG, "duration_s": 300.0}).json()["id"]
    rec_id = op.get(f"/api/sweeps/{sweep_id}").json()["recording_id"]
    events, stop = [], threading.Event()
    reader = threading.Thread(target=_read_live, args=(svc.url, rec_id, events, stop), daemon=True)
    reader.start()
    wait_for(lambda: len(events) > 3, 30, "live samples")
    svc.stop(signal.SIGTERM)
    reader.join(10)
    assert events[-1][0] == "end"  # the live client was told, not cut off
    # uvicorn exits by re-raising the signal once shut down (-15), the convention supervisors expect; a
    # process that hangs is killed by stop() after 20 s and shows -9 here
    assert svc.proc.returncode in (0, -signal.SIGTERM)
    assert "graceful shutdown exceeded" not in svc.output()  # the live stream did not hold it up (5 s)
    with h5py.File(svc.data_dir / "recordings" / f"{rec_id}.h5") as f:
        assert f["entry"].attrs["status"] == "aborted"
        assert "shutting down" in f["entry"].attrs["status_reason"] and f["entry/data/time"].shape[0] > 0


def test_explain_job_names_a_hidden_effect(service, tmp_path, make_run):
    """POST /explain on an uploaded sweep of a rig with hidden quadratic damping: the analysis names it and
    adding it closes the free-run gap; its figures are served."""
    from identify.data.recording import write_csv
    from protocol.sweep import SineSweep

    run = make_run(rig=RigParameters.design(effects={"quadratic_damping": 2.0}), sweep=SineSweep(1.0, 20.0, 30.0, 1.3),
                   fs_hz=1000.0, seed=5)  # the analysis tries every catalog effect, faults included: a short record
    csv = tmp_path / "qd.csv"
    write_csv(csv, run.recording)
    op = service.client()
    rec = op.post("/api/recordings", params={"filename": "qd.csv"}, content=csv.read_bytes()).json()
    job = op.post(f"/api/recordings/{rec['id']}/explain", json={})
    assert job.status_code == 202 and job.json()["kind"] == "explain"
    done = wait_for_job(op, lambda jid=job.json()["id"]: op.get(f"/api/jobs/{jid}").json(), what="the explain job")
    assert done["state"] == "completed", done
    result = op.get(f"/api/recordings/{rec['id']}/explanation").json()
    assert result["effect"] == "quadratic_damping" and result["gap_after"] < 0.5 * result["gap_before"]
    figures = op.get(f"/api/recordings/{rec['id']}/plots", params={"kind": "explain"}).json()
    assert {"residual_time.png", "candidates.png", "gap.png"} <= set(figures)
    png = op.get(f"/api/recordings/{rec['id']}/plots/gap.png", params={"kind": "explain"})
    assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
    assert op.get(f"/api/recordings/{rec['id']}/model").status_code == 404  # explained, not identified


def test_dashboard_is_served_and_calls_only_real_endpoints(service):
    """The dashboard page and its scripts: served without a token (it asks for one), and every API path
    its scripts call exists in the OpenAPI document with that method (so the page cannot drift from the API)."""
    import re

    page = httpx.get(service.url + "/")
    assert page.status_code == 200 and "EMERGENCY STOP" in page.text
    scripts = re.findall(r'<script src="(/static/[a-z]+\.js)"', page.text)
    assert len(scripts) >= 3
    text = page.text
    for src in scripts:
        js = httpx.get(service.url + src)
        assert js.status_code == 200 and "javascript" in js.headers["content-type"], src
        text += js.text
    assert httpx.get(service.url + "/static/../app.py").status_code == 404  # only the shipped files
    spec = httpx.get(service.url + "/openapi.json").json()["paths"]
    calls = re.findall(r'api\("(GET|POST)", `?"?(/api/[^`"?]+)', text)
    calls += [("GET", p) for p in re.findall(r'(?:new EventSource\(|href=")`?(/api/[^`"?]+)', text)]
    assert len(calls) >= 15
    for method, path in calls:
        template = re.sub(r"\$\{[^}]+\}", "{x}", path)
        matches = [p for p in spec if re.fullmatch(re.sub(r"\{[^}]+\}", "[^/]+", p), template)]
        assert matches and any(method.lower() in spec[p] for p in matches), (method, path)


def test_joint_and_job_requests_are_checked_when_made(service, tmp_path, table1_run):
    """What a job would fail on is refused with the request: a recording given twice to a joint fit (its
    evidence counted twice, every standard error shrunk by sqrt(2); a copy uploaded under another id fails
    its job, naming both uploads), a band or rows out of order. A joint fit
    reads each recording as it was uploaded (a MAT file with its own variable names); explain needs no body;
    the dashboard's recordings carry no server path."""
    from scipy.io import savemat

    from identify.data.recording import write_csv

    op = service.client()
    rec = table1_run.recording
    write_csv(tmp_path / "sweep.csv", rec)
    savemat(tmp_path / "lab.mat", {"acc_base": rec.input, "acc_mass": rec.output})
    csv_id = op.post("/api/recordings", params={"filename": "sweep.csv"},
                     content=(tmp_path / "sweep.csv").read_bytes()).json()["id"]
    mat_id = op.post("/api/recordings", content=(tmp_path / "lab.mat").read_bytes(),
                     params={"filename": "lab.mat", "input": "acc_base", "output": "acc_mass",
                             "fs_hz": rec.fs_hz}).json()["id"]
    twice = op.post("/api/identify", json={"recording_ids": [csv_id, csv_id]})
    assert twice.status_code == 422 and twice.json()["detail"].startswith(f"recording(s) {csv_id} given more than once")
    # the same file uploaded twice (two ids): the job refuses it, naming both uploads as uploaded
    copy_id = op.post("/api/recordings", params={"filename": "again.csv"},
                      content=(tmp_path / "sweep.csv").read_bytes()).json()["id"]
    copied = op.post("/api/identify", json={"recording_ids": [csv_id, copy_id], "placements": 0}).json()
    failed = wait_for_job(op, lambda: op.get(f"/api/jobs/{copied['id']}").json(), what="joint job of a copy")
    assert failed["state"] == "failed" and failed["error"].startswith(
        f"again.csv (recording {copy_id}) holds the same samples as sweep.csv (recording {csv_id}) (a copy?)"), failed
    for body in ({"band_hz": [20, 1]}, {"samples": [500, 100]}):
        bad = op.post(f"/api/recordings/{csv_id}/identify", json=body)
        assert bad.status_code == 422 and "must satisfy" in bad.text, bad.text
    explain = op.post(f"/api/recordings/{csv_id}/explain")  # no body: the defaults
    assert explain.status_code == 202, explain.text
    joint = op.post("/api/identify", json={"recording_ids": [csv_id, mat_id], "placements": 0})
    assert joint.status_code == 202, joint.text
    done = wait_for_job(op, lambda: op.get(f"/api/jobs/{joint.json()['id']}").json(), what="joint job")
    assert done["state"] == "completed", done  # the MAT file read with its own names, as uploaded
    listed = op.get("/api/dashboard/recordings").json()["items"]
    assert listed and all("path" not in r for r in listed)
    assert "path" not in op.get(f"/api/dashboard/recordings/{csv_id}").json()
    # not left running into the next test
    wait_for_job(op, lambda: op.get(f"/api/jobs/{explain.json()['id']}").json(), what="explain job")


def test_mat_and_hdf5_uploads(service, tmp_path, table1_run):
    """A MAT file with the lab's own variable names (read options as query parameters) and an HDF5
    recording of the DAQ: both accepted, read as a job reads them, and identified."""
    from scipy.io import savemat

    from daq.recorder import Recorder

    rec = table1_run.recording
    savemat(tmp_path / "lab.mat", {"acc_base": rec.input, "acc_mass": rec.output})
    h5 = tmp_path / "daq.h5"
    r = Recorder(h5, fs_hz=rec.fs_hz)
    r.append(0, np.column_stack([rec.input, rec.output]))
    r.close()
    op = service.client()
    mat = op.post("/api/recordings", content=(tmp_path / "lab.mat").read_bytes(),
                  params={"filename": "lab.mat", "input": "acc_base", "output": "acc_mass", "fs_hz": rec.fs_hz})
    assert mat.status_code == 201, mat.text
    assert op.post("/api/recordings", params={"filename": "lab.mat"},  # default column names: not there
                   content=(tmp_path / "lab.mat").read_bytes()).status_code == 422
    up = op.post("/api/recordings", params={"filename": "daq.h5"}, content=h5.read_bytes())
    assert up.status_code == 201 and up.json()["info"]["samples"] == rec.n_samples
    # an HDF5 recording without a channel the job would read: refused on arrival, like a CSV without its
    # column (not stored, to fail later as a job naming the server's own path)
    import h5py

    with h5py.File(h5, "r+") as f:
        del f["entry/data/mass_acc"]
    nomass = op.post("/api/recordings", params={"filename": "nomass.h5"}, content=h5.read_bytes())
    assert nomass.status_code == 422, nomass.text
    assert nomass.json()["detail"] == "nomass.h5: missing channel(s) ['mass_acc']; found ['table_acc']"
    assert nomass.json()["detail"].count("/") == 0  # no path of the server's
    for rid in (mat.json()["id"], up.json()["id"]):
        job = op.post(f"/api/recordings/{rid}/identify", json={}).json()
        done = wait_for_job(op, lambda: op.get(f"/api/jobs/{job['id']}").json(), what="job")
        assert done["state"] == "completed", done
        model = op.get(f"/api/recordings/{rid}/model").json()
        assert set(model["model"]["q1_dot"]) == {"q1", "q2", "q1*q2^2", "q2^3", "zdd"}


def test_ctrl_c_in_a_terminal_stops_the_service_without_tracebacks(tmp_path):
    """A terminal's Ctrl-C sends SIGINT to the whole process group: the service, its rig controller and
    its job workers. The service stops its children; each worker printed a KeyboardInterrupt traceback."""
    s = Service(tmp_path / "data", own_group=True).start()
    try:
        def workers():
            kids = []
            for pid in os.listdir("/proc"):
                try:
                    stat = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
                    cmd = open(f"/proc/{pid}/cmdline", "rb").read()
                except (OSError, IndexError):
                    continue
                if pid.isdigit() and int(stat[1]) == s.proc.pid and b"multiprocessing" in cmd:
                    kids.append(int(pid))
            return kids
        def ignoring_sigint(pid: int) -> bool:  # /proc/PID/status SigIgn: the mask of ignored signals
            try:
                lines = open(f"/proc/{pid}/status").read().splitlines()
            except OSError:
                return False
            mask = next(int(ln.split()[1], 16) for ln in lines if ln.startswith("SigIgn:"))
            return bool(mask & (1 << (signal.SIGINT - 1)))

        # every worker up and past its initializer (which is what ignores SIGINT): no sleep to guess it
        wait_for(lambda: (kids := workers()) and all(ignoring_sigint(k) for k in kids), 120, "the job workers")
        os.killpg(s.proc.pid, signal.SIGINT)
        s.proc.wait(30)
        out = s.output()
        assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
    finally:
        s.stop()
