"""A term the selection kept whose coefficient is within SIGNIFICANT_Z standard errors of zero is reported
apart, as an uncertain term, and is not in the model, its refit or its simulation (issue 30's "term
lottery"), whatever its inclusion probability; a term beyond it stays, whatever its probability. Real fits
on simulated rigs."""
import numpy as np
import pytest

import identify.trust.uncertainty as unc
from identify.identifier import SparseIdentifier
from protocol.sweep import SineSweep
from reports.text import summary
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import noise_input_recording, run_sweep

TRUTH = RigParameters.paper_table1().model().equations["q1_dot"]


def _record(seed: int, duration_s: float, noise: float = 0.05):
    sensors = dict(table_sensor=Accelerometer(noise), mass_sensor=Accelerometer(noise))
    return run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, duration_s, 1.3), 2048.0, 2.0,
                     seed=seed, **sensors).recording


def test_a_kept_term_within_a_few_standard_errors_of_zero_is_reported_apart():
    """30 s, 5 % noise, seed 418825265: the held-out placement of the fit keeps q1*q2^3 (an even term, so
    it is trusted before any displacement below the band is carried: the last test), none of the 24 random
    placements does. Reported: the five true terms; q1*q2^3 apart, with its probability. (Found as one of 3
    in 60 fresh draws at 1-5 % noise and 20-60 s keeping a spurious term, then q1^2*q2 from a carried pass.)"""
    rec = _record(418825265, 30.0)
    ident = SparseIdentifier().fit(rec)  # only terms the selection kept are judged and listed apart
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH) and res["selection"]["q1_dot"]["n_terms"] == len(TRUTH)
    apart = res["uncertain_terms"]["q1_dot"]
    assert list(apart) == ["q1*q2^3"] and res["uncertain_terms"]["q2_dot"] == {}
    term = apart["q1*q2^3"]
    assert term["inclusion_probability"] < unc.MIN_INCLUSION_PROBABILITY  # (its |z| < 3 is the rule itself)
    # left out of what is simulated and validated, and of the selection's support, too
    assert "q1*q2^3" not in ident.training_model_.equations["q1_dot"]
    assert "q1*q2^3" not in ident.validated_model_.equations["q1_dot"]
    for t, c in TRUTH.items():  # the terms left, refit without it, hold the truth
        assert abs(res["model"]["q1_dot"][t] - c) < 3 * res["standard_errors"]["q1_dot"][t], t


def test_no_reported_term_is_within_a_few_standard_errors_of_zero():
    """Fresh draw (seed printed): whatever is selected, every term in the model has a coefficient beyond
    SIGNIFICANT_Z standard errors (but q2_dot = q1, exact by construction), and every uncertain term is
    within them and absent from the model."""
    seed = int(np.random.SeedSequence().generate_state(1)[0])
    print(f"seed {seed}")
    res = SparseIdentifier().fit(_record(seed, 20.0)).result()
    for eq, terms in res["model"].items():
        se = res["standard_errors"][eq]
        for t, c in terms.items():
            assert abs(c) > unc.SIGNIFICANT_Z * se[t] or (eq, t, c, se[t]) == ("q2_dot", "q1", 1.0, 0.0), (eq, t)
        for t, entry in res["uncertain_terms"][eq].items():
            assert t not in terms and abs(entry["coefficient"]) <= unc.SIGNIFICANT_Z * entry["standard_error"]


def test_a_term_the_data_carry_stays_whatever_its_probability():
    """Design rig beyond the jump (3.5 mm, no end stops), 2 % noise, seed 0 (tests/identify/
    test_beyond_the_jump.py's case): the placements keep the damping q1 in 9 of 24, yet it is -3.72 +- 0.39,
    far beyond SIGNIFICANT_Z standard errors from zero. It stays: left out, the refit lost the input
    (zdd -0.10 for -1)."""
    sensors = dict(table_sensor=Accelerometer(0.02), mass_sensor=Accelerometer(0.02))
    rec = run_sweep(RigParameters.design(end_stop_travel_mm=None), SineSweep(1.0, 20.0, 30.0, 3.5), seed=0,
                    **sensors).recording
    res = SparseIdentifier().fit(rec).result()
    assert res["inclusion_probability"]["q1_dot"]["q1"] < unc.MIN_INCLUSION_PROBABILITY
    c, se = res["model"]["q1_dot"]["q1"], res["standard_errors"]["q1_dot"]["q1"]
    assert abs(c) > unc.SIGNIFICANT_Z * se and res["uncertain_terms"] == {"q1_dot": {}, "q2_dot": {}}


def test_a_kept_term_within_a_few_standard_errors_is_left_out_whatever_its_probability():
    """A 60 s record of 2-20 Hz noise on the Table 1 rig (sim.synth.noise_input_recording), seed 7018 (one of
    60 draws, 7000-7059, all of which gave the true model): the selection keeps q2^2, the constant and q1^2,
    at P(kept) 0.58-0.63 but 2.5-2.9 standard errors from zero (a rule that also asked P(kept) < 0.5 kept
    them). The three are reported apart; the model is the true one, each coefficient within 3 standard
    errors of the truth. Without inclusion probabilities (placements=0) the same terms leave: the bound is on
    the standard errors, which do not depend on them. (The case before, seed 1314243276, was one where an even
    selection carried a displacement below the band the data did not establish: the last test.)"""
    apart_expected = {"q2^2", "1", "q1^2"}
    rec = noise_input_recording(7018)
    res = SparseIdentifier().fit(rec).result()
    apart = res["uncertain_terms"]["q1_dot"]
    assert set(apart) == apart_expected, apart
    assert all(u["inclusion_probability"] >= unc.MIN_INCLUSION_PROBABILITY for u in apart.values()), apart
    assert set(res["model"]["q1_dot"]) == set(TRUTH)
    for t, c in TRUTH.items():
        assert abs(res["model"]["q1_dot"][t] - c) < 3 * res["standard_errors"]["q1_dot"][t], t
    bare = SparseIdentifier(placements=0).fit(rec).result()
    assert set(bare["uncertain_terms"]["q1_dot"]) == apart_expected and set(bare["model"]["q1_dot"]) == set(TRUTH)
    assert all(u["inclusion_probability"] is None for u in bare["uncertain_terms"]["q1_dot"].values())
    assert bare["uncertainty"]["term_rules"]["significant_z"] == unc.SIGNIFICANT_Z  # the bound stated all the same
    said = summary(bare, "noise.csv")
    assert f"(within {unc.SIGNIFICANT_Z:g} standard errors of zero)" in said and "q2^2 (q1_dot) " in said
    assert "P(kept)" not in said.split("uncertain terms")[1].split("\n")[0]  # said without a probability


def test_an_even_term_the_data_do_not_establish_carries_no_displacement_below_the_band():
    """Seed 5036 (30 s, 5 % noise; found in 40 draws): the first selection has q2^2 and q2^4, an even force
    within 2 standard errors of zero. Carried as if it were one, the second pass on the band-limited
    columns kept q2^4 in the model (before: q1, q2, q1*q2^2, q2^3, q2^4, zdd; offset carried, SIMEX). Decided
    on the terms the data establish: the true five, no offset, the two listed apart, the closed-form chain
    bias (no carried offset stands in its way)."""
    ident = SparseIdentifier(validate=False).fit(_record(5036, 30.0))
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH)
    assert ident.offset_["carried"] is False
    assert {"q2^2", "q2^4"} <= set(res["uncertain_terms"]["q1_dot"])
    assert ident.uncertainty_["chain_bias"]["method"] == unc.ANALYTIC
    for term, c in TRUTH.items():
        assert abs(ident.model_.coefficient("q1_dot", term) / c - 1) < 0.03, term


def test_an_odd_spurious_term_leaves_by_the_final_rule():
    """30 s, 5 % noise, seed 5009 (of the same 40 draws as the last test): the selection keeps q1^2*q2, an odd
    term, so no offset is in question and the fit's own trust leaves it out (-1.9 standard errors, P(kept)
    0.17): the five true terms, q1^2*q2 apart, nothing carried."""
    ident = SparseIdentifier(validate=False).fit(_record(5009, 30.0))
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH) and ident.offset_["carried"] is False
    assert list(res["uncertain_terms"]["q1_dot"]) == ["q1^2*q2"]
    assert "q1^2*q2" not in ident.training_model_.equations["q1_dot"]


def test_a_carried_offset_lists_only_what_its_own_selection_left_out():
    """Design rig with an asymmetric spring (1e4 N/m^2), 40 s, 2 % noise, seed 21: the first selection's
    uncertain terms (trusted before the carry) belong to a selection the carried pass replaces, so they are
    not listed (q1^2 was, in 5 seeds of 5 at 1e4 N/m^2); the carried model is the rig's (q2^2 within 5 %)."""
    s = Accelerometer(noise_fraction=0.02)
    rig = RigParameters.design(effects={"quadratic_stiffness": 1.0e4})
    rec = run_sweep(rig, SineSweep(1, 20, 40.0, 1.3), 2048.0, 2.0, seed=21, table_sensor=s, mass_sensor=s).recording
    ident = SparseIdentifier(validate=False).fit(rec)
    truth = rig.model().equations["q1_dot"]
    assert ident.offset_["carried"] and set(ident.model_.equations["q1_dot"]) == set(truth)
    assert ident.model_.coefficient("q1_dot", "q2^2") == pytest.approx(truth["q2^2"], rel=0.05)
    # the carried selection is the rig's five terms; the replaced one had left out q1^2 (listed before the fix)
    assert ident.uncertain_terms_["q1_dot"] == {}
