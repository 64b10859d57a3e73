import numpy as np
import pytest

from identify.errors import ModelError
from identify.regression.library import Library
from identify.regression.terms import FeatureSpace


def test_paper_library_has_16_columns_in_table_order():
    lib = Library()
    assert lib.names == ["1", "q1", "q2", "q1^2", "q1*q2", "q2^2", "q1^3", "q1^2*q2", "q1*q2^2", "q2^3",
                         "q1^4", "q1^3*q2", "q1^2*q2^2", "q1*q2^3", "q2^4", "zdd"]


@pytest.mark.parametrize("text,canonical", [("q2*q1", "q1*q2"), ("q2 * q2 * q1", "q1*q2^2"), ("1", "1"),
                                            ("|q1|*q1", "q1*|q1|"), ("sign(q1)", "sign(q1)"), ("q1^2*q1", "q1^3")])
def test_term_names_are_canonical(text, canonical):
    assert FeatureSpace(("q1", "q2"), ("zdd",)).parse(text).name == canonical


@pytest.mark.parametrize("bad", ["q3", "x^2", "q1^", "sin(q1)", "q1**2"])
def test_unknown_terms_are_refused_by_name(bad):
    with pytest.raises(ModelError, match="unknown term"):
        FeatureSpace(("q1", "q2"), ("zdd",)).parse(bad)


def test_library_columns_equal_their_formulas():
    rng = np.random.default_rng(1)
    X, U = rng.standard_normal((50, 2)), rng.standard_normal((50, 1))
    lib = Library(extra_terms=("sign(q1)", "q1*|q1|", "|q2|"))
    A = lib.evaluate(X, U)
    q1, q2 = X.T
    expect = {"1": np.ones(50), "q1^2*q2": q1**2 * q2, "q1*q2^3": q1 * q2**3, "q2^4": q2**4,
              "sign(q1)": np.sign(q1), "q1*|q1|": q1 * np.abs(q1), "|q2|": np.abs(q2), "zdd": U[:, 0]}
    for name, col in expect.items():
        np.testing.assert_allclose(A[:, lib.names.index(name)], col, rtol=1e-14)


def test_duplicate_terms_are_refused():
    with pytest.raises(ModelError, match="duplicate"):
        Library(extra_terms=("q2*q1",))
    with pytest.raises(ModelError, match="degree"):
        Library(degree=0)
