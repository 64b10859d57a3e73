"""benchmarks/explain_robustness.py's own machinery on two tiny cases (4 s sweeps): a case reproduces from
(seed, case) alone, the plan is the same whatever --cases, the scoring and Wilson intervals are right, and
the per-case record carries what the JSON promises."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import explain_robustness as bench  # noqa: E402


def test_wilson_interval_matches_the_closed_form():
    # textbook values (Wilson 1927; e.g. Newcombe 1998 table I): 0/10 -> [0, 0.278], 9/10 -> [0.596, 0.982]
    assert bench.wilson(0, 10) == pytest.approx((0.0, 0.2775), abs=5e-4)
    assert bench.wilson(9, 10) == pytest.approx((0.5958, 0.9821), abs=5e-4)
    assert bench.wilson(0, 0) == (0.0, 1.0)


def test_plan_is_prefix_stable_and_cycles_through_every_name():
    cases = [bench.plan_case(i) for i in range(240)]
    singles = [names[0] for cat, names in cases if cat == "single"]
    assert set(singles) == set(bench.PHYSICS) and len(singles) == 80
    assert {names[0] for cat, names in cases if cat == "sensor_fault"} == set(bench.MEASUREMENT)
    assert [bench.plan_case(i) for i in range(12)] == cases[:12]


@pytest.mark.slow
def test_two_tiny_cases_reproduce_and_are_scored():
    a = [bench.run_case(123, i, duration_s=4.0) for i in (0, 1)]
    again = bench.run_case(123, 1, duration_s=4.0)
    for r in a:
        assert "error" not in r and "draw_error" not in r, r.get("error") or r.get("draw_error")
        assert {"seed", "case", "drawn", "truth", "effects", "right", "seconds", "cpu_seconds"} <= set(r)
    assert a[0]["category"] == "single" and a[0]["truth"] == [bench.PHYSICS[0]]
    assert a[1]["category"] == "none" and a[1]["truth"] == []
    # (seed, case) alone fixes the draw and the noise: the same answer again
    assert again["drawn"] == a[1]["drawn"] and again["effects"] == a[1]["effects"] and again["right"] == a[1]["right"]
    s = bench.summary(a)
    assert s["cases"] == 2 and s["tally"]["all"]["n"] == 2 and s["tally"]["none (plain rig)"]["n"] == 1
    assert s["right"] == sum(r["right"] for r in a)
