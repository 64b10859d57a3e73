"""The uncertainty step's cost with the chain bias in closed form (default) and with SIMEX, on the
service's record size: Table 1 rig, 60 s 1-20 Hz sweep at 1.3 mm, 0.5 % noise, 2048 Hz (126 977
samples; SIMEX takes 64 replicates there). The public call, SparseIdentifier(bias_method=...).fit with
its free-run validation, CPU seconds, next to its refit_uncertainty part (wall), in rounds in one process.

    python benchmarks/bias_methods.py [--rounds 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identify.identifier import SparseIdentifier  # noqa: E402
from sim.rig import RigParameters  # noqa: E402
from sim.sensors import Accelerometer  # noqa: E402
from protocol.sweep import SineSweep  # noqa: E402
from sim.synth import run_sweep  # noqa: E402

METHODS = ("auto", "simex")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    sensor = Accelerometer(noise_fraction=0.005)
    rec = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 60, 1.3), seed=1, table_sensor=sensor,
                    mass_sensor=sensor).recording
    print(f"{rec.n_samples} samples; per round, CPU s of fit (with validation) and wall s of its uncertainty step")
    print("round  " + "  ".join(f"{m:>7s} fit  uncertainty" for m in METHODS))
    for r in range(args.rounds):  # rounds: a load spike hits both methods alike
        cells = []
        for method in METHODS:
            t0 = time.process_time()
            ident = SparseIdentifier(bias_method=method).fit(rec)
            cells.append(f"{time.process_time() - t0:11.3f}  {ident.timings_['refit_uncertainty']:11.3f}")
        print(f"{r:5d}  " + "  ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
