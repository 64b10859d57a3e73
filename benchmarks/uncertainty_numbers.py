"""What the uncertainty step reports on five fixed sweeps, to compare two versions of the code.

    python benchmarks/uncertainty_numbers.py dump before.json      # on one version (a checkout)
    python benchmarks/uncertainty_numbers.py dump after.json       # on the other
    python benchmarks/uncertainty_numbers.py compare before.json after.json

Sweeps (1-20 Hz, 2048 Hz, both accelerometers at the noise given): benchmarks/identify_speed.py's
million-sample record (Table 1 rig, 1.2 mm, 0.5 %), and four of 30-60 s: Table 1 at 1.2 mm / 0.5 % /
60 s (seed 2), 1.3 mm / 0.5 % / 60 s (seed 1, the issue's case), 1.0 mm / 5 % / 30 s (seed 3), the design
rig (1.8 mm pre-stress) at 1.1 mm / 2 % / 30 s (seed 4). For each, SparseIdentifier(validate=False) as
shipped: the reported coefficients and standard errors, the chain bias and the noise's share of each
variance (closed form), and the inclusion probabilities. `compare` prints, per sweep and quantity, the
largest relative change (absolute for probabilities). Standard errors and noise shares of an exactly
fitted equation (q2_dot = q1: a standard error ~1e-16 of the coefficient, rounding) are left out.
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

KEYS = ("coef", "se", "bias", "noise_share", "p_in")


def dump(path: str) -> None:
    import identify.trust.uncertainty as unc
    from identify import SparseIdentifier
    from identify_speed import sweep_recording
    from sim.rig import RigParameters
    from sim.sensors import Accelerometer
    from sim.synth import run_sweep
    from protocol.sweep import SineSweep

    shares = {}
    closed_form = unc.analytic_chain_bias

    def keep_share(*args, **kw):  # the noise's share is not in the result: read it where it is made
        out = closed_form(*args, **kw)
        if out is not None:
            shares["last"] = out["spread_var"]
        return out

    unc.analytic_chain_bias = keep_share
    sweeps = {"million": sweep_recording(1_000_000)[0]}
    table1, design = RigParameters.paper_table1(), RigParameters.design(prestress_m=1.8e-3, damping_ns_per_m=2.0)
    for name, rig, amp, noise, seconds, seed in (("t1_1.2mm_60s", table1, 1.2, 0.005, 60, 2),
                                                 ("t1_1.3mm_60s", table1, 1.3, 0.005, 60, 1),
                                                 ("t1_5pc_30s", table1, 1.0, 0.05, 30, 3),
                                                 ("design_2pc_30s", design, 1.1, 0.02, 30, 4)):
        sensors = {k: Accelerometer(noise_fraction=noise) for k in ("table_sensor", "mass_sensor")}
        sweeps[name] = run_sweep(rig, SineSweep(1, 20, seconds, amp), fs_hz=2048, seed=seed, **sensors).recording
    out = {}
    for name, rec in sweeps.items():
        ident = SparseIdentifier(validate=False).fit(rec)
        names, eqs = ident.library_.names, list(ident.selections_)
        share = {eqs[e]: {names[j]: float(v[j]) for j in np.flatnonzero(v)} for e, v in shares.pop("last", {}).items()}
        out[name] = {"coef": ident.model_.equations, "se": ident.standard_errors_, "noise_share": share,
                     "bias": {eq: (ident.uncertainty_["chain_bias"] or {}).get(eq, {}) for eq in eqs},
                     "p_in": ident.uncertainty_["inclusion_probability"] or {}}
        print(name, json.dumps(out[name]["se"]), flush=True)
    Path(path).write_text(json.dumps(out, indent=1))


def compare(path_a: str, path_b: str) -> None:
    a, b = (json.loads(Path(p).read_text()) for p in (path_a, path_b))
    for sweep in a:
        worst = {}
        for key in KEYS:
            for eq, terms in a[sweep][key].items():
                for term, x in terms.items():
                    y = b[sweep][key].get(eq, {}).get(term, float("nan"))
                    coef = a[sweep]["coef"].get(eq, {}).get(term, 0.0)
                    spread = abs(x) if key == "se" else np.sqrt(abs(x)) if key == "noise_share" else None
                    if spread is not None and spread < 1e-12 * abs(coef):
                        continue  # exactly fitted: rounding
                    if key == "p_in":
                        d = abs(y - x)
                    else:
                        d = abs(y - x) / abs(x) if x else abs(y)
                    worst[key] = max(worst.get(key, 0.0), d)
        print(f"{sweep:16s} " + "  ".join(f"{k} {worst.get(k, 0.0):.1e}" for k in KEYS))


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "dump":
        dump(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
