"""Identification you can trust (issue 11), against simulated rigs with known coefficients:
standard errors that cover the truth, inclusion probabilities that tell real terms from spurious ones,
and reported coefficients that do not depend on where the held-out blocks fall."""
import numpy as np
import pytest

import identify.trust.uncertainty as unc
from identify.chain.states import reconstruct_states
from identify.errors import IdentificationError
from identify.regression.gram import BlockGram
from identify.identifier import SparseIdentifier, holdout_blocks
from identify.regression.optimizers.base import least_squares
from identify.simulation.validation import validate
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from protocol.sweep import SineSweep

WEAK = "q1*q2^2"
TABLE1_WEAK = 1.1620e4


def _sensors(noise):
    return dict(table_sensor=Accelerometer(noise_fraction=noise), mass_sensor=Accelerometer(noise_fraction=noise))


def _random_case(rng):
    """The Table 1 rig or the design rig with a random pre-stress and damping; 0.8-1.3 mm; noise
    log-uniform 0.3-6 % on both accelerometers."""
    if rng.random() < 0.5:
        rig = RigParameters.paper_table1()
    else:
        rig = RigParameters.design(prestress_m=rng.uniform(1.5e-3, 2.2e-3),
                                   damping_ns_per_m=3.7294 * 0.49 * rng.uniform(0.7, 1.5))
    return rig, rng.uniform(0.8, 1.3), float(np.exp(rng.uniform(np.log(0.003), np.log(0.06))))


@pytest.mark.slow
def test_standard_errors_cover_the_truth_on_randomised_rigs():
    """Truth within 2 SE for ~95 % and 3 SE for ~99 % of terms x cases. 24 cases give ~110 trials,
    correlated within a case; at a true coverage of 95 % / 99 % the binomial 3-sigma lower bounds for
    110 independent trials are 0.89 / 0.96, so we ask 0.88 / 0.96. The SE must not be inflated either:
    at most 90 % within 1 SE (Gaussian: 68 %; an SE twice too large gives 95 %). Measured on these cases
    (benchmarks/coverage.py --seed 11 --duration 30 --noise 0.003 0.06 --cases 24; chain bias and the
    noise's share of the variance in closed form): 0.80 / 0.99 / 1.00 within 1 / 2 / 3 SE (with SIMEX,
    64 replicates: 0.79 / 0.98 / 1.00); without the chain-bias correction 0.53 / 0.88 / 0.99. Short records hide most of the bias (it stays, the spread shrinks with length):
    on 60 s sweeps (--cases 30) the estimator before issue 11 covered 0.80 / 0.96 within 2 / 3 SE, this
    one 0.98 / 0.99; test_the_issue_case_is_covered checks such a record."""
    rng = np.random.default_rng(11)
    z = []
    for _ in range(24):
        rig, amp, noise = _random_case(rng)
        run = run_sweep(rig, SineSweep(1, 20, 30, amp), fs_hz=2048, seed=int(rng.integers(1 << 31)),
                        **_sensors(noise))
        truth = run.truth["model"]["q1_dot"]
        ident = SparseIdentifier(validate=False, placements=0).fit(run.recording)
        se = ident.standard_errors_["q1_dot"]
        z += [abs(c - truth.get(t, 0.0)) / se[t] for t, c in ident.model_.equations["q1_dot"].items()]
    z = np.array(z)
    assert z.size >= 100
    assert np.mean(z < 2) >= 0.88 and np.mean(z < 3) >= 0.96, (np.mean(z < 2), np.mean(z < 3), z.max())
    assert np.mean(z < 1) <= 0.90, np.mean(z < 1)


@pytest.fixture(scope="module")
def issue_case():
    """The issue's case: Table 1 rig, 1-20 Hz, 60 s, 1.3 mm, 0.5 % noise, seed 1 (q1*q2^2 was 5.5 SE off)."""
    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 60, 1.3), seed=1, **_sensors(0.005))
    return run, SparseIdentifier().fit(run.recording)


def test_the_issue_case_is_covered(issue_case):
    run, ident = issue_case
    truth = run.truth["model"]["q1_dot"]
    assert set(ident.model_.equations["q1_dot"]) == set(truth)
    for t, c in ident.model_.equations["q1_dot"].items():
        assert abs(c - truth[t]) < 3 * ident.standard_errors_["q1_dot"][t], t


@pytest.mark.slow
def test_chain_bias_is_measured_and_removed():
    """At 5 % noise the integrated states' noise biases q2 and q2^3 (errors in variables). The noise
    floors read from the spectra match the sensors' true noise, and the bias estimate (in closed form,
    identify.chain.bias_correction) removes the bias: mean over 4 records of the error with and without the
    correction. Measured (60 s sweeps): q2 -0.206 % -> -0.040 %, q2^3 +0.353 % -> +0.086 %, what is
    left half a standard error of the 4-record mean (the linear SIMEX extrapolation used before left
    -0.056 % and +0.14 %). Asked: at least half of each removed, and what is left within 1.5 standard
    errors of the mean."""
    rig = RigParameters.paper_table1()
    before, after, se = [], [], []
    for seed in range(4):
        run = run_sweep(rig, SineSweep(1, 20, 60, 1.3), seed=seed, **_sensors(0.05))
        ident = SparseIdentifier(validate=False, placements=0).fit(run.recording)
        cb = ident.uncertainty_["chain_bias"]
        assert cb["method"] == "analytic (corrected score)"
        assert cb["noise_std"]["input"] == pytest.approx(0.05 * np.std(run.table_acc_true), rel=0.05)
        assert cb["noise_std"]["output"] == pytest.approx(0.05 * np.std(run.mass_acc_true), rel=0.05)
        truth, eq = run.truth["model"]["q1_dot"], ident.model_.equations["q1_dot"]
        after.append([eq[t] / truth[t] - 1 for t in ("q2", "q2^3")])
        before.append([(eq[t] + cb["q1_dot"][t]) / truth[t] - 1 for t in ("q2", "q2^3")])
        se.append([ident.standard_errors_["q1_dot"][t] / abs(truth[t]) for t in ("q2", "q2^3")])
    before, after = np.mean(before, 0), np.mean(after, 0)
    se_mean = np.sqrt(np.mean(np.square(se), 0) / 4)
    assert np.all(np.abs(before) > 1e-3), before  # a bias worth removing: > 0.1 %
    assert np.all(np.abs(after) < 0.5 * np.abs(before)), (before, after)
    assert np.all(np.abs(after) < 1.5 * se_mean), (after, se_mean)


def _closed_form_and_simex(recording):
    """The default fit of `recording` (no validation, no placements), its all-rows coefficients, and its
    chain bias both ways on the same fit: closed form and SIMEX with 256 replicates."""
    from identify.trust import uncertainty as unc

    ident = SparseIdentifier(validate=False, placements=0).fit(recording)
    sig = ident.states_
    gram = ident._gram(sig, holdout_blocks(sig)[0])
    sups = {e: s.support for e, s in enumerate(ident.selections_.values())}
    coefs = {e: unc.refit_all_rows(gram, sups[e], e, covariance=False)[0] for e in sups}
    closed = unc.analytic_chain_bias(recording, sig, gram, ident.library_, sups, coefs)
    simex = unc.chain_bias(recording, sig, sups, coefs, lambda s2, cols: ident._gram(s2, gram.edges, cols), 256)
    return ident, sups, coefs, closed, simex


@pytest.mark.slow
def test_closed_form_bias_matches_a_large_simex():
    """The corrected-score bias (identify.chain.bias_correction, the default) against SIMEX with 256 replicates on
    the same fit: Table 1 rig, 60 s, 5 % noise. SIMEX is a Monte Carlo (mc_var: its variance) and
    extrapolates linearly in the noise variance, the closed form is exact for Gaussian noise: they agree
    to first order. Measured: every kept term within 0.42 of SIMEX's Monte Carlo standard errors; asked
    within 4 of them plus 5 % of the bias (the curvature SIMEX's linear extrapolation misses), and the
    bias must be well resolved (> 5 Monte Carlo SE for q2 and q2^3) so the comparison means something."""
    from identify.trust import uncertainty as unc

    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 60, 1.3), seed=0, **_sensors(0.05))
    ident, sups, coefs, closed, simex = _closed_form_and_simex(run.recording)
    assert ident.result()["uncertainty"]["chain_bias"]["method"] == unc.ANALYTIC
    assert closed["method"] == unc.ANALYTIC and simex["replicates"] == 256
    names = ident.library_.names
    for j in np.flatnonzero(sups[0]):
        a, b, se = closed["bias"][0][j], simex["bias"][0][j], np.sqrt(simex["mc_var"][0][j])
        assert abs(a - b) <= 4 * se + 0.05 * abs(a), (names[j], a, b, se)
        if names[j] in ("q2", "q2^3"):
            assert abs(a) > 5 * se, (names[j], a, se)
    # the reported coefficients are the all-rows refit less this bias
    for j in np.flatnonzero(sups[0]):
        assert ident.model_.equations["q1_dot"][names[j]] == pytest.approx(coefs[0][j] - closed["bias"][0][j])


@pytest.mark.slow
def test_closed_form_noise_spread_matches_the_replicates_spread():
    """The sensor noise's share of each coefficient's variance, linearised on the band's bins
    (identify.trust.noise_spread), against the spread of 256 SIMEX replicates (128 antithetic pairs: each
    standard deviation to ~6 %) on the same fit. At 0.5 % noise the replicates are linear in the noise
    to well below that (at 5 % their antithetic halves carry third-order terms: 5-20 % apart). Table 1
    rig at 1.2 mm, 60 s. Measured 0.1-7 % apart; asked within 20 % (3 Monte Carlo sigma) for every kept
    q1_dot term, and the weak term's share must be what sets its standard error when it is the larger."""
    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 60, 1.2), seed=2, **_sensors(0.005))
    ident, sups, coefs, closed, simex = _closed_form_and_simex(run.recording)
    names = ident.library_.names
    assert {names[j] for j in np.flatnonzero(sups[0])} == set(run.truth["model"]["q1_dot"])
    for j in np.flatnonzero(sups[0]):
        a, b = np.sqrt(closed["spread_var"][0][j]), np.sqrt(simex["spread_var"][0][j])
        assert abs(a / b - 1) < 0.2, (names[j], a, b)
    se = ident.standard_errors_["q1_dot"][WEAK]
    assert se >= np.sqrt(closed["spread_var"][0][names.index(WEAK)]) * (1 - 1e-9)


def test_simex_where_the_closed_form_does_not_apply():
    """A kept term that is not a monomial of the states and input (q1*|q1|: quadratic damping) has no
    corrected score: the closed form declines (None) and the identifier says SIMEX ran; bias_method=
    "simex" forces SIMEX on a monomial model, and the coefficients then differ from the closed form's by
    less than their standard errors (both remove the same bias)."""
    from identify.trust import uncertainty as unc

    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 20, 1.3), seed=4, **_sensors(0.02))
    ident = SparseIdentifier(validate=False, placements=0, extra_terms=("q1*|q1|",)).fit(run.recording)
    sig = ident.states_
    gram = ident._gram(sig, holdout_blocks(sig)[0])
    names = ident.library_.names
    sups = {e: s.support.copy() for e, s in enumerate(ident.selections_.values())}
    sups[0][names.index("q1*|q1|")] = True
    coefs = {e: unc.refit_all_rows(gram, sups[e], e, covariance=False)[0] for e in sups}
    assert unc.analytic_chain_bias(run.recording, sig, gram, ident.library_, sups, coefs) is None
    simex = SparseIdentifier(validate=False, placements=0, bias_method="simex").fit(run.recording).result()
    closed = SparseIdentifier(validate=False, placements=0).fit(run.recording).result()
    assert simex["uncertainty"]["chain_bias"]["method"] == "SIMEX" and "(SIMEX)" in simex["uncertainty"]["coefficients"]
    assert closed["uncertainty"]["chain_bias"]["method"] == "analytic (corrected score)"
    for term, c in closed["model"]["q1_dot"].items():
        assert abs(c - simex["model"]["q1_dot"][term]) < closed["standard_errors"]["q1_dot"][term], term
    with pytest.raises(IdentificationError):
        SparseIdentifier(bias_method="exact").fit(run.recording)


@pytest.mark.slow
@pytest.mark.parametrize("duration_s, noise_fraction", [(15, 0.005), (60, 0.05)])
def test_noise_floors_from_the_band_search_spectra(duration_s, noise_fraction):
    """The fit reads the sensors' noise from the Welch spectra the chain's band search computed (the
    input's and the response's; the output's variance is their difference). A 15 s record gives that
    search 3 segments, whose median bin lies 11 % of the variance below the level: without the median's
    correction each std would come out ~5.6 % low, and 3 % is asked. Truth: the simulated sensors'
    noise; and the floors agree with the separate Welch of the two channels used where there are no such
    spectra (a given band)."""
    for seed in range(3):
        run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, duration_s, 1.2), seed=seed,
                        **_sensors(noise_fraction))
        rec = run.recording
        sig = reconstruct_states(rec)
        assert sig.spectra is not None and sig.spectra.segments == (3 if duration_s == 15 else 14)
        read = unc.noise_floors(rec, sig.band_hz, sig.spectra)
        truth = [noise_fraction * np.std(run.table_acc_true), noise_fraction * np.std(run.mass_acc_true)]
        np.testing.assert_allclose(read, truth, rtol=0.03)
        np.testing.assert_allclose(read, unc.noise_floors(rec, sig.band_hz), rtol=0.03)
    assert reconstruct_states(rec, band_hz=sig.band_hz).spectra is None  # no band search, no spectra


def test_inclusion_probabilities_tell_real_from_spurious_terms(issue_case):
    run, ident = issue_case
    p = ident.result()["inclusion_probability"]
    truth = run.truth["model"]["q1_dot"]
    for term in ident.library_.names:
        if term in truth:
            assert p["q1_dot"][term] >= 0.9, term
        else:
            assert p["q1_dot"].get(term, 0.0) <= 0.25, term
    assert p["q2_dot"] == {"q1": 1.0}


@pytest.mark.slow
def test_reported_coefficients_do_not_depend_on_the_heldout_placement():
    """Table 1 rig, a 40 s sweep followed by 150 s of rest: the default blocks take a large share of the
    resonance region out of the training fit, whose q1*q2^2 came out 6 % off (docs/identification.md
    section 6). The reported coefficients are refit on all rows: the weak term spreads <= 1 % over
    held-out fractions of 10-30 % (each moves the blocks), and lies within 1 % of the truth."""
    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 40, 1.3), fs_hz=1024, settle_s=150, seed=0,
                    table_sensor=Accelerometer(noise_fraction=0, noise_ms2=0.02),
                    mass_sensor=Accelerometer(noise_fraction=0, noise_ms2=0.02))
    weak, training = [], []
    for fraction in (0.1, 0.2, 0.3):
        ident = SparseIdentifier(validate=False, placements=0, holdout_fraction=fraction).fit(run.recording)
        weak.append(ident.model_.equations["q1_dot"][WEAK])
        training.append(ident.training_model_.equations["q1_dot"].get(WEAK, 0.0))
    weak = np.array(weak)
    assert np.ptp(weak) <= 0.01 * TABLE1_WEAK, weak
    assert np.all(np.abs(weak / TABLE1_WEAK - 1) < 0.01), weak
    assert np.ptp(training) > 0.01 * TABLE1_WEAK, training  # the lottery the refit removes


def test_validation_scores_a_fit_that_never_saw_the_heldout_rows(issue_case):
    run, ident = issue_case
    sig, held_rows = ident.states_, ident.heldout_rows_
    edges, held = holdout_blocks(sig)
    v = sig.valid
    gram = BlockGram.from_library(ident.library_, (sig.q1[v], sig.q2[v]), sig.input[v][:, None],
                                  (sig.q1_dot[v], sig.q1[v]), edges)
    train = gram.equations(~held)
    names = ident.library_.names
    sup = np.array([n in ident.model_.equations["q1_dot"] for n in names])
    x = least_squares(train.G, train.B[:, 0], sup)
    assert ident.training_model_.equations["q1_dot"] == pytest.approx({n: x[j] for j, n in enumerate(names) if sup[j]})
    assert ident.model_.equations["q1_dot"] != ident.training_model_.equations["q1_dot"]
    again = validate(ident.training_model_, sig, held_rows)[0]
    assert again["heldout"] == ident.validation_["heldout"]


def test_report_table_shows_the_inclusion_probabilities(issue_case):
    from reports.text import coefficient_table

    run, ident = issue_case
    lines = coefficient_table(ident.result()).splitlines()
    assert lines[0].split("|")[4:6] == [" P(kept) q1_dot ", " P(kept) q2_dot "]
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in lines[2:]}
    p = ident.result()["inclusion_probability"]
    assert rows["q2^3"][2] == f"{p['q1_dot']['q2^3']:.2f}" and rows["q1"][3] == "1.00"
    assert rows["q1^2"][2] == f"{p['q1_dot'].get('q1^2', 0.0):.2f}"


def test_the_kinematic_equation_is_exact_not_measured(issue_case):
    """q2_dot = q1 holds by construction of the chain: reported as coefficient 1 with no standard error,
    not as the least squares' rounding (0.9999999999999999 +- 6e-17), and said so in the JSON and tables."""
    from reports.text import coefficient_table

    run, ident = issue_case
    result = ident.result()
    assert result["model"]["q2_dot"] == {"q1": 1.0} and result["standard_errors"]["q2_dot"] == {"q1": 0.0}
    assert "by construction" in result["uncertainty"]["exact"]["q2_dot"]
    assert "q1_dot" not in result["uncertainty"]["exact"]  # the measured equation keeps its errors
    assert all(se > 0 for se in result["standard_errors"]["q1_dot"].values())
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]]
            for ln in coefficient_table(result).splitlines()[2:]}
    assert rows["q1"][1] == "1 (exact)" and " ± " in rows["q1"][0]


@pytest.mark.parametrize("layout", ["base", "force"])
def test_noise_chain_is_the_chain_applied_to_the_noise(layout):
    """SIMEX replicates add the chain's image of the noise to the states instead of rerunning the chain:
    exact because every step of the chain is linear. Checked against identify.chain.states itself, so a change
    there that this copy misses fails here."""
    import dataclasses

    from identify.chain.states import reconstruct_states
    from identify.data.recording import Recording
    from identify.trust.uncertainty import NoiseChain

    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 10, 1.3), fs_hz=1024, **_sensors(0.005))
    rec = run.recording
    if layout == "force":
        rec = Recording(run.recording.input, run.states[:, 1], 1024.0, "force")
    band = (1.0, 100.0) if layout == "base" else (0.0, 100.0)
    # in double precision, as NoiseChain transforms: linearity to rounding (the chain's default single
    # precision adds its own rounding, ~2e-7 of the peak, to each)
    sig = reconstruct_states(rec, band, dtype=np.float64)
    rng = np.random.default_rng(3)
    e_in, e_out = 0.01 * rng.standard_normal(rec.n_samples), 0.01 * rng.standard_normal(rec.n_samples)
    noisier = reconstruct_states(dataclasses.replace(rec, input=rec.input + e_in, output=rec.output + e_out), band,
                                 dtype=np.float64)
    added = NoiseChain(sig, rec.n_samples, layout)(e_in, e_out)
    v = sig.valid
    for name, d in zip(("q1", "q2", "q1_dot", "input"), added):
        want = getattr(noisier, name)[v] - getattr(sig, name)[v]
        assert np.max(np.abs(d[v] - want)) <= 1e-9 * np.max(np.abs(getattr(noisier, name)[v])), name


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["base", "force"])
def test_noise_drawn_on_the_band_has_the_chains_statistics(layout):
    """SIMEX draws the chain's image of fresh noise on the band's bins (NoiseChain.draw) instead of
    transforming white noise through the chain (NoiseChain.__call__, checked above against the chain
    itself). On the valid rows both must have the same covariance between q1, q2, q1_dot and the input
    (the lag-0 moments are all a Gram of the library sees; the q2 / q1_dot covariance is the errors-in-
    variables bias). The integrated states' noise sits at the band's bottom (q2's near 1 Hz), so a 20 s
    record holds few independent samples of it: over 40 draws of each the variances of q1 and q2 differed
    by 3.0 % and 3.7 %, over 400 draws by 0.03 % and 0.14 % (every entry within 0.15 % of the product of
    the standard deviations). 200 draws each, asked within 5 %."""
    from identify.chain.states import reconstruct_states
    from identify.data.recording import Recording
    from identify.trust.uncertainty import NoiseChain

    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 20, 1.3), fs_hz=1024, **_sensors(0.005))
    rec = run.recording
    if layout == "force":
        rec = Recording(run.recording.input, run.states[:, 1], 1024.0, "force")
    sig = reconstruct_states(rec, (1.0, 100.0) if layout == "base" else (0.0, 100.0))
    chain = NoiseChain(sig, rec.n_samples, layout)
    rng = np.random.default_rng(5)
    v = sig.valid

    def covariance(draws):
        return np.mean([np.cov(np.array([d[v] for d in draw])) for draw in draws], axis=0)

    n = rec.n_samples
    through_chain = covariance(chain(0.01 * rng.standard_normal(n), 0.02 * rng.standard_normal(n)) for _ in range(200))
    on_the_band = covariance(chain.draw(rng, 0.01, 0.02) for _ in range(200))
    sd = np.sqrt(np.diag(through_chain))
    assert np.all(np.abs(on_the_band - through_chain) <= 0.05 * np.outer(sd, sd)), (on_the_band, through_chain)


def test_replicates_follow_the_record_length():
    """64 SIMEX replicates (32 antithetic pairs) where they are cheap, 16 at a million samples."""
    from identify.trust.uncertainty import replicates_for

    assert [replicates_for(n) for n in (30_000, 250_000, 500_000, 1_000_000, 10_000_000)] == [64, 64, 32, 16, 16]


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["base", "force"])
def test_lag0_covariance_is_that_of_the_band_limited_draws(layout):
    """The closed-form chain bias needs only the lag-0 covariance of the chain's noise image
    (BandLimitedNoise.covariance, from the band's filters, no draws). Against 300 draws of 60 s at
    1024 Hz: each entry's sampling error is at most ~2 % of the product of the standard deviations (q2's
    noise sits near 1 Hz, ~60 independent periods per draw: 1 / sqrt(300 x 60) x sqrt(2) ~ 1 %);
    asked within 3 %. The q2 / q1_dot covariance (the errors-in-variables bias of the stiffness) must be
    clearly negative, and q1's with q2 zero (H_q1 conj H_q2 is imaginary on every bin)."""
    from identify.noise.chain_noise import BandLimitedNoise

    fs, n = 1024.0, 61_440
    band = (1.0, 100.0) if layout == "base" else (0.0, 100.0)
    noise = BandLimitedNoise(n, fs, band, layout)
    want = noise.covariance(0.01, 0.02)
    rng = np.random.default_rng(7)
    got = np.mean([np.cov(np.array(noise.draw(0.01, 0.02, rng)), bias=True) for _ in range(300)], axis=0)
    sd = np.sqrt(np.diag(want))
    assert np.all(np.abs(got - want) <= 0.03 * np.outer(sd, sd)), (got / np.outer(sd, sd), want / np.outer(sd, sd))
    assert want[0, 1] == pytest.approx(0.0, abs=1e-12 * sd[0] * sd[1])
    if layout == "base":
        assert want[1, 2] < -0.1 * sd[1] * sd[2]


@pytest.mark.slow
def test_corrected_sums_are_unbiased_for_the_noise_free_moments():
    """identify.chain.bias_correction: for a monomial y^k of noisy signals y = x + d (d the chain's Gaussian noise
    image), sum_t T_k(y_t) has expectation sum_t x_t^k. Known truth: x is a fixed set of signals (a
    simulated rig's states), d is drawn by BandLimitedNoise at a noise level where the raw sums are off
    by many of their standard errors. Over 200 draws the mean corrected sum must lie within 4 standard
    errors of the mean of the noise-free sum, for monomials up to degree 9 (a Gram entry of a degree-4
    library with q1_dot's target is at most q1_dot x degree 4; q1^2 q2^4 q1_dot^2... covers products of
    all four signals)."""
    from identify.noise.chain_noise import BandLimitedNoise
    from identify.chain.bias_correction import CorrectedSums

    run = run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 20, 1.3), fs_hz=1024, **_sensors(0.0))
    from identify.chain.states import reconstruct_states

    sig = reconstruct_states(run.recording, (1.0, 100.0))
    v = sig.valid
    x = [sig.q1[v], sig.q2[v], sig.q1_dot[v], sig.input[v]]
    noise = BandLimitedNoise(run.recording.n_samples, 1024.0, (1.0, 100.0), "base")
    # a strong noise (10 % of each channel's RMS acceleration): large biases, so the test can fail
    s_in, s_out = 0.1 * np.std(run.recording.input), 0.1 * np.std(run.recording.output)
    cov = noise.covariance(s_in, s_out)
    monomials = [(0, 2, 0, 0), (0, 1, 1, 0), (0, 4, 0, 0), (1, 2, 1, 0), (0, 3, 1, 0), (2, 4, 0, 0),
                 (0, 6, 0, 0), (1, 4, 1, 0), (0, 8, 0, 0), (1, 1, 0, 1), (0, 2, 0, 2), (2, 2, 1, 1)]
    clean = np.array([np.sum(np.prod([xv ** p for xv, p in zip(x, k)], axis=0)) for k in monomials])
    rng = np.random.default_rng(2)
    raw, fixed = [], []
    for _ in range(200):
        d = noise.draw(s_in, s_out, rng)
        y = [xv + dv[v] for xv, dv in zip(x, d)]
        sums = CorrectedSums(cov, {}, y)
        raw.append([sums.raw_sum(k) for k in monomials])
        fixed.append([sums(k) for k in monomials])
    raw, fixed = np.array(raw), np.array(fixed)
    se = fixed.std(0, ddof=1) / np.sqrt(len(fixed))
    z_fixed = (fixed.mean(0) - clean) / se
    z_raw = (raw.mean(0) - clean) / (raw.std(0, ddof=1) / np.sqrt(len(raw)))
    assert np.all(np.abs(z_fixed) < 4), dict(zip(monomials, z_fixed.round(1)))
    assert np.max(np.abs(z_raw)) > 20, dict(zip(monomials, z_raw.round(1)))  # the noise does bias the raw sums
