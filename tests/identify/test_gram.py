"""Inverting normal matrices whose columns differ in scale by many orders (identify.regression.gram.scaled_pinv)."""
import numpy as np

from identify.regression.gram import scaled_pinv


def test_scaled_pinv_keeps_small_scale_directions():
    # columns like the rig's: q2 ~ 1e-2 m, q2^4 ~ 1e-9 m^4 (a 6 mm response), zdd ~ 10 m/s^2:
    # condition ~1e20 in raw units
    rng = np.random.default_rng(0)
    base = rng.standard_normal((5000, 3))
    base[:, 1] += 0.5 * base[:, 0]  # correlated, as q2 and q2^3 are
    A = base * np.array([1e-2, 1e-9, 10.0])
    G = A.T @ A
    exact = np.diag(1 / np.array([1e-2, 1e-9, 10.0])) @ np.linalg.inv(base.T @ base) @ np.diag(
        1 / np.array([1e-2, 1e-9, 10.0]))
    np.testing.assert_allclose(scaled_pinv(G), exact, rtol=1e-8)
    # the raw pinv cuts the small-scale direction: its variance comes out orders of magnitude too small
    assert np.linalg.pinv(G)[1, 1] < 1e-6 * exact[1, 1]


def test_scaled_pinv_of_collinear_columns_is_the_minimum_norm_inverse():
    x = np.linspace(-1, 1, 200)
    A = np.column_stack([x, 2 * x, x ** 2])  # the first two are collinear
    G = A.T @ A
    P = scaled_pinv(G)
    np.testing.assert_allclose(G @ P @ G, G, rtol=1e-8, atol=1e-10 * np.abs(G).max())
