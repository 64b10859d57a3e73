"""`shakeid plan-campaign` (daq.plan): the real command on the Table 1 rig's model. The proposed campaign
brackets the jump (one amplitude below the onset with no fold, the others fold; the band holds every
predicted jump frequency with margin) and stays inside the limits: the PLC's check, and the simulated
rig itself run through each proposed sweep (its end stops and accelerometers: the truth, not the
planner's prediction) stays inside the travel and the accelerometer range, and its up-sweeps at the
folding amplitudes jump inside the band. A model without a fold is refused in one line."""
import pytest
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from daq.campaign import load_plan
from daq.preflight import nominal_response
from identify.frf import frequency_response
from identify.frf.measured import measured_jump, sweep_envelope
from protocol.sweep import SineSweep
from sim.config import RigConfig
from sim.synth import run_sweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
CFG = RigConfig()  # the simulated rig's limits, ranges and travel: what plan-campaign uses without --config


def run(*args):
    return subprocess.run([SHAKEID, *map(str, args)], capture_output=True, text=True, timeout=600)


def test_the_proposal_brackets_the_jump_inside_the_limits(tmp_path):
    model = tmp_path / "model.json"
    model.write_text(json.dumps(CFG.rig.model().to_dict()))
    proc = run("plan-campaign", model, "--out", tmp_path / "plan.toml", "--json")
    assert proc.returncode == 0, proc.stderr
    proposal = json.loads(proc.stdout)
    plan = load_plan(tmp_path / "plan.toml")  # the file `shakeid campaign` runs
    assert list(plan.amplitudes_mm) == proposal["plan"]["amplitudes_mm"] and set(plan.directions) == {"up", "down"}
    f_lo, f_hi = plan.f_start_hz, plan.f_end_hz
    below, *folding = plan.amplitudes_mm
    assert len(folding) == 2 and below < proposal["onset_mm"] <= min(folding)
    truth = CFG.rig.model()
    assert frequency_response(truth, below).jump_down_hz is None  # the default band: no fold anywhere
    for a in folding:
        resp = frequency_response(truth, a)
        assert resp.jump_down_hz is not None and resp.jump_up_hz is not None
        assert f_lo <= 0.9 * resp.jump_up_hz and resp.jump_down_hz * 1.1 <= f_hi, (a, resp.jump_up_hz, resp.jump_down_hz)
    seed = int(np.random.SeedSequence().entropy % 2**31)
    print(f"seed {seed}")
    travel, mass_range = min(CFG.rig.travels_mm), nominal_response(CFG).mass_range_ms2
    for k, s in enumerate(plan.sweeps()):
        assert CFG.limits.check(SineSweep(s.f_start_hz, s.f_end_hz, s.duration_s, s.amplitude_mm))[1] == ""
        if s.direction != "up":
            continue
        rec = run_sweep(CFG.rig, SineSweep(s.f_start_hz, s.f_end_hz, s.duration_s, s.amplitude_mm), seed=seed + k)
        peak_mm = 1e3 * float(np.max(np.abs(rec.states[:, 1])))  # the true relative displacement
        assert peak_mm < travel, (s, peak_mm)
        assert float(np.max(np.abs(rec.mass_acc_true))) < mass_range, s
        jump = measured_jump(sweep_envelope(rec.recording))
        if s.amplitude_mm in folding:  # the sweep jumps, inside the band, not at its edges
            assert jump is not None and f_lo + 0.1 * (f_hi - f_lo) < jump["frequency_hz"] < f_hi - 0.1 * (f_hi - f_lo), (s, jump)


def test_a_model_without_a_fold_is_refused(tmp_path):
    linear = CFG.rig.model().to_dict()
    linear["model"]["q1_dot"] = {k: v for k, v in linear["model"]["q1_dot"].items() if k in ("q1", "q2", "zdd")}
    (tmp_path / "linear.json").write_text(json.dumps(linear))
    proc = run("plan-campaign", tmp_path / "linear.json")
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith("shakeid: error: the model predicts no jump up to") and "nothing to bracket" in proc.stderr
