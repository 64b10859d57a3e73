"""Physics of the base-excited Duffing rig (the paper's eq. 2) with optional real-rig effects.

    m q'' = -c q' - k q - k3 q^3 - sum_e F_e(q', q) - g m z''

q = x - z is the mass displacement relative to the table (m), z'' the table acceleration (m/s^2),
g the input gain (1 for an ideal rig; Table 1 of the paper identified 1.0243). In state form
q1 = q' (m/s), q2 = q (m), this is an identify.SparseModel, so the simulator and the identifier share
one model type and one integrator.

The rail has end stops: beyond a travel d each side (|q| > d) the mass presses into a stiff damped
bumper, F = -k_c stop(q) - c_c q' contact(q) (identify.regression.terms). Without them the paper's Table 1 model,
whose +1.162e4 q' q^2 term is negative damping for |q| > 17.9 mm, diverges on a slow sweep. The
travel can differ per side (end_stop_lower_mm, end_stop_upper_mm; inf: no stop on that side).

Physics beyond the plain terms of identify.explain.effects, the ground truth of the discrepancy suite
(sim/scenarios.py), described here on the sim's own terms so the truth does not depend on the catalog
it is judged against (sim/physics.py builds the equations):
- cubic_damping (effects value: N s^3/m^3, F = c3 q'^3) and asymmetric_stiffness (effects value dk in
  N/m, F = dk max(q, 0), or dk min(q, 0) with asymmetric_side = -1) as effects entries;
- stiffness_drift r: k(t) = k (1 + r t / T) over the record of length T (an input `drift` = t/T);
- Bouc-Wen hysteresis: F = a k z, z' = A q' - beta |q'| |z|^(n-1) z - gamma q' |z|^n (a state z, m);
- out of the catalog: a tuned absorber (a second mode: mass m_a on a spring k_a and damper c_a riding on
  the mass) and free play in the linear spring's mount (the spring force k dz(q), dz the dead zone of
  half-width g).
They run in sim.synth.run_sweep; the PLC refuses them (it steps the two rig states only).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from identify.explain.effects import CATALOG
from identify.model import SparseModel

from . import physics

#: Rig constants of the paper's setup.
PAPER_MASS_KG = 0.49
PAPER_SPRING_N_PER_M = 16.7e3   # k_l, each linear spring
PAPER_PROFILE_PER_M = 4.0       # a, profile f(x) = a x^2 + b

#: End-stop travel (mm, each side): above the 17.10 mm the paper's standard sweep (1-20 Hz, 60 s,
#: 1.3 mm) reaches on the Table 1 rig, so that sweep never touches the stops, and below the 17.9 mm
#: where that rig's damping c - 1.162e4 m q^2 turns negative.
END_STOP_TRAVEL_MM = 17.5
#: Bumper stiffness (N/m) and damping (N s/m): an elastomer pad. On the 0.49 kg mass the contact
#: frequency sqrt(k_c/m)/2pi is 200 Hz: 10x the sweep's top frequency, so the stop is a wall to the
#: rig (a 0.6 m/s impact penetrates 0.33 mm of the 17.5 mm travel, for 2.6 ms), yet RK4 at the PLC's
#: 2048 Hz x 8 substeps takes ~40 steps per contact (omega_c h = 0.077 < 0.1, identify.simulation.simulate's
#: accuracy target). Damping ratio c_c/(2 sqrt(k_c m)) = 0.24: restitution 0.45, a lossy elastomer;
#: much less and the mass rattles, much more and the linear pad pulls on release.
CONTACT_STIFFNESS_N_PER_M = 7.7e5
CONTACT_DAMPING_NS_PER_M = 300.0


@dataclass
class RigParameters:
    """Mass (kg), viscous damping c (N s/m), linear and cubic stiffness k (N/m), k3 (N/m^3),
    input gain, extra effects {catalog name: force coefficient in the effect's unit}, and the end
    stops: travel (mm each side, None or inf: no stops), contact stiffness (N/m) and damping (N s/m)."""

    mass_kg: float = PAPER_MASS_KG
    damping_ns_per_m: float = 3.7294 * PAPER_MASS_KG
    stiffness_n_per_m: float = 971.0169 * PAPER_MASS_KG
    cubic_stiffness_n_per_m3: float = 4 * PAPER_SPRING_N_PER_M * PAPER_PROFILE_PER_M**2
    input_gain: float = 1.0
    effects: dict[str, float] = field(default_factory=dict)
    end_stop_travel_mm: float | None = END_STOP_TRAVEL_MM
    contact_stiffness_n_per_m: float = CONTACT_STIFFNESS_N_PER_M
    contact_damping_ns_per_m: float = CONTACT_DAMPING_NS_PER_M
    end_stop_lower_mm: float | None = None     # travel on the q < 0 side (None: end_stop_travel_mm)
    end_stop_upper_mm: float | None = None     # travel on the q > 0 side (None: end_stop_travel_mm)
    asymmetric_side: int = 1                   # asymmetric_stiffness acts on q > 0 (+1) or q < 0 (-1)
    stiffness_drift: float = 0.0               # r: k(t) = k (1 + r t / T), T the record length
    hysteresis_alpha: float = 0.0              # a: Bouc-Wen force a k z (0: none)
    hysteresis_A: float = 1.0                  # Bouc-Wen A (dimensionless)
    hysteresis_beta: float = 0.0               # Bouc-Wen beta (1/m^n)
    hysteresis_gamma: float = 0.0              # Bouc-Wen gamma (1/m^n)
    hysteresis_n: int = 1                      # Bouc-Wen exponent n (1, 2 or 3)
    absorber_mass_kg: float = 0.0              # second mode: absorber mass (0: none)
    absorber_stiffness_n_per_m: float = 0.0
    absorber_damping_ns_per_m: float = 0.0
    spring_free_play_mm: float = 0.0           # dead zone half-width g of the linear spring (0: none)

    def __post_init__(self):
        physics.check_effects(self.effects, CATALOG)
        if self.mass_kg <= 0:
            raise ValueError("mass must be positive")
        if self.end_stop_travel_mm is not None and not self.end_stop_travel_mm > 0:
            raise ValueError(f"end_stop_travel_mm must be positive (inf: no end stops), got {self.end_stop_travel_mm}")
        if not (0 < self.contact_stiffness_n_per_m < math.inf and 0 <= self.contact_damping_ns_per_m < math.inf):
            raise ValueError("contact stiffness must be positive and contact damping non-negative, both finite")
        for side in ("end_stop_lower_mm", "end_stop_upper_mm"):
            v = getattr(self, side)
            if v is not None and not v > 0:
                raise ValueError(f"{side} must be positive (inf: no stop on that side), got {v}")
        physics.check_rig(self)

    @property
    def travels_mm(self) -> tuple[float, float]:
        """End-stop travel (mm) on the (q < 0, q > 0) sides; inf: no stop on that side."""
        both = math.inf if self.end_stop_travel_mm is None else float(self.end_stop_travel_mm)
        return tuple(both if v is None else float(v) for v in (self.end_stop_lower_mm, self.end_stop_upper_mm))

    @property
    def natural_frequency_hz(self) -> float:
        """The linear natural frequency sqrt(k / m) / 2 pi (Hz): where a drawn sweep and effect are placed."""
        return math.sqrt(self.stiffness_n_per_m / self.mass_kg) / (2 * math.pi)

    @property
    def end_stops(self) -> bool:
        """True when the rail has an end stop on at least one side (a finite travel)."""
        return any(math.isfinite(v) for v in self.travels_mm)

    def in_contact(self, q_m) -> np.ndarray:
        """True where the displacement q (m) is beyond an end stop's travel."""
        lower, upper = self.travels_mm
        q = np.asarray(q_m, dtype=float)
        return (q > upper * 1e-3) | (q < -lower * 1e-3)

    @property
    def sim_only(self) -> bool:
        """True when the rig has physics only run_sweep runs (extra states or the drift input)."""
        return physics.extra_physics(self)

    @classmethod
    def design(cls, prestress_m: float = 1.78e-3, **kw) -> "RigParameters":
        """The paper's design: k = 4 k_l a b, k3 = 4 k_l a^2, damping from Table 1."""
        k = 4 * PAPER_SPRING_N_PER_M * PAPER_PROFILE_PER_M * prestress_m
        return cls(stiffness_n_per_m=k, **kw)

    @classmethod
    def paper_table1(cls) -> "RigParameters":
        """The model the paper identified (Table 1), including its displacement-dependent damping."""
        m = PAPER_MASS_KG
        return cls(m, 3.7294 * m, 971.0169 * m, 2.5033e6 * m, 1.0243,
                   {"displacement_dependent_damping": -1.1620e4 * m})

    def model(self, end_stops: bool = False) -> SparseModel:
        """The rig as dq/dt equations (coefficients divided by the mass): by default the smooth model
        identification sees; `end_stops=True` adds the bumpers' terms (the physics the rig runs).
        Physics beyond the plain terms adds states (z, absorber qa1/qa2, contact coordinates) or the
        input `drift` (sim/physics.py); `initial_state(model)` gives their state at rest."""
        m = self.mass_kg
        q1 = {"q1": -self.damping_ns_per_m / m, "q2": -self.stiffness_n_per_m / m,
              "q2^3": -self.cubic_stiffness_n_per_m3 / m, "zdd": -self.input_gain}
        if physics.general(self):
            return physics.build_model(self, q1, end_stops)
        for name, coef in self.effects.items():
            for term, weight in CATALOG[name].force.items():  # the effect's own force (identify.explain.effects)
                q1[term] = q1.get(term, 0.0) - coef * weight / m
        if not (end_stops and self.end_stops):
            return SparseModel({"q1_dot": q1, "q2_dot": {"q1": 1.0}})
        q1.update({"stop(q2)": -self.contact_stiffness_n_per_m / m, "q1*contact(q2)": -self.contact_damping_ns_per_m / m})
        return SparseModel({"q1_dot": q1, "q2_dot": {"q1": 1.0}}, travel={"q2": self.end_stop_travel_mm * 1e-3})

    def initial_state(self, model: SparseModel) -> list[float]:
        """The state of `model` with the rig at rest (q = 0): zero but for shifted contact coordinates."""
        return physics.initial_state(self, model)

    def end_stop_summary(self) -> dict | None:
        """The end stops as numbers (travel mm, k_c N/m, c_c N s/m, contact frequency Hz, damping ratio),
        None without stops."""
        if not self.end_stops:
            return None
        k, c, m = self.contact_stiffness_n_per_m, self.contact_damping_ns_per_m, self.mass_kg
        out = {"travel_mm": self.end_stop_travel_mm, "contact_stiffness_n_per_m": k, "contact_damping_ns_per_m": c,
               "contact_frequency_hz": math.sqrt(k / m) / (2 * math.pi), "damping_ratio": c / (2 * math.sqrt(k * m))}
        lower, upper = self.travels_mm
        if lower != upper or lower != self.end_stop_travel_mm:
            out.update(travel_mm=None, lower_travel_mm=None if math.isinf(lower) else lower,
                       upper_travel_mm=None if math.isinf(upper) else upper)
        return out

    def to_dict(self) -> dict:
        return {"mass_kg": self.mass_kg, "damping_ns_per_m": self.damping_ns_per_m,
                "stiffness_n_per_m": self.stiffness_n_per_m,
                "cubic_stiffness_n_per_m3": self.cubic_stiffness_n_per_m3, "input_gain": self.input_gain,
                "effects": dict(self.effects),
                "end_stop_travel_mm": self.end_stop_travel_mm if self.end_stops else None,
                "contact_stiffness_n_per_m": self.contact_stiffness_n_per_m,
                "contact_damping_ns_per_m": self.contact_damping_ns_per_m, **physics.extra_fields(self)}
