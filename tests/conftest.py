"""Shared fixtures: synthetic sweeps of the simulated rig with known coefficients (the ground truth)."""
from __future__ import annotations

from pathlib import Path

import pytest

from identify.data.recording import write_csv
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep


def sweep_run(noise: float = 0.005, seed: int = 0, **kw):
    sensor = Accelerometer(noise_fraction=noise)
    return run_sweep(table_sensor=sensor, mass_sensor=sensor, seed=seed, **kw)


#: q1_dot terms of the Table 1 model
TRUE_Q1 = {"q1", "q2", "q1*q2^2", "q2^3", "zdd"}


@pytest.fixture(scope="session")
def make_run():
    """Factory for further synthetic runs: make_run(noise=0.02, seed=0, sweep=SineSweep(...))."""
    return sweep_run


@pytest.fixture(scope="session")
def true_q1_terms():
    return set(TRUE_Q1)


@pytest.fixture(scope="session")
def table1_run():
    """The acceptance case: the paper's Table 1 rig, 1-20 Hz over 60 s at 1.3 mm, 0.5 % noise."""
    return sweep_run()


@pytest.fixture(scope="session")
def table1_truth():
    return RigParameters.paper_table1().model().equations


@pytest.fixture(scope="session")
def table1_csv(table1_run, tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "sweep.csv"
    write_csv(path, table1_run.recording)
    return path


@pytest.fixture
def can_relay():
    """A python-can-remote relay (a virtual CAN bus served over websocket on loopback), for CAN between
    processes; yields its port once it accepts connections."""
    import socket
    import subprocess
    import sys
    import time

    from sim.server import free_port

    port = free_port()
    relay = subprocess.Popen([sys.executable, "-m", "can_remote", "-i", "virtual", "-c", f"relay{port}",
                              "-H", "127.0.0.1", "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        end = time.time() + 15.0
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                break
            except OSError:
                assert relay.poll() is None and time.time() < end, "python-can-remote relay did not start"
                time.sleep(0.1)
        yield port
    finally:
        relay.terminate()
        relay.wait(10)


@pytest.fixture(scope="session")
def dask_cluster(tmp_path_factory):
    """A real Dask cluster as separate processes on loopback: `dask scheduler` and two `dask worker`s
    (one thread each, no nanny), on free ports; yields the scheduler address once both workers have joined, and
    terminates all three afterwards."""
    import subprocess
    import sys

    from distributed import Client

    from sim.server import free_port

    dask = str(Path(sys.executable).with_name("dask"))
    address = f"tcp://127.0.0.1:{free_port()}"
    log = open(tmp_path_factory.mktemp("dask") / "dask.log", "w")
    common = dict(stdout=log, stderr=subprocess.STDOUT)
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                               "--no-dashboard"], **common)]
    try:
        # --no-nanny: one process per worker, so terminating it leaves nothing behind
        procs += [subprocess.Popen([dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                                    "--no-dashboard", "--name", f"worker-{i}", "--death-timeout", "60"], **common)
                  for i in range(2)]
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in reversed(procs):
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


@pytest.fixture
def sim_rig(tmp_path):
    """`shakeid sim` at 10x on free ports, as its own process, and (its rig configuration file, its Modbus
    port); watchdog 5 s of rig time, 0.5 s of wall time: ten heartbeats."""
    import subprocess
    import sys

    from sim.server import free_port

    modbus, stream = free_port(), free_port()
    cfg = tmp_path / "rig.toml"
    cfg.write_text(f'[plc]\ntransport = "modbus"\nhost = "127.0.0.1"\nport = {modbus}\n'
                   f'[stream]\nurl = "socket://127.0.0.1:{stream}"\nsensitivity_counts_per_ms2 = 655.34\n'
                   f'[limits]\nwatchdog_s = 5.0\n[sim]\nspeed = 10.0\n')
    shakeid = str(Path(sys.executable).with_name("shakeid"))
    proc = subprocess.Popen([shakeid, "sim", "--config", str(cfg)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    assert "simulated rig" in proc.stdout.readline()
    yield cfg, modbus
    proc.terminate()
    proc.wait(10)
