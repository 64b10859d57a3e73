"""daq.plan.propose_campaign in-process on the Table 1 rig's nominal model: every sweep of the proposed plan,
up and down, passes the PLC's limits and the preflight without a warning (the check a campaign runs before
each sweep), and each amplitude's recorded prediction is that of its sweep travelling furthest. The command
and the simulated rig's own runs of the proposal: tests/shakeid/test_plan_campaign.py."""
import pytest

from daq.campaign import parse_plan, plan_prediction, plan_violation
from daq.plan import propose_campaign
from daq.preflight import assess, nominal_response
from protocol.sweep import SineSweep
from sim.config import RigConfig

pytestmark = pytest.mark.slow  # a proposal costs ~4 s of CPU (its steady-state scans)


def test_every_proposed_sweep_both_ways_passes_the_preflight_without_a_warning():
    cfg = RigConfig()
    rig = nominal_response(cfg)
    proposal = propose_campaign(rig, cfg.limits)
    plan = parse_plan(proposal["plan"])
    assert set(plan.directions) == {"up", "down"}
    assert plan_violation(cfg.limits, plan) is None and plan_prediction(rig, cfg.limits, plan) == (None, {})
    furthest: dict[float, float] = {}
    for s in plan.sweeps():
        verdict = assess(rig, SineSweep(s.f_start_hz, s.f_end_hz, s.duration_s, s.amplitude_mm), suggest=False)
        assert verdict.refusal is None and verdict.warnings == [], s
        furthest[s.amplitude_mm] = max(furthest.get(s.amplitude_mm, 0.0), verdict.record["travel_peak_mm"])
    assert {a["amplitude_mm"]: a["preflight"]["travel_peak_mm"] for a in proposal["amplitudes"]} == furthest
