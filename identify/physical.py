"""Physical parameters of the rig from an identified model (the paper's section 2.1).

q1_dot = -(c/m) q1 - (k/m) q2 - (k3/m) q2^3 - g zdd, and with the profile f(x) = a x^2 + b on springs k_l:
k = 4 k_l a b (so the pre-stress is b = k / (4 k_l a)) and k3 = 4 k_l a^2 by design.
"""
from __future__ import annotations

from dataclasses import dataclass

from .model import SparseModel


@dataclass(frozen=True)
class RigConstants:
    """Known constants of the rig: moving mass (kg), each linear spring k_l (N/m), profile a (1/m)."""

    mass_kg: float = 0.49
    spring_n_per_m: float = 16.7e3
    profile_per_m: float = 4.0

    def __post_init__(self):
        if not self.mass_kg > 0:  # every force is the mass times an acceleration; a stiffness divides by it
            raise ValueError(f"rig mass must be > 0 kg, got {self.mass_kg}")


def physical_parameters(model: SparseModel, rig: RigConstants = RigConstants(), mass_source: str = "given") -> dict:
    """Forces per unit mass times the mass: SI parameters with standard errors. mass_source says where
    rig.mass_kg came from ("given", "recording", "assumed": the default, which scales every value when
    the rig's moving mass differs)."""
    eq = "q1_dot"
    se = (model.standard_errors or {}).get(eq, {})
    m = rig.mass_kg

    def value(term: str, scale: float):
        c = model.coefficient(eq, term)
        return {"value": -m * c * scale if c else None,
                "std_error": m * se.get(term, 0.0) * scale if c and term in se else None}

    out = {
        "mass_kg": m,
        "mass_source": mass_source,
        "damping_ns_per_m": value("q1", 1.0),
        "stiffness_n_per_m": value("q2", 1.0),
        "cubic_stiffness_n_per_m3": value("q2^3", 1.0),
        "input_gain": {"value": -model.coefficient(eq, "zdd") or None},
    }
    k = out["stiffness_n_per_m"]["value"]
    denom = 4 * rig.spring_n_per_m * rig.profile_per_m
    out["prestress_b_m"] = {"value": k / denom if k is not None else None,
                            "std_error": (out["stiffness_n_per_m"]["std_error"] / denom
                                          if out["stiffness_n_per_m"]["std_error"] is not None else None)}
    out["design"] = {"cubic_stiffness_n_per_m3": 4 * rig.spring_n_per_m * rig.profile_per_m**2,
                     "cubic_stiffness_per_kg": 4 * rig.spring_n_per_m * rig.profile_per_m**2 / m}
    return out
