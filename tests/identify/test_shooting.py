"""The shooting error's inputs (identify.simulation.shooting.ShootingData): a fine input grid too large to
hold is built per segment, with the values the whole record's grid has."""
import numpy as np
import pytest

from identify.model import SparseModel
from identify.simulation import shooting
from identify.simulation.shooting import ShootingData


def _data(n=20000, cut=12000):
    rng = np.random.default_rng()
    x = np.convolve(rng.standard_normal(n), np.hanning(40), "same") + 3.0  # band-limited, off zero
    q = np.column_stack([np.gradient(x), x]) * 1e-3
    starts = np.arange(0, n, 400)
    stops = np.minimum(starts + 400, n)
    return ShootingData(q, np.column_stack([x, np.linspace(-0.5, 0.5, n)]), x, "q1_dot", 1000.0, starts, stops,
                        np.zeros(starts.size, bool), cuts=(cut,))


@pytest.mark.parametrize("substeps", [1, 4, 16])
def test_a_segments_fine_inputs_are_the_records(substeps):
    """Rows a..b-1 interpolated from the segment and FINE_PAD rows either side, the recording's mean removed:
    the same numbers as the whole record's grid, at the record's edges, a cut between two recordings and
    inside (the band-limited filter reaches ~10 rows)."""
    d = _data()
    up = 2 * substeps
    full = d.fine(substeps)
    for a, b in [(0, 300), (5000, 5400), (11800, 12000), (12000, 12400), (19600, 20000)]:
        np.testing.assert_array_equal(d.segment_fine(a, b, substeps), full[a * up:(b - 1) * up + 1])


def test_a_grid_over_the_budget_is_not_held_and_the_run_is_the_same(monkeypatch):
    """Above FINE_GRID_BYTES fine() holds nothing and run() builds each segment's inputs: the same
    simulated signal and errors; below, only the last substeps' grid is kept."""
    d = _data()
    model = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "q2^3": -1e6, "zdd": -1.0}, "q2_dot": {"q1": 1.0}},
                        states=("q1", "q2"), inputs=("zdd", "tau"))
    held = d.run(model)
    assert len(d._fine) == 1
    monkeypatch.setattr(shooting, "FINE_GRID_BYTES", 1024)
    fresh = _copy(d)
    assert fresh.fine(2) is None and fresh._fine == {}
    per_segment = fresh.run(model)
    np.testing.assert_allclose(per_segment[0], held[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(per_segment[1], held[1], rtol=1e-12)


def _copy(d: ShootingData) -> ShootingData:
    return ShootingData(d.states, d.inputs, d.measured, d.gap, d.fs_hz, d.starts, d.stops, d.held, cuts=d.cuts)


def test_offsets_of_some_segments_are_those_of_the_whole_record():
    """ShootingData.offsets computes only the segments asked for (a refit runs the training segments), each
    from its own rows: bitwise what the computation over every segment gives them, 0 for the others."""
    d = _data()
    model = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "q2^2": 3e4, "q2^3": -1e6, "zdd": -1.0},
                         "q2_dot": {"q1": 1.0}}, states=("q1", "q2"), inputs=("zdd", "tau"))
    every = d.offsets(model, None)
    assert np.count_nonzero(every) > len(every) // 2  # an asymmetric spring: the offsets are not all 0
    some = np.array([0, 3, 4, 17, len(every) - 1])
    part = d.offsets(model, some)
    np.testing.assert_array_equal(part[some], every[some])
    assert not np.delete(part, some).any()
    assert not d.offsets(model, np.array([], dtype=int)).any()


def test_a_smooth_model_runs_in_steps_of_several_samples_and_friction_sample_by_sample(monkeypatch):
    """run() steps as the free run does (choose_step): a smooth model slow against the rows' rate takes RK4
    steps of several samples. On a record the model itself made (a 1-8 Hz chirp at 1000 Hz, run at 8 substeps),
    each segment started from its true state: the gap signal within 2e-5 of its peak of the run in steps of
    one sample (measured 5e-6; the Table 1 rig: 1.2e-8 - 3.4e-6 of its peak at 1-4 samples a step,
    tests/identify/test_simulate.py), both within 2e-4 of the truth (7e-5: the input interpolated between
    samples, not the step).
    Coulomb friction's sign(q1) keeps one step per sample, and its offsets read every row
    (OFFSET_ROW_STEP is for smooth models only)."""
    from identify.simulation.simulate import equation_rows, simulate
    fs, n = 1000.0, 20000
    t = np.arange(n) / fs
    u = (-1e-3 * (2 * np.pi * (1 + 0.35 * t)) ** 2 * np.sin(2 * np.pi * (t + 0.175 * t ** 2)))[:, None]
    smooth = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "q2^3": -1e5, "zdd": -1.0}, "q2_dot": {"q1": 1.0}},
                         states=("q1", "q2"), inputs=("zdd",))
    states = simulate(smooth, 1 / fs, [0.0, 0.0], u, substeps=8).states
    truth = equation_rows(smooth, states, u)
    starts = np.arange(0, n, 400)
    d = ShootingData(states, u, truth, "q1_dot", fs, starts, np.minimum(starts + 400, n), np.zeros(starts.size, bool))
    out, _, step = d.run(smooth)
    assert step[0] == 1 and step[1] > 1
    with monkeypatch.context() as m:
        m.setattr(shooting, "choose_step", lambda model, dt, scale: (1, 1))
        d1 = ShootingData(states, u, truth, "q1_dot", fs, d.starts, d.stops, d.held)
        one, _, step1 = d1.run(smooth)
    assert step1 == (1, 1)
    peak = np.max(np.abs(truth))
    assert np.max(np.abs(out - one)) < 2e-5 * peak  # measured 5e-6 in steps of 3 samples
    assert np.max(np.abs(out - truth)) < 2e-4 * peak  # either: 7e-5, the input's interpolation between samples
    friction = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "sign(q1)": -0.5, "zdd": -1.0},
                            "q2_dot": {"q1": 1.0}}, states=("q1", "q2"), inputs=("zdd",))
    assert d.run(friction)[2] == (1, 1)
    asymmetric = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "q2^2": 3e4, "sign(q1)": -0.5, "zdd": -1.0},
                              "q2_dot": {"q1": 1.0}}, states=("q1", "q2"), inputs=("zdd",))
    every = d.offsets(asymmetric, None)
    monkeypatch.setattr(shooting, "OFFSET_ROW_STEP", 1)
    np.testing.assert_array_equal(d.offsets(asymmetric, None), every)  # friction: every row either way
    smooth_asym = SparseModel({"q1_dot": {"q1": -2.0, "q2": -900.0, "q2^2": 3e4, "zdd": -1.0}, "q2_dot": {"q1": 1.0}},
                              states=("q1", "q2"), inputs=("zdd",))
    all_rows = d.offsets(smooth_asym, None)
    monkeypatch.setattr(shooting, "OFFSET_ROW_STEP", 2)
    assert not np.array_equal(d.offsets(smooth_asym, None), all_rows)  # a smooth model: every other row
