"""The simulated rig at its limits: end stops on the rail, a PLC that never emits a non-finite sample, and
accelerometers that clip at their range and recover. Known truth: the same physics simulated in one piece."""
import dataclasses

import numpy as np
import pytest

from identify.model import SparseModel
from identify.simulation.simulate import simulate
from protocol import frames
from protocol.plc import Command, Fault, State
from sim.plc import PLCConfig, RigPLC
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.server import SENSITIVITY
from protocol.sweep import SineSweep
from sim.synth import run_sweep

FS = 2048.0
LONG = SineSweep(1.0, 20.0, 300.0, 1.3)   # legal (5 mm, 0.5 m/s, 40 m/s^2 limits), reaches the stops
QUIET = dict(table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0))


def no_stops(rig: RigParameters) -> RigParameters:
    return dataclasses.replace(rig, end_stop_travel_mm=None)


def test_default_end_stops_are_physical_and_resolved():
    rig = RigParameters.paper_table1()
    stops = rig.end_stop_summary()
    assert 100 <= stops["contact_frequency_hz"] <= 300 and 0.2 <= stops["damping_ratio"] <= 0.3
    assert 2 * np.pi * stops["contact_frequency_hz"] / (FS * PLCConfig().substeps) < 0.1  # omega_c h of the PLC
    # contact begins before the Table 1 damping c - 1.162e4 m q^2 turns negative
    c_over_k = rig.damping_ns_per_m / -rig.effects["displacement_dependent_damping"]
    assert stops["travel_mm"] < 1e3 * np.sqrt(c_over_k)
    assert RigParameters(end_stop_travel_mm=float("inf")).end_stop_summary() is None
    assert no_stops(rig).model(end_stops=True).travel == {}
    with pytest.raises(ValueError, match="end_stop_travel_mm"):
        RigParameters(end_stop_travel_mm=-1.0)


@pytest.mark.parametrize("v", [0.3, 0.6, 1.0])
def test_the_mass_bounces_off_the_stop(v):
    """Thrown into the bumper at v, the rig's mass penetrates (v/w_c) exp(-zeta acos(zeta)/sqrt(1-zeta^2))
    (0.72 v/w_c) less at most the bumper's static give to the springs' push at the travel (a/w_c^2 = 19
    um), and comes back slower than it came, but not slower than the bumper alone returns it."""
    rig = RigParameters.paper_table1()
    s = rig.end_stop_summary()
    d, w, z = s["travel_mm"] * 1e-3, 2 * np.pi * s["contact_frequency_hz"], s["damping_ratio"]
    res = simulate(rig.model(end_stops=True), 1 / (8 * FS), [v, d], np.zeros(8 * 64), substeps=1)
    q1, q2 = res.states.T
    free = v / w * np.exp(-z * np.arccos(z) / np.sqrt(1 - z**2))
    push = -rig.model().rhs(np.array([[0.0, d]]), np.zeros((1, 1)))[0, 0]  # m/s^2, springs at the travel
    assert free - push / w**2 < q2.max() - d < free
    # the springs are conservative, but shorten the contact: less is dissipated than by the bumper alone
    back = -q1[np.argmax(q2 < d)]  # the first step out of contact
    assert v * np.exp(-z * np.pi / np.sqrt(1 - z**2)) < back < v


def test_standard_sweep_never_touches_the_stops():
    """The paper's sweep reaches 17.10 mm, under the 17.5 mm travel: no contact, the truth is the smooth
    model, and the response is the rig without stops, sample for sample."""
    run = run_sweep(**QUIET)
    assert run.truth["contact_samples"] == 0 and 0.016 < run.truth["max_abs_q_m"] < 0.0175
    assert run.truth["model"] == RigParameters.paper_table1().model().to_dict()["model"]
    assert "travel" not in run.truth and run.truth["end_stops"]["travel_mm"] == 17.5
    free = run_sweep(no_stops(RigParameters.paper_table1()), **QUIET)
    np.testing.assert_array_equal(run.states, free.states)


@pytest.mark.slow
def test_long_slow_sweep_completes_against_the_stops():
    """The 300 s sweep that used to diverge: it completes, touches the stops, and its truth is the model with
    the stops (loadable as it is)."""
    run = run_sweep(sweep=LONG, settle_s=0.5)
    truth = run.truth
    assert truth["contact_samples"] > 100
    assert 0.0175 < truth["max_abs_q_m"] < 0.0185
    model = SparseModel.from_dict(truth)
    assert model.travel == {"q2": 0.0175} and model.coefficient("q1_dot", "stop(q2)") == pytest.approx(-7.7e5 / 0.49)
    assert np.all(np.isfinite(run.recording.output)) and np.all(np.isfinite(run.states))


def _sweep_plc(plc: RigPLC, sweep: SineSweep, step_s: float = 1.0, until=None) -> np.ndarray:
    """Start `sweep` on the PLC and advance it in big steps with a live heartbeat; samples (n, 2)."""
    plc.setpoints.update(f_start_hz=sweep.f_start_hz, f_end_hz=sweep.f_end_hz, duration_s=sweep.duration_s,
                         amplitude_mm=sweep.amplitude_mm)
    plc.command(Command.START)
    assert plc.state == State.RUNNING, plc.fault_message
    out, end = [], plc.time_s + sweep.duration_s + 1.0
    while plc.time_s < end and (until is None or not until(plc)):
        plc.set_heartbeat(plc.heartbeat + 1)
        out.append(plc.advance(step_s)[1])
    return np.vstack(out)


def _reference(rig: RigParameters, sweep: SineSweep, n: int, substeps: int = 8) -> np.ndarray:
    """Mass acceleration of the sweep started at rig time 0, simulated in one piece with the PLC's steps."""
    t_fine = (np.arange(n * 2 * substeps + 1) / (2 * substeps) - 1) / FS
    zdd_fine = sweep.kinematics(t_fine)[2]
    model = rig.model(end_stops=True)
    res = simulate(model, 1 / FS, [0.0, 0.0], inputs_fine=zdd_fine[:, None], substeps=substeps, n_samples=n + 1)
    zdd = zdd_fine[2 * substeps::2 * substeps]
    return model.rhs(res.states[1:], zdd[:, None])[:, 0] + zdd


@pytest.mark.slow
def test_plc_long_sweep_stays_finite_hits_the_stops_and_the_sensor_recovers():
    """The 300 s sweep on the PLC in 1 s steps: never a non-finite sample, the stops are hit, the mass
    accelerometer saturates at contact and follows the motion again right after (no stuck zeros)."""
    plc = RigPLC(PLCConfig(table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0)))
    samples = _sweep_plc(plc, LONG)
    assert plc.state == State.DONE and plc.fault == Fault.NONE
    assert np.all(np.isfinite(samples)) and np.all(np.isfinite(plc.x))
    assert plc.contact_samples > 100
    truth = _reference(plc.config.rig, LONG, samples.shape[0])
    np.testing.assert_allclose(samples[:, 1], truth, rtol=0, atol=1e-6 * np.abs(truth).max())
    # on the stream (+-50 m/s^2 full scale): contact saturates frames, flagged; every other frame reads the
    # motion to an LSB, including the ones right after each saturation
    n = samples.shape[0] // 64 * 64
    blocks = samples[:n].reshape(-1, 64, 2)
    flags = np.array([frames.to_counts(b, SENSITIVITY)[1] for b in blocks])
    counts = np.stack([frames.to_counts(b, SENSITIVITY)[0] for b in blocks]).reshape(-1, 2)
    saturated = np.flatnonzero(flags & frames.FLAG_SATURATED)
    assert 10 < saturated.size < 0.05 * len(blocks)
    clear = np.abs(truth[:n]) * SENSITIVITY < 32767
    assert np.all(np.abs(counts[clear, 1] / SENSITIVITY - truth[:n][clear]) <= 0.51 / SENSITIVITY)
    assert np.all(np.abs(counts[~clear, 1]) == 32767)
    after = blocks[saturated[-1] + 1:, :, 1]
    assert after.shape[0] > 100 and np.all(np.std(after, axis=1) > 0)


def test_plc_diverging_rig_faults_with_finite_samples_and_reset_recovers():
    """The Table 1 rig without end stops on the 300 s sweep: its response leaves the simulable range; the
    PLC faults (code 9, with the time), stops the table, keeps every sample finite; RESET brings back a
    rig whose next sweep records exactly what a fresh rig records."""
    rig = no_stops(RigParameters.paper_table1())
    plc = RigPLC(PLCConfig(rig=rig, table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0)))
    samples = _sweep_plc(plc, LONG, until=lambda p: p.fault != Fault.NONE)
    assert (plc.state, plc.fault) == (State.FAULT, Fault.SIMULATION)
    assert "left the simulable range at t = " in plc.fault_message and plc.status()["fault_code"] == 9
    t_fault = plc.stop_t
    assert 60 < t_fault < 300
    for _ in range(3):
        samples = np.vstack([samples, plc.advance(1.0)[1]])
    assert np.all(np.isfinite(samples)) and np.all(np.isfinite(plc.x))
    k = int(round(t_fault * FS))
    after = samples[k:k + int(0.5 * FS), 1]  # the mass restarts from rest while the table ramps to rest
    assert np.abs(after).max() < 50 and np.std(after) > 0.01
    assert plc.status()["position_mm"] == 0.0 and plc._table_at_rest()
    plc.command(Command.RESET)
    assert plc.state == State.IDLE and plc.fault == Fault.NONE and np.all(plc.x == 0.0)
    short = SineSweep(2.0, 10.0, 20.0, 1.0)
    assert plc.time_s == int(plc.time_s)  # whole seconds: the next sweep starts on the sample grid
    again = _sweep_plc(plc, short)
    assert plc.state == State.DONE and plc.fault == Fault.NONE
    fresh = _sweep_plc(RigPLC(PLCConfig(rig=rig, table_sensor=Accelerometer(0), mass_sensor=Accelerometer(0))),
                       short)
    assert np.std(again[:, 1]) > 1.0
    np.testing.assert_allclose(again[:, 1], fresh[:, 1], rtol=0, atol=1e-9 * np.abs(fresh[:, 1]).max())


def test_plc_rig_that_cannot_be_simulated_at_all_stays_finite():
    """Negative damping far beyond the bumpers' (-500 N s/m): the response leaves the range at once and again
    from rest; the mass is then taken to move with the table, so the samples stay finite and say so: the
    mass reads the table's acceleration while it ramps down, then both read rest."""
    plc = RigPLC(PLCConfig(rig=RigParameters(damping_ns_per_m=-500.0), table_sensor=Accelerometer(0),
                           mass_sensor=Accelerometer(0)))
    samples = _sweep_plc(plc, SineSweep(2.0, 10.0, 20.0, 1.0), step_s=0.25, until=lambda p: p.time_s >= 2.0)
    assert (plc.state, plc.fault) == (State.FAULT, Fault.SIMULATION)
    assert np.all(np.isfinite(samples))
    assert np.std(samples[:, 1]) > 0 and np.all(samples[-int(FS):] == 0.0)  # at rest, noise-free sensors
    plc.command(Command.RESET)
    assert plc.state == State.IDLE and plc.fault == Fault.NONE
