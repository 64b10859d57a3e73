"""Shared fixtures: synthetic sweeps of the simulated rig with known coefficients (the ground truth)."""
from __future__ import annotations

import pytest

from identify.recording import write_csv
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
