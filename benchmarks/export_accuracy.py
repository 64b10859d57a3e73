"""How closely an exported FMU runs the model: the paper's Table 1 model exported with `shakeid export`'s
code (identify.export), stepped by FMPy with 1 ms communication steps under a 5 Hz base excitation (the
table at 1.0-1.5 mm, random phase; fresh seed each run, printed), against shakeid's compiled free run.

    python benchmarks/export_accuracy.py [--rounds 3]

Relative RMS of q1 and q2 (RMS of the difference over the RMS of the reference), per round:
  held       FMU, input held over each step (FMPy's default)  vs shakeid's free run of the held input, its own
             step choice (1 RK4 step per ms)
  held-fine  the same FMU                                     vs that free run with 32 RK4 steps per ms (~exact)
  coarse     the FMU with max_step_s = 1 ms (1 RK4 step)      vs the ~exact run: what the internal substeps buy
  linear     FMU given the input's slope each step            vs shakeid's free run, input linearly interpolated
  zoh        FMU, input held                                  vs shakeid's default free run of the same samples
             (band-limited interpolation): the price of holding the input, not an integration error
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from identify.export import export_model  # noqa: E402
from identify.simulation.simulate import choose_substeps, simulate  # noqa: E402
from sim.rig import RigParameters  # noqa: E402

DT_S, N, F_HZ = 1e-3, 5001, 5.0


def held_run(model, u, substeps):
    x, out = np.zeros(2), [np.zeros(2)]
    for uk in u[:-1]:
        x = simulate(model, DT_S, x, inputs_fine=np.full((2 * substeps + 1, 1), uk), substeps=substeps,
                     n_samples=2).states[1]
        out.append(x)
    return np.array(out)


def fmu_run(path, u, start_values=None):
    sig = np.zeros(u.size, dtype=[("time", float), ("zdd", float)])
    sig["time"], sig["zdd"] = np.arange(u.size) * DT_S, u
    r = simulate_fmu(str(path), input=sig, output=["q1", "q2"], stop_time=(u.size - 1) * DT_S, output_interval=DT_S,
                     start_values=start_values or {})
    return np.column_stack([r["q1"], r["q2"]])


def fmu_linear_run(path, u):
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    out = [fmu.getReal([vr["q1"], vr["q2"]])]
    for k in range(u.size - 1):
        fmu.setReal([vr["zdd"]], [u[k]])
        fmu.setRealInputDerivatives([vr["zdd"]], [1], [(u[k + 1] - u[k]) / DT_S])
        fmu.doStep(k * DT_S, DT_S)
        out.append(fmu.getReal([vr["q1"], vr["q2"]]))
    fmu.terminate()
    fmu.freeInstance()
    return np.array(out)


def rel(a, b):
    e = np.sqrt(np.mean((a - b) ** 2, axis=0)) / np.sqrt(np.mean(b**2, axis=0))
    return f"q1 {e[0]:.2e}  q2 {e[1]:.2e}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    seed = np.random.SeedSequence().entropy
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    model = RigParameters.paper_table1().model()
    own = choose_substeps(model, DT_S, [0.5, 0.02])
    with tempfile.TemporaryDirectory() as tmp:
        path = export_model(model, "fmu", Path(tmp) / "table1.fmu", "Table 1")
        for r in range(args.rounds):
            amp, phase = rng.uniform(1.0e-3, 1.5e-3), rng.uniform(0, 2 * np.pi)
            w = 2 * np.pi * F_HZ
            u = -amp * w**2 * np.sin(w * np.arange(N) * DT_S + phase)
            fmu, exact = fmu_run(path, u), held_run(model, u, 32)
            print(f"round {r + 1}: table {amp * 1e3:.2f} mm, max |q2| {np.abs(exact[:, 1]).max() * 1e3:.1f} mm")
            print(f"  held       {rel(fmu, held_run(model, u, own))}  (shakeid: {own} RK4 step(s) per ms)")
            print(f"  held-fine  {rel(fmu, exact)}")
            print(f"  coarse     {rel(fmu_run(path, u, {'max_step_s': DT_S}), exact)}")
            lin = simulate(model, DT_S, [0.0, 0.0], u, interpolation="linear", substeps=10).states
            print(f"  linear     {rel(fmu_linear_run(path, u), lin)}")
            print(f"  zoh        {rel(fmu, simulate(model, DT_S, [0.0, 0.0], u).states)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
