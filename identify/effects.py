"""Catalog of what a real rig (or its recording) has beyond the textbook Duffing oscillator.

Physics: a force on the mass, F = coefficient * term(q1, q2), with q1 the relative velocity (m/s) and
q2 the relative displacement (m). Effects with plain library terms (`plain`) can be simulated by the rig
simulator from `RigParameters(effects=...)` and offered by the identification library; the others need a
parameter the library cannot hold as a coefficient, which the discrepancy workflow fits itself:
- end_stop: contact beyond a travel d (m), found by a search over d; one or two sided, as the
  pair stop(q2) (two sided, symmetric) and sign(q2)*stop(q2) (the asymmetry between the sides);
- stiffness_drift: k(t) = k (1 + r t/T), the term q2*tau with tau = t/T - 1/2 a known input
  (T the record's length);
- hysteresis: Bouc-Wen with an internal state z (m): F = -alpha m z,
  z' = q1 - beta |q1| z - gamma q1 |z| (n = 1), (beta, gamma) found by search, z a third model state.

Measurement: the recording is wrong, not the rig. They are fitted with the model by correcting the
channels (identify.measurement) and comparing the corrected model's prediction of what was recorded:
- mass_acc_gain, table_acc_gain: a channel reads (1 + g) times the true acceleration;
- channel_delay: the mass channel lags the table channel by tau (s);
- bias_drift: a sensor bias that drifts linearly over the record (m/s^2 from start to end).

`sign` is the sign a dissipative effect's coefficient must have in dq1/dt (negative: the force opposes
the motion), or 0 for effects that may go either way. `group` names effects the data often cannot tell
apart: the analysis reports the ones that come close as surrogates of the one it names.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Effect:
    name: str
    terms: tuple[str, ...]
    unit: str
    description: str
    kind: str = "physics"     # "physics" | "measurement"
    sign: int = 0             # required sign of the dq1/dt coefficient (dissipative: -1), 0 = free
    group: str = ""           # effects of one group are each other's surrogates
    plain: bool = True        # simulated and fitted as plain library terms with coefficients

    @property
    def dissipative(self) -> bool:
        return self.sign < 0


CATALOG: dict[str, Effect] = {e.name: e for e in (
    Effect("coulomb_friction", ("sign(q1)",), "N", "dry friction of the rail: constant force opposing the motion",
           sign=-1, group="damping"),
    Effect("displacement_dependent_damping", ("q1*q2^2",), "N s/m^3",
           "damping growing with stroke, e.g. follower bearings loaded by the profile", group="damping"),
    Effect("quadratic_stiffness", ("q2^2",), "N/m^2", "asymmetric spring: profile or pre-stress offset",
           group="asymmetry"),
    Effect("quadratic_damping", ("q1*|q1|",), "N s^2/m^2", "velocity-squared (aerodynamic/turbulent) damping",
           sign=-1, group="damping"),
    Effect("cubic_damping", ("q1^3",), "N s^3/m^3", "damping growing with the square of the velocity (viscous "
           "shear at high rates)", sign=-1, group="damping"),
    Effect("asymmetric_stiffness", ("|q2|",), "N/m", "a spring stiffer on one side: F = dk max(q2, 0) = "
           "dk/2 (q2 + |q2|), the |q2| term next to the model's own q2", group="asymmetry"),
    Effect("end_stop", ("stop(q2)", "sign(q2)*stop(q2)", "q1*contact(q2)", "q1*sign(q2)*contact(q2)"), "N/m",
           "contact beyond a travel d, one or two sided, with the contact's spring (stop(q2) = sign(q2) "
           "max(|q2| - d, 0)) and damping (q1 contact(q2)); d is searched", group="asymmetry", plain=False),
    Effect("stiffness_drift", ("q2*tau",), "N/m", "stiffness drifting over the record, k (1 + r t/T), e.g. "
           "a warming spring (tau = t/T - 1/2)", plain=False),
    Effect("hysteresis", ("z",), "N/m", "Bouc-Wen hysteresis with an internal state z: "
           "z' = q1 - beta |q1| z - gamma q1 |z|; (beta, gamma) searched", plain=False),
    Effect("mass_acc_gain", (), "1", "gain error of the mass accelerometer: it reads (1 + g) x''",
           kind="measurement", plain=False),
    Effect("table_acc_gain", (), "1", "gain error of the table accelerometer: it reads (1 + g) z''",
           kind="measurement", plain=False),
    Effect("channel_delay", (), "s", "the mass channel lags the table channel by tau (s)",
           kind="measurement", plain=False),
    Effect("bias_drift", (), "m/s^2", "a sensor bias drifting linearly over the record (change from start to "
           "end)", kind="measurement", plain=False),
)}

#: Physics effects the rig simulator can add as plain force terms (RigParameters(effects=...)).
PLAIN = {n: e for n, e in CATALOG.items() if e.plain}
