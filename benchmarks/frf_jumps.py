"""Measured sweep jumps against the model's folds: the figures of docs/frf.md ("The measured counterpart" and
"Side by side"), from the simulated Table 1 rig with known truth, sensor noise drawn from a printed seed.

  python benchmarks/frf_jumps.py [--seed S] [--figure docs/frf-overlay.png]

1. The paper's sweep (1-20 Hz in 60 s, 0.317 Hz/s) up and down at 1.0, 1.1, 1.2 and 1.3 mm:
   identify.frf.measured.compare_sweep with the true model (the measured jump, the steady-state fold at the
   recorded table amplitude, the sweep-rate bias, agreement), and, for an up-sweep, where the true response
   falls off its upper branch (the first table cycle past the peak below half of it) beside the measured
   jump (a down-sweep's rise onto the upper branch grows over many cycles: no one cycle to compare with).
2. The side-by-side figure: 4-8 Hz up and down in 40 s (0.1 Hz/s) at 0.8, 1.1 and 1.2 mm against the Table 1
   model and the same model with 20 % less cubic stiffness (judged): identify.frf.side_by_side and
   reports.frf_overlay.overlay_figure, written to --figure when given; its jump table printed.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identify.frf.measured import compare_sweep, cycle_envelope, sweep_envelope  # noqa: E402
from identify.frf.side_by_side import side_by_side  # noqa: E402
from protocol.sweep import SineSweep  # noqa: E402
from reports.frf_overlay import jump_rows, overlay_figure  # noqa: E402
from sim.rig import RigParameters  # noqa: E402
from sim.sensors import Accelerometer  # noqa: E402
from sim.synth import run_sweep  # noqa: E402

NOISE = 0.005  # sensor noise, share of each channel's RMS
RIG = RigParameters.paper_table1()


def _run(sweep: SineSweep, seed):
    sensor = Accelerometer(noise_fraction=NOISE)
    return run_sweep(RIG, sweep, table_sensor=sensor, mass_sensor=sensor, seed=seed)


def true_fall(run) -> float:
    """Frequency (Hz, mid-cycle) where an up-sweep's true response falls off its upper branch: the first
    table cycle past the peak below half of it (and the one before)."""
    env = sweep_envelope(run.recording)
    rows = env["signals"].valid
    true = cycle_envelope(run.states[rows, 1], np.asarray(env["signals"].input[rows]), run.recording.fs_hz)
    a, f = true["response_mm"], true["frequency_hz"]
    peak = int(np.argmax(a))
    k = peak + int(np.flatnonzero(a[peak:] < 0.5 * a[peak])[0])
    return float(0.5 * (f[k - 1] + f[k]))


def hz(x, fmt=".3f") -> str:
    return "-" if x is None else format(x, fmt)


def paper_sweeps(seed: int) -> None:
    print("1. the paper's sweep, 1-20 Hz in 60 s, compare_sweep with the true model")
    print(f"{'mm':>4} {'dir':>4} {'measured jump, Hz':>20} {'fold':>7} {'bias':>7} {'own run':>8} "
          f"{'agrees':>6} {'true fall':>9}")
    for k, amplitude in enumerate((1.0, 1.1, 1.2, 1.3)):
        for direction in ("up", "down"):
            f0, f1 = (1.0, 20.0) if direction == "up" else (20.0, 1.0)
            run = _run(SineSweep(f0, f1, 60.0, amplitude), [seed, k, direction == "up"])
            cmp = compare_sweep(RIG.model(), run.recording)
            j, own = cmp["measured"], cmp["model_sweep_jump"]
            measured = "none" if j is None else f"{j['frequency_hz']:.3f} +- {j['uncertainty_hz']:.3f}"
            print(f"{amplitude:4.1f} {direction:>4} {measured:>20} {hz(cmp['fold_hz']):>7} "
                  f"{hz(cmp['bias_hz'], '+.3f'):>7} {hz(own and own['frequency_hz']):>8} {str(cmp['agrees']):>6} "
                  f"{hz(true_fall(run) if direction == 'up' else None):>9}")


def side_by_side_figure(seed: int, figure: str | None) -> None:
    print("\n2. side by side: 4-8 Hz in 40 s, up and down, Table 1 model and 20 % less cubic stiffness (judged)")
    recordings, names = [], []
    for k, amplitude in enumerate((0.8, 1.1, 1.2)):
        for direction, (f0, f1) in (("up", (4.0, 8.0)), ("down", (8.0, 4.0))):
            recordings.append(_run(SineSweep(f0, f1, 40.0, amplitude), [seed, 10 + k, direction == "up"]).recording)
            names.append(f"{amplitude:g} mm {direction}")
    softer = replace(RIG, cubic_stiffness_n_per_m3=0.8 * RIG.cubic_stiffness_n_per_m3)
    doc = side_by_side({"Table 1": RIG.model(), "k3 - 20 %": softer.model()}, recordings, fit_percent=99.0,
                       judged="k3 - 20 %", names=names)
    for row in jump_rows(doc):
        print("  " + " | ".join(row))
    for flag in doc["flags"]:
        print(f"  flagged: {flag}")
    if figure:
        overlay_figure(doc, figure)
        print(f"  figure: {figure}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, help="reproduce a printed run (default: a new seed)")
    p.add_argument("--figure", help="write the side-by-side figure here (e.g. docs/frf-overlay.png)")
    args = p.parse_args(argv)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed} (--seed {seed} repeats this run's noise); sensor noise {NOISE:.1%}; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    paper_sweeps(seed)
    side_by_side_figure(seed, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
