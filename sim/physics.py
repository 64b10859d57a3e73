"""The rig's physics beyond the textbook Duffing terms, as SparseModel equations (used by sim/rig.py).

The ground truth of the discrepancy suite is described here on the simulator's own terms, not taken
from identify/explain/effects.py (the catalog the suite judges): a force F on the mass enters as -F/m in
dq1/dt. Everything is a sum of products of features (identify.regression.terms), so the compiled RK4 kernel runs
it; physics that is not a term of (q1, q2) gets extra states or an extra input:

- cubic_damping            F = c3 q1^3                                         (term q1^3)
- asymmetric_stiffness     F = dk max(q2, 0) = dk (q2 + |q2|)/2, or dk min(q2, 0) = dk (q2 - |q2|)/2
- end stops per side       travel L below, U above (m): equal: stop(q2), q1*contact(q2) at d = U;
                           one side only (d, s = +-1): (stop(q2) + s sign(q2) stop(q2))/2 (and the same
                           for contact), which is the stop on that side only (sign(q2) = s in contact,
                           and stop(q2) = 0 near q2 = 0 where sign jumps); two different travels: a
                           contact coordinate qe = q2 - (U - L)/2 (qe' = q1) with a symmetric travel
                           (U + L)/2, so the kernel's contact stepping applies unchanged.
- stiffness_drift          k(t) = k (1 + r t/T): an input `drift` = t/T on the fine grid, term q2*drift
- hysteresis (Bouc-Wen)    F = a k z; z' = A q1 - beta |q1| |z|^(n-1) z - gamma q1 |z|^n, a state z (m),
                           integer n (1..3): |z|^(n-1) z is z^n (n odd) or z^(n-1)|z| (n even)
- absorber (second mode)   states qa1, qa2: absorber velocity and displacement relative to the mass;
                           F = -(k_a qa2 + c_a qa1) on the mass; qa'' = -(k_a qa2 + c_a qa1)/m_a - q'' - z''
- spring free play         the linear spring's force k dz(q2, g), dz(q, g) = sign(q) max(|q| - g, 0):
                           stop() of a coordinate qf = q2 with travel g (the kernel cuts steps at +-g)

The mass accelerometer reads q'' + z'' at the samples (mass_acceleration): the equation's value, except
where Coulomb friction holds the mass to the table (Filippov's sliding condition at q1 = 0), where q'' is 0;
the kernel's RK4 steps through sign(q1)'s jump, and its q1 chatters about 0 while the mass is stuck.
No change to the compiled kernel was needed: it carries up to 8 states and 8 inputs. Accuracy of
run_sweep against these laws integrated independently by DOP853 at rtol 1e-10 (tests/sim/
test_effects_physics.py, 6.5 s sweeps at 1 kHz): 1e-9 of the peak displacement for the smooth ones
(cubic damping, drift, absorber: 16 substeps), 2e-9 for Bouc-Wen (n = 1, 2) and asymmetric stiffness
(|q1|, |z|, |q2| kinks: 64 substeps), 2.5e-6 and 6e-6 with hard (7.7e5 N/m) end-stop contacts and free
play, where DOP853 steps through the kinks the kernel cuts its steps at.
"""
from __future__ import annotations

import math

import numpy as np

from identify.model import SparseModel
from identify.simulation.simulate import sampled_q1_dot
from identify.regression.terms import FeatureSpace

#: Plain-term physics built here rather than by RigParameters' own path; every effect's force,
#: F = value * sum(weight * term), is its class's (identify.explain.effects, Effect.force). asymmetric_stiffness is
#: given for the q > 0 side; asymmetric_side = -1 flips the |q2| weight.
SIM_TERM_EFFECTS = ("cubic_damping", "asymmetric_stiffness")
#: Effect names that are not `effects` entries but fields (physics) or sensor faults (measurement).
NOT_AN_EFFECTS_ENTRY = {
    "end_stop": "RigParameters end_stop_travel_mm / end_stop_lower_mm / end_stop_upper_mm",
    "stiffness_drift": "RigParameters stiffness_drift",
    "hysteresis": "RigParameters hysteresis_alpha, hysteresis_beta, hysteresis_gamma, hysteresis_n",
    "mass_acc_gain": "Accelerometer gain (the mass sensor)",
    "table_acc_gain": "Accelerometer gain (the table sensor)",
    "channel_delay": "Accelerometer delay_s",
    "bias_drift": "Accelerometer bias_drift_ms2",
}
#: Fields of RigParameters this module adds, with their defaults (to_dict writes them only when set).
EXTRA_DEFAULTS = {"end_stop_lower_mm": None, "end_stop_upper_mm": None, "asymmetric_side": 1,
                  "stiffness_drift": 0.0, "hysteresis_alpha": 0.0, "hysteresis_A": 1.0, "hysteresis_beta": 0.0,
                  "hysteresis_gamma": 0.0, "hysteresis_n": 1, "absorber_mass_kg": 0.0,
                  "absorber_stiffness_n_per_m": 0.0, "absorber_damping_ns_per_m": 0.0, "spring_free_play_mm": 0.0}


def check_effects(effects: dict, catalog: dict) -> None:
    for name in effects:
        if name in NOT_AN_EFFECTS_ENTRY:
            raise ValueError(f"effect {name!r} is not an effects entry: set {NOT_AN_EFFECTS_ENTRY[name]}")
    known = set(catalog) | set(SIM_TERM_EFFECTS)
    unknown = set(effects) - known
    if unknown:
        raise ValueError(f"unknown effect(s) {sorted(unknown)}; known: {sorted(known)}")


def check_rig(rig) -> None:
    """Refuse physics that is not physical or not runnable, by field name."""
    finite = ("stiffness_drift", "hysteresis_alpha", "hysteresis_A", "hysteresis_beta", "hysteresis_gamma")
    for name in finite:
        if not math.isfinite(getattr(rig, name)):
            raise ValueError(f"{name} must be finite, got {getattr(rig, name)}")
    if rig.asymmetric_side not in (1, -1):
        raise ValueError(f"asymmetric_side must be +1 (q > 0) or -1 (q < 0), got {rig.asymmetric_side}")
    if not rig.stiffness_drift > -1:
        raise ValueError(f"stiffness_drift must be > -1 (the spring keeps a positive stiffness), got {rig.stiffness_drift}")
    if rig.hysteresis_n not in (1, 2, 3):
        raise ValueError(f"hysteresis_n must be 1, 2 or 3, got {rig.hysteresis_n}")
    if rig.hysteresis_alpha and not rig.hysteresis_beta + rig.hysteresis_gamma > 0:
        raise ValueError("Bouc-Wen needs hysteresis_beta + hysteresis_gamma > 0 (else z is unbounded)")
    if not (0 <= rig.absorber_mass_kg < math.inf and 0 <= rig.absorber_damping_ns_per_m < math.inf):
        raise ValueError("absorber mass and damping must be finite and non-negative")
    if rig.absorber_mass_kg > 0 and not 0 < rig.absorber_stiffness_n_per_m < math.inf:
        raise ValueError("an absorber needs a positive, finite absorber_stiffness_n_per_m")
    if not 0 <= rig.spring_free_play_mm < math.inf:
        raise ValueError(f"spring_free_play_mm must be finite and non-negative, got {rig.spring_free_play_mm}")


def extra_physics(rig) -> bool:
    """True when the rig needs more than the states (q1, q2) and the input zdd."""
    return bool(rig.stiffness_drift or rig.hysteresis_alpha or rig.absorber_mass_kg > 0 or rig.spring_free_play_mm > 0)


def general(rig) -> bool:
    """True when the model is built here rather than by RigParameters' own (unchanged) path."""
    return (extra_physics(rig) or any(n in SIM_TERM_EFFECTS for n in rig.effects)
            or rig.end_stop_lower_mm is not None or rig.end_stop_upper_mm is not None)


def extra_fields(rig) -> dict:
    return {k: getattr(rig, k) for k, d in EXTRA_DEFAULTS.items() if getattr(rig, k) != d}


def _bouc_wen_terms(n: int) -> tuple[str, str]:
    """(|q1| |z|^(n-1) z, q1 |z|^n) as term names for integer n."""
    zz = lambda p: "" if p == 0 else ("*z" if p == 1 else f"*z^{p}")  # noqa: E731
    if n % 2:  # n odd: |z|^(n-1) z = z^n, |z|^n = z^(n-1) |z|
        return f"|q1|{zz(n)}", f"q1{zz(n - 1)}*|z|"
    return f"|q1|{zz(n - 1)}*|z|", f"q1{zz(n)}"


def _layout(rig, end_stops: bool):
    """States, inputs, travel (m) and the end-stop description of the model."""
    states, inputs, travel = ["q1", "q2"], ["zdd"], {}
    if rig.hysteresis_alpha:
        states.append("z")
    if rig.absorber_mass_kg > 0:
        states += ["qa1", "qa2"]
    if rig.spring_free_play_mm > 0:
        states.append("qf")
        travel["qf"] = rig.spring_free_play_mm * 1e-3
    if rig.stiffness_drift:
        inputs.append("drift")
    stops = None
    if end_stops and rig.end_stops:
        lower, upper = (v * 1e-3 for v in rig.travels_mm)
        if lower == upper:
            stops = ("q2", 0)
            travel["q2"] = upper
        elif math.isinf(lower) or math.isinf(upper):
            stops = ("q2", 1 if math.isinf(lower) else -1)
            travel["q2"] = min(lower, upper)
        else:
            stops = ("qe", 0)
            states.append("qe")
            travel["qe"] = 0.5 * (upper + lower)
    return states, inputs, travel, stops


def build_model(rig, q1_base: dict, end_stops: bool) -> SparseModel:
    """The rig's equations with every field of sim/rig.py's docstring (see this module's docstring)."""
    states, inputs, travel, stops = _layout(rig, end_stops)
    space = FeatureSpace(tuple(states), tuple(inputs), travel)
    eqs: dict[str, dict[str, float]] = {f"{s}_dot": {} for s in states}

    def add(eq: str, term: str, coef: float) -> None:
        name = space.parse(term).name
        eqs[eq][name] = eqs[eq].get(name, 0.0) + coef

    m, k = rig.mass_kg, rig.stiffness_n_per_m
    spring = "stop(qf)" if rig.spring_free_play_mm > 0 else "q2"
    for term, coef in q1_base.items():
        add("q1_dot", spring if term == "q2" else term, coef)
    if rig.stiffness_drift:
        add("q1_dot", f"{spring}*drift", -k * rig.stiffness_drift / m)
    from identify.explain.effects import CATALOG
    for name, value in rig.effects.items():
        weights = dict(CATALOG[name].force)
        if name == "asymmetric_stiffness" and rig.asymmetric_side == -1:
            weights["|q2|"] = -weights["|q2|"]
        for term, w in weights.items():
            add("q1_dot", term, -value * w / m)
    if rig.hysteresis_alpha:
        add("q1_dot", "z", -rig.hysteresis_alpha * k / m)
        t_beta, t_gamma = _bouc_wen_terms(rig.hysteresis_n)
        add("z_dot", "q1", rig.hysteresis_A)
        add("z_dot", t_beta, -rig.hysteresis_beta)
        add("z_dot", t_gamma, -rig.hysteresis_gamma)
    if stops is not None:
        state, side = stops
        kc, cc = rig.contact_stiffness_n_per_m / m, rig.contact_damping_ns_per_m / m
        for term, coef in ((f"stop({state})", -kc), (f"q1*contact({state})", -cc)):
            add("q1_dot", term, coef if side == 0 else 0.5 * coef)
            if side:
                add("q1_dot", f"{term}*sign({state})", 0.5 * side * coef)
    if rig.absorber_mass_kg > 0:
        ka, ca, ma = rig.absorber_stiffness_n_per_m, rig.absorber_damping_ns_per_m, rig.absorber_mass_kg
        add("q1_dot", "qa2", ka / m)
        add("q1_dot", "qa1", ca / m)
        for term, coef in list(eqs["q1_dot"].items()):  # qa'' = -(k_a qa + c_a qa')/m_a - q'' - z''
            add("qa1_dot", term, -coef)
        add("qa1_dot", "zdd", -1.0)
        add("qa1_dot", "qa2", -ka / ma)
        add("qa1_dot", "qa1", -ca / ma)
        add("qa2_dot", "qa1", 1.0)
    for s in states[1:]:
        if s not in ("z", "qa1", "qa2"):
            add(f"{s}_dot", "q1", 1.0)
    return SparseModel(eqs, states=tuple(states), inputs=tuple(inputs), travel=travel or None)


def initial_state(rig, model: SparseModel) -> list[float]:
    """Rest (q = 0): every state 0 but the end-stop coordinate qe = q2 - (U - L)/2."""
    x0 = [0.0] * len(model.states)
    if "qe" in model.states:
        lower, upper = (v * 1e-3 for v in rig.travels_mm)
        x0[model.states.index("qe")] = -0.5 * (upper - lower)
    return x0


def mass_acceleration(model: SparseModel, states: np.ndarray, u: np.ndarray, dt_s: float) -> np.ndarray:
    """The mass's absolute acceleration x'' = q'' + z'' (m/s^2) at the samples, what the mass accelerometer
    reads: states (n, >= model's) and inputs u (n, >= model's) as the kernel integrated them, dt_s apart.
    q'' as identify.simulation.simulate.sampled_q1_dot reads it: 0 where Coulomb friction holds the mass
    to the table (the kernel's chatter about q1 = 0 is no rig's)."""
    states = np.asarray(states, dtype=float)[:, :len(model.states)]
    u = np.asarray(u, dtype=float)[:, :len(model.inputs)]
    return sampled_q1_dot(model, states, u, dt_s) + u[:, 0]
