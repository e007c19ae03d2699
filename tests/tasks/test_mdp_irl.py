"""MDPs, planning, gradient IRL and factorial IRL (mmconcepts.tasks)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.tasks import (
    MDP,
    FactorialIRL,
    GradIRL,
    MaxEntIRL,
    boltzmann_policy,
    empirical_policy,
    factorial_objective,
    gradirl_objective,
    greedy_policy,
    grid_world,
    maxent_objective,
    policy_evaluation,
    policy_iteration,
    q_gradient,
    q_values,
    sample_trajectories,
    soft_value_iteration,
    value_iteration,
)
from mmconcepts.tasks.factorial import component_features


@pytest.fixture
def world():
    return grid_world(5)


def _random_mdp(rng, S=7, A=3, gamma=0.8):
    P = rng.random((A, S, S)) ** 3
    return MDP(P / P.sum(axis=2, keepdims=True), discount=gamma)


def test_grid_world_rows_sum_to_one_and_are_stochastic():
    mdp = grid_world(10)
    assert mdp.transitions.shape == (4, 100, 100)
    np.testing.assert_allclose(mdp.transitions.sum(axis=2), 1.0)
    # interior cell 55 (row 5, col 5), action up (0) -> cell 45 with 0.7 + 0.3 / 4
    assert mdp.transitions[0, 55, 45] == pytest.approx(0.7 + 0.3 / 4)
    assert mdp.transitions[0, 55, 65] == pytest.approx(0.3 / 4)
    assert (mdp.transitions[0, 55] > 0).sum() == 4  # stochastic: 4 possible next cells
    # corner 0: up is not feasible -> uniform over the 2 feasible moves (down, right)
    assert mdp.transitions[0, 0, 10] == pytest.approx(0.5) and mdp.transitions[0, 0, 1] == pytest.approx(0.5)
    other = grid_world(10, random_includes_intended=False)
    assert other.transitions[0, 55, 45] == pytest.approx(0.7)
    np.testing.assert_allclose(other.transitions.sum(axis=2), 1.0)


def test_value_iteration_is_the_bellman_fixed_point(rng, world):
    r = rng.standard_normal((world.n_states, world.n_actions))
    V, Q = value_iteration(world, r)
    np.testing.assert_allclose(V, q_values(world, V, r).max(axis=1), atol=1e-9)
    np.testing.assert_allclose(Q, q_values(world, V, r), atol=1e-9)
    # the greedy policy is optimal: its exact value equals V*
    np.testing.assert_allclose(policy_evaluation(world, greedy_policy(Q), r), V, atol=1e-8)


def test_policy_iteration_equals_value_iteration(rng, world):
    R = rng.standard_normal((7, world.n_states, world.n_actions))
    V_vi, Q_vi = value_iteration(world, R)
    V_pi, Q_pi = policy_iteration(world, R)
    assert V_pi.shape == V_vi.shape and Q_pi.shape == Q_vi.shape
    np.testing.assert_allclose(V_pi, V_vi, atol=1e-8)
    np.testing.assert_allclose(Q_pi, Q_vi, atol=1e-8)
    # exact: V is the optimality equation's fixed point to round-off
    np.testing.assert_allclose(V_pi, q_values(world, V_pi, R).max(axis=-1), atol=1e-12)
    # warm start from values of other rewards, single task and batch shapes
    V_w, _ = policy_iteration(world, R[0], init=V_vi[1])
    np.testing.assert_allclose(V_w, V_vi[0], atol=1e-8)
    # ties (all-equal rewards) do not make the loop cycle
    V_t, _ = policy_iteration(world, np.ones((world.n_states, world.n_actions)))
    np.testing.assert_allclose(V_t, 1.0 / (1.0 - world.discount))


def test_policy_evaluation_solves_bellman_equation(rng, world):
    r = rng.standard_normal((world.n_states, world.n_actions))
    pi = boltzmann_policy(rng.standard_normal(r.shape), 2.0)
    V = policy_evaluation(world, pi, r)
    Q = q_values(world, V, r)
    np.testing.assert_allclose(V, (pi * Q).sum(axis=1), atol=1e-10)  # eq. (2.25)


def test_batched_equals_per_task(rng, world):
    R = rng.standard_normal((6, world.n_states, world.n_actions))
    V, Q = value_iteration(world, R)
    Vs, Qs = soft_value_iteration(world, R)
    pis = boltzmann_policy(Q, 1.5)
    Vp = policy_evaluation(world, pis, R)
    for i in range(6):
        v, q = value_iteration(world, R[i])
        np.testing.assert_allclose(V[i], v, atol=1e-12)
        np.testing.assert_allclose(Q[i], q, atol=1e-12)
        np.testing.assert_allclose(Vs[i], soft_value_iteration(world, R[i])[0], atol=1e-12)
        np.testing.assert_allclose(Vp[i], policy_evaluation(world, pis[i], R[i]), atol=1e-10)


def test_sampled_trajectories_follow_the_world(rng, world):
    V, Q = value_iteration(world, rng.standard_normal((25, 4)))
    trajs = sample_trajectories(world, greedy_policy(Q), 50, 8, random_state=rng)
    pi = greedy_policy(Q)
    for xi in trajs:
        assert xi.shape == (8, 2)
        assert (pi[xi[:, 0], xi[:, 1]] > 0).all()  # only greedy actions
        assert (world.transitions[xi[:-1, 1], xi[:-1, 0], xi[1:, 0]] > 0).all()  # feasible moves
    mu, piE = empirical_policy(world, trajs)
    assert mu.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(piE.sum(axis=1), 1.0)


def test_q_gradient_matches_finite_differences(rng):
    mdp = _random_mdp(rng)
    S, A, d = mdp.n_states, mdp.n_actions, 4
    F = rng.standard_normal((S, A, d))
    theta = rng.standard_normal(d)
    _, Q = value_iteration(mdp, F @ theta)
    phi = q_gradient(mdp, F, greedy_policy(Q))
    phi_it = q_gradient(mdp, F, greedy_policy(Q), method="iterate")
    np.testing.assert_allclose(phi, phi_it, atol=1e-9)
    eps = 1e-6
    for j in range(d):
        e = np.zeros(d)
        e[j] = eps
        fd = (value_iteration(mdp, F @ (theta + e))[1] - value_iteration(mdp, F @ (theta - e))[1]) / (2 * eps)
        np.testing.assert_allclose(phi[:, :, j], fd, atol=1e-5)  # eq. (2.34)


@pytest.mark.parametrize("tabular", [True, False])
def test_gradirl_gradient_matches_finite_differences(rng, tabular):
    mdp = _random_mdp(rng)
    S, A = mdp.n_states, mdp.n_actions
    F = None if tabular else rng.standard_normal((S, A, 5))
    d = S * A if tabular else 5
    theta = rng.standard_normal((2, d))
    mu = rng.dirichlet(np.ones(S), 2)
    piE = rng.dirichlet(np.ones(A), (2, S))
    loss, grad = gradirl_objective(mdp, theta, mu, piE, features=F, beta=1.7)
    _, grad_it = gradirl_objective(mdp, theta, mu, piE, features=F, beta=1.7, method="iterate")
    np.testing.assert_allclose(grad, grad_it, atol=1e-9)
    eps = 1e-6
    for j in rng.choice(d, size=min(d, 6), replace=False):
        e = np.zeros_like(theta)
        e[:, j] = eps
        fd = (gradirl_objective(mdp, theta + e, mu, piE, features=F, beta=1.7)[0]
              - gradirl_objective(mdp, theta - e, mu, piE, features=F, beta=1.7)[0]) / (2 * eps)
        np.testing.assert_allclose(grad[:, j], fd, rtol=1e-4, atol=1e-8)  # eq. (2.33)-(2.34)


def test_maxent_gradient_matches_finite_differences(rng):
    mdp = _random_mdp(rng)
    theta = rng.standard_normal((1, mdp.n_states * mdp.n_actions))
    counts = rng.integers(0, 3, (1, mdp.n_states, mdp.n_actions)).astype(float)
    loss, grad = maxent_objective(mdp, theta, counts, l2=0.1)
    eps = 1e-6
    for j in range(0, theta.shape[1], 3):
        e = np.zeros_like(theta)
        e[0, j] = eps
        fd = (maxent_objective(mdp, theta + e, counts, l2=0.1)[0] - maxent_objective(mdp, theta - e, counts, l2=0.1)[0]) / (2 * eps)
        assert grad[0, j] == pytest.approx(fd[0], rel=1e-4, abs=1e-8)


def test_factorial_gradients_match_finite_differences(rng):
    mdp = _random_mdp(rng)
    S, A = mdp.n_states, mdp.n_actions
    n, k, d = 3, 2, S * A
    D = rng.standard_normal((k, d))
    Hc = rng.standard_normal((n, k))
    mu = rng.dirichlet(np.ones(S), n)
    piE = rng.dirichlet(np.ones(A), (n, S))
    loss, gD, gH = factorial_objective(mdp, D, Hc, mu, piE)
    eps = 1e-6
    for (i, j) in [(0, 0), (1, 5), (0, d - 1)]:
        E = np.zeros_like(D)
        E[i, j] = eps
        fd = (factorial_objective(mdp, D + E, Hc, mu, piE)[0] - factorial_objective(mdp, D - E, Hc, mu, piE)[0]) / (2 * eps)
        assert gD[i, j] == pytest.approx(fd, rel=1e-4, abs=1e-8)  # eq. (4.9)
    for (i, j) in [(0, 0), (2, 1)]:
        E = np.zeros_like(Hc)
        E[i, j] = eps
        fd = (factorial_objective(mdp, D, Hc + E, mu, piE)[0] - factorial_objective(mdp, D, Hc - E, mu, piE)[0]) / (2 * eps)
        assert gH[i, j] == pytest.approx(fd, rel=1e-4, abs=1e-8)  # eq. (4.10)


def _tasks(world, rng, n=8, m=5, k=3):
    D = rng.standard_normal((k, world.n_states * world.n_actions))
    Hc = rng.uniform(0, 1, (n, k))
    R = (Hc @ D).reshape(n, world.n_states, world.n_actions)
    _, Q = value_iteration(world, R)
    demos = [sample_trajectories(world, greedy_policy(Q[i]), m, 8, random_state=rng) for i in range(n)]
    return D, R, demos


def test_gradirl_lowers_the_loss_and_imitates(rng, world):
    D, R, demos = _tasks(world, rng)
    est = GradIRL(max_iter=40).fit(world, demos)
    assert est.theta_.shape == (8, world.n_states * world.n_actions)
    mus, pis = zip(*(empirical_policy(world, t) for t in demos))
    start = gradirl_objective(world, np.zeros_like(est.theta_), np.array(mus), np.array(pis))[0]
    assert (est.loss_ < 0.5 * start).all()
    me = MaxEntIRL(max_iter=30).fit(world, demos)
    assert me.rewards_.shape == R.shape


def test_factorial_irl_does_not_increase_loss(rng, world):
    D, R, demos = _tasks(world, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fa = FactorialIRL(3, max_iter=5, inner_steps=3, flat_max_iter=20).fit(world, demos)
    h = np.array(fa.loss_history_)
    assert (np.diff(h) <= 1e-12).all()
    assert len(h) == fa.n_iter_ + 1 and 1 <= fa.n_iter_ <= 5  # the initial loss, then one per alternation
    assert fa.components_.shape == (3, 100) and fa.coefficients_.shape == (8, 3)
    np.testing.assert_allclose(fa.theta_, fa.coefficients_ @ fa.components_)
    assert fa.reward_features(world).shape == (25, 4, 3)
    assert fa.transform(world, demos[:2], max_iter=5).shape == (2, 3)
    np.testing.assert_allclose(component_features(world, D)[..., 0], D[0].reshape(25, 4))


def test_bad_transitions_are_refused():
    P = np.full((2, 3, 3), 0.3)
    with pytest.raises(ParameterError, match="sum to one"):
        MDP(P)
    with pytest.raises(ParameterError, match="shape"):
        MDP(np.full((2, 3, 4), 0.25))
    with pytest.raises(ParameterError, match="nonnegative"):
        MDP(np.array([[[1.5, -0.5], [0.0, 1.0]]]))
    with pytest.raises(ParameterError, match="discount"):
        MDP(np.full((1, 2, 2), 0.5), discount=1.0)


@pytest.mark.parametrize("transitions", [[[["a", 1.0], [0.0, 1.0]]], [[[1.0, 0.0], [0.0]]],
                                         [[[1 + 1j, 0.0], [0.0, 1.0]]], np.eye(2, dtype=complex)[None]])
def test_transitions_that_are_not_numbers_are_refused(transitions):
    with pytest.raises(ParameterError, match="transitions must be an array of probabilities"):
        MDP(transitions)


def test_rewards_that_are_not_numbers_are_refused():
    with pytest.raises(ParameterError, match="rewards must be an array of numbers"):
        MDP(np.ones((1, 1, 1)), rewards=[["x"]])


@pytest.mark.parametrize("solve", [value_iteration, policy_iteration, soft_value_iteration])
def test_init_of_the_wrong_length_or_not_finite_is_refused(world, solve):
    r = np.zeros((25, 4))
    with pytest.raises(ParameterError, match=r"init must have shape \(25,\) or \(n_tasks, 25\).*; got \(24,\)"):
        solve(world, r, init=np.zeros(24))
    with pytest.raises(ParameterError, match=r"init must have shape .*; got \(3, 25\)"):
        solve(world, np.zeros((2, 25, 4)), init=np.zeros((3, 25)))
    for bad in (np.nan, np.inf, 1e308):
        init = np.zeros(25)
        init[3] = bad
        with pytest.raises(DataError, match="init"):
            solve(world, r, init=init)
    with pytest.raises(ParameterError, match="init must be an array of numbers"):
        solve(world, r, init=["a"] * 25)
    V, _ = solve(world, np.zeros((2, 25, 4)), init=np.ones(25))  # one start for every task broadcasts
    assert V.shape == (2, 25) and np.isfinite(V).all()


def test_bad_rewards_and_trajectories_are_refused(world):
    with pytest.raises(ParameterError, match="rewards must have shape"):
        value_iteration(world, np.zeros((4, 25)))
    with pytest.raises(DataError, match="unknown state 25"):
        empirical_policy(world, [np.array([[0, 1], [25, 0]])])
    with pytest.raises(DataError, match="unknown action 4"):
        empirical_policy(world, [np.array([[0, 4]])])
    with pytest.raises(DataError, match="shape"):
        empirical_policy(world, [np.array([0, 1, 2])])
    with pytest.raises(DataError, match="list of trajectories"):
        GradIRL().fit(world, [np.array([[0, 1]])])
    with pytest.raises(ParameterError, match="features"):
        GradIRL(np.zeros((3, 3))).fit(world, [[np.array([[0, 1]])]])


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), shape=st.sampled_from([(1, 4, 7), (3, 5, 2), (2, 1, 6), (4, 3, 3)]),
       axis=st.sampled_from([0, 1, 2]), scale=st.sampled_from([1e-3, 1.0, 300.0]),
       special=st.sampled_from(["none", "minus_inf", "all_minus_inf", "plus_inf"]))
def test_the_soft_values_logsumexp_is_scipys(seed, shape, axis, scale, special):
    """The log-sum-exp of the soft values: scipy's ``special.logsumexp`` to rounding, infinite entries included."""
    from scipy.special import logsumexp as scipy_logsumexp

    from mmconcepts.tasks.mdp import _logsumexp

    rng = np.random.default_rng(seed)
    Q = rng.normal(size=shape) * scale
    if special == "minus_inf":
        Q[rng.random(shape) < 0.3] = -np.inf
    elif special == "all_minus_inf":  # one whole line along the axis
        line = [int(rng.integers(n)) for n in shape]
        line[axis] = slice(None)
        Q[tuple(line)] = -np.inf
    elif special == "plus_inf":
        Q.flat[rng.integers(Q.size)] = np.inf
    expected = scipy_logsumexp(Q, axis=axis)
    got = _logsumexp(Q, axis)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(np.isposinf(got), np.isposinf(expected))
    np.testing.assert_array_equal(np.isneginf(got), np.isneginf(expected))
    finite = np.isfinite(expected)
    np.testing.assert_allclose(got[finite], expected[finite], rtol=1e-12, atol=1e-12 * scale)
