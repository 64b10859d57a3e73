"""Physics of the base-excited Duffing rig (the paper's eq. 2) with optional real-rig effects.

    m q'' = -c q' - k q - k3 q^3 - sum_e F_e(q', q) - g m z''

q = x - z is the mass displacement relative to the table (m), z'' the table acceleration (m/s^2),
g the input gain (1 for an ideal rig; Table 1 of the paper identified 1.0243). In state form
q1 = q' (m/s), q2 = q (m), this is an identify.SparseModel, so the simulator and the identifier share
one model type and one integrator.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from identify.effects import CATALOG
from identify.model import SparseModel

#: Rig constants of the paper's setup.
PAPER_MASS_KG = 0.49
PAPER_SPRING_N_PER_M = 16.7e3   # k_l, each linear spring
PAPER_PROFILE_PER_M = 4.0       # a, profile f(x) = a x^2 + b


@dataclass
class RigParameters:
    """Mass (kg), viscous damping c (N s/m), linear and cubic stiffness k (N/m), k3 (N/m^3),
    input gain, and extra effects {catalog name: force coefficient in the effect's unit}."""

    mass_kg: float = PAPER_MASS_KG
    damping_ns_per_m: float = 3.7294 * PAPER_MASS_KG
    stiffness_n_per_m: float = 971.0169 * PAPER_MASS_KG
    cubic_stiffness_n_per_m3: float = 4 * PAPER_SPRING_N_PER_M * PAPER_PROFILE_PER_M**2
    input_gain: float = 1.0
    effects: dict[str, float] = field(default_factory=dict)

    def __post_init__(self):
        unknown = set(self.effects) - set(CATALOG)
        if unknown:
            raise ValueError(f"unknown effect(s) {sorted(unknown)}; known: {sorted(CATALOG)}")
        if self.mass_kg <= 0:
            raise ValueError("mass must be positive")

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

    def model(self) -> SparseModel:
        """The rig as dq/dt equations (coefficients divided by the mass)."""
        m = self.mass_kg
        q1 = {"q1": -self.damping_ns_per_m / m, "q2": -self.stiffness_n_per_m / m,
              "q2^3": -self.cubic_stiffness_n_per_m3 / m, "zdd": -self.input_gain}
        for name, coef in self.effects.items():
            for term in CATALOG[name].terms:
                q1[term] = q1.get(term, 0.0) - coef / m
        return SparseModel({"q1_dot": q1, "q2_dot": {"q1": 1.0}})

    def to_dict(self) -> dict:
        return {"mass_kg": self.mass_kg, "damping_ns_per_m": self.damping_ns_per_m,
                "stiffness_n_per_m": self.stiffness_n_per_m,
                "cubic_stiffness_n_per_m3": self.cubic_stiffness_n_per_m3, "input_gain": self.input_gain,
                "effects": dict(self.effects)}
