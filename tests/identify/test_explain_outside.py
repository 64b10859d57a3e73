"""Physics outside the catalog is not given a catalog name at confidence. Free play of the spring (no
force within +-gap, then the spring) stiffens with the amplitude, and along one sweep the amplitude moves
with time: a stiffness drift's q2*tau closes part of the gap (17 % of the NRMSE) and was named at
confidence 0.95, leaving 3.3x the noise floor (benchmarks/explain_robustness.py --seed 410682751 --case 44,
reproduced here by its draw). Right explanations rarely leave more than 2x (OUTSIDE_FACTOR's comment has the
counts): above OUTSIDE_FACTOR x the floor the named effects are surrogates for physics outside the catalog.
At the factor of before (5) this draw's drift stays named at 0.95: the first assertion below then fails."""
import numpy as np
import pytest

from identify.explain.workflow import OUTSIDE, OUTSIDE_FACTOR, DiscrepancyAnalysis
from sim.scenarios import make_scenario
from sim.scoring import score

SEED, CASE = 410682751, 44  # the draw that showed it (a fixed seed to reproduce, as the benchmark prints)


@pytest.mark.slow
def test_free_play_is_not_named_a_stiffness_drift():
    sc = make_scenario(np.random.default_rng([SEED, CASE]), "out_of_catalog", ["free_play"], wide=True)
    res = DiscrepancyAnalysis().fit(sc.run(seed=[SEED, CASE, 1]).recording).result()
    assert res["gap_after"] > OUTSIDE_FACTOR * res["noise_floor"]  # the explanation leaves the gap open
    assert res["effects"], "the drift's partial fit is still reported, as a surrogate"
    for e in res["effects"]:
        assert OUTSIDE in e["surrogate_for"] and e["confidence"] < 0.5, e
    assert res["remaining"]["segments"]  # where the rest of the gap is
    verdict = score("out_of_catalog", ["free_play"], res, tuple(sc.nuisances))
    assert verdict["wrong_names"] == [] and verdict["spurious_measurement"] == []
