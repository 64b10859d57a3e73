"""The PLC's side of the protocol: states, commands, fault codes, safety limits, setpoint and status names.

States: IDLE -> RUNNING -> DONE; FAULT and ESTOP need RESET (docs/rig-protocols.md). The limits are checked
by the PLC on START and by the DAQ before it writes a sweep (`Limits.check`, one rule for both).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, fields

import numpy as np

from .sweep import SineSweep


class State(enum.IntEnum):
    IDLE = 0
    RUNNING = 1
    DONE = 2
    FAULT = 3
    ESTOP = 4


class Command(enum.IntEnum):
    NONE = 0
    START = 1
    STOP = 2
    RESET = 3
    ESTOP = 4


class Fault(enum.IntEnum):
    NONE = 0
    STROKE = 1        # amplitude above the stroke limit
    VELOCITY = 2      # peak table velocity above the limit
    ACCELERATION = 3  # peak table acceleration above the limit
    FREQUENCY = 4     # frequency outside [f_min, f_max]
    DURATION = 5      # duration not positive or above the limit
    WATCHDOG = 6      # heartbeat stopped changing during a sweep
    INJECTED = 7      # drive fault injected for tests
    NOT_READY = 8     # START while not IDLE/DONE
    SIMULATION = 9    # simulated rig only: its response left the simulable range (RIG_STATE_BOUND, or not finite)


#: the shortest sweep, s: a sweep is at least one period at the lowest frequency the rig runs at (Limits.f_min_hz
#: 0.2 Hz: 5 s would refuse short test sweeps; 1 s is 100 PLC cycles). Shorter durations were accepted and
#: then read as 0 by the PLC's float32 setpoint (1e-300 s), which faulted the rig and needed a reset.
MIN_SWEEP_DURATION_S = 1.0

#: Bound on the rig state (m, m/s): far beyond any physical motion of the mass between its end stops. The
#: simulated rig faults (Fault.SIMULATION) when its response leaves it; the DAQ's preflight says a model
#: that leaves it ran away (daq.preflight.RUNAWAY_BOUND).
RIG_STATE_BOUND = 10.0

#: The sweep setpoints the PLC holds, in register / symbol order.
SETPOINT_NAMES = ("f_start_hz", "f_end_hz", "duration_s", "amplitude_mm")


@dataclass
class PLCStatus:
    """What the PLC reports: state (State), fault code (Fault), sweep time, sweep frequency, table position."""

    state: int
    fault_code: int
    elapsed_s: float
    frequency_hz: float
    position_mm: float


@dataclass
class Limits:
    """Safety limits of the table, checked before a sweep starts (and by the DAQ before it writes)."""

    max_stroke_mm: float = 5.0
    max_velocity_ms: float = 0.5
    max_acceleration_ms2: float = 40.0
    f_min_hz: float = 0.2
    f_max_hz: float = 50.0
    max_duration_s: float = 600.0
    # heartbeat timeout; + the 0.2 s ramp + one 10 ms PLC cycle keeps the table at rest within 0.5 s.
    # 4x the largest interval between 50 ms heartbeats measured under load with the rig controller
    # real-time (63 ms, docs/service.md); without real-time rights use 0.5 s (examples/sim-rig.toml)
    watchdog_s: float = 0.25

    def check(self, sweep: SineSweep) -> tuple[Fault, str]:
        """(Fault.NONE, "") if the sweep is safe, else the first violated limit and a message naming it."""
        a = sweep.amplitude_mm * 1e-3
        f_top = max(sweep.f_start_hz, sweep.f_end_hz)
        f_low = min(sweep.f_start_hz, sweep.f_end_hz)
        if not (self.f_min_hz <= f_low and f_top <= self.f_max_hz):
            return Fault.FREQUENCY, (f"frequency {f_low:g}-{f_top:g} Hz outside the limit "
                                     f"{self.f_min_hz:g}-{self.f_max_hz:g} Hz")
        if not MIN_SWEEP_DURATION_S <= sweep.duration_s <= self.max_duration_s:
            return Fault.DURATION, (f"duration {sweep.duration_s:g} s outside the limit {MIN_SWEEP_DURATION_S:g}-"
                                    f"{self.max_duration_s:g} s")
        if sweep.amplitude_mm > self.max_stroke_mm:
            return Fault.STROKE, f"amplitude {sweep.amplitude_mm:g} mm above the stroke limit {self.max_stroke_mm:g} mm"
        v = a * 2 * np.pi * f_top
        if v > self.max_velocity_ms:
            return Fault.VELOCITY, f"peak velocity {v:.3g} m/s above the limit {self.max_velocity_ms:g} m/s"
        acc = a * (2 * np.pi * f_top) ** 2
        if acc > self.max_acceleration_ms2:
            return Fault.ACCELERATION, (f"peak acceleration {acc:.3g} m/s^2 above the limit "
                                        f"{self.max_acceleration_ms2:g} m/s^2")
        return Fault.NONE, ""


#: The limits the PLC reports, in register / symbol order: the fields of Limits.
LIMIT_NAMES = tuple(f.name for f in fields(Limits))
#: The status fields, in register / symbol order: the fields of PLCStatus.
STATUS_NAMES = tuple(f.name for f in fields(PLCStatus))
