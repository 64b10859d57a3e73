"""Catalog of physical effects a real rig has beyond the textbook Duffing oscillator.

Each effect is a force term on the mass, F = coefficient * term(q1, q2), with q1 the relative velocity
(m/s) and q2 the relative displacement (m). The rig simulator adds them to the physics; the library
can offer their terms; the discrepancy workflow scores them. Adding an effect is one more entry here.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Effect:
    name: str
    terms: tuple[str, ...]
    unit: str
    description: str


CATALOG: dict[str, Effect] = {e.name: e for e in (
    Effect("coulomb_friction", ("sign(q1)",), "N", "dry friction of the rail: constant force opposing the motion"),
    Effect("displacement_dependent_damping", ("q1*q2^2",), "N s/m^3",
           "damping growing with stroke, e.g. follower bearings loaded by the profile"),
    Effect("quadratic_stiffness", ("q2^2",), "N/m^2", "asymmetric spring: profile or pre-stress offset"),
    Effect("quadratic_damping", ("q1*|q1|",), "N s^2/m^2", "velocity-squared (aerodynamic/turbulent) damping"),
)}
