"""The evidence a name needs (issue 32): a measurement fault is named only where its own test finds it
(identify.explain.effects.faults: the segment-clustered sandwich test of the fitted fault), and a candidate
that explains nearly all of the gap is not excluded for turning over a sign the incomplete baseline had
(identify.explain.admissibility, rule 2). Against known truth: the design rig with and without a delayed
mass channel, and two wide draws of benchmarks/explain_robustness.py that were answered wrongly before."""
import numpy as np
import pytest

from identify.explain.effects import CATALOG
from identify.explain.workflow import DiscrepancyAnalysis
from sim.scenarios import make_scenario
from sim.scoring import score

from .test_explain_effects import FS, _delayed, _run

ALPHA = DiscrepancyAnalysis().alpha


@pytest.mark.slow
def test_a_fault_is_significant_only_where_the_recording_has_it():
    """On a clean recording the delay and gain searches settle on values their own test calls zero (60
    clean draws of this rig, seeds 100-159: 2 delays and no gain below alpha = 1e-3, the test still a
    little liberal where few segments carry the curvature: docs/discrepancy.md); with the mass channel
    1 ms late the delay is found within 0.1 ms and its test is decisive (seeds 5-7: t 70-132)."""
    clean = DiscrepancyAnalysis().fit(_run())
    assert clean.effect_ == "none"
    for name in ("channel_delay", "mass_acc_gain"):
        c = CATALOG[name].propose(clean.fitter_, clean.baseline_structure_)
        assert c.p_value >= ALPHA, (name, c.extra, c.p_value)
    rec = _run()
    rec.output[:] = _delayed(rec.output, 1e-3, FS)
    late = DiscrepancyAnalysis().fit(rec)
    c = CATALOG["channel_delay"].propose(late.fitter_, late.baseline_structure_)
    assert c.extra["channel_delay"] == pytest.approx(1e-3, abs=1e-4)
    assert c.p_value < 1e-6 and c.wald > 25.0


def _wide_case(seed: int, case: int, category: str, names: list[str]):
    """Case `case` of `benchmarks/explain_robustness.py --seed seed`: its scenario and the analysis' result."""
    sc = make_scenario(np.random.default_rng([seed, case]), category, names, wide=True)
    return sc, DiscrepancyAnalysis().fit(sc.run(seed=[seed, case, 1]).recording).result()


@pytest.mark.slow
def test_a_delay_the_data_do_not_ask_for_is_not_named_after_a_gain():
    """A 3.7 % mass-accelerometer gain, named at confidence 1.0; a channel delay of 10 us (0.02 samples)
    came second at confidence 0.68: its refit had closed 20 % of what was left, the delay itself carrying
    nothing. Its own test now calls it zero: the gain alone is named."""
    sc, res = _wide_case(646344572, 4, "sensor_fault", ["mass_acc_gain"])
    assert sc.truth_effects == ["mass_acc_gain"]
    verdict = score("sensor_fault", sc.truth_effects, res, tuple(sc.nuisances))
    assert verdict["right"] and not verdict["spurious_measurement"], verdict
    assert res["effects"][0]["coefficients"]["mass_acc_gain"] == pytest.approx(
        sc.magnitudes["mass_acc_gain"]["gain"] - 1, rel=0.1)


@pytest.mark.slow
def test_hysteresis_that_restores_the_hardening_spring_is_named():
    """Bouc-Wen hysteresis at 5.9 % of the spring force: the textbook Duffing fit reads its saturating force
    as a softening q2^3 (+4.2e6, 5 standard errors); the hysteresis candidate restores the hardening spring
    and closes 98 % of the gap, and was excluded for that flip while a channel delay closing 84 % was named
    in its place. Hysteresis alone is named now."""
    sc, res = _wide_case(1649110157, 51, "single", ["hysteresis"])
    assert sc.truth_effects == ["hysteresis"]
    verdict = score("single", sc.truth_effects, res, tuple(sc.nuisances))
    assert verdict["right"] and verdict["names"] == ["hysteresis"] and not verdict["spurious_measurement"], verdict
    assert res["model"]["q1_dot"]["q2^3"] < 0  # hardening, as the rig is
