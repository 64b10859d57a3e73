"""The uncertainty step's cost with the chain bias in closed form (default) and with SIMEX, on the
service's record size: Table 1 rig, 60 s 1-20 Hz sweep at 1.3 mm, 0.5 % noise, 2048 Hz (126 977 samples;
SIMEX takes 64 replicates there). CPU seconds of SparseIdentifier().fit (with validation) and its
refit_uncertainty part, 3 rounds, one process.

    python benchmarks/bias_methods.py
"""
import time
from identify.identifier import SparseIdentifier
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from sim.sweep import SineSweep
s = dict(table_sensor=Accelerometer(noise_fraction=0.005), mass_sensor=Accelerometer(noise_fraction=0.005))
rec = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 60, 1.3), seed=1, **s).recording
print(rec.n_samples)
for r in range(3):
    for m in ("auto", "simex"):
        t = time.process_time(); i = SparseIdentifier(bias_method=m).fit(rec); print(m, round(time.process_time() - t, 3), round(i.timings_["refit_uncertainty"], 3))
