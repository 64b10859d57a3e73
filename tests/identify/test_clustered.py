"""The segment-clustered sandwich the shooting-error tests share (identify.explain.clustered), against the
quantity it stands for: the leave-one-segment-out (jackknife) shifts of a least-squares fit, computed by
refitting without each segment."""
import numpy as np
from scipy import stats

from identify.explain.clustered import MAX_LEVERAGE, cr3_covariance, wald_p


def _segments(rng, n_segments=12, rows=40, d=3):
    X = [rng.normal(size=(rows, d)) * rng.uniform(0.5, 2.0, size=d) for _ in range(n_segments)]
    y = [x @ np.array([1.0, -2.0, 0.5])[:d] + rng.normal(size=rows) for x in X]
    return X, y


def test_cr3_covariance_is_the_sum_of_the_jackknife_shifts():
    """Least squares: beta_(-s) - beta = -(X'X - X_s'X_s)^-1 X_s' r_s exactly, r the full fit's residuals, so
    the covariance is sum_s (beta_(-s) - beta)(beta_(-s) - beta)' (every leverage here is below the cap)."""
    rng = np.random.default_rng(20261128)
    X, y = _segments(rng)
    Xa, ya = np.vstack(X), np.concatenate(y)
    beta = np.linalg.lstsq(Xa, ya, rcond=None)[0]
    shifts = []
    for s in range(len(X)):
        keep = [i for i in range(len(X)) if i != s]
        b = np.linalg.lstsq(np.vstack([X[i] for i in keep]), np.concatenate([y[i] for i in keep]), rcond=None)[0]
        shifts.append(b - beta)
    D = np.array(shifts)
    H = Xa.T @ Xa
    cov = cr3_covariance(H, [x.T @ x for x in X], [x.T @ (yy - x @ beta) for x, yy in zip(X, y)])
    assert np.allclose(cov, D.T @ D, rtol=1e-10, atol=0)


def test_a_segment_above_the_leverage_cap_is_scaled_to_it():
    """One parameter: a segment holding 95 % of the curvature counts as MAX_LEVERAGE of it; one with a
    negative curvature (a full second difference can be) as none."""
    H = np.array([[10.0]])
    cov = cr3_covariance(H, [np.array([[9.5]]), np.array([[-1.0]]), np.array([[1.5]])], [[2.0], [1.0], [-1.0]])
    expected = (2.0 / (10.0 - MAX_LEVERAGE * 10.0)) ** 2 + (1.0 / 10.0) ** 2 + (-1.0 / 8.5) ** 2
    assert np.isclose(cov[0, 0], expected, rtol=1e-14)


def test_wald_p_is_student_t_for_one_coefficient_and_f_for_several():
    assert np.isclose(wald_p(np.array([2.5]), np.array([[1.0]]), 15), 2 * stats.t.sf(2.5, 14), rtol=1e-12)
    cov = np.array([[4.0, 1.0], [1.0, 1.0]])
    coef = np.array([3.0, -1.0])
    w = coef @ np.linalg.solve(cov, coef)
    assert np.isclose(wald_p(coef, cov, 20), stats.f.sf(w / 2, 2, 19), rtol=1e-12)
    assert wald_p(np.array([1.0]), np.array([[0.0]]), 10) == 1.0  # nothing determined


def test_several_parameters_cap_the_whole_segment_and_a_singular_test_determines_nothing():
    """d = 2: a segment whose largest leverage is 0.95 has its whole H_s scaled by MAX_LEVERAGE / 0.95 (the
    other direction's leverage too); a correlation matrix that is singular gives p = 1."""
    H = np.diag([10.0, 10.0])
    Hs = np.diag([9.5, 1.0])
    g = np.array([1.0, 2.0])
    scaled = Hs * MAX_LEVERAGE / 0.95
    shift = np.linalg.solve(H - scaled, g)
    assert np.allclose(cr3_covariance(H, [Hs], [g]), np.outer(shift, shift), rtol=1e-12)
    assert wald_p(np.array([1.0, 1.0]), np.array([[1.0, 1.0], [1.0, 1.0]]), 10) == 1.0
