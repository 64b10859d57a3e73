"""Discrepancy workflow on randomised scenarios with known truth: how often it is right, per category,
and whether its stated confidence means what it says.

    python benchmarks/explain_robustness.py --cases 150            # a new seed, printed (hours on 2 cores)
    python benchmarks/explain_robustness.py --cases 15 --json out.json
    python benchmarks/explain_robustness.py --seed 12 --only 72     # reproduce one case of a printed seed

Every run draws a new seed (printed first) unless --seed is given: the suite is never tuned on one draw.
On top of sim/scenarios.py's draws, each case's sweep runs down instead of up with probability
DOWN_SHARE, and with probability NUISANCE_SHARE its recording gets measurement nuisances: quantisation
of both channels to 10-16 bits over their range and/or mains hum (50 or 60 Hz, 1-5 % of the channel's
std) on one channel. Both are printed per case and tallied apart.

Scenarios come from sim/scenarios.py (categories none / single / two_effects / sensor_fault /
out_of_catalog; rig, sweep, sample rate, noise and effect sizes drawn there, see its docstring). The plan
is a fixed pattern of nine slots -- single, none, sensor_fault, two_effects, single, out_of_catalog,
sensor_fault, two_effects, single -- so any --cases covers the categories in those proportions and
`single`, `sensor_fault` and `out_of_catalog` cycle through their effect names in turn. Case i draws its
scenario from default_rng([seed, i]) and its sensor noise from seed i, so a case can be rerun alone
(--only i).

Each case runs `DiscrepancyAnalysis().fit(recording).result()` and is scored by the contract's rules
(sim.scenarios.score): none -> effect "none"; single -> the first effect named is the truth and the gap
is at least halved; two_effects -> both truth names among the effects and no wrong physical name at
confidence >= 0.5; sensor_fault -> the first effect is the truth (a measurement effect);
out_of_catalog -> "unexplained", or a first effect flagged as a surrogate that halves the gap. A wrong
physical name is a physics entry at confidence >= 0.5 outside the truth and its surrogate groups
(sim.scenarios.SURROGATE_GROUPS); counted on its own, the target is 0. A result without an `effects`
list (before issue 12) is read as one physics entry for its `effect`.

Per category: right, honest (not right, but `unexplained` with no wrong physical name) and miss, with
Wilson 95 % intervals on the right rate. Prints one line per case, the tally per category, and two
calibration tables: the first named effect's
stated confidence (binned) against the rate at which the case was right, and every named entry's
confidence against the rate at which that name is true (in the truth or its surrogate group).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identify.explain import DiscrepancyAnalysis  # noqa: E402
from sim.scenarios import (CATEGORIES, MEASUREMENT, OUT_OF_CATALOG, PHYSICS, SURROGATE_GROUPS,  # noqa: E402
                           make_scenario, result_effects, score)

PATTERN = ("single", "none", "sensor_fault", "two_effects", "single", "out_of_catalog", "sensor_fault",
           "two_effects", "single")
CYCLE = {"single": PHYSICS, "sensor_fault": MEASUREMENT, "out_of_catalog": OUT_OF_CATALOG}
BINS = (0.0, 0.25, 0.5, 0.75, 0.9, 1.0001)
#: Share of cases swept down instead of up, and share given quantisation and/or mains hum.
DOWN_SHARE = 0.3
NUISANCE_SHARE = 0.25
BITS = (10, 16)
HUM_SHARE = (0.01, 0.05)
#: z of the Wilson intervals (95 %).
WILSON_Z = 1.96
KEEP = ("effect", "effects", "terms", "confidence", "gap_before", "gap_after", "gap_closed", "noise_floor",
        "remaining")


def plan(n_cases: int) -> list[tuple[str, list[str] | None]]:
    """(category, truth names or None to draw) for each case, in the order run."""
    seen = {c: 0 for c in CATEGORIES}
    out = []
    for i in range(n_cases):
        cat = PATTERN[i % len(PATTERN)]
        names = [CYCLE[cat][seen[cat] % len(CYCLE[cat])]] if cat in CYCLE else None
        seen[cat] += 1
        out.append((cat, names))
    return out


def wilson(k: int, n: int, z: float = WILSON_Z) -> tuple[float, float]:
    """Wilson score interval of a rate k / n."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return float(max(mid - half, 0.0)), float(min(mid + half, 1.0))


def nuisances(rng: np.random.Generator, recording) -> dict:
    """Quantisation and/or mains hum added to `recording` in place (drawn with NUISANCE_SHARE)."""
    if rng.random() >= NUISANCE_SHARE:
        return {}
    out = {}
    kind = rng.choice(["quantisation", "hum", "both"])
    if kind in ("quantisation", "both"):
        bits = int(rng.integers(BITS[0], BITS[1] + 1))
        for x in (recording.input, recording.output):
            step = (np.max(x) - np.min(x)) / 2 ** bits
            x[:] = np.round(x / step) * step
        out["bits"] = bits
    if kind in ("hum", "both"):
        f = float(rng.choice([50.0, 60.0]))
        share = float(rng.uniform(*HUM_SHARE))
        x = recording.output if rng.random() < 0.5 else recording.input
        t = np.arange(x.size) / recording.fs_hz
        x += share * np.std(x) * np.sqrt(2) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        out.update(hum_hz=f, hum_share=share)
    return out


def run_case(i: int, seed: int, category: str, names) -> dict:
    t0 = time.perf_counter()
    rng = np.random.default_rng([seed, i])
    sc = make_scenario(rng, category, names)
    down = bool(rng.random() < DOWN_SHARE)
    if down:
        sc = dataclasses.replace(sc, sweep=dataclasses.replace(sc.sweep, f_start_hz=sc.sweep.f_end_hz,
                                                               f_end_hz=sc.sweep.f_start_hz))
    run = sc.run(seed=i)
    extra = nuisances(rng, run.recording)
    rec = {"case": i, "category": category, "truth": sc.truth_effects, "scenario": sc.describe(),
           "magnitudes": sc.magnitudes, "sim_seconds": time.perf_counter() - t0, "down": down, "nuisance": extra}
    t0 = time.perf_counter()
    try:
        res = DiscrepancyAnalysis().fit(run.recording).result()
    except Exception as exc:  # a crash is a wrong answer, not the end of the suite
        rec.update(error=f"{type(exc).__name__}: {exc}", right=False, wrong_names=[], names=[], seconds=0.0)
        traceback.print_exc()
        return rec
    rec["seconds"] = time.perf_counter() - t0
    rec["result"] = {k: res.get(k) for k in KEEP if k in res}
    rec["effects"] = result_effects(res)
    rec.update(score(category, sc.truth_effects, res))
    return rec


def line(r: dict) -> str:
    if "error" in r:
        return f"ERR {r['case']:3d} {r['category']:14s} {','.join(r['truth']) or '-':44s} {r['error'][:80]}"
    res = r["result"]
    named = ", ".join(f"{e['name']}{'~' if e.get('surrogate_for') else ''}({(e.get('confidence') or 0):.2f})"
                      for e in r["effects"]) or res.get("effect")
    closed = res.get("gap_closed")
    wrong = f" WRONG-NAME {','.join(r['wrong_names'])}" if r["wrong_names"] else ""
    tags = ("v" if r.get("down") else "^") + "".join(f" {k}={v:.3g}" for k, v in r.get("nuisance", {}).items())
    return (f"{'OK ' if r['right'] else 'BAD'} {r['case']:3d} {r['category']:14s} {tags:28s} {','.join(r['truth']) or '-':44s} -> "
            f"{named:50s} closed={'-' if closed is None else f'{closed:.2f}'} gap={res.get('gap_before') or 0:.4f} "
            f"{r['seconds']:.1f}s{wrong}")


def calibration(pairs: list[tuple[float, bool]]) -> list[dict]:
    rows = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        hits = [ok for c, ok in pairs if lo <= c < hi]
        rows.append({"confidence": f"{lo:.2f}-{min(hi, 1.0):.2f}", "n": len(hits),
                     "right_rate": (sum(hits) / len(hits)) if hits else None,
                     "mean_confidence": float(np.mean([c for c, _ in pairs if lo <= c < hi])) if hits else None})
    return rows


def summary(records: list[dict]) -> dict:
    tally = {}
    groups = {c: [r for r in records if r["category"] == c] for c in CATEGORIES}
    groups.update({"swept down": [r for r in records if r.get("down")],
                   "with nuisance": [r for r in records if r.get("nuisance")], "all": records})
    for c, rs in groups.items():
        right = sum(r["right"] for r in rs)
        honest = sum(not r["right"] and not r["wrong_names"] and (r.get("result") or {}).get("effect") == "unexplained"
                     for r in rs)
        tally[c] = {"right": right, "honest": honest, "miss": len(rs) - right - honest, "n": len(rs),
                    "right_wilson95": wilson(right, len(rs))}
    by_case = [((r["effects"][0].get("confidence") or 0.0), r["right"]) for r in records if r.get("effects")]
    by_entry = []
    for r in records:
        allowed = set(r["truth"]) | {g for t in r["truth"] for g in SURROGATE_GROUPS.get(t, ())}
        for e in r.get("effects", []):
            true = e["name"] in allowed or bool(set(e.get("surrogate_for") or ()) & set(r["truth"]))
            by_entry.append(((e.get("confidence") or 0.0), true))
    n = len(records)
    return {"cases": n, "right": sum(r["right"] for r in records), "tally": tally,
            "wrong_names_at_0.5": sum(len(r["wrong_names"]) for r in records),
            "cases_with_wrong_name": sum(bool(r["wrong_names"]) for r in records),
            "errors": sum("error" in r for r in records),
            "seconds_per_case": float(np.mean([r["seconds"] for r in records])) if records else 0.0,
            "sim_seconds_per_case": float(np.mean([r["sim_seconds"] for r in records])) if records else 0.0,
            "calibration_by_case": calibration(by_case), "calibration_by_entry": calibration(by_entry)}


def print_summary(s: dict) -> None:
    print(f"\nright: {s['right']} / {s['cases']} ({100 * s['right'] / max(s['cases'], 1):.0f} %; target >= 90 %)")
    print("  category        right honest  miss     n   right rate [Wilson 95 %]")
    for c, t in s["tally"].items():
        lo, hi = t["right_wilson95"]
        rate = f"{t['right'] / t['n']:.2f} [{lo:.2f}, {hi:.2f}]" if t["n"] else "-"
        print(f"  {c:14s} {t['right']:6d} {t['honest']:6d} {t['miss']:5d} {t['n']:5d}   {rate}")
    print(f"wrong physical names at confidence >= 0.5: {s['wrong_names_at_0.5']} (in {s['cases_with_wrong_name']} "
          f"cases; target 0); errors: {s['errors']}; per case: analysis {s['seconds_per_case']:.1f} s, "
          f"scenario {s['sim_seconds_per_case']:.1f} s")
    for key, what in (("calibration_by_case", "first effect's confidence vs case right"),
                      ("calibration_by_entry", "each named effect's confidence vs name true")):
        print(f"\n{what}:\n  confidence   n   right-rate  mean-confidence")
        for row in s[key]:
            rate = "-" if row["right_rate"] is None else f"{row['right_rate']:.2f}"
            mc = "-" if row["mean_confidence"] is None else f"{row['mean_confidence']:.2f}"
            print(f"  {row['confidence']:10s} {row['n']:3d}   {rate:>10s}  {mc:>15s}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=150)
    ap.add_argument("--seed", type=int, default=None, help="reproduce a printed run (default: a new seed)")
    ap.add_argument("--only", type=int, nargs="*", help="run only these case indices (of the --cases plan)")
    ap.add_argument("--json", help="write per-case records and the summary here")
    args = ap.parse_args(argv)
    if args.seed is None:
        args.seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {args.seed} (rerun with --seed {args.seed})", flush=True)
    records = []
    for i, (cat, names) in enumerate(plan(args.cases)):
        if args.only and i not in args.only:
            continue
        records.append(run_case(i, args.seed, cat, names))
        print(line(records[-1]), flush=True)
    s = summary(records)
    print_summary(s)
    if args.json:
        Path(args.json).write_text(json.dumps({"seed": args.seed, "cases": records, "summary": s}, indent=1,
                                              default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
