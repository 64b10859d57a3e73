"""A real `shakeid serve` process (uvicorn) with its embedded simulated rig, on a free loopback port."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from sim.server import free_port

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
OPERATOR, VIEWER = "operator-token-for-tests", "viewer-token-for-tests"
#: how long a start may take before it counts as hung: a hang guard, not a speed target (at load 15-20 on 2 cores
#: starts took over 60 s)
START_TIMEOUT_S = 240
#: how long a test's request may wait for its answer: a hang guard too (an upload is checked by a process at
#: nice +10, which a machine at load 10 starves: a 10 s bound timed out there)
REQUEST_TIMEOUT_S = 120


class Service:
    """One service process; start() again on the same data_dir is a restart."""

    def __init__(self, data_dir: Path, speed: float = 10.0, env: dict | None = None, args: tuple = (),
                 own_group: bool = False):
        """own_group: the service leads its own process group, as in a terminal (a Ctrl-C reaches all of it)."""
        self.data_dir, self.speed, self.extra_env, self.args = data_dir, speed, env or {}, tuple(args)
        self.own_group = own_group
        self.proc: subprocess.Popen | None = None
        self.port = 0

    def start(self, attempts: int = 3) -> "Service":
        """Start the process on a free port; another port when the bind lost a race for it (free_port draws
        below the ephemeral range, but another server started meanwhile, the service's own embedded rig
        included, may draw the same port: seen once in a suite run as "address already in use")."""
        attempt = 0
        while True:
            attempt += 1
            self.port = free_port()  # below the ephemeral range: no client socket can take it before the bind
            env = {**os.environ, "SHAKEID_TOKENS": f"{OPERATOR}:operator,{VIEWER}:viewer", **self.extra_env}
            self.log = open(self.data_dir.parent / f"serve-{self.port}.log", "w")
            self.proc = subprocess.Popen([SHAKEID, "serve", "--data-dir", str(self.data_dir), "--port",
                                          str(self.port), "--sim-speed", str(self.speed), *self.args],
                                         stdout=self.log, stderr=subprocess.STDOUT, env=env,
                                         start_new_session=self.own_group)
            end = time.monotonic() + START_TIMEOUT_S
            while True:
                try:
                    if httpx.get(self.url + "/api/health", timeout=1).status_code == 200:
                        return self
                except httpx.HTTPError:
                    pass
                if self.proc.poll() is not None:
                    break
                if time.monotonic() >= end:  # stopped, not left behind: its real-time controller would starve the rest
                    self.stop()
                    raise AssertionError("service did not start: " + self.output())
                time.sleep(0.1)
            lost_race = "address already in use" in self.output()
            self.log.close()
            if not lost_race or attempt >= attempts:
                raise AssertionError(f"service did not start (attempt {attempt} of {attempts}): " + self.output())

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def output(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return Path(self.log.name).read_text()

    def client(self, token: str | None = OPERATOR) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        client = httpx.Client(base_url=self.url, headers=headers, timeout=REQUEST_TIMEOUT_S)
        client.service_pid = self.proc.pid  # whose job workers jobs_seen watches
        return client

    def stop(self, sig=signal.SIGTERM) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def wait_for(fn, timeout_s: float = 60.0, what: str = "condition"):
    end = time.monotonic() + timeout_s
    while True:
        value = fn()
        if value:
            return value
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.1)


#: the longest any wait_while_moving lasts, moving or not: a worker that computes without end (its CPU
#: always moving) fails here instead of holding the suite until CI's own limit
WAIT_CEILING_S = 5400.0


def wait_while_moving(done, progress, stall_s: float = 900.0, what: str = "the condition"):
    """Wait until done() returns something true and return it, for as long as progress() keeps changing: on a
    busy machine work takes as long as the machine gives it, so no fixed bound fits every load; a test fails
    when nothing moved for stall_s (a stuck queue or a stalled sweep), or after WAIT_CEILING_S in all, saying
    what it waited for."""
    start = moved = time.monotonic()
    seen = None
    while True:
        value = done()
        if value:
            return value
        now = progress()
        if now != seen:
            moved, seen = time.monotonic(), now
        assert time.monotonic() - moved < stall_s, f"{what}: nothing moved for {stall_s:.0f} s (last: {now})"
        assert time.monotonic() - start < WAIT_CEILING_S, f"{what}: not done after {WAIT_CEILING_S:.0f} s (last: {now})"
        time.sleep(1.0)


def job_ended(fetch):
    """A done() for wait_while_moving: the job's JSON once it has left queued/running, else None."""
    return lambda: (j := fetch())["state"] not in ("queued", "running") and j


def wait_for_job(client, fetch, stall_s: float = 900.0, what: str = "the job") -> dict:
    """Wait until fetch() (a job's JSON) has left queued/running, for as long as the service's job queue
    moves: a service identifies every recording, so on a busy machine a job can wait behind many others for
    longer than any fixed time, and the job workers run at nice +10 (server/worker.py), so a busy machine
    starves them by design. Fails when for stall_s no job of the service changed state and its job workers
    used no CPU (a stuck queue: 15 minutes with nothing started, finished or computed), or after
    WAIT_CEILING_S in all (a worker computing without end), saying what it waited for."""
    return wait_while_moving(job_ended(fetch), lambda: jobs_seen(client), stall_s, what)


def jobs_seen(client) -> tuple:
    """What moves in a service's job queue (a progress() for wait_while_moving): every job's state, and the
    CPU seconds its job workers have used (a job can run for many minutes without a state change where
    the machine starves the workers at nice +10; a stuck worker uses none)."""
    states = frozenset((j["id"], j["state"]) for j in client.get("/api/jobs", params={"limit": 500}).json())
    pid = getattr(client, "service_pid", None)
    return states, (int(workers_cpu_s(pid)) if pid else None)


def workers_cpu_s(service_pid: int) -> float:
    """CPU seconds (user + system) of the job workers below a service process: its descendants started by
    multiprocessing's spawn (the process pool), read from /proc."""
    children: dict = {}
    stats: dict = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:  # gone meanwhile
                continue
            children.setdefault(int(fields[1]), []).append(int(entry.name))
            stats[int(entry.name)] = (float(fields[11]) + float(fields[12]), b"spawn_main" in cmdline)
    tick, total, todo = os.sysconf("SC_CLK_TCK"), 0.0, list(children.get(service_pid, []))
    while todo:
        pid = todo.pop()
        ticks, worker = stats.get(pid, (0.0, False))
        total += ticks / tick if worker else 0.0
        todo.extend(children.get(pid, []))
    return total


def wait_for_sweep(client, sweep_id: str, stall_s: float = 300.0, what: str = "the sweep to end") -> dict:
    """Wait until a sweep has left queued/running, for as long as its progress moves (the simulated rig runs
    at --sim-speed when the machine gives it the CPU, slower when it does not)."""
    fetch = lambda: client.get(f"/api/sweeps/{sweep_id}").json()  # noqa: E731
    return wait_while_moving(job_ended(fetch), lambda: (s := fetch())["state"] + str(s.get("progress")),
                             stall_s, what)


@pytest.fixture
def service(tmp_path):
    s = Service(tmp_path / "data").start()
    yield s
    s.stop()
