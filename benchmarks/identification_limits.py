"""Identification at its limits (issue 11): even terms, short records, beyond the jump. Prints the figures
of docs/identification.md ("Even terms", "Short records", "Beyond the jump").

    python benchmarks/identification_limits.py [--part even|short|jump]     # ~4 min on 2 cores

Uses only the public API (SparseIdentifier.fit / result), so the same script measures an older checkout:
    BASE=$(mktemp -d) && git archive <commit> identify sim | tar -x -C "$BASE" && cp identify/_simkernel*.so "$BASE/identify/"
    PYTHONPATH="$BASE" python benchmarks/identification_limits.py
"""
import argparse
import itertools
import sys
import time
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1]))  # appended: a PYTHONPATH checkout comes first

from identify.chain.band import excited_band  # noqa: E402
from identify.errors import IdentificationError  # noqa: E402
from identify.identifier import SparseIdentifier  # noqa: E402
from sim.rig import RigParameters  # noqa: E402
from sim.sensors import Accelerometer  # noqa: E402
from sim.synth import run_sweep  # noqa: E402
from protocol.sweep import SineSweep  # noqa: E402


def run(rig, sweep, noise=0.005, seed=0, **kw):
    s = Accelerometer(noise_fraction=noise)
    return run_sweep(rig=rig, sweep=sweep, table_sensor=s, mass_sensor=s, seed=seed, **kw)


def terms_vs_truth(model, truth) -> str:
    q1 = model.equations["q1_dot"]
    known = " ".join(f"{t} {100 * (q1[t] / c - 1):+.2f}%" if t in q1 else f"{t} MISSING" for t, c in truth.items())
    spurious = sorted(set(q1) - set(truth))
    return known + ("  spurious: " + ", ".join(spurious) if spurious else "")


def even():
    print("== even terms: design rig + quadratic stiffness, 1-20 Hz at 1.3 mm, 0.5 % noise")
    for k2, (T, seed) in itertools.product((3e3, 1e4, 2e4, 3e4), ((40.0, 5), (40.0, 1), (15.0, 1))):
        rig = RigParameters.design(effects={"quadratic_stiffness": k2})
        r = run(rig, SineSweep(1.0, 20.0, T, 1.3), seed=seed)
        t0 = time.perf_counter()
        ident = SparseIdentifier(validate=False).fit(r.recording)
        dt = time.perf_counter() - t0
        off = ident.result()["chain"].get("displacement_below_band", {"carried": "n/a"})
        off_s = f"offset rms {off['rms_mm']:.3f} mm, {off['passes']} passes" if off.get("carried") is True else "no offset"
        print(f"k2 {k2:7.0f} N/m^2 {T:4.0f} s seed {seed}: {terms_vs_truth(ident.model_, rig.model().equations['q1_dot'])}"
              f"  [{off_s}, fit {dt:.2f} s]", flush=True)


    print("== even terms, other conditions (seed 2)")
    design = RigParameters.design
    t1 = RigParameters.paper_table1()
    t1q = RigParameters(t1.mass_kg, t1.damping_ns_per_m, t1.stiffness_n_per_m, t1.cubic_stiffness_n_per_m3,
                        t1.input_gain, {**t1.effects, "quadratic_stiffness": 2e4})
    for name, rig, sw, noise, fs, extra in (
            ("2e4, 2 % noise", design(effects={"quadratic_stiffness": 2e4}), SineSweep(1, 20, 40, 1.3), 0.02, 2048.0, ()),
            ("2e4, 60 s at 1000 Hz", design(effects={"quadratic_stiffness": 2e4}), SineSweep(1, 20, 60, 1.3), 0.005, 1000.0, ()),
            ("Table 1 rig + 2e4, 1.2 mm", t1q, SineSweep(1, 20, 60, 1.2), 0.005, 2048.0, ()),
            ("2e4 + Coulomb 0.1 N", design(effects={"quadratic_stiffness": 2e4, "coulomb_friction": 0.1}),
             SineSweep(1, 20, 40, 1.3), 0.005, 2048.0, ("sign(q1)",)),
            ("-2e4", design(effects={"quadratic_stiffness": -2e4}), SineSweep(1, 20, 40, 1.3), 0.005, 2048.0, ())):
        r = run(rig, sw, noise=noise, seed=2, fs_hz=fs)
        ident = SparseIdentifier(extra_terms=extra).fit(r.recording)
        print(f"{name}: {terms_vs_truth(ident.model_, rig.model().equations['q1_dot'])} -> {ident.result()['status']}",
              flush=True)


def short():
    print("== short records: 0.5-17 Hz 13 s sweeps ending with the sweep (design rig, 0.5 % noise), 12 seeds")
    for seed in range(12):
        rec = run(RigParameters.design(), SineSweep(0.5, 17.0, 13.0, 1.3), seed=seed, settle_s=0.0).recording
        lo = excited_band(rec.output - rec.input, rec.fs_hz)[0]
        try:
            out = "band %.3g-%.3g Hz" % SparseIdentifier(validate=False).fit(rec).states_.band_hz
        except IdentificationError as e:
            out = f"refused: {e}"
        print(f"seed {seed:2d}: response edge {lo:.3f} Hz; {out}", flush=True)
    print("== short records: 13-15 s sweeps at 1.3 mm, 0.5 % noise, seed 1: exact supports")
    exact = total = 0
    for (name, rig), settle, sw in itertools.product(
            (("design", RigParameters.design()), ("table1", RigParameters.paper_table1())), (0.0, 0.5, 2.0),
            (SineSweep(1, 20, 15, 1.3), SineSweep(1, 20, 14, 1.3), SineSweep(2, 20, 15, 1.3), SineSweep(1, 17, 15, 1.3))):
        rec = run(rig, sw, seed=1, settle_s=settle).recording
        try:
            model = SparseIdentifier(validate=False).fit(rec).model_
            ok = set(model.equations["q1_dot"]) == set(rig.model().equations["q1_dot"])
            line = terms_vs_truth(model, rig.model().equations["q1_dot"])
        except IdentificationError as e:
            ok, line = False, f"refused: {e}"
        exact += ok
        total += 1
        print(f"{name} {sw.f_start_hz:g}-{sw.f_end_hz:g} Hz {sw.duration_s:g} s settle {settle:g} s: {line}", flush=True)
    print(f"exact supports: {exact} of {total}")


def jump():
    print("== beyond the jump: design rig without end stops, 1-20 Hz at 3.5 mm, seed 0")
    rig = RigParameters.design(end_stop_travel_mm=None)
    truth = rig.model().equations["q1_dot"]
    for T, noise, fs in itertools.product((15.0, 25.0, 30.0, 45.0, 60.0), (0.005, 0.02), (2048.0, 1000.0)):
        r = run(rig, SineSweep(1.0, 20.0, T, 3.5), noise=noise, fs_hz=fs)
        ident = SparseIdentifier().fit(r.recording)
        doc = ident.result()
        q1 = ident.model_.equations["q1_dot"]
        nrmse = max(v["nrmse"] for v in doc["validation"]["heldout"].values())
        gain = -q1.get("zdd", 0.0)
        damping = q1.get("q1", 0.0) / truth["q1"] - 1
        print(f"{T:3.0f} s {100 * noise:3.1f} % {fs:5.0f} Hz max|q| {1e3 * r.truth['max_abs_q_m']:5.1f} mm: input gain {gain:.3f}"
              f" damping {100 * damping:+6.1f} % worst held-out NRMSE {nrmse:.3f} -> {doc['status']}"
              f"{': ' + doc['reason'][:70] if doc['reason'] else ''}", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", choices=("even", "short", "jump"))
    args = ap.parse_args()
    for part in (even, short, jump):
        if args.part in (None, part.__name__):
            part()
