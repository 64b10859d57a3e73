"""Admissibility rules and one-sided end stops' tied coefficients, on hand-made coefficients."""
import numpy as np
import pytest

from identify.explain.admissibility import check
from identify.explain.structure import Fitter, Structure

STOP = ("stop(q2)", "sign(q2)*stop(q2)", "q1*contact(q2)", "q1*sign(q2)*contact(q2)")


def test_end_stop_must_push_back_and_dissipate_on_both_sides():
    upper_only = dict(zip(STOP, (-100.0, -100.0, -2.0, -2.0)))
    assert check("end_stop", upper_only, {}, {}) == ""
    lower_only = dict(zip(STOP, (-100.0, 100.0, -2.0, 2.0)))
    assert check("end_stop", lower_only, {}, {}) == ""
    outwards_below = dict(zip(STOP, (-100.0, -101.0, -2.0, -2.0)))  # lower side: c1 - c2 = +1 > 0
    assert "outwards" in check("end_stop", outwards_below, {}, {})
    injecting = dict(zip(STOP, (-100.0, -100.0, -2.0, -2.5)))       # lower side: d1 - d2 = +0.5 > 0
    assert "injects energy" in check("end_stop", injecting, {}, {})


def test_end_stop_must_be_stiffer_than_the_rigs_spring():
    # the case that motivated it: a 6.4 N/m per kg one-sided "stop" on a rig of 1894 N/m per kg
    soft = dict(zip(STOP, (-3.18, -3.18, -0.001, -0.001)), q2=-1894.0)
    assert "softer than the rig's own spring" in check("end_stop", soft, {}, {})
    # a one-sided contact at 2x the spring (the suite's softest) is a stop; the stiffer side counts
    stiff = dict(zip(STOP, (-1894.0, 1894.0, -0.5, 0.5)), q2=-1894.0)   # lower side: 3788
    assert check("end_stop", stiff, {}, {}) == ""
    just_below = dict(stiff, **{"stop(q2)": -940.0, "sign(q2)*stop(q2)": 940.0})  # lower side 1880 < 1894
    assert "softer" in check("end_stop", just_below, {}, {})


def test_dissipative_terms_and_sign_flips_are_refused():
    assert "injects energy" in check("quadratic_damping", {"q1*|q1|": 0.3}, {}, {})
    assert check("quadratic_damping", {"q1*|q1|": -0.3}, {}, {}) == ""
    # q2^3 at -2.2e6 +- 1e5 (22 SE) turned positive: refused; at 2 SE it is not well determined
    assert "flips the sign" in check("coulomb_friction", {"sign(q1)": -0.5, "q2^3": 1.0e6},
                                     {"q2^3": -2.2e6}, {"q2^3": 1e5})
    assert check("coulomb_friction", {"sign(q1)": -0.5, "q2^3": 1.0e6}, {"q2^3": -2.2e5}, {"q2^3": 1e5}) == ""


def test_a_sign_flip_that_explains_nearly_everything_is_allowed():
    """Rule 2 guards against trading one error for another; a candidate that removes nearly all of the
    gap traded nothing: the baseline's sign was the missing effect's imprint (Bouc-Wen hysteresis read as
    a softening q2^3 by the textbook fit, restored to hardening)."""
    from identify.explain.admissibility import FLIP_WAIVED_SHARE, flips_waived

    flipped, base, se = {"z": -200.0, "q2^3": -1.6e6}, {"q2^3": 4.2e6}, {"q2^3": 0.8e6}
    assert "flips the sign" in check("hysteresis", flipped, base, se)
    assert check("hysteresis", flipped, base, se, waive_flips=True) == ""
    # the effect's own rules still hold
    assert "restoring" in check("hysteresis", {"z": 200.0, "q2^3": -1.6e6}, base, se, waive_flips=True)
    assert flips_waived(FLIP_WAIVED_SHARE) and not flips_waived(0.99 * FLIP_WAIVED_SHARE)


def test_one_sided_stop_ties_its_asymmetry_terms():
    terms = ("q1", "q2", "q2^3", "zdd") + STOP
    for side in (1, -1):
        st = Structure(terms, travel=1e-3, side=side)
        T = Fitter.tie_matrix(st, list(terms))
        assert T.shape == (8, 6)
        free = np.arange(1.0, 7.0)  # q1, q2, q2^3, zdd, stop(q2), q1*contact(q2)
        full = dict(zip(terms, T @ free))
        assert full["sign(q2)*stop(q2)"] == side * full["stop(q2)"] == side * 5.0
        assert full["q1*sign(q2)*contact(q2)"] == side * full["q1*contact(q2)"] == side * 6.0
        assert check("end_stop", {t: -abs(v) * (side if "sign(q2)" in t else 1) for t, v in full.items()}, {}, {}) == ""
    assert Fitter.tie_matrix(Structure(terms, travel=1e-3), list(terms)).shape == (8, 8)


def test_wald_test_of_a_one_sided_stop_counts_its_free_coefficients():
    """A one-sided stop has four terms but two free coefficients (the other two follow them): its Wald
    statistic is chi-square with 2 degrees of freedom, not 4 (a p-value 4-8x too large near 1e-3)."""
    from scipy import stats

    from identify.explain.effects import wald_p
    from identify.explain.structure import Fit

    terms = ("q1", "q2") + STOP
    T = Fitter.tie_matrix(Structure(terms, travel=1e-3, side=1), list(terms))
    free_cov = np.diag([1e-4, 1e-2, 4.0, 1e-2])  # q1, q2, stop(q2), q1*contact(q2)
    cov = T @ free_cov @ T.T
    coef = dict(zip(terms, T @ np.array([-3.0, -900.0, -5.0, -0.25])))
    fit = Fit(coef, {}, cov, list(terms), 0.0)
    w, p = wald_p(fit, STOP)
    assert w == pytest.approx(5.0**2 / 4.0 + 0.25**2 / 1e-2, rel=1e-9)  # the free pair's own statistic
    assert p == pytest.approx(stats.chi2.sf(w, 2), rel=1e-9)
    two_sided = Fit(coef, {}, np.diag([1e-4, 1e-2, 4.0, 4.0, 1e-2, 1e-2]), list(terms), 0.0)
    assert wald_p(two_sided, STOP)[1] == pytest.approx(stats.chi2.sf(wald_p(two_sided, STOP)[0], 4), rel=1e-9)


def test_a_sign_within_its_uncertainty_of_zero_is_not_a_violation():
    """The sign rules are statistical: contact damping of +0.05 +- 0.04 per side (the issue's stops had
    +0.02..+0.1, statistically zero, and were rejected) and a side pushing outwards by 1 +- 2 are zero,
    not violations; the same values with standard errors ten times smaller are."""
    zero_damping = dict(zip(STOP, (-100.0, -100.0, 0.03, 0.02)))          # both sides +0.05 and +0.01
    wide = dict(zip(STOP, (5.0, 5.0, 0.03, 0.03)))
    assert check("end_stop", zero_damping, {}, {}, wide) == ""
    assert "injects energy" in check("end_stop", zero_damping, {}, {}, {t: v / 10 for t, v in wide.items()})
    outwards_a_hair = dict(zip(STOP, (-100.0, -101.0, -2.0, -2.0)))       # lower side: +1
    assert check("end_stop", outwards_a_hair, {}, {}, dict(zip(STOP, (1.5, 1.5, 0.1, 0.1)))) == ""
    assert "outwards" in check("end_stop", outwards_a_hair, {}, {}, dict(zip(STOP, (0.15, 0.15, 0.1, 0.1))))
    assert check("quadratic_damping", {"q1*|q1|": 0.3}, {}, {}, {"q1*|q1|": 0.2}) == ""
    assert "injects energy" in check("quadratic_damping", {"q1*|q1|": 0.3}, {}, {}, {"q1*|q1|": 0.1})


def test_the_best_excluded_candidate_is_refit_only_when_it_fits_best():
    """A candidate excluded at its equation-error start is judged again on its shooting refit when it fits
    the segments better than every admissible one (identify.explain.rounds.Rounds._judged_after_refit);
    otherwise no refit is spent on it."""
    from identify.explain.effects import Candidate
    from identify.explain.rounds import Rounds

    def cand(name, err, admissible):
        c = Candidate(name, "physics", [], None, None)
        c.err, c.admissible = np.array(err, dtype=float), admissible
        return c

    hyst, stop = cand("hysteresis", [1.0, 1.0], False), cand("end_stop", [9.0, 9.0], False)
    delay = cand("channel_delay", [4.0, 4.0], True)
    cands = [delay, stop, hyst]
    assert Rounds._judged_after_refit(cands, [delay], 1e-3) == [hyst]
    assert Rounds._judged_after_refit([delay, stop], [delay], 1e-3) == []
    assert Rounds._judged_after_refit([stop, hyst], [], 1e-3) == [hyst]
    # excluded as insignificant: a refit keeps its test, so none is spent on it
    hyst.p_value = 0.2
    assert Rounds._judged_after_refit(cands, [delay], 1e-3) == []
