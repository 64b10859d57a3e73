"""A term the selection kept whose coefficient is within SIGNIFICANT_Z standard errors of zero is reported
apart, as an uncertain term, and is not in the model, its refit or its simulation (issue 30's "term
lottery"), whatever its inclusion probability; a term beyond it stays, whatever its probability. Real fits
on simulated rigs."""
import numpy as np

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
    """The found case: 30 s, 5 % noise, seed 418825265 (one of 3 in 60 fresh draws at 1-5 % noise and
    20-60 s to keep a spurious term; every true term had P(kept) 1.00). The held-out placement of the fit
    keeps q1*q2^3, none of the 24 random placements does. Reported: the five true terms; q1*q2^3 apart,
    with a coefficient within 3 standard errors of its true 0. (It was q1^2*q2 while an even selection
    carried a displacement below the band without asking whether the data establish it: the last test.)"""
    rec = _record(418825265, 30.0)
    ident = SparseIdentifier().fit(rec)  # only terms the selection kept are judged and listed apart
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH) and res["selection"]["q1_dot"]["n_terms"] == len(TRUTH)
    apart = res["uncertain_terms"]["q1_dot"]
    assert list(apart) == ["q1*q2^3"] and res["uncertain_terms"]["q2_dot"] == {}
    term = apart["q1*q2^3"]
    assert term["inclusion_probability"] < unc.MIN_INCLUSION_PROBABILITY
    assert abs(term["coefficient"]) < 3 * term["standard_error"]
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
    on the terms the data establish: the true five, no offset, the two listed apart within 3 standard
    errors of their true 0, the closed-form chain bias (no carried offset stands in its way)."""
    ident = SparseIdentifier(validate=False).fit(_record(5036, 30.0))
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH)
    assert ident.offset_["carried"] is False
    apart = res["uncertain_terms"]["q1_dot"]
    assert {"q2^2", "q2^4"} <= set(apart)
    for term in apart.values():
        assert abs(term["coefficient"]) < 3 * term["standard_error"]
    assert ident.uncertainty_["chain_bias"]["method"] == unc.ANALYTIC
    for term, c in TRUTH.items():
        assert abs(ident.model_.coefficient("q1_dot", term) / c - 1) < 0.03, term
