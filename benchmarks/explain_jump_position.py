"""Does the jump's position decide the explanation? Plain rigs (no effect) drawn wide, explained, and the
gap/floor and the answer compared between the cases whose measured jump falls in a held-out shooting
segment and the others (issue 32 item 1: "show, on plain rigs, that the gap/floor distribution does not
depend on the jump's position").

    python benchmarks/explain_jump_position.py                    # 40 cases, a new seed (printed)
    python benchmarks/explain_jump_position.py --cases 6          # a smoke run
    python benchmarks/explain_jump_position.py --seed S --case K  # reproduce case K of a printed run

Scenarios: plain rigs that jump. sim/wide.py's draw (design rig +-30 %, sweeps within 1-25 Hz turned upwards,
where the jump down is sharp (the down-sweeps' jumps up were seldom detected at all),
over 15-120 s, 1000 or 2048 Hz, noise 0.2-5 %, quantisation and hum as nuisances) with the table amplitude
drawn from JUMP_AMPLITUDE_MM instead, where the hardening rigs' response folds (the wide suite's amplitudes
mostly do not: its draws past sim.scenarios.MAX_RESPONSE_MM are redrawn, which leaves 0.8-2.2 mm, and 2 of
12 plain cases jumped), on a rig without end stops (MAX_PEAK_MM). Each case runs the public call,
`DiscrepancyAnalysis().fit(recording)`, and reads: the measured jump's time (result["jump"]), the
shooting segment it falls in (held out or not: analysis.fitter_), the share of the baseline's held-out
squared error that the largest held-out segment carries, the gap before over the noise floor, the answer.

Reported: per group (jump in a held-out segment / jump in a training segment / no jump) the rate of plain
answers (`none`, or only the nuisances the recording has: mains hum, quantisation) with its Wilson 95 % interval and the gap/floor quartiles, and a Mann-Whitney U test of gap/floor
between the first two groups (a p-value well above 0.05 with both groups populated: no dependence seen at
this size; the test's power is stated by the group sizes). Every case goes to --json as it ends.
Processes in parallel (--workers, default os.cpu_count()).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from scipy.stats import mannwhitneyu  # noqa: E402

from explain_robustness import wilson  # noqa: E402
from identify import DiscrepancyAnalysis  # noqa: E402
from sim.synth import run_sweep  # noqa: E402
from sim.wide import NUISANCE_NAMES, draw_base, nuisances  # noqa: E402

#: Table amplitudes drawn (mm): where the wide rigs' response folds.
JUMP_AMPLITUDE_MM = (1.5, 3.5)
#: The rigs here have no end stops and a response up to this (mm): a longer-travel build of the rig, so
#: that the jump, not the stops, shapes the response (tests/identify/test_explain_jump.py does the same).
MAX_PEAK_MM = 30.0
MAX_TRIES = 50
GROUPS = ("jump held out", "jump in training", "no jump")


def _jump_segment(analysis, t_s: float) -> tuple[int | None, bool | None]:
    """The shooting segment (index, held out?) holding the measured jump at t_s (recording time)."""
    f = analysis.fitter_
    sig = analysis.states_
    row = int(round(t_s * sig.fs_hz)) - sig.valid.start
    inside = np.flatnonzero((f.starts <= row) & (row < f.stops))
    if inside.size == 0:
        return None, None
    i = int(inside[0])
    return i, bool(f.seg_held[i])


def run_case(seed: int, i: int) -> dict:
    rec = {"seed": seed, "case": i, "reproduce": f"--seed {seed} --case {i}"}
    rng = np.random.default_rng([seed, i])
    for _ in range(MAX_TRIES):
        rig, sweep, fs, (table, mass), _ = draw_base(rng)
        rig = dataclasses.replace(rig, end_stop_travel_mm=None)
        lo, hi = sorted((sweep.f_start_hz, sweep.f_end_hz))  # up: the hardening rig's jump down is sharp
        sweep = dataclasses.replace(sweep, f_start_hz=lo, f_end_hz=hi, amplitude_mm=float(rng.uniform(*JUMP_AMPLITUDE_MM)))
        try:
            run = run_sweep(rig, sweep, fs, 2.0, table, mass, seed=[seed, i, 1])
        except ValueError:  # the rig diverged at this amplitude: an unlucky draw
            continue
        if run.truth["max_abs_q_m"] < MAX_PEAK_MM * 1e-3:
            break
    else:
        raise RuntimeError(f"no draw within {MAX_PEAK_MM} mm in {MAX_TRIES} tries")
    rec.update(rig={"mass_kg": rig.mass_kg, "fn_hz": rig.natural_frequency_hz,
                    "cubic_n_per_m3": rig.cubic_stiffness_n_per_m3},
               sweep=dataclasses.asdict(sweep), fs_hz=fs, noise=[table.noise_fraction, mass.noise_fraction],
               amplitude_mm=sweep.amplitude_mm, down=sweep.f_start_hz > sweep.f_end_hz,
               peak_mm=run.truth["max_abs_q_m"] * 1e3, record_s=run.recording.output.size / fs)
    t0, c0 = time.perf_counter(), time.process_time()
    analysis = DiscrepancyAnalysis().fit(run.recording)
    res = analysis.result()
    rec.update(seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0)
    jump = (res.get("jump") or {}).get("measured")
    held = analysis.fitter_.seg_held
    err = np.asarray(analysis.baseline_segment_errors_)[held]
    segment, jump_held = _jump_segment(analysis, jump["t_s"]) if jump else (None, None)
    present = {NUISANCE_NAMES[k] for k in nuisances(table, mass) if k in NUISANCE_NAMES}
    named = [e["name"] for e in res.get("effects") or []]
    rec.update(effect=res["effect"], confidence=res.get("confidence"), named=named, nuisances=sorted(present),
               plain=res["effect"] == "none" or (bool(named) and set(named) <= present),
               gap_over_floor=res["gap_before"] / res["noise_floor"],
               jump_t_s=jump["t_s"] if jump else None, jump_segment=segment,
               largest_held_share=float(err.max() / err.sum()) if err.sum() > 0 else 0.0,
               group=GROUPS[2] if jump is None or jump_held is None else GROUPS[0] if jump_held else GROUPS[1])
    return rec


def summary(cases: list[dict]) -> dict:
    out = {}
    for g in GROUPS:
        cs = [c for c in cases if c["group"] == g]
        k = sum(c["plain"] for c in cs)
        ratio = [c["gap_over_floor"] for c in cs]
        out[g] = {"n": len(cs), "none": k, "none_rate": k / len(cs) if cs else None,
                  "wilson95": wilson(k, len(cs)),
                  "gap_over_floor_quartiles": np.quantile(ratio, [0.25, 0.5, 0.75]).tolist() if cs else None,
                  "largest_held_share_median": float(np.median([c["largest_held_share"] for c in cs])) if cs else None}
    a = [c["gap_over_floor"] for c in cases if c["group"] == GROUPS[0]]
    b = [c["gap_over_floor"] for c in cases if c["group"] == GROUPS[1]]
    out["mann_whitney_p"] = float(mannwhitneyu(a, b).pvalue) if a and b else None
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--seed", type=int, help="reproduce a printed run (default: a fresh seed)")
    ap.add_argument("--case", type=int, help="only this case (with --seed)")
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--json", type=Path, help="every case and the summary, written as cases end")
    args = ap.parse_args(argv)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed} (--seed {seed} repeats this run); load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores",
          flush=True)
    todo = [args.case] if args.case is not None else list(range(args.cases))
    cases: list[dict] = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        futures = {pool.submit(run_case, seed, i): i for i in todo}
        for fut in as_completed(futures):
            try:
                c = fut.result()
            except Exception as exc:  # a crash is reported, the run goes on
                print(f"case {futures[fut]}: {type(exc).__name__}: {exc}", flush=True)
                continue
            cases.append(c)
            jt = "-" if c["jump_t_s"] is None else f"{c['jump_t_s']:.1f}s"
            print(f"[{len(cases)}/{len(todo)}] case {c['case']:3d} {'v' if c['down'] else '^'} "
                  f"Z={c['amplitude_mm']:.1f}mm peak {c['peak_mm']:4.1f}mm {c['record_s']:.0f}s jump {jt:7s} {c['group']:17s} "
                  f"largest held share {c['largest_held_share']:.2f} gap/floor {c['gap_over_floor']:.2f} "
                  f"-> {c['effect']}{'' if c['plain'] else ' NOT PLAIN'} ({c['cpu_seconds']:.1f} s CPU)", flush=True)
            if args.json:
                args.json.write_text(json.dumps({"seed": seed, "cases": sorted(cases, key=lambda r: r["case"])},
                                                indent=1, default=str))
    s = summary(cases)
    for g in GROUPS:
        r = s[g]
        q = r["gap_over_floor_quartiles"]
        print(f"{g:17s} n={r['n']:3d}  plain {r['none']}/{r['n']} [{r['wilson95'][0]:.2f}, {r['wilson95'][1]:.2f}]"
              + (f"  gap/floor quartiles {q[0]:.2f} {q[1]:.2f} {q[2]:.2f}" if q else ""))
    print(f"Mann-Whitney U, gap/floor, held out vs training: p = {s['mann_whitney_p']}")
    if args.json:
        args.json.write_text(json.dumps({"seed": seed, "cases": sorted(cases, key=lambda r: r["case"]),
                                         "summary": s}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
