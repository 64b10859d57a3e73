"""Scale-out figures: many recordings re-identified by `shakeid batch`, in the local process pool and on
a Dask cluster of 1 and 2 workers (real `dask scheduler` / `dask worker` processes on loopback).

    python benchmarks/scale.py [--recordings 200] [--duration-s 25] [--fs-hz 1024] [--distinct 8]

The recordings are short sweeps of the paper's Table 1 rig (1-20 Hz, 1.3 mm, 0.5 % noise) written as the
DAQ's HDF5; `--distinct` different noise seeds are simulated and copied under N names (re-identifying a
recording is the workload, simulating it is not). Each figure is the wall time of one `shakeid batch ...
--json` process, from its start to its exit: local pool start (spawned processes) or connecting to the
scheduler included, the cluster's own start excluded (it is already running, as a lab's would be). Every
run must return N models with status ok, else the script stops.

Printed side by side: files/s and the speed-up over one worker of the same kind.
Target (issue 13): Dask with 2 workers >= 1.6x Dask with 1 worker. On a 2-core machine that is also
running other work the ratio is bounded by the free cores, so read it together with the machine's load
(printed).

The out-of-core part of issue 13 (one recording of 1e6-1e8 samples identified chunk by chunk: time per
sample, peak RSS, the h5py read beside it) is benchmarks/out_of_core.py.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

BIN = Path(sys.executable).parent
SHAKEID, DASK = str(BIN / "shakeid"), str(BIN / "dask")


def make_recordings(folder: Path, n: int, distinct: int, duration_s: float, fs_hz: float) -> list[Path]:
    from daq.recorder import Recorder
    from sim.sensors import Accelerometer
    from protocol.sweep import SineSweep
    from sim.synth import run_sweep

    sensor = Accelerometer(noise_fraction=0.005)
    originals = []
    for seed in range(min(n, distinct)):
        rec = run_sweep(sweep=SineSweep(1.0, 20.0, duration_s, 1.3), fs_hz=fs_hz, table_sensor=sensor,
                        mass_sensor=sensor, seed=seed).recording
        path = folder / f"seed{seed}.h5"
        r = Recorder(path, fs_hz=rec.fs_hz)
        r.append(0, np.column_stack([rec.input, rec.output]))
        r.close("complete")
        originals.append(path)
    paths = []
    for i in range(n):
        path = folder / f"rec{i:04d}.h5"
        shutil.copyfile(originals[i % len(originals)], path)
        paths.append(path)
    return paths


def run_batch(paths: list[Path], extra: list[str]) -> tuple[float, dict]:
    t0 = time.perf_counter()
    proc = subprocess.run([SHAKEID, "batch", *map(str, paths), "--json", *extra], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"shakeid batch {' '.join(extra)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    doc = json.loads(proc.stdout)
    ok = sum(m["status"] == "ok" for m in doc["models"].values())
    if ok != len(paths):
        sys.exit(f"shakeid batch {' '.join(extra)}: {ok} of {len(paths)} models ok")
    return wall, doc


class Cluster:
    """`dask scheduler` + `workers` x `dask worker` (one thread each) on loopback, until close()."""

    def __init__(self, workers: int, log: Path):
        from distributed import Client

        from sim.server import free_port

        self.address = f"tcp://127.0.0.1:{free_port()}"
        self.log = open(log, "w")
        out = dict(stdout=self.log, stderr=subprocess.STDOUT)
        self.procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port",
                                        self.address.rsplit(":", 1)[1], "--no-dashboard"], **out)]
        self.procs += [subprocess.Popen([DASK, "worker", self.address, "--host", "127.0.0.1", "--nthreads", "1",
                                         "--no-dashboard", "--death-timeout", "60"], **out) for _ in range(workers)]
        with Client(self.address, timeout=60) as client:
            client.wait_for_workers(workers, timeout=120)

    def close(self) -> None:
        for proc in reversed(self.procs):
            proc.terminate()
        for proc in reversed(self.procs):
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.log.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recordings", type=int, default=200)
    ap.add_argument("--duration-s", type=float, default=25.0, help="sweep length of each recording (25 s)")
    ap.add_argument("--fs-hz", type=float, default=1024.0)
    ap.add_argument("--distinct", type=int, default=8, help="different noise seeds simulated (8)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="shakeid-scale-") as tmp:
        folder = Path(tmp)
        paths = make_recordings(folder, args.recordings, args.distinct, args.duration_s, args.fs_hz)
        print(f"{len(paths)} recordings of {args.duration_s:g} s at {args.fs_hz:g} Hz "
              f"({args.distinct} distinct); {os.cpu_count()} CPUs; load average before: "
              f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}")
        rows = []
        for workers in (1, 2):
            wall, doc = run_batch(paths, ["--workers", str(workers)])
            rows.append(("local pool", workers, wall, len({m["computed_on"] for m in doc["models"].values()})))
        for workers in (1, 2):
            cluster = Cluster(workers, folder / f"dask-{workers}.log")
            try:
                wall, doc = run_batch(paths, ["--scheduler", cluster.address])
            finally:
                cluster.close()
            rows.append(("dask", workers, wall, len({m["computed_on"] for m in doc["models"].values()})))
        print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
        print(f"{'backend':<12} {'workers':>7} {'used':>5} {'wall s':>8} {'files/s':>8} {'vs 1 worker':>12}")
        one = {}
        for kind, workers, wall, used in rows:
            one.setdefault(kind, wall)
            print(f"{kind:<12} {workers:>7} {used:>5} {wall:>8.2f} {len(paths) / wall:>8.2f} "
                  f"{one[kind] / wall:>11.2f}x")
        dask = {w: wall for kind, w, wall, _ in rows if kind == "dask"}
        print(f"target: dask 2 workers >= 1.6x 1 worker: {dask[1] / dask[2]:.2f}x")


if __name__ == "__main__":  # the Dask client and the local pool spawn processes that import this file
    main()
