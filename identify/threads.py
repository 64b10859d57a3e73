"""BLAS threads where they do not pay: one.

numpy's OpenBLAS starts 2 threads here (one per core). The identification's BLAS work is many small
products (BlockGram.from_library: ~120 GEMMs of 8192 x 18 per million samples), where a second thread
costs more in hand-over than it saves (measured: 84 ms CPU with 2 threads against 26 ms with one for
those ~120), and on a loaded machine (the service's job workers, `shakeid batch`, Dask workers beside each
other) the threads oversubscribe the cores: a 1e6-sample fit took 3-59x the CPU time. The limit is set in
the library, at the call site, so every caller (CLI, batch, job workers, Dask) runs under it.
threadpoolctl is the standard control (scikit-learn uses it the same way)."""
from __future__ import annotations

import functools

import scipy.linalg  # noqa: F401  (loads scipy's BLAS, if it is its own, before the libraries are listed)
from threadpoolctl import ThreadpoolController

#: the loaded BLAS libraries, found once (a fresh threadpool_limits scans them on every call)
_CONTROLLER = ThreadpoolController()


def one_blas_thread(fn):
    """Run fn with BLAS limited to one thread (the previous limit restored after)."""
    @functools.wraps(fn)
    def limited(*args, **kwargs):
        with _CONTROLLER.limit(limits=1, user_api="blas"):
            return fn(*args, **kwargs)
    return limited
