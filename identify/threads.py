"""BLAS threads where they do not pay: one, for the whole of a fit.

numpy's OpenBLAS starts one thread per core (2 here). The identification's BLAS work is many small
products: BlockGram.from_library's ~120 GEMMs of 8192 x 18 per million samples, Welch's per-segment
lines (identify.chain.spectral.welch_psd), the noise's share, the path's small solves. A second thread costs
more in hand-over than it saves, and on a loaded machine (the service's job workers, `shakeid batch`,
Dask workers beside each other, other users) the threads oversubscribe the cores and spin. Measured at
1e6 samples (docs/identification.md, "Threads"): welch_psd of two channels alone 0.056 s CPU with one
thread against 0.17-0.30 s with OpenBLAS's default 2 at load ~4; the earlier limit on from_library alone
left the fit at 1.4-1.6x the one-thread CPU under load.

The limit is set in the library, at the public entry points (SparseIdentifier.fit, the out-of-core
fit_source, the discrepancy analysis), so every caller (CLI, batch, job workers, Dask workers, a
notebook) runs under it. threadpoolctl's limit is process-wide, so overlapping fits in threads of one
process (a Dask worker's threads) share one limit: the first to enter sets it, the last to leave
restores what was there (a reference count), never one fit restoring two threads under another.
threadpoolctl (3.8) lets only the thread that first set a limit change OpenBLAS's while it lives; in a
Dask worker that is the first task thread, whose limit of one then stays (what the worker wants).
threadpoolctl is the standard control (scikit-learn uses it the same way).

Threads that do pay: the explanation's shooting runs (map_runs). A shooting refit's finite-difference
Jacobian is one full multiple-shooting run per coefficient, each independent of the others, and the
compiled kernels that do most of a run release the GIL; so the columns, a round's candidate refits and the
masking check's refits run side by side on the cores this process may use, and a run asked for outside the
threads (a refit's trial step, a one-column Jacobian) splits its segments over them (usable_cores, at most
MAX_RUN_THREADS). Each run computes what it would alone and the results are taken in order: the numbers
are those of the serial loop, bit for bit (tests/identify/test_threads.py)."""
from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import scipy.linalg  # noqa: F401  (loads scipy's BLAS, if it is its own, before the libraries are listed)
from threadpoolctl import ThreadpoolController

#: the loaded BLAS libraries, found once (a fresh threadpool_limits scans them on every call)
_CONTROLLER = ThreadpoolController()
_LOCK = threading.Lock()
_HOLDERS = 0  # fits running under the limit in this process
_LIMITER = None  # threadpoolctl's limiter while _HOLDERS > 0 (restores the previous limits)


def one_blas_thread(fn):
    """Run fn with BLAS limited to one thread; the previous limit restored when the last such call in
    the process returns."""
    @functools.wraps(fn)
    def limited(*args, **kwargs):
        global _HOLDERS, _LIMITER
        with _LOCK:
            if _HOLDERS == 0:
                _LIMITER = _CONTROLLER.limit(limits=1, user_api="blas")
            _HOLDERS += 1
        try:
            return fn(*args, **kwargs)
        finally:
            with _LOCK:
                _HOLDERS -= 1
                if _HOLDERS == 0:
                    _LIMITER.restore_original_limits()
                    _LIMITER = None
    return limited


def blas_threads() -> int:
    """The BLAS thread count now in force (the largest over the loaded BLAS libraries)."""
    return max((lib.num_threads for lib in _CONTROLLER.select(user_api="blas").lib_controllers), default=1)


#: Most threads one explanation's shooting runs use at once (identify.explain: the columns of a finite-
#: difference Jacobian, each a full multiple-shooting run of the model with one coefficient moved). The
#: compiled kernels (identify/_simkernel.c) release the GIL for a run's segments (one call per run thread,
#: simulate_segments) and a pass over the rows, most of a run's time, so two columns run side by side on two
#: cores, and a run asked for outside the threads splits its segments over them.
MAX_RUN_THREADS = 4

_POOL = None  # (pid, threads, ThreadPoolExecutor): made on first use, again in a forked child (its threads are gone)
_POOL_LOCK = threading.Lock()


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity (taskset, a container's --cpuset-cpus), not a CPU
    quota (--cpus), which leaves every core visible; set RUN_THREADS_ENV where a quota applies."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


#: Environment variable that sets run_threads() (e.g. 1 in a worker that shares its cores with others, or
#: to time the serial explanation: the numbers are the same). The service's job workers get their share of
#: the cores (share_cores); docker-compose's Dask workers, one thread each, set it to 1.
RUN_THREADS_ENV = "SHAKEID_RUN_THREADS"


def _env_threads() -> str:
    """RUN_THREADS_ENV as set ('' when not)."""
    return os.environ.get(RUN_THREADS_ENV, "").strip()


def run_threads() -> int:
    """How many threads map_runs uses: RUN_THREADS_ENV when set, else usable_cores(), at most
    MAX_RUN_THREADS."""
    value = _env_threads()
    if value:
        if not (value.isascii() and value.isdigit() and int(value) >= 1):
            raise ValueError(f"{RUN_THREADS_ENV}={value!r}: give a whole number of threads, 1 or more")
        return min(int(value), MAX_RUN_THREADS)
    return max(1, min(usable_cores(), MAX_RUN_THREADS))


def share_cores(processes: int) -> None:
    """In one of `processes` worker processes on this machine: run_threads() becomes its share of the
    cores (at least 1), unless RUN_THREADS_ENV is set already (a pool initializer: server.worker)."""
    if not _env_threads():
        os.environ[RUN_THREADS_ENV] = str(max(1, usable_cores() // max(1, processes)))


def map_runs(fn, items) -> list:
    """[fn(x) for x in items], the calls spread over run_threads() threads, the results in order. For
    independent runs that spend their time in the compiled kernels (each call computes what it would
    alone, so the numbers are those of the serial loop, bit for bit). scipy's least_squares takes it as
    `workers` for its finite-difference Jacobian."""
    items = list(items)
    n = run_threads()
    if n == 1 or len(items) < 2 or threading.current_thread().name.startswith("shakeid-run"):
        return [fn(x) for x in items]  # one core, one item, or already on a run thread: no nesting
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL[:2] != (os.getpid(), n):
            # a new count gets a new pool; the old one is not shut down (a call that took it just before may
            # still be submitting to it): its idle threads end when it is collected
            _POOL = (os.getpid(), n, ThreadPoolExecutor(max_workers=n, thread_name_prefix="shakeid-run"))
        pool = _POOL[2]
    return list(pool.map(fn, items))


def _after_fork_in_child() -> None:
    """A forked child has none of the parent's threads, and a lock another thread held at the fork stays
    held: the child starts with no pool and fresh locks."""
    global _POOL, _POOL_LOCK, _LOCK
    _POOL, _POOL_LOCK, _LOCK = None, threading.Lock(), threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)
