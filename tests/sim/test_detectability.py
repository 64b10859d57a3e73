"""The scenarios' detectability (sim/detectability.py): an effect the plain model hides is redrawn, a visible
one gets sensors quiet enough, and the promise holds on the record the workflow is then given."""
import copy

import numpy as np
import pytest

from identify.explain.workflow import DiscrepancyAnalysis
from sim import detectability
from sim.detectability import DETECTABLE, MIN_NOISE, Changes
from sim.scenarios import make_scenario

SHORT = dict(duration_s=20.0, fs_hz=1000.0)


def _with_coulomb(plain, relative_force: float):
    """The plain scenario with a Coulomb friction of relative_force x its pilot's spring force."""
    sc = copy.deepcopy(plain)
    sc.category, sc.truth_effects = "single", ["coulomb_friction"]
    value = relative_force * plain.pilot["Fs_n"]
    return sc, {"coulomb_friction": Changes(rig={"effects": {"coulomb_friction": value}})}


@pytest.mark.slow
def test_a_hidden_effect_is_redrawn_and_a_visible_one_gets_quiet_sensors():
    plain = make_scenario(np.random.default_rng(3), "none", **SHORT)
    for s in (plain.table_sensor, plain.mass_sensor):
        s.noise_fraction = 0.05  # the wide draws' noisiest sensors
    # 1e-4 of the spring force: far under the floor at any noise the suite allows
    tiny, own = _with_coulomb(plain, 1e-4)
    assert detectability.quiet_enough(tiny, plain.rig, own, np.random.default_rng(0)) is None
    assert tiny.magnitudes["coulomb_friction"]["noise_cap"] < MIN_NOISE
    # 3 % of it (the suite's middle): seen, and the sensors lowered from 5 % to the measured cap (3.0 %)
    visible, own = _with_coulomb(plain, 0.03)
    assert detectability.quiet_enough(visible, plain.rig, own, np.random.default_rng(0)) is visible
    m = visible.magnitudes["coulomb_friction"]
    assert MIN_NOISE <= m["noise_cap"] < 0.05
    assert visible.table_sensor.noise_fraction == visible.mass_sensor.noise_fraction == m["noise_cap"]
    assert m["gap_alone"] == pytest.approx(DETECTABLE * m["floor_per_noise"] * m["noise_cap"], rel=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("name, seed", [("stiffness_drift", 5), ("cubic_damping", 6)])
def test_the_drawn_effect_stands_above_the_floor_on_its_own_record(name, seed):
    """What the workflow is given: the scenario's own record, noise as drawn (then lowered) and nuisances.
    Its baseline gap must clear none_factor (2) x the floor, where `none` stops being the right answer:
    DETECTABLE (4) x leaves a factor 2 for the floor's estimate on a record with the effect and hum."""
    sc = make_scenario(np.random.default_rng(seed), "single", [name], wide=True, **SHORT)
    g = DiscrepancyAnalysis().baseline_gap(sc.run(seed=seed).recording)
    assert g["gap"] >= DiscrepancyAnalysis().none_factor * g["noise_floor"]
