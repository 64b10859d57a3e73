"""The service's job backend on an existing Dask cluster ([compute] scheduler = "tcp://HOST:PORT").

DaskPool stands in for the ProcessPoolExecutor of server/jobs.py: the dispatcher submits the same worker
function (server/worker.run_job) with the same arguments and gets a concurrent.futures.Future back, so
the catalog, the result files and the job states are the same whichever backend ran the job.

The workers write the result files themselves: the service's data directory must be mounted at the same
path on every Dask worker (docker-compose.yml mounts the shakeid-data volume at /data in both).

The scheduler is reached lazily, when a job is submitted, so a scheduler that is down never stops the
service from starting or answering: the job fails with the reason ("cannot reach the Dask scheduler
...") and the next job tries again.
"""
from __future__ import annotations

import threading
import time
from concurrent.futures import Future

from identify.errors import ShakeidError

#: seconds to wait for the scheduler when connecting (the dispatcher thread waits, not the web server)
CONNECT_TIMEOUT_S = 10.0
#: seconds between asking the scheduler how many worker threads the cluster has
CAPACITY_REFRESH_S = 5.0


class DaskPool:
    """submit()/shutdown() as concurrent.futures executors, on the Dask scheduler at `address`."""

    def __init__(self, address: str, connect_timeout_s: float = CONNECT_TIMEOUT_S):
        self.address, self.connect_timeout_s = address, connect_timeout_s
        self._client = None
        self._lock = threading.Lock()
        self._capacity, self._capacity_at = 1, 0.0
        self._futures: set = set()  # distributed futures in flight (held so the scheduler keeps them)

    def _connected(self):
        """The client, (re)connected if needed; ShakeidError naming the scheduler when it cannot be."""
        with self._lock:
            if self._client is not None and self._client.status == "running":
                return self._client
            if self._client is not None:
                self._client.close(timeout=2)
                self._client = None
            from distributed import Client

            try:
                self._client = Client(self.address, timeout=self.connect_timeout_s, set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise ShakeidError(f"cannot reach the Dask scheduler {self.address}: {exc}") from None
            return self._client

    def capacity(self) -> int:
        """Jobs to keep in flight: the cluster's worker threads (at least 1, so a job still goes out
        and fails with the reason when the scheduler is down). Asked at most every few seconds."""
        now = time.monotonic()
        if now - self._capacity_at > CAPACITY_REFRESH_S:
            self._capacity_at = now
            client = self._client
            try:
                if client is not None and client.status == "running":
                    self._capacity = max(1, sum(client.nthreads().values()))
            except Exception:  # noqa: BLE001 - the scheduler went away: a submit will say so
                self._capacity = 1
        return self._capacity

    def submit(self, fn, *args) -> Future:
        out: Future = Future()
        out.set_running_or_notify_cancel()
        try:
            client = self._connected()
            fut = client.submit(fn, *args, pure=False)
        except ShakeidError as exc:
            out.set_exception(exc)
            return out
        except Exception as exc:  # noqa: BLE001 - the connection broke while submitting
            out.set_exception(ShakeidError(f"the Dask scheduler {self.address} failed the submission: {exc}"))
            return out
        self._futures.add(fut)
        fut.add_done_callback(lambda f: self._settle(f, out))
        return out

    def _settle(self, fut, out: Future) -> None:
        """Copy a finished distributed future into the executor-style future the dispatcher watches."""
        self._futures.discard(fut)
        try:
            if fut.status == "finished":
                out.set_result(fut.result())
            elif fut.status == "cancelled":  # the client lost the scheduler, or the scheduler lost the task
                out.set_exception(ShakeidError(f"the Dask scheduler {self.address} lost this job "
                                               "(scheduler stopped or connection lost)"))
            else:
                exc = fut.exception()
                if type(exc).__name__ == "KilledWorker":
                    exc = ShakeidError("the Dask workers running this job died (killed or out of memory)")
                out.set_exception(exc)
        except Exception as exc:  # noqa: BLE001 - whatever reading the outcome raised is the job's error
            if not out.done():
                out.set_exception(ShakeidError(f"the Dask scheduler {self.address}: {type(exc).__name__}: {exc}"))

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        """Let go of the cluster: jobs still on it are cancelled (they stay "running" in the catalog and
        are re-queued on the next start, as with the process pool)."""
        with self._lock:
            client, self._client = self._client, None
        if client is not None:
            if cancel_futures and self._futures:
                try:
                    client.cancel(list(self._futures))
                except Exception:  # noqa: BLE001 - the scheduler is gone already
                    pass
            client.close(timeout=5)
