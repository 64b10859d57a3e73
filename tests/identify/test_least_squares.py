"""least_squares_many (the selection rule's batched refits) against least_squares, support by support,
and the row grouping it relies on."""
import numpy as np

from identify.regression.optimizers.base import distinct_rows, least_squares, least_squares_many


def _design(rng, n=400, m=10):
    L = rng.standard_normal((m, m)) * 0.5 + np.eye(m)
    A = rng.standard_normal((n, m)) @ L * np.logspace(-6, 3, m)  # raw columns of very different scales
    return A.T @ A, A.T @ rng.standard_normal(n)


def test_batched_refits_are_the_refits_one_by_one():
    rng = np.random.default_rng(0)
    G, b = _design(rng)
    supports = rng.random((60, G.shape[0])) < 0.5
    supports[0] = False                      # the empty model
    supports[1] = True                       # every column
    many = least_squares_many(G, b, supports)
    for s, x in zip(supports, many):
        ref = least_squares(G, b, s)
        np.testing.assert_allclose(x, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max(initial=1e-300))
        assert np.all(x[~s] == 0)


def test_a_singular_support_falls_back_to_the_minimum_norm_solution():
    """Two identical columns: the subsystem is singular, and lstsq's minimum-norm answer (the weight
    shared equally) is what least_squares gives; the batch must give it too, beside regular rows."""
    rng = np.random.default_rng(1)
    A = rng.standard_normal((300, 4))
    A[:, 3] = A[:, 1]
    y = A[:, 1] + 0.5 * A[:, 0] + 0.01 * rng.standard_normal(300)
    G, b = A.T @ A, A.T @ y
    supports = np.array([[1, 1, 0, 1], [1, 1, 0, 0], [0, 1, 1, 1]], dtype=bool)
    many = least_squares_many(G, b, supports)
    for s, x in zip(supports, many):
        np.testing.assert_allclose(x, least_squares(G, b, s), rtol=1e-9, atol=1e-12)
    assert abs(many[0, 1] - many[0, 3]) < 1e-9 and abs(many[0, 1] - 0.5) < 0.01


def test_distinct_rows_groups_equal_rows():
    rng = np.random.default_rng(2)
    a = rng.random((200, 6)) < 0.3
    first, which = distinct_rows(a)
    ref, ref_inv = np.unique(a, axis=0, return_inverse=True)
    assert first.size == ref.shape[0]
    np.testing.assert_array_equal(a[first][which], a)          # every row is its group's row
    assert all(np.flatnonzero(which == g)[0] == f for g, f in enumerate(first))  # the first occurrence
