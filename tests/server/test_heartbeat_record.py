"""A sweep's heartbeat intervals kept in its recording's info as a histogram (server/sweep_launch.py
HEARTBEAT_BIN_MS), so benchmarks/estop_latency.py pools the intervals of many sweeps into one p99.
Real processes: `shakeid serve` with its controller and embedded simulated rig."""
from __future__ import annotations

from server.sweep_launch import HEARTBEAT_BIN_MS

from .conftest import wait_for

#: ~4 s at the service's 10x simulated rig: ~80 beats
SWEEP = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 40.0, "amplitude_mm": 1.0, "settle_s": 2.0}


def test_a_sweeps_heartbeat_intervals_are_recorded_as_a_histogram(service):
    op = service.client()
    r = op.post("/api/sweeps", json=SWEEP)
    assert r.status_code == 202, r.text
    url = f"/api/sweeps/{r.json()['id']}"
    wait_for(lambda: op.get(url).json()["state"] not in ("queued", "running"), 120, "the sweep's end")
    sweep = op.get(url).json()
    assert sweep["state"] == "completed", sweep
    info = op.get(f"/api/recordings/{sweep['recording_id']}").json()["info"]
    hist = {float(edge): n for edge, n in info["heartbeat_histogram_ms"].items()}
    assert sum(hist.values()) == info["heartbeats"] - 1  # every interval, once
    assert all(edge % HEARTBEAT_BIN_MS == 0 for edge in hist)
    # the largest interval's bin holds the largest interval (heartbeat_max_s is rounded to 0.1 ms)
    largest_ms = 1000 * info["heartbeat_max_s"]
    assert max(hist) - 0.1 <= largest_ms <= max(hist) + HEARTBEAT_BIN_MS + 0.1
    # on a 50 ms grid: the bulk of the intervals in the bins around the nominal period
    nominal_ms = 1000 * info["heartbeat_nominal_s"]
    near = sum(n for edge, n in hist.items() if abs(edge + HEARTBEAT_BIN_MS / 2 - nominal_ms) <= 10)
    assert near >= 0.5 * sum(hist.values())
