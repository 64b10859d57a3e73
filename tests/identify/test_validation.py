"""Free-run validation's scoring: held-out subsets and fit metrics against their definitions."""
import numpy as np
import pytest

from identify.simulation.validation import _runs, _runs_of, fit_metrics, heldout_and_all_metrics


@pytest.mark.parametrize("mask", [
    np.repeat([False, True, False, False, True, True, False, True], [5, 3, 4, 2, 6, 1, 3, 7]).astype(bool),
    np.ones(20, dtype=bool), np.zeros(20, dtype=bool),
    np.arange(30) % 3 == 0,  # runs of one
])
def test_held_out_runs_are_the_masked_rows(mask):
    x = np.random.default_rng(0).standard_normal(mask.size)
    np.testing.assert_array_equal(_runs_of(_runs(mask))(x), x[mask])


@pytest.mark.parametrize("mask", [
    np.repeat([False, True, False, False, True, True, False, True], [50, 30, 40, 20, 60, 10, 30, 70]).astype(bool),
    np.ones(200, dtype=bool), np.zeros(200, dtype=bool), np.arange(300) % 3 == 0,
])
def test_heldout_and_all_metrics_in_one_pass_equal_fit_metrics_on_the_subsets(mask):
    """validate scores the held-out rows and all rows from one error array: the figures of fit_metrics on
    the concatenated held-out rows and on all rows, to rounding; a non-finite simulated sample outside
    the held-out rows leaves the held-out figures, one inside takes them away."""
    rng = np.random.default_rng(2)
    y = 5.0 + np.cumsum(rng.standard_normal(mask.size))  # offset and drift: the held-out mean is not the mean
    s = y + 0.3 * rng.standard_normal(mask.size)
    held, whole = heldout_and_all_metrics(y, s, _runs(mask))
    for got, want in ((held, fit_metrics(y[mask], s[mask])), (whole, fit_metrics(y, s))):
        for k in want:
            assert (got[k] is None and want[k] is None) or got[k] == pytest.approx(want[k], rel=1e-11), (k, got, want)
    if mask.any() and not mask.all():
        for inside in (True, False):
            s2 = s.copy()
            s2[np.flatnonzero(mask == inside)[0]] = np.nan
            held, whole = heldout_and_all_metrics(y, s2, _runs(mask))
            assert whole["nrmse"] is None and (held["nrmse"] is None) == inside
            if not inside:
                assert held["nrmse"] == pytest.approx(fit_metrics(y[mask], s[mask])["nrmse"], rel=1e-11)


def test_fit_metrics_follow_their_definitions_and_refuse_a_non_finite_simulation():
    rng = np.random.default_rng(1)
    y = 3.0 + rng.standard_normal(1000)
    s = y + 0.1 * rng.standard_normal(1000)
    m = fit_metrics(y, s)
    nrmse = np.sqrt(np.mean((y - s) ** 2)) / np.std(y)
    assert m["nrmse"] == pytest.approx(nrmse, rel=1e-13) and m["fit_percent"] == pytest.approx(100 * (1 - nrmse))
    for bad in (np.nan, np.inf):
        s2 = s.copy()
        s2[500] = bad
        assert fit_metrics(y, s2) == {"nrmse": None, "fit_percent": None, "rmse": None}
    assert fit_metrics(y[:0], s[:0])["nrmse"] is None


def test_the_validation_reports_the_steps_it_took(table1_run, table1_truth):
    """validate's document says how the free run stepped: RK4 substeps per sample and samples per step
    (identify.simulation.simulate.choose_step: the Table 1 rig at 2048 Hz is slow enough for steps of 2 samples)."""
    from identify.chain.states import reconstruct_states
    from identify.model import SparseModel
    from identify.simulation.simulate import choose_step
    from identify.simulation.validation import validate
    sig = reconstruct_states(table1_run.recording)
    model = SparseModel(table1_truth)
    v = sig.valid
    rows = np.zeros(v.stop - v.start, dtype=bool)
    rows[::7] = True
    out = validate(model, sig, rows)[0]
    scale = 1.5 * np.max(np.abs(sig.states[v]), axis=0)
    assert (out["substeps"], out["samples_per_step"]) == choose_step(model, 1 / sig.fs_hz, scale) == (1, 2)
    assert out["heldout"]["q2"]["fit_percent"] > 95
