"""BLAS limited to one thread for the whole of a fit (identify.threads), shared by overlapping fits in
threads of one process (a Dask worker's), and the process's own limit back when the last one leaves."""
import threading

import numpy as np
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
