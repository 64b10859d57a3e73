"""Admissibility rules and one-sided end stops' tied coefficients, on hand-made coefficients."""
import numpy as np

from identify.admissibility import check
from identify.structure import Fitter, Structure

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


def test_dissipative_terms_and_sign_flips_are_refused():
    assert "injects energy" in check("quadratic_damping", {"q1*|q1|": 0.3}, {}, {})
    assert check("quadratic_damping", {"q1*|q1|": -0.3}, {}, {}) == ""
    # q2^3 at -2.2e6 +- 1e5 (22 SE) turned positive: refused; at 2 SE it is not well determined
    assert "flips the sign" in check("coulomb_friction", {"sign(q1)": -0.5, "q2^3": 1.0e6},
                                     {"q2^3": -2.2e6}, {"q2^3": 1e5})
    assert check("coulomb_friction", {"sign(q1)": -0.5, "q2^3": 1.0e6}, {"q2^3": -2.2e5}, {"q2^3": 1e5}) == ""


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
