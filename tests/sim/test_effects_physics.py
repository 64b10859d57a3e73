"""The suite's physics and sensor faults against independent truth: the force laws of the contract
written out here in plain numpy and integrated with scipy's DOP853 at tight tolerance, closed forms
(energy per cycle of cubic damping, the drifting resonance), and the sensor readings against the true
signal, exact."""
import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sim.plc import PLCConfig, RigPLC
from sim.rig import RigParameters
from sim.sensors import Accelerometer, delay
from protocol.sweep import SineSweep
from sim.synth import run_sweep

M, C, K, K3 = 0.5, 1.0, 800.0, 5e6           # fn = 6.4 Hz, damping ratio 0.025
BASE = RigParameters(mass_kg=M, damping_ns_per_m=C, stiffness_n_per_m=K, cubic_stiffness_n_per_m3=K3)
SWEEP = SineSweep(2.0, 12.0, 6.0, 0.5)
FS, SETTLE = 1000.0, 0.5
QUIET = dict(table_sensor=Accelerometer(0.0), mass_sensor=Accelerometer(0.0))


def table_acceleration(sweep: SineSweep):
    """z''(t) as a scalar function: SineSweep.kinematics' closed form between the fades (one numpy call
    per RHS evaluation costs more than the rest of it), kinematics itself within them."""
    A, f0, f1, T, F = sweep.amplitude_mm * 1e-3, sweep.f_start_hz, sweep.f_end_hz, sweep.duration_s, sweep.fade

    def zdd(t):
        if t < F or t > T - F:
            return float(sweep.kinematics(np.array([t]))[2][0])
        phi = 2 * math.pi * (f0 * t + (f1 - f0) * t * t / (2 * T))
        dphi = 2 * math.pi * (f0 + (f1 - f0) * t / T)
        return A * (math.cos(phi) * 2 * math.pi * (f1 - f0) / T - math.sin(phi) * dphi * dphi)
    return zdd


def reference(rig: RigParameters, sweep, fs=FS, settle=SETTLE):
    """States at the samples from the contract's force laws (not sim/physics.py), by DOP853."""
    n = int(round((sweep.duration_s + settle) * fs)) + 1
    T = (n - 1) / fs
    m, c, k, k3 = rig.mass_kg, rig.damping_ns_per_m, rig.stiffness_n_per_m, rig.cubic_stiffness_n_per_m3
    lower, upper = (v * 1e-3 for v in rig.travels_mm)
    g = rig.spring_free_play_mm * 1e-3
    a, A, beta, gamma, nb = (rig.hysteresis_alpha, rig.hysteresis_A, rig.hysteresis_beta, rig.hysteresis_gamma,
                             rig.hysteresis_n)
    ma, ka, ca = rig.absorber_mass_kg, rig.absorber_stiffness_n_per_m, rig.absorber_damping_ns_per_m

    zdd_at = table_acceleration(sweep)

    def f(t, x):
        v, q, z, va, ya = x
        zdd = zdd_at(t)
        spring = q if g == 0 else math.copysign(max(abs(q) - g, 0.0), q)
        force = c * v + k * (1 + rig.stiffness_drift * t / T) * spring + k3 * q**3
        for name, val in rig.effects.items():
            force += {"cubic_damping": val * v**3,
                      "asymmetric_stiffness": val * (max(q, 0.0) if rig.asymmetric_side == 1 else min(q, 0.0)),
                      "coulomb_friction": val * np.sign(v)}[name]
        force += a * k * z
        if q > upper:
            force += rig.contact_stiffness_n_per_m * (q - upper) + rig.contact_damping_ns_per_m * v
        if q < -lower:
            force += rig.contact_stiffness_n_per_m * (q + lower) + rig.contact_damping_ns_per_m * v
        absorber = ka * ya + ca * va if ma > 0 else 0.0
        qdd = (-force + absorber) / m - zdd
        zd = A * v - beta * abs(v) * abs(z) ** (nb - 1) * z - gamma * v * abs(z) ** nb if a else 0.0
        vad = -absorber / ma - qdd - zdd if ma > 0 else 0.0
        return [qdd, v, zd, vad, va]

    t = np.arange(n) / fs
    sol = solve_ivp(f, (0, T), np.zeros(5), "DOP853", t_eval=t, rtol=1e-10, atol=1e-13)
    assert sol.success
    return sol.y.T


def sim_error(rig, sweep=None):
    sweep = sweep or SWEEP
    run = run_sweep(rig, sweep, FS, SETTLE, seed=None, **QUIET)
    ref = reference(rig, sweep)
    err = np.max(np.abs(run.states[:, 1] - ref[:, 1])) / np.max(np.abs(ref[:, 1]))
    return err, run, ref


SMOOTH = {"effects": {"cubic_damping": 2.0}, "stiffness_drift": 0.15, "absorber_mass_kg": 0.02,
          "absorber_stiffness_n_per_m": 0.02 * (2 * np.pi * 9.0) ** 2, "absorber_damping_ns_per_m": 0.05}


@pytest.mark.parametrize("fields, tol", [
    (SMOOTH, 1e-7),
    ({"effects": {"asymmetric_stiffness": 80.0}, "hysteresis_alpha": 0.1, "hysteresis_beta": 300.0,
      "hysteresis_gamma": 200.0}, 1e-6),
    ({"effects": {"asymmetric_stiffness": 80.0}, "asymmetric_side": -1, "hysteresis_alpha": 0.1,
      "hysteresis_beta": 6e4, "hysteresis_gamma": 4e4, "hysteresis_n": 2}, 1e-6),
    ({"spring_free_play_mm": 0.3, "end_stop_upper_mm": 3.0, "end_stop_lower_mm": math.inf}, 3e-5),
    ({"end_stop_upper_mm": 3.5, "end_stop_lower_mm": 2.5}, 3e-5),
], ids=["cubic_damping+drift+absorber", "asymmetric+bouc_wen_n1", "asymmetric_negative+bouc_wen_n2",
        "free_play+upper_stop_only", "two_travels"])
@pytest.mark.slow
def test_physics_matches_independent_integration(fields, tol):
    """Each physics against the contract's force law integrated by DOP853 (rtol 1e-10), combined so one
    reference run checks several laws (a wrong one anywhere shows): the displacement within `tol` of its
    peak. Measured: 1e-9 (smooth), 2e-9 (asymmetric + Bouc-Wen, at 64 substeps), 6e-6 and 2.5e-6 with
    contacts (hard 7.7e5 N/m bumpers; the kernel cuts its steps at contact, DOP853 steps through it)."""
    rig = dataclasses.replace(BASE, **fields)
    err, run, ref = sim_error(rig)
    assert err < tol
    if rig.hysteresis_alpha:  # the internal state too, and it saturates at (A / (beta + gamma))^(1/n)
        z_max = (1 / (rig.hysteresis_beta + rig.hysteresis_gamma)) ** (1 / rig.hysteresis_n)
        assert np.max(np.abs(run.internal["z"] - ref[:, 2])) < tol * z_max
        assert 0.9 * z_max < np.max(np.abs(run.internal["z"])) < z_max
    if rig.absorber_mass_kg:
        assert np.max(np.abs(run.internal["qa2"] - ref[:, 4])) < tol * np.max(np.abs(ref[:, 4]))


def test_one_sided_stop_acts_on_its_side_only():
    """An upper stop at 3 mm: the mass goes past -3 mm freely, not past +3 mm (more than the bumper's
    penetration), and until the first contact it moves as the rig without stops; the lower stop mirrors it."""
    free = run_sweep(dataclasses.replace(BASE, end_stop_travel_mm=None), SWEEP, FS, SETTLE, seed=None, **QUIET)
    first = None
    for side, kw in ((1, {"end_stop_upper_mm": 3.0, "end_stop_lower_mm": math.inf}),
                     (-1, {"end_stop_upper_mm": math.inf, "end_stop_lower_mm": 3.0})):
        run = run_sweep(dataclasses.replace(BASE, **kw), SWEEP, FS, SETTLE, seed=None, **QUIET)
        q = side * run.states[:, 1]
        assert 0.0030 < q.max() < 0.0032 and q.min() < -0.004
        assert run.truth["contact_samples"] == np.count_nonzero(q > 0.003) > 10
        first = np.argmax(q > 0.003)
        np.testing.assert_allclose(run.states[:first], free.states[:first], rtol=0, atol=1e-12)
        assert run.truth["end_stops"]["lower_travel_mm" if side == -1 else "upper_travel_mm"] == 3.0
    assert first > 0


def test_cubic_damping_energy_per_cycle():
    """Steady state at 5 Hz on a linear rig with cubic damping: the damper's force, recovered from the
    true mass acceleration (F = -m x'' - c q' - k q), dissipates (3 pi / 4) c3 w^3 Q^4 per cycle, the
    closed form for q = Q sin(w t) (within 1 %: the damper distorts q a little)."""
    c3, f = 3.0, 5.0
    rig = dataclasses.replace(BASE, cubic_stiffness_n_per_m3=0.0, effects={"cubic_damping": c3})
    run = run_sweep(rig, SineSweep(f, f, 12.0, 0.5), 4000.0, 0.0, seed=None, **QUIET)
    fs, w = 4000.0, 2 * np.pi * f
    v, q = run.states[:, 0], run.states[:, 1]
    force = -M * run.mass_acc_true - C * v - K * q
    cycles = slice(int(8 * fs), int(8 * fs) + int(10 * fs / f) + 1)  # ten cycles after 8 s (decay time 1 s)
    energy = np.trapezoid(force[cycles] * v[cycles], dx=1 / fs) / 10
    amp = 0.5 * (q[cycles].max() - q[cycles].min())
    assert energy == pytest.approx(0.75 * np.pi * c3 * w**3 * amp**4, rel=0.01)


def test_stiffness_drift_moves_the_resonance():
    """A slow sweep over a linear rig whose stiffness grows 40 % over the record peaks where a rig of the
    constant stiffness k (1 + r t_peak/T) peaks (0.5 %; measured 0.2 %), well above the undrifted rig."""
    sweep, fs, settle, r = SineSweep(3.0, 12.0, 40.0, 0.3), 500.0, 1.0, 0.4
    lin = dataclasses.replace(BASE, cubic_stiffness_n_per_m3=0.0)

    def peak(rig):
        run = run_sweep(rig, sweep, fs, settle, seed=None, **QUIET)
        t = np.argmax(np.abs(run.states[:, 1])) / fs
        return t, float(sweep.frequency_hz(t))

    t_drift, f_drift = peak(dataclasses.replace(lin, stiffness_drift=r))
    _, f_then = peak(dataclasses.replace(lin, stiffness_n_per_m=K * (1 + r * t_drift / (sweep.duration_s + settle))))
    _, f_plain = peak(lin)
    assert f_drift == pytest.approx(f_then, rel=0.005)
    assert f_drift > 1.05 * f_plain


# -- sensor faults --------------------------------------------------------------------------------------
def test_gain_and_bias_drift_exact_and_the_noise_unchanged():
    """gain and bias drift in the readings exactly as stated; the noise is the healthy sensor's, draw for draw."""
    x = np.sin(np.linspace(0, 40, 5001)) * 3.0
    healthy = Accelerometer(noise_fraction=0.01, bias_ms2=0.1).measure(x, np.random.default_rng(3))
    faulty = Accelerometer(noise_fraction=0.01, bias_ms2=0.1, gain=1.03, bias_drift_ms2=-0.04)
    y = faulty.measure(x, np.random.default_rng(3))
    np.testing.assert_allclose(y - (1.03 * x - 0.04 * np.linspace(0, 1, x.size)), healthy - x, rtol=0, atol=1e-13)
    assert faulty.faults() == {"gain": 1.03, "bias_drift_ms2": -0.04} and Accelerometer().faults() == {}


def test_table_delay_exact_from_the_sweep():
    """A delayed table sensor reads the analytic table acceleration at t - delay, to rounding."""
    d = 0.37e-3
    run = run_sweep(BASE, SWEEP, FS, SETTLE, seed=None, table_sensor=Accelerometer(0.0, delay_s=d),
                    mass_sensor=Accelerometer(0.0))
    t = np.arange(run.recording.input.size) / FS
    np.testing.assert_allclose(run.recording.input, SWEEP.kinematics(t - d)[2], rtol=0, atol=1e-12)
    assert run.truth["sensor_faults"] == {"table_sensor": {"delay_s": d}}


def test_mass_delay_against_the_fine_grid_truth():
    """A fractional delay of the mass channel (3/8 sample at 1 kHz; run_sweep re-simulates the rig under
    the delayed table motion) against the same rig sampled at 8 kHz and read 3 fine samples earlier."""
    d = 3 / 8000.0
    run = run_sweep(BASE, SWEEP, FS, SETTLE, seed=None, table_sensor=Accelerometer(0.0),
                    mass_sensor=Accelerometer(0.0, delay_s=d))
    fine = run_sweep(BASE, SWEEP, 8000.0, SETTLE, seed=None, **QUIET).mass_acc_true
    want = fine[np.arange(1, run.recording.output.size) * 8 - 3]
    assert np.max(np.abs(run.recording.output[1:] - want)) < 1e-7 * np.max(np.abs(want))
    np.testing.assert_array_equal(run.recording.input, run.table_acc_true)  # the table channel is not delayed


def test_frequency_domain_delay_of_a_band_limited_record():
    """Without the exact delayed signal the sensor delays in the frequency domain: exact for a record that
    starts and ends at rest (the table's sweep with its C2 fades: 3.4e-6 of the peak), and a whole number
    of samples is a shift."""
    fs, d = 1000.0, 0.37e-3
    t = np.arange(int((SWEEP.duration_s + SETTLE) * fs) + 1) / fs
    x = SWEEP.kinematics(t)[2]
    y = Accelerometer(0.0, delay_s=d).measure(x, np.random.default_rng(0), fs)
    assert np.max(np.abs(y - SWEEP.kinematics(t - d)[2])) < 1e-5 * np.max(np.abs(x))  # measured 3.4e-6
    noise = np.random.default_rng(0).standard_normal(x.size)  # any signal, up to its Nyquist bin
    np.testing.assert_allclose(delay(noise, 5.0)[5:], noise[:-5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(delay(noise, 5.0)[:5], 0.0, rtol=0, atol=1e-12)


# -- the rig's parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize("kw, match", [
    ({"effects": {"end_stop": 1.0}}, "end_stop_lower_mm"),
    ({"effects": {"hysteresis": 1.0}}, "hysteresis_alpha"),
    ({"effects": {"channel_delay": 1.0}}, "delay_s"),
    ({"hysteresis_alpha": 0.1, "hysteresis_beta": 1.0, "hysteresis_n": 4}, "hysteresis_n"),
    ({"hysteresis_alpha": 0.1}, "beta \\+ hysteresis_gamma"),
    ({"absorber_mass_kg": 0.01}, "absorber_stiffness"),
    ({"end_stop_upper_mm": -1.0}, "end_stop_upper_mm"),
    ({"stiffness_drift": -1.0}, "stiffness_drift"),
    ({"asymmetric_side": 0}, "asymmetric_side"),
])
def test_unphysical_rig_refused_by_name(kw, match):
    with pytest.raises(ValueError, match=match):
        RigParameters(**kw)
    with pytest.raises(ValueError, match="delay_s must be >= 0"):
        Accelerometer(delay_s=-1e-3)


def test_plc_refuses_physics_it_cannot_step():
    with pytest.raises(ValueError, match="run_sweep"):
        RigPLC(PLCConfig(rig=dataclasses.replace(BASE, stiffness_drift=0.1)))
    RigPLC(PLCConfig(rig=dataclasses.replace(BASE, effects={"cubic_damping": 1.0})))  # a plain term runs


def test_contact_is_counted_per_side():
    """Contact (truth, PLC counters) is judged per side: an upper-only stop never counts q < -travel."""
    q = np.array([-0.02, -0.004, 0.0, 0.004, 0.02])
    one = RigParameters(end_stop_upper_mm=3.0, end_stop_lower_mm=math.inf)
    assert one.in_contact(q).tolist() == [False, False, False, True, True]
    assert RigParameters(end_stop_travel_mm=3.0).in_contact(q).tolist() == [True, True, False, True, True]
    assert not RigParameters(end_stop_travel_mm=None).in_contact(q).any()
    assert RigParameters(end_stop_lower_mm=5.0).travels_mm == (5.0, 17.5)
