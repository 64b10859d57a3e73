"""The measured counterpart (identify.frf.measured) on simulated sweeps with known truth: up and down
sweeps of the Table 1 rig at three table amplitudes, each with a predicted fold; the measured jump lies
between the steady-state fold and the fold + the stated sweep-rate bias, give or take its uncertainty."""
import numpy as np
import pytest

from identify.frf.measured import compare_sweep, cycle_envelope, measured_jump, sweep_envelope
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from protocol.sweep import SineSweep
from sim.synth import run_sweep
from identify.data.recording import Recording
from identify.errors import IdentificationError

RIG = RigParameters.paper_table1()
NOISE = 0.005


def _record(amplitude_mm, direction, seed):
    sweep = SineSweep(3.0, 9.0, 20.0, amplitude_mm) if direction == "up" else SineSweep(9.0, 3.0, 20.0, amplitude_mm)
    sensor = Accelerometer(noise_fraction=NOISE)
    return run_sweep(RIG, sweep, table_sensor=sensor, mass_sensor=sensor, seed=seed)


@pytest.mark.slow
@pytest.mark.parametrize("amplitude_mm", [1.0, 1.1, 1.2])
@pytest.mark.parametrize("direction", ["up", "down"])
def test_measured_jump_agrees_with_the_predicted_fold_within_the_sweep_rate_bias(amplitude_mm, direction):
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    run = _record(amplitude_mm, direction, seed)
    cmp = compare_sweep(RIG.model(), run.recording)
    assert cmp["direction"] == direction
    assert cmp["amplitude_mm"] == pytest.approx(amplitude_mm, rel=2e-3)
    assert cmp["rate_hz_per_s"] == pytest.approx((6.0 if direction == "up" else -6.0) / 20.0, rel=1e-2)
    jump, fold, bias = cmp["measured"], cmp["fold_hz"], cmp["bias_hz"]
    assert jump is not None and fold is not None and bias is not None
    # the sweep lags the steady state: an up-sweep jumps down above its fold, a down-sweep up below it
    assert bias > 0 if direction == "up" else bias < 0
    print(f"{direction} {amplitude_mm} mm: measured {jump['frequency_hz']:.3f} +- {jump['uncertainty_hz']:.3f} Hz, "
          f"fold {fold:.3f} Hz, bias {bias:+.3f} Hz")
    assert cmp["agrees"], cmp
    # and the steady-state fold alone (no bias) would not explain an up-sweep's jump: the bias is real
    if direction == "up":
        assert jump["frequency_hz"] - jump["uncertainty_hz"] > fold


def test_envelope_is_the_true_response_envelope():
    """The per-cycle envelope read from the two noisy accelerometers (through the chain's band-limited
    integration) is that of the true relative displacement within 1.5 %, wherever the response is loud;
    its frequency is the sweep's within 0.5 %."""
    run = _record(1.1, "up", int(np.random.SeedSequence().entropy % 2**32))
    env = sweep_envelope(run.recording)
    fs = run.recording.fs_hz
    rows = env["signals"].valid  # the true displacement cut in the same table cycles
    true = cycle_envelope(run.states[rows, 1], np.asarray(env["signals"].input[rows]), fs)
    true_t = true["t_s"] + rows.start / fs
    loud = env["response_mm"] > 0.3 * env["response_mm"].max()
    jump = measured_jump(env)
    away = np.abs(env["t_s"] - jump["t_s"]) > 0.5       # the jump itself: one cycle's shift is 2x
    sel = loud & away & (env["t_s"] > 3.0)
    assert sel.sum() > 20
    same = np.searchsorted(true_t, env["t_s"][sel])
    assert np.allclose(true_t[same], env["t_s"][sel])
    assert np.allclose(env["response_mm"][sel], true["response_mm"][same], rtol=0.015)
    assert np.allclose(env["frequency_hz"][sel], run.sweep.frequency_hz(env["t_s"][sel] - 0.0), rtol=5e-3)


def test_a_sweep_without_a_fold_agrees_with_the_models_own_sweep():
    """At 0.6 mm the model has no fold; whatever steep passage the sweep shows, the model's own run over
    the recorded table motion shows it at the same frequency."""
    run = _record(0.6, "up", int(np.random.SeedSequence().entropy % 2**32))
    cmp = compare_sweep(RIG.model(), run.recording)
    assert cmp["fold_hz"] is None and cmp["bias_hz"] is None
    assert cmp["agrees"], cmp


@pytest.mark.slow
def test_the_jump_is_where_the_response_leaves_its_branch_not_a_later_beat():
    """The paper's sweep (1-20 Hz in 60 s at 1.3 mm): past the jump the transient beats against the forcing
    (3.4 -> 5.4 -> 2.2 mm), and a beat's node is a larger ratio than the jump (14.0 -> 10.4 -> 4.4 mm). The
    measured jump is the fall from the upper branch: its transition holds the cycle where the true
    response first drops below half its peak, and its frequency is within a cycle of it (the ratio rule
    answered the node 0.18 Hz later, 8 cycles). The model's own run jumps there too."""
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    run = run_sweep(RIG, SineSweep(1.0, 20.0, 60.0, 1.3), table_sensor=Accelerometer(noise_fraction=NOISE),
                    mass_sensor=Accelerometer(noise_fraction=NOISE), seed=seed)
    env = sweep_envelope(run.recording)
    rows = env["signals"].valid
    true = cycle_envelope(run.states[rows, 1], np.asarray(env["signals"].input[rows]), run.recording.fs_hz)
    a, f = true["response_mm"], true["frequency_hz"]
    peak = int(np.argmax(a))
    fall = peak + int(np.flatnonzero(a[peak:] < 0.5 * a[peak])[0])  # first cycle off the upper branch
    cycle_hz = f[fall] - f[fall - 1]
    cmp = compare_sweep(RIG.model(), run.recording)
    jump = cmp["measured"]
    print(f"true fall at {f[fall - 1]:.3f}-{f[fall]:.3f} Hz; measured {jump['frequency_hz']:.3f} "
          f"+- {jump['uncertainty_hz']:.3f} Hz; the model's own run {cmp['model_sweep_jump']['frequency_hz']:.3f} Hz")
    assert jump["frequency_hz"] - jump["uncertainty_hz"] <= f[fall] + 1e-9
    assert jump["frequency_hz"] + jump["uncertainty_hz"] >= f[fall - 1] - 1e-9
    assert abs(jump["frequency_hz"] - 0.5 * (f[fall - 1] + f[fall])) <= cycle_hz
    assert abs(cmp["model_sweep_jump"]["frequency_hz"] - jump["frequency_hz"]) <= jump["uncertainty_hz"] + cycle_hz
    assert cmp["agrees"], cmp


@pytest.mark.parametrize("direction, rest_s", [("up", 15.0), ("down", 15.0), ("up", 60.0)])
def test_rest_before_and_after_the_sweep_leaves_the_table_amplitude_and_jump(direction, rest_s):
    """A recorder started before the PLC's start and stopped after its end holds the table at rest: its
    sensor noise makes short "cycles" of any level, a few at the sweep's. The median of all cycles had read
    0.68 mm for a 1.2 mm sweep with 5 s of settle (and, most likely, the 1.049 mm seen once through the
    service under load). The table amplitude is the level holding the table's motion, the sweep's rate and
    jump those of its own cycles (steady_cycles), with rest up to three times the sweep on each side."""
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    run = _record(1.1, direction, seed)
    rec = run.recording
    rng = np.random.default_rng([seed, 1])
    rest = int(rest_s * rec.fs_hz)
    # the rest as the sensors read it: their noise (NOISE of each channel's motion over the sweep), no motion
    table, mass = (Accelerometer(noise_fraction=0.0, noise_ms2=NOISE * float(np.std(x)))
                   for x in (run.table_acc_true, run.mass_acc_true))
    def rested(sensor, x):
        return np.concatenate([sensor.measure(np.zeros(rest), rng), x, sensor.measure(np.zeros(rest), rng)])

    rested = Recording(rested(table, rec.input), rested(mass, rec.output), rec.fs_hz)
    env, plain = sweep_envelope(rested), sweep_envelope(rec)
    assert env["cycles"]["edges"].size > plain["cycles"]["edges"].size + 50  # the rest made cycles of its own
    sweep_s = rec.n_samples / rec.fs_hz
    assert rest_s < env["t_s"].min() and env["t_s"].max() < rest_s + sweep_s  # none of the rest's is kept
    assert env["amplitude_mm"] == pytest.approx(1.1, rel=2e-3)
    assert env["rate_hz_per_s"] == pytest.approx((6.0 if direction == "up" else -6.0) / 20.0, rel=1e-2)
    jump, alone = measured_jump(env), measured_jump(plain)
    # the same jump within its uncertainty (the rest moves the chain's band a little), in time as in frequency:
    # a down-sweep's rise is smeared over many cycles (+-0.2 Hz, ~0.7 s at 0.3 Hz/s; 0.55 s seen once)
    assert jump["frequency_hz"] == pytest.approx(alone["frequency_hz"], abs=alone["uncertainty_hz"])
    smeared_s = alone["uncertainty_hz"] / abs(plain["rate_hz_per_s"])
    assert jump["t_s"] == pytest.approx(alone["t_s"] + rest_s, abs=smeared_s)


def test_a_table_without_a_steady_amplitude_is_refused():
    """A recording whose table amplitude wanders (here the sweep's samples scaled by 0.3-3x) has no level
    holding STEADY_SHARE of the table's motion: said, not read at one end."""
    run = _record(1.1, "up", int(np.random.SeedSequence().entropy % 2**32))
    rec = run.recording
    g = np.geomspace(0.3, 3.0, rec.n_samples)
    with pytest.raises(IdentificationError, match="not a sine sweep at one amplitude"):
        sweep_envelope(Recording(rec.input * g, rec.output * g, rec.fs_hz))


@pytest.mark.slow
def test_fresh_sweeps_with_rest_read_their_amplitude_and_rate():
    """Sweeps drawn wide (four bands up or down, 10-90 s, 0.5-1.5 mm, settle 0.5-60 s, noise 0.2-5 %, mains
    hum 0-5 %; a new seed each run) read their table amplitude within 1 % and their rate within 5 %, none
    refused (docs/frf.md: of 120 drawn from 5 s on, 119 within 1 % and 3 %; the other, a 5 s sweep, left the
    chain 5 cycles: sweeps that short are not drawn here)."""
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    for _ in range(12):
        lo, hi = [(1.0, 20.0), (3.0, 9.0), (2.0, 15.0), (4.0, 8.0)][rng.integers(4)]
        lo, hi = (lo, hi) if rng.random() < 0.5 else (hi, lo)
        duration_s, amplitude_mm = float(rng.uniform(10, 90)), float(rng.uniform(0.5, 1.5))
        settle_s = float(rng.choice([0.5, 2.0, 10.0, 30.0, 60.0]))
        sensor = Accelerometer(noise_fraction=float(np.exp(rng.uniform(np.log(0.002), np.log(0.05)))),
                               hum_fraction=float(rng.choice([0.0, 0.0, 0.01, 0.05])))
        run = run_sweep(RIG, SineSweep(lo, hi, duration_s, amplitude_mm), settle_s=settle_s, table_sensor=sensor,
                        mass_sensor=sensor, seed=int(rng.integers(2**31)))
        env = sweep_envelope(run.recording)
        case = (lo, hi, duration_s, amplitude_mm, settle_s, sensor)
        assert env["amplitude_mm"] == pytest.approx(amplitude_mm, rel=0.01), case
        assert env["rate_hz_per_s"] == pytest.approx((hi - lo) / duration_s, rel=0.05), case
