"""Evidence for the default selection rule: how often each rule returns the true support.

    python benchmarks/selection_rules.py [--seeds 3]

Simulated sweeps of the paper's Table 1 rig (1-20 Hz, 60 s) at several table amplitudes (a smaller
amplitude makes the q1*q2^2 term weaker) and sensor noise levels; for each rule the share of seeds whose
q1_dot support is exactly {q1, q2, q1*q2^2, q2^3, zdd}, and what went wrong otherwise. Feeds
docs/identification.md.
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identify.identifier import SparseIdentifier  # noqa: E402
from sim.rig import RigParameters  # noqa: E402
from sim.sensors import Accelerometer  # noqa: E402
from protocol.sweep import SineSweep  # noqa: E402
from sim.synth import run_sweep  # noqa: E402

RULES = ("paper", "heldout", "bic")


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--noise", type=float, nargs="*", default=[0.005, 0.02, 0.05, 0.1, 0.2, 0.3])
    p.add_argument("--amplitudes-mm", type=float, nargs="*", default=[1.3, 0.8])
    args = p.parse_args(argv)
    truth = set(RigParameters.paper_table1().model().equations["q1_dot"])
    print(f"{'amp mm':>6s} {'noise':>6s} " + " ".join(f"{r:>22s}" for r in RULES))
    for amp in args.amplitudes_mm:
        for noise in args.noise:
            sensor = Accelerometer(noise_fraction=noise)
            hits, faults = Counter(), {r: Counter() for r in RULES}
            for seed in range(args.seeds):
                run = run_sweep(sweep=SineSweep(amplitude_mm=amp), table_sensor=sensor, mass_sensor=sensor, seed=seed)
                for rule in RULES:
                    got = set(SparseIdentifier(selection=rule, validate=False).fit(run.recording)
                              .model_.equations["q1_dot"])
                    if got == truth:
                        hits[rule] += 1
                    else:
                        faults[rule].update([f"-{t}" for t in truth - got] + [f"+{t}" for t in got - truth])
            cells = []
            for rule in RULES:
                worst = ",".join(k for k, _ in faults[rule].most_common(2))
                cells.append(f"{hits[rule]}/{args.seeds} {worst}"[:22])
            print(f"{amp:6.2f} {noise:6.1%} " + " ".join(f"{c:>22s}" for c in cells), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
