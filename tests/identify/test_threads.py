"""BLAS limited to one thread for the whole of a fit (identify.threads), shared by overlapping fits in
threads of one process (a Dask worker's), and the process's own limit back when the last one leaves."""
import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from identify.threads import blas_threads, one_blas_thread


def test_overlapping_calls_hold_one_limit_and_the_last_restores_it():
    """A fit in the process's main thread, another in a worker thread entering and leaving meanwhile (a
    Dask worker's threads): both run on one thread, the short one's exit does not restore the limit under
    the long one, and the process's own setting is back once both are done. (threadpoolctl lets only the
    thread that first set a limit change OpenBLAS's, while it lives: here the main thread.)"""
    before = blas_threads()
    seen = {}

    @one_blas_thread
    def short_fit():
        seen["short"] = blas_threads()

    @one_blas_thread
    def long_fit():
        seen["long, on entry"] = blas_threads()
        t = threading.Thread(target=short_fit)
        t.start()
        t.join(timeout=60)
        seen["long, after the short one left"] = blas_threads()

    long_fit()
    assert seen == {"long, on entry": 1, "short": 1, "long, after the short one left": 1}
    assert blas_threads() == before


def test_a_fit_runs_on_one_blas_thread_and_gives_the_limit_back():
    from identify.identifier import SparseIdentifier
    from identify.regression.library import Library

    seen = []
    evaluate = Library.evaluate

    def watched(self, *args, **kwargs):  # the library's own evaluation, watched for the limit in force
        seen.append(blas_threads())
        return evaluate(self, *args, **kwargs)

    rng = np.random.default_rng()
    fs, n = 1000.0, 40_000
    t = np.arange(n) / fs
    zdd = np.sin(2 * np.pi * (1.0 + 0.1 * t) * t) + 0.01 * rng.standard_normal(n)
    x = np.zeros(2)
    out = np.empty(n)
    for i in range(n):  # a linear oscillator, 5 Hz, damped, driven by the base: enough to fit
        a = -(2 * np.pi * 5) ** 2 * x[1] - 2.0 * x[0] - zdd[i]
        x[0] += a / fs
        x[1] += x[0] / fs
        out[i] = a + zdd[i]
    from identify.data.recording import Recording

    rec = Recording(zdd, out + 0.01 * rng.standard_normal(n), fs)
    with threadpool_limits(limits=2, user_api="blas"):
        Library.evaluate = watched
        try:
            SparseIdentifier(validate=False, placements=0).fit(rec)
        finally:
            Library.evaluate = evaluate
        assert seen and set(seen) == {1}
        assert blas_threads() == 2


# -- the explanation's shooting runs in threads (identify.threads.map_runs) ------------------------------

def test_map_runs_keeps_the_order_runs_on_several_threads_and_does_not_nest(monkeypatch):
    """Results in the order of the items; the first two calls meet at a barrier, so they must be on two
    threads at once (one thread would time out there); a map_runs called from a run thread runs its items
    right there, on that thread (a bounded pool waiting on itself would hang)."""
    import identify.threads as th

    monkeypatch.setattr(th, "run_threads", lambda: 2)
    monkeypatch.setattr(th, "_POOL", None)  # a pool of its own, not one an earlier test left
    meet = threading.Barrier(2, timeout=30)

    def inner(x):
        return x, threading.current_thread().name

    def outer(x):
        if x < 2:
            meet.wait()  # BrokenBarrierError unless the other call runs at the same time
        return x * x, threading.current_thread().name, th.map_runs(inner, range(3))

    out = th.map_runs(outer, range(6))
    assert [o[0] for o in out] == [x * x for x in range(6)]
    assert out[0][1] != out[1][1] and all(name.startswith("shakeid-run") for _, name, _ in out)
    for _, name, nested in out:  # each nested item on the outer call's own thread
        assert nested == [(0, name), (1, name), (2, name)]
    monkeypatch.setattr(th, "run_threads", lambda: 1)
    assert {n for _, n in th.map_runs(inner, range(4))} == {threading.current_thread().name}


def _child_maps(queue):
    import identify.threads as th

    th.run_threads = lambda: 2
    queue.put(th.map_runs(lambda x: x + 1, range(5)))


def test_map_runs_works_in_a_forked_child_of_a_process_that_used_it(monkeypatch):
    """A worker forked after the parent ran threads: the child's pool is its own (the parent's threads do
    not exist in it), not a pool whose workers never answer."""
    import multiprocessing

    import identify.threads as th

    monkeypatch.setattr(th, "run_threads", lambda: 2)
    assert th.map_runs(lambda x: x, range(4)) == [0, 1, 2, 3]  # the parent's pool exists now
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_child_maps, args=(queue,), daemon=True)
    child.start()
    try:
        assert queue.get(timeout=60) == [1, 2, 3, 4, 5]
        child.join(timeout=60)
        assert child.exitcode == 0
    finally:
        if child.is_alive():
            child.kill()


def test_a_job_worker_takes_its_share_of_the_cores(monkeypatch):
    """share_cores (the service's job-worker initializer): the cores split between the workers, at least one
    thread each; a value the operator set stays."""
    import identify.threads as th

    monkeypatch.setattr(th, "usable_cores", lambda: 4)
    for workers, threads in ((1, 4), (2, 2), (3, 1), (8, 1)):
        monkeypatch.delenv(th.RUN_THREADS_ENV, raising=False)
        th.share_cores(workers)
        assert th.run_threads() == threads
    monkeypatch.setenv(th.RUN_THREADS_ENV, "3")
    th.share_cores(2)
    assert th.run_threads() == 3


@pytest.mark.slow
def test_an_explanation_in_threads_is_the_serial_one_to_the_last_digit(monkeypatch):
    """The rounds' refits, their Jacobians' columns, the polish and the masking check's screen and refits run
    side by side; each run computes what it would alone and the results are taken in order, so the whole
    document is the serial one, float for float (Coulomb 0.1 N + quadratic damping 1 N s^2/m^2: every one
    of those paths runs, test_masking)."""
    import json

    import identify.threads as th
    from identify.explain.workflow import DiscrepancyAnalysis

    from .test_explain_effects import _run

    rec = _run({"coulomb_friction": 0.1, "quadratic_damping": 1.0})
    docs = {}
    for n in (1, 2):
        monkeypatch.setattr(th, "run_threads", lambda: n)
        docs[n] = json.dumps(DiscrepancyAnalysis().fit(rec).result(), sort_keys=True, default=str)
    assert json.loads(docs[1])["effects"][1].get("masked_by") == "coulomb_friction"  # the masking path ran
    assert docs[2] == docs[1]


def test_the_run_threads_follow_the_environment_and_refuse_nonsense(monkeypatch):
    """SHAKEID_RUN_THREADS sets the count (capped at MAX_RUN_THREADS); unset, the usable cores; a value that
    is not a whole number of threads is refused in words, not read as 0 or ignored."""
    import identify.threads as th

    monkeypatch.setenv(th.RUN_THREADS_ENV, "1")
    assert th.run_threads() == 1
    monkeypatch.setenv(th.RUN_THREADS_ENV, "64")
    assert th.run_threads() == th.MAX_RUN_THREADS
    monkeypatch.delenv(th.RUN_THREADS_ENV)
    assert th.run_threads() == max(1, min(th.usable_cores(), th.MAX_RUN_THREADS))
    for bad in ("0", "two", "-1", "1.5", "\u00b2"):
        monkeypatch.setenv(th.RUN_THREADS_ENV, bad)
        with pytest.raises(ValueError, match="whole number of threads"):
            th.run_threads()
