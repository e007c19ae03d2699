"""Property tests (hypothesis) of the planning invariants.

On random MDPs and rewards: value iteration reaches the Bellman optimality fixed point and
policy iteration the same values; the greedy policy's exact value is the optimal value;
policies are distributions; soft values lie between the hard ones and
``V* + log(A) / (1 - gamma)`` (``max <= logsumexp <= max + log A`` at every backup).
"""

from __future__ import annotations

import pytest

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mmconcepts.tasks import (
    MDP,
    boltzmann_policy,
    greedy_policy,
    policy_evaluation,
    policy_iteration,
    q_values,
    soft_value_iteration,
    value_iteration,
)

pytestmark = pytest.mark.property

_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def mdps_and_rewards(draw):
    S, A = draw(st.integers(2, 8)), draw(st.integers(1, 4))
    gamma = draw(st.floats(0.0, 0.95))
    seed = draw(st.integers(0, 2**32 - 1))
    scale = draw(st.sampled_from([0.1, 1.0, 10.0]))
    rng = np.random.default_rng(seed)
    P = rng.random((A, S, S)) ** draw(st.sampled_from([1, 3, 8]))  # higher powers: nearly deterministic moves
    P /= P.sum(axis=2, keepdims=True)
    R = rng.standard_normal((draw(st.integers(1, 3)), S, A)) * scale
    if draw(st.booleans()):
        R[0] = R[0, 0, 0]  # all rewards tied in one task
    return MDP(P, discount=gamma), R


@_SETTINGS
@given(mdps_and_rewards())
def test_value_iteration_is_the_optimality_fixed_point_and_policy_iteration_agrees(case):
    mdp, R = case
    V, Q = value_iteration(mdp, R)
    scale = 1.0 + np.abs(R).max() / (1.0 - mdp.discount)
    np.testing.assert_allclose(Q, q_values(mdp, V, R), atol=1e-8 * scale)
    np.testing.assert_allclose(V, Q.max(axis=-1), atol=1e-8 * scale)
    V_pi, Q_pi = policy_iteration(mdp, R)
    np.testing.assert_allclose(V_pi, V, atol=1e-7 * scale)
    np.testing.assert_allclose(Q_pi, Q, atol=1e-7 * scale)
    # the greedy policy is optimal: its exact value is V*
    np.testing.assert_allclose(policy_evaluation(mdp, greedy_policy(Q), R), V, atol=1e-7 * scale)


@_SETTINGS
@given(mdps_and_rewards(), st.floats(0.01, 100.0))
def test_policies_are_distributions_and_greedy_keeps_only_the_best_actions(case, beta):
    mdp, R = case
    _, Q = value_iteration(mdp, R)
    for pi in (greedy_policy(Q), boltzmann_policy(Q, beta)):
        assert pi.shape == Q.shape
        assert (pi >= 0).all()
        np.testing.assert_allclose(pi.sum(axis=-1), 1.0, atol=1e-12)
    g = greedy_policy(Q)
    best = Q >= Q.max(axis=-1, keepdims=True) - 1e-8
    assert (g[~best] == 0).all()
    np.testing.assert_allclose(g[best], np.broadcast_to(1.0 / best.sum(axis=-1, keepdims=True), Q.shape)[best])


@_SETTINGS
@given(mdps_and_rewards())
def test_soft_values_lie_between_the_optimal_values_and_their_entropy_bound(case):
    mdp, R = case
    V, _ = value_iteration(mdp, R)
    Vs, Qs = soft_value_iteration(mdp, R)
    slack = 1e-8 * (1.0 + np.abs(R).max() / (1.0 - mdp.discount))
    assert (Vs >= V - slack).all()
    assert (Vs <= V + np.log(mdp.n_actions) / (1.0 - mdp.discount) + slack).all()
    # the soft Bellman equation: Q = R + gamma P V, V = log sum_a exp Q
    np.testing.assert_allclose(Qs, q_values(mdp, Vs, R), atol=slack)
    # the soft policy exp(Q - V) is a distribution
    np.testing.assert_allclose(np.exp(Qs - Vs[..., None]).sum(axis=-1), 1.0, atol=1e-9)
