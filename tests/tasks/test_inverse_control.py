"""Factorial inverse feedback control (mmconcepts.tasks.inverse_control)."""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.tasks import (
    FactorialInverseControl,
    RBFFeatures,
    brillinger_regression,
    control_trajectories,
    relative_l2_error,
)


def test_rbf_jacobian_matches_finite_differences(rng):
    f = RBFFeatures(5)
    q = rng.random((4, 2))
    J = f.jacobian(q)
    eps = 1e-6
    for k in range(2):
        e = np.zeros(2)
        e[k] = eps
        np.testing.assert_allclose(J[..., k], (f.value(q + e) - f.value(q - e)) / (2 * eps), atol=1e-6)


def test_trajectories_descend_the_cost(rng):
    f = RBFFeatures(5)
    beta = rng.standard_normal((3, 25))
    traj = control_trajectories(f, beta, rng.random((3, 2)), n_steps=50)
    costs = np.array([f.cost(beta[i], traj[i]) for i in range(3)])
    assert (np.diff(costs, axis=1) <= 1e-9).all()  # small gradient steps never increase the cost


def test_brillinger_recovers_beta_exactly(rng):
    f = RBFFeatures(3, sigma=0.5)
    beta = rng.standard_normal(9)
    trajs = control_trajectories(f, np.tile(beta, (6, 1)), rng.random((6, 2)), n_steps=40)
    np.testing.assert_allclose(brillinger_regression(f, list(trajs)), beta, atol=1e-8)
    b_ridge = brillinger_regression(f, list(trajs), regression="ridge", alpha=1e-10)
    np.testing.assert_allclose(b_ridge, beta, atol=1e-5)


def test_ode_trajectories_are_the_limit_of_small_euler_steps(rng):
    f = RBFFeatures(5)
    beta = rng.standard_normal((4, 25))
    start = rng.random((4, 2))
    ode = control_trajectories(f, beta, start, n_steps=20, dt=0.01, method="ode")
    fine = control_trajectories(f, beta, start, n_steps=2000, dt=1e-4)[:, ::100]
    coarse = control_trajectories(f, beta, start, n_steps=20, dt=0.01)
    err_fine, err_coarse = np.abs(ode - fine).max(), np.abs(ode - coarse).max()
    assert err_fine < 0.03 * err_coarse  # Euler is first order: 100x finer steps, ~100x closer to the flow
    np.testing.assert_allclose(ode[:, 0], start)
    costs = np.array([f.cost(beta[i], ode[i]) for i in range(4)])
    assert (np.diff(costs, axis=1) <= 1e-9).all()  # gradient flow never increases the cost


def test_brillinger_on_continuous_data_is_an_approximation(rng):
    f = RBFFeatures(3, sigma=0.5)
    beta = rng.standard_normal(9)
    trajs = control_trajectories(f, np.tile(beta, (6, 1)), rng.random((6, 2)), n_steps=40, method="ode")
    b = brillinger_regression(f, list(trajs))
    err = np.linalg.norm(b - beta) / np.linalg.norm(beta)
    assert 1e-6 < err < 0.2  # not exact any more (eq. 4.2 is a finite-difference approximation), but close


def test_supervised_dictionary_is_recovered_and_loss_decreases(rng):
    f = RBFFeatures(5)
    D = rng.standard_normal((4, 25))
    A = rng.uniform(0, 1, (60, 4))
    demos = control_trajectories(f, A @ D, rng.random((60, 2)), n_steps=60)
    sup = FactorialInverseControl(4, features=f, max_iter=300, random_state=0).fit(list(demos), A)
    assert (np.diff(sup.loss_history_) <= 1e-9 * sup.loss_history_[0]).all()
    im_sup = control_trajectories(f, A @ sup.components_, demos[:, 0], n_steps=60)
    assert np.mean(relative_l2_error(demos, im_sup)) < 0.05
    uns = FactorialInverseControl(4, features=f, max_iter=50, random_state=0).fit(list(demos))
    im = control_trajectories(f, uns.coefficients_ @ uns.components_, demos[:, 0], n_steps=60)
    rand = FactorialInverseControl(4, features=f, max_iter=1, d_steps=1, random_state=0).fit(list(demos))
    im0 = control_trajectories(f, rand.coefficients_ @ rand.components_, demos[:, 0], n_steps=60)
    assert np.mean(relative_l2_error(demos, im)) < 0.8 * np.mean(relative_l2_error(demos, im0))
    assert uns.transform(list(demos[:3])).shape == (3, 4)


def test_cg_reaches_the_least_squares_dictionary_where_steepest_descent_crawls(rng):
    f = RBFFeatures(5)
    D = rng.standard_normal((4, 25))
    A = rng.uniform(0.5, 1.5, (40, 4))
    demos = control_trajectories(f, A @ D, rng.random((40, 2)), n_steps=60)  # noise-free: D is the minimiser
    cg = FactorialInverseControl(4, features=f, max_iter=2000, d_solver="cg", random_state=1).fit(list(demos), A)
    np.testing.assert_allclose(cg.components_, D, atol=1e-4 * np.abs(D).max())
    assert np.linalg.norm(cg.init_components_ - D) > 0.5 * np.linalg.norm(D)  # it did not start there
    assert (np.diff(cg.loss_history_) <= 1e-9 * cg.loss_history_[0]).all()
    sd = FactorialInverseControl(4, features=f, max_iter=cg.n_iter_, d_solver="steepest", random_state=1)
    sd.fit(list(demos), A)
    np.testing.assert_array_equal(sd.init_components_, cg.init_components_)
    assert np.linalg.norm(sd.components_ - D) > 100 * np.linalg.norm(cg.components_ - D)
    uns = FactorialInverseControl(4, features=f, max_iter=5, d_solver="cg", random_state=1).fit(list(demos))
    assert uns.loss_history_[-1] < uns.loss_history_[0]


def test_bad_input():
    f = RBFFeatures(5)
    with pytest.raises(DataError, match="shape"):
        brillinger_regression(f, np.zeros((1, 2)))
    with pytest.raises(DataError, match="NaN"):
        brillinger_regression(f, np.array([[0.1, 0.2], [np.nan, 0.3]]))
    with pytest.raises(ParameterError, match="regression"):
        brillinger_regression(f, np.random.default_rng(0).random((5, 2)), regression="lasso")
    with pytest.raises(ParameterError, match="method"):
        control_trajectories(f, np.zeros(25), [0.5, 0.5], method="rk4")
    with pytest.raises(ParameterError, match="settle_tol"):
        control_trajectories(f, np.zeros(25), [0.5, 0.5], method="ode", settle_tol=1e-3)
    with pytest.raises(ParameterError, match="d_solver"):
        FactorialInverseControl(2, features=f, d_solver="newton").fit([np.zeros((3, 2)) + 0.5], np.ones((1, 2)))
    with pytest.raises(ParameterError, match="coefficients"):
        FactorialInverseControl(2, features=f).fit([np.zeros((3, 2)) + 0.5], np.ones((2, 2)))
