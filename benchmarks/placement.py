"""Where the held-out blocks fall: the weak term's estimate, training-only fit against reported.

    python benchmarks/placement.py [--fs 2048]

Two records of the Table 1 rig (truth q1*q2^2 = 11620): the standard 60 s, 1.3 mm sweep at 0.5 %
noise, and a 40 s sweep followed by 150 s of rest at 0.02 m/s^2 noise (docs/identification.md
section 6). For held-out fractions 10-30 % prints the error of q1*q2^2 in the training-only fit (what
the identifier reported before issue 11) and in the reported all-rows fit, then for the standard sweep
the inclusion probabilities and what the uncertainty step costs.
"""
from __future__ import annotations

import argparse

import numpy as np

from identify import SparseIdentifier
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from protocol.sweep import SineSweep

WEAK, TRUTH = "q1*q2^2", 1.1620e4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fs", type=float, default=2048.0)
    args = ap.parse_args()
    rig = RigParameters.paper_table1()
    records = {
        "60 s sweep, 0.5 %": run_sweep(rig, SineSweep(1, 20, 60, 1.3), fs_hz=args.fs, seed=1,
                                       table_sensor=Accelerometer(noise_fraction=0.005),
                                       mass_sensor=Accelerometer(noise_fraction=0.005)),
        "40 s sweep + 150 s rest": run_sweep(rig, SineSweep(1, 20, 40, 1.3), fs_hz=args.fs, settle_s=150, seed=0,
                                             table_sensor=Accelerometer(noise_fraction=0, noise_ms2=0.02),
                                             mass_sensor=Accelerometer(noise_fraction=0, noise_ms2=0.02)),
    }
    for label, run in records.items():
        train, reported = [], []
        for fraction in (0.1, 0.15, 0.2, 0.25, 0.3):
            ident = SparseIdentifier(validate=False, placements=0, holdout_fraction=fraction).fit(run.recording)
            train.append(100 * (ident.training_model_.equations["q1_dot"].get(WEAK, 0.0) / TRUTH - 1))
            reported.append(100 * (ident.model_.equations["q1_dot"].get(WEAK, 0.0) / TRUTH - 1))
            se = ident.standard_errors_["q1_dot"].get(WEAK, float("nan"))
            print(f"{label:24s} held out {fraction:.0%}: {WEAK} training-only {train[-1]:+.3f} %, "
                  f"reported {reported[-1]:+.3f} % (SE {100 * se / TRUTH:.3f} %)", flush=True)
        print(f"{label:24s} spread (max - min): training-only {np.ptp(train):.3f} %, reported {np.ptp(reported):.3f} %\n")
    run = records["60 s sweep, 0.5 %"]
    ident = SparseIdentifier().fit(run.recording)
    print("inclusion probability:", ident.result()["inclusion_probability"])
    truth = run.truth["model"]["q1_dot"]
    print("z = (estimate - truth) / SE:", {t: round((c - truth.get(t, 0.0)) / ident.standard_errors_["q1_dot"][t], 2)
                                          for t, c in ident.model_.equations["q1_dot"].items()})
    print("chain bias:", ident.uncertainty_["chain_bias"])
    print("timings (s):", {k: round(v, 3) for k, v in ident.timings_.items()})
    plain = SparseIdentifier(bias_replicates=0, placements=0).fit(run.recording)
    print("timings without bias replicates and placements (s):", {k: round(v, 3) for k, v in plain.timings_.items()})


if __name__ == "__main__":
    main()
