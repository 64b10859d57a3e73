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

#: The gain beside the friction. The issue's 2.5 % leaves its own gap at 1.85x the floor on this record (gap
#: 0.0046 against the plain rig's 0.0019, floor 0.0022), under the suite's DETECTABLE (4x): what a record
#: cannot show, no explanation names (test_a_gain_under_the_floor_is_not_named_as_physics). 5 % stands at 3.6x.
GAIN = 0.05


def _record(gain: float, seed: int = 5):
    s = Accelerometer(noise_fraction=0.005)
    rig = RigParameters.design(effects={"coulomb_friction": 0.1})
    rec = run_sweep(rig, SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1000.0, table_sensor=s, mass_sensor=s,
                    seed=seed).recording
    rec.output[:] = rec.output * (1 + gain)
    return rig, rec


def test_coulomb_friction_does_not_mask_a_mass_gain():
    """Coulomb 0.1 N closes most of the first round's gap; the 5 % gain is still named after it, as a
    measurement effect, and Coulomb's level stays within 10 % of the truth (the issue saw it 24 % off).
    The gain comes out at 0.077 here (0.081 at seed 6: its search trades it against the friction and the
    baseline's coefficients): asked within 0.04 of the truth, its sign right; the gap ends at 1.8x the
    floor, under none_factor (2) x it."""
    rig, rec = _record(GAIN)
    res = DiscrepancyAnalysis().fit(rec).result()
    named = {e["name"]: e for e in res["effects"] if e["confidence"] >= 0.5}
    assert {"coulomb_friction", "mass_acc_gain"} <= set(named), res["effects"]
    assert named["mass_acc_gain"]["kind"] == "measurement"
    assert res["model"]["q1_dot"]["sign(q1)"] == pytest.approx(-0.1 / rig.mass_kg, rel=0.10)
    assert named["mass_acc_gain"]["coefficients"]["mass_acc_gain"] == pytest.approx(GAIN, abs=0.04)
    assert res["gap_after"] < res["thresholds"]["none_factor"] * res["noise_floor"]


@pytest.mark.xfail(strict=True, reason="open on issue 32: beside Coulomb friction a 2.5 % mass gain (1.85x the "
                   "floor on its own) is not named, and stiffness drift, q2*tau -159 against k 1017, closes 23 % of "
                   "what Coulomb leaves and is named at 0.80 (0.75 with band-limited columns in the gain's search); "
                   "at seeds 6 and 7 nothing is named after Coulomb")
def test_a_gain_under_the_floor_is_not_named_as_physics():
    """What a record cannot show is not named as something else: no physics name beyond Coulomb at
    confidence >= 0.5."""
    _, rec = _record(0.025)
    res = DiscrepancyAnalysis().fit(rec).result()
    physics = [e["name"] for e in res["effects"] if e["kind"] == "physics" and e["confidence"] >= 0.5]
    assert physics == ["coulomb_friction"], res["effects"]
