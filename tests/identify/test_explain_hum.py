"""Mains hum is a measurement effect: named, its frequency and level given, removed, and held to a
physical name's evidence (issue 32 item 5). The issue saw hum at 1-5 % of a channel answered
`unexplained`, gap 8-16x the noise floor. Design rig, 1-20 Hz in 30 s at 1.3 mm, 1000 Hz (the chain's
band reaches 100 Hz, so 50 Hz hum is in it), 0.5 % sensor noise; the hum is added here to the recorded
channel, at a phase drawn from a fresh seed (printed)."""
import numpy as np
import pytest

from identify.explain.workflow import DiscrepancyAnalysis
from protocol.sweep import SineSweep
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

FS = 1000.0
SWEEP = SineSweep(1.0, 20.0, 30.0, 1.3)


def _with_hum(channel: str, hz: float, share: float, seed: int):
    s = Accelerometer(noise_fraction=0.005)
    rec = run_sweep(RigParameters.design(), SWEEP, fs_hz=FS, table_sensor=s, mass_sensor=s, seed=5).recording
    x = rec.output if channel == "mass" else rec.input
    amp = share * float(np.std(x))
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    x[:] = x + amp * np.cos(2 * np.pi * hz * np.arange(x.size) / FS + phase)
    return rec, amp


@pytest.mark.parametrize("channel, hz", [("mass", 50.0), ("mass", 60.0)])
def test_mains_hum_is_named_as_a_measurement_effect(channel, hz):
    """3 % hum on the mass channel: `mains_hum`, a measurement effect, at its frequency, its amplitude on
    that channel within 5 % and the other channel's under a tenth of it; the gap more than halved and
    no physical name at confidence >= 0.5. (Hum on the table channel alone enters the input and q''
    alike and cancels in the model, input gain -1: it leaves no gap, and the answer is `none`.)"""
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"phase seed {seed}")
    rec, amp = _with_hum(channel, hz, 0.03, seed)
    res = DiscrepancyAnalysis().fit(rec).result()
    first = res["effects"][0] if res["effects"] else {}
    assert res["effect"] == "mains_hum" and first["kind"] == "measurement", res["candidates"]
    c = first["coefficients"]
    other = "table" if channel == "mass" else "mass"
    assert c["hum_hz"] == hz and c[f"hum_{channel}_ms2"] == pytest.approx(amp, rel=0.05)
    assert c[f"hum_{other}_ms2"] < 0.1 * amp
    assert first["p_value"] < 1e-3 and first["confidence"] >= 0.5
    assert res["gap_closed"] > 0.5
    assert not [e for e in res["effects"] if e["kind"] == "physics" and e["confidence"] >= 0.5]
