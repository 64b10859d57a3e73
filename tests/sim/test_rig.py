"""The simulated rig is ground truth: its kinematics are exact and its integration error is negligible."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sim.rig import RigParameters
from sim.sensors import Accelerometer
from protocol.sweep import SineSweep
from sim.synth import run_sweep


def test_sweep_kinematics_are_consistent_derivatives():
    sw = SineSweep(1.0, 20.0, 10.0, 1.3)
    t = np.linspace(0, 10, 400001)
    z, zd, zdd = sw.kinematics(t)
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(z, h)[1:-1], zd[1:-1], atol=2e-3 * np.abs(zd).max())
    np.testing.assert_allclose(np.gradient(zd, h)[1:-1], zdd[1:-1], atol=2e-3 * np.abs(zdd).max())
    # starts and ends at rest (C2 fades): no step in acceleration for the accelerometers to see
    for v in (z, zd, zdd):
        assert abs(v[0]) < 1e-12 and abs(v[-1]) < 1e-9
    assert np.abs(z).max() == pytest.approx(1.3e-3, rel=1e-3)
    assert sw.frequency_hz(5.0) == pytest.approx(10.5)


def test_paper_table1_rig_model():
    eqs = RigParameters.paper_table1().model().equations
    assert eqs["q1_dot"] == pytest.approx({"q1": -3.7294, "q2": -971.0169, "q2^3": -2.5033e6, "zdd": -1.0243,
                                           "q1*q2^2": 1.162e4})
    assert eqs["q2_dot"] == {"q1": 1.0}


def test_design_rig_uses_profile_geometry():
    rig = RigParameters.design(prestress_m=2e-3)
    assert rig.stiffness_n_per_m == pytest.approx(4 * 16.7e3 * 4 * 2e-3)
    assert rig.cubic_stiffness_n_per_m3 == pytest.approx(4 * 16.7e3 * 16)
    with pytest.raises(ValueError, match="unknown effect"):
        RigParameters(effects={"magic": 1.0})


@pytest.mark.slow
def test_truth_integration_error_is_far_below_sensor_noise():
    """Smooth rig against a tight adaptive reference; sensor noise is 5e-3 of the signal."""
    rig = RigParameters.paper_table1()
    sw = SineSweep(3.0, 8.0, 4.0, 1.0)
    run = run_sweep(rig, sw, settle_s=0.5, table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0))
    model = rig.model()
    t = np.arange(run.recording.n_samples) / run.recording.fs_hz
    ref = solve_ivp(lambda tt, x: model.rhs(x[None, :], [[sw.kinematics(tt)[2]]])[0], (0, t[-1]), [0.0, 0.0],
                    t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13)
    assert np.max(np.abs(run.states[:, 1] - ref.y[1])) / np.max(np.abs(ref.y[1])) < 1e-7


def test_truth_with_coulomb_friction_is_converged():
    """sign(q1) makes the right-hand side jump, which adaptive reference solvers crawl through; instead
    the truth (64 RK4 steps per sample when non-smooth) is checked against 4x finer steps."""
    rig = RigParameters.paper_table1()
    rig.effects["coulomb_friction"] = 0.2
    sw = SineSweep(3.0, 8.0, 4.0, 1.0)
    quiet = dict(table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0), settle_s=0.5)
    coarse = run_sweep(rig, sw, **quiet).states[:, 1]
    fine = run_sweep(rig, sw, substeps=256, **quiet).states[:, 1]
    assert np.max(np.abs(coarse - fine)) / np.max(np.abs(fine)) < 1e-4  # 50x below 0.5 % sensor noise


def test_sensor_model():
    rng = np.random.default_rng(0)
    x = np.sin(np.linspace(0, 100, 100000))
    y = Accelerometer(noise_fraction=0.01, bias_ms2=0.5, lsb_ms2=0.01).measure(x, rng)
    assert np.mean(y - x) == pytest.approx(0.5, abs=2e-3)
    assert np.std(y - x) == pytest.approx(np.hypot(0.01 * np.std(x), 0.01 / np.sqrt(12)), rel=0.05)
    assert np.allclose(np.round(y / 0.01) * 0.01, y)
    clipped = Accelerometer(noise_fraction=0, range_ms2=0.5).measure(x, rng)
    assert clipped.max() == 0.5
