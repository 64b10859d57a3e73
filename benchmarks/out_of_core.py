"""Out-of-core identification of long HDF5 recordings: time per sample and peak RSS from 1e6 to 1e8 samples,
beside the in-core run of 1e6 samples and the plain h5py read of the same files.

    python benchmarks/out_of_core.py [--samples 1e6 1e7 1e8] [--in-core 1e6] [--fs-hz 2048] [--keep DIR]

The records: a 60 s sweep of the paper's Table 1 rig (1-20 Hz, 1.3 mm, 0.5 % noise, 2048 Hz; it starts
and ends at rest) simulated with four noise seeds, the four cycled and concatenated up to N samples
(simulating a 13-hour sweep is not the workload; identifying it is), written in the DAQ's HDF5 layout
(daq/recorder.py: /entry/data/{time, table_acc, mass_acc}, float32 channels, @fs_hz, status complete) by
h5py in blocks. Each figure is one fresh process (`shakeid identify FILE --json`, via shakeid.cli.main,
stdout discarded, imports done before the clock starts), so its peak RSS (VmHWM) is that run's alone:

- in core: the default identification (SIMEX chain bias with 16 replicates included) and the same with
  --bias-replicates 0, which is what the out-of-core path does (it skips SIMEX: identify/out_of_core.py);
- out of core: --chunked (2^20-sample chunks), one process;
- read: h5py reading both channels of the file in 2^20-row blocks, nothing else.

Printed side by side: seconds, microseconds per sample, the ratio to the in-core 1e6 run without SIMEX
(target: <= 1.5, i.e. linear), peak RSS (target: flat, <= 1 GB), the read's share. Files are deleted
at the end unless --keep.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

BLOCK = 1 << 20


def write_record(path: Path, n: int, fs_hz: float, seeds: int = 4) -> float:
    """A DAQ-layout HDF5 file of n samples: sweeps cycled (module doc). Returns seconds spent."""
    import h5py

    from sim.sensors import Accelerometer
    from sim.sweep import SineSweep
    from sim.synth import run_sweep

    t0 = time.perf_counter()
    sensor = Accelerometer(noise_fraction=0.005)
    parts = [run_sweep(sweep=SineSweep(1.0, 20.0, 60.0, 1.3), fs_hz=fs_hz, table_sensor=sensor, mass_sensor=sensor,
                       seed=s).recording for s in range(seeds)]
    cycle_in = np.concatenate([p.input for p in parts]).astype("f4")
    cycle_out = np.concatenate([p.output for p in parts]).astype("f4")
    with h5py.File(path, "w") as f:
        e = f.create_group("entry")
        e.attrs.update(NX_class="NXentry", status="complete", status_reason="", fs_hz=fs_hz, samples_written=n)
        e.create_group("sweep")
        inst = e.create_group("instrument")
        d = e.create_group("data")
        ds = {"time": d.create_dataset("time", (n,), dtype="f8", chunks=(4096,))}
        for ch in ("table_acc", "mass_acc"):
            inst.create_group(ch).attrs.update(units="m/s^2", sensitivity=1.0)
            ds[ch] = d.create_dataset(ch, (n,), dtype="f4", chunks=(4096,))
            ds[ch].attrs["units"] = "m/s^2"
        e.create_dataset("gaps", (0, 2), dtype="i8")
        for a in range(0, n, BLOCK):
            b = min(a + BLOCK, n)
            idx = np.arange(a, b) % cycle_in.size
            ds["time"][a:b] = np.arange(a, b) / fs_hz
            ds["table_acc"][a:b] = cycle_in[idx]
            ds["mass_acc"][a:b] = cycle_out[idx]
    return time.perf_counter() - t0


def peak_rss_mb() -> float:
    """This process's peak resident set (VmHWM, MB). Not ru_maxrss: that survives exec, so a child
    started by a parent holding the simulated records would report the parent's peak."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(kind: str, path: str, extra: list[str]) -> None:
    """Run one measurement in this (fresh) process; print {"seconds", "rss_mb", ...} as JSON."""
    out = {}
    if kind != "read":  # imports are not the workload: loaded before the clock starts
        import daq.h5source  # noqa: F401
        import identify.identifier  # noqa: F401
        import identify.out_of_core  # noqa: F401
        import shakeid.cli  # noqa: F401
    t0 = time.perf_counter()
    if kind == "read":
        import h5py

        with h5py.File(path, "r") as f:
            d = f["entry/data"]
            total = 0.0
            for a in range(0, d["table_acc"].shape[0], BLOCK):
                total += float(d["table_acc"][a:a + BLOCK].astype(float).sum() + d["mass_acc"][a:a + BLOCK].astype(float).sum())
        out["checksum"] = total
    else:
        import contextlib
        import io

        from shakeid.cli import main

        buf = io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
            code = main(["identify", path, "--json", *extra])
        res = json.loads(buf.getvalue())
        out.update(code=code, status=res["status"], model=res["model"]["q1_dot"],
                   timings=res.get("timings_s"), chunks=res.get("out_of_core", {}).get("chunks"))
    out["seconds"] = time.perf_counter() - t0
    out["rss_mb"] = peak_rss_mb()
    print(json.dumps(out))


def measure(kind: str, path: Path, extra=()) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", kind, str(path), *extra], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{kind} {path}: failed\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child(sys.argv[2], sys.argv[3], sys.argv[4:])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=float, nargs="+", default=[1e6, 1e7, 1e8])
    ap.add_argument("--in-core", type=float, nargs="*", default=[1e6], help="sizes also identified in core")
    ap.add_argument("--fs-hz", type=float, default=2048.0)
    ap.add_argument("--keep", metavar="DIR", help="write the files here and keep them")
    args = ap.parse_args()
    folder = Path(args.keep or tempfile.mkdtemp(prefix="ooc-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}")
    rows = []
    sizes = sorted({int(s) for s in args.samples} | {int(s) for s in args.in_core})
    try:
        for n in sizes:
            path = folder / f"record_{n}.h5"
            if not path.exists():
                sec = write_record(path, n, args.fs_hz)
                print(f"wrote {path.name}: {n} samples, {path.stat().st_size / 1e9:.2f} GB in {sec:.1f} s", flush=True)
            read = measure("read", path)
            rows.append(("h5py read", n, read))
            print(f"  read {n:.0e}: {read['seconds']:.2f} s, {read['rss_mb']:.0f} MB", flush=True)
            if n in {int(s) for s in args.in_core}:
                for label, extra in (("in core", []), ("in core, no SIMEX", ["--bias-replicates", "0"])):
                    r = measure("identify", path, extra)
                    rows.append((label, n, r))
                    print(f"  {label} {n:.0e}: {r['seconds']:.2f} s, {r['rss_mb']:.0f} MB, {r['status']}", flush=True)
            if n in {int(s) for s in args.samples}:
                r = measure("identify", path, ["--chunked"])
                rows.append(("out of core", n, r))
                print(f"  out of core {n:.0e}: {r['seconds']:.2f} s, {r['rss_mb']:.0f} MB, {r['status']}, "
                      f"timings {json.dumps({k: round(v, 2) for k, v in (r['timings'] or {}).items()})}", flush=True)
            if not args.keep and n != sizes[-1]:
                path.unlink()
    finally:
        if not args.keep:
            for p in folder.glob("*.h5"):
                p.unlink()
            folder.rmdir()
    ref = next((r for lbl, n, r in rows if lbl == "in core, no SIMEX" and n == int(min(args.in_core or [0]))), None)
    ref_us = ref["seconds"] / min(args.in_core) * 1e6 if ref else None
    print(f"\n{'run':<20}{'samples':>10}{'seconds':>10}{'us/sample':>11}{'x in-core 1e6':>15}{'peak RSS MB':>13}  status / model q2^3")
    for label, n, r in rows:
        us = r["seconds"] / n * 1e6
        ratio = f"{us / ref_us:.2f}" if ref_us and label != "h5py read" else "-"
        extra = "" if label == "h5py read" else f"  {r['status']} / {r['model'].get('q2^3', float('nan')):.6g}"
        print(f"{label:<20}{n:>10.0e}{r['seconds']:>10.2f}{us:>11.3f}{ratio:>15}{r['rss_mb']:>13.0f}{extra}")


if __name__ == "__main__":
    main()
