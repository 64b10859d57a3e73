"""A term the selection kept but most random held-out placements leave out (P(kept) below
MIN_INCLUSION_PROBABILITY) is reported apart, as an uncertain term, and is not in the model, its refit or
its simulation (issue 30's "term lottery"). Real fits on the simulated Table 1 rig."""
import numpy as np

import identify.trust.uncertainty as unc
from identify.identifier import SparseIdentifier
from protocol.sweep import SineSweep
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep

TRUTH = RigParameters.paper_table1().model().equations["q1_dot"]


def _record(seed: int, duration_s: float, noise: float = 0.05):
    sensors = dict(table_sensor=Accelerometer(noise), mass_sensor=Accelerometer(noise))
    return run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, duration_s, 1.3), 2048.0, 2.0,
                     seed=seed, **sensors).recording


def test_a_kept_term_most_placements_leave_out_is_reported_apart():
    """The found case: 30 s, 5 % noise, seed 418825265 (one of 3 in 60 fresh draws at 1-5 % noise and
    20-60 s to keep a spurious term; every true term had P(kept) 1.00). The held-out placement of the fit
    keeps q1^2*q2, none of the 24 random placements does. Reported: the five true terms; q1^2*q2 apart,
    with a coefficient within 3 standard errors of its true 0."""
    rec = _record(418825265, 30.0)
    before = SparseIdentifier(placements=0).fit(rec).result()  # no probabilities: the selection as made
    assert "q1^2*q2" in before["model"]["q1_dot"]
    ident = SparseIdentifier().fit(rec)
    res = ident.result()
    assert set(res["model"]["q1_dot"]) == set(TRUTH) and res["selection"]["q1_dot"]["n_terms"] == len(TRUTH)
    apart = res["uncertain_terms"]["q1_dot"]
    assert list(apart) == ["q1^2*q2"] and res["uncertain_terms"]["q2_dot"] == {}
    term = apart["q1^2*q2"]
    assert term["inclusion_probability"] < unc.MIN_INCLUSION_PROBABILITY
    assert abs(term["coefficient"]) < 3 * term["standard_error"]
    # left out of what is simulated and validated, and of the selection's support, too
    assert "q1^2*q2" not in ident.training_model_.equations["q1_dot"]
    assert "q1^2*q2" not in ident.validated_model_.equations["q1_dot"]
    for t, c in TRUTH.items():  # the terms left, refit without it, hold the truth
        assert abs(res["model"]["q1_dot"][t] - c) < 3 * res["standard_errors"]["q1_dot"][t], t


def test_no_reported_term_is_one_most_placements_leave_out():
    """Fresh draw (seed printed): whatever is selected, every term in the model has P(kept) >= the bound and
    every uncertain term is below it and absent from the model."""
    seed = int(np.random.SeedSequence().generate_state(1)[0])
    print(f"seed {seed}")
    res = SparseIdentifier().fit(_record(seed, 20.0)).result()
    for eq, terms in res["model"].items():
        probs = res["inclusion_probability"][eq]
        assert all(probs[t] >= unc.MIN_INCLUSION_PROBABILITY for t in terms), (eq, terms, probs)
        for t, entry in res["uncertain_terms"][eq].items():
            assert t not in terms and entry["inclusion_probability"] < unc.MIN_INCLUSION_PROBABILITY
