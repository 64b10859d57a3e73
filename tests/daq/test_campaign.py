"""Campaign plans (daq/campaign.py): reading, expansion in run order, the limit check naming the sweep,
the loop's pause/resume/abort rules; and the downward sweep a campaign needs, on the simulated PLC."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.campaign import (Campaign, CampaignControl, PlanError, load_plan, parse_plan, plan_violation,
                          run_campaign)
from protocol.plc import Command, Limits, State
from sim.plc import PLCConfig, RigPLC
from protocol.sweep import SineSweep

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "campaign.toml"
PLAN = {"name": "t", "sweep": {"f_start_hz": 2.0, "f_end_hz": 15.0, "duration_s": 4.0},
        "amplitudes_mm": [0.5, 1.0], "directions": ["up", "down"]}


def test_the_example_plan_expands_in_run_order():
    plan = load_plan(EXAMPLE)
    sweeps = plan.sweeps()
    assert [(s.index, s.amplitude_mm, s.direction) for s in sweeps] == [
        (1, 0.3, "up"), (2, 0.3, "down"), (3, 0.6, "up"), (4, 0.6, "down"),
        (5, 0.9, "up"), (6, 0.9, "down"), (7, 1.2, "up"), (8, 1.2, "down")]
    assert all((s.f_start_hz, s.f_end_hz) == ((1.0, 20.0) if s.direction == "up" else (20.0, 1.0)) for s in sweeps)
    assert {(s.duration_s, s.settle_s) for s in sweeps} == {(120.0, 2.0)}
    assert plan_violation(Limits(), plan) is None  # the example runs on the default limits
    assert parse_plan(plan.to_dict()) == plan  # the dict form (catalog, API) reads back to the same plan


def test_amplitude_ranges_include_their_stop_and_repeats_repeat_the_list():
    plan = parse_plan({**PLAN, "amplitudes_mm": {"start": 0.4, "stop": 1.6, "step": 0.4}, "directions": ["down"],
                       "repeats": 2})
    assert plan.amplitudes_mm == (0.4, 0.8, 1.2, 1.6)  # 1.6 is reached despite (1.6 - 0.4) / 0.4 = 2.9999...
    assert [(s.repeat, s.amplitude_mm) for s in plan.sweeps()] == [(r, a) for r in (1, 2) for a in (0.4, 0.8, 1.2, 1.6)]
    assert parse_plan({**PLAN, "amplitudes_mm": {"start": 0.4, "stop": 1.5, "step": 0.4}}).amplitudes_mm == (0.4, 0.8, 1.2)


@pytest.mark.parametrize("change, message", [
    ({"colour": "red"}, "unknown key(s) colour"),
    ({"name": "../x"}, "name: '../x' must be"),
    ({"sweep": {"f_start_hz": 15.0, "f_end_hz": 2.0, "duration_s": 4.0}}, "f_start_hz 15 must be below f_end_hz 2"),
    ({"sweep": {"f_start_hz": 2.0, "f_end_hz": 15.0}}, "sweep.duration_s is missing"),
    ({"directions": ["up", "up"]}, "directions: ['up', 'up'] must list"),
    ({"directions": ["sideways"]}, "directions: ['sideways'] must list"),
    ({"amplitudes_mm": []}, "amplitudes_mm: a non-empty list"),
    ({"amplitudes_mm": [1.0, float("nan")]}, "amplitudes_mm[1]: nan must be finite"),
    ({"amplitudes_mm": {"start": 0.1, "stop": 1.0, "step": 0.001}}, "a campaign has at most 500 sweeps"),
    ({"repeats": 0}, "repeats: 0 must be a whole number"),
    ({"rest_between_s": -1}, "rest_between_s: -1 must be finite and >= 0"),
])
def test_a_plan_that_cannot_run_is_refused_by_name(change, message):
    with pytest.raises(PlanError) as err:
        parse_plan({**PLAN, **change})
    assert message in str(err.value)


def test_a_non_finite_number_in_a_toml_plan_is_refused(tmp_path):
    path = tmp_path / "plan.toml"
    path.write_text('name = "x"\namplitudes_mm = [1.0]\nrest_between_s = inf\n'
                    '[sweep]\nf_start_hz = 1.0\nf_end_hz = 20.0\nduration_s = 10.0\n')
    with pytest.raises(PlanError, match=r"plan.toml: rest_between_s: inf must be finite"):
        load_plan(path)


def test_a_toml_plan_error_names_the_file_once(tmp_path):
    """An unknown key at the plan's top level: "plan.toml: unknown key(s) rest_s; ..." (it read
    "plan.toml: plan.toml: unknown key(s) ...")."""
    path = tmp_path / "plan.toml"
    path.write_text('name = "x"\namplitudes_mm = [1.0]\nrest_s = 3\n'
                    '[sweep]\nf_start_hz = 1.0\nf_end_hz = 20.0\nduration_s = 10.0\n')
    with pytest.raises(PlanError) as err:
        load_plan(path)
    assert str(err.value).startswith(f"{path}: unknown key(s) rest_s; known: ") and str(err.value).count(str(path)) == 1


def test_the_limit_check_names_the_first_unsafe_sweep_and_its_limit():
    plan = parse_plan({**PLAN, "sweep": {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 60.0},
                       "amplitudes_mm": [1.0, 3.0, 4.5]})
    # 3 mm at 20 Hz: 0.377 m/s (under 0.5) but 47.4 m/s^2 (over 40): the acceleration limit
    assert plan_violation(Limits(), plan) == ("sweep 3 of 6 (3 mm, up): peak acceleration 47.4 m/s^2 above the "
                                              "limit 40 m/s^2")
    assert plan_violation(Limits(max_acceleration_ms2=100.0, max_velocity_ms=1.0), plan) is None
    long = parse_plan({**PLAN, "sweep": {**PLAN["sweep"], "duration_s": 900.0}})
    assert plan_violation(Limits(), long) == "sweep 1 of 4 (0.5 mm, up): duration 900 s outside the limit 1-600 s"


def test_a_downward_sweep_is_exact_and_decreasing():
    """SineSweep(f_start > f_end): the frequency falls linearly; velocity and acceleration are the exact
    derivatives of the displacement (checked by finite differences), fades included."""
    sweep = SineSweep(15.0, 2.0, 10.0, 1.0)
    t = np.arange(0, 10.0, 1e-5)
    z, zd, zdd = sweep.kinematics(t)
    np.testing.assert_allclose(np.gradient(z, t)[1:-1], zd[1:-1], atol=1e-6 * np.abs(zd).max())
    np.testing.assert_allclose(np.gradient(zd, t)[1:-1], zdd[1:-1], atol=1e-5 * np.abs(zdd).max())
    crossings = t[np.flatnonzero(np.diff(np.sign(z[(t > 1) & (t < 9)])) != 0)] + 1
    f_measured = 0.5 / np.diff(crossings)  # half a period between zero crossings
    f_true = sweep.frequency_hz(0.5 * (crossings[1:] + crossings[:-1]))
    np.testing.assert_allclose(f_measured, f_true, rtol=0.01)
    assert f_true[0] > 13.5 and f_true[-1] < 4.0 and np.all(np.diff(f_measured) < 0)


def _plc_sweep(f0: float, f1: float, amplitude_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """A sweep on the simulated PLC (no network): frequency (Hz) and relative acceleration envelope
    (m/s^2) per 0.5 s of the sweep."""
    plc = RigPLC(PLCConfig(limits=Limits(watchdog_s=1e4), fs_hz=1024.0))
    for name, v in {"f_start_hz": f0, "f_end_hz": f1, "duration_s": 40.0, "amplitude_mm": amplitude_mm}.items():
        plc.set_setpoint(name, v)
    plc.command(Command.START)
    assert plc.state == State.RUNNING, plc.fault_message
    blocks = []
    while plc.state == State.RUNNING:
        blocks.append(plc.advance(0.5)[1])
    rel = np.concatenate(blocks)
    rel = rel[:, 1] - rel[:, 0]
    n = 512
    env = np.array([np.abs(rel[k:k + n]).max() for k in range(0, rel.size - n + 1, n)])
    return SineSweep(f0, f1, 40.0, amplitude_mm).frequency_hz(np.arange(env.size) * 0.5 + 0.25), env


def test_a_downward_sweep_on_the_plc_sees_the_other_branch():
    """Why campaigns sweep both ways: the rig (Table 1, hardening) at 1.3 mm follows its upper branch
    on an upward sweep past the linear resonance (4.96 Hz) before it jumps down; a downward sweep
    jumps up near the linear resonance. At 0.4 mm the response is nearly linear: both peak near 5 Hz."""
    peaks = {}
    for amp in (0.4, 1.3):
        for f0, f1 in ((2.0, 12.0), (12.0, 2.0)):
            f, env = _plc_sweep(f0, f1, amp)
            peaks[amp, f0 < f1] = f[np.argmax(env)]
    assert peaks[1.3, True] - peaks[1.3, False] > 1.0, peaks      # measured: 6.9 vs 5.2 Hz
    assert abs(peaks[0.4, True] - peaks[0.4, False]) < 0.75, peaks  # measured: 5.3 vs 4.8 Hz (sweep lag)
    assert all(4.3 < peaks[0.4, up] < 5.8 for up in (True, False)), peaks


def _outcomes(script: list[dict], ran: list[int], control: CampaignControl | None = None, abort_at: int = 0):
    """A run_sweep that returns scripted outcomes in turn and notes which sweep ran."""
    def run_sweep(planned, item):
        ran.append(planned.index)
        if planned.index == abort_at:
            control.abort("aborted by the operator")
        out = script.pop(0)
        return {"recording_id": f"rec{len(ran)}", **out}
    return run_sweep


OK = {"status": "complete", "reason": "", "quality": {"usable_for_identification": True, "reasons": []}}


def test_the_loop_pauses_on_a_failed_sweep_resumes_it_and_completes():
    campaign, saves, ran = Campaign(parse_plan({**PLAN, "rest_between_s": 0.01})), [], []
    save = lambda c: saves.append(c.state)  # noqa: E731
    script = [OK, {"status": "aborted", "reason": "emergency stop"}]
    run_campaign(campaign, _outcomes(script, ran), CampaignControl(), save)
    assert (campaign.state, campaign.reason) == ("paused", "sweep 2 of 4 (0.5 mm, down) ended aborted: emergency stop")
    assert ran == [1, 2] and [it["status"] for it in campaign.items] == ["complete", "failed", "planned", "planned"]
    assert saves[0] == "running" and saves[-1] == "paused"
    # resume: sweep 2 again; sweep 3 records but its quality flags make it unusable: paused again
    script = [OK, {**OK, "quality": {"usable_for_identification": False, "reasons": ["mass_acc dead"]}}]
    run_campaign(campaign, _outcomes(script, ran), CampaignControl(), save)
    assert campaign.reason == ("sweep 3 of 4 (1 mm, up) recorded, but not usable for identification: mass_acc dead")
    assert ran == [1, 2, 2, 3] and campaign.items[1]["attempts"][0]["recording_id"] == "rec2"
    run_campaign(campaign, _outcomes([OK, OK], ran), CampaignControl(), save)
    assert (campaign.state, campaign.reason, ran) == ("completed", None, [1, 2, 2, 3, 3, 4])
    assert campaign.recording_ids() == ["rec1", "rec3", "rec5", "rec6"]  # the complete ones, in plan order
    assert campaign.progress() == {"done": 4, "total": 4, "current": None}


def test_an_abort_ends_the_campaign_and_a_pause_or_a_rig_problem_stops_before_the_next_sweep():
    control, ran = CampaignControl(), []
    campaign = Campaign(parse_plan(PLAN))
    script = [OK, {"status": "aborted", "reason": "campaign t: aborted by the operator"}]
    run_campaign(campaign, _outcomes(script, ran, control, abort_at=2), control, lambda c: None)
    assert (campaign.state, campaign.reason, ran) == ("aborted", "aborted by the operator", [1, 2])

    control, ran = CampaignControl(), []
    campaign = Campaign(parse_plan(PLAN))
    control.pause("paused by operator")  # asked for before the loop ran: no sweep starts
    run_campaign(campaign, _outcomes([OK], ran), control, lambda c: None)
    assert ran == [] and campaign.state == "paused"

    control, ran = CampaignControl(), []
    campaign = Campaign(parse_plan({**PLAN, "rest_between_s": 0.2}))
    run_campaign(campaign, _outcomes([OK, OK], ran), control, lambda c: None,
                 check=lambda: "the PLC is in emergency stop")  # seen during the rest after sweep 1
    assert ran == [1] and campaign.state == "paused"
    assert campaign.reason == "before sweep 2 of 4: the PLC is in emergency stop"
    assert [it["status"] for it in campaign.items] == ["complete", "planned", "planned", "planned"]

    control, ran = CampaignControl(), []
    campaign = Campaign(parse_plan(PLAN))

    def held(planned, item):  # a halt came between the loop's check and the start: nothing started
        ran.append(planned.index)
        control.halt("emergency stop")
        return {"status": "held"}
    run_campaign(campaign, held, control, lambda c: None)
    assert ran == [1] and (campaign.state, campaign.reason) == ("paused", "emergency stop")
    assert campaign.items[0]["status"] == "planned" and control.halted
