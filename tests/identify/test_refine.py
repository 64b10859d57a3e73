"""The free-run error the output-error refit minimises (identify.simulation.refine): its RK4 steps are chosen as
validation chooses them (identify.simulation.simulate.choose_step), several samples at a time for a model slow
against the sample rate, and that moves neither the error nor the refit beyond RK4's own error."""
import numpy as np
import pytest

from identify.identifier import SparseIdentifier
from identify.simulation.refine import FreeRunError, refine_free_run


@pytest.fixture(scope="module")
def table1_fit(table1_run):
    return SparseIdentifier(validate=False).fit(table1_run.recording)


def test_free_run_error_steps_as_validation_does(table1_fit):
    """The Table 1 rig at 2048 Hz (omega_max dt = 0.036) takes RK4 steps of 2 samples, as validation's free
    run does; the error it reports is the sample-by-sample run's to RK4's error. Measured: residuals within
    1.0e-7 of each other (the largest is 4.2e-4), costs within 3.9e-4 of each other. Bound: RK4 at
    h omega = 0.072 is off by up to 1.4e-5 of the peak (identify.simulation.simulate.STEP_OMEGA) against a model
    error of ~1e-2 of it, which moves a sum of squares by up to ~3e-3 of itself."""
    sig, model = table1_fit.states_, table1_fit.model_
    strided = FreeRunError(sig, None, model=model)
    by_sample = FreeRunError(sig, None, model=model, substeps=1)
    assert (strided.substeps, strided.stride) == (1, 2)
    assert (by_sample.substeps, by_sample.stride) == (1, 1)
    r2, r1 = strided.residuals(model), by_sample.residuals(model)
    assert not np.array_equal(r2, r1)  # the steps differ ...
    assert np.max(np.abs(r2 - r1)) < 1e-3 * np.max(np.abs(r1))  # ... by RK4's error only
    assert strided.cost(model) == pytest.approx(by_sample.cost(model), rel=3e-3)


@pytest.mark.slow
def test_refit_in_steps_of_two_samples_matches_the_sample_by_sample_refit(table1_fit):
    """The refit's coefficients with steps of 2 samples against those with one step per sample: measured
    within 3.5e-7 of each other, against the 1e-3 - 1e-2 of a coefficient's standard error; the bound is
    1e-5."""
    sig, model = table1_fit.states_, table1_fit.model_
    fast, info_fast = refine_free_run(model, sig)
    slow, info_slow = refine_free_run(model, sig, substeps=1)
    assert info_fast["accepted"] and info_slow["accepted"]
    assert info_fast["cost_after"] < 0.5 * info_fast["cost_before"]
    for term, c in slow.equations["q1_dot"].items():
        assert fast.equations["q1_dot"][term] == pytest.approx(c, rel=1e-5), term
