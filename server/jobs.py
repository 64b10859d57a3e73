"""Identification jobs: queued in the catalog, run in a process pool, outside the event loop.

A dispatcher thread takes queued jobs in order and keeps up to `workers` of them in the pool; each job
writes into <data_dir>/results/<job id>/. With a Dask scheduler ([compute] scheduler, server/settings.py)
the same jobs go to that cluster instead (server/dask_backend.py), as many at a time as it has worker
threads; same worker function, same result files. Jobs outlive the service: the queue is the catalog, and on
start `Catalog.recover_after_restart` puts jobs a dead service left running back in the queue.

The web server is the jobs table's one writer. The rig controller only records: when a sweep or a campaign
completes it says so (an event on its link), and the dispatcher queues what auto-identification owes
(`NamedQueries.owed_jobs`: every complete sweep recording without an identification, every completed
campaign without a joint one). The catalog, not the event, is the truth: on start the dispatcher queues
what is owed, so a recording that completed while the web server was down is identified all the same.
"""
from __future__ import annotations

import multiprocessing
import os
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from identify.errors import ShakeidError

from . import worker
from .catalog import Catalog, delivered, new_id

#: how long a stopping service waits for a running job whose result is already delivered, s (what is left
#: is the report folder's rename: milliseconds; the bound only guards against a stuck worker)
FINISH_GRACE_S = 5.0


def queue_job(catalog: Catalog, results_dir: Path, kind: str, recording_id: str, options: dict | None = None) -> dict:
    """Put a job in the catalog's queue (JobQueue's; nothing else writes the jobs table)."""
    job_id = new_id()
    return catalog.insert("jobs", id=job_id, created=time.time(), updated=time.time(), kind=kind,
                          recording_id=recording_id, options=options or {}, state="queued", attempts=0,
                          error=None, result_dir=str(Path(results_dir) / job_id))


class JobQueue:
    def __init__(self, catalog: Catalog, results_dir: Path, workers: int = 1, scheduler: str | None = None,
                 connect_timeout_s: float = 10.0, auto_identify: bool = True):
        """auto_identify: queue what NamedQueries.owed_jobs finds (on start and after each controller event)."""
        self.catalog, self.results_dir, self.workers = catalog, Path(results_dir), workers
        self.auto_identify = auto_identify
        self._owed = threading.Event()  # look for owed jobs at the next turn of the dispatcher
        if auto_identify:
            self._owed.set()
        self.scheduler, self.connect_timeout_s = scheduler, connect_timeout_s
        self.pool = self._new_pool()
        self._wake = threading.Event()
        self._stop = self._terminating = False
        self._running: dict[str, Future] = {}
        self._pool_lock = threading.Lock()
        self._thread = threading.Thread(target=self._dispatch, name="job-dispatcher", daemon=True)

    def _new_pool(self):
        if self.scheduler:
            from .dask_backend import DaskPool

            return DaskPool(self.scheduler, self.connect_timeout_s)
        # spawn, not fork: the service has threads (uvicorn, rig, dispatcher) a fork would copy mid-flight
        pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=worker.die_with_parent, initargs=(os.getpid(), self.workers))
        for _ in range(self.workers):
            pool.submit(worker.warm_up)  # imports numpy/scipy/matplotlib now, not in the first job
        return pool

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """Stop taking jobs (a graceful stop: SIGTERM). A running job whose result is delivered is let
        finish (only the report's rename is left; at most FINISH_GRACE_S); the others are stopped with their
        worker and parked: queued again, the attempt not counted (a stop is not the job's fault), so the next
        start runs them. A job left "running" (the service was killed) is recovered on the next start
        (Catalog.recover_after_restart)."""
        self._stop = True
        self._wake.set()
        self._thread.join(5)
        for job_id, fut in list(self._running.items()):
            job = self.catalog.get("jobs", job_id)
            if job is not None and delivered(job):
                wait([fut], timeout=FINISH_GRACE_S)
        self._terminating = True  # from here a job's end is the stop's doing, not the job's
        with self._pool_lock:
            pool = self.pool
        for job_id in list(self._running):
            job = self.catalog.get("jobs", job_id)
            if job is not None and job["state"] == "running":
                self.catalog.update("jobs", job_id, state="queued", attempts=max(0, job["attempts"] - 1),
                                    error="parked: the service stopped during this job; it runs again on the next start")
        for proc in list((getattr(pool, "_processes", None) or {}).values()):  # None once shut down
            proc.terminate()
        # not under the lock: shutdown joins the pool's manager thread, which runs _done callbacks
        pool.shutdown(wait=True, cancel_futures=True)

    def submit(self, kind: str, recording_id: str, options: dict | None = None) -> dict:
        job = queue_job(self.catalog, self.results_dir, kind, recording_id, options)
        self._wake.set()
        return job

    def wake(self) -> None:
        """Look at the queue now, not at the next poll."""
        self._wake.set()

    def recording_completed(self) -> None:
        """The rig controller completed a sweep or a campaign: queue what auto-identification owes now."""
        if self.auto_identify:
            self._owed.set()
            self._wake.set()

    def _queue_owed(self) -> None:
        self._owed.clear()
        for kind, recording_id, options in self.catalog.queries.owed_jobs():
            queue_job(self.catalog, self.results_dir, kind, recording_id, options)

    def _dispatch(self) -> None:
        while not self._stop:
            if self._owed.is_set():
                self._queue_owed()
            with self._pool_lock:
                pool = self.pool
            capacity = pool.capacity() if self.scheduler else self.workers
            job = self.catalog.next_queued_job() if len(self._running) < capacity else None
            if job is None:
                self._wake.wait(0.5)
                self._wake.clear()
                continue
            rec = self.catalog.get("recordings", job["recording_id"])
            if rec is None:
                self.catalog.update("jobs", job["id"], state="failed", error="recording no longer in the catalog")
                continue
            path, recs = os.path.abspath(rec["path"]), [rec]
            if job["kind"] in worker.SEVERAL_KINDS:  # several recordings: options name them all, in order
                recs = [self.catalog.get("recordings", r) for r in job["options"].get("recording_ids", [])]
                if any(r is None for r in recs) or len(recs) < 2:
                    what = "joint identification" if job["kind"] == "identify_joint" else "campaign's explanation"
                    self.catalog.update("jobs", job["id"], state="failed",
                                        error=f"a {what} needs two or more recordings in the catalog")
                    continue
                path = [os.path.abspath(r["path"]) for r in recs]
            self.catalog.update("jobs", job["id"], state="running", attempts=job["attempts"] + 1)
            with self._pool_lock:
                pool = self.pool
            # absolute paths: a Dask worker does not share our working directory (the data dir must be
            # mounted at the same path there)
            # the names its errors give the recordings (worker._public): an upload as uploaded, with its id
            names = {os.path.abspath(r["path"]): f"{r['filename']} (recording {r['id']})" for r in recs
                     if r.get("origin") == "upload" and r.get("filename")}
            fut = pool.submit(worker.run_job, job["kind"], path, {**job["options"], "display_names": names},
                              os.path.abspath(job["result_dir"]))
            self._running[job["id"]] = fut
            fut.add_done_callback(lambda f, jid=job["id"], rid=rec["id"], kind=job["kind"], p=pool:
                                  self._done(jid, rid, kind, f, p))

    def _done(self, job_id: str, recording_id: str, kind: str, fut: Future, broken_pool=None) -> None:
        self._running.pop(job_id, None)
        if fut.cancelled() or self._terminating:
            return  # stopped by the service's stop: parked by stop()
        exc = fut.exception()
        if exc is None:
            summary = fut.result()
            # the recording's summary first, then the job's state: whoever sees the job completed (a client
            # polling it, then reading the recording) finds the summary there (the other order left a
            # window, seen once under load by tests/server/test_jobs.py)
            self.catalog.set_info(recording_id, **{f"last_{kind}_job": job_id, kind: summary})
            self.catalog.update("jobs", job_id, state="completed", error=None)
        elif isinstance(exc, BrokenProcessPool):
            # a worker died (killed, out of memory, a crash in native code): this job fails with that
            # reason, later ones get a new pool
            self.catalog.update("jobs", job_id, state="failed",
                                error="the identification worker process died during this job (killed or out of memory)")
            with self._pool_lock:
                if self.pool is broken_pool:
                    self.pool.shutdown(wait=False, cancel_futures=True)
                    self.pool = self._new_pool()
        elif isinstance(exc, ShakeidError):
            self.catalog.update("jobs", job_id, state="failed", error=str(exc))
        else:
            self.catalog.update("jobs", job_id, state="failed", error=f"internal error: {type(exc).__name__}: {exc}")
        self._wake.set()
