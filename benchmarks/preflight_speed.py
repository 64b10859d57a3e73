"""Speed of the preflight's prediction (docs/daq.md, "Preflight that predicts"): the call every front end
makes before a sweep reaches the PLC, `daq.sweep.predicted_verdict`, on the simulated rig's nominal model
(examples/sim-rig.toml), default threads, wall and CPU time per call, and the machine's load average.

    .venv/bin/python benchmarks/preflight_speed.py [--seed S]

Sweeps: the docs' three (1-20 Hz over 300 s at 1.0 mm: passes; the paper's 60 s at 1.3 mm: warned; 300 s at
1.3 mm: refused, with its search for what passes), then three fresh 1-20 Hz sweeps of 15-300 s at
0.6-1.3 mm (seed printed). The model is nominal (no noise): the prediction's cost depends on the sweep only.
"""
import argparse
import os
import time

import numpy as np

from daq.preflight import nominal_response
from daq.sweep import SweepRequest, predicted_verdict
from sim.config import load_config


def timed(response, duration_s: float, amplitude_mm: float) -> None:
    """One predicted_verdict call, printed with its wall and CPU time and its verdict."""
    req = SweepRequest(f_start_hz=1.0, f_end_hz=20.0, duration_s=duration_s, amplitude_mm=amplitude_mm)
    wall, cpu = time.perf_counter(), time.process_time()
    verdict = predicted_verdict(response, req)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    said = "refused" if verdict.refusal else ("warned" if verdict.warnings else "passes")
    print(f"1-20 Hz, {duration_s:5.1f} s, {amplitude_mm:.2f} mm: wall {wall:.3f} s, cpu {cpu:.3f} s; "
          f"travel peak {verdict.record['travel_peak_mm']:.2f} mm; {said}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=None, help="the fresh sweeps' seed (default: fresh, printed)")
    args = p.parse_args()
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}; load average (1, 5, 15 min) at the start:", " ".join(f"{x:.1f}" for x in os.getloadavg()))
    response = nominal_response(load_config("examples/sim-rig.toml"))
    predicted_verdict(response, SweepRequest(1.0, 20.0, 10.0, 0.5))  # warm-up: imports, the compiled kernel
    for duration_s, amplitude_mm in ((300.0, 1.0), (60.0, 1.3), (300.0, 1.3)):
        timed(response, duration_s, amplitude_mm)
    rng = np.random.default_rng(seed)
    for _ in range(3):
        timed(response, round(float(rng.uniform(15, 300)), 1), round(float(rng.uniform(0.6, 1.3)), 2))
    print("load average (1, 5, 15 min) at the end:", " ".join(f"{x:.1f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
