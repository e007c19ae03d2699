"""Known answers and library references for the task learners.

``MaxEntIRL`` fitted on demonstrations whose action counts are those of a soft-optimal
policy must give that policy back (the likelihood is maximal there); the soft values are
pinned to ``scipy.special.logsumexp`` of the Q-values.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

from mmconcepts.tasks import MDP, MaxEntIRL, soft_value_iteration


def _soft_world(seed: int = 3, S: int = 6, A: int = 3, d: int = 4):
    rng = np.random.default_rng(seed)
    P = rng.random((A, S, S)) ** 3
    P /= P.sum(axis=2, keepdims=True)
    mdp = MDP(P, discount=0.8)
    F = rng.standard_normal((S, A, d))
    theta = rng.standard_normal(d)
    return mdp, F, theta


def _soft_policy(mdp, rewards):
    V, Q = soft_value_iteration(mdp, rewards)
    return np.exp(Q - V[..., None])


def test_maxent_irl_recovers_the_soft_optimal_policy_that_made_the_demonstrations():
    """Known answer: demonstrations with the action counts of a soft-optimal policy.

    Each state s is visited n_s = 2000 times and action a is taken round(n_s pi*(a|s))
    times, pi* the soft-optimal (maximum causal entropy) policy of a linear reward
    F theta*. The log-likelihood of these counts is maximal at pi_theta = pi*, so
    without penalty the fit must give back pi*, the counts (n_s pi(a|s)), the feature
    expectations and theta* (the features are generic, so theta is identifiable). A fit
    that does not descend stays at theta = 0, the uniform policy.
    """
    mdp, F, theta = _soft_world()
    pi_true = _soft_policy(mdp, F @ theta)
    n_per_state = 2000
    counts = np.rint(n_per_state * pi_true).astype(int)
    demo = [np.array([[s, a]] * counts[s, a]) for s in range(mdp.n_states) for a in range(mdp.n_actions)
            if counts[s, a]]
    est = MaxEntIRL(features=F, l2=0.0, max_iter=500, tol=1e-12).fit(mdp, [demo])

    pi = _soft_policy(mdp, est.rewards_[0])
    n_s = counts.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(pi, pi_true, atol=2e-3)  # rounding the counts moves pi by <= 0.5 / 2000 per cell
    np.testing.assert_allclose(n_s * pi, counts, atol=2.0)  # the state-action counts
    np.testing.assert_allclose(np.einsum("sa,sad->d", n_s * pi, F), np.einsum("sa,sad->d", counts, F),
                               rtol=1e-3, atol=1.0)  # the feature expectations
    np.testing.assert_allclose(est.theta_[0], theta, atol=2e-2)
    assert est.n_iter_ > 1
    # the uniform policy of theta = 0 is far from it: the test can tell a fit that did not move
    assert np.abs(pi_true - 1.0 / mdp.n_actions).max() > 0.2


def test_maxent_irl_tabular_rewards_give_back_the_empirical_policy():
    """With one reward per (s, a), any policy is soft-optimal for some reward: the fit
    must reproduce the demonstrated action frequencies of each visited state."""
    mdp, _, _ = _soft_world(seed=5)
    rng = np.random.default_rng(1)
    target = rng.dirichlet(np.ones(mdp.n_actions) * 2.0, mdp.n_states)
    counts = np.rint(50 * target).astype(int) + 1
    demo = [np.array([[s, a]] * counts[s, a]) for s in range(mdp.n_states) for a in range(mdp.n_actions)]
    est = MaxEntIRL(l2=0.0, max_iter=2000, tol=1e-14).fit(mdp, [demo])
    pi = _soft_policy(mdp, est.rewards_[0])
    np.testing.assert_allclose(pi, counts / counts.sum(axis=1, keepdims=True), atol=1e-3)


@pytest.mark.parametrize("seed", [0, 1])
def test_soft_values_are_scipy_logsumexp_of_the_q_values(seed):
    rng = np.random.default_rng(seed)
    mdp, F, theta = _soft_world(seed)
    R = rng.standard_normal((2, mdp.n_states, mdp.n_actions)) * 30.0  # large rewards: the max shift matters
    V, Q = soft_value_iteration(mdp, R)
    np.testing.assert_allclose(V, logsumexp(Q, axis=2), rtol=1e-12, atol=1e-10)
    # and Q is the soft Bellman backup of V
    backup = R + mdp.discount * np.einsum("ast,kt->ksa", mdp.transitions, V)
    np.testing.assert_allclose(Q, backup, rtol=1e-9, atol=1e-8)
