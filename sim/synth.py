"""Synthetic recordings of the rig: the ground truth every identification test is checked against."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from identify.data.recording import Recording
from identify.simulation.simulate import simulate
from protocol.sweep import SineSweep

from .physics import mass_acceleration
from .rig import RigParameters
from .sensors import Accelerometer

#: The paper's sample time, 0.488 ms.
PAPER_FS_HZ = 2048.0
#: RK4 steps per sample for ground truth: h = 30 us at 2048 Hz, error < 1e-7 of the response against
#: solve_ivp (tests/sim/test_rig.py), far below any sensor noise.
TRUTH_SUBSTEPS = 16
#: With non-smooth terms (sign, |.|) RK4 drops to first order at each switch: 4x finer steps keep the
#: truth's error near 3e-5 of the response (self-convergence test), still 100x below 0.5 % noise.
TRUTH_SUBSTEPS_NONSMOOTH = 64
#: Features of the end stops: zero until contact, so a run that never touches the stops is the smooth
#: model's, step for step; the kernel cuts its steps where contact begins and ends, so with contact
#: 16 substeps stay fourth order (a 20 s sweep with 260 contact samples: 9e-7 against 256 substeps).
_END_STOP_FEATURES = ("stop(", "contact(")
_CHUNK = 1 << 20


@dataclass
class SyntheticRun:
    recording: Recording
    rig: RigParameters
    sweep: SineSweep
    states: np.ndarray  # true (q1, q2) at the samples
    table_acc_true: np.ndarray
    mass_acc_true: np.ndarray
    truth: dict = field(default_factory=dict)
    internal: dict = field(default_factory=dict)  # further true states at the samples: z, qa1, qa2 (sim/physics.py)


def run_sweep(rig: RigParameters | None = None, sweep: SineSweep | None = None, fs_hz: float = PAPER_FS_HZ,
              settle_s: float = 2.0, table_sensor: Accelerometer | None = None,
              mass_sensor: Accelerometer | None = None, seed: int | None = 0,
              substeps: int | None = None) -> SyntheticRun:
    """Simulate one sweep on the rig (plus `settle_s` at rest) and measure it with two accelerometers.

    The truth says how many samples were in contact with the end stops (`contact_samples`); its
    `model` is the smooth rig model when there was none, else it includes the end-stop terms and
    `travel` (so `SparseModel.from_dict(truth)` is the model that made the data either way)."""
    rig = rig or RigParameters.paper_table1()
    sweep = sweep or SineSweep()
    model = rig.model(end_stops=True)
    if substeps is None:
        substeps = TRUTH_SUBSTEPS if all(_smooth(model, t) for t in model.terms) else TRUTH_SUBSTEPS_NONSMOOTH
    n = int(round((sweep.duration_s + settle_s) * fs_hz)) + 1
    res, u = _integrate(rig, model, sweep, fs_hz, n, substeps)
    contact_samples = int(np.count_nonzero(rig.in_contact(res.states[:, 1]))) if rig.end_stops else 0
    if contact_samples == 0:
        model = rig.model()
    zdd = u[:, 0]
    mass_acc = mass_acceleration(model, res.states, u, 1.0 / fs_hz)
    rng = np.random.default_rng(seed)
    table_sensor = table_sensor or Accelerometer()
    mass_sensor = mass_sensor or Accelerometer()
    table_late = mass_late = None  # the true accelerations at t - delay, for delayed sensors
    if table_sensor.delay_s:
        table_late = sweep.kinematics(np.arange(n) / fs_hz - table_sensor.delay_s)[2]
    if mass_sensor.delay_s:  # the rig is at rest before the sweep: the delayed input gives the delayed motion
        res_late, u_late = _integrate(rig, rig.model(end_stops=True), sweep, fs_hz, n, substeps, mass_sensor.delay_s)
        mass_late = mass_acceleration(model, res_late.states, u_late, 1.0 / fs_hz)
    rec = Recording(table_sensor.measure(zdd, rng, fs_hz, table_late), mass_sensor.measure(mass_acc, rng, fs_hz, mass_late),
                    fs_hz, "base", source="simulated rig")
    truth = {**{k: v for k, v in model.to_dict().items() if k in ("model", "travel")}, "rig": rig.to_dict(),
             "end_stops": rig.end_stop_summary(), "contact_samples": contact_samples,
             "sweep": {"f_start_hz": sweep.f_start_hz, "f_end_hz": sweep.f_end_hz, "duration_s": sweep.duration_s,
                       "amplitude_mm": sweep.amplitude_mm, "fade_s": sweep.fade},
             "fs_hz": fs_hz, "settle_s": settle_s, "max_abs_q_m": float(np.max(np.abs(res.states[:, 1])))}
    faults = {name: s.faults() for name, s in (("table_sensor", table_sensor), ("mass_sensor", mass_sensor)) if s.faults()}
    if faults:
        truth["sensor_faults"] = faults
    rec.metadata["truth"] = truth
    internal = {s: res.states[:, i] for i, s in enumerate(model.states) if s in ("z", "qa1", "qa2")}
    return SyntheticRun(rec, rig, sweep, res.states[:, :2], zdd, mass_acc, truth, internal)


def noise_free_sweep(sweep: SineSweep | None = None, fs_hz: float = PAPER_FS_HZ) -> SyntheticRun:
    """One sweep of the Table 1 rig measured by noise-free sensors (default: the acceptance sweep, 1-20 Hz
    over 60 s at 1.3 mm; at rest at both ends): the motion daq.long_record repeats with fresh noise."""
    quiet = Accelerometer(noise_fraction=0.0)
    return run_sweep(sweep=sweep or SineSweep(1.0, 20.0, 60.0, 1.3), fs_hz=fs_hz, table_sensor=quiet,
                     mass_sensor=quiet, seed=0)


def noise_input_recording(seed: int, rig: RigParameters | None = None, duration_s: float = 60.0,
                          fs_hz: float = 1024.0, band_hz: tuple = (2.0, 20.0), rms_scale: float = 5.0,
                          noise: float = 0.005) -> Recording:
    """A recording of the rig (default: Table 1) under random table acceleration: white noise through a
    4th-order Butterworth band-pass over band_hz, forward and back (zero phase), times rms_scale (m/s^2 per
    unit of filtered noise), with sensor noise of `noise` x each channel's std. Not a sweep: what a lab's
    random-excitation test records (tests/identify/test_band.py, test_uncertain_terms.py, the FRF job)."""
    from scipy.signal import butter, sosfiltfilt

    model = (rig or RigParameters.paper_table1()).model()
    rng = np.random.default_rng(seed)
    sos = butter(4, list(band_hz), "bandpass", fs=fs_hz, output="sos")
    zdd = sosfiltfilt(sos, rng.standard_normal(int(duration_s * fs_hz))) * rms_scale
    run = simulate(model, 1 / fs_hz, [0.0, 0.0], zdd[:, None], state_scale=np.array([0.1, 0.01]))
    mass = mass_acceleration(model, run.states, zdd[:, None], 1.0 / fs_hz)
    return Recording(zdd + noise * np.std(zdd) * rng.standard_normal(zdd.size),
                     mass + noise * np.std(mass) * rng.standard_normal(zdd.size), fs_hz)


def _integrate(rig, model, sweep, fs_hz, n, substeps, late_s: float = 0.0):
    """The rig's states at n samples and the inputs there, driven by the sweep delayed by `late_s` s."""
    dt = 1.0 / fs_hz
    n_fine, h2 = (n - 1) * 2 * substeps + 1, dt / (2 * substeps)
    u_fine = np.empty((n_fine, len(model.inputs)))
    for a in range(0, n_fine, _CHUNK):  # in chunks: the kinematics' temporaries of a long sweep add up to GBs
        b = min(a + _CHUNK, n_fine)
        t = np.arange(a, b) * h2
        u_fine[a:b, 0] = sweep.kinematics(t - late_s if late_s else t)[2]
    if "drift" in model.inputs:  # stiffness drift: t / T over the record
        u_fine[:, model.inputs.index("drift")] = (np.arange(n_fine) - late_s / h2) / (n_fine - 1)
    res = simulate(model, dt, rig.initial_state(model), inputs_fine=u_fine, substeps=substeps, n_samples=n,
                   bound=10.0)
    if res.diverged:
        raise ValueError(f"rig response diverged at t = {res.n_valid * dt:.3f} s: reduce the amplitude")
    return res, u_fine[:: 2 * substeps]




def _smooth(model, term) -> bool:
    """A term RK4 at TRUTH_SUBSTEPS integrates to fourth order: plain states and inputs, or anything
    times an end-stop feature (the kernel cuts its steps at contact, and stop() vanishes near q = 0
    where a sign() factor with it jumps)."""
    names = [f for f, _ in term.factors]
    return (any(f.startswith(_END_STOP_FEATURES) for f in names)
            or all(f in model.states or f in model.inputs for f in names))
