"""`shakeid explain` as a user runs it (the command, end to end) beside the public call that
benchmarks/explain_robustness.py times, `DiscrepancyAnalysis().fit(recording).result()`, on fresh wide draws
of 60 s recordings (58 s sweep + 2 s settle), with one busy process beside (docs/discrepancy.md, "Time").

    python benchmarks/explain_cli.py [--seed S] [--cases 0 1 4 8]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from explain_robustness import plan_case  # noqa: E402
from identify.data.recording import write_csv  # noqa: E402
from identify.explain.workflow import DiscrepancyAnalysis  # noqa: E402
from sim.scenarios import make_scenario  # noqa: E402

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, help="reproduce a printed run (default: a new seed)")
    p.add_argument("--cases", type=int, nargs="+", default=[0, 1, 4, 8],
                   help="explain_robustness case numbers (their category from the case: 0 single, 1 none, 4 sensor "
                        "fault, 8 out of catalog)")
    args = p.parse_args(argv)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed} (--seed {seed} repeats it); one busy process beside", flush=True)
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for i in args.cases:
                category, names = plan_case(i)
                sc = make_scenario(np.random.default_rng([seed, i]), category, names, wide=True, duration_s=58.0)
                rec = sc.run(seed=[seed, i, 1]).recording
                path = Path(tmp) / f"case{i}.csv"
                write_csv(path, rec)
                t0 = time.perf_counter()
                DiscrepancyAnalysis().fit(rec).result()
                call = time.perf_counter() - t0
                t0 = time.perf_counter()
                proc = subprocess.run([SHAKEID, "explain", str(path), "--json"], capture_output=True, text=True)
                command = time.perf_counter() - t0
                print(f"case {i} {category} {names or ''}: call {call:.1f} s, `shakeid explain --json` {command:.1f} s "
                      f"(exit {proc.returncode}), load {os.getloadavg()[0]:.1f}", flush=True)
    finally:
        busy.kill()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
