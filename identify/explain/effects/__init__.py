"""Catalog of what a real rig (or its recording) has beyond the textbook Duffing oscillator: one class per
effect (identify.explain.effects.base.Effect), registered here. Adding an effect is one module with its class and
one `register(...)` line below; the rig simulator (RigParameters(effects=...) for plain physics), the
identification library (an effect's name among extra_terms), the discrepancy workflow
(identify.explain.workflow) and its report and JSON all read this registry.

Physics (a force on the mass): identify.explain.effects.plain (plain library terms), end_stop, stiffness_drift,
hysteresis. Measurement (the recording is wrong, not the rig): faults (gains, delay), bias_drift, mains_hum.
"""
from __future__ import annotations

from .base import CATALOG, Candidate, Effect, expand_terms, plain_effects, register, unregister, wald_p
from .bias_drift import BiasDrift
from .end_stop import EndStop
from .faults import ChannelDelay, MassAccGain, TableAccGain
from .hysteresis import Hysteresis
from .mains_hum import MainsHum
from .plain import (AsymmetricStiffness, CoulombFriction, CubicDamping, DisplacementDependentDamping,
                    QuadraticDamping, QuadraticStiffness)
from .stiffness_drift import StiffnessDrift

register(CoulombFriction())
register(DisplacementDependentDamping())
register(QuadraticStiffness())
register(QuadraticDamping())
register(CubicDamping())
register(AsymmetricStiffness())
register(EndStop())
register(StiffnessDrift())
register(Hysteresis())
register(MassAccGain())
register(TableAccGain())
register(ChannelDelay())
register(BiasDrift())
register(MainsHum())

__all__ = ["CATALOG", "Candidate", "Effect", "expand_terms", "plain_effects", "register", "unregister", "wald_p"]
