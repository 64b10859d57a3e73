"""How a scenario draws each effect (sim/scenarios.py): one small function per effect, registered in DRAWS.

Each function sets what the effect changes on a Draw (rig fields, the plain-term effects dict, the
sensors) and its report magnitudes, from the pilot's peak displacement Q, peak velocity V and spring force
Fs and, for forces, the drawn fraction rho of Fs (scenarios.RELATIVE_FORCE; the sizes are in sim/scenarios.py's
docstring). The order of the random draws is the scenarios' record: a seed and case reproduce a scenario
(benchmarks/explain_robustness.py --seed S --case N), so a function draws what it draws in a fixed order.
Adding an effect to the suite is one function here and one line in DRAWS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .rig import RigParameters
from .sensors import Accelerometer


@dataclass
class Draw:
    """A scenario being drawn: the random source, the plain rig and sweep, the sensors (changed in place),
    the pilot's Q (m), V (m/s) and Fs (N); what the effects change: RigParameters fields, the plain-term
    effects {name: force coefficient}, and each effect's report magnitudes."""

    rng: np.random.Generator
    rig: RigParameters
    sweep: object
    table: Accelerometer
    mass: Accelerometer
    Q: float
    V: float
    Fs: float
    fields: dict = field(default_factory=dict)
    effects: dict = field(default_factory=dict)
    mags: dict = field(default_factory=dict)


#: Plain force effects: the force coefficient is rho Fs over this scale at the pilot's (V, Q).
FORCE_SCALE = {
    "coulomb_friction": lambda d: 1.0,
    "displacement_dependent_damping": lambda d: d.V * d.Q**2,
    "quadratic_stiffness": lambda d: d.Q**2,
    "quadratic_damping": lambda d: d.V**2,
    "cubic_damping": lambda d: d.V**3,
    "asymmetric_stiffness": lambda d: d.Q,
}


def plain_force(name: str):
    def draw(d: Draw, r: float) -> None:
        sign = d.rng.choice([-1, 1]) if name == "quadratic_stiffness" else 1  # a spring may soften or harden
        d.effects[name] = sign * r * d.Fs / FORCE_SCALE[name](d)
        if name == "asymmetric_stiffness":
            d.fields["asymmetric_side"] = int(d.rng.choice([-1, 1]))
    return draw


def end_stop(d: Draw, r) -> None:
    gap = d.rng.uniform(0.7, 0.9) * d.Q * 1e3
    side = str(d.rng.choice(["both", "upper", "lower"]))
    d.fields.update(end_stop_travel_mm=gap if side == "both" else None,
                    end_stop_lower_mm=None if side == "both" else (gap if side == "lower" else math.inf),
                    end_stop_upper_mm=None if side == "both" else (gap if side == "upper" else math.inf))
    kc = d.rng.uniform(2.0, 10.0) * d.Fs / d.Q
    d.fields.update(contact_stiffness_n_per_m=kc,
                    contact_damping_ns_per_m=2 * d.rng.uniform(0.1, 0.25) * math.sqrt(kc * d.rig.mass_kg))
    d.mags["end_stop"] = {"gap_mm": gap, "side": side, "contact_stiffness_n_per_m": kc}


def stiffness_drift(d: Draw, r) -> None:
    rate = float(d.rng.choice([-1, 1]) * d.rng.uniform(0.05, 0.15))
    d.fields["stiffness_drift"] = rate
    d.mags["stiffness_drift"] = {"r": rate, "relative_force": abs(rate) * d.rig.stiffness_n_per_m * d.Q / d.Fs}


def hysteresis(d: Draw, r: float) -> None:
    z_max = d.rng.uniform(0.2, 0.5) * d.Q
    share = d.rng.uniform(0.5, 0.9)
    d.fields.update(hysteresis_alpha=r * d.Fs / (d.rig.stiffness_n_per_m * z_max), hysteresis_beta=share / z_max,
                    hysteresis_gamma=(1 - share) / z_max, hysteresis_n=1, hysteresis_A=1.0)
    d.mags["hysteresis"] = {"alpha": d.fields["hysteresis_alpha"], "z_max_m": z_max, "relative_force": r}


def second_mode(d: Draw, r) -> None:
    m, fn = d.rig.mass_kg, d.rig.natural_frequency_hz
    ma = d.rng.uniform(0.02, 0.06) * m
    # within the sweep: below 0.85 of its top frequency, which a down-sweep starts at (f_end_hz, its low end,
    # put the mode below the band, where it reads as a constant mass-channel gain: seed 3485374292 cases 32,
    # 56, 104, 128, fa at 0.48 fn, all answered mass_acc_gain)
    top_hz = max(d.sweep.f_start_hz, d.sweep.f_end_hz)
    fa = min(d.rng.uniform(1.3, 2.2) * fn, 0.85 * top_hz)  # the cap exact, not 1 ulp over
    ka = ma * (2 * math.pi * fa) ** 2
    ca = 2 * d.rng.uniform(0.02, 0.08) * math.sqrt(ka * ma)
    d.fields.update(absorber_mass_kg=ma, absorber_stiffness_n_per_m=ka, absorber_damping_ns_per_m=ca)
    d.mags["second_mode"] = {"mass_ratio": ma / m, "frequency_hz": fa, "relative_force": ma / m}


def free_play(d: Draw, r: float) -> None:
    k = d.rig.stiffness_n_per_m
    g = min(r * d.Fs / k, 0.3 * d.Q, 0.5 * d.sweep.amplitude_mm * 1e-3)  # g > Z: the spring never engages
    d.fields["spring_free_play_mm"] = g * 1e3
    d.mags["free_play"] = {"free_play_mm": g * 1e3, "relative_force": k * g / d.Fs}


def gain(name: str):
    def draw(d: Draw, r) -> None:
        g = 1 + d.rng.choice([-1, 1]) * d.rng.uniform(0.02, 0.05)
        (d.mass if name == "mass_acc_gain" else d.table).gain = g
        d.mags[name] = {"gain": g, "relative_force": abs(g - 1)}
    return draw


def channel_delay(d: Draw, r) -> None:
    delay = d.rng.uniform(0.3e-3, 2e-3)
    channel = str(d.rng.choice(["table", "mass"]))
    (d.mass if channel == "mass" else d.table).delay_s = delay
    d.mags["channel_delay"] = {"delay_s": delay, "channel": channel,
                               "relative_force": 2 * math.pi * d.rig.natural_frequency_hz * delay}


def bias_drift(d: Draw, r) -> None:
    b = d.rng.choice([-1, 1]) * d.rng.uniform(0.01, 0.05)
    channel = str(d.rng.choice(["table", "mass"]))
    (d.mass if channel == "mass" else d.table).bias_drift_ms2 = b
    d.mags["bias_drift"] = {"bias_drift_ms2": b, "channel": channel,
                            "relative_force": abs(b) / (2 * math.pi * d.rig.natural_frequency_hz * d.V)}


#: Every effect a scenario can hold, and how it is drawn.
DRAWS = {
    **{name: plain_force(name) for name in FORCE_SCALE},
    "end_stop": end_stop,
    "stiffness_drift": stiffness_drift,
    "hysteresis": hysteresis,
    "second_mode": second_mode,
    "free_play": free_play,
    "mass_acc_gain": gain("mass_acc_gain"),
    "table_acc_gain": gain("table_acc_gain"),
    "channel_delay": channel_delay,
    "bias_drift": bias_drift,
}
