"""Tests written from the mutation run on ``mmconcepts.tasks``.

Each test kills mutants that the rest of the suite let survive (see /work/notes/mutation13.md):
the adjoint gradient against the same derivative written by hand as a linear solve (both
methods, the fixed point without a convergence warning), the stopping rule of factorial inverse
control as documented, trajectories given as floats, and the argument checks and messages of
the IRL learners.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.tasks import (
    MDP,
    FactorialInverseControl,
    FactorialIRL,
    GradIRL,
    RBFFeatures,
    adjoint_gradient,
    control_trajectories,
    empirical_policy,
    gradirl_objective,
    grid_world,
    value_iteration,
)
from mmconcepts.tasks.irl import check_task_demonstrations
from mmconcepts.tasks.mdp import check_trajectories

pytestmark = pytest.mark.mutation


def _random_mdp(seed=0, S=5, A=3, gamma=0.8):
    rng = np.random.default_rng(seed)
    P = rng.random((A, S, S)) ** 2
    P /= P.sum(axis=2, keepdims=True)
    return MDP(P, discount=gamma), rng


@pytest.mark.parametrize("method", ["solve", "iterate"])
def test_adjoint_gradient_is_the_derivative_of_a_linear_functional_of_q_pi(method):
    """For a fixed policy pi, Q^pi = r + gamma P pi Q^pi is linear in r: Q^pi = M^{-1} r with
    M = I - gamma P Pi on (s, a) pairs. So J(r) = <g, Q^pi(r)> has dJ/dr = M^{-T} g, written
    here by hand with numpy (independent of the package). The fixed-point method must reach it
    without a ConvergenceWarning."""
    mdp, rng = _random_mdp()
    S, A, T, gamma = mdp.n_states, mdp.n_actions, 2, mdp.discount
    g = rng.standard_normal((T, S, A))
    pi = rng.random((T, S, A))
    pi /= pi.sum(axis=2, keepdims=True)
    expected = np.empty_like(g)
    for t in range(T):
        # rows (s, a), columns (s', a'): P(s'|s, a) pi(a'|s')
        PPi = np.einsum("asx,xb->saxb", mdp.transitions, pi[t]).reshape(S * A, S * A)
        M = np.eye(S * A) - gamma * PPi
        expected[t] = np.linalg.solve(M.T, g[t].reshape(-1)).reshape(S, A)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = adjoint_gradient(mdp, g, pi, method=method)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-10)


def test_gradirl_objective_checks_init():
    mdp, rng = _random_mdp()
    S, A = mdp.n_states, mdp.n_actions
    mu = np.full((1, S), 1.0 / S)
    pi_E = np.full((1, S, A), 1.0 / A)
    theta = rng.standard_normal((1, S * A))
    gradirl_objective(mdp, theta, mu, pi_E, init=np.zeros((1, S)))  # an array is fine
    with pytest.raises(ParameterError, match="init"):
        gradirl_objective(mdp, theta, mu, pi_E, init=5.0)


def test_trajectories_given_as_integral_floats_are_accepted_and_others_refused():
    mdp = grid_world(3)
    ints = np.array([[0, 1], [3, 2], [4, 0]])
    out = check_trajectories(mdp, [ints.astype(float)])
    assert out[0].dtype == np.int64
    np.testing.assert_array_equal(out[0], ints)
    mu_f, pi_f = empirical_policy(mdp, [ints.astype(float)])
    mu_i, pi_i = empirical_policy(mdp, [ints])
    np.testing.assert_array_equal(mu_f, mu_i)
    np.testing.assert_array_equal(pi_f, pi_i)
    for bad in ([[0.5, 1.0]], [[np.nan, 1.0]], [[0.0, np.inf]]):
        with pytest.raises(DataError, match="integer state and action indices"):
            check_trajectories(mdp, [np.array(bad)])


def test_task_demonstrations_name_the_task_and_trajectory_at_fault():
    mdp = grid_world(3)
    good = np.array([[0, 1], [1, 1]])
    with pytest.raises(DataError, match=r"task 1 trajectory 0, step 1: unknown state 99"):
        check_task_demonstrations(mdp, [[good], [np.array([[0, 1], [99, 0]])]])


def _irl_tasks():
    """Two tasks of the 3 x 3 grid world, a few hand-written (state, action) steps each."""
    return grid_world(3), [[np.array([[0, 1], [1, 2], [4, 3]])], [np.array([[8, 0], [5, 0]]), np.array([[2, 2]])]]


def test_factorial_irl_refuses_more_components_than_tasks_with_the_bound_in_the_message():
    world, demos = _irl_tasks()
    with pytest.raises(ParameterError, match=r"n_components=3 must be at most min\(n_tasks, d\) = 2"):
        FactorialIRL(3).fit(world, demos)


def test_factorial_irl_checks_the_shape_of_a_given_flat_theta():
    world, demos = _irl_tasks()
    d = world.n_states * world.n_actions
    with pytest.raises(ParameterError, match=rf"flat_theta must have shape \(2, {d}\); got \(2, 3\)"):
        FactorialIRL(1, max_iter=1).fit(world, demos, flat_theta=np.zeros((2, 3)))


def _control(seed=1, n=8):
    rng = np.random.default_rng(seed)
    f = RBFFeatures(3, sigma=0.5)
    D = rng.standard_normal((2, f.n_features))
    A = rng.uniform(0.2, 1.0, (n, 2))
    trajs = control_trajectories(f, A @ D, rng.random((n, 2)), n_steps=12)
    return f, list(trajs), A


def _check_stopping_rule(history, tol, max_iter):
    """The documented rule: stop after the first iteration whose relative decrease is <= tol."""
    h = np.asarray(history)
    rel = (h[:-1] - h[1:]) / h[:-1]
    assert len(h) < max_iter  # it did stop before max_iter
    assert rel[-1] <= tol
    assert (rel[:-1] > tol).all()


@pytest.mark.parametrize("supervised", [False, True])
def test_factorial_inverse_control_stops_by_its_relative_decrease_rule(supervised):
    f, trajs, A = _control()
    tol, max_iter = 1e-2, 300
    est = FactorialInverseControl(2, features=f, max_iter=max_iter, tol=tol, d_solver="steepest", random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(trajs, A if supervised else None)
    _check_stopping_rule(est.loss_history_, tol, max_iter)
    assert est.n_iter_ == len(est.loss_history_)


def test_rewards_of_the_wrong_shape_are_refused_with_both_accepted_shapes():
    mdp = grid_world(3)
    with pytest.raises(ParameterError, match=r"^rewards must have shape \(n_states, n_actions\) or "
                                             r"\(n_tasks, n_states, n_actions\) = \(9, 4\); got \(9,\)"):
        value_iteration(mdp, np.zeros(9))


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_factorial_irl_transform_is_gradirl_on_the_learnt_features_with_its_beta():
    """As documented: the coefficients of new tasks are GradIRL (same beta) on reward_features."""
    world, demos = _irl_tasks()
    fa = FactorialIRL(2, beta=3.0, max_iter=2, inner_steps=2, flat_max_iter=3).fit(world, demos)
    got = fa.transform(world, demos[:1], max_iter=5)
    ref = GradIRL(fa.reward_features(world), beta=3.0, max_iter=5).fit(world, demos[:1]).theta_
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    beta1 = GradIRL(fa.reward_features(world), beta=1.0, max_iter=5).fit(world, demos[:1]).theta_
    assert not np.allclose(got, beta1, rtol=1e-6)
