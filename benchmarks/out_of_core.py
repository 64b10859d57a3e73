"""Out-of-core identification of long HDF5 recordings: time per sample, peak RSS and how far the truth is
from each coefficient in standard errors (z), from 1e6 to 1e8 samples, beside the in-core run and the
plain h5py read of the same files.

    python benchmarks/out_of_core.py [--samples 1e6 1e7 1e8] [--in-core 1e6] [--fs-hz 2048] [--keep DIR]
                                     [--seed N]

The records (daq.long_record.write_long_record over sim.synth.noise_free_sweep): the paper's Table 1 rig swept 1-20 Hz over 60 s at
1.3 mm (it starts and ends at rest), the motion repeated up to N samples, with fresh sensor noise (0.5 %
of each channel's std) on every sample: the seed is fresh each run and printed (--seed repeats one).
Written in the DAQ's HDF5 layout (/entry/data/{time, table_acc, mass_acc}, float32 channels, @fs_hz,
status complete). Each figure is one fresh process (`shakeid identify FILE --json`, via shakeid.cli.main,
stdout discarded, imports done before the clock starts), so its peak RSS (VmHWM) is that run's alone:

- in core: the default identification (chain bias in closed form, identify.chain.bias_correction);
- out of core: --chunked (2^20-sample chunks), one process: the same fit sequence (identify.fitting),
  the same closed-form chain bias and standard errors;
- read: h5py reading both channels of the file in 2^20-row blocks, nothing else.

Printed side by side: seconds, microseconds per sample, the ratio to the in-core run of the smallest
--in-core size (target: <= 1.5, i.e. linear), peak RSS (target: flat, <= 1 GB), and the z-score of
each q1_dot coefficient against the truth ((estimate - truth) / its standard error: honest standard
errors keep |z| below 3 but for 0.3 % of the terms). Files are deleted at the end unless --keep.
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


def write_record(path: Path, n: int, fs_hz: float, seed: int) -> dict:
    """A DAQ-layout HDF5 file of n samples with fresh noise throughout (module doc): the truth and seconds."""
    from daq.long_record import write_long_record
    from sim.synth import noise_free_sweep

    t0 = time.perf_counter()
    run = noise_free_sweep(fs_hz=fs_hz)
    write_long_record(path, n, run.recording, seed=seed)
    return {"model": run.recording.metadata["truth"]["model"], "seconds": time.perf_counter() - t0}


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
        out.update(code=code, status=res["status"], model=res["model"]["q1_dot"], se=res["standard_errors"]["q1_dot"],
                   timings=res.get("timings_s"), chunks=res.get("out_of_core", {}).get("chunks"))
    out["seconds"] = time.perf_counter() - t0
    out["rss_mb"] = peak_rss_mb()
    print(json.dumps(out))


def measure(kind: str, path: Path, extra=()) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", kind, str(path), *extra], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{kind} {path}: failed\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def z_scores(r: dict, truth: dict) -> dict:
    """{term: (estimate - truth) / standard error} of the q1_dot terms both have."""
    return {t: (c - truth[t]) / r["se"][t] for t, c in r["model"].items() if t in truth and r["se"].get(t)}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child(sys.argv[2], sys.argv[3], sys.argv[4:])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=float, nargs="+", default=[1e6, 1e7, 1e8])
    ap.add_argument("--in-core", type=float, nargs="*", default=[1e6], help="sizes also identified in core")
    ap.add_argument("--fs-hz", type=float, default=2048.0)
    ap.add_argument("--keep", metavar="DIR", help="write the files here and keep them")
    ap.add_argument("--seed", type=int, help="noise seed (default: fresh, printed)")
    args = ap.parse_args()
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().generate_state(1)[0])
    folder = Path(args.keep or tempfile.mkdtemp(prefix="ooc-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; noise seed {seed} (each size: seed + size)")
    rows = []
    sizes = sorted({int(s) for s in args.samples} | {int(s) for s in args.in_core})
    try:
        for n in sizes:
            path = folder / f"record_{n}.h5"
            written = write_record(path, n, args.fs_hz, seed + n)
            truth = written["model"]["q1_dot"]
            print(f"wrote {path.name}: {n} samples, {path.stat().st_size / 1e9:.2f} GB in {written['seconds']:.1f} s",
                  flush=True)
            read = measure("read", path)
            rows.append(("h5py read", n, read, None))
            print(f"  read {n:.0e}: {read['seconds']:.2f} s, {read['rss_mb']:.0f} MB", flush=True)
            runs = ([("in core", [])] if n in {int(s) for s in args.in_core} else []) + \
                ([("out of core", ["--chunked"])] if n in {int(s) for s in args.samples} else [])
            for label, extra in runs:
                r = measure("identify", path, extra)
                z = z_scores(r, truth)
                rows.append((label, n, r, z))
                print(f"  {label} {n:.0e}: {r['seconds']:.2f} s, {r['rss_mb']:.0f} MB, {r['status']}, z "
                      f"{json.dumps({t: round(v, 2) for t, v in z.items()})}, timings "
                      f"{json.dumps({k: round(v, 2) for k, v in (r['timings'] or {}).items()})}", flush=True)
            if not args.keep:
                path.unlink()
    finally:
        if not args.keep:
            for p in folder.glob("*.h5"):
                p.unlink()
            folder.rmdir()
    ref = next((r for lbl, n, r, _ in rows if lbl == "in core" and n == int(min(args.in_core or [0]))), None)
    ref_us = ref["seconds"] / min(args.in_core) * 1e6 if ref else None
    print(f"\n{'run':<14}{'samples':>10}{'seconds':>10}{'us/sample':>11}{'x in-core':>11}{'peak RSS MB':>13}"
          f"  status, max |z| (term)")
    for label, n, r, z in rows:
        us = r["seconds"] / n * 1e6
        ratio = f"{us / ref_us:.2f}" if ref_us and label != "h5py read" else "-"
        worst = max(z, key=lambda t: abs(z[t])) if z else None
        extra = "" if z is None else f"  {r['status']}, {abs(z[worst]):.2f} ({worst})"
        print(f"{label:<14}{n:>10.0e}{r['seconds']:>10.2f}{us:>11.3f}{ratio:>11}{r['rss_mb']:>13.0f}{extra}")


if __name__ == "__main__":
    main()
