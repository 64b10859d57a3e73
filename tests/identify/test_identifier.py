"""End-to-end identification against known truth (the issue's acceptance numbers)."""
import numpy as np
import pytest

from identify.identifier import SparseIdentifier
from protocol.sweep import SineSweep

#: issue 2 acceptance: coefficients within 2 %, the weak q1*q2^2 within 5 %
TOLERANCE = {"q1*q2^2": 0.05}


@pytest.fixture(scope="module")
def fitted(table1_run):
    return SparseIdentifier().fit(table1_run.recording)


def _check_model(model, truth, true_q1_terms, tol=0.02, weak_tol=0.05):
    assert set(model.equations["q1_dot"]) == true_q1_terms
    assert set(model.equations["q2_dot"]) == {"q1"}
    assert model.coefficient("q2_dot", "q1") == pytest.approx(1.0, abs=1e-6)
    for term, true in truth["q1_dot"].items():
        limit = weak_tol if term == "q1*q2^2" else tol
        assert abs(model.coefficient("q1_dot", term) / true - 1) < limit, term


def test_table1_sweep_gives_back_the_table1_model(fitted, table1_truth, true_q1_terms):
    _check_model(fitted.model_, table1_truth, true_q1_terms)


def test_free_run_validation_on_heldout_blocks(fitted):
    val = fitted.validation_
    assert not val["diverged"]
    assert val["heldout_samples"] > 0.15 * fitted.recording_.n_samples
    assert val["heldout"]["q1_dot"]["fit_percent"] > 98.0
    assert val["heldout"]["q2"]["fit_percent"] > 97.0


def test_standard_errors_cover_the_truth(fitted, table1_truth):
    """Block-robust standard errors: the truth within 5 standard errors of every estimate (the chain's
    small integration bias included), and no absurdly large error bar either."""
    se = fitted.standard_errors_["q1_dot"]
    for term, true in table1_truth["q1_dot"].items():
        est = fitted.model_.coefficient("q1_dot", term)
        assert abs(est - true) < 5 * se[term], term
        assert se[term] < 0.02 * abs(true), term


def test_physical_parameters(fitted):
    phys = fitted.result()["physical"]
    m = 0.49
    assert phys["cubic_stiffness_n_per_m3"]["value"] == pytest.approx(2.5033e6 * m, rel=0.02)
    assert phys["stiffness_n_per_m"]["value"] == pytest.approx(971.0169 * m, rel=0.02)
    assert phys["damping_ns_per_m"]["value"] == pytest.approx(3.7294 * m, rel=0.02)
    # pre-stress b = k / (4 k_l a) and the design cubic stiffness 4 k_l a^2
    assert phys["prestress_b_m"]["value"] == pytest.approx(971.0169 * m / (4 * 16.7e3 * 4), rel=0.02)
    assert phys["design"]["cubic_stiffness_n_per_m3"] == pytest.approx(4 * 16.7e3 * 16)
    # another mass scales every force; no mass (0, negative) is refused where it is given
    from identify.physical import RigConstants, physical_parameters

    heavy = physical_parameters(fitted.model_, RigConstants(mass_kg=2 * m))
    assert heavy["stiffness_n_per_m"]["value"] == pytest.approx(2 * phys["stiffness_n_per_m"]["value"])
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="rig mass must be > 0 kg"):
            RigConstants(mass_kg=bad)


@pytest.mark.parametrize("case", [
    dict(sweep=SineSweep(2.0, 30.0, 40.0, 1.0)),                 # other range, shorter, smaller
    dict(sweep=SineSweep(20.0, 1.0, 60.0, 1.3)),                 # downward sweep
    dict(fs_hz=1000.0, noise=0.02, seed=3),                      # other sample rate, 2 % noise
    dict(sweep=SineSweep(1.0, 20.0, 25.0, 1.3), seed=4),         # fast sweep
])
@pytest.mark.slow
def test_robust_to_record_length_range_rate_and_noise(make_run, table1_truth, true_q1_terms, case):
    model = SparseIdentifier(validate=False).fit(make_run(**case).recording).model_
    _check_model(model, table1_truth, true_q1_terms, tol=0.02, weak_tol=0.05)


def test_other_rig_parameters(make_run):
    """A stiffer, heavier rig without displacement-dependent damping: the support follows the physics."""
    from sim.rig import RigParameters

    rig = RigParameters(mass_kg=1.2, damping_ns_per_m=9.0, stiffness_n_per_m=3.0e3, cubic_stiffness_n_per_m3=4e6)
    model = SparseIdentifier(validate=False).fit(make_run(rig=rig, sweep=SineSweep(2, 25, 60, 1.5)).recording).model_
    truth = rig.model().equations["q1_dot"]
    assert set(model.equations["q1_dot"]) == set(truth)
    for term, true in truth.items():
        assert abs(model.coefficient("q1_dot", term) / true - 1) < 0.02, term


def test_paper_holdout_of_the_first_30000_samples(table1_run, table1_truth, true_q1_terms):
    ident = SparseIdentifier(holdout_samples=30000).fit(table1_run.recording)
    res = ident.result()
    assert res["chain"]["heldout_samples"] == 30000 - ident.states_.valid.start
    assert np.all(ident.heldout_rows_[: 30000 - ident.states_.valid.start])
    assert not ident.validation_["diverged"]
    _check_model(ident.model_, table1_truth, true_q1_terms, tol=0.03, weak_tol=0.10)


def test_free_run_refit_keeps_an_accurate_model(fitted, table1_run):
    ident = SparseIdentifier(refine="free-run").fit(table1_run.recording)
    assert ident.refinement_["cost_after"] <= ident.refinement_["cost_before"]
    assert (ident.validation_["heldout"]["q2"]["nrmse"]
            <= fitted.validation_["heldout"]["q2"]["nrmse"] * 1.05)


@pytest.mark.parametrize("kw,match", [({"refine": "magic"}, "unknown refine"), ({"method": "lars"}, "unknown method")])
def test_unknown_options_are_refused_before_any_work(table1_run, kw, match):
    from identify.errors import IdentificationError

    ident = SparseIdentifier(**kw)
    with pytest.raises(IdentificationError, match=match):
        ident.fit(table1_run.recording)
    assert not hasattr(ident, "states_")  # refused before the measurement chain ran
