"""The job queue on its own: real worker processes, a real SQLite catalog."""
import os
import signal
import time

import pytest

from identify.recording import write_csv
from server.catalog import Catalog
from server.jobs import JobQueue

from .conftest import wait_for


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


def test_a_killed_worker_fails_its_job_with_the_reason_and_the_next_job_runs(queue):
    cat, jobs = queue
    # a slow job (free-run refit) so it is still running when its worker is killed
    victim = jobs.submit("identify", "0000000000aa", {"refine": "free-run"})
    wait_for(lambda: cat.get("jobs", victim["id"])["state"] == "running", 30, "running")
    time.sleep(0.3)
    for pid in list(jobs.pool._processes):
        os.kill(pid, signal.SIGKILL)
    failed = wait_for(lambda: (j := cat.get("jobs", victim["id"]))["state"] != "running" and j, 30, "failure")
    assert failed["state"] == "failed" and "worker process died" in failed["error"]
    after = jobs.submit("identify", "0000000000aa", {})
    done = wait_for(lambda: (j := cat.get("jobs", after["id"]))["state"] in ("completed", "failed") and j, 60, "job")
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
    assert cat.get("jobs", job["id"])["state"] == "running"  # re-queued by recover_after_restart next time
    assert cat.recover_after_restart() == [f"job {job['id']}: re-queued after a restart"]
