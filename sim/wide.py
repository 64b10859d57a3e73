"""The wide draws of the discrepancy suite (issue 32 item 7; benchmarks/explain_robustness.py): rigs, sweeps
and recordings nobody tuned for, used by sim.scenarios.make_scenario(..., wide=True).

The rig is the design rig (sim.rig.RigParameters.design) with mass, damping, linear and cubic stiffness each
scaled by RIG_SPREAD (0.7-1.3); the table amplitude is TABLE_AMPLITUDE_MM (0.8-4 mm, not rescaled to a target
response, so the hardening rig's jump falls anywhere in the record); the sweep runs up or down between
F_LOW_HZ (1 Hz to F_LOW_PER_FN x fn) and F_HIGH_HZ (F_HIGH_PER_FN x fn to 25 Hz) in DURATION_S (15-120 s);
1000 or 2048 Hz; sensor noise NOISE_FRACTION (0.2-5 % of each channel's std). A draw whose plain rig runs
past sim.scenarios.MAX_RESPONSE_MM is redrawn (the rig's stops are at 17.5 mm: an operator could not run
it), so large amplitudes survive on the stiffer, better damped rigs only.

Nuisances on top: with QUANTISATION_SHARE both channels quantised to ADC_BITS (10-16) bits over the record's
range; with HUM_SHARE mains hum (50 or 60 Hz, HUM_FRACTION 1-5 % of the channel's std) on the table, the
mass or both channels. They are measurement effects that exist (`nuisances`, named by NUISANCE_NAMES).
"""
from __future__ import annotations

import math

import numpy as np

from protocol.sweep import SineSweep

from .rig import RigParameters
from .sensors import Accelerometer

RIG_SPREAD = (0.7, 1.3)
TABLE_AMPLITUDE_MM = (0.8, 4.0)
F_LOW_HZ, F_HIGH_HZ = 1.0, 25.0
F_LOW_PER_FN, F_HIGH_PER_FN = 0.7, 1.5
DURATION_S = (15.0, 120.0)
DOWN_SHARE = 0.5
SAMPLE_RATES_HZ = (1000.0, 2048.0)
NOISE_FRACTION = (0.002, 0.05)
QUANTISATION_SHARE = 0.5
ADC_BITS = (10, 16)
HUM_SHARE = 0.3
HUM_HZ = (50.0, 60.0)
HUM_FRACTION = (0.01, 0.05)
#: The measurement effects a nuisance is (what an explanation may name where it exists).
NUISANCE_NAMES = {"hum": "mains_hum", "quantisation": "quantisation"}


def draw_base(rng: np.random.Generator, duration_s: float | None = None, fs_hz: float | None = None):
    """A rig, sweep, sample rate and the two sensors (noise and nuisances set), as sim.scenarios._base
    returns them, with no target response (None: the table amplitude is the drawn one)."""
    design = RigParameters.design()
    s = rng.uniform(*RIG_SPREAD, size=4)
    rig = RigParameters(mass_kg=design.mass_kg * s[0], damping_ns_per_m=design.damping_ns_per_m * s[1],
                        stiffness_n_per_m=design.stiffness_n_per_m * s[2],
                        cubic_stiffness_n_per_m3=design.cubic_stiffness_n_per_m3 * s[3])
    fn = rig.natural_frequency_hz
    f_lo = rng.uniform(F_LOW_HZ, max(F_LOW_HZ, F_LOW_PER_FN * fn))
    f_hi = rng.uniform(min(F_HIGH_PER_FN * fn, F_HIGH_HZ), F_HIGH_HZ)
    duration = rng.uniform(*DURATION_S) if duration_s is None else float(duration_s)
    amplitude = rng.uniform(*TABLE_AMPLITUDE_MM)
    down = bool(rng.random() < DOWN_SHARE)
    sweep = SineSweep(f_hi if down else f_lo, f_lo if down else f_hi, duration, amplitude)
    fs = float(rng.choice(SAMPLE_RATES_HZ)) if fs_hz is None else float(fs_hz)
    sensors = [Accelerometer(noise_fraction=rng.uniform(*NOISE_FRACTION)) for _ in range(2)]
    _nuisances(rng, sensors)
    return rig, sweep, fs, sensors, None


def _nuisances(rng, sensors) -> None:
    """Quantisation (both channels) and mains hum (one or both) set on the sensors, as drawn."""
    if rng.random() < QUANTISATION_SHARE:
        bits = int(rng.integers(ADC_BITS[0], ADC_BITS[1] + 1))
        for s in sensors:
            s.adc_bits = bits
    if rng.random() < HUM_SHARE:
        hz = float(rng.choice(HUM_HZ))
        where = rng.choice(["table", "mass", "both"])
        for name, s in zip(("table", "mass"), sensors):
            if where in (name, "both"):
                s.hum_fraction, s.hum_hz = float(rng.uniform(*HUM_FRACTION)), hz
                s.hum_phase_rad = float(rng.uniform(0, 2 * math.pi))


def nuisances(table: Accelerometer, mass: Accelerometer) -> dict:
    """The nuisances the two sensors have, {NUISANCE_NAMES kind: details} (empty: none)."""
    out = {}
    if table.adc_bits or mass.adc_bits:
        out["quantisation"] = {"bits": max(table.adc_bits, mass.adc_bits)}
    hum = {ch: {"fraction": s.hum_fraction, "hz": s.hum_hz} for ch, s in (("table", table), ("mass", mass))
           if s.hum_fraction}
    if hum:
        out["hum"] = hum
    return out
