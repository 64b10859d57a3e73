"""ADMM-LASSO path against an independent reference solver (scikit-learn's coordinate descent).

sklearn's `tol` bounds the duality gap, and a gap g allows coefficient errors ~ sqrt(2 g): at tol=1e-10
the reference itself is off by ~1e-5 (seen on the exactly-fitting q2_dot equation, where the true
LASSO solution is 1 - lambda). The reference therefore runs at tol=1e-13 (coefficients good to
~5e-7; tighter gaps are below float64 round-off at n ~ 1e5) and coefficients are compared to 2e-6.
"""
import numpy as np
import pytest
from sklearn.linear_model import lasso_path

from identify.chain.states import reconstruct_states
from identify.regression.gram import BlockGram
from identify.regression.library import Library
from identify.regression.optimizers import ADMMLasso


def _scaled_problem(table1_run):
    sig = reconstruct_states(table1_run.recording)
    v = sig.valid
    lib = Library()
    A = lib.evaluate(sig.states[v], sig.input[v][:, None])
    Y = np.column_stack([sig.q1_dot[v], sig.q1[v]])
    return A, Y


def test_path_support_matches_reference_at_every_lambda(table1_run):
    A, Y = _scaled_problem(table1_run)
    n = A.shape[0]
    ne = BlockGram(np.column_stack([A, Y]), 2, [0, n]).equations([0])
    path = ADMMLasso(n_lambdas=100).fit_path(ne)
    # the reference solves the same scaled problem: unit-RMS columns and target
    s = np.sqrt((A**2).mean(0))
    As = A / s
    for eq in range(2):
        ys = Y[:, eq] / np.sqrt((Y[:, eq] ** 2).mean())
        lams = path.params[:, eq]
        _, ref, _ = lasso_path(As, ys, alphas=lams, precompute=As.T @ As, Xy=As.T @ ys, tol=1e-13, max_iter=1000000)
        ref = ref.T  # (k, m), in the order of `lams`
        ours = path.coefs[:, :, eq] * s[None, :] / np.sqrt((Y[:, eq] ** 2).mean())
        for k in range(lams.size):
            # round-off (the reference leaves ~1e-15 on a term entering exactly at lambda_max) is zero
            assert np.array_equal(np.abs(ours[k]) > 1e-12, np.abs(ref[k]) > 1e-12), f"support differs at #{k} eq {eq}"
            np.testing.assert_allclose(ours[k], ref[k], atol=2e-6)
        if eq == 1:  # q2_dot = q1 exactly: the LASSO solution is known in closed form
            np.testing.assert_allclose(ours[:, 1], np.maximum(1 - lams, 0), atol=1e-9)
        assert np.all(path.iterations[:, eq] < 50000), "ADMM hit max_iter"


def test_exact_supports_on_random_correlated_design():
    rng = np.random.default_rng(3)
    n, m = 2000, 12
    L = rng.standard_normal((m, m)) * 0.4 + np.eye(m)
    A = rng.standard_normal((n, m)) @ L  # correlated columns
    x_true = np.zeros(m)
    x_true[[1, 4, 7]] = [2.0, -1.0, 0.3]
    y = A @ x_true + 0.1 * rng.standard_normal(n)
    ne = BlockGram(np.column_stack([A, y]), 1, [0, n]).equations([0])
    path = ADMMLasso(n_lambdas=60).fit_path(ne)
    s = np.sqrt((A**2).mean(0))
    ys = y / np.sqrt((y**2).mean())
    _, ref, _ = lasso_path(A / s, ys, alphas=path.params[:, 0], tol=1e-13, max_iter=1000000)
    ours = path.coefs[:, :, 0] * s / np.sqrt((y**2).mean())
    np.testing.assert_allclose(ours, ref.T, atol=2e-6)
    assert all(np.array_equal(np.abs(o) > 1e-12, np.abs(r) > 1e-12) for o, r in zip(ours, ref.T))


def test_lambda_max_gives_empty_model_and_path_densifies():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((500, 6))
    y = A @ np.array([1.0, 0, 0, 0.5, 0, 0]) + 0.01 * rng.standard_normal(500)
    ne = BlockGram(np.column_stack([A, y]), 1, [0, 500]).equations([0])
    path = ADMMLasso(n_lambdas=30).fit_path(ne)
    nnz = (path.coefs[:, :, 0] != 0).sum(1)
    assert nnz[0] == 0
    assert nnz[-1] >= 2
    assert path.params[0, 0] > path.params[-1, 0]


@pytest.mark.parametrize("bad_column", [0.0])
def test_all_zero_column_stays_zero(bad_column):
    rng = np.random.default_rng(1)
    A = rng.standard_normal((300, 4))
    A[:, 2] = bad_column
    y = A[:, 0] - A[:, 1]
    ne = BlockGram(np.column_stack([A, y]), 1, [0, 300]).equations([0])
    path = ADMMLasso(n_lambdas=20).fit_path(ne)
    assert np.all(path.coefs[:, 2, 0] == 0) and np.all(np.isfinite(path.coefs))


def test_batched_paths_are_the_paths_one_by_one(table1_run):
    """fit_paths (the inclusion probabilities' placements in one batch) against fit_path on each set of
    normal equations: the same supports and iteration counts at every lambda, coefficients to rounding.
    Problems of different conditioning (10 blocks of 50 left out in turn, and the first 60 %) make
    them stop at different iterations, which a batch must respect."""
    A, Y = _scaled_problem(table1_run)
    n = A.shape[0]
    gram = BlockGram(np.column_stack([A, Y]), 2, np.linspace(0, n, 51).round().astype(int))
    rng = np.random.default_rng(3)
    masks = [rng.permutation(50) >= 10 for _ in range(5)] + [np.arange(50) < 30]
    nes = [gram.equations(m) for m in masks]
    opt = ADMMLasso(n_lambdas=100)
    batch = opt.fit_paths(nes)
    alone = [opt.fit_path(ne) for ne in nes]
    assert len({int(p.iterations.max()) for p in alone}) > 1  # they do stop at different iterations
    for b, a in zip(batch, alone):
        np.testing.assert_array_equal(b.coefs != 0, a.coefs != 0)
        np.testing.assert_array_equal(b.iterations, a.iterations)
        np.testing.assert_array_equal(b.params, a.params)
        np.testing.assert_allclose(b.coefs, a.coefs, rtol=1e-9, atol=1e-12 * np.abs(a.coefs).max())


def _kkt_violation(G, b, x, lam):
    """Largest violation of the LASSO optimality conditions (scaled units) at one lambda: on the
    support b - G x = lam sign(x), off it |b - G x| <= lam."""
    g = b - G @ x
    on = x != 0
    return max(np.max(np.abs(g[on] - lam * np.sign(x[on])), initial=0.0),
               np.max(np.abs(g[~on]) - lam, initial=0.0))


def test_polished_path_is_the_exact_minimiser_at_every_lambda(table1_run):
    """Active-set polishing (ADMMLasso.polish_every) certifies each point by the optimality conditions
    and returns the minimiser to rounding, where ADMM's own stop leaves its tolerance: the conditions
    hold to 1e-12 with polishing; the supports are those of ADMM iterated to its tolerance alone."""
    A, Y = _scaled_problem(table1_run)
    n = A.shape[0]
    ne = BlockGram(np.column_stack([A, Y]), 2, [0, n]).equations([0])
    polished = ADMMLasso(n_lambdas=100).fit_path(ne)
    plain = ADMMLasso(n_lambdas=100, polish_every=0).fit_path(ne)
    G, B, (s, ys, _) = ADMMLasso._scaled(ne)
    worst_plain = 0.0
    for eq in range(2):
        for k in range(100):
            lam = polished.params[k, eq]
            x = polished.coefs[k, :, eq] * s / ys[eq]
            assert _kkt_violation(G, B[:, eq], x, lam) < 1e-12, f"not optimal at #{k} eq {eq}"
            xp = plain.coefs[k, :, eq] * s / ys[eq]
            worst_plain = max(worst_plain, _kkt_violation(G, B[:, eq], xp, lam))
    np.testing.assert_array_equal(polished.coefs != 0, plain.coefs != 0)
    assert worst_plain > 1e-12  # the conditions above are tighter than ADMM's stop: the check can fail
    # q2_dot = q1 exactly: the LASSO solution is 1 - lambda, now to rounding
    lams = polished.params[:, 1]
    np.testing.assert_allclose(polished.coefs[:, 1, 1] * s[1] / ys[1], np.maximum(1 - lams, 0), atol=1e-13)


def test_a_warm_start_changes_where_the_iterates_start_not_where_they_end(table1_run):
    """The inclusion probabilities start each held-out placement's path from the fit's own path
    (fit_paths(start=...)): the paths must be those of a cold start (same supports at every lambda,
    coefficients to 1e-9 of the largest: both are certified minimisers or within ADMM's tolerance), and
    the start must actually be used (fewer iterations), alone or in a batch."""
    A, Y = _scaled_problem(table1_run)
    n = A.shape[0]
    gram = BlockGram(np.column_stack([A, Y]), 2, np.linspace(0, n, 51).round().astype(int))
    rng = np.random.default_rng(5)
    fit_path = ADMMLasso().fit_path(gram.equations(np.arange(50) % 5 != 0))  # the fit: every 5th block held out
    nes = [gram.equations(rng.permutation(50) >= 10) for _ in range(6)]      # six other placements
    opt = ADMMLasso()
    cold = opt.fit_paths(nes)
    warm = opt.fit_paths(nes, start=fit_path)
    for c, w, ne in zip(cold, warm, nes):
        np.testing.assert_array_equal(c.coefs != 0, w.coefs != 0)
        np.testing.assert_allclose(w.coefs, c.coefs, rtol=0, atol=1e-9 * np.abs(c.coefs).max())
        alone = opt.fit_paths([ne], start=fit_path)[0]
        np.testing.assert_array_equal(alone.iterations, w.iterations)
    assert max(w.iterations.max() for w in warm) < max(c.iterations.max() for c in cold)
