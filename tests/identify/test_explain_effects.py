"""Explain until explained, against known truth: two effects at once, sensor faults named as such,
hysteresis outside the plain-term physics, and nothing at 3 % noise. Design rig, 1-20 Hz in 30 s at
1.3 mm, sampled at 1000 Hz (band to 100 Hz: the response's harmonics fit), 0.5 % sensor noise."""
import json

import numpy as np
import pytest

from identify.explain.workflow import DiscrepancyAnalysis
from identify.model import SparseModel
from identify.data.recording import Recording
from identify.simulation.simulate import simulate
from sim.rig import RigParameters
from sim.scenarios import make_scenario
from sim.sensors import Accelerometer
from protocol.sweep import SineSweep
from sim.synth import run_sweep

FS = 1000.0
SWEEP = SineSweep(1.0, 20.0, 30.0, 1.3)


def _run(effects=None, noise=0.005, seed=5):
    s = Accelerometer(noise_fraction=noise)
    return run_sweep(RigParameters.design(effects=effects or {}), SWEEP, fs_hz=FS, table_sensor=s, mass_sensor=s,
                     seed=seed).recording


def _delayed(x: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """x(t - tau): a channel recorded tau late (frequency-domain shift)."""
    n, m = x.size, x.mean()
    f = np.fft.rfftfreq(2 * n, 1 / fs)
    return np.fft.irfft(np.fft.rfft(x - m, 2 * n) * np.exp(-2j * np.pi * f * tau), 2 * n)[:n] + m


@pytest.mark.slow
def test_two_effects_are_both_named_with_their_coefficients():
    """Coulomb friction 0.1 N and quadratic damping 2 N s^2/m^2 on one rig: both named, both levels
    within 10 % of truth (the issue saw one named at confidence 1.0 and Coulomb 32 % low). It named cubic
    damping for the quadratic while the simulated mass accelerometer and the model's runs read the kernel's
    chatter about q1 = 0 while the mass was stuck (identify.simulation.simulate.sampled_q1_dot): then
    Coulomb's model left the record's floor, itself raised by that chatter, unmet."""
    res = DiscrepancyAnalysis().fit(_run({"coulomb_friction": 0.1, "quadratic_damping": 2.0})).result()
    names = [e["name"] for e in res["effects"]]
    assert {"coulomb_friction", "quadratic_damping"} <= set(names)
    m = 0.49
    assert res["model"]["q1_dot"]["sign(q1)"] == pytest.approx(-0.1 / m, rel=0.10)
    assert res["model"]["q1_dot"]["q1*|q1|"] == pytest.approx(-2.0 / m, rel=0.10)
    assert res["effect"] == names[0] and res["gap_after"] < 2 * res["noise_floor"]
    assert all(set(e) >= {"name", "kind", "terms", "coefficients", "confidence", "gap_after", "surrogate_for"}
               for e in res["effects"])
    json.dumps(res)


@pytest.mark.slow
def test_mass_accelerometer_gain_is_named_as_a_gain():
    """A -3 % gain error of the mass accelerometer is a measurement effect with its value, not physics
    (the issue saw displacement-dependent damping at 0.89-0.95, its sign following the gain's; +3 % is
    named too, docs/discrepancy.md)."""
    gain = -0.03
    rec = _run()
    rec.output[:] = rec.output * (1 + gain)
    res = DiscrepancyAnalysis().fit(rec).result()
    first = res["effects"][0]
    assert "gain" in res["effect"] and first["kind"] == "measurement"
    assert first["coefficients"]["mass_acc_gain"] == pytest.approx(gain, abs=0.005)
    assert not [e for e in res["effects"] if e["kind"] == "physics" and e["confidence"] >= 0.5]
    assert res["gap_closed"] > 0.5


@pytest.mark.slow
def test_channel_delay_is_named_as_a_delay():
    """The mass channel 1 ms late: channel_delay with its value (the issue saw energy-injecting quadratic
    damping at confidence 0.89)."""
    rec = _run()
    rec.output[:] = _delayed(rec.output, 1e-3, FS)
    res = DiscrepancyAnalysis().fit(rec).result()
    assert "delay" in res["effect"] and res["effects"][0]["kind"] == "measurement"
    assert res["effects"][0]["coefficients"]["channel_delay"] == pytest.approx(1e-3, abs=1e-4)
    assert res["gap_closed"] > 0.5


def _bouc_wen_recording(a=0.3, saturation_m=2e-3, noise=0.005, seed=5):
    """Design rig plus a Bouc-Wen force F = a k z, z' = q1 - beta |q1| z - gamma q1 |z| (beta = gamma,
    z saturating at `saturation_m`), measured by two accelerometers."""
    rig = RigParameters.design()
    eq = dict(rig.model().equations["q1_dot"])
    eq["z"] = -a * rig.stiffness_n_per_m / rig.mass_kg
    s = 1.0 / saturation_m
    model = SparseModel({"q1_dot": eq, "q2_dot": {"q1": 1.0}, "z_dot": {"q1": 1.0, "|q1|*z": -s / 2, "q1*|z|": -s / 2}},
                        states=("q1", "q2", "z"))
    n = int((SWEEP.duration_s + 2) * FS) + 1
    zdd = SWEEP.kinematics(np.arange(n) / FS)[2]
    states = simulate(model, 1 / FS, [0, 0, 0], zdd[:, None], substeps=16).states
    qdd = model.rhs(states, zdd[:, None])[:, 0]
    rng, sensor = np.random.default_rng(seed), Accelerometer(noise_fraction=noise)
    return Recording(sensor.measure(zdd, rng), sensor.measure(qdd + zdd, rng), FS, "base", source="Bouc-Wen rig")


@pytest.mark.slow
def test_hysteresis_is_named_or_flagged():
    """Bouc-Wen hysteresis (the issue saw `none` at confidence 1.0, gap 25x the noise floor): named as
    hysteresis, or `unexplained`, or a surrogate flagged as such that closes at least half the gap."""
    res = DiscrepancyAnalysis().fit(_bouc_wen_recording()).result()
    assert res["gap_before"] > 3 * res["noise_floor"]
    if res["effect"] == "hysteresis":
        assert res["gap_closed"] >= 0.5 and res["model"]["q1_dot"]["z"] < 0
    elif res["effect"] == "unexplained":
        assert res["remaining"]["segments"]
    else:
        assert res["effects"][0]["surrogate_for"] and res["gap_closed"] >= 0.5


def test_plain_rig_at_three_percent_noise_answers_none():
    res = DiscrepancyAnalysis().fit(_run(noise=0.03)).result()
    assert res["effect"] == "none" and res["effects"] == [] and res["confidence"] > 0.5
    assert res["gap_before"] <= 2 * res["noise_floor"]


@pytest.mark.parametrize("channel, change", [("table", 0.03), ("mass", -0.03)])
def test_bias_drift_is_named_from_the_raw_channel(channel, change):
    """A sensor bias drifting by 0.03 m/s^2 over the record never reaches the band-limited states, so no
    gap shows it (the suite's drifts left gaps at 0.8-1.0x the noise floor and were answered `none`);
    the raw channel below the band does (identify.explain.drift). Measured on the suite's five drift cases:
    t = 12-198 and the change within 0.1-5.5 % of the truth; on the clean rigs beside them |t| <= 2.5.
    Asked: named, on the right channel, within 15 %; the other channel not named."""
    drifting = Accelerometer(noise_fraction=0.005, bias_drift_ms2=change)
    clean = Accelerometer(noise_fraction=0.005)
    sensors = {"table_sensor": drifting if channel == "table" else clean,
               "mass_sensor": drifting if channel == "mass" else clean}
    rec = run_sweep(RigParameters.design(), SWEEP, fs_hz=FS, seed=5, **sensors).recording
    res = DiscrepancyAnalysis().fit(rec).result()
    assert res["effect"] == "bias_drift", res["effects"]
    drifts = [e for e in res["effects"] if e["name"] == "bias_drift"]
    assert len(drifts) == 1 and drifts[0]["kind"] == "measurement" and drifts[0]["confidence"] > 0.99
    assert drifts[0]["coefficients"] == {f"bias_drift_{channel}": pytest.approx(change, rel=0.15)}


@pytest.mark.slow
def test_one_sided_end_stop_is_named_with_its_side_travel_and_contact():
    """A stop above the mass only (case 72 of benchmarks/explain_robustness.py: travel 1.59 mm, contact
    stiffness 11300 N/m per kg, damping 47 N s/m per kg, 1000 Hz, 30 s): end_stop, one sided above, its
    travel within 3 % and the contact's spring and damping within 25 % of the truth, the gap more than
    halved. Before, the two-sided fit pushed outwards by 0.7 % on the side without a stop, was rejected,
    and the answer was `unexplained` (the best admissible candidate closed 13 %)."""
    sc = make_scenario(np.random.default_rng([12, 72]), "single", ["end_stop"])
    truth, m = sc.magnitudes["end_stop"], sc.rig.mass_kg
    assert truth["side"] == "upper"
    res = DiscrepancyAnalysis().fit(sc.run(seed=72).recording).result()
    first = res["effects"][0]
    c = first["coefficients"]
    assert res["effect"] == "end_stop" and c["sides"] == "upper"
    assert c["travel_m"] == pytest.approx(truth["gap_mm"] * 1e-3, rel=0.03)
    # one sided: the asymmetry terms equal the symmetric ones, so the lower side feels nothing
    assert c["sign(q2)*stop(q2)"] == c["stop(q2)"] and c["q1*sign(q2)*contact(q2)"] == c["q1*contact(q2)"]
    assert -2 * c["stop(q2)"] == pytest.approx(truth["contact_stiffness_n_per_m"] / m, rel=0.25)
    assert -2 * c["q1*contact(q2)"] == pytest.approx(sc.rig.contact_damping_ns_per_m / m, rel=0.25)
    assert res["gap_closed"] >= 0.5


def _suite_case(i: int, category: str, names=None, detectable: bool = True):
    """Case i of benchmarks/explain_robustness.py (seed 12): its scenario and the analysis' result
    (detectable=False: drawn as before sim.detectability measured each effect's gap)."""
    sc = make_scenario(np.random.default_rng([12, i]), category, names, detectable=detectable)
    return sc, DiscrepancyAnalysis().fit(sc.run(seed=i).recording).result()


def _physics_names(res, at_least=0.5):
    return [e["name"] for e in res["effects"] if e["kind"] == "physics" and e["confidence"] >= at_least]


@pytest.mark.slow
def test_a_soft_contact_after_the_named_effect_is_not_called_an_end_stop():
    """Case 22, a stiffness drift: once it was named, a one-sided `end_stop` of 6.4 N/m per kg on a rig of
    1894 took 38 % of a gap at 1.2x the noise floor at confidence 0.95. A contact softer than the rig's own
    spring is no stop (identify.explain.admissibility): only the drift is named. That draw (a 6.9 Hz rig,
    3.8-23.6 Hz in 32 s, 1.4 % noise) was later answered `none` (the drift's gap 1.21x the floor after
    trimming: an xfail here); sim.detectability now finds the drift's own gap there under DETECTABLE x the
    floor even at MIN_NOISE and redraws: a 3.9 Hz rig, r = -5.2 % over 2.2-11.7 Hz in 50 s, 0.3 % noise."""
    sc, res = _suite_case(22, "single", ["stiffness_drift"])
    assert sc.truth_effects == ["stiffness_drift"]
    assert res["effect"] == "stiffness_drift" and _physics_names(res) == ["stiffness_drift"]
    # the rule is what removes it (without it the same run names end_stop at 0.95): no stop softer than
    # the spring is admissible in any round
    k = -res["model"]["q1_dot"]["q2"]
    stops = [c for rnd in res["rounds"] for c in rnd if c["name"] == "end_stop"]
    assert stops and all(c["rejected"] for c in stops
                         if -c["coefficients"]["stop(q2)"] + abs(c["coefficients"]["sign(q2)*stop(q2)"]) < k)


@pytest.mark.slow
def test_hysteresis_and_quadratic_stiffness_are_named_and_nothing_else():
    """Case 88: Bouc-Wen hysteresis (5.9 % of the spring force) and quadratic stiffness (4.3 %). With the
    explanation refit for 12 evaluations only, 1.79x the noise floor was left and cubic damping was named
    for it at confidence 1.0; refit to convergence (explain.POLISH_NFEV) it leaves about 1.1x. Both true
    effects named, no third physical name, the quadratic stiffness within 5 % of the truth. Drawn without
    the detectability measurement: the quadratic stiffness alone leaves a gap under the floor (0.00066
    against 0.00084 at 0.2 % noise) and would be redrawn; beside the hysteresis it is named all the same."""
    sc, res = _suite_case(88, "two_effects", detectable=False)
    assert sorted(sc.truth_effects) == ["hysteresis", "quadratic_stiffness"]
    assert sorted(_physics_names(res)) == ["hysteresis", "quadratic_stiffness"]
    q = sc.magnitudes["quadratic_stiffness"]["value"]
    assert res["model"]["q1_dot"]["q2^2"] == pytest.approx(-q / sc.rig.mass_kg, rel=0.05)
    assert res["gap_after"] < 1.5 * res["noise_floor"]
