"""Tests of the beta-NMF core (thesis section 2.1)."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.decomposition import NMF as SkNMF
from sklearn.decomposition._nmf import _beta_divergence
from sklearn.utils.estimator_checks import check_estimator

from mmconcepts.errors import ConvergenceWarning, DataError, ParameterError
from mmconcepts.nmf import (
    NMF,
    beta_divergence,
    beta_nmf,
    dictionary_distance,
    hoyer_sparseness,
    match_components,
    mm_exponent,
    project_hoyer,
)

BETAS = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]


def _positive(rng, n=40, m=30):
    return rng.random((n, m)) + 0.05


def _lowrank(rng, n=50, m=30, k=4):
    W = rng.gamma(1.0, 1.0, (n, k))
    H = rng.gamma(1.0, 1.0, (k, m))
    return W, H, W @ H


# --------------------------------------------------------------------------- losses
@pytest.mark.parametrize("beta", BETAS + [3.0, -0.5])
def test_loss_equals_sklearn(rng, beta):
    X = _positive(rng)
    W, H = rng.random((40, 5)), rng.random((5, 30))
    assert beta_divergence(X, W, H, beta) == pytest.approx(_beta_divergence(X, W, H, beta), rel=1e-10)


@pytest.mark.parametrize("beta", [0.5, 1.0, 1.5, 2.0, 2.5])
def test_sparse_loss_equals_dense(rng, beta):
    X = sp.random(60, 40, density=0.1, random_state=3, format="csr") * 5
    W, H = rng.random((60, 4)), rng.random((4, 40))
    assert beta_divergence(X, W, H, beta) == pytest.approx(beta_divergence(X.toarray(), W, H, beta), rel=1e-9)


def test_loss_named_betas_and_values(rng):
    X = _positive(rng, 5, 4)
    W, H = rng.random((5, 2)), rng.random((2, 4))
    Y = W @ H
    assert beta_divergence(X, W, H, "frobenius") == pytest.approx(0.5 * np.sum((X - Y) ** 2))
    assert beta_divergence(X, W, H, "kullback-leibler") == pytest.approx(np.sum(X * np.log(X / Y) - X + Y))
    assert beta_divergence(X, W, H, "itakura-saito") == pytest.approx(np.sum(X / Y - np.log(X / Y) - 1))
    assert beta_divergence(X, W, H, 1.0) == pytest.approx(beta_divergence(X, W, H, 1.0 + 1e-7), rel=1e-5)


def test_mm_exponent_table_2_2():
    assert mm_exponent(0.0) == 0.5
    assert mm_exponent(0.5) == pytest.approx(1 / 1.5)
    assert mm_exponent(1.0) == mm_exponent(2.0) == 1.0
    assert mm_exponent(3.0) == 0.5


# --------------------------------------------------------------------------- monotonicity
@pytest.mark.parametrize(
    "kind, beta",
    # beta <= 0 is undefined on the zeros of a sparse matrix (refused, tested below)
    [(kind, beta) for kind in ("dense", "sparse", "masked") for beta in BETAS if kind != "sparse" or beta > 0],
)
def test_mu_never_increases_loss(rng, beta, kind):
    X = _positive(rng)
    mask = None
    if kind == "sparse":
        X = sp.csr_matrix(X * (rng.random(X.shape) < 0.3))
    elif kind == "masked":
        mask = rng.random(X.shape) < 0.7
    res = beta_nmf(X, 5, beta_loss=beta, init="random", random_state=1, max_iter=60, tol=0, loss_every=1, mask=mask)
    steps = np.diff(res.loss_history)
    assert steps.max() <= 1e-9 * res.loss_history[0]
    assert res.loss_history[-1] < 0.9 * res.loss_history[0]


def test_heuristic_update_is_an_option(rng):
    X = _positive(rng)
    mm = beta_nmf(X, 4, beta_loss=0.5, init="random", random_state=0, max_iter=30, tol=0)
    heur = beta_nmf(X, 4, beta_loss=0.5, update_rule="heuristic", init="random", random_state=0, max_iter=30, tol=0)
    assert not np.allclose(mm.W, heur.W)
    assert heur.loss_history[-1] < heur.loss_history[0]
    # identical for 1 <= beta <= 2 where gamma = 1
    a = beta_nmf(X, 4, beta_loss=1.5, init="random", random_state=0, max_iter=10, tol=0)
    b = beta_nmf(X, 4, beta_loss=1.5, update_rule="heuristic", init="random", random_state=0, max_iter=10, tol=0)
    np.testing.assert_array_equal(a.W, b.W)


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0, 2.5])
def test_mu_matches_sklearn_iterates(rng, beta):
    X = _positive(rng, 50, 20)
    W0, H0 = rng.random((50, 4)), rng.random((4, 20))
    sk = SkNMF(4, init="custom", solver="mu", beta_loss=beta, max_iter=80, tol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
    res = beta_nmf(X, 4, init="custom", W=W0, H=H0, beta_loss=beta, max_iter=80, tol=0)
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(res.H, sk.components_, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("order", ["C", "F"])
def test_blocked_kl_update_matches_sklearn_over_several_blocks(rng, order):
    # 300 features give blocks of 1747 rows: 4000 rows make three blocks, the last partial.
    X = np.asarray(_positive(rng, 4000, 300), order=order)
    W0, H0 = rng.random((4000, 3)), rng.random((3, 300))
    sk = SkNMF(3, init="custom", solver="mu", beta_loss=1.0, max_iter=5, tol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
    res = beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=5, tol=0)
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-10)
    np.testing.assert_allclose(res.H, sk.components_, rtol=1e-10)


def _blocked_kl_case(rng):
    # 2000 features give blocks of 262 rows: 2458 rows make ten blocks (the last partial), in
    # eight stripes of two or one blocks, so stripes sum several blocks and threads several stripes.
    X = _positive(rng, 2458, 2000)
    return X, rng.random((2458, 3)), rng.random((3, 2000))


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_blocked_kl_update_in_threads_matches_sklearn(rng, threads):
    from threadpoolctl import threadpool_limits

    X, W0, H0 = _blocked_kl_case(rng)
    sk = SkNMF(3, init="custom", solver="mu", beta_loss=1.0, max_iter=4, tol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
    with threadpool_limits(limits=threads, user_api="blas"):
        res = beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=4, tol=0)
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-10)
    np.testing.assert_allclose(res.H, sk.components_, rtol=1e-10)


def test_blocked_kl_update_does_not_depend_on_the_number_of_threads(rng):
    from threadpoolctl import threadpool_limits

    X, W0, H0 = _blocked_kl_case(rng)
    out = []
    for threads in (1, 2, 3):
        with threadpool_limits(limits=threads, user_api="blas"):
            out.append(beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=4, tol=0))
    for res in out[1:]:
        np.testing.assert_array_equal(res.W, out[0].W)
        np.testing.assert_array_equal(res.H, out[0].H)


def _fit_in_child(args):
    X, W0, H0 = args
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):
        return beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=2, tol=0).W


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_blocked_kl_update_runs_in_a_forked_child(rng):
    # The parent's thread pool does not exist in a forked child: the child must make its own.
    import multiprocessing as mp

    from threadpoolctl import threadpool_limits

    X, W0, H0 = _blocked_kl_case(rng)
    with threadpool_limits(limits=2, user_api="blas"):
        want = beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=2, tol=0).W
    with mp.get_context("fork").Pool(1) as pool:
        got = pool.apply_async(_fit_in_child, ((X, W0, H0),)).get(timeout=60)
    np.testing.assert_array_equal(got, want)


def _blas_thread_counts():
    from threadpoolctl import threadpool_info

    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_blocked_kl_update_from_other_threads_is_reproducible(rng):
    # Off the main thread the blocks run one after the other and never touch the process-wide
    # BLAS thread count: fits running at once in two threads equal the same fits run alone.
    import threading

    from threadpoolctl import threadpool_limits

    X, W0, H0 = _blocked_kl_case(rng)
    W1 = rng.random(W0.shape)

    def fit(W, out, key):
        out[key] = beta_nmf(X, 3, init="custom", W=W, H=H0, beta_loss=1.0, max_iter=3, tol=0)

    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_thread_counts()
        alone: dict = {}
        for key, W in (("a", W0), ("b", W1)):
            t = threading.Thread(target=fit, args=(W, alone, key))
            t.start()
            t.join()
        together: dict = {}
        threads = [threading.Thread(target=fit, args=(W, together, key)) for key, W in (("a", W0), ("b", W1))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert _blas_thread_counts() == before
    for key in ("a", "b"):
        np.testing.assert_array_equal(together[key].W, alone[key].W)
        np.testing.assert_array_equal(together[key].H, alone[key].H)


def test_blocked_kl_update_restores_the_blas_threads(rng):
    from threadpoolctl import threadpool_limits

    X, W0, H0 = _blocked_kl_case(rng)
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_thread_counts()
        beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=2, tol=0)
        assert _blas_thread_counts() == before


def _child_blas_threads(_):
    return _blas_thread_counts()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_child_forked_while_blocks_run_gets_the_blas_threads_back(rng):
    # A fork while the main thread's blocks hold BLAS at one thread (another thread forks)
    # must not leave the child with one BLAS thread for good.
    import multiprocessing as mp

    from threadpoolctl import threadpool_limits

    from mmconcepts.nmf import _problem

    X, W0, H0 = _blocked_kl_case(rng)
    with threadpool_limits(limits=2, user_api="blas"):
        beta_nmf(X, 3, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=1, tol=0)  # makes the controller
        before = _blas_thread_counts()
        _problem._limiter = _problem._blas.limit(limits=1)  # as inside _stripes_in_threads
        try:
            with mp.get_context("fork").Pool(1) as pool:
                child = pool.apply_async(_child_blas_threads, (None,)).get(timeout=60)
        finally:
            _problem._limiter.restore_original_limits()
            _problem._limiter = None
    assert child == before


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_projected_gradient_decreases_loss(rng, beta):
    W, H, X = _lowrank(rng)
    res = beta_nmf(X, 4, beta_loss=beta, solver="pg", init="random", random_state=0, max_iter=40, tol=0, loss_every=1)
    assert np.diff(res.loss_history).max() <= 1e-9 * res.loss_history[0]
    assert res.loss_history[-1] < 0.05 * res.loss_history[0]
    assert (res.W >= 0).all() and (res.H >= 0).all()


def _lin_steps(f, gradient, L, alpha, n_inner=5, sigma=0.01, shrink=0.1):
    """Lin's (2007) projected-gradient steps with the Armijo rule along the projection arc, every objective
    evaluated afresh by ``f``: the reference for :meth:`_Solver._pg_step`. Returns (L, the step carried to the next
    call)."""
    for _ in range(n_inner):
        grad, f0 = gradient(L), f(L)

        def trial(a):
            Ln = np.maximum(L - a * grad, 0.0)
            fn = f(Ln)
            return bool(np.isfinite(fn)) and fn - f0 <= sigma * float(np.sum(grad * (Ln - L))), Ln

        ok, Ln = trial(alpha)
        if ok:
            for _ in range(20):
                ok2, Ln2 = trial(alpha / shrink)
                if not ok2 or np.array_equal(Ln2, Ln):
                    break
                alpha, Ln = alpha / shrink, Ln2
        else:
            start = alpha
            for _ in range(40):
                alpha *= shrink
                ok, Ln = trial(alpha)
                if ok:
                    break
            if not ok:
                return L, start  # stationary: the step stays the one this inner step started with
        L = Ln
    return L, alpha


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), beta=st.sampled_from([0.5, 1.0, 1.5]), side=st.sampled_from([0, 1]),
       step=st.sampled_from([1e-4, 1e-2, 1.0]))
def test_the_projected_gradient_step_is_lins_rule_with_every_objective_evaluated(seed, beta, side, step):
    """The projected gradient's inner steps start from the objective its accepted trial evaluated: the same steps as
    Lin's rule evaluating the objective afresh (numpy, thesis eq. 2.3, infinite where a product is 0) at every inner
    step."""
    from mmconcepts.nmf._problem import Problem
    from mmconcepts.nmf._solver import _Solver
    from mmconcepts.nmf._updates import Penalty

    g = np.random.default_rng(seed)
    X = g.gamma(1.0, 1.0, (15, 11)) + 0.01
    W, Ht = g.gamma(1.0, 1.0, (15, 3)) + 0.1, g.gamma(1.0, 1.0, (11, 3)) + 0.1
    solver = _Solver(Problem(X), beta, "pg", "mm", (Penalty(), Penalty()), (None, None))
    solver.step[side] = step
    L, R, Xs = (W, Ht, X) if side == 0 else (Ht, W, X.T)

    def f(L):  # X > 0 everywhere; a step that zeroes a row of L makes the divergence infinite for beta <= 1
        Y = L @ R.T
        with np.errstate(divide="ignore"):
            if beta == 1.0:
                return np.sum(Xs * np.log(Xs / Y) - Xs + Y)
            return np.sum(Xs**beta + (beta - 1) * Y**beta - beta * Xs * Y ** (beta - 1)) / (beta * (beta - 1))

    expected, alpha = _lin_steps(f,
                                 lambda L: solver._gradient(side, solver.problem.sides[side], L, R), L.copy(), step)
    got = solver._pg_step(side, solver.problem.sides[side], L.copy(), R)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=0)
    assert solver.step[side] == pytest.approx(alpha, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sparse=st.booleans(), l1=st.sampled_from([0.0, 0.3]),
       l2=st.sampled_from([0.0, 0.7]), side=st.sampled_from([0, 1]), scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_the_quadratic_armijo_change_is_the_objective_difference(seed, sparse, l1, l2, side, scale):
    """Under the unmasked Frobenius loss the projected gradient's trials take f(L + D) - f(L) from the gradient and
    R^T R; it equals the difference of the objective computed directly (numpy), penalties included."""
    from mmconcepts.nmf._problem import Problem
    from mmconcepts.nmf._solver import _quadratic_change, _Solver
    from mmconcepts.nmf._updates import Penalty

    g = np.random.default_rng(seed)
    X = g.gamma(1.0, scale, (23, 17)) * (g.random((23, 17)) < 0.4)
    W, Ht = g.gamma(1.0, 1.0, (23, 4)), g.gamma(1.0, 1.0, (17, 4))
    pen = Penalty(l1=l1, l2=l2)
    solver = _Solver(Problem(sp.csr_matrix(X) if sparse else X), 2.0, "pg", "mm", (pen, pen), (None, None))
    L, R, Xs = (W, Ht, X) if side == 0 else (Ht, W, X.T)
    Ln = np.maximum(L - 0.05 * g.standard_normal(L.shape), 0.0)

    def f(L):
        return 0.5 * np.sum((Xs - L @ R.T) ** 2) + l1 * L.sum() + 0.5 * l2 * np.sum(L * L)

    grad = solver._gradient(side, solver.problem.sides[side], L, R)
    np.testing.assert_allclose(grad, L @ R.T @ R - Xs @ R + l1 + l2 * L, rtol=1e-10, atol=1e-10 * np.abs(grad).max())
    D = Ln - L
    change = _quadratic_change(float(np.sum(grad * D)), D, R.T @ R, l2)
    direct = f(Ln) - f(L)
    assert change == pytest.approx(direct, rel=1e-9, abs=1e-12 * f(L))
    assert change == pytest.approx(solver._side_objective(side, Ln, R) - solver._side_objective(side, L, R),
                                   rel=1e-9, abs=1e-12 * f(L))


@pytest.mark.parametrize("sparse", [False, True])
def test_projected_gradient_frobenius_takes_the_steps_of_the_evaluated_objective(rng, sparse, monkeypatch):
    """The unmasked Frobenius fit decides its steps without evaluating the objective (a mask of ones, which
    evaluates it, gives the same fit), with penalties."""
    from mmconcepts.nmf import _solver

    W, H, X = _lowrank(rng)
    X = X * (rng.random(X.shape) < 0.5)
    X = sp.csr_matrix(X) if sparse else X
    fit = dict(init="random", random_state=0, max_iter=30, tol=0, alpha_W=0.01, l1_ratio=0.5)
    evaluated = beta_nmf(X, 4, beta_loss=2.0, solver="pg", mask=np.ones(X.shape), **fit)

    def refuse(*args, **kwargs):
        raise AssertionError("the side objective was evaluated")

    side_objective = _solver._Solver._side_objective
    monkeypatch.setattr(_solver._Solver, "_side_objective", refuse)
    quadratic = beta_nmf(X, 4, beta_loss=2.0, solver="pg", **fit)
    np.testing.assert_allclose(quadratic.W, evaluated.W, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(quadratic.H, evaluated.H, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(quadratic.loss_history, evaluated.loss_history, rtol=1e-9)
    # a mask that hides cells: the loss is no longer the quadratic of R^T R, the trials evaluate it
    calls = []
    monkeypatch.setattr(_solver._Solver, "_side_objective", lambda *a: calls.append(1) or side_objective(*a))
    mask = (rng.random(X.shape) < 0.8).astype(float)
    masked = beta_nmf(X, 4, beta_loss=2.0, solver="pg", mask=mask, **fit)
    assert calls and np.diff(masked.loss_history).max() <= 1e-9 * masked.loss_history[0]


# --------------------------------------------------------------------------- sparse, dtype, masks
@pytest.mark.parametrize("beta", [0.5, 1.0, 1.5, 2.0, 2.5])
def test_sparse_fit_equals_dense_fit(rng, beta):
    X = sp.random(80, 50, density=0.1, random_state=2, format="csr")
    X.data = rng.poisson(3.0, X.nnz) + 1.0
    a = beta_nmf(X, 5, beta_loss=beta, init="random", random_state=0, max_iter=40, tol=0)
    b = beta_nmf(X.toarray(), 5, beta_loss=beta, init="random", random_state=0, max_iter=40, tol=0)
    np.testing.assert_allclose(a.W, b.W, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(a.H, b.H, rtol=1e-7, atol=1e-10)


def _numerator_reference(X, weights, L, R, beta, eps):
    """sum_p w_p x_p max(y_p, eps)**(beta - 2) R[j_p] per row, y = L R^T at the stored entries (numpy)."""
    rows = np.repeat(np.arange(X.shape[0]), np.diff(X.indptr))
    y = np.einsum("pk,pk->p", L[rows], R[X.indices])
    if beta < 2.0:
        y = np.maximum(y, eps)
    e = X.data * y ** (beta - 2.0) * (weights if weights.size else 1.0)
    return np.asarray(sp.csr_matrix((e, X.indices, X.indptr), shape=X.shape) @ R), y


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
@pytest.mark.parametrize("weighted", [False, True])
def test_sparse_kernels_agree_with_numpy_for_every_tiling(rng, beta, weighted):
    """The sparse kernels walk each group of rows tile by tile of R's rows: every tile size and
    number of row groups gives numpy's answer, and the same bits (a row's entries are summed in
    their stored order whatever the tiling), column indices sorted or not."""
    from mmconcepts.nmf import _kernels

    X = sp.random(23, 700, density=0.08, random_state=5, format="csr")
    X.data = rng.poisson(2.0, X.nnz) + 1.0
    L, R = rng.random((23, 6)), rng.random((700, 6))
    w = rng.random(X.nnz) if weighted else np.empty(0)
    ref_num, ref_y = _numerator_reference(X, w, L, R, beta, 1e-9)
    none = _kernels._NO_DEN  # no fused update
    def factors(Z, weights, groups):  # the kernel's scratch
        return _kernels._factors(Z.indptr, Z.data, weights, L, groups)

    keep = _kernels._NO_RATIOS
    whole = _kernels._mu_numerator(X.indptr, X.indices, X.data, w, L, R, beta, 1e-9, 0.0, np.empty_like(L), none, 1, 10**9,
                                   factors(X, w, 1), keep, _kernels._NO_SUMS)
    np.testing.assert_allclose(whole, ref_num, rtol=1e-12)
    shuffled = X.copy()  # the same entries, each row's column indices in another order
    for i in range(X.shape[0]):
        sl = slice(X.indptr[i], X.indptr[i + 1])
        order = rng.permutation(sl.stop - sl.start)
        shuffled.indices[sl], shuffled.data[sl] = X.indices[sl][order], X.data[sl][order]
    for groups, tile in [(1, 1), (2, 7), (3, 64), (23, 100), (5, 699), (2, 701)]:
        got = _kernels._mu_numerator(X.indptr, X.indices, X.data, w, L, R, beta, 1e-9, 0.0, np.empty_like(L), none, groups,
                                     tile, factors(X, w, groups), keep, _kernels._NO_SUMS)
        np.testing.assert_array_equal(got, whole)
        y = _kernels._lowrank_at_nonzeros(X.indptr, X.indices, L, R, np.empty(X.nnz), groups, tile)
        np.testing.assert_allclose(y if beta >= 2.0 else np.maximum(y, 1e-9), ref_y, rtol=1e-13)
        got = _kernels._mu_numerator(shuffled.indptr, shuffled.indices, shuffled.data, np.empty(0), L, R, beta, 1e-9,
                                     0.0, np.empty_like(L), none, groups, tile, factors(shuffled, np.empty(0), groups),
                                     keep, _kernels._NO_SUMS)
        np.testing.assert_allclose(got, _numerator_reference(shuffled, np.empty(0), L, R, beta, 1e-9)[0], rtol=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_fused_kl_update_equals_numerator_then_numpy_update(rng, dtype):
    """The sparse I-divergence update divides each finished numerator row in the kernel: L ends
    as ``L * (N / den)`` computed by numpy, bit for bit, for every tiling, its entries below
    ``flush_below`` set to zero (and only those)."""
    from mmconcepts.nmf import _kernels

    X = sp.random(19, 500, density=0.1, random_state=7, format="csr", dtype=dtype)
    X.data = (rng.poisson(2.0, X.nnz) + 1.0).astype(dtype)
    L, R = rng.random((19, 5)).astype(dtype), rng.random((500, 5)).astype(dtype)
    flush = _kernels.flush_below(dtype)
    assert flush == np.sqrt(np.finfo(dtype).tiny).astype(dtype)
    den = R.sum(axis=0)
    eps = dtype(_kernels.EPSILON)
    none = np.empty(0, dtype)

    def numerator(L):
        return _kernels._mu_numerator(X.indptr, X.indices, X.data, none, L, R, 1.0, eps, 0.0, np.empty_like(L),
                                      _kernels._NO_DEN, 1, 10**9, _kernels._factors(X.indptr, X.data, none, L, 1),
                                      _kernels._NO_RATIOS, _kernels._NO_SUMS)

    # entries that the update takes below the flush: some lowered (set to zero), one raised (kept)
    L[1] *= 1e-3  # a row far below its data: its factors are above 1
    rising = np.argwhere(numerator(L)[1:] / den > 1.0)[0] + (1, 0)
    L[0, :3] = flush * np.array([0.5, 1.0, 4.0], dtype=dtype)
    L[tuple(rising)] = flush / 1e6
    N = numerator(L)
    expected = L * (N / den)
    low = (expected < flush) & (N / den < 1.0)
    assert expected[tuple(rising)] < flush and not low[tuple(rising)]
    assert 1 <= low.sum() == int(low[0, :3].sum())  # only those made low
    expected[low] = 0.0
    for groups, tile in [(1, 10**9), (2, 64), (3, 7), (19, 1)]:
        L2 = L.copy()
        kept = np.full(X.nnz, np.nan)
        ratio = _kernels._mu_numerator(X.indptr, X.indices, X.data, none, L2, R, 1.0, eps, flush,
                                       np.empty_like(L), den, groups, tile, _kernels._factors(X.indptr, X.data, none, L,
                                                                                              groups), kept,
                                       _kernels._NO_SUMS)
        np.testing.assert_array_equal(ratio, N / den)
        np.testing.assert_array_equal(L2, expected)  # L updated in place by the kernel
        # the ratios x / y of the L it started from, at every stored entry
        y = np.einsum("ij,ij->i", L[np.repeat(np.arange(19), np.diff(X.indptr))], R[X.indices])
        np.testing.assert_allclose(kept, X.data.astype(np.float64) / y, rtol=1e-12 if dtype == np.float64 else 1e-5)
    L3 = L.copy()
    assert _kernels.kl_update(X.indptr, X.indices, X.data, L3, R, den, np.empty_like(L)) is L3
    np.testing.assert_array_equal(L3, expected)


@pytest.mark.parametrize("sparse", [True, False])
def test_kl_transform_with_a_fixed_dictionary_matches_sklearn(rng, sparse):
    """W's updates against a fixed H (transform) reuse H's sums; the iterates stay scikit-learn's."""
    from sklearn.decomposition import non_negative_factorization

    X = sp.random(40, 300, density=0.1, random_state=8, format="csr")
    X.data = rng.poisson(3.0, X.nnz) + 1.0
    X = X[:, np.asarray(X.getnnz(axis=0)) > 0]
    X = X if sparse else X.toarray()
    H = rng.random((4, X.shape[1])) + 0.1
    W0 = np.full((40, 4), np.sqrt(X.mean() / 4))  # scikit-learn's start when H is fixed (it ignores a given W)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk, _, _ = non_negative_factorization(X, W=W0.copy(), H=H.copy(), n_components=4, init="custom",
                                                update_H=False, solver="mu", beta_loss=1.0, max_iter=40, tol=0)
    res = beta_nmf(X, 4, init="custom", W=W0, H=H, update_H=False, beta_loss=1.0, max_iter=40, tol=0)
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(res.H, H)


def test_frobenius_transform_forms_the_dictionary_products_once(rng, monkeypatch):
    """Under beta = 2, W's updates against a fixed H (transform) form X H^T and H H^T once: the iterates are
    scikit-learn's and, to the bit, those of updates that form them every time; an R not the fixed one is
    never served the fixed one's products."""
    from sklearn.decomposition import non_negative_factorization

    import mmconcepts.nmf._problem as problem

    X = rng.random((40, 300)) ** 3
    H = rng.random((6, 300)) + 0.1
    W0 = np.full((40, 6), np.sqrt(X.mean() / 6))  # scikit-learn's start when H is fixed (it ignores a given W)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk, _, _ = non_negative_factorization(X, W=W0.copy(), H=H.copy(), n_components=6, init="custom",
                                                update_H=False, solver="mu", beta_loss=2.0, max_iter=50, tol=0)
    formed = []
    dense_nd = problem.Side._dense_nd

    def spy(self, L, R, beta, fixed=False):
        formed.append(self.fixed_products is None or self.fixed_products[0] is not R or not fixed)
        return dense_nd(self, L, R, beta, fixed)

    monkeypatch.setattr(problem.Side, "_dense_nd", spy)
    res = beta_nmf(X, 6, init="custom", W=W0, H=H, update_H=False, beta_loss=2.0, max_iter=50, tol=0)
    assert len(formed) == 50 and sum(formed) == 1
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-10, atol=1e-14)
    monkeypatch.undo()
    # the same updates forming every product each time
    side, Ht = problem.Problem(X).sides[0], np.ascontiguousarray(H.T)
    W = W0.copy()
    for _ in range(50):
        num, den = side.numerator_denominator(W, Ht, 2.0)
        W *= num / den
    np.testing.assert_array_equal(res.W, W)
    # another R, even after the fixed one's products were kept: its own products
    side = problem.Problem(X).sides[0]
    side.numerator_denominator(W0, Ht, 2.0, fixed=True)
    other = Ht * 2.0
    num, den = side.numerator_denominator(W0, other, 2.0, fixed=True)
    np.testing.assert_allclose(num, X @ other, rtol=1e-13)
    np.testing.assert_allclose(den, W0 @ (other.T @ other), rtol=1e-13)


def test_sparse_kl_fit_flushes_entries_no_product_should_underflow_and_keeps_sklearn_iterates(rng):
    """A sparse I-divergence fit whose factors' entries fall by orders of magnitude per iteration (scikit-learn's
    own iterates hold entries between 0 and the square root of the smallest normal number): ours hold none
    there (set to zero) and stay scikit-learn's iterates to 1e-10."""
    from mmconcepts.nmf import _kernels

    X = sp.random(2000, 300, density=0.01, format="csr", random_state=np.random.RandomState(0),
                  data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
    X = X[:, np.asarray(X.getnnz(axis=0)) > 0]
    scale = np.sqrt(X.mean() / 10)
    W0, H0 = np.abs(scale * rng.standard_normal((2000, 10))), np.abs(scale * rng.standard_normal((10, X.shape[1])))
    sk = SkNMF(10, init="custom", solver="mu", beta_loss=1.0, max_iter=100, tol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
    flush = _kernels.flush_below(np.float64)

    def low(A):
        return int(((A > 0) & (A < flush)).sum())

    assert low(W_sk) + low(sk.components_) > 0  # the case reaches the flush
    res = beta_nmf(X, 10, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=100, tol=0)
    assert low(res.W) == low(res.H) == 0
    assert (res.W == 0).sum() > (W_sk == 0).sum()
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-10, atol=1e-10 * np.abs(W_sk).max())
    np.testing.assert_allclose(res.H, sk.components_, rtol=1e-10, atol=1e-10 * np.abs(sk.components_).max())


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_dense_update_flushes_the_entries_it_lowers_below_the_smallest_normal_number(rng, beta):
    """A dense multiplicative update is numpy's ``L * N / D``, except that an entry it lowers below the smallest
    normal number is zero; one that it raises is kept however small (a start of subnormal size climbs back)."""
    import mmconcepts.nmf._problem as problem
    from mmconcepts.nmf._updates import Penalty, mu_update

    X = rng.random((20, 15)) + 0.1
    L, R = rng.random((20, 3)) + 0.1, rng.random((15, 3)) + 0.1
    tiny = np.finfo(np.float64).tiny
    L[0, 0], L[1, 1] = 4.0 * tiny, 1e-320  # the first falls below tiny under a factor below 1/4; the second rises
    L[2, 2] = 1e-200  # falls, and stays above tiny: kept
    side = problem.Problem(X).sides[0]
    num, den = side.numerator_denominator(L, R, beta)
    factor = num / den
    factor[0, 0], factor[1, 1], factor[2, 2] = 0.1, 8.0, 0.5  # (through the numerator: the update reads N / D)
    num = factor * den
    expected = L * (num / den)
    assert 0 < expected[0, 0] < tiny and 0 < expected[1, 1] < tiny and factor[1, 1] > 1
    assert tiny < expected[2, 2] < 1e-154
    expected[0, 0] = 0.0

    class Fixed:  # the side's numerator and denominator, the first entry's made to fall
        def numerator_denominator(self, L, R, beta, fixed=False):
            return num.copy(), den

    got = mu_update(Fixed(), L.copy(), R, beta, 1.0, Penalty())
    np.testing.assert_array_equal(got, expected)


def test_sparse_fit_over_many_tiles_matches_sklearn(rng, monkeypatch):
    """A fit whose dictionary spans many tiles (tiles shrunk to 64 of 1000 columns) keeps
    scikit-learn's KL iterates."""
    from mmconcepts.nmf import _kernels

    monkeypatch.setattr(_kernels, "_TILE_BYTES", 1)
    assert _kernels._tiling(np.zeros(31), np.zeros((1000, 4))) == (min(30, _kernels.nb.get_num_threads()), 64)
    X = sp.random(30, 1000, density=0.05, random_state=6, format="csr")
    X.data = rng.poisson(3.0, X.nnz) + 1.0
    X = X[:, np.asarray(X.getnnz(axis=0)) > 0]  # no empty column (they would leave the iterations)
    W0, H0 = rng.random((30, 4)) + 0.1, rng.random((4, X.shape[1])) + 0.1
    sk = SkNMF(4, init="custom", solver="mu", beta_loss=1.0, max_iter=30, tol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        W_sk = sk.fit_transform(X.toarray(), W=W0.copy(), H=H0.copy())
    res = beta_nmf(X, 4, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=30, tol=0)
    np.testing.assert_allclose(res.W, W_sk, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(res.H, sk.components_, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("beta, rule, alpha", [(1.0, "mm", 0.0), (0.5, "mm", 0.0), (2.0, "mm", 0.01),
                                               (2.5, "heuristic", 0.0), (1.5, "mm", 0.01)])
def test_empty_columns_left_out_after_the_first_update_match_sklearn(rng, beta, rule, alpha, monkeypatch):
    """Most columns of a sparse count matrix hold nothing (HAC): after the first update they are
    left out of the iterations (their H columns are exactly 0) and put back as zeros; the iterates
    are scikit-learn's on the whole matrix."""
    from mmconcepts.nmf import _solver

    X = sp.random(40, 400, density=0.01, random_state=4, format="csr")
    X.data = rng.poisson(3.0, X.nnz) + 1.0
    empty = np.asarray(X.getnnz(axis=0)) == 0
    assert empty.mean() > 0.5
    W0, H0 = rng.random((40, 4)) + 0.1, rng.random((4, 400)) + 0.1
    reduced = []
    real = _solver._EmptyColumns.reduce

    def spy(self, sol, Ht):
        out = real(self, sol, Ht)
        reduced.append(out is not None and out[1].shape[0])
        return out

    monkeypatch.setattr(_solver._EmptyColumns, "reduce", spy)
    widths = []  # rows of Ht at each update of Ht

    def spy_on(real_update):
        def spy_update(side, L, R, *args):
            if L.shape[1] == 4 and R.shape[0] == 40:
                widths.append(L.shape[0])
            return real_update(side, L, R, *args)
        return spy_update

    # (the unpenalised I-divergence's one-pass update, and every other)
    monkeypatch.setattr(_solver, "sparse_kl_update", spy_on(_solver.sparse_kl_update))
    monkeypatch.setattr(_solver, "mu_update", spy_on(_solver.mu_update))
    kw = dict(beta_loss=beta, max_iter=60, tol=0, alpha_W=alpha, l1_ratio=0.5)
    rule_kw = {} if rule == "mm" else {"update_rule": rule}
    res = beta_nmf(X, 4, init="custom", W=W0, H=H0, **kw, **rule_kw)
    kept = int((~empty).sum())
    assert reduced == [kept]  # left out once, after the first iteration
    assert widths == [400] + [kept] * 59
    assert (res.H[:, empty] == 0).all()
    if rule == "mm" and 1.0 <= beta <= 2.0:  # scikit-learn's MU is the MM rule for beta in [1, 2]
        sk = SkNMF(4, init="custom", solver="mu", beta_loss=beta, max_iter=60, tol=0, alpha_W=alpha, l1_ratio=0.5)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            W_sk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
        np.testing.assert_allclose(res.W, W_sk, rtol=1e-6, atol=1e-8 * W_sk.max())
        np.testing.assert_allclose(res.H, sk.components_, rtol=1e-6, atol=1e-8 * sk.components_.max())
    # the same fit over all the columns (the leaving-out disabled) to rounding
    monkeypatch.setattr(_solver._EmptyColumns, "MIN_SHARE", 2.0)
    full = beta_nmf(X, 4, init="custom", W=W0, H=H0, **kw, **rule_kw)
    assert len(reduced) == 1
    np.testing.assert_allclose(res.W, full.W, rtol=1e-10, atol=1e-12 * full.W.max())
    np.testing.assert_allclose(res.H, full.H, rtol=1e-10, atol=1e-12 * full.H.max())
    np.testing.assert_allclose(res.loss_history, full.loss_history, rtol=1e-12)
    assert res.n_iter == full.n_iter


def test_empty_columns_left_out_stop_at_the_same_iteration(rng, monkeypatch):
    """With the stopping rule on (tol > 0, the objective every iteration), leaving the empty columns out
    changes neither when the fit stops nor the recorded objectives."""
    from mmconcepts.nmf import _solver

    X = sp.random(40, 400, density=0.01, random_state=6, format="csr")
    X.data = rng.poisson(3.0, X.nnz) + 1.0
    kw = dict(beta_loss=1.0, init="random", random_state=2, max_iter=500, tol=1e-3, loss_every=1)
    res = beta_nmf(X, 4, **kw)
    monkeypatch.setattr(_solver._EmptyColumns, "MIN_SHARE", 2.0)
    full = beta_nmf(X, 4, **kw)
    assert res.converged and 1 < res.n_iter < 500
    assert res.n_iter == full.n_iter
    np.testing.assert_array_equal(res.loss_iterations, full.loss_iterations)
    np.testing.assert_allclose(res.loss_history, full.loss_history, rtol=1e-12)
    np.testing.assert_allclose(res.H, full.H, rtol=1e-10, atol=1e-12 * full.H.max())


def test_empty_columns_kept_where_they_cannot_be_left_out(rng, monkeypatch):
    """A mask, a fixed H or Hoyer's constraints: the columns stay (their H need not become 0)."""
    from mmconcepts.nmf import _solver

    X = sp.random(30, 200, density=0.01, random_state=5, format="csr")
    X.data += 1.0
    calls = []
    monkeypatch.setattr(_solver._EmptyColumns, "reduce", lambda self, sol, Ht: calls.append(1))
    mask = np.ones(X.shape, bool)
    beta_nmf(X, 3, beta_loss=1.0, mask=mask, init="random", random_state=0, max_iter=5, tol=0)
    beta_nmf(X, 3, beta_loss=2.0, sparseness_H=0.5, init="random", random_state=0, max_iter=5, tol=0)
    beta_nmf(X, 3, beta_loss=1.0, update_H=False, H=rng.random((3, 200)), max_iter=5, tol=0)
    beta_nmf(X, 3, beta_loss=1.0, init="random", random_state=0, max_iter=1, tol=0)
    assert calls == []
    beta_nmf(X, 3, beta_loss=1.0, init="random", random_state=0, max_iter=5, tol=0)
    assert calls == [1]


@pytest.mark.parametrize("sparse", [False, True])
def test_float32_kept_and_agrees_with_float64(rng, sparse):
    _, _, X = _lowrank(rng)
    X32 = X.astype(np.float32)
    if sparse:
        X, X32 = sp.csr_matrix(X), sp.csr_matrix(X32)
    m64 = NMF(4, beta_loss=1, init="random", random_state=0, max_iter=50, tol=0).fit(X)
    m32 = NMF(4, beta_loss=1, init="random", random_state=0, max_iter=50, tol=0).fit(X32)
    assert m32.components_.dtype == np.float32
    assert m32.transform(X32).dtype == np.float32
    np.testing.assert_allclose(m32.components_, m64.components_, rtol=2e-3, atol=1e-4)


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("sparse", [False, True])
def test_garbage_in_masked_cells_changes_nothing(rng, beta, sparse):
    X = _positive(rng)
    mask = rng.random(X.shape) < 0.75
    garbage = X.copy()
    garbage[~mask] = rng.choice([1e6, -5.0, np.nan, np.inf, 0.0], size=int((~mask).sum()))
    clean = X.copy()
    clean[~mask] = 0.0
    if sparse:
        clean = sp.csr_matrix(clean)
        g2 = garbage.copy()
        g2[~np.isfinite(g2)] = 7.0  # sparse matrices hold finite junk here
        garbage = sp.csr_matrix(g2)
    a = NMF(5, beta_loss=beta, init="random", random_state=0, max_iter=30, tol=0).fit(clean, mask=mask)
    b = NMF(5, beta_loss=beta, init="random", random_state=0, max_iter=30, tol=0).fit(garbage, mask=mask)
    np.testing.assert_allclose(a.components_, b.components_, rtol=1e-10)
    np.testing.assert_allclose(a.transform(clean, mask=mask), b.transform(garbage, mask=mask), rtol=1e-10)


def test_mask_recovers_missing_cells(rng):
    W, H, X = _lowrank(rng, 60, 40, 3)
    mask = rng.random(X.shape) < 0.8
    model = NMF(3, beta_loss=1, init="random", random_state=0, max_iter=1500, tol=0)
    Wf = model.fit_transform(np.where(mask, X, np.nan), mask=mask)
    Xhat = model.inverse_transform(Wf)
    err_missing = np.abs(Xhat - X)[~mask].mean() / X[~mask].mean()
    assert err_missing < 0.05


# --------------------------------------------------------------------------- transform on features
@pytest.mark.parametrize("beta", [1.0, 2.0])
@pytest.mark.parametrize("features", [slice(0, 20), np.arange(10, 30), "bool"])
def test_transform_on_feature_subset_recovers_coefficients(rng, beta, features):
    k, m = 3, 30
    H = rng.gamma(0.5, 1.0, (k, m))
    H /= H.sum(axis=0, keepdims=True) * 0.4 + H.sum(axis=1, keepdims=True)  # rows do not sum to one
    W = rng.gamma(2.0, 1.0, (25, k))
    X = W @ H
    if isinstance(features, str):
        features = np.zeros(m, bool)
        features[::2] = True
    model = NMF(k, beta_loss=beta, init="custom", max_iter=1, tol=0, transform_max_iter=3000)
    model.fit(X, W=W, H=H)
    model.components_ = H  # the exact dictionary
    idx = np.arange(m)[features]
    W_hat = model.transform(X[:, idx], features=features)
    np.testing.assert_allclose(W_hat, W, rtol=2e-3)
    np.testing.assert_allclose(model.inverse_transform(W_hat, features=features), X[:, idx], rtol=2e-3)


def test_subset_update_without_denominator_is_biased(rng):
    """The thesis author's update dropped the denominator: biased when atoms do not sum to one."""
    H = rng.gamma(0.5, 1.0, (3, 30))
    W = rng.gamma(2.0, 1.0, (10, 3))
    X = W @ H
    sub = slice(0, 12)
    Hs = H[:, sub]
    Wb = np.full_like(W, 1.0)
    for _ in range(3000):  # I-divergence update without the denominator Hs.sum(axis=1)
        Wb *= ((X[:, sub] / (Wb @ Hs)) @ Hs.T) / H.sum(axis=1)
    model = NMF(3, beta_loss=1, init="custom", max_iter=1, tol=0, transform_max_iter=3000).fit(X, W=W, H=H)
    model.components_ = H
    good = model.transform(X[:, sub], features=sub)
    assert np.abs(good - W).max() / W.max() < 1e-2
    assert np.abs(Wb - W).max() / W.max() > 0.1


def test_features_validation(rng):
    X = _positive(rng, 10, 6)
    model = NMF(2, init="random", random_state=0, max_iter=5, tol=0, transform_max_iter=5).fit(X)
    with pytest.raises(ParameterError, match="out of range"):
        model.transform(X[:, :2], features=[0, 9])
    with pytest.raises(ParameterError, match="boolean mask"):
        model.transform(X[:, :2], features=np.array([True, False]))
    with pytest.raises(DataError, match="features selects 3"):
        model.transform(X[:, :2], features=[0, 1, 2])
    with pytest.raises(DataError, match="X has 5 features, but NMF is expecting 6"):
        model.transform(X[:, :5])
    with pytest.raises(ParameterError, match="selects no feature"):
        model.inverse_transform(np.ones((1, 2)), features=slice(3, 3))


# --------------------------------------------------------------------------- online
@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0])
def test_partial_fit_single_batch_equals_fit(rng, beta):
    X = _positive(rng)
    kw = dict(beta_loss=beta, init="random", random_state=0, max_iter=30, tol=0, forget_factor=1.0)
    full = NMF(4, **kw).fit(X)
    online = NMF(4, **kw).partial_fit(X)
    np.testing.assert_allclose(online.components_, full.components_, rtol=1e-9)


def _separable(rng, n=200, k=4, width=6):
    H = np.zeros((k, k * width))
    for i in range(k):  # separable atoms: each has features of its own, so the dictionary is identifiable
        H[i, i * width:(i + 1) * width] = rng.uniform(0.5, 1.5, width)
    W = rng.gamma(1.0, 1.0, (n, k))
    return W, H, W @ H


def test_partial_fit_streams_batches(rng):
    W, H, X = _separable(rng, 400, 3, 10)
    model = NMF(3, beta_loss=1, init="random", random_state=0, max_iter=20, forget_factor=0.9)
    for _ in range(3):
        for batch in np.array_split(X, 8):
            model.partial_fit(batch)
    assert model.n_steps_ == 24
    assert dictionary_distance(model.components_, H) < 0.05
    with pytest.raises(DataError, match="expecting 30"):
        model.partial_fit(X[:, :10])


# --------------------------------------------------------------------------- constraints and penalties
def test_hoyer_known_values_and_infeasible_norms():
    # the projection's invariants are property tests in tests/nmf/test_properties.py
    assert hoyer_sparseness(np.ones(9)) == pytest.approx(0.0)
    assert hoyer_sparseness(np.eye(9)[0]) == pytest.approx(1.0)
    with pytest.raises(ParameterError, match="no vector"):
        project_hoyer(np.ones(4), 5.0, 1.0)


def test_hoyer_constraints_hold_after_fit(rng):
    _, _, X = _lowrank(rng, 60, 40, 4)
    res = beta_nmf(X, 4, sparseness_H=0.6, sparseness_W=0.3, init="random", random_state=0, max_iter=40, tol=0,
                   loss_every=1)
    np.testing.assert_allclose(hoyer_sparseness(res.H, axis=1), 0.6, atol=1e-6)
    np.testing.assert_allclose(hoyer_sparseness(res.W, axis=0), 0.3, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(res.H, axis=1), 1.0, rtol=1e-6)
    assert res.loss_history[-1] < res.loss_history[1]


def test_l1_penalty_sparsifies(rng):
    _, _, X = _lowrank(rng)
    kw = dict(beta_loss=1, init="random", random_state=0, max_iter=300, tol=0)
    plain = NMF(6, **kw).fit_transform(X)
    l1 = NMF(6, alpha_W=0.05, l1_ratio=1.0, **kw).fit_transform(X)  # alpha_H='same': both factors
    assert np.nanmean(hoyer_sparseness(l1, axis=1)) > np.nanmean(hoyer_sparseness(plain, axis=1)) + 0.2
    assert (l1 < 1e-3 * l1.max()).mean() > (plain < 1e-3 * plain.max()).mean() + 0.2


# --------------------------------------------------------------------------- inits
@pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")  # short fits on purpose
@pytest.mark.parametrize("init", ["random", "nndsvd", "nndsvda", "nndsvdar"])
def test_inits(rng, init):
    _, _, X = _lowrank(rng)
    model = NMF(4, beta_loss=2, init=init, random_state=0, max_iter=300)
    model.fit(X)
    # plain NNDSVD keeps exact zeros, which multiplicative updates cannot leave
    assert model.reconstruction_err_ / np.linalg.norm(X) < (0.5 if init == "nndsvd" else 0.05)
    assert model.loss_history_[-1] < model.loss_history_[0]
    again = NMF(4, beta_loss=2, init=init, random_state=0, max_iter=300).fit(X)
    np.testing.assert_array_equal(model.components_, again.components_)


def _blocks(rng, beta):
    """Three diagonal blocks of decreasing weight. With two components NNDSVD's factors are zero on
    the third block (rows 14-18, columns 11-14), which W @ H then misses entirely. For beta <= 0,
    3e-7 everywhere makes X positive; NNDSVD's threshold still zeroes the third block."""
    from scipy.linalg import block_diag

    X = block_diag(rng.random((8, 6)) + 1.0, rng.random((6, 5)) + 0.5, rng.random((5, 4)) + 0.2)
    return X + 3e-7 if beta <= 0 else X


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0, 1.5, 2.0])
def test_nndsvd_start_leaves_no_cell_of_x_out_of_reach(rng, beta):
    """A zero of W or H never moves under the multiplicative updates: NNDSVD's zeros on the third
    block left W @ H zero there for the whole fit (an infinite objective for beta <= 1, cells never
    fitted for beta > 1). The start fills them, and the objective is finite and decreases."""
    X = _blocks(rng, beta)
    res = beta_nmf(X, 2, beta_loss=beta, init="nndsvd", max_iter=100, tol=0, loss_every=1, random_state=0)
    hist = res.loss_history
    assert np.isfinite(hist).all(), hist[:3]
    assert np.all(np.diff(hist) <= 1e-10 * hist[0])
    assert hist[-1] < 0.95 * hist[0]
    assert ((res.W @ res.H)[X > 0] > 0).all()


def test_nndsvd_is_sklearns_with_the_unreachable_rows_and_columns_filled(rng):
    """Known answer: scikit-learn's NNDSVD (same randomized SVD, same seed), whose zeros are kept except
    in the rows of W and columns of H of the cells W @ H would miss, filled with the mean of X."""
    from sklearn.decomposition._nmf import _initialize_nmf

    from mmconcepts.nmf._init import initialize

    seed = int(np.random.default_rng(0).integers(0, 2**31 - 1))  # the seed initialize draws from its stream
    _, _, lowrank = _lowrank(rng)
    for X, rows, cols in ((_blocks(rng, 1.0), slice(14, 19), slice(11, 15)), (lowrank, slice(0, 0), slice(0, 0))):
        W_sk, H_sk = _initialize_nmf(X, 2, init="nndsvd", eps=1e-6, random_state=seed)
        W, H = initialize(X, 2, "nndsvd", np.random.default_rng(0))
        keep_r = np.ones(X.shape[0], bool)
        keep_r[rows] = False
        keep_c = np.ones(X.shape[1], bool)
        keep_c[cols] = False
        np.testing.assert_allclose(W[keep_r], W_sk[keep_r], rtol=1e-10, atol=0)
        np.testing.assert_allclose(H[:, keep_c], H_sk[:, keep_c], rtol=1e-10, atol=0)
        assert (W_sk[keep_r] == 0).any() or X is lowrank  # zeros elsewhere are kept
        assert (W_sk[rows] == 0).all() and (H_sk[:, cols] == 0).all()
        np.testing.assert_array_equal(W[rows], X.mean())
        np.testing.assert_array_equal(H[:, cols], X.mean())


def _custom_start(rng, zero):
    X = _positive(rng, 6, 5)
    W, H = rng.random((6, 2)) + 0.1, rng.random((2, 5)) + 0.1
    if zero == "W row":
        W[3] = 0.0
        cell, named = (3, 0), "row 3 of W is all zero"
    elif zero == "H column":
        H[:, 4] = 0.0
        cell, named = (0, 4), "column 4 of H is all zero"
    else:  # W[2] and H[:, 1] share no nonzero component
        W[2] = [1.0, 0.0]
        H[:, 1] = [0.0, 1.0]
        cell, named = (2, 1), "row 2 of W and column 1 of H have no nonzero component in common"
    return X, W, H, cell, named


@pytest.mark.parametrize("zero", ["W row", "H column", "cell"])
@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0, 1.5, 2.0])
def test_a_given_start_that_leaves_w_h_zero_where_x_is_not(rng, beta, zero):
    """beta <= 1: the objective would be infinite for the whole fit: refused, naming the first cell.
    beta > 1: a given zero is a support the updates keep (finite objective): fitted, the zeros kept.
    Masking the cells out, or the projected gradient (which moves zeros), lifts the refusal."""
    X, W, H, (i, j), named = _custom_start(rng, zero)
    fit = dict(beta_loss=beta, init="custom", max_iter=30, tol=0, loss_every=1)
    if beta <= 1:
        with pytest.raises(DataError, match=rf"W @ H is zero at \d+ cells? where X > 0 \(the first: sample {i}, "
                                            rf"feature {j}\): {named}"):
            beta_nmf(X, 2, W=W, H=H, **fit)
        unreached = (W > 0).astype(float) @ (H > 0).astype(float) == 0
        res = beta_nmf(X, 2, W=W, H=H, mask=~unreached, **fit)
        assert np.isfinite(res.loss_history).all() and res.loss_history[-1] < res.loss_history[0]
        res = beta_nmf(X, 2, W=W, H=H, solver="pg", **fit)
        assert np.isfinite(res.loss_history[-1]) and ((res.W @ res.H)[X > 0] > 0).all()
    else:
        res = beta_nmf(X, 2, W=W, H=H, **fit)
        assert np.isfinite(res.loss_history).all() and np.all(np.diff(res.loss_history) <= 1e-12)
        assert (res.W @ res.H)[i, j] == 0 and ((W == 0) <= (res.W == 0)).all()


def test_the_projected_gradient_refuses_a_start_that_stops_both_of_its_steps(rng):
    """A zero row of W makes H's step infinite whatever it does, a zero column of H makes W's: with both,
    neither factor moves and the KL objective stays infinite; with one of them, the other step repairs it."""
    X, W, H, _, _ = _custom_start(rng, "W row")
    H[:, 4] = 0.0
    with pytest.raises(DataError, match=r"sample 3, feature 0\): row 3 of W is all zero\. As the projected gradient"):
        beta_nmf(X, 2, W=W, H=H, beta_loss=1.0, solver="pg", max_iter=5)
    res = beta_nmf(X, 2, W=W, H=H, beta_loss=2.0, solver="pg", max_iter=5, tol=0)
    assert np.isfinite(res.loss_history).all()


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0])
def test_a_fixed_dictionary_with_a_zero_column_where_x_is_not(rng, beta):
    X, W, H, _, _ = _custom_start(rng, "H column")
    if beta <= 1:
        for solver in ("mu", "pg"):  # a fixed zero column stays zero whatever the solver
            with pytest.raises(DataError, match=r"column 4 of H is all zero.*update_H=False"):
                beta_nmf(X, 2, H=H, update_H=False, beta_loss=beta, solver=solver, max_iter=5)
    else:
        res = beta_nmf(X, 2, H=H, update_H=False, beta_loss=beta, max_iter=5, tol=0)
        assert np.isfinite(res.loss_history).all()


@pytest.mark.parametrize("beta", [0.5, 2.0])
def test_a_given_factor_that_is_all_zero_is_refused(rng, beta):
    """As scikit-learn: an all-zero start is no start (the multiplicative updates would keep it zero)."""
    X, W, H, _, _ = _custom_start(rng, "W row")
    with pytest.raises(DataError, match=r"^init='custom': W is all zero"):
        beta_nmf(X, 2, W=np.zeros_like(W), H=H, beta_loss=beta, init="custom")
    with pytest.raises(DataError, match=r"^init='custom': H is all zero"):
        beta_nmf(X, 2, W=W + 1, H=np.zeros_like(H), beta_loss=beta, init="custom")


@pytest.mark.parametrize("bad, match", [
    ("nan", r"W contains 1 NaN"), ("inf", r"W contains 1 NaN or infinite"), ("negative", r"Negative values .* W"),
    ("shape", r"W must have shape \(6, 2\)"), ("k", r"H must have shape \(2, 5\)"), ("1d", r"W must be 2-D"),
    ("sparse", r"W must be a dense array"), ("text", r"W must hold numbers"),
])
def test_a_given_start_that_is_not_a_pair_of_factors_is_refused(rng, bad, match):
    X, W, H, _, _ = _custom_start(rng, "cell")
    W = W.copy()
    if bad == "nan":
        W[0, 0] = np.nan
    elif bad == "inf":
        W[0, 0] = np.inf
    elif bad == "negative":
        W[0, 0] = -1.0
    elif bad == "shape":
        W = W[:-1]
    elif bad == "k":
        H = np.vstack([H, H])
    elif bad == "1d":
        W = W.ravel()
    elif bad == "sparse":
        W = sp.csr_matrix(W)
    elif bad == "text":
        W = np.full(W.shape, "a")
    with pytest.raises(DataError, match=match):
        beta_nmf(X, 2, W=W, H=H, init="custom", beta_loss=2.0)


def test_an_infinite_objective_is_named_not_blamed_on_tol():
    """The fit below ends with an infinite KL objective (a cell of 6e-319 whose reconstruction
    underflows to 0): the warning says so and names the cell, rather than asking for more iterations."""
    rng = np.random.default_rng(3)
    X = rng.random((30, 12)) * (rng.random((30, 12)) < 0.5)
    X[:, -1] = 0.0
    X[0, -1] = 6e-319
    with pytest.warns(ConvergenceWarning) as record:
        res = beta_nmf(X, 3, beta_loss=1, init="random", random_state=0, max_iter=60, tol=1e-4)
    assert np.isinf(res.loss_history[-1])
    message = str(record[0].message)
    assert "infinite objective" in message and "sample 0, feature 11" in message and "6e-319" in message
    assert "increase max_iter" not in message


def test_convergence_warning_and_tol(rng):
    X = _positive(rng)
    with pytest.warns(ConvergenceWarning):
        NMF(5, init="random", random_state=0, max_iter=3, tol=1e-12).fit(X)
    model = NMF(3, init="random", random_state=0, max_iter=5000, tol=1e-3).fit(X)
    assert model.n_iter_ < 5000
    assert model.loss_iterations_[-1] == model.n_iter_


class _ScriptedSolver:
    """A solver whose updates change nothing and whose objective follows a script; ``fused``: read from the next W
    update where there is one, as the sparse I-divergence's update reads it."""

    def __init__(self, values, fused=False):
        self.values, self.fused, self.read_apart = list(values), fused, 0

    def update(self, side, A, B):
        return A

    def objective_in_update(self):
        return self.fused

    def update_W_with_objective(self, W, Ht):
        return self.values.pop(0)

    def objective(self, W, Ht):
        self.read_apart += 1
        return self.values.pop(0)


@pytest.mark.parametrize("script, n_iter, converged", [
    # finite -> infinite (a subnormal cell whose reconstruction underflows): not a decrease
    ([100.0, 90.0, np.inf, np.inf, np.inf, np.inf], 5, False),
    # infinite, then two finite objectives that settle: converged at the second finite one
    ([100.0, 90.0, np.inf, 50.0, 50.0, 50.0], 4, True),
    # an overflowing start waits for the first finite error as its reference
    ([np.inf, 90.0, 90.0, 10.0, 10.0, 10.0], 2, True),
    ([100.0, 90.0, 80.0, 70.0, 70.0, 70.0], 4, True),
])
@pytest.mark.parametrize("fused", [False, True])
def test_stopping_rule_never_reads_an_infinite_objective_as_progress(script, n_iter, converged, fused):
    from mmconcepts.nmf._solver import _iterate

    W, Ht = np.ones((2, 1)), np.ones((3, 1))
    solver = _ScriptedSolver(script, fused)
    out = _iterate(solver, W, Ht, True, 5, 1e-3, 1)
    assert (out[2], out[5]) == (n_iter, converged)
    np.testing.assert_array_equal(out[3], script[:n_iter + 1])
    np.testing.assert_array_equal(out[4], np.arange(n_iter + 1))
    # read from the W updates, but for the last iteration's (no update follows it)
    assert solver.read_apart == (1 if fused and n_iter == 5 else 0 if fused else n_iter + 1)


@pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")
def test_kl_fit_with_subnormal_cells_runs_until_it_settles():
    """Soft-VQ histograms hold cells of about 1e-319; the KL objective can become infinite."""
    rng = np.random.default_rng(3)
    X = rng.random((30, 12)) * (rng.random((30, 12)) < 0.5)
    X[:, -1] = 0.0
    X[0, -1] = 6e-319  # the only mass of the last column: its dictionary entries underflow
    model = NMF(3, beta_loss=1, init="random", random_state=0, max_iter=60, tol=1e-4).fit(X)
    hist = model.loss_history_
    assert not (np.isinf(hist[-1]) and model.n_iter_ < 60), (model.n_iter_, hist)


# --------------------------------------------------------------------------- comparison
def test_matching_distance_zero_for_scaled_permuted_copy(rng):
    A = rng.random((6, 20))
    perm = rng.permutation(6)
    B = A[perm] * rng.uniform(0.1, 10, (6, 1))
    for metric in ["cosine", "euclidean", "l1"]:
        match = match_components(A, B, metric=metric)
        assert match.distance == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_array_equal(perm[match.cols], match.rows)
    assert dictionary_distance(A, rng.random((6, 20))) > 0.05


@pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")  # short fits on purpose
def test_recovery_of_identifiable_dictionary(rng):
    W, H, X = _separable(rng)
    model = NMF(4, beta_loss=1, init="random", random_state=0, max_iter=2000, tol=1e-7).fit(X)
    assert dictionary_distance(model.components_, H) < 1e-3


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "X, match",
    [
        (np.array([[1.0, -1.0], [0.5, 2.0]]), "Negative values"),
        (np.array([[1.0, np.nan], [0.5, 2.0]]), "NaN"),
        (np.array([[1.0, np.inf], [0.5, 2.0]]), "NaN or infinite"),
        (np.zeros((0, 3)), "0 sample"),
        (np.ones(3), "2-D"),
    ],
)
def test_bad_data(X, match):
    with pytest.raises(DataError, match=match):
        NMF(1).fit(X)


@pytest.mark.parametrize("form", ["dense", "sparse", "dok", "object"])
@pytest.mark.parametrize("masked", [False, True])
def test_complex_data_is_refused_with_or_without_a_mask(rng, form, masked):
    """Complex X is refused whether or not a mask comes with it, dense, sparse or one complex number in an
    object array (never its imaginary part dropped), by beta_nmf, NMF.fit and beta_divergence alike."""
    X = _positive(rng, 6, 5) + 1j * rng.random((6, 5))
    if form == "sparse":
        X = sp.csr_matrix(X)
    elif form == "dok":  # a sparse format without a .data array
        X = sp.dok_array(X)
    elif form == "object":
        X = X.real.astype(object)
        X[2, 3] = 1 + 1j
    mask = np.ones((6, 5), bool) if masked else None
    with pytest.raises(DataError, match="Complex data not supported: X holds complex numbers"):
        beta_nmf(X, 2, mask=mask, max_iter=2)
    with pytest.raises(DataError, match="Complex data not supported"):
        NMF(2, max_iter=2).fit(X, mask=mask)
    with pytest.raises(DataError, match="Complex data not supported"):
        beta_divergence(X, np.ones((6, 2)), np.ones((2, 5)), 2, mask=mask)


@pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")  # short fits on purpose
def test_bad_parameters(rng):
    X = _positive(rng, 6, 5)
    with pytest.raises(ParameterError, match="n_components"):
        NMF(0).fit(X)
    with pytest.raises(ParameterError, match="solver"):
        NMF(2, solver="als").fit(X)
    with pytest.raises(ParameterError, match="beta_loss"):
        NMF(2, beta_loss="hellinger").fit(X)
    with pytest.raises(ParameterError, match="init"):
        NMF(2, init="svd").fit(X)
    with pytest.raises(ParameterError, match="sparseness_H"):
        NMF(2, sparseness_H=1.5).fit(X)
    X0 = X.copy()
    X0[0, 0] = 0
    with pytest.raises(DataError, match="beta_loss=0 is undefined"):
        NMF(2, beta_loss=0).fit(X0)
    mask = np.ones_like(X0, bool)
    mask[0, 0] = False
    NMF(2, beta_loss=0, init="random", random_state=0, max_iter=5).fit(X0, mask=mask)  # masked zero is fine
    with pytest.raises(DataError, match="shape of X"):
        NMF(2).fit(X, mask=np.ones((2, 2), bool))
    with pytest.raises(DataError, match="observes no cell"):
        NMF(2).fit(X, mask=np.zeros_like(X, bool))
    with pytest.raises(DataError, match="W must have shape"):
        NMF(2, init="custom").fit(X, W=np.ones((3, 2)), H=np.ones((2, 5)))
    for err in (DataError, ParameterError):
        assert issubclass(err, ValueError)


# --------------------------------------------------------------------------- scikit-learn contract
@pytest.mark.slow
@pytest.mark.parametrize(
    "estimator",
    [NMF(2, max_iter=1000, tol=1e-6), NMF(2, beta_loss=1, max_iter=1000, tol=1e-6),
     NMF(2, solver="pg", beta_loss=1, max_iter=500, tol=1e-6)],
    ids=["mu-frobenius", "mu-kl", "pg-kl"],
)
def test_sklearn_estimator_checks(estimator):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = check_estimator(estimator, on_fail=None)
    failed = [(r["check_name"], str(r["exception"])[:200]) for r in results if r["status"] == "failed"]
    assert failed == []
    assert sum(r["status"] == "passed" for r in results) > 40


def test_stopping_rule_waits_for_a_finite_objective():
    """KL against a dictionary column of denormal size overflows the first objective to inf.

    The rule used to divide by that infinite reference (stopping at the second finite check,
    wherever the fit was) and warn about inf - inf; it now takes the first finite error as the
    reference, so the fit runs to the tolerance.
    """
    import warnings

    rng = np.random.default_rng(0)
    X = rng.random((30, 12)) + 0.1
    W0, H0 = rng.random((30, 3)) + 0.1, rng.random((3, 12)) + 0.1
    H0[:, 0] = 1e-320
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning from inf - inf
        res = beta_nmf(X, 3, beta_loss=1, W=W0, H=H0, init="custom", max_iter=500, tol=1e-4)
    assert res.loss_history[0] == np.inf and np.isfinite(res.loss_history[1:]).all()
    assert res.converged and res.n_iter > 30
    errs = np.sqrt(2 * res.loss_history[1:])
    # it stopped where scikit-learn's rule says, measured from the first finite error
    assert (errs[-2] - errs[-1]) / errs[0] < 1e-4 <= (errs[-3] - errs[-2]) / errs[0]


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0])
def test_rescale_features_scales_the_dictionary_and_the_pooled_statistics(rng, beta):
    """A known answer: columns times c, A times c ** (1/gamma + beta - 1), B times c ** (beta - 1) (I-divergence: B
    untouched, still one broadcast row); other columns and a factor of 1 change nothing."""
    from mmconcepts.nmf import mm_exponent

    X = rng.random((30, 8)) + 0.1
    model = NMF(3, beta_loss=beta, max_iter=5, random_state=0)
    model.partial_fit(X[:15]).partial_fit(X[15:])
    H0 = model.components_.copy()
    A0, B0 = (np.array(s, copy=True) for s in model._stats)
    cols, c = slice(2, 5), 3.0
    assert model.rescale_features(cols, 1.0) is model and np.array_equal(model.components_, H0)
    model.rescale_features(cols, c)
    gamma = mm_exponent(beta)
    expected_H = H0.astype(np.float64)
    expected_H[:, cols] *= c
    np.testing.assert_array_equal(model.components_, expected_H)
    A, B = model._stats
    np.testing.assert_allclose(A[cols], A0[cols] * c ** (1 / gamma + beta - 1), rtol=1e-12)
    np.testing.assert_array_equal(np.delete(A, np.s_[2:5], axis=0), np.delete(A0, np.s_[2:5], axis=0))
    np.testing.assert_allclose(B[cols], B0[cols] * c ** (beta - 1), rtol=1e-12)
    if beta == 1.0:
        assert B.strides[0] == 0  # still one row broadcast over the features
    model.rescale_features(cols, 1 / c)  # and back
    np.testing.assert_allclose(model.components_, H0, rtol=1e-12)


def test_rescale_features_refuses_a_bad_factor_or_an_unfitted_model(rng):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        NMF(2).rescale_features(slice(None), 2.0)
    model = NMF(2, max_iter=3, random_state=0).fit(rng.random((10, 4)))
    for bad in (0.0, -1.0, np.inf, np.nan):
        with pytest.raises(ParameterError, match="positive finite"):
            model.rescale_features(slice(None), bad)


# --------------------------------------------------------------------------- coefficients to convergence
def _nnls_rows(X, H, mask=None, l2=0.0):
    """The exact coefficients for beta = 2 (scipy's NNLS, one row at a time): an outside answer.

    An L2 penalty l2 |w|^2 / 2 is the same least squares with sqrt(l2) I below H.T and zeros below x."""
    from scipy.optimize import nnls

    X = X.toarray() if sp.issparse(X) else X
    k = H.shape[0]
    out = np.empty((X.shape[0], k))
    for i, x in enumerate(X):
        cols = np.ones(X.shape[1], bool) if mask is None else mask[i]
        A = np.vstack([H[:, cols].T, np.sqrt(l2) * np.eye(k)])
        out[i] = nnls(A, np.concatenate([x[cols], np.zeros(k)]), maxiter=50 * k)[0]
    return out


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("case", ["dense", "sparse", "mask", "features", "l2", "sparse-mask", "mask-k+1"])
def test_frobenius_transform_is_the_exact_nonnegative_least_squares(rng, case):
    """With H fixed, beta = 2 is nonnegative least squares per row: transform matches scipy's NNLS.

    Multiplicative updates alone leave the coefficients percents from it (asserted, so that the
    test shows the difference the solution to convergence makes)."""
    X = rng.random((60, 25)) ** 2
    model = NMF(6, random_state=0, alpha_W=0.01 if case == "l2" else 0.0, max_iter=300).fit(X)
    if "sparse" in case:
        X[-2:] = 0.0  # empty last rows of a CSR matrix
    H = model.components_
    mask = rng.random(X.shape) < 0.7 if "mask" in case else None
    if case == "mask-k+1":  # each row observes one feature more than there are atoms: still one minimiser
        mask = np.argsort(rng.random(X.shape), axis=1) < 7
    Xin = sp.csr_matrix(X) if "sparse" in case else X
    if case == "features":
        cols = np.arange(3, 20)
        W, want = model.transform(X[:, cols], features=cols), _nnls_rows(X[:, cols], H[:, cols])
    else:
        W = model.transform(Xin, mask=mask)
        want = _nnls_rows(X, H, mask, l2=X.shape[1] * model.alpha_W)
    np.testing.assert_allclose(W, want, rtol=0, atol=1e-7 * want.max())
    mu_only = beta_nmf(X if mask is None else X * mask, 6, H=H, update_H=False, mask=mask, max_iter=200,
                       alpha_W=model.alpha_W) if case != "features" else None
    if mu_only is not None:
        assert np.abs(mu_only.W - want).max() > 1e-3 * want.max()


def _row_minimum(x, H, observed, beta):
    """The coefficients of one row by scipy's L-BFGS-B on (w >= 0), for 1 <= beta <= 2: an outside answer.

    The objective drops the terms that do not depend on w: y - x log y (beta = 1), and
    y^beta / beta - x y^(beta-1) / (beta - 1) otherwise; its gradient is H (y^(beta-1) - x y^(beta-2))."""
    from scipy.optimize import minimize

    Hc, xc = H[:, observed], x[observed]

    def f(w):
        y = np.maximum(w @ Hc, 1e-300)
        if beta == 1.0:
            value = np.sum(y - xc * np.log(y))
        else:
            value = np.sum(y**beta / beta - xc * y ** (beta - 1) / (beta - 1))
        return float(value), Hc @ (y ** (beta - 1) - xc * y ** (beta - 2))

    res = minimize(f, np.full(H.shape[0], xc.mean() / Hc.mean() / H.shape[0]), jac=True, method="L-BFGS-B",
                   bounds=[(0, None)] * H.shape[0], options=dict(ftol=1e-15, gtol=1e-12, maxiter=20000))
    return res.x


@pytest.mark.parametrize("beta, case", [(1.0, "dense"), (1.0, "sparse"), (1.0, "mask"), (1.0, "float32"),
                                        (1.5, "dense"), (1.5, "mask")])
@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_transform_is_the_minimum_scipy_finds(rng, beta, case):
    X = rng.gamma(1.0, 1.0, (30, 20))
    X[rng.random(X.shape) < 0.2] = 0.0  # zeros: the sparse path only visits the stored values
    model = NMF(4, beta_loss=beta, random_state=0, max_iter=300).fit(X)
    X[-2:] = 0.0  # rows without a value (the last rows of a CSR matrix): their coefficients are 0
    H = model.components_
    mask = rng.random(X.shape) < 0.7 if case == "mask" else None
    Xin = {"sparse": sp.csr_matrix(X), "float32": X.astype(np.float32)}.get(case, X)
    W = model.transform(Xin, mask=mask)
    assert W.dtype == (np.float32 if case == "float32" else np.float64)
    want = np.array([_row_minimum(x, H, np.ones(X.shape[1], bool) if mask is None else mask[i], beta)
                     for i, x in enumerate(X)])
    np.testing.assert_allclose(W, want, rtol=0, atol=(1e-4 if case == "float32" else 1e-6) * want.max())


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("beta", [1.0, 1.5, 2.0])
def test_coefficients_scale_with_the_data_and_against_the_dictionary(rng, beta):
    """Homogeneity: the coefficients of c X are c times those of X, and those of X for the dictionary
    d H are 1 / d times; at 2 ** +-40 the solver works on rescaled data (exact powers of two)."""
    X = rng.gamma(1.0, 1.0, (20, 12))
    model = NMF(3, beta_loss=beta, random_state=0, max_iter=100).fit(X)
    W = model.transform(X)
    for c in [2.0**40, 2.0**-40]:
        np.testing.assert_allclose(model.transform(c * X), c * W, rtol=1e-7, atol=1e-9 * c * W.max())
    model.components_ = model.components_ * 2.0**40
    np.testing.assert_allclose(model.transform(X), W / 2.0**40, rtol=1e-7, atol=1e-9 * W.max() / 2.0**40)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_coefficients_with_an_l2_penalty_scale_with_the_data(rng):
    """beta = 2 with an L2 penalty on W: both terms scale as c^2, so the coefficients of c X are c times
    those of X, the penalty brought to the rescaled problem's units (and not the same without it)."""
    X = rng.gamma(1.0, 1.0, (20, 12))
    model = NMF(3, random_state=0, max_iter=100, alpha_W=0.05).fit(X)
    W = model.transform(X)
    c = 2.0**40
    np.testing.assert_allclose(model.transform(c * X), c * W, rtol=1e-7, atol=1e-9 * c * W.max())
    assert np.abs(NMF(3, random_state=0, max_iter=100).fit(X).transform(X) - W).max() > 1e-3 * W.max()
    # a dictionary at 2 ** -30 is rescaled for the solver, and the penalty with it: scipy's NNLS, as given
    model.components_ = model.components_ * 2.0**-30
    want = _nnls_rows(X, model.components_, l2=X.shape[1] * model.alpha_W)
    np.testing.assert_allclose(model.transform(X), want, rtol=0, atol=1e-7 * want.max())


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("beta", [1.0, 1.5, 2.0])
@pytest.mark.parametrize("sparse", [False, True])
def test_newton_steps_converge_in_a_few_steps_from_the_updates(rng, beta, sparse):
    """Quadratic convergence once the zero coefficients are found: a handful of steps from the
    updates' coefficients (a wrong Hessian still descends, but needs many more)."""
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = rng.gamma(0.5, 1.0, (80, 40))
    model = NMF(6, beta_loss=beta, random_state=0, max_iter=200).fit(X)
    start = beta_nmf(X, 6, H=model.components_, update_H=False, beta_loss=beta, max_iter=200).W
    W, converged = solve_coefficients(sp.csr_matrix(X) if sparse else X, model.components_, start, beta, max_iter=8)
    assert converged
    np.testing.assert_allclose(W, model.transform(X), rtol=0, atol=1e-6 * W.max())


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("beta", [1.0, 1.5, 2.0])
@pytest.mark.parametrize("start", ["flat", "1000 times", "1/1000 times", "random"])
def test_newton_steps_reach_the_minimum_from_any_start(rng, beta, start):
    """The Armijo search along the projection arc makes the steps converge from far starts too (full
    Newton steps alone do not, e.g. for beta = 1.5 from 1000 times the minimum)."""
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = rng.gamma(0.5, 1.0, (80, 40))
    model = NMF(6, beta_loss=beta, random_state=0, max_iter=200).fit(X)
    want = model.transform(X)
    W0 = {"flat": np.full_like(want, want.mean()), "1000 times": 1000 * want + 1, "1/1000 times": 1e-3 * want + 1e-6,
          "random": 10 * rng.random(want.shape)}[start]
    W, converged = solve_coefficients(X, model.components_, W0, beta)
    assert converged
    np.testing.assert_allclose(W, want, rtol=0, atol=1e-7 * want.max())


def _kernel_density_rows(rng, n, m, width):
    """Rows of a few Gaussian bumps, normalised: kernel-density histograms, whose tails fall to 1e-100 of the peak."""
    bins = np.arange(m)
    X = np.zeros((n, m))
    for row in X:
        for centre in rng.uniform(0, m, rng.integers(1, 4)):
            row += rng.uniform(0.5, 1.0) * np.exp(-0.5 * ((bins - centre) / width) ** 2)
    return X / X.sum(axis=1, keepdims=True)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_no_row_of_wide_kernel_density_histograms_stops_above_its_minimum():
    """30 kernel-density rows over 256 bins, 150 atoms (chapter 3's sizes): scipy's L-BFGS-B, started from each row's
    answer, lowers no row's I-divergence by more than 1e-9 of it (an outside answer; the test above starts it from
    the updates' start, which it does not always bring as low). Rows were declared converged 6.9e-4 above their
    minimum where the search along the projection arc failed at the largest ridge (held coefficients shrinking at
    every step length): they now take multiplicative updates and Newton's steps again. No RuntimeWarning either."""
    from scipy.optimize import minimize

    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = _kernel_density_rows(np.random.default_rng(1), 30, 256, 4.0)
    H = NMF(150, beta_loss=1.0, random_state=1, max_iter=200).fit(X).components_
    start = beta_nmf(X, 150, H=H, update_H=False, max_iter=100, random_state=2).W
    W, converged = solve_coefficients(X, H, start, 1.0)
    assert converged
    for w, x in zip(W, X):
        def f(v, x=x):
            y = np.maximum(v @ H, 1e-300)
            return float(np.sum(y - x * np.log(y))), H @ (1.0 - x / y)

        better = minimize(f, w, jac=True, method="L-BFGS-B", bounds=[(0, None)] * len(w),
                          options=dict(ftol=1e-15, gtol=1e-12, maxiter=20000)).x
        ours, theirs = (elementwise_beta_divergence(x, v @ H, 1.0).sum() for v in (w, better))
        assert ours <= theirs * (1 + 1e-9)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("seed, n, m, k, width", [(0, 30, 64, 20, 2.5), (0, 30, 64, 20, 3.0), (0, 30, 128, 60, 4.0),
                                                  (0, 40, 96, 40, 3.0), (3, 40, 200, 100, 5.0)])
def test_coefficients_of_kernel_density_histograms_reach_the_minimum(seed, n, m, k, width):
    """Histograms whose tails reach 1e-90 of their peak (chapter 3's kernel densities): curvatures hundreds of
    orders of magnitude apart, products far below their x, coefficients pushed to 1e-58 by the updates. The
    solver converges, to an objective no worse than scipy's L-BFGS-B from the same start (an outside answer),
    and finite: no cell with x > 0 is left without a product, however small its x."""
    from scipy.optimize import minimize

    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = _kernel_density_rows(np.random.default_rng(seed), n, m, width)
    assert (X / X.max(axis=1, keepdims=True)).min() < 1e-90
    H = NMF(k, beta_loss=1.0, random_state=1, max_iter=200).fit(X).components_
    start = beta_nmf(X, k, H=H, update_H=False, max_iter=100, random_state=2).W
    W, converged = solve_coefficients(X, H, start, 1.0)
    assert converged

    def objective(w, x):
        return elementwise_beta_divergence(x, w @ H, 1.0).sum()

    for w, w0, x in zip(W, start, X):
        def f(v, x=x):
            y = np.maximum(v @ H, 1e-300)
            return float(np.sum(y - x * np.log(y))), H @ (1.0 - x / y)

        ref = minimize(f, w0, jac=True, method="L-BFGS-B", bounds=[(0, None)] * len(w0),
                       options=dict(ftol=1e-15, gtol=1e-12, maxiter=20000)).x
        assert np.isfinite(objective(w, x)) and objective(w, x) <= objective(ref, x) * (1 + 1e-9)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("seed, n, m, k, width", [(0, 30, 64, 20, 3.0), (0, 30, 128, 60, 4.0)])
def test_no_newton_step_raises_a_rows_objective(monkeypatch, seed, n, m, k, width):
    """Every step leaves each row's objective no higher than it was, up to its rounding (1e-10 of it: the terms
    cancel to far less than their sum): a row optimal to tol takes a full Newton step only where it does not raise
    the objective (on these kernel-density rows, one that zeroed its held coefficients at once raised it by 1.5e-8
    of it, and the row cycled between such steps and searched ones to the step limit)."""
    from mmconcepts.nmf import _coefficients as C

    X = _kernel_density_rows(np.random.default_rng(seed), n, m, width)
    H = NMF(k, beta_loss=1.0, random_state=1, max_iter=200).fit(X).components_
    start = beta_nmf(X, k, H=H, update_H=False, max_iter=100, random_state=2).W
    seen: dict[int, list[float]] = {}
    directions = C._newton_directions

    def recording(model, rows, W, *args):
        for r, f in zip(rows, model.objective(rows, W)):
            seen.setdefault(int(r), []).append(float(f))
        return directions(model, rows, W, *args)

    monkeypatch.setattr(C, "_newton_directions", recording)
    _, converged = C.solve_coefficients(X, H, start, 1.0)
    assert converged
    for r, fs in seen.items():
        f = np.array(fs)
        assert np.all(f[1:] <= f[:-1] * (1 + 1e-10)), (r, np.max(f[1:] / f[:-1]))


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_coefficients_of_wide_kernel_density_histograms_converge():
    """60 atoms over 128 bins of kernel densities: every row stops before the step limit (clipped coefficients
    near zero held, cells whose x cannot matter left to collapse), and no row ends above its start."""
    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = _kernel_density_rows(np.random.default_rng(0), 30, 128, 4.0)
    H = NMF(60, beta_loss=1.0, random_state=1, max_iter=200).fit(X).components_
    start = beta_nmf(X, 60, H=H, update_H=False, max_iter=100, random_state=2).W
    W, converged = solve_coefficients(X, H, start, 1.0)
    assert converged
    f, f0 = (elementwise_beta_divergence(X, V @ H, 1.0).sum(axis=1) for V in (W, start))
    assert np.all(f <= f0)


@pytest.mark.parametrize("beta, case", [(2.0, "dense"), (2.0, "sparse"), (1.0, "sparse"), (1.0, "dense"),
                                        (1.5, "dense"), (1.0, "mask"), (1.5, "penalty")])
def test_the_curvature_blocks_are_the_gradients_derivative(rng, beta, case):
    """Each model's Hessian blocks (any order of coefficients) and diagonal against central finite differences of
    its own gradient (an outside answer), penalties included."""
    from mmconcepts.nmf._coefficients import _rows_model
    from mmconcepts.nmf._updates import Penalty

    n, m, k = 4, 12, 5
    X = rng.gamma(1.0, 1.0, (n, m)) * (rng.random((n, m)) < 0.7)
    Ht = rng.gamma(1.0, 1.0, (m, k)) + 0.1
    W = rng.random((n, k)) + 0.2
    mask = rng.random((n, m)) < 0.8 if case == "mask" else None
    penalty = Penalty(l1=0.1, l2=0.3) if case == "penalty" else Penalty()
    model = _rows_model(sp.csr_matrix(X) if case == "sparse" else X, Ht, beta, penalty, mask)
    rows = np.arange(n)

    def gradient(V):
        return np.vstack([g for _, g, _, _ in model.derivatives(rows, V)])

    (_, _, _, curvature), = list(model.derivatives(rows, W))
    order = np.array([rng.permutation(k)[:3] for _ in range(n)])
    block = curvature.block(order, rows)
    h = 1e-6
    for i in range(n):
        for a, j in enumerate(order[i]):
            step = np.zeros_like(W)
            step[i, j] = h
            column = (gradient(W + step) - gradient(W - step))[i] / (2 * h)
            np.testing.assert_allclose(block[i, :, a], column[order[i]], rtol=1e-6, atol=1e-8)
            assert curvature.diag[i, j] == pytest.approx(column[j], rel=1e-6)
    if beta == 2.0 or case != "sparse":  # the Hessian's product, where a model forms it: the same derivative along V
        V = rng.standard_normal((n, k))
        directional = (gradient(W + h * V) - gradient(W - h * V)) / (2 * h)
        np.testing.assert_allclose(curvature.product(V), directional, rtol=1e-6, atol=1e-8)


def test_gathered_scaled_rows_are_numpys_fancy_indexing_bit_for_bit(rng):
    """The kernel that stacks each row's scaled dictionary block equals numpy's indexing and product, to the bit:
    rows in any order, an empty row, columns from a non-contiguous slice."""
    from mmconcepts.nmf._kernels import gather_scaled_rows

    X = sp.random(9, 40, density=0.3, format="csr", random_state=np.random.RandomState(1))
    X = sp.csr_matrix(X.toarray() * (np.arange(9)[:, None] != 4))  # row 4 has no entry
    R = rng.gamma(1.0, 1.0, (40, 7))
    scale = rng.random(X.nnz) * 1e3
    rows = np.array([8, 4, 0, 3, 3])
    cols = np.array([rng.permutation(7) for _ in rows])[:, :5]  # non-contiguous
    lengths = np.diff(X.indptr)[rows]
    got = gather_scaled_rows(X.indptr, X.indices, scale, R, rows, cols, np.empty((lengths.sum(), 5)))
    want = np.vstack([R[X.indices[X.indptr[r]:X.indptr[r + 1], None], cols[i]] * scale[X.indptr[r]:X.indptr[r + 1], None]
                      for i, r in enumerate(rows)])
    np.testing.assert_array_equal(got, want)


def test_sparse_kl_curvature_blocks_are_the_products_of_the_scaled_dictionary(rng, monkeypatch):
    """The I-divergence Hessian block of a row of a sparse X, for a subset of rows of a later row block, is A^T A
    with A = H^T at the row's columns and the chosen coefficients, scaled by sqrt(x) / y (numpy's product)."""
    from mmconcepts.nmf import _coefficients as C

    n, m, k = 30, 50, 6
    X = sp.csr_matrix(rng.gamma(1.0, 1.0, (n, m)) * (rng.random((n, m)) < 0.4))
    Ht = rng.gamma(1.0, 1.0, (m, k)) + 0.1
    W = rng.random((n, k)) + 0.2
    model = C._rows_model(X, Ht, 1.0, C.Penalty(), None)
    rows = np.arange(n)
    y = C.lowrank_at_nonzeros(X.indptr, X.indices, W, Ht, np.empty(X.nnz))  # the products the model forms
    c = np.sqrt(X.data) / np.maximum(y, C._FLOOR)
    monkeypatch.setattr(C, "_BLOCK_CELLS", 10 * k)  # row blocks of 10 rows: the later blocks' rows start past 0
    parts = list(model.derivatives(rows, W))
    assert len(parts) == 3
    part, _, _, curvature = parts[1]
    sel = np.array([7, 2, 5, 0, 9])
    order = np.array([rng.permutation(k)[:4] for _ in sel])
    for cells in (4, 200, 1 << 22):  # rows gathered one at a time, a few at a time, all at once
        monkeypatch.setattr(C, "_BLOCK_CELLS", cells)
        got = curvature.block(order, sel)
        for i, r in enumerate(part.start + sel):
            lo, hi = X.indptr[r], X.indptr[r + 1]
            A = Ht[X.indices[lo:hi, None], order[i]] * c[lo:hi, None]
            np.testing.assert_array_equal(got[i], A.T @ A)


@pytest.mark.parametrize("masked", [False, True])
def test_a_least_squares_step_solves_the_free_coefficients_where_the_held_ones_land(rng, masked):
    """beta = 2: a full projected Newton step leaves the free coefficients at the least-squares solution (numpy's
    lstsq) for the held ones at the values the same step gives them, not at the held ones' old values (rows would
    otherwise alternate between most atoms held and none, as chapter 3's k = 150 transforms did)."""
    from mmconcepts.nmf._coefficients import _newton_directions, _rows_model
    from mmconcepts.nmf._updates import Penalty

    n, m, k = 6, 30, 8
    Ht = rng.gamma(0.5, 1.0, (m, k)) + 0.01
    X = (rng.gamma(0.5, 1.0, (n, k)) * (rng.random((n, k)) < 0.5)) @ Ht.T + 0.01 * rng.random((n, m))
    W = np.where(rng.random((n, k)) < 0.5, 1e-4, rng.random((n, k)) + 0.5)  # some near zero: candidates to hold
    mask = rng.random((n, m)) < 0.8 if masked else None
    model = _rows_model(X * (mask if masked else 1), Ht, 2.0, Penalty(), mask)
    rows = np.arange(n)
    _, _, d, active, *_ = _newton_directions(model, rows, W, 1e-7, np.full(n, 1e-14))
    landed = np.maximum(W - d, 0.0)
    checked = 0
    for i in rows:
        free = ~active[i]
        if not active[i].any() or (landed[i, free] <= 0).any():
            continue  # nothing held, or a free coefficient clipped: the step is not the restricted solution
        seen = np.ones(m, dtype=bool) if mask is None else mask[i]
        rest = X[i, seen] - Ht[seen][:, ~free] @ landed[i, ~free]
        want = np.linalg.lstsq(Ht[seen][:, free], rest, rcond=None)[0]
        np.testing.assert_allclose(landed[i, free], want, rtol=1e-7, atol=1e-9 * np.abs(want).max())
        checked += 1
    assert checked >= 2


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_least_squares_rows_over_a_wide_dictionary_reach_scipys_nnls(seed):
    """beta = 2, 150 atoms over 256 bins, rows that use about a tenth of them (chapter 3's dictionary sizes), from
    the multiplicative updates' start: every row reaches scipy's NNLS answer to 1e-9 of its largest coefficient.
    (A line search that reads the free coefficients' decrease from the raw gradient, not from the step's own
    right-hand side, stops rows about 3e-3 short here.)"""
    from scipy.optimize import nnls

    from mmconcepts.nmf._coefficients import solve_coefficients

    rng = np.random.default_rng(seed)
    H = rng.gamma(0.3, 1.0, (150, 256))
    X = (rng.gamma(0.5, 1.0, (12, 150)) * (rng.random((12, 150)) < 0.1)) @ H + 0.05 * rng.random((12, 256))
    start = beta_nmf(X, 150, H=H, update_H=False, max_iter=50, random_state=0).W
    W, converged = solve_coefficients(X, H, start, 2.0)
    assert converged
    for i in range(len(X)):
        want = nnls(H.T, X[i])[0]
        np.testing.assert_allclose(W[i], want, rtol=0, atol=1e-9 * want.max())


def test_the_curvature_model_holds_no_subnormal_number():
    """Subnormal products are a hundred times slower to form and multiply: a dictionary with entries down to
    1e-300 gives a curvature model whose entries' products are all normal numbers."""
    from mmconcepts.nmf._coefficients import _Dense
    from mmconcepts.nmf._updates import Penalty

    Ht = np.array([[1.0, 1e-200, 1e-300], [0.5, 1e-160, 2.0], [1e-155, 1e-155, 1.0]])
    model = _Dense(np.ones((2, 3)), Ht, 1.0, Penalty(), None)
    kept = model.Hn[model.Hn > 0]
    assert kept.min() ** 2 >= np.finfo(np.float64).tiny
    np.testing.assert_array_equal(model.Hn.T[Ht >= 1e-100], Ht[Ht >= 1e-100])  # the entries that matter are kept


def test_a_full_newton_step_leaves_no_cell_with_x_without_a_product():
    """Known answer: atom 2 alone reaches a cell with x = 1e-30, its coefficient 10 times its optimum; the row is
    optimal to tol, whose full Newton step would zero it (an infinite divergence): it shrinks instead."""
    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import solve_coefficients

    H = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    X = np.array([[1.0, 1.0, 1e-30]])
    W, converged = solve_coefficients(X, H, np.array([[1.0, 1e-29]]), 1.0)
    assert converged and W[0, 0] == pytest.approx(1.0, rel=1e-12) and 0 < W[0, 1] < 1e-29
    assert np.isfinite(elementwise_beta_divergence(X, W @ H, 1.0).sum())


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("beta", [1.0, 1.5, 2.0])
def test_coefficients_do_not_depend_on_the_atoms_units(rng, beta):
    """Atoms scaled by factors from 1e-40 to 1e40 (curvatures 1e160 apart): each coefficient scales by the
    inverse factor, as the products stay the same (the Newton system is scaled by its curvatures)."""
    from mmconcepts.nmf._coefficients import solve_coefficients

    X = rng.gamma(0.5, 1.0, (40, 30))
    model = NMF(6, beta_loss=beta, random_state=0, max_iter=200).fit(X)
    H = model.components_
    start = beta_nmf(X, 6, H=H, update_H=False, beta_loss=beta, max_iter=50).W
    want, converged = solve_coefficients(X, H, start, beta)
    assert converged
    units = 10.0 ** np.linspace(-40, 40, 6)
    W, converged = solve_coefficients(X, H * units[:, None], start / units, beta)
    assert converged
    np.testing.assert_allclose(W * units, want, rtol=0, atol=1e-6 * want.max())


@pytest.mark.parametrize("beta", [1.0, 1.5, 2.0])
def test_the_solvers_objective_is_the_divergence_continued_below_its_floor(beta):
    """Above the floor, d_beta itself; continuous there and finite at y = 0 where x > 0; at beta = 1, linear
    below it with the slope the gradient takes there, 1 - x / floor (for beta > 1 the change below the
    floor is beyond the objective's resolution)."""
    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import _FLOOR, _floored_divergence

    x = np.array([0.0, 1e-120, 1e-3, 1.0, 7.0])
    y = np.array([1e-90, 1e-50, 0.3, 1.0, 20.0])
    np.testing.assert_allclose(_floored_divergence(x, y, beta), elementwise_beta_divergence(x, y, beta), rtol=1e-13)
    for xi in (1e-3, 1.0):
        below, at, zero = _floored_divergence(np.full(3, xi), np.array([_FLOOR * (1 - 1e-9), _FLOOR, 0.0]), beta)
        assert below == pytest.approx(at, rel=1e-9) and np.isfinite(zero)
        if beta == 1.0:
            y1, y2 = 0.25 * _FLOOR, 0.75 * _FLOOR
            d1, d2 = _floored_divergence(np.full(2, xi), np.array([y1, y2]), beta)
            assert (d2 - d1) / (y2 - y1) == pytest.approx(1.0 - xi / _FLOOR, rel=1e-6)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_more_atoms_than_the_features_tell_apart_keep_the_updates(rng):
    """A dictionary of 6 atoms seen through 4 features: the coefficients' minimisers form a set, and
    transform gives the updates' point of it (as beta_nmf with the dictionary fixed)."""
    X = rng.gamma(1.0, 1.0, (20, 10))
    model = NMF(6, random_state=0, max_iter=50).fit(X)
    cols = [0, 3, 5, 8]
    want = beta_nmf(X[:, cols], 6, H=model.components_[:, cols], update_H=False, max_iter=50).W
    np.testing.assert_array_equal(model.transform(X[:, cols], features=cols), want)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_fit_transform_returns_the_coefficients_transform_gives(rng, beta):
    """fit_transform(X) is fit(X).transform(X): the fit's last W, solved to convergence for the final
    dictionary, is the minimiser transform reaches from its flat start; and it explains X at
    least as well as the fit's own W."""
    X = rng.gamma(1.0, 1.0, (50, 30))
    model = NMF(5, beta_loss=beta, random_state=0, max_iter=100)
    W = model.fit_transform(X)
    np.testing.assert_allclose(W, model.transform(X), rtol=0, atol=1e-7 * W.max())
    own = beta_nmf(X, 5, beta_loss=beta, random_state=0, max_iter=100).W
    assert beta_divergence(X, W, model.components_, beta) <= beta_divergence(X, own, model.components_, beta)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_outside_the_convex_betas_transform_is_the_multiplicative_updates(rng):
    """For beta outside [1, 2] (a problem in W that need not be convex) and with Hoyer constraints on W,
    transform is the multiplicative updates alone, as beta_nmf with the dictionary fixed."""
    X = rng.gamma(1.0, 1.0, (20, 10)) + 0.1
    for kw in [dict(beta_loss=0.5), dict(beta_loss=2.5), dict(sparseness_W=0.3)]:
        model = NMF(3, random_state=0, max_iter=50, **kw).fit(X)
        want = beta_nmf(X, 3, H=model.components_, update_H=False, max_iter=50,
                        **{k: v for k, v in model._solver_kwargs().items()})
        np.testing.assert_array_equal(model.transform(X), want.W)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_coefficients_that_do_not_converge_warn(rng, monkeypatch):
    import mmconcepts.nmf._estimator as est

    X = rng.gamma(1.0, 1.0, (20, 10))
    model = NMF(3, beta_loss=1, random_state=0, max_iter=20).fit(X)
    solve = est.solve_coefficients
    monkeypatch.setattr(est, "solve_coefficients", lambda *a, **kw: solve(*a, **{**kw, "max_iter": 1}))
    with pytest.warns(ConvergenceWarning, match="projected Newton steps did not converge"):
        model.transform(X)


def test_under_the_i_divergence_a_row_with_fewer_positive_values_than_atoms_has_no_single_minimiser():
    """beta = 1: a cell with x = 0 adds (w H)_j, linear in w, so it gives no curvature: a row needs as many
    observed cells with x > 0 as there are atoms (here 3 atoms, independent); beta = 2 counts observed cells."""
    from mmconcepts.nmf._coefficients import determined_rows
    from mmconcepts.nmf._updates import Penalty

    H = np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
    X = np.array([[1.0, 2.0, 3.0, 0.0],    # 3 positive values: one minimiser
                  [1.0, 2.0, 0.0, 0.0],    # 2: a set under beta = 1
                  [0.0, 0.0, 0.0, 5.0]])   # 1
    assert determined_rows(X, H, 1.0).tolist() == [True, False, False]
    assert determined_rows(sp.csr_matrix(X), H, 1.0).tolist() == [True, False, False]
    assert determined_rows(X, H, 2.0).tolist() == [True, True, True]
    mask = np.array([[True, True, False, True]] * 3)  # the third row's one positive value stays observed
    assert determined_rows(X, H, 1.0, mask=mask).tolist() == [False, False, False]
    assert determined_rows(X, H, 2.0, mask=mask).tolist() == [True, True, True]
    assert determined_rows(X, H, 1.0, penalty=Penalty(l2=0.1)).all()  # an L2 penalty: strictly convex


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_fit_does_not_solve_the_coefficients_fit_transform_does(rng, monkeypatch):
    """fit learns the dictionary only: the training coefficients, solved for the final dictionary, are
    fit_transform's (and MultimodalNMF's); fit's components are fit_transform's."""
    import mmconcepts.nmf._estimator as est
    from mmconcepts.multimodal import MultimodalNMF

    X = rng.gamma(1.0, 1.0, (30, 12))
    calls = []
    solve = est.solve_coefficients
    monkeypatch.setattr(est, "solve_coefficients", lambda *a, **kw: calls.append(1) or solve(*a, **kw))
    a = NMF(4, beta_loss=1, random_state=0, max_iter=30).fit(X)
    mm = MultimodalNMF(4, max_iter=30, random_state=0).fit({"a": X[:, :6], "b": X[:, 6:]})
    assert calls == []
    b = NMF(4, beta_loss=1, random_state=0, max_iter=30)
    b.fit_transform(X)
    MultimodalNMF(4, max_iter=30, random_state=0).fit_transform({"a": X[:, :6], "b": X[:, 6:]})
    assert len(calls) == 2
    np.testing.assert_array_equal(a.components_, b.components_)
    assert mm.components_.shape == (4, 12)


# --------------------------------------------------------------------------- cost of a fit
def test_fit_does_not_solve_the_coefficients(rng, monkeypatch):
    """fit learns the dictionary only: the coefficients solved to convergence are fit_transform's alone."""
    import mmconcepts.nmf._estimator as estimator

    X = _positive(rng)
    expected = NMF(3, beta_loss=1, random_state=0, max_iter=30).fit(X).components_

    def refuse(*args, **kwargs):
        raise AssertionError("fit solved the coefficients")

    monkeypatch.setattr(estimator, "solve_coefficients", refuse)
    model = NMF(3, beta_loss=1, random_state=0, max_iter=30).fit(X)
    np.testing.assert_array_equal(model.components_, expected)
    with pytest.raises(AssertionError, match="fit solved"):
        NMF(3, beta_loss=1, random_state=0, max_iter=30).fit_transform(X)


@pytest.mark.parametrize("kind", ["dense", "sparse", "masked", "penalised", "rescaled"])
@pytest.mark.parametrize("beta", [1.0, 2.0, 0.5])
def test_final_divergence_is_that_of_the_final_factors(rng, kind, beta):
    """extra['divergence'] (reconstruction_err_'s source) is D_beta(X | W H) of the returned factors, in X's
    units, without the penalties."""
    X = _positive(rng, 60, 45) * (rng.random((60, 45)) < 0.6)
    X[0, 0] = 1.0
    kw: dict = dict(beta_loss=beta, init="nndsvda", max_iter=25, tol=0, random_state=0)
    mask = None
    if kind == "sparse":
        X = sp.csr_matrix(X)
    elif kind == "masked":
        mask = rng.random(X.shape) < 0.8
    elif kind == "penalised":
        kw.update(alpha_W=0.01, alpha_H=0.02, l1_ratio=0.5)
    elif kind == "rescaled":  # outside the range fitted as given: the fit runs on X / 2 ** 40
        X = X * 2.0**40
    res = beta_nmf(X, 4, mask=mask, **kw)
    expected = beta_divergence(X, res.W, res.H, beta, mask=mask)
    assert res.extra["divergence"] == pytest.approx(expected, rel=1e-9)
    if kind == "penalised":
        assert res.loss_history[-1] > expected * (1 + 1e-6)
    model = NMF(4, **kw).fit(X, mask=mask)
    assert model.reconstruction_err_ == pytest.approx(np.sqrt(2 * expected), rel=1e-9)


@pytest.mark.parametrize("n, m, k", [(157, 30, 3), (40, 300, 12), (25, 25, 25)])
def test_frobenius_objective_from_the_kept_numerator(rng, n, m, k):
    """Under beta = 2 the objective after an H update reuses its numerator X^T W: it equals the elementwise sum
    (scikit-learn's _beta_divergence) on a loose fit, falls back to the direct sum on a close one, and
    a numerator kept for another W, or used once already, is not reused."""
    import mmconcepts.nmf._problem as problem
    from mmconcepts.nmf._solver import _Solver
    from mmconcepts.nmf._updates import Penalty

    X = rng.random((n, m)) * 3.0
    W, Ht = rng.random((n, k)), rng.random((m, k))
    prob = problem.Problem(X)
    sol = _Solver(prob, 2.0, "mu", "mu", (Penalty(), Penalty()), (None, None))
    sol.objective_next = True
    Ht = sol.update(1, Ht, W)
    kept = prob.sides[1].kept_numerator
    assert kept is not None and kept[0] is W
    np.testing.assert_allclose(kept[1], X.T @ W, rtol=1e-13)
    expected = _beta_divergence(X, W, Ht.T, 2.0)  # half the squared norm, as ours
    got = prob.divergence(W, Ht, 2.0)
    assert got == pytest.approx(expected, rel=1e-11)
    assert got != prob.sides[0].divergence(W, Ht, 2.0) or n * m < 1000  # the shortcut ran (rounding differs)
    assert prob.sides[1].kept_numerator is None  # used once
    # kept for another W: not reused
    Ht = sol.update(1, Ht, W)
    other = W.copy()
    assert prob.divergence(other, Ht, 2.0) == prob.sides[0].divergence(other, Ht, 2.0)
    # a close fit: the terms cancel, the direct sum is taken
    Xc = W @ Ht.T + 1e-4 * rng.random((n, m))
    close = problem.Problem(Xc)
    sol = _Solver(close, 2.0, "mu", "mu", (Penalty(), Penalty()), (None, None))
    sol.objective_next = True
    Ht2 = sol.update(1, Ht.copy(), W)
    assert close.divergence(W, Ht2, 2.0) == close.sides[0].divergence(W, Ht2, 2.0)


@pytest.mark.parametrize("beta", BETAS + [3.0])
@pytest.mark.parametrize("masked", [False, True])
def test_dense_divergence_by_blocks_equals_the_elementwise_sum(rng, monkeypatch, beta, masked):
    """The dense divergence, by blocks of rows over several stripes, equals the sum of its terms (zeros of X,
    unobserved cells and cells where W H = 0 included)."""
    import mmconcepts.nmf._problem as problem
    from mmconcepts.nmf._beta import elementwise_beta_divergence

    monkeypatch.setattr(problem, "_DIVERGENCE_BLOCK_BYTES", 8 * 30 * 7)  # 16-row blocks: 10 blocks, 8 stripes
    n, m, k = 157, 30, 3
    X = rng.random((n, m)) + 0.1
    if beta > 0:
        X *= rng.random((n, m)) < 0.7
    W, Ht = rng.random((n, k)), rng.random((m, k))
    M = (rng.random((n, m)) < 0.75) if masked else None
    if M is not None:
        X = X * M
    Y = W @ Ht.T
    terms = elementwise_beta_divergence(X, Y, beta)
    expected = float(np.sum(terms if M is None else np.where(M, terms, 0.0)))
    assert problem.Problem(X, M).divergence(W, Ht, beta) == pytest.approx(expected, rel=1e-12)
    if 0 < beta <= 1 and M is not None:  # a row of W of zeros: W H = 0 where X > 0 is infinite, unless unobserved
        W[5] = 0.0
        X[5] = 0.0
        X[5, 0] = 1.0
        expected_inf = np.inf if M[5, 0] else None
        got = problem.Problem(X, M).divergence(W, Ht, beta)
        if expected_inf is not None:
            assert got == np.inf
        else:
            assert np.isfinite(got)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), max_iter=st.integers(0, 25), loss_every=st.integers(1, 6),
       tol=st.sampled_from([0.0, 1e-4, 1e-2, 0.2]), update_H=st.booleans(), rescale=st.sampled_from([1.0, 1e-3]),
       empty_column=st.booleans(), kernel_sums=st.booleans())
def test_objective_read_in_the_w_update_equals_the_objective_evaluated_apart(seed, max_iter, loss_every, tol,
                                                                               update_H, rescale, empty_column,
                                                                               kernel_sums):
    """Sparse, unmasked I-divergence fits read each recorded objective from the next W update: the same
    iterates, stopping iteration and objectives (to rounding) as evaluating it apart, and each objective is
    scikit-learn's I-divergence of the factors it was recorded for. With the factors' column sums added by the
    kernel (``kernel_sums``, here from the first row on), the iterates are scikit-learn's."""
    from mmconcepts.nmf import _problem, _solver

    rng = np.random.default_rng(seed)
    X = sp.random(40, 30, density=0.2, format="csr", random_state=rng, dtype=np.float64)
    X.data = (rng.poisson(2.0, X.nnz) + 1.0) * rescale
    if empty_column:
        X = sp.csr_matrix(X.multiply(np.arange(30) != 7))  # stored zeros in column 7
    W0, H0 = rng.random((40, 4)) + 0.1, rng.random((4, 30)) + 0.1
    kw = dict(beta_loss=1.0, init="custom", W=W0, H=H0, update_H=update_H, max_iter=max_iter, tol=tol,
              loss_every=loss_every)
    threshold = _problem._KERNEL_SUM_ROWS
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        assert _solver._Solver.objective_in_update  # the path this test compares with the reference
        original = _solver._Solver.objective_in_update
        try:
            _problem._KERNEL_SUM_ROWS = 1 if kernel_sums else 10**9
            fused = beta_nmf(X, 4, **kw)
            _solver._Solver.objective_in_update = lambda self: False  # type: ignore[method-assign]
            apart = beta_nmf(X, 4, **kw)
        finally:
            _solver._Solver.objective_in_update = original  # type: ignore[method-assign]
            _problem._KERNEL_SUM_ROWS = threshold
    Xe = X.copy()
    Xe.eliminate_zeros()  # (stored zeros, which the fits are given, break scikit-learn's sparse products)
    if kernel_sums and tol == 0 and update_H and max_iter > 0:
        sk = SkNMF(4, init="custom", solver="mu", beta_loss=1.0, max_iter=max_iter, tol=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            W_sk = sk.fit_transform(Xe, W=W0.copy(), H=H0.copy())
        np.testing.assert_allclose(fused.W, W_sk, rtol=1e-10, atol=1e-13 * W_sk.max())
        np.testing.assert_allclose(fused.H, sk.components_, rtol=1e-10, atol=1e-13 * sk.components_.max())
    assert (fused.n_iter, fused.converged) == (apart.n_iter, apart.converged)
    np.testing.assert_array_equal(fused.loss_iterations, apart.loss_iterations)
    np.testing.assert_array_equal(fused.W, apart.W)
    np.testing.assert_array_equal(fused.H, apart.H)
    np.testing.assert_allclose(fused.loss_history, apart.loss_history, rtol=1e-12)
    np.testing.assert_allclose(fused.extra["divergence"], apart.extra["divergence"], rtol=1e-12)
    np.testing.assert_allclose(fused.extra["divergence"], _beta_divergence(Xe, fused.W, fused.H, 1.0), rtol=1e-10)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), max_iter=st.integers(0, 25), loss_every=st.integers(1, 6),
       tol=st.sampled_from([0.0, 1e-4, 1e-2, 0.2]), update_H=st.booleans(), beta=st.sampled_from([0.5, 1.5, 2.5, 3.0]),
       rule=st.sampled_from(["mm", "heuristic"]), masked=st.booleans(), zero_row=st.booleans())
def test_dense_fractional_objective_read_in_the_w_update_equals_the_objective_evaluated_apart(
        seed, max_iter, loss_every, tol, update_H, beta, rule, masked, zero_row):
    """Dense fits under a beta outside {0, 1, 2} read each recorded objective from the next W update, which forms
    the product and its power beta - 1: the same iterates and stopping iteration as evaluating it apart, the same
    objectives to rounding, each scikit-learn's beta-divergence of the factors it was recorded for. A row of zeros
    drives its products below the update's floor, where the divergence is taken from the product as it is."""
    from mmconcepts.nmf import _solver

    rng = np.random.default_rng(seed)
    X = rng.gamma(1.0, 1.0, (30, 25)) * (rng.random((30, 25)) < 0.7)
    if zero_row:
        X[3] = 0.0
    mask = (rng.random(X.shape) < 0.8).astype(float) if masked else None
    W0, H0 = rng.random((30, 4)) + 0.1, rng.random((4, 25)) + 0.1
    if zero_row:
        W0[3] = 1e-9  # its products start below the floor (float32's eps)
    kw = dict(beta_loss=beta, init="custom", W=W0, H=H0, update_H=update_H, max_iter=max_iter, tol=tol,
              loss_every=loss_every, update_rule=rule, mask=mask)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        original = _solver._Solver.objective_in_update
        assert original(_solver._Solver(_solver.Problem(X, mask), beta, "mu", rule, (_solver.Penalty(),) * 2,
                                        (None, None)))  # the path this test compares with the reference
        try:
            fused = beta_nmf(X, 4, **kw)
            _solver._Solver.objective_in_update = lambda self: False  # type: ignore[method-assign]
            apart = beta_nmf(X, 4, **kw)
        finally:
            _solver._Solver.objective_in_update = original  # type: ignore[method-assign]
    assert (fused.n_iter, fused.converged) == (apart.n_iter, apart.converged)
    np.testing.assert_array_equal(fused.loss_iterations, apart.loss_iterations)
    np.testing.assert_array_equal(fused.W, apart.W)
    np.testing.assert_array_equal(fused.H, apart.H)
    np.testing.assert_allclose(fused.loss_history, apart.loss_history, rtol=1e-11)
    if mask is None:
        np.testing.assert_allclose(fused.extra["divergence"], _beta_divergence(X, fused.W, fused.H, beta),
                                   rtol=1e-10)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), beta=st.sampled_from([0.5, 1.5, 2.5, 3.0]), masked=st.booleans(),
       dtype=st.sampled_from([np.float64, np.float32]))
def test_the_fractional_divergence_from_the_updates_power_is_the_divergence_without_its_terms_in_x(
        seed, beta, masked, dtype):
    """sum m (d_beta(x | y) - x^beta / (beta (beta - 1))) from y and y^(beta - 1): numpy's elementwise
    divergence (thesis eq. 2.3), zeros of X and unobserved cells included."""
    from mmconcepts.nmf import _kernels
    from mmconcepts.nmf._beta import elementwise_beta_divergence

    rng = np.random.default_rng(seed)
    X = (rng.gamma(1.0, 1.0, (9, 7)) * (rng.random((9, 7)) < 0.6)).astype(dtype)
    Y = (rng.gamma(1.0, 1.0, (9, 7)) + 1e-3).astype(dtype)
    M = (rng.random((9, 7)) < 0.7).astype(dtype) if masked else np.empty((0, 0), dtype=dtype)
    x, y = X.astype(np.float64), Y.astype(np.float64)
    terms = elementwise_beta_divergence(x, y, beta) - x**beta / (beta * (beta - 1.0))
    expected = float(np.sum(terms * (M if masked else 1.0)))
    got = _kernels.fractional_divergence_from_power(X, Y, Y ** dtype(beta - 1.0), M, beta)
    assert got == pytest.approx(expected, rel=1e-5 if dtype == np.float32 else 1e-12)


@pytest.mark.parametrize("n", [1, 63, 64, 65, 300, 1000])
def test_kl_update_sums_the_updated_factor_the_same_way_for_any_number_of_threads(rng, n):
    """The column sums the sparse I-divergence kernel adds while it updates L: those of numpy on the updated L (to
    rounding), each block of rows summed the same way whatever the number of row groups (threads), and the update
    itself unchanged by them."""
    from mmconcepts.nmf import _kernels

    X = sp.random(n, 300, density=0.05, random_state=5, format="csr")
    X.data = rng.poisson(2.0, X.nnz) + 1.0
    L, R = rng.random((n, 7)), rng.random((300, 7))
    den = R.sum(axis=0)
    plain = L.copy()
    _kernels.kl_update(X.indptr, X.indices, X.data, plain, R, den, np.empty_like(L))
    blocks = -(-n // _kernels.SUM_ROWS)
    first = None
    for groups in [1, 2, 3, 5, 16]:
        L2, sums = L.copy(), np.full((blocks, 7), np.nan)
        _kernels._mu_numerator(X.indptr, X.indices, X.data, np.empty(0), L2, R, 1.0, _kernels.EPSILON,
                               _kernels.flush_below(L.dtype), np.empty_like(L), den, groups, 40, _kernels._factors(X.indptr, X.data, np.empty(0), L,
                                                                                   groups),
                               _kernels._NO_RATIOS, sums)
        np.testing.assert_array_equal(L2, plain)
        for b in range(blocks):
            np.testing.assert_allclose(sums[b], plain[b * 64:(b + 1) * 64].sum(axis=0), rtol=1e-13)
        if first is None:
            first = sums
        np.testing.assert_array_equal(sums, first)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), beta=st.sampled_from([1.0, 1.5, 2.0]), sparse=st.booleans(),
       l2=st.sampled_from([0.0, 0.3]))
def test_newton_systems_read_back_for_fewer_free_coefficients_equal_those_formed_again(seed, beta, sparse, l2):
    """A row solved again with more coefficients held reads its Newton system from the first solve's (the rows and
    columns of the coefficients still free): the same steps as forming that system again from the curvature."""
    from mmconcepts.nmf._coefficients import _restricted_newton, _rows_model
    from mmconcepts.nmf._updates import Penalty

    rng = np.random.default_rng(seed)
    n, m, k = 9, 30, 7
    X = rng.gamma(1.0, 1.0, (n, m)) * (rng.random((n, m)) < 0.7)
    X = sp.csr_matrix(X) if sparse and beta == 1.0 else X
    Ht, W = rng.random((m, k)) + 0.05, rng.random((n, k)) + 0.01
    model = _rows_model(X, Ht, beta, Penalty(l2=l2), None)
    rows = np.arange(n)
    part, g, _den, curvature = next(iter(model.derivatives(rows, W)))
    safe = np.maximum(curvature.diag, 1e-12)
    ridge = 10.0 ** rng.uniform(-14, 0, n)
    act = rng.random((n, k)) < 0.3
    systems: list = [None] * n
    _restricted_newton(curvature, rows, g, act, safe, ridge, systems)
    more = act | (rng.random((n, k)) < 0.4)
    again = np.flatnonzero(rng.random(n) < 0.7)
    formed = _restricted_newton(curvature, again, g[again], more[again], safe[again], ridge[again])
    read = _restricted_newton(curvature, again, g[again], more[again], safe[again], ridge[again],
                              known=[systems[i] for i in again])
    np.testing.assert_allclose(read, formed, rtol=1e-12, atol=0)
