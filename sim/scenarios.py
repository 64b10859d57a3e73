"""Randomised discrepancy scenarios with known truth: the suite the discrepancy workflow is judged on
(benchmarks/explain_robustness.py, docs in benchmarks/README.md); sim/scoring.py judges an answer.

    rng = np.random.default_rng(1)
    sc = make_scenario(rng, "two_effects")       # sc.truth_effects == ["hysteresis", "cubic_damping"], ...
    run = sc.run(seed=0)                          # a SyntheticRun; run.recording.metadata["truth"] says it too

Categories (CATEGORIES): "none" (the textbook Duffing rig), "single" (one catalog physics effect),
"two_effects" (two of them, not from one surrogate group), "sensor_fault" (one measurement effect),
"out_of_catalog" (physics the catalog does not have: a second mode, free play in the spring mount).

The rig: mass 0.3-1.5 kg, natural frequency 3-9 Hz, damping ratio 2-6 %, cubic stiffness such that
k3 Q^2 / k = 0.2-1 at a target amplitude Q of 4-11 mm; the sweep covers (0.3-0.6) fn to (2.5-4) fn
(at most 40 Hz) in 30-60 s with 2 s of settling; 1000 or 2048 Hz; sensor noise 0.2-3 % of each
channel's std, drawn per channel and then lowered, if need be, until each effect's own gap, measured by
running it alone (sim.detectability), stands DETECTABLE x the noise floor; a scenario whose effect cannot,
even at MIN_NOISE, is redrawn. The table amplitude is set from a pilot run of the
plain rig (no noise, at the scenario's sample rate: near the hardening rig's jump the response depends on
the last digits of the integration, so a pilot at another rate can peak elsewhere) so its response peaks
near the target amplitude.

Effect sizes are set from that pilot's peak displacement Q, peak velocity V and spring force
Fs = k Q + k3 Q^3: each effect's force at (V, Q) is a drawn fraction rho of Fs (RELATIVE_FORCE, 2-10 %),
e.g. Coulomb friction mu = rho Fs, quadratic damping c2 = rho Fs / V^2. End stops: a gap of 0.7-0.9 Q on
one or both sides, a bumper 2-10 times the rig's secant stiffness Fs / Q (relative force: at the deepest
contact). Stiffness drift: r = +-(5-15) %. Bouc-Wen (n = 1, A = 1): z saturates at
z_max = 1 / (beta + gamma) = 0.2-0.5 Q, a k z_max = rho Fs. Sensor faults: a gain error of +-(2-5) %, a
delay of 0.3-2 ms on one channel, a bias ramp of +-(0.01-0.05) m/s^2 over the record on one channel. Out
of catalog: an absorber of 2-6 % of the mass tuned to 1.3-2.2 fn (damping ratio 2-8 %); free play of the
linear spring with k g = rho Fs (g <= 0.3 Q and g <= Z/2: with g above the table amplitude Z the mass
floats and the spring never engages). `magnitudes[name]["relative_force"]` is rho for forces; for sensor
faults the relative size of the error: |gain - 1|, the phase 2 pi fn delay at resonance, the bias ramp
over the peak mass acceleration. Each effect's draw is one function in sim/effect_draws.py (DRAWS).

A drawn scenario is checked by running its physics once (no noise): it must not diverge, stay below
MAX_RESPONSE_MM, reach at least MIN_RESPONSE of the plain rig's peak, and touch the end stops only if end
stops are its effect (then in >= 10 samples); otherwise it is redrawn (make_scenario never raises for an
unlucky draw).

Wide draws (`wide=True`, sim/wide.py; issue 32 item 7): a rig within +-30 % of the design rig, a table
amplitude of 0.8-4 mm as drawn (no pilot rescaling: the jump falls anywhere), sweeps up or down within
1-25 Hz over 15-120 s, noise 0.2-5 %, and quantisation and mains hum as measurement nuisances
(`Scenario.nuisances`); the effects are sized and checked as above.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from identify.explain.effects import CATALOG
from protocol.sweep import SineSweep

from . import detectability
from .detectability import MIN_NOISE
from .effect_draws import DRAWS, Draw
from . import wide as wide_draws
from .rig import RigParameters
from .sensors import Accelerometer
from .synth import SyntheticRun, run_sweep

CATEGORIES = ("none", "single", "two_effects", "sensor_fault", "out_of_catalog")
#: Catalog physics and the sensor faults a scenario can hold, in the catalog's order: read from the
#: registry the analysis uses (identify.explain.effects.CATALOG), not listed again; each one needs its draw
#: (sim/effect_draws.py DRAWS; the catalog's mains hum is a nuisance of wide draws, sim/wide.py).
PHYSICS = tuple(n for n, e in CATALOG.items() if e.kind == "physics")
MEASUREMENT = tuple(n for n, e in CATALOG.items() if e.kind == "measurement" and n in DRAWS)
#: Physics outside the catalog: what no name fits (a second mode, free play of the spring).
OUT_OF_CATALOG = ("second_mode", "free_play")
#: Physics a sweep can hardly tell apart: naming one for another is not a *wrong* name (the suite counts
#: wrong names outside the truth and its groups). Symmetric by construction.
SURROGATE_GROUPS = {
    "quadratic_stiffness": ("asymmetric_stiffness", "end_stop"),
    "asymmetric_stiffness": ("quadratic_stiffness", "end_stop"),
    "end_stop": ("quadratic_stiffness", "asymmetric_stiffness"),
    "quadratic_damping": ("cubic_damping",),
    "cubic_damping": ("quadratic_damping",),
    "coulomb_friction": ("hysteresis",),
    "hysteresis": ("coulomb_friction",),
    "displacement_dependent_damping": (),
    "stiffness_drift": (),
}
#: Drawn range of each effect's force at the pilot's (V, Q) over the spring force Fs there.
RELATIVE_FORCE = {
    "coulomb_friction": (0.02, 0.05), "displacement_dependent_damping": (0.03, 0.08),
    "quadratic_stiffness": (0.03, 0.08), "quadratic_damping": (0.02, 0.06), "cubic_damping": (0.02, 0.06),
    "asymmetric_stiffness": (0.04, 0.10), "hysteresis": (0.03, 0.08), "free_play": (0.02, 0.06),
}
#: Largest sensor noise a narrow draw starts from (fraction of each channel's std); the quietest is
#: sim.detectability.MIN_NOISE, where every effect's own gap is measured.
MAX_NOISE = 0.03
#: Largest response allowed without end stops as the effect: under the rig's 17.5 mm travel with margin.
MAX_RESPONSE_MM = 14.0
#: Smallest response allowed, over the plain rig's: an effect that kills the resonance is not "a few %".
MIN_RESPONSE = 0.35
MAX_TRIES = 30


@dataclass
class Scenario:
    """One randomised case: a rig, a sweep, two sensors, and what is true about them."""

    category: str
    truth_effects: list[str]
    rig: RigParameters
    sweep: SineSweep
    fs_hz: float
    table_sensor: Accelerometer
    mass_sensor: Accelerometer
    settle_s: float = 2.0
    magnitudes: dict = field(default_factory=dict)  # per effect: its parameters and relative force
    pilot: dict = field(default_factory=dict)       # Q (m), V (m/s), Fs (N) of the plain rig
    nuisances: dict = field(default_factory=dict)   # sim.wide.nuisances: quantisation, hum (wide draws)

    def run(self, seed: int | None = 0) -> SyntheticRun:
        """Simulate and measure the scenario (the physics is the same for every seed; `seed` draws the
        sensor noise). The recording's truth holds category, truth_effects and magnitudes."""
        run = run_sweep(self.rig, self.sweep, self.fs_hz, self.settle_s, self.table_sensor, self.mass_sensor, seed)
        run.truth.update(category=self.category, truth_effects=list(self.truth_effects),
                         magnitudes=self.magnitudes, pilot=self.pilot, nuisances=self.nuisances)
        run.recording.metadata["truth"] = run.truth
        return run

    def describe(self) -> str:
        """One line: category, effects with their relative force, rig and sweep."""
        eff = ",".join(f"{n}({self.magnitudes.get(n, {}).get('relative_force', 0) * 100:.1f}%)"
                       for n in self.truth_effects) or "-"
        fn = self.rig.natural_frequency_hz
        noise = max(self.table_sensor.noise_fraction, self.mass_sensor.noise_fraction)
        extra = "".join(f" {k}" for k in self.nuisances)
        return (f"{self.category:14s} {eff:44s} fn={fn:4.1f}Hz Z={self.sweep.amplitude_mm:.2f}mm "
                f"Q={self.pilot.get('Q_m', 0) * 1e3:4.1f}mm "
                f"{self.sweep.f_start_hz:.1f}-{self.sweep.f_end_hz:.1f}Hz/{self.sweep.duration_s:.0f}s "
                f"fs={self.fs_hz:.0f} noise<={noise * 100:.1f}%{extra}")

    def drawn(self) -> dict:
        """Everything drawn, JSON-ready: rig, sweep, sample rate, sensors, effect sizes, pilot, nuisances."""
        return {"category": self.category, "truth_effects": list(self.truth_effects),
                "rig": dataclasses.asdict(self.rig), "sweep": dataclasses.asdict(self.sweep), "fs_hz": self.fs_hz,
                "table_sensor": dataclasses.asdict(self.table_sensor),
                "mass_sensor": dataclasses.asdict(self.mass_sensor), "settle_s": self.settle_s,
                "magnitudes": self.magnitudes, "pilot": self.pilot, "nuisances": self.nuisances}


def make_scenario(rng: np.random.Generator, category: str, effects: list[str] | None = None, *,
                  duration_s: float | None = None, fs_hz: float | None = None, wide: bool = False,
                  detectable: bool = True) -> Scenario:
    """A random scenario of `category` (CATEGORIES); `effects` fixes the truth names instead of drawing
    them (e.g. ["end_stop"] for "single"); `duration_s` and `fs_hz` fix the sweep's length and the sample
    rate (tests use short records); `wide` draws rig, sweep and recording from sim/wide.py's distributions;
    `detectable=False` skips the measured detectability (sim.detectability: noise as drawn, no redraw for an
    effect the plain model hides), to reproduce a case drawn before it.
    Redraws until the physics checks (module docstring)."""
    if category not in CATEGORIES:
        raise ValueError(f"unknown category {category!r}; known: {CATEGORIES}")
    unknown = [n for n in (effects or []) if n not in DRAWS]
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}; known: {sorted(DRAWS)}")
    for _ in range(MAX_TRIES):
        names = list(effects) if effects is not None else _draw_names(rng, category)
        try:
            sc = _draw(rng, category, names, duration_s, fs_hz, wide, detectable)
        except ValueError:  # the pilot or the physics diverged: an unlucky draw
            continue
        if sc is not None:
            return sc
    raise RuntimeError(f"no sane {category} scenario in {MAX_TRIES} draws (effects {effects})")


def _draw_names(rng, category) -> list[str]:
    if category == "single":
        return [str(rng.choice(PHYSICS))]
    if category == "two_effects":
        while True:
            a, b = (str(x) for x in rng.choice(PHYSICS, 2, replace=False))
            if b not in SURROGATE_GROUPS[a]:
                return [a, b]
    if category == "sensor_fault":
        return [str(rng.choice(MEASUREMENT))]
    if category == "out_of_catalog":
        return [str(rng.choice(OUT_OF_CATALOG))]
    return []


def _base(rng, duration_s=None, fs_hz=None):
    """A plain rig, sweep, sample rate and sensors (sensor noise per channel)."""
    m = rng.uniform(0.3, 1.5)
    fn = rng.uniform(3.0, 9.0)
    k = m * (2 * math.pi * fn) ** 2
    zeta = rng.uniform(0.02, 0.06)
    q_target = rng.uniform(4e-3, 11e-3)
    k3 = rng.uniform(0.2, 1.0) * k / q_target**2
    rig = RigParameters(mass_kg=m, damping_ns_per_m=2 * zeta * math.sqrt(k * m), stiffness_n_per_m=k,
                        cubic_stiffness_n_per_m3=k3)
    f0 = max(0.5, rng.uniform(0.3, 0.6) * fn)
    f1 = min(40.0, rng.uniform(2.5, 4.0) * fn)
    sweep = SineSweep(f0, f1, rng.uniform(30.0, 60.0), 2 * zeta * q_target * 1e3)
    fs = float(rng.choice([1000.0, 2048.0]))
    sweep = sweep if duration_s is None else dataclasses.replace(sweep, duration_s=float(duration_s))
    fs = fs if fs_hz is None else float(fs_hz)
    sensors = [Accelerometer(noise_fraction=rng.uniform(MIN_NOISE, MAX_NOISE)) for _ in range(2)]
    return rig, sweep, fs, sensors, q_target


def _pilot(rig, sweep, fs, q_target):
    """Scale the table amplitude so the plain rig peaks near q_target (None: as drawn); (sweep, Q, V, Fs)."""
    quiet = Accelerometer(noise_fraction=0.0)
    for attempt in range(4):
        run = run_sweep(rig, sweep, fs, 2.0, quiet, quiet, None)
        q = run.truth["max_abs_q_m"]
        if q_target is None or abs(q / q_target - 1) < 0.15 or attempt == 3:
            break
        sweep = dataclasses.replace(sweep, amplitude_mm=sweep.amplitude_mm * q_target / q)
    q, v = run.truth["max_abs_q_m"], float(np.max(np.abs(run.states[:, 0])))
    return sweep, q, v, rig.stiffness_n_per_m * q + rig.cubic_stiffness_n_per_m3 * q**3


def _draw(rng, category, names, duration_s=None, fs_hz=None, wide=False, detectable=True) -> Scenario | None:
    """One draw: the plain rig, sweep and sensors, the pilot, each effect (sim.effect_draws), the physics
    check, and the measured detectability; None for a draw make_scenario must redo."""
    rig, sweep, fs, (table, mass), q_target = (wide_draws.draw_base if wide else _base)(rng, duration_s, fs_hz)
    sweep, Q, V, Fs = _pilot(rig, sweep, fs, q_target)
    if wide and Q >= MAX_RESPONSE_MM * 1e-3:
        return None  # the plain rig alone runs too far (wide draws: the amplitude is not rescaled)
    d = Draw(rng, rig, sweep, table, mass, Q, V, Fs)
    own = {name: _draw_effect(d, name) for name in names}
    sc = Scenario(category, list(names), dataclasses.replace(rig, effects=d.effects, **d.fields), sweep, fs, table,
                  mass, magnitudes=d.mags, pilot={"Q_m": Q, "V_ms": V, "Fs_n": Fs, "fn_hz": rig.natural_frequency_hz},
                  nuisances=wide_draws.nuisances(table, mass))
    if not _sane(sc, Q, Fs):
        return None
    return detectability.quiet_enough(sc, rig, own, rng) if detectable else sc


def _draw_effect(d: Draw, name: str) -> detectability.Changes:
    """Draw effect `name` onto d (its rho first, for forces); what it changed of the plain scenario."""
    before = (dict(d.fields), dataclasses.asdict(d.table), dataclasses.asdict(d.mass))
    r = d.rng.uniform(*RELATIVE_FORCE[name]) if name in RELATIVE_FORCE else None
    DRAWS[name](d, r)
    if name in d.effects:
        d.mags[name] = {"value": d.effects[name], "relative_force": r}
    return detectability.Changes(
        rig={**{k: v for k, v in d.fields.items() if k not in before[0]},
             **({"effects": {name: d.effects[name]}} if name in d.effects else {})},
        table={k: v for k, v in dataclasses.asdict(d.table).items() if before[1][k] != v},
        mass={k: v for k, v in dataclasses.asdict(d.mass).items() if before[2][k] != v})


def _sane(sc: Scenario, Q: float, Fs: float) -> bool:
    """The scenario's physics run once without noise (what sc.run() will run): it touches the end stops
    only when they are its effect (then >= 10 samples, their relative force read at the deepest contact),
    else stays between MIN_RESPONSE x the plain peak Q and MAX_RESPONSE_MM."""
    quiet = Accelerometer(noise_fraction=0.0)
    check = run_sweep(sc.rig, sc.sweep, sc.fs_hz, sc.settle_s, quiet, quiet, None)
    contact = check.truth["contact_samples"]
    if "end_stop" in sc.truth_effects:
        lower, upper = (v * 1e-3 for v in sc.rig.travels_mm)
        q2 = check.states[:, 1]
        depth = max(q2.max() - upper, -q2.min() - lower, 0.0)
        sc.magnitudes["end_stop"]["relative_force"] = sc.rig.contact_stiffness_n_per_m * depth / Fs
        return contact >= 10
    return contact == 0 and MIN_RESPONSE * Q < check.truth["max_abs_q_m"] < MAX_RESPONSE_MM * 1e-3
