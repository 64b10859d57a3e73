"""The service's jobs on a Dask cluster ([compute] scheduler): real `dask scheduler` + `dask worker`
processes on loopback (the dask_cluster fixture), a distributed.LocalCluster for the quicker cases, and a
scheduler that is not there (the job fails saying so, the service keeps answering)."""
import json
import time
from pathlib import Path

import pytest

from identify.data.recording import write_csv
from server.catalog import Catalog
from server.dask_backend import DaskPool
from server.jobs import JobQueue
from server.settings import Settings, SettingsError
from shakeid.batch_cmd import worker_name
from sim.server import free_port
from protocol.sweep import SineSweep

from .conftest import OPERATOR, Service, wait_for

SHORT = SineSweep(1.0, 20.0, 25.0, 1.3)  # 25 s at 1024 Hz: identifies the Table 1 terms in ~1 s


@pytest.fixture(scope="module")
def short_csv(make_run, tmp_path_factory):
    path = tmp_path_factory.mktemp("dask-rec") / "short.csv"
    write_csv(path, make_run(sweep=SHORT, fs_hz=1024.0).recording)
    return path


def _catalog(tmp_path, csv: Path, rec_id: str = "0000000000aa") -> Catalog:
    cat = Catalog(tmp_path / "catalog.sqlite")
    cat.insert("recordings", id=rec_id, created=time.time(), origin="upload", filename=csv.name, path=str(csv),
               status="complete", sweep_id=None, info={})
    return cat


def _finished(cat, job_id, timeout_s=90):
    return wait_for(lambda: (j := cat.get("jobs", job_id))["state"] in ("completed", "failed") and j, timeout_s,
                    f"job {job_id}")


@pytest.mark.slow
def test_jobs_run_on_separate_dask_worker_processes_and_write_the_same_result_files(dask_cluster, tmp_path,
                                                                                     short_csv, true_q1_terms):
    pool = DaskPool(dask_cluster)
    try:  # the pool really dispatches to the cluster's workers (their addresses, not this process)
        where = {pool.submit(worker_name).result(60) for _ in range(4)}
        assert where and all(w.startswith("tcp://127.0.0.1:") for w in where)
        assert pool.capacity() == 2  # two workers of one thread each
    finally:
        pool.shutdown()
    cat = _catalog(tmp_path, short_csv)
    jobs = JobQueue(cat, tmp_path / "results", scheduler=dask_cluster)
    jobs.start()
    try:
        submitted = [jobs.submit("identify", "0000000000aa", {}) for _ in range(2)]
        for job in submitted:
            done = _finished(cat, job["id"])
            assert done["state"] == "completed", done
            model = json.loads((Path(job["result_dir"]) / "model.json").read_text())
            assert {t for t, c in model["model"]["q1_dot"].items() if c} == true_q1_terms
            assert (Path(job["result_dir"]) / "report" / "index.html").exists()
        info = cat.get("recordings", "0000000000aa")["info"]
        assert info["last_identify_job"] in {j["id"] for j in submitted}
        assert set(info["identify"]["terms"]["q1_dot"]) == true_q1_terms
    finally:
        jobs.stop()
        cat.close()


@pytest.mark.slow
def test_a_refused_recording_fails_its_job_with_the_reason_through_a_local_cluster(tmp_path, short_csv,
                                                                                  true_q1_terms):
    from distributed import LocalCluster

    bad = tmp_path / "bad.csv"
    bad.write_text("t,table_acc\n0,1\n0.001,2\n")  # no mass_acc column
    cat = _catalog(tmp_path, short_csv)
    cat.insert("recordings", id="0000000000bb", created=time.time(), origin="upload", filename="bad.csv",
               path=str(bad), status="complete", sweep_id=None, info={})
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as cluster:  # :0, not 8787: others may hold it
        jobs = JobQueue(cat, tmp_path / "results", scheduler=cluster.scheduler_address)
        jobs.start()
        try:
            failed = _finished(cat, jobs.submit("identify", "0000000000bb", {})["id"])
            good = _finished(cat, jobs.submit("identify", "0000000000aa", {})["id"])
        finally:
            jobs.stop()
    assert failed["state"] == "failed"
    # named as it was uploaded, with its id, not by the path on the worker's disk
    assert failed["error"] == "bad.csv (recording 0000000000bb): missing column(s) 'mass_acc'; found 't', 'table_acc'"
    assert good["state"] == "completed", good
    assert set(cat.get("recordings", "0000000000aa")["info"]["identify"]["terms"]["q1_dot"]) == true_q1_terms
    cat.close()


@pytest.mark.slow
def test_an_unreachable_scheduler_fails_the_job_with_the_reason_and_the_service_keeps_answering(tmp_path,
                                                                                                short_csv):
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    service = Service(tmp_path / "data", env={"SHAKEID_SCHEDULER": address}).start()
    try:
        op = service.client(OPERATOR)
        rec = op.post("/api/recordings", params={"filename": "short.csv"}, content=short_csv.read_bytes())
        assert rec.status_code == 201, rec.text
        job = op.post(f"/api/recordings/{rec.json()['id']}/identify", json={}).json()
        answered = 0
        while (state := op.get(f"/api/jobs/{job['id']}").json())["state"] in ("queued", "running"):
            assert op.get("/api/health").status_code == 200  # while the dispatcher waits for the scheduler
            answered += 1
            assert answered < 600, "the job never ended"
            time.sleep(0.1)
        assert state["state"] == "failed"
        assert state["error"].startswith(f"cannot reach the Dask scheduler {address}"), state["error"]
        assert answered > 0 and op.get("/api/health").status_code == 200
    finally:
        service.stop()


def test_compute_settings_are_read_and_checked(tmp_path):
    cfg = tmp_path / "rig.toml"
    cfg.write_text('[compute]\nscheduler = "tcp://dask-scheduler:8786"\nconnect_timeout_s = 3\n')
    s = Settings.load(cfg, env={})
    assert (s.scheduler, s.connect_timeout_s) == ("tcp://dask-scheduler:8786", 3.0)
    assert Settings.load(cfg, env={"SHAKEID_SCHEDULER": "tcp://10.0.0.9:8786"}).scheduler == "tcp://10.0.0.9:8786"
    assert Settings.load(None, env={}).scheduler is None  # default: the embedded process pool
    cfg.write_text('[compute]\nschedular = "tcp://x:8786"\n')
    with pytest.raises(SettingsError, match=r"unknown key\(s\) in \[compute\]: schedular"):
        Settings.load(cfg, env={})
    cfg.write_text('[compute]\nscheduler = "dask-scheduler"\n')
    with pytest.raises(SettingsError, match="Dask address like tcp://"):
        Settings.load(cfg, env={})
