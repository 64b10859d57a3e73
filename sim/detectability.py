"""Whether a scenario's effects can be seen at all: each effect's gap measured, not predicted.

A scenario (sim/scenarios.py) promises that each of its effects leaves a held-out gap DETECTABLE x the
noise floor, so that `none` is not the right answer to it. The promise used to rest on a table of gap per
unit of effect size (GAP_PER_SIZE, the smallest seen on the narrow draws of one seed). On the wide draws
(sim/wide.py) the table over-predicted: a stiffness drift on one long down-sweep, for instance, is absorbed by
the plain model's stiffness (the sweep passes the resonance in a few seconds of a two-minute drift), and
such effects came out at 0.7-1.1x the floor, where no explanation can name them (benchmarks/results/
explain_robustness-2026-11-27.md). Now the gap is measured: the scenario's sweep is run on the plain rig
and on the rig with each effect alone, both sensors at MIN_NOISE with their drawn quantisation and no hum
(a measurement effect the rounds name and remove), the same noise draw in each, and the discrepancy
workflow's baseline (the paper's identification, refit on the shooting error:
identify.explain.DiscrepancyAnalysis.baseline_gap) gives each its held-out gap. The effect's own gap is
g0 = sqrt(g_effect^2 - g_plain^2) (what the noise and the plain model's own misfit leave removed); the floor
per unit of noise fraction is the plain run's noise floor over MIN_NOISE (read on the plain rig: an effect
with broadband content, an impact or a friction stick, raises the workflow's estimate of the floor on its
own record, which is the workflow's to cope with, not the scenario's promise; and an upper bound where
quantisation adds a floor of its own, so the cap below is safe). The scenario's sensors are then made
quiet enough that g0 stands DETECTABLE x the floor, and a scenario whose effect cannot stand there even at
MIN_NOISE is redrawn (make_scenario): the effect hides in the plain model on that rig and sweep. Only the
baseline is used, never an explanation: which effect is missing is not consulted.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from identify.explain.workflow import DiscrepancyAnalysis

from .sensors import Accelerometer
from .synth import run_sweep

#: Each effect's own gap must be at least this multiple of the scenario's noise floor ("none" is right only
#: within ~2x the floor, and an effect must be able to halve its gap above it).
DETECTABLE = 4.0
#: The quietest sensor a scenario may have (noise fraction of each channel's std): the gap is measured at it.
MIN_NOISE = 0.002
#: Effects the gap does not see by design: a bias ramp on one channel is found by a trend test on the raw
#: channels (identify.explain.drift), not by the free-run gap (0.8-1.0 of the floor).
UNSEEN_BY_GAP = ("bias_drift",)


@dataclass
class Changes:
    """What one effect changes of the plain scenario: RigParameters fields, and faults of each sensor."""

    rig: dict = field(default_factory=dict)
    table: dict = field(default_factory=dict)
    mass: dict = field(default_factory=dict)


def baseline_gap(sc, rig, changes: Changes, seed: int) -> dict:
    """The baseline's gap and noise floor on the scenario's sweep run by `rig`, both sensors at MIN_NOISE
    with their drawn quantisation and `changes`' faults, the noise drawn from `seed`."""
    table, mass = (Accelerometer(noise_fraction=MIN_NOISE, adc_bits=drawn.adc_bits, **faults)
                   for drawn, faults in ((sc.table_sensor, changes.table), (sc.mass_sensor, changes.mass)))
    rec = run_sweep(rig, sc.sweep, sc.fs_hz, sc.settle_s, table, mass, seed).recording
    return DiscrepancyAnalysis().baseline_gap(rec)


def quiet_enough(sc, plain_rig, own: dict, rng: np.random.Generator):
    """The scenario with its sensors' noise lowered until each effect's own gap stands DETECTABLE x the
    floor (recorded in sc.magnitudes[name]: gap_alone, floor_per_noise, noise_cap), or None when an effect
    cannot stand there even at MIN_NOISE (make_scenario redraws)."""
    names = [n for n in sc.truth_effects if n not in UNSEEN_BY_GAP]
    if not names:
        return sc
    seed = int(rng.integers(2**32))
    plain = baseline_gap(sc, plain_rig, Changes(), seed)
    per_noise = plain["noise_floor"] / MIN_NOISE
    for name in names:
        g = baseline_gap(sc, dataclasses.replace(plain_rig, **own[name].rig), own[name], seed)["gap"]
        g0 = math.sqrt(max(g**2 - plain["gap"] ** 2, 0.0))
        cap = g0 / (DETECTABLE * per_noise) if per_noise > 0 else math.inf
        sc.magnitudes.setdefault(name, {}).update(gap_alone=g0, floor_per_noise=per_noise, noise_cap=cap)
        if cap < MIN_NOISE:
            return None
        for sensor in (sc.table_sensor, sc.mass_sensor):
            sensor.noise_fraction = min(sensor.noise_fraction, cap)
    return sc
