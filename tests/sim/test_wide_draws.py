"""The wide draws of the discrepancy suite (sim/wide.py, make_scenario(..., wide=True)): every drawn rig,
sweep and recording inside the stated distributions, each nuisance drawn about as often as stated, the
plain rig of a scenario inside MAX_RESPONSE_MM, and the nuisances a scenario states are the ones its
sensors have and its recording's truth carries. Fresh seeds, printed."""
import numpy as np
import pytest

from sim import wide
from sim.rig import RigParameters
from sim.scenarios import MAX_RESPONSE_MM, make_scenario

SHORT = dict(duration_s=12.0, fs_hz=1000.0)
#: draws of the distributions (no physics run: cheap); the shares of quantisation (0.5) and hum (0.3) are
#: then within 4 binomial standard deviations of the stated ones (0.071 and 0.065: a false alarm 1 in 16 000)
BASE_DRAWS = 800


def _seed() -> np.random.Generator:
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    return np.random.default_rng(seed)


def test_the_draws_are_inside_their_distributions():
    rng = _seed()
    design = RigParameters.design()
    quantised = humming = 0
    for _ in range(BASE_DRAWS):
        rig, sweep, fs, sensors, target = wide.draw_base(rng)
        assert target is None  # the table amplitude is the drawn one, not rescaled to a response
        for name in ("mass_kg", "damping_ns_per_m", "stiffness_n_per_m", "cubic_stiffness_n_per_m3"):
            ratio = getattr(rig, name) / getattr(design, name)
            assert wide.RIG_SPREAD[0] <= ratio <= wide.RIG_SPREAD[1], (name, ratio)
        fn = rig.natural_frequency_hz
        f_lo, f_hi = sorted((sweep.f_start_hz, sweep.f_end_hz))
        assert wide.F_LOW_HZ <= f_lo <= max(wide.F_LOW_HZ, wide.F_LOW_PER_FN * fn), (f_lo, fn)
        assert min(wide.F_HIGH_PER_FN * fn, wide.F_HIGH_HZ) <= f_hi <= wide.F_HIGH_HZ, (f_hi, fn)
        assert wide.TABLE_AMPLITUDE_MM[0] <= sweep.amplitude_mm <= wide.TABLE_AMPLITUDE_MM[1]
        assert wide.DURATION_S[0] <= sweep.duration_s <= wide.DURATION_S[1] and fs in wide.SAMPLE_RATES_HZ
        for s in sensors:
            assert wide.NOISE_FRACTION[0] <= s.noise_fraction <= wide.NOISE_FRACTION[1]
        stated = wide.nuisances(*sensors)
        assert set(stated) <= set(wide.NUISANCE_NAMES)
        if "quantisation" in stated:
            quantised += 1
            assert sensors[0].adc_bits == sensors[1].adc_bits  # one converter for both channels
            assert wide.ADC_BITS[0] <= stated["quantisation"]["bits"] <= wide.ADC_BITS[1]
        else:
            assert sensors[0].adc_bits == sensors[1].adc_bits == 0
        if "hum" in stated:
            humming += 1
            assert {ch["hz"] for ch in stated["hum"].values()} <= set(wide.HUM_HZ) and len(
                {ch["hz"] for ch in stated["hum"].values()}) == 1  # one mains frequency
            assert all(wide.HUM_FRACTION[0] <= ch["fraction"] <= wide.HUM_FRACTION[1] for ch in stated["hum"].values())
        else:
            assert sensors[0].hum_fraction == sensors[1].hum_fraction == 0.0
    assert quantised / BASE_DRAWS == pytest.approx(wide.QUANTISATION_SHARE, abs=0.071)
    assert humming / BASE_DRAWS == pytest.approx(wide.HUM_SHARE, abs=0.065)


@pytest.mark.slow
def test_a_wide_scenario_keeps_the_plain_rig_inside_and_carries_its_nuisances():
    rng = _seed()
    for _ in range(2):
        sc = make_scenario(rng, "none", wide=True, **SHORT)
        assert sc.sweep.duration_s == SHORT["duration_s"] and sc.fs_hz == SHORT["fs_hz"]
        assert wide.TABLE_AMPLITUDE_MM[0] <= sc.sweep.amplitude_mm <= wide.TABLE_AMPLITUDE_MM[1]  # as drawn
        assert sc.pilot["Q_m"] < MAX_RESPONSE_MM * 1e-3  # redrawn otherwise
        assert sc.nuisances == wide.nuisances(sc.table_sensor, sc.mass_sensor) == sc.drawn()["nuisances"]
    assert sc.run(seed=1).recording.metadata["truth"]["nuisances"] == sc.nuisances


def test_a_second_mode_is_drawn_within_the_sweep_up_or_down():
    """The absorber's frequency lies inside the swept band whichever way the sweep runs (it was capped at
    0.85 of f_end_hz, a down-sweep's low end, which put the mode below the band, where it reads as a constant
    mass-channel gain; then capped as a ratio times fn, 1 ulp over the cap at seed 2590853839). Cheap: the
    draws only (detectable=False runs no physics)."""
    directions = set()
    for rng in (np.random.default_rng(2590853839), _seed()):
        for _ in range(40):
            sc = make_scenario(rng, "out_of_catalog", ["second_mode"], wide=True, detectable=False, **SHORT)
            lo, hi = sorted((sc.sweep.f_start_hz, sc.sweep.f_end_hz))
            fa = sc.magnitudes["second_mode"]["frequency_hz"]
            assert lo < fa <= 0.85 * hi, (sc.describe(), fa)
            directions.add(sc.sweep.f_start_hz > sc.sweep.f_end_hz)
    assert directions == {True, False}  # both directions were drawn (a 1 in 5e11 chance otherwise)
