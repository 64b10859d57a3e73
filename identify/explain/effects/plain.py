"""Physics with plain library terms: a force on the mass, F = coefficient x term(q1, q2), with q1 the
relative velocity (m/s) and q2 the relative displacement (m). The rig simulator adds them from
RigParameters(effects={name: coef}); the discrepancy workflow fits each by one least-squares fit
(Effect.propose); a dissipative one must take the sign that opposes the motion (Effect.admissibility).
"""
from __future__ import annotations

from .base import Effect


class CoulombFriction(Effect):
    name, terms, unit = "coulomb_friction", ("sign(q1)",), "N"
    description = "dry friction of the rail: constant force opposing the motion"
    sign, group = -1, "damping"


class DisplacementDependentDamping(Effect):
    name, terms, unit = "displacement_dependent_damping", ("q1*q2^2",), "N s/m^3"
    description = "damping growing with stroke, e.g. follower bearings loaded by the profile"
    group = "damping"
    #: Sign-free in the rounds (the paper's identified rig, Table 1, has an energy-injecting q1*q2^2), but
    #: under a friction's mask looked for as what bearings do: dissipating (identify.explain.masking).
    masked_sign = -1


class QuadraticStiffness(Effect):
    name, terms, unit = "quadratic_stiffness", ("q2^2",), "N/m^2"
    description = "asymmetric spring: profile or pre-stress offset"
    group = "asymmetry"


class QuadraticDamping(Effect):
    name, terms, unit = "quadratic_damping", ("q1*|q1|",), "N s^2/m^2"
    description = "velocity-squared (aerodynamic/turbulent) damping"
    sign, group = -1, "damping"


class CubicDamping(Effect):
    name, terms, unit = "cubic_damping", ("q1^3",), "N s^3/m^3"
    description = "damping growing with the square of the velocity (viscous shear at high rates)"
    sign, group = -1, "damping"


class AsymmetricStiffness(Effect):
    name, terms, unit = "asymmetric_stiffness", ("|q2|",), "N/m"
    description = ("a spring stiffer on one side: F = dk max(q2, 0) = dk/2 (q2 + |q2|), the |q2| term next to "
                   "the model's own q2")
    group = "asymmetry"
    force = {"q2": 0.5, "|q2|": 0.5}  # the simulator's: dk max(q2, 0) (sim.physics flips it for the lower side)
