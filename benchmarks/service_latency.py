"""HTTP service figures against a real `shakeid serve` (uvicorn, embedded simulated rig at 10x).

    python benchmarks/service_latency.py [--sweeps 3] [--pollers 50] [--poll-seconds 5]

1. Sweep end -> model available, for a 60 s sweep (1-20 Hz, 1.3 mm, the paper's rig): the recording's
   end_time (written when the file is closed) to the first 200 of GET /api/recordings/{id}/model (polled
   every 20 ms), with the steps between: job queued, model.json written, figures done. Anchor: the same
   recording identified by `shakeid identify FILE.h5 --json` as a fresh process, and in process.
   Target (issue 5): <= 2 s.
2. GET /api/sweeps/{id} latency while a sweep runs: 1 poller back-to-back (the anchor: one request at a
   time), 50 concurrent pollers back-to-back (saturation), and 50 pollers each every 100 ms (ten times a
   dashboard's refresh rate): median, p95, p99 and requests/s. The embedded simulated rig (physics at 10x)
   shares the service process and the 2 cores.
"""
from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import h5py
import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.server import free_port  # noqa: E402

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
TOKEN = "benchmark-operator-token"
SWEEP = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 60.0, "amplitude_mm": 1.3, "settle_s": 2.0}


def start_service(data_dir: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    proc = subprocess.Popen([SHAKEID, "serve", "--data-dir", str(data_dir), "--port", str(port), "--sim-speed", "10"],
                            env={**os.environ, "SHAKEID_TOKENS": f"{TOKEN}:operator"},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    for _ in range(600):
        try:
            if httpx.get(url + "/api/health", timeout=1).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    raise SystemExit("service did not start")


def model_latency(client: httpx.Client, data_dir: Path) -> dict:
    sweep = client.post("/api/sweeps", json=SWEEP).json()
    sid = sweep["id"]
    rec_id = client.get(f"/api/sweeps/{sid}").json()["recording_id"]
    while client.get(f"/api/sweeps/{sid}").json()["state"] in ("queued", "running"):
        time.sleep(0.2)
    while client.get(f"/api/recordings/{rec_id}/model").status_code != 200:
        time.sleep(0.02)
    t_model = time.time()
    path = data_dir / "recordings" / f"{rec_id}.h5"
    with h5py.File(path, "r") as f:
        t_end = datetime.fromisoformat(f["entry"].attrs["end_time"]).timestamp()
    job = [j for j in client.get("/api/jobs").json() if j["recording_id"] == rec_id][0]
    while job["state"] == "running":
        time.sleep(0.05)
        job = client.get(f"/api/jobs/{job['id']}").json()
    model_file = data_dir / "results" / job["id"] / "model.json"
    return {"path": path, "model_s": t_model - t_end, "queued_s": job["created"] - t_end,
            "written_s": model_file.stat().st_mtime - t_end, "figures_s": job["updated"] - t_end}


async def poll(url: str, sid: str, pollers: int, seconds: float, period_s: float = 0.0) -> dict:
    """`pollers` keep-alive connections, each sending GET /api/sweeps/{sid} back-to-back (period_s = 0)
    or every period_s (a dashboard's refresh; staggered starts). A minimal
    asyncio HTTP/1.1 client: a full client library costs more CPU per request than the service does,
    and on 2 cores it would measure itself."""
    host, port = url.split("//")[1].split(":")
    request = (f"GET /api/sweeps/{sid} HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {TOKEN}\r\n\r\n").encode()
    lat: list[float] = []
    end = time.perf_counter() + seconds

    async def one(k: int):
        reader, writer = await asyncio.open_connection(host, int(port))
        next_t = time.perf_counter() + period_s * k / pollers
        while time.perf_counter() < end:
            if period_s:
                await asyncio.sleep(max(0.0, next_t - time.perf_counter()))
                next_t += period_s
            t0 = time.perf_counter()
            writer.write(request)
            head = await reader.readuntil(b"\r\n\r\n")
            assert head.startswith(b"HTTP/1.1 200"), head[:40]
            length = int(next(line.split(b":")[1] for line in head.split(b"\r\n")
                              if line.lower().startswith(b"content-length")))
            await reader.readexactly(length)
            lat.append(time.perf_counter() - t0)
        writer.close()

    t0 = time.perf_counter()
    await asyncio.gather(*(one(k) for k in range(pollers)))
    wall = time.perf_counter() - t0
    a = np.array(lat) * 1e3
    return {"n": a.size, "p50": np.percentile(a, 50), "p95": np.percentile(a, 95), "p99": np.percentile(a, 99),
            "rps": a.size / wall}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--sweeps", type=int, default=3)
    p.add_argument("--pollers", type=int, default=50)
    p.add_argument("--poll-seconds", type=float, default=5.0)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        data = Path(d) / "data"
        proc, url = start_service(data)
        try:
            client = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30)
            print(f"1. sweep end -> model available, 60 s sweep at 2048 Hz (122 880 samples + settle), {args.sweeps} runs")
            print(f"{'run':>4s} {'job queued s':>13s} {'model.json s':>13s} {'GET model 200 s':>16s} {'figures s':>10s}")
            runs = []
            for k in range(args.sweeps):
                r = model_latency(client, data)
                runs.append(r)
                print(f"{k + 1:4d} {r['queued_s']:13.3f} {r['written_s']:13.3f} {r['model_s']:16.3f} {r['figures_s']:10.3f}",
                      flush=True)
            path = runs[-1]["path"]
            t0 = time.perf_counter()
            subprocess.run([SHAKEID, "identify", str(path), "--json"], capture_output=True, check=True)
            cli = time.perf_counter() - t0
            from daq.recorder import read_h5_recording
            from identify import SparseIdentifier

            t0 = time.perf_counter()
            SparseIdentifier().fit(read_h5_recording(path))
            inproc = time.perf_counter() - t0
            best = min(r["model_s"] for r in runs)
            print(f"anchors on the same file: `shakeid identify --json` process {cli:.3f} s, in-process fit {inproc:.3f} s")
            print(f"model available {best:.3f} s (best) / {max(r['model_s'] for r in runs):.3f} s (worst) after the "
                  f"sweep's end; target <= 2 s")

            print(f"\n2. GET /api/sweeps/{{id}} during a running sweep, {args.poll_seconds:g} s each")
            sid = client.post("/api/sweeps", json={**SWEEP, "duration_s": 600.0}).json()["id"]
            print(f"{'pollers':>8s} {'each polls':>12s} {'requests':>9s} {'p50 ms':>8s} {'p95 ms':>8s} {'p99 ms':>8s} "
                  f"{'req/s':>8s}")
            for n, period in ((1, 0.0), (args.pollers, 0.0), (args.pollers, 0.1)):
                r = asyncio.run(poll(url, sid, n, args.poll_seconds, period))
                print(f"{n:8d} {'back-to-back' if not period else f'every {period * 1e3:.0f} ms':>12s} {r['n']:9d} "
                      f"{r['p50']:8.2f} {r['p95']:8.2f} {r['p99']:8.2f} {r['rps']:8.0f}", flush=True)
            client.post(f"/api/sweeps/{sid}/abort")
        finally:
            proc.terminate()
            proc.wait(30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
