"""Masking (identify/explain/masking.py): Coulomb friction hides a weaker damping of its group below the noise
floor; the group check finds it by a refit and a test on the shooting error, and finds nothing on a rig
without it. Design rig, 1-20 Hz in 30 s at 1.3 mm, 1000 Hz, 0.5 % noise (test_explain_effects._run)."""
from dataclasses import replace

import pytest

from identify.explain.masking import shooting_test
from identify.explain.workflow import DiscrepancyAnalysis

from .test_explain_effects import _run

MASS_KG = 0.49  # the design rig's (RigParameters.design)


def _joint_refit(effects: dict):
    """The textbook baseline plus Coulomb friction and quadratic damping, refit together on the shooting
    error from a dissipative start, and its fitter."""
    analysis = DiscrepancyAnalysis()
    fitter = analysis._fitter(_run(effects))
    cur, _ = analysis._baseline(fitter)
    st = cur.adding("test", ("sign(q1)", "q1*|q1|"))
    st = replace(st, coef=tuple(dict(cur.coefficients, **{"sign(q1)": -0.2, "q1*|q1|": -1.0}).items()))
    return fitter, fitter.refine(st, max_nfev=40)


@pytest.mark.slow
def test_shooting_test_tells_a_present_term_from_an_absent_one():
    """Quadratic damping 2 N s^2/m^2 beside Coulomb 0.1 N: refit within 15 % of truth and p < 1e-6 (measured
    -3.81 against -4.08, p 4e-22); on the Coulomb-only rig the same term is within 3 of its standard errors of
    zero and not significant at the analysis' alpha (measured +0.32 +- 0.21, p 0.14). Coulomb's own level is
    within 5 % on both and significant."""
    for effects, present in (({"coulomb_friction": 0.1, "quadratic_damping": 2.0}, True),
                             ({"coulomb_friction": 0.1}, False)):
        fitter, st = _joint_refit(effects)
        se, p = shooting_test(fitter, st, ["q1*|q1|"])
        c = st.coefficients["q1*|q1|"]
        if present:
            assert c == pytest.approx(-2.0 / MASS_KG, rel=0.15) and p < 1e-6
        else:
            assert abs(c) < 3 * se["q1*|q1|"] and p > DiscrepancyAnalysis().alpha
        se_c, p_c = shooting_test(fitter, st, ["sign(q1)"])
        assert st.coefficients["sign(q1)"] == pytest.approx(-0.1 / MASS_KG, rel=0.05) and p_c < 1e-6


@pytest.mark.slow
def test_damping_masked_by_coulomb_friction_is_named():
    """Coulomb 0.1 N and quadratic damping 1 N s^2/m^2: with Coulomb named the gap is below the noise floor
    (the rounds stop there), and the group check names the damping, masked_by Coulomb, on its dissipative
    side within 30 % of truth (measured -1.62 against -2.04: what is below the floor is weakly determined;
    the equation error had it on the wrong side)."""
    res = DiscrepancyAnalysis().fit(_run({"coulomb_friction": 0.1, "quadratic_damping": 1.0})).result()
    first, second = res["effects"][:2]
    assert first["name"] == "coulomb_friction" and first["gap_after"] < res["noise_floor"]
    assert second["name"] == "quadratic_damping" and second["masked_by"] == "coulomb_friction"
    assert res["model"]["q1_dot"]["q1*|q1|"] == pytest.approx(-1.0 / MASS_KG, rel=0.30)
    assert res["model"]["q1_dot"]["sign(q1)"] == pytest.approx(-0.1 / MASS_KG, rel=0.10)


@pytest.mark.slow
def test_coulomb_alone_masks_nothing():
    """Coulomb friction alone: the group check runs (its table is the last round: the damping group's other
    members) and names nothing more."""
    res = DiscrepancyAnalysis().fit(_run({"coulomb_friction": 0.1})).result()
    assert [e["name"] for e in res["effects"]] == ["coulomb_friction"]
    checked = {c["name"] for c in res["rounds"][-1]}
    assert checked and checked <= {"quadratic_damping", "cubic_damping", "displacement_dependent_damping"}
