"""The job queue on its own: real worker processes, a real SQLite catalog. The waits' bounds are generous
(minutes): a job takes seconds idle and several times that on a loaded machine (the suite must pass at load
10); a bound only stops a hung test."""
import os
import signal
import time
from pathlib import Path

import pytest

from identify.data.recording import write_csv
from server.catalog import Catalog
from server.jobs import JobQueue

from .conftest import job_ended, wait_for, wait_while_moving, workers_cpu_s


@pytest.fixture
def queue(tmp_path, table1_run):
    """A catalog with one uploaded recording (id 0000000000aa) and a started one-worker job queue."""
    cat = Catalog(tmp_path / "catalog.sqlite")
    csv = tmp_path / "r.csv"
    write_csv(csv, table1_run.recording)
    cat.insert("recordings", id="0000000000aa", created=time.time(), origin="upload", filename="r.csv", path=str(csv),
               status="complete", sweep_id=None, info={})
    jobs = JobQueue(cat, tmp_path / "results", workers=1)
    jobs.start()
    yield cat, jobs
    jobs.stop()  # returns at once when already stopped
    cat.close()


@pytest.mark.slow
def test_a_killed_worker_fails_its_job_with_the_reason_and_the_next_job_runs(queue):
    cat, jobs = queue
    # a slow job (free-run refit) so it is still running when its worker is killed
    victim = jobs.submit("identify", "0000000000aa", {"refine": "free-run"})
    wait_for(lambda: cat.get("jobs", victim["id"])["state"] == "running", 120, "running")
    time.sleep(0.3)
    for pid in list(jobs.pool._processes):
        os.kill(pid, signal.SIGKILL)
    failed = wait_for(lambda: (j := cat.get("jobs", victim["id"]))["state"] != "running" and j, 120, "failure")
    assert failed["state"] == "failed" and "worker process died" in failed["error"]
    after = jobs.submit("identify", "0000000000aa", {})
    done = _completed(cat, after["id"])
    assert done["state"] == "completed", done
    assert cat.get("recordings", "0000000000aa")["info"]["identify"]["terms"]["q1_dot"]


def test_stopping_with_a_job_running_returns_and_leaves_it_for_the_next_start(queue):
    import threading

    cat, jobs = queue
    job = jobs.submit("identify", "0000000000aa", {"refine": "free-run"})
    wait_for(lambda: cat.get("jobs", job["id"])["state"] == "running", 30, "running")
    stopper = threading.Thread(target=jobs.stop)
    stopper.start()
    stopper.join(30)
    assert not stopper.is_alive(), "JobQueue.stop() hung with a job running"
    # parked: queued again, the attempt not counted (a stop is not the job's fault); nothing to recover
    parked = cat.get("jobs", job["id"])
    assert parked["state"] == "queued" and parked["attempts"] == 0 and "parked" in parked["error"], parked
    assert cat.recover_after_restart() == []


def _jobs_seen(cat):
    """What moves in the queue: every job's state and attempts, and the CPU its workers (this process's
    pool) have used: a job starved at nice +10 on a busy machine runs long without a state change."""
    return {(j["id"], j["state"], j["attempts"]) for j in cat.list("jobs", limit=500)}, int(workers_cpu_s(os.getpid()))


def _completed(cat, job_id):
    """The job once it has ended, waited for as long as the queue moves (conftest.wait_while_moving)."""
    return wait_while_moving(job_ended(lambda: cat.get("jobs", job_id)), lambda: _jobs_seen(cat), what="the job")


@pytest.mark.slow
def test_a_job_whose_result_was_delivered_adopts_it_when_run_again(queue):
    """The service was killed after model.json was written, before the staged report was renamed (and
    after two attempts): the job is re-queued, not failed, and its re-run adopts the delivered model (the
    same bytes, no new fit) and puts the report in place."""
    cat, jobs = queue
    job = jobs.submit("identify", "0000000000aa", {})
    assert _completed(cat, job["id"])["state"] == "completed"
    out = Path(job["result_dir"])
    delivered = (out / "model.json").read_bytes()
    (out / "report").rename(out / "report.partial")  # as if killed between the result file and the rename
    cat.update("jobs", job["id"], state="running", attempts=2)
    assert cat.recover_after_restart() == [f"job {job['id']}: its result was delivered before the restart; "
                                           "re-queued to adopt it"]
    jobs.wake()
    done = _completed(cat, job["id"])
    assert done["state"] == "completed", done
    assert (out / "model.json").read_bytes() == delivered
    assert (out / "report" / "index.html").is_file() and not (out / "report.partial").exists()


@pytest.mark.slow
def test_a_half_written_report_of_an_interrupted_run_does_not_fail_the_re_run(queue):
    """An interrupted run left a staged report without its index.html and no model.json (the fit was not
    delivered): the re-run starts from a clean staging folder and completes."""
    cat, jobs = queue
    jobs.stop()
    job = jobs.submit("identify", "0000000000aa", {})
    staging = Path(job["result_dir"]) / "report.partial"
    staging.mkdir(parents=True)
    (staging / "input.png").write_bytes(b"half")
    (staging / "model.json").write_text("{")
    again = JobQueue(cat, Path(job["result_dir"]).parent, workers=1)
    again.start()
    try:
        done = _completed(cat, job["id"])
    finally:
        again.stop()
    assert done["state"] == "completed", done
    assert (staging.parent / "report" / "index.html").is_file() and not staging.exists()


@pytest.mark.slow
def test_a_sweep_completed_while_the_web_server_was_down_is_identified_when_it_starts(tmp_path, table1_run, make_run):
    """The rig controller only records (it never writes the jobs table): a complete sweep recording and a
    completed campaign that nobody queued, as after a web server that was down when they ended, get their
    identification and their joint identification on the next start, each once; an aborted recording none."""
    cat = Catalog(tmp_path / "catalog.sqlite")
    ids = ["0000000000b1", "0000000000b2", "0000000000b3"]
    for k, (rec_id, status) in enumerate(zip(ids, ("complete", "complete", "aborted"))):
        csv = tmp_path / f"{rec_id}.csv"
        write_csv(csv, (table1_run if k == 0 else make_run(seed=k)).recording)  # two runs: a joint fit refuses copies
        cat.insert("recordings", id=rec_id, created=time.time() + k, origin="sweep", filename=csv.name,
                   path=str(csv), status=status, sweep_id=None, info={"kept": k})
    cat.insert("campaigns", id="00000000c0c0", created=time.time(), state="completed", recording_ids=ids[:2])
    jobs = JobQueue(cat, tmp_path / "results", workers=1)
    jobs.start()
    try:
        try:
            wait_while_moving(lambda: cat.count("jobs", "state IN ('completed', 'failed')") == 3,
                              lambda: _jobs_seen(cat), what="the three owed jobs done")
        except AssertionError:
            raise AssertionError([(j["kind"], j["recording_id"], j["state"], j["error"]) for j in cat.list("jobs")])
        jobs.recording_completed()  # a late event: nothing more is owed
        wait_for(lambda: not jobs._owed.is_set(), what="the dispatcher's look at what is owed")
    finally:
        jobs.stop()
    done = cat.list("jobs", limit=10)
    assert sorted((j["kind"], j["recording_id"]) for j in done) == [
        ("identify", ids[0]), ("identify", ids[1]), ("identify_joint", ids[0])]
    assert all(j["state"] == "completed" for j in done), [(j["kind"], j["state"], j["error"]) for j in done]
    assert next(j for j in done if j["kind"] == "identify_joint")["options"]["recording_ids"] == ids[:2]
    # the model's summary was added to the recording's info, what was there kept
    info = cat.get("recordings", ids[0])["info"]
    assert info["kept"] == 0 and info["last_identify_job"] and info["identify"]["terms"]
    cat.close()


def test_no_owed_jobs_are_queued_without_auto_identification(tmp_path):
    cat = Catalog(tmp_path / "catalog.sqlite")
    cat.insert("recordings", id="0000000000b1", created=time.time(), origin="sweep", filename="x.h5",
               path=str(tmp_path / "x.h5"), status="complete", sweep_id=None, info={})
    jobs = JobQueue(cat, tmp_path / "results", workers=1, auto_identify=False)
    jobs.recording_completed()  # the controller's event, before the dispatcher's first look at the queue
    # a job of a recording not in the catalog: failed by the dispatcher's first turn, which would have queued
    # what is owed before it (so its end, not a wait of some length, says the turn is over)
    marker = jobs.submit("identify", "0000000000ff")
    jobs.start()
    try:
        assert cat.queries.owed_jobs() == [("identify", "0000000000b1", {})]  # owed, yet not queued
        wait_for(lambda: cat.get("jobs", marker["id"])["state"] == "failed", what="the dispatcher's first turn")
        assert [j["id"] for j in cat.list("jobs")] == [marker["id"]]
    finally:
        jobs.stop()
        cat.close()


def test_info_keys_are_set_beside_the_others_and_a_non_finite_value_is_stored_as_null(tmp_path):
    """Catalog.set_info (the rig controller's sweep outcome, the dispatcher's job summary): the keys it sets
    are added, the others kept; a non-finite float (a fit's -inf percent) is null, never a failed write."""
    cat = Catalog(tmp_path / "catalog.sqlite")
    cat.insert("recordings", id="0000000000b1", created=time.time(), origin="sweep", filename="x.h5",
               path=str(tmp_path / "x.h5"), status="running", sweep_id=None, info={"sweep": {"note": "kept"}})
    cat.set_info("0000000000b1", status_reason=None, quality={"flags": 0})
    cat.set_info("0000000000b1", identify={"fit_percent": float("-inf"), "gap": [1.0, float("nan")]},
                 last_identify_job="0000000000j1")
    assert cat.get("recordings", "0000000000b1")["info"] == {
        "sweep": {"note": "kept"}, "status_reason": None, "quality": {"flags": 0},
        "identify": {"fit_percent": None, "gap": [1.0, None]}, "last_identify_job": "0000000000j1"}
    cat.close()
