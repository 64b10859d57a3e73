"""The compiled free-run simulator against exact solutions and a tight reference integrator."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from identify.model import SparseModel
from identify.simulation.simulate import fine_grid_input, simulate

TABLE1 = {"q1_dot": {"q1": -3.7294, "q2": -971.0169, "q1*q2^2": 1.162e4, "q2^3": -2.5033e6, "zdd": -1.0243},
          "q2_dot": {"q1": 1.0}}


def test_undamped_oscillator_matches_cosine():
    w = 2 * np.pi * 5.0
    model = SparseModel({"q1_dot": {"q2": -w**2}, "q2_dot": {"q1": 1.0}})
    dt = 1 / 2048
    n = 4096
    res = simulate(model, dt, [0.0, 1.0], np.zeros(n), substeps=4)
    t = np.arange(n) * dt
    np.testing.assert_allclose(res.states[:, 1], np.cos(w * t), atol=1e-8)
    np.testing.assert_allclose(res.states[:, 0], -w * np.sin(w * t), atol=1e-6 * w)


def test_duffing_sweep_matches_tight_reference():
    """An analytic input, so the reference integrator and the kernel see exactly the same forcing."""
    fs, T, substeps = 2048.0, 8.0, 2
    n = int(T * fs)

    def u(t):
        return -1.3e-3 * (2 * np.pi * 5) ** 2 * np.sin(2 * np.pi * (3 * t + 0.5 * t**2))

    model = SparseModel(TABLE1)
    t = np.arange(n) / fs
    ref = solve_ivp(lambda tt, x: model.rhs(x[None, :], [[u(tt)]])[0], (0, t[-1]), [0.0, 0.0], t_eval=t,
                    method="DOP853", rtol=1e-11, atol=1e-14)
    t_fine = np.arange((n - 1) * 2 * substeps + 1) / (2 * substeps * fs)
    res = simulate(model, 1 / fs, [0.0, 0.0], inputs_fine=u(t_fine)[:, None], substeps=substeps, n_samples=n)
    scale = np.max(np.abs(ref.y[1]))
    assert scale > 5e-3  # the cubic term matters at this amplitude
    # RK4 with 2 substeps: 7e-10 measured (4th order: 16x per halving); an O(h^2) bug gives ~1e-5
    assert np.max(np.abs(res.states[:, 1] - ref.y[1])) < 1e-8 * scale


def test_divergence_is_reported_and_marked_nan():
    model = SparseModel({"q1_dot": {"q1": 50.0, "q2": -100.0}, "q2_dot": {"q1": 1.0}})  # negative damping
    res = simulate(model, 1e-3, [0.0, 1.0], np.zeros(5000), substeps=1, bound=1e3)
    assert res.diverged
    assert 0 < res.n_valid < 5000
    assert np.all(np.isnan(res.states[res.n_valid:])) and np.all(np.isfinite(res.states[:res.n_valid]))


def test_input_channel_count_is_checked():
    with pytest.raises(ValueError, match="input has 2 channels"):
        simulate(SparseModel(TABLE1), 1e-3, [0, 0], np.zeros((10, 2)), substeps=1)


@pytest.mark.parametrize("method", ["bandlimited", "cubic", "linear"])
def test_fine_grid_input_keeps_samples_and_interpolates(method):
    fs = 1000.0
    n = 2000
    t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 7 * t)
    fine = fine_grid_input(x, 3, method)[:, 0]
    assert fine.shape == ((n - 1) * 6 + 1,)
    tf = np.arange(fine.size) / (6 * fs)
    inner = slice(600, fine.size - 600)  # away from the record's edges
    tol = {"bandlimited": 1e-3, "cubic": 1e-6, "linear": 2e-3}[method]
    assert np.max(np.abs(fine[inner] - np.sin(2 * np.pi * 7 * tf[inner]))) < tol


@pytest.mark.parametrize("equations, travel", [
    (TABLE1, None),
    # constant, |q|, sign, products across states and input, a term shared by both equations
    ({"q1_dot": {"1": 0.3, "sign(q1)": -0.2, "q1*|q1|": 4.0, "q2^2": 3e4, "q2^3*|q2|": 7.0,
                 "q1^2*q2^2*zdd": 2.0, "zdd": -1.0},
      "q2_dot": {"q1": 1.0, "q2^2": 5.0}}, None),
    # end stops: the penetration and the contact indicator on each row's own side
    ({"q1_dot": {"q2": -900.0, "stop(q2)": -5e5, "q1*contact(q2)": -30.0, "zdd": -1.0},
      "q2_dot": {"q1": 1.0}}, {"q2": 0.02}),
    ({"q1_dot": {}, "q2_dot": {"q1": 1.0}}, None),  # an empty equation is zero
])
@pytest.mark.parametrize("equation", [0, 1])
def test_equation_rows_is_the_models_rhs(equations, travel, equation):
    """The compiled one-equation evaluation against SparseModel.rhs (numpy, the library's columns), on
    strided state columns and an input column: the same sums, so equal to rounding."""
    from identify.simulation.simulate import equation_rows

    rng = np.random.default_rng(3)
    model = SparseModel(equations, travel=travel)
    n = 3001  # not a multiple of the kernel's block of rows
    x = rng.standard_normal((n, 2)) * [0.3, 0.025]  # q2 on both sides of the 0.02 m travel
    u = rng.standard_normal((n, 1))
    got = equation_rows(model, (x[:, 0], x[:, 1]), u, equation)
    want = model.rhs(x, u)[:, equation]
    assert got.shape == (n,)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * max(np.max(np.abs(want)), 1.0))
    if travel:
        assert np.any(np.abs(x[:, 1]) > 0.02) and np.any(np.abs(x[:, 1]) < 0.02)


@pytest.mark.slow
def test_steps_of_several_samples_converge_at_fourth_order():
    """simulate(stride=s): RK4 steps of s samples, the samples inside a step from RK4's continuous
    extension. Against DOP853 on the Duffing sweep (analytic input): the error grows as h^4 with the step
    (16x per doubling; an O(h^2) or O(h^3) interpolation bug shows as 4-8x), the samples inside a step no
    worse than its ends, the last, shorter step included (n - 1 not a multiple of the stride). Measured
    (of the peak): 1.2e-8, 2.0e-7, 1.05e-6, 3.4e-6 for strides 1-4 (h omega_max 0.036-0.14)."""
    fs, T = 2048.0, 8.0
    n = int(T * fs) + 3  # n - 1 = 16386: a last step of 2 samples for stride 4, of 1 for stride 3

    def u(t):
        return -1.3e-3 * (2 * np.pi * 5) ** 2 * np.sin(2 * np.pi * (3 * t + 0.5 * t**2))

    model = SparseModel(TABLE1)
    t = np.arange(n) / fs
    ref = solve_ivp(lambda tt, x: model.rhs(x[None, :], [[u(tt)]])[0], (0, t[-1]), [0.0, 0.0], t_eval=t,
                    method="DOP853", rtol=1e-11, atol=1e-14).y[1]
    fine = u(np.arange((n - 1) * 2 + 1) / (2 * fs))[:, None]
    scale = np.max(np.abs(ref))
    errors = {}
    for stride in (1, 2, 3, 4):
        res = simulate(model, 1 / fs, [0.0, 0.0], inputs_fine=fine, substeps=1, n_samples=n, stride=stride)
        err = np.abs(res.states[:, 1] - ref) / scale
        ends, inside = err[::stride].max(), err.max()
        assert inside < 2.0 * ends, (stride, ends, inside)
        errors[stride] = inside
    assert errors[1] < 1e-7 and errors[2] < 1e-6, errors
    assert 10 < errors[4] / errors[2] < 25 and 10 < errors[2] / errors[1] < 25, errors


def test_a_stride_is_refused_where_it_does_not_apply():
    stops = SparseModel({"q1_dot": {"q2": -900.0, "stop(q2)": -5e5, "zdd": -1.0}, "q2_dot": {"q1": 1.0}},
                        travel={"q2": 0.02})
    with pytest.raises(ValueError, match="stride"):
        simulate(stops, 1e-3, [0.0, 0.0], inputs_fine=np.zeros((199, 1)), substeps=1, n_samples=100, stride=2)
    with pytest.raises(ValueError, match="stride"):
        simulate(SparseModel(TABLE1), 1e-3, [0.0, 0.0], inputs_fine=np.zeros((397, 1)), substeps=2,
                 n_samples=100, stride=2)


def test_choose_step_keeps_h_omega_within_the_bound():
    """Steps of several samples only for a model without end stops slow against the sample rate, each
    with h omega_max <= STEP_OMEGA like substeps (the Table 1 rig oscillates: its rate is its largest
    |eigenvalue|)."""
    from identify.simulation.simulate import STEP_OMEGA, choose_step, max_frequency, step_rate
    scale = [0.8, 0.023]  # the Table 1 rig's states at 15 mm (x 1.5)
    model = SparseModel(TABLE1)
    omega = max_frequency(model, scale)
    assert step_rate(model, scale) == omega
    for fs in (2048.0, 8192.0, 256.0):
        substeps, stride = choose_step(model, 1 / fs, scale)
        h = stride / (substeps * fs)
        assert h * omega <= STEP_OMEGA and (stride == 1 or substeps == 1)
        assert (stride + 1) / fs * omega > STEP_OMEGA or stride == 4  # the longest step allowed
    assert choose_step(model, 1 / 2048.0, scale) == (1, 2)
    assert choose_step(model, 1 / 256.0, scale)[1] == 1
    stops = SparseModel({"q1_dot": {"q2": -900.0, "stop(q2)": -5e5, "zdd": -1.0}, "q2_dot": {"q1": 1.0}},
                        travel={"q2": 0.02})
    assert choose_step(stops, 1 / 2048.0, [0.8, 0.023])[1] == 1


def test_a_fast_real_mode_takes_longer_steps_and_stays_accurate():
    """A Bouc-Wen state relaxes at beta |q1| + gamma |q1| (~2600 1/s here, a candidate the explanation
    fits on a 5 Hz rig), a real eigenvalue: the step is held to STEP_DECAY on it, not STEP_OMEGA (3 RK4
    steps per sample at 2048 Hz, not 13), and the free run stays within 1e-4 of each state's largest value
    of a run at 4x as many steps (1e-4: 20x under the quietest accelerometer noise the suite draws, 0.2 %;
    measured 4e-5 on q1 and q2, 8e-4 on the hysteresis state z itself, whose force is 1/1000 of the
    stiffness's, hence its own looser bound)."""
    from identify.simulation.simulate import STEP_DECAY, STEP_OMEGA, choose_step, max_frequency, step_rate
    model = SparseModel({"q1_dot": {"q1": -3.49, "q2": -998.3, "q2^3": -1.9e6, "zdd": -0.969, "z": -18.9},
                         "q2_dot": {"q1": 1.0}, "z_dot": {"q1": 1.0, "|q1|*z": -56.0, "q1*|z|": -3943.0}},
                        states=("q1", "q2", "z"), inputs=("zdd",))
    scale = [0.65, 0.019, 3.75e-4]  # 1.5x the states' largest values on the record the candidate came from
    fs = 2048.0
    rate, omega = step_rate(model, scale), max_frequency(model, scale)
    assert rate == pytest.approx(omega * STEP_OMEGA / STEP_DECAY, rel=1e-9)  # the z mode is the fastest
    substeps, stride = choose_step(model, 1 / fs, scale)
    assert substeps == int(np.ceil(rate / fs / STEP_OMEGA)) == 3 and stride == 1
    assert int(np.ceil(omega / fs / STEP_OMEGA)) == 13  # what the oscillation's rule would take
    t = np.arange(int(4 * fs)) / fs
    u = -1.3e-3 * (2 * np.pi * 5) ** 2 * np.sin(2 * np.pi * (3 * t + 0.5 * t**2))
    runs = [simulate(model, 1 / fs, [0.0, 0.0, 0.0], u, substeps=s).states for s in (substeps, 4 * substeps)]
    peak = np.max(np.abs(runs[1]), axis=0)
    err = np.max(np.abs(runs[0] - runs[1]), axis=0) / peak
    assert np.all(peak > 0.1 * np.array(scale) / 1.5), peak  # the run moves the states as the record did
    assert err[0] < 1e-4 and err[1] < 1e-4 and err[2] < 2e-3, err


@pytest.mark.parametrize("equations, travel, substeps, stride", [
    (TABLE1, None, 1, 2),  # steps of two samples
    (TABLE1, None, 3, 1),
    ({"q1_dot": {"q2": -900.0, "stop(q2)": -5e5, "q1*contact(q2)": -30.0, "sign(q1)": -0.3, "zdd": -1.0},
      "q2_dot": {"q1": 1.0}}, {"q2": 0.004}, 2, 1),  # end stops (cut steps) and a friction
])
def test_segments_in_one_call_are_the_segment_by_segment_runs(equations, travel, substeps, stride):
    """simulate_segments (multiple shooting's runs in one compiled call) against simulate per segment, bit
    for bit: each segment from its own state over its stretch of the record's fine input, segments of
    unequal length that need not adjoin, one of them diverging (its samples written count short, the rows
    of the others untouched)."""
    from identify.simulation.simulate import simulate_segments

    rng = np.random.default_rng(5)
    fs, n = 1000.0, 3000
    model = SparseModel(equations, travel=travel)
    t = np.arange(n) / fs
    u = (-4.0 * np.sin(2 * np.pi * (3 * t + 2 * t**2)))[:, None]
    fine = fine_grid_input(u, substeps)
    starts = np.array([0, 400, 1000, 1700, 2500])
    stops = np.array([400, 950, 1700, 2400, 3000])  # 950 -> 1000 and 2400 -> 2500 are not run
    x0s = rng.standard_normal((starts.size, 2)) * [0.1, 0.003]
    x0s[3] = [1e4, 0.5]  # far outside the bound: diverges
    bound = 10.0
    out = np.full((n, 2), 7.0)
    written = simulate_segments(model, 1 / fs, x0s, fine, substeps, starts, stops, out, bound=bound, stride=stride)
    up = 2 * substeps
    for j, (a, b) in enumerate(zip(starts, stops)):
        one = simulate(model, 1 / fs, x0s[j], inputs_fine=fine[a * up:(b - 1) * up + 1], substeps=substeps,
                       n_samples=b - a, bound=bound, stride=stride)
        assert written[j] == one.n_valid
        np.testing.assert_array_equal(out[a:a + one.n_valid], one.states[:one.n_valid])
    whole = written == stops - starts
    assert not whole[3] and whole[[0, 1, 2, 4]].all()
    assert np.all(out[950:1000] == 7.0) and np.all(out[2400:2500] == 7.0)
    if travel:  # the stops are hit
        assert np.max(np.abs(out[:950, 1])) > travel["q2"]
    assert np.all(out[starts[3] + written[3]:stops[3]] == 7.0)  # the diverged segment's rows past its last
    assert simulate_segments(model, 1 / fs, x0s[:0], fine, substeps, starts[:0], stops[:0], out, bound=bound).size == 0
    empty = simulate_segments(model, 1 / fs, x0s[:2], fine, substeps, [0, 400], [0, 950], out, bound=bound,
                              stride=stride)  # an empty segment writes nothing, as simulate with 0 samples
    assert list(empty) == [0, 550]
    b = int(stops[0])
    simulate_segments(model, 1 / fs, x0s[:1], fine[:(b - 1) * up + 1], substeps, starts[:1], stops[:1], out,
                      bound=bound, stride=stride)  # exactly the input the segment reads
    with pytest.raises(ValueError, match="segments"):  # one row short of it
        simulate_segments(model, 1 / fs, x0s[:1], fine[:(b - 1) * up], substeps, starts[:1], stops[:1], out,
                          bound=bound, stride=stride)
    with pytest.raises(ValueError, match="overlap"):  # threads write segments' rows side by side
        simulate_segments(model, 1 / fs, x0s[:2], fine, substeps, [0, 300], [400, 950], out, bound=bound)
