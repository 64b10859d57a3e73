"""The weak term's standard error as recordings are added (issue 13, joint identification).

    python benchmarks/joint_se.py [--seeds 8] [--amplitudes 1.3 1.2 1.1] [--replicates N]

Per seed: the Table 1 rig swept 1-20 Hz over 30 s at 1024 Hz, 0.5 % noise, once at each amplitude (the
first listed is the strongest for q1*q2^2); fitted alone (the first recording) and jointly with the
first 2, 3, ... recordings. Prints, per number of recordings, the median over seeds of the weak term's
reported SE (the identifier's: the noise share in closed form, or SIMEX with --replicates where SIMEX runs, and the block sandwich alone), the spread of its
estimate over seeds (the true sampling error, with its own uncertainty ~1/sqrt(2 (seeds - 1))), and the
median error against the truth. Also the best single recording's SE (the smallest of the recordings
fitted alone), which the joint fit must beat.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from identify import SparseIdentifier
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from protocol.sweep import SineSweep

WEAK = "q1*q2^2"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--amplitudes", type=float, nargs="+", default=[1.3, 1.2, 1.1])
    ap.add_argument("--replicates", type=int, default=None, help="SIMEX replicates (default: the identifier's, by record length)")
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--fs", type=float, default=1024.0)
    a = ap.parse_args()
    rig = RigParameters.paper_table1()
    truth = rig.model().equations["q1_dot"][WEAK]
    sensor = Accelerometer(noise_fraction=0.005)
    n = len(a.amplitudes)
    se, se_sandwich, est = ([[] for _ in range(n)] for _ in range(3))
    best_single = []
    t0 = time.perf_counter()
    for s in range(a.seeds):
        recs = [run_sweep(rig, SineSweep(1, 20, a.duration, amp), fs_hz=a.fs, seed=1000 * s + i,
                          table_sensor=sensor, mass_sensor=sensor).recording for i, amp in enumerate(a.amplitudes)]
        singles = []
        for r in recs:
            fit = SparseIdentifier(validate=False, placements=0, bias_replicates=a.replicates).fit(r)
            singles.append(fit.standard_errors_["q1_dot"].get(WEAK, np.nan))
        best_single.append(np.nanmin(singles))
        for k in range(1, n + 1):
            fit = SparseIdentifier(validate=False, placements=0, bias_replicates=a.replicates).fit(recs[:k])
            plain = SparseIdentifier(validate=False, placements=0, bias_replicates=0).fit(recs[:k])
            se[k - 1].append(fit.standard_errors_["q1_dot"].get(WEAK, np.nan))
            se_sandwich[k - 1].append(plain.standard_errors_["q1_dot"].get(WEAK, np.nan))
            est[k - 1].append(fit.model_.equations["q1_dot"].get(WEAK, np.nan))
    print(f"q1*q2^2 (truth {truth:.5g}), {a.seeds} seeds, amplitudes {a.amplitudes} mm, {a.duration:g} s at "
          f"{a.fs:g} Hz, 0.5 % noise, {'default' if a.replicates is None else a.replicates} bias_replicates ({time.perf_counter() - t0:.0f} s)")
    print("recordings | median SE (reported) | median SE (sandwich) | spread over seeds | median |error| | "
          "joint SE < best single's")
    for k in range(n):
        e = np.array(est[k])
        wins = np.mean(np.array(se[k]) < np.array(best_single)) if k else float("nan")
        print(f"{k + 1:10d} | {np.nanmedian(se[k]):17.1f} | {np.nanmedian(se_sandwich[k]):20.1f} | "
              f"{np.nanstd(e, ddof=1):17.1f} | {np.nanmedian(np.abs(e - truth)):15.1f} | "
              + ("-" if not k else f"{wins:.0%} of seeds"))
    print(f"best single recording's SE, median: {np.median(best_single):.1f}")


if __name__ == "__main__":
    main()
