"""Keep adding while the gap stays above the floor (issue 32 item 4): a strong effect must not mask a
second one. The issue saw Coulomb friction + a 2.5 % mass-accelerometer gain named Coulomb alone;
Coulomb + quadratic damping is tests/identify/test_explain_effects.py::
test_two_effects_are_both_named_with_their_coefficients. Design rig, 1-20 Hz in 30 s at 1.3 mm,
1000 Hz, 0.5 % sensor noise."""
import pytest

from identify.explain.workflow import DiscrepancyAnalysis
from protocol.sweep import SineSweep
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

GAIN = 0.025


def test_coulomb_friction_does_not_mask_a_mass_gain():
    """Coulomb 0.1 N closes 96 % of the first round's gap; the 2.5 % gain is still named after it, as a
    measurement effect, and Coulomb's level stays within 10 % of the truth (the issue saw it 24 % off).
    The gain comes out at 0.037 here (its search trades it against the friction and the baseline's
    coefficients): asked within 0.015 of the truth, its sign right."""
    s = Accelerometer(noise_fraction=0.005)
    rig = RigParameters.design(effects={"coulomb_friction": 0.1})
    rec = run_sweep(rig, SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1000.0, table_sensor=s, mass_sensor=s,
                    seed=5).recording
    rec.output[:] = rec.output * (1 + GAIN)
    res = DiscrepancyAnalysis().fit(rec).result()
    named = {e["name"]: e for e in res["effects"] if e["confidence"] >= 0.5}
    assert {"coulomb_friction", "mass_acc_gain"} <= set(named), res["effects"]
    assert named["mass_acc_gain"]["kind"] == "measurement"
    assert res["model"]["q1_dot"]["sign(q1)"] == pytest.approx(-0.1 / rig.mass_kg, rel=0.10)
    assert named["mass_acc_gain"]["coefficients"]["mass_acc_gain"] == pytest.approx(GAIN, abs=0.015)
    assert res["gap_after"] < res["noise_floor"]
