"""Speed of identify.frf.frequency_response (docs/frf.md, Speed): the Table 1 model at 1.1 and 1.2 mm
over 1-20 Hz (both folds), wall and CPU time per call after one warm-up call, default threads, and the
machine's load average (wall time on a shared machine is the load's, CPU time is the call's).

    .venv/bin/python benchmarks/frf_speed.py
"""
import os
import time

from identify import frequency_response
from sim.rig import RigParameters


def main() -> None:
    model = RigParameters.paper_table1().model()
    frequency_response(model, 1.2, (1, 20))  # warm-up: imports, caches
    for amplitude in (1.1, 1.2, 1.2, 1.2):
        wall, cpu = time.perf_counter(), time.process_time()
        r = frequency_response(model, amplitude, (1, 20))
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        points = sum(len(b["frequency_hz"]) for b in r.branches)
        print(f"{amplitude} mm: wall {wall:.3f} s, cpu {cpu:.3f} s, H = {r.harmonics}, {points} points, "
              f"folds {r.jump_down_hz:.4f} / {r.jump_up_hz:.4f} Hz")
    print("load average (1, 5, 15 min):", " ".join(f"{x:.1f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
