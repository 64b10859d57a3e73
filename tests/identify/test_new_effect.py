"""Adding an effect is one class plus one registration (identify.explain.effects): an effect defined here, in the
test, is simulated by the rig simulator, taken by name by the identification library, fitted and named
by the discrepancy workflow, and shown by its report and JSON, with no other change anywhere.

The effect: stroke-proportional damping, F = -c |q2| q1 (a wiper contact whose pressure grows with the
stroke), the term q1*|q2| that no registered effect has. Design rig, 1-20 Hz in 30 s at 1.3 mm, 1000 Hz,
0.5 % sensor noise; c = 80 N s/m^2 adds about 0.8 N s/m of damping at 10 mm of stroke.
"""
import json

import pytest

from identify.explain.effects import CATALOG, Effect, expand_terms, register, unregister
from identify.explain.workflow import DiscrepancyAnalysis
from identify.identifier import SparseIdentifier
from identify.regression.library import Library
from reports.explain import write_explain_report
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from protocol.sweep import SineSweep
from sim.synth import run_sweep

C_NS_PER_M2 = 80.0


class StrokeDamping(Effect):
    name, terms, unit = "stroke_damping", ("q1*|q2|",), "N s/m^2"
    description = "damping proportional to the stroke: a wiper contact pressed harder the further it moves"
    sign, group = -1, "damping"


@pytest.fixture(scope="module")
def effect():
    e = register(StrokeDamping())
    yield e
    unregister(e.name)


@pytest.fixture(scope="module")
def recording(effect):
    rig = RigParameters.design(effects={effect.name: C_NS_PER_M2})
    s = Accelerometer(noise_fraction=0.005)
    return run_sweep(rig, SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1000.0, table_sensor=s, mass_sensor=s,
                     seed=5).recording


def test_the_simulator_runs_the_registered_effect(effect):
    rig = RigParameters.design(effects={effect.name: C_NS_PER_M2})
    assert rig.model().equations["q1_dot"]["q1*|q2|"] == pytest.approx(-C_NS_PER_M2 / rig.mass_kg)
    with pytest.raises(ValueError, match="unknown effect"):
        RigParameters.design(effects={"no_such_effect": 1.0})


def test_identification_takes_the_effect_by_name(effect, recording):
    assert "q1*|q2|" in Library(extra_terms=expand_terms((effect.name,))).names
    model = SparseIdentifier(extra_terms=(effect.name,)).fit(recording).model_  # the name for its terms
    assert "q1*|q2|" in model.equations["q1_dot"]


@pytest.mark.slow
def test_the_workflow_names_it_and_the_report_shows_it(effect, recording, tmp_path):
    analysis = DiscrepancyAnalysis().fit(recording)
    res = analysis.result()
    assert res["effect"] == effect.name, res["effects"]
    named = res["effects"][0]
    assert named["kind"] == "physics" and named["terms"] == ["q1*|q2|"]
    m = RigParameters.design().mass_kg
    assert named["coefficients"]["q1*|q2|"] == pytest.approx(-C_NS_PER_M2 / m, rel=0.2)
    assert res["gap_closed"] > 0.5
    assert any(c["name"] == effect.name and c["description"] == effect.description for c in res["candidates"])
    out = write_explain_report(analysis, tmp_path / "report")
    assert json.loads((out / "explain.json").read_text())["effect"] == effect.name
    page = (out / "index.html").read_text()
    assert effect.name in page


class OtherStrokeDamping(StrokeDamping):
    name = "stroke_damping_other"


def test_a_registered_effect_is_gone_once_unregistered():
    e = register(OtherStrokeDamping())
    assert CATALOG[e.name] is e
    with pytest.raises(ValueError, match="registered already"):
        register(OtherStrokeDamping())
    unregister(e.name)
    assert e.name not in CATALOG
