"""The simulated PLC: one logic for every protocol front end (Modbus TCP, ADS); its states, commands,
faults and limits are the protocol's (protocol/plc.py).

It holds the sweep setpoints, obeys commands, checks the safety limits before a sweep starts, keeps a
heartbeat watchdog, and moves the table. `advance(dt_s)` runs the rig physics for dt_s of rig time and
returns the accelerometer samples it produced, so a front end or a stream server never touches physics.

States: IDLE -> RUNNING -> DONE; FAULT (refused start, watchdog, injected fault, a rig response that
cannot be simulated) and ESTOP need RESET. Stopping (command, watchdog, e-stop) ramps the table to rest
with a C2 fade of `ramp_s` (e-stop, drive and simulation faults: the shorter `estop_ramp_s`), so the
motion stays physical and the accelerometers see no step. The rig runs with its end stops
(RigParameters.model(end_stops=True)); every sample it emits is finite.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from identify.simulation.simulate import simulate
from protocol.plc import RIG_STATE_BOUND, SETPOINT_NAMES, Command, Fault, Limits, State
from protocol.sweep import SineSweep, smoothstep

from .physics import mass_acceleration
from .rig import RigParameters
from .sensors import Accelerometer


@dataclass
class PLCConfig:
    rig: RigParameters = field(default_factory=RigParameters.paper_table1)
    limits: Limits = field(default_factory=Limits)
    fs_hz: float = 2048.0
    table_sensor: Accelerometer = field(default_factory=lambda: Accelerometer(noise_fraction=0, noise_ms2=0.02))
    mass_sensor: Accelerometer = field(default_factory=lambda: Accelerometer(noise_fraction=0, noise_ms2=0.02))
    ramp_s: float = 0.2
    estop_ramp_s: float = 0.05
    substeps: int = 8
    # the sensors' noise seed; None: a fresh one at every power-on (RigPLC.seed says which), so sweeps after
    # two fresh starts are independent draws (with 0, every `shakeid serve` repeated one noise stream)
    seed: int | None = None


class RigPLC:
    """Setpoints (f_start_hz, f_end_hz, duration_s, amplitude_mm), commands, status, and the rig."""

    def __init__(self, config: PLCConfig | None = None):
        self.config = config or PLCConfig()
        self.model = self.config.rig.model()                 # the smooth model identification sees
        self.physics = self.config.rig.model(end_stops=True)  # what runs: with the end stops
        if self.physics.states != ("q1", "q2") or self.physics.inputs != ("zdd",):
            raise ValueError(f"the rig PLC steps (q1, q2) driven by zdd; this rig needs states {self.physics.states} "
                             f"and inputs {self.physics.inputs} (drift, hysteresis, absorber, free play, two "
                             "different end-stop travels): simulate it with sim.synth.run_sweep")
        self.contact_samples = 0     # samples in contact with an end stop since power-on
        seed = self.config.seed
        self.seed = int(np.random.SeedSequence().entropy if seed is None else seed)  # reproduces this power-on
        self.rng = np.random.default_rng(self.seed)
        self.setpoints = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 60.0, "amplitude_mm": 1.0}
        self.state = State.IDLE
        self.fault = Fault.NONE
        self.fault_message = ""
        self.time_s = 0.0            # rig clock, s since power-on
        self.sample_index = 0        # samples produced since power-on
        self.sweep: SineSweep | None = None
        self.sweep_t0 = 0.0
        self.stop_t: float | None = None  # rig time the ramp-down began
        self.stop_ramp = self.config.ramp_s
        self.heartbeat = 0
        self.heartbeat_seen_t = 0.0
        self.x = np.zeros(2)         # rig state (q1, q2) at the last emitted sample

    # -- interface of every front end --------------------------------------------------------------
    def set_setpoint(self, name: str, value: float) -> None:
        if name not in SETPOINT_NAMES:
            raise KeyError(name)
        self.setpoints[name] = float(value)

    def set_heartbeat(self, value: int) -> None:
        if value != self.heartbeat:
            self.heartbeat = value
            self.heartbeat_seen_t = self.time_s

    def command(self, cmd: int) -> None:
        cmd = Command(cmd)
        if cmd == Command.ESTOP:
            self._begin_stop(self.config.estop_ramp_s)
            self.state = State.ESTOP
        elif cmd == Command.STOP and self.state == State.RUNNING:
            self._begin_stop(self.config.ramp_s)
            self.state = State.DONE
        elif cmd == Command.RESET and self.state in (State.FAULT, State.ESTOP, State.DONE):
            if self._table_at_rest():
                if self.fault == Fault.SIMULATION or not np.all(np.isfinite(self.x)):
                    self.x = np.zeros(2)
                self.state, self.fault, self.fault_message = State.IDLE, Fault.NONE, ""
        elif cmd == Command.START:
            self._start()

    def status(self) -> dict:
        t = self._sweep_time()
        running = self.state == State.RUNNING and self.sweep is not None
        return {"state": int(self.state), "state_name": self.state.name.lower(), "fault_code": int(self.fault),
                "fault": self.fault_message, "elapsed_s": t if running else 0.0,
                "frequency_hz": float(self.sweep.frequency_hz(t)) if running else 0.0,
                "position_mm": float(self._table(np.array([self.time_s]))[0][0] * 1e3),
                "heartbeat": self.heartbeat, "time_s": self.time_s}

    def inject_fault(self) -> None:
        """A drive fault mid-sweep (tests of the DAQ's abort path)."""
        if self.state == State.RUNNING:
            self._begin_stop(self.config.estop_ramp_s)
        self.state, self.fault, self.fault_message = State.FAULT, Fault.INJECTED, "drive fault (injected)"

    # -- physics ------------------------------------------------------------------------------------
    def advance(self, dt_s: float) -> tuple[int, np.ndarray]:
        """Run dt_s of rig time: returns (index of the first new sample, samples (n, 2) in m/s^2:
        table, mass). The watchdog and the end of the sweep are checked on the way."""
        fs = self.config.fs_hz
        n_end = int(np.floor((self.time_s + dt_s) * fs))
        first = self.sample_index
        n = n_end - first
        if n <= 0:
            self.time_s += dt_s
            return first, np.empty((0, 2))
        if self.state == State.RUNNING:
            silent = self.time_s - self.heartbeat_seen_t
            if silent > self.config.limits.watchdog_s:
                self._begin_stop(self.config.ramp_s)
                self.state, self.fault = State.FAULT, Fault.WATCHDOG
                self.fault_message = f"heartbeat silent for {silent:.2f} s (watchdog {self.config.limits.watchdog_s:g} s)"
        zdd, mass = self._physics(first, n)
        samples = np.column_stack([self.config.table_sensor.measure(zdd, self.rng),
                                   self.config.mass_sensor.measure(mass, self.rng)])
        self.sample_index = n_end
        self.time_s += dt_s
        if self.state == State.RUNNING and self._sweep_time() >= self.sweep.duration_s:
            self.state = State.DONE
        return first, samples

    def _physics(self, first: int, n: int, retry: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Table and mass acceleration (m/s^2) of samples first .. first + n - 1 (sample k at rig time
        k / fs), from self.x, the state at sample first - 1. Where the response leaves the simulable
        range: fault SIMULATION, the table stops, the mass restarts from rest; if it leaves again at
        once, the mass moves with the table for the rest of the call (finite, and the fault says why)."""
        fs, S = self.config.fs_hz, self.config.substeps
        t_fine = (first - 1 + np.arange(n * 2 * S + 1) / (2 * S)) / fs
        zdd_fine = self._table(t_fine)[2]
        zdd = zdd_fine[2 * S::2 * S]
        res = simulate(self.physics, 1 / fs, self.x, inputs_fine=zdd_fine[:, None], substeps=S, n_samples=n + 1,
                       bound=RIG_STATE_BOUND)
        states = res.states[1:res.n_valid]
        mass = mass_acceleration(self.physics, states, zdd[:len(states), None], 1 / fs)
        finite = np.isfinite(mass)
        good = len(states) if finite.all() else int(np.argmin(finite))
        states, mass = states[:good], mass[:good]
        if good:
            self.x = states[-1].copy()
            self.contact_samples += int(np.count_nonzero(self.config.rig.in_contact(states[:, 1])))  # per side
        if good == n:
            return zdd, mass
        self._simulation_fault((first + good) / fs)
        self.x = np.zeros(2)
        if retry:
            rest_zdd, rest_mass = self._physics(first + good, n - good, retry=False)
        else:  # the mass held at rest relative to the table: it reads the table's acceleration
            rest_zdd = rest_mass = self._table((first + good + np.arange(n - good)) / fs)[2]
        return np.concatenate([zdd[:good], rest_zdd]), np.concatenate([mass, rest_mass])

    def _simulation_fault(self, t: float) -> None:
        if self.sweep is not None and self.stop_t is None:
            self.stop_t, self.stop_ramp = t, self.config.estop_ramp_s
        if self.fault != Fault.SIMULATION:
            self.state, self.fault = State.FAULT, Fault.SIMULATION
            self.fault_message = (f"rig response left the simulable range at t = {t:.4f} s (|q| or |q'| above "
                                  f"{RIG_STATE_BOUND:g} or not finite): table stopped, mass state reset to rest")

    # -- internals ----------------------------------------------------------------------------------
    def _start(self) -> None:
        if self.state not in (State.IDLE, State.DONE) or not self._table_at_rest():
            self.state, self.fault = State.FAULT, Fault.NOT_READY
            self.fault_message = "start refused: the rig is not idle"
            return
        try:
            sweep = SineSweep(**self.setpoints)
        except ValueError as exc:
            self.state, self.fault, self.fault_message = State.FAULT, Fault.DURATION, f"start refused: {exc}"
            return
        fault, message = self.config.limits.check(sweep)
        if fault != Fault.NONE:
            self.state, self.fault, self.fault_message = State.FAULT, fault, "start refused: " + message
            return
        self.sweep, self.sweep_t0, self.stop_t = sweep, self.time_s, None
        self.heartbeat_seen_t = self.time_s
        self.state = State.RUNNING

    def _begin_stop(self, ramp_s: float) -> None:
        if self.sweep is not None and self.stop_t is None:
            self.stop_t, self.stop_ramp = self.time_s, ramp_s

    def _sweep_time(self) -> float:
        return self.time_s - self.sweep_t0 if self.sweep is not None else 0.0

    def _table_at_rest(self) -> bool:
        if self.sweep is None:
            return True
        end = self.sweep_t0 + self.sweep.duration_s
        if self.stop_t is not None:
            end = min(end, self.stop_t + self.stop_ramp)
        return self.time_s >= end

    def _table(self, t: np.ndarray):
        """Table displacement, velocity, acceleration at rig times t: the sweep times the stop ramp."""
        if self.sweep is None:
            z = np.zeros_like(t)
            return z, z, z
        z, zd, zdd = self.sweep.kinematics(t - self.sweep_t0)
        if self.stop_t is None:
            return z, zd, zdd
        r = self.stop_ramp
        w, dw, ddw = smoothstep((t - self.stop_t) / r)
        env, denv, ddenv = 1 - w, -dw / r, -ddw / r**2
        return env * z, denv * z + env * zd, ddenv * z + 2 * denv * zd + env * zdd
