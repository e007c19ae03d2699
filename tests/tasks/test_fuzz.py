"""Fuzz tests of mmconcepts.tasks: a typed error or a correct result.

Every example ends in :func:`_fuzz.assert_typed_or_good`. "Correct" is checked against
references that do not share code with the package: the optimal values of a small MDP by
enumerating every deterministic policy and solving its Bellman equation with numpy (and
pymdptoolbox's policy iteration when it is installed), policies that are probability
distributions over valid actions, trajectories that only take steps of positive
probability.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from _fuzz import assert_typed_or_good, fuzz_settings
from mmconcepts.errors import ConvergenceWarning
from mmconcepts.tasks import (
    MDP,
    FactorialInverseControl,
    FactorialIRL,
    GradIRL,
    MaxEntIRL,
    RBFFeatures,
    boltzmann_policy,
    brillinger_regression,
    control_trajectories,
    greedy_policy,
    grid_world,
    policy_evaluation,
    policy_iteration,
    q_values,
    sample_trajectories,
    soft_value_iteration,
    value_iteration,
)

pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")]

EDGE_FLOATS = st.sampled_from([0.0, -0.0, 1.0, -1.0, 1e-300, 1e300, -1e300, np.inf, -np.inf, np.nan, 0.5, 1e-8])
FLOATS = st.one_of(st.floats(-1e3, 1e3, allow_nan=False), EDGE_FLOATS)
SETTINGS = dict(suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@st.composite
def mdps(draw, max_states=4, max_actions=3):
    """A valid random MDP (rows normalised), some with absorbing or deterministic rows."""
    S = draw(st.integers(1, max_states))
    A = draw(st.integers(1, max_actions))
    P = draw(arrays(float, (A, S, S), elements=st.floats(0, 1, allow_nan=False)))
    if draw(st.booleans()):  # make some rows deterministic
        P = (P == P.max(axis=2, keepdims=True)).astype(float)
    P = P + (P.sum(axis=2, keepdims=True) == 0)  # an all-zero row becomes uniform
    P = P / P.sum(axis=2, keepdims=True)
    gamma = draw(st.sampled_from([0.0, 0.3, 0.9, 0.99]))
    return MDP(P, discount=gamma)


def reward_arrays(mdp, *, edges=True):
    shape = st.sampled_from([(mdp.n_states, mdp.n_actions), (2, mdp.n_states, mdp.n_actions)])
    elements = FLOATS if edges else st.floats(-10, 10, allow_nan=False)
    return shape.flatmap(lambda s: arrays(float, s, elements=elements))


def brute_force_optimum(mdp, r):
    """V* of one task by enumerating every deterministic policy (numpy only)."""
    S, A = mdp.n_states, mdp.n_actions
    best = np.full(S, -np.inf)
    for acts in itertools.product(range(A), repeat=S):
        P = mdp.transitions[list(acts), np.arange(S), :]
        rp = r[np.arange(S), list(acts)]
        V = np.linalg.solve(np.eye(S) - mdp.discount * P, rp)
        best = np.maximum(best, V)
    return best


def check_values(mdp, r, res, *, atol):
    V, Q = res
    batch = r.shape[:-2]
    if V.shape != batch + (mdp.n_states,) or Q.shape != batch + (mdp.n_states, mdp.n_actions):
        return False
    if not np.allclose(V, Q.max(axis=-1)):
        return False
    for t, rt in enumerate(r.reshape(-1, mdp.n_states, mdp.n_actions)):
        ref = brute_force_optimum(mdp, rt)
        scale = 1.0 + np.abs(ref).max()
        if not np.allclose(V.reshape(-1, mdp.n_states)[t], ref, rtol=0, atol=atol * scale):
            return False
    return True


def is_policy(pi, shape):
    return pi.shape == shape and (pi >= 0).all() and np.allclose(pi.sum(axis=-1), 1.0)


# ----------------------------------------------------------------------------- MDP construction


@fuzz_settings(300, **SETTINGS)
@given(
    shape=st.sampled_from([(1, 1, 1), (2, 3, 3), (1, 2, 3), (0, 2, 2), (2, 0, 0), (3, 3), (2, 2, 2, 2)]),
    fill=EDGE_FLOATS,
    normalise=st.booleans(),
    discount=st.one_of(EDGE_FLOATS, st.floats(-2, 2, allow_nan=False)),
)
def test_fuzz_mdp(shape, fill, normalise, discount):
    P = np.full(shape, fill) if fill == fill else np.full(shape, np.nan)
    if normalise and len(shape) == 3 and shape[-1] and np.isfinite(fill) and fill > 0:
        P = P / P.sum(axis=-1, keepdims=True)

    def check(m):
        return (m.transitions.shape == shape and 0 <= m.discount < 1
                and np.allclose(m.transitions.sum(axis=2), 1.0) and (m.transitions >= 0).all())

    assert_typed_or_good("mmconcepts.tasks.MDP", lambda: MDP(P, discount=discount), check=check)


@fuzz_settings(100, **SETTINGS)
@given(size=st.sampled_from([-1, 0, 1, 2, 3, 2.5, np.nan]), p=st.one_of(EDGE_FLOATS, st.floats(0, 1)),
       discount=st.sampled_from([0.0, 0.9, 1.0, np.nan]))
def test_fuzz_grid_world(size, p, discount):
    def check(m):
        return m.n_states == int(size) ** 2 and m.n_actions == 4 and np.allclose(m.transitions.sum(axis=2), 1.0)

    assert_typed_or_good("mmconcepts.tasks.grid_world", lambda: grid_world(size, success_prob=p, discount=discount),
                         check=check)


# ----------------------------------------------------------------------------- planning


@fuzz_settings(200, **SETTINGS)
@given(data=st.data(), max_iter=st.sampled_from([-1, 0, 1, 2] + [10_000] * 6),
       tol=st.sampled_from([1e-10] * 4 + [1e-3, 0.0, -1.0, np.nan, np.inf]))
def test_fuzz_value_iteration(data, max_iter, tol):
    """V agrees with the optimum over every deterministic policy, to the accuracy the stopping rule promises."""
    mdp = data.draw(mdps())
    r = data.draw(reward_arrays(mdp))

    def call():
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            res = value_iteration(mdp, r, tol=tol, max_iter=max_iter)
        converged = not any(issubclass(x.category, ConvergenceWarning) for x in w)
        return res, converged

    def check(out):
        res, converged = out
        if not converged:  # only the shapes and V = max Q are promised
            V, Q = res
            return V.shape == r.shape[:-1] and np.allclose(V, Q.max(axis=-1))
        g = mdp.discount
        return check_values(mdp, r, res, atol=10 * tol * max(g, 1e-3) / (1 - g) + 1e-9)

    assert_typed_or_good("mmconcepts.tasks.value_iteration", call, check=check)


@fuzz_settings(150, **SETTINGS)
@given(data=st.data(), max_iter=st.sampled_from([-1, 0, 1] + [1000] * 4))
def test_fuzz_policy_iteration(data, max_iter):
    mdp = data.draw(mdps())
    r = data.draw(reward_arrays(mdp))

    def check(res):
        return max_iter < 5 or check_values(mdp, r, res, atol=1e-8)

    assert_typed_or_good("mmconcepts.tasks.policy_iteration", lambda: policy_iteration(mdp, r, max_iter=max_iter),
                         check=check)


@fuzz_settings(150, **SETTINGS)
@given(data=st.data())
def test_fuzz_soft_value_iteration(data):
    """The soft values satisfy V = logsumexp(Q) and dominate the hard optimum (log-sum-exp >= max)."""
    mdp = data.draw(mdps())
    r = data.draw(reward_arrays(mdp))

    def check(res):
        V, Q = res
        if V.shape != r.shape[:-1] or Q.shape != r.shape:
            return False
        lse = np.log(np.exp(Q - Q.max(-1, keepdims=True)).sum(-1)) + Q.max(-1)
        hard, _ = value_iteration(mdp, r)
        return np.allclose(V, lse) and (V >= hard - 1e-6 * (1 + np.abs(hard))).all()

    assert_typed_or_good("mmconcepts.tasks.soft_value_iteration", lambda: soft_value_iteration(mdp, r), check=check)


def test_value_iteration_matches_pymdptoolbox():
    """A second reference: pymdptoolbox's policy iteration on random MDPs (skipped without it)."""
    mdptoolbox = pytest.importorskip("mdptoolbox.mdp")
    rng = np.random.default_rng(0)
    for _ in range(10):
        S, A = rng.integers(1, 6), rng.integers(1, 4)
        P = rng.random((A, S, S))
        P /= P.sum(axis=2, keepdims=True)
        r = rng.normal(size=(S, A))
        mdp = MDP(P, discount=0.9)
        pi = mdptoolbox.PolicyIteration(P, r, 0.9)
        pi.run()
        V, _ = value_iteration(mdp, r, tol=1e-12)
        np.testing.assert_allclose(V, np.asarray(pi.V), atol=1e-8)


def test_value_iteration_hand_solved():
    """One state, two actions (rewards 1 and 2), gamma = 0.5: V* = 2 / (1 - 0.5) = 4."""
    mdp = MDP(np.ones((2, 1, 1)), discount=0.5)
    V, Q = value_iteration(mdp, [[1.0, 2.0]])
    np.testing.assert_allclose(V, [4.0])
    np.testing.assert_allclose(Q, [[3.0, 4.0]])


@fuzz_settings(300, **SETTINGS)
@given(Q=st.sampled_from([(1, 1), (3, 2), (2, 3, 4), (0, 2), (2, 0), (3,), ()]).flatmap(
    lambda s: arrays(float, s, elements=FLOATS)), tie_tol=st.sampled_from([0.0, 1e-8, 1.0, -1.0, np.nan, np.inf]))
def test_fuzz_greedy_policy(Q, tie_tol):
    """Rows are distributions whose support is the best actions (ties within the tolerance)."""

    def check(pi):
        if Q.ndim < 1 or not is_policy(pi, Q.shape):
            return False
        best = Q.max(axis=-1, keepdims=True)
        support = pi > 0
        # every chosen action is a best one (within the tie tolerance), and a best action is chosen
        finite = np.isfinite(best)
        near = Q >= np.where(finite, best - tie_tol * (1 + np.abs(np.where(finite, best, 0))) - 1e-12, best)
        near |= np.isneginf(best)
        return bool(np.all(~support | near) and np.all((support & (Q == best)).any(axis=-1) | np.isneginf(best[..., 0])))

    assert_typed_or_good("mmconcepts.tasks.greedy_policy", lambda: greedy_policy(Q, tie_tol=tie_tol), check=check)


@fuzz_settings(300, **SETTINGS)
@given(Q=st.sampled_from([(1, 1), (3, 2), (2, 3, 4), (0, 2), (2, 0), (3,)]).flatmap(
    lambda s: arrays(float, s, elements=FLOATS)), beta=st.one_of(EDGE_FLOATS, st.floats(0, 100)))
def test_fuzz_boltzmann_policy(Q, beta):
    def check(pi):
        if not is_policy(pi, Q.shape):
            return False
        # a better action is never less probable (beta >= 0); beta = 0 is uniform
        better = Q[..., :, None] > Q[..., None, :]
        monotone = np.all(~better | (pi[..., :, None] >= pi[..., None, :] - 1e-12))
        return bool(monotone and (beta != 0 or np.allclose(pi, 1.0 / Q.shape[-1])))

    assert_typed_or_good("mmconcepts.tasks.boltzmann_policy", lambda: boltzmann_policy(Q, beta), check=check)


@fuzz_settings(200, **SETTINGS)
@given(data=st.data())
def test_fuzz_q_values_and_policy_evaluation(data):
    """Q of the values of a policy, evaluated at the policy, gives back those values (Bellman eq. 2.25)."""
    mdp = data.draw(mdps())
    r = data.draw(reward_arrays(mdp))
    kind = data.draw(st.sampled_from(["valid", "negative", "unnormalised", "nan", "shape"]))
    pi = data.draw(arrays(float, (mdp.n_states, mdp.n_actions), elements=st.floats(0.01, 1)))
    pi = pi / pi.sum(axis=1, keepdims=True)
    if kind == "negative":
        pi[0, 0] = -0.5
    elif kind == "unnormalised":
        pi = pi * 2
    elif kind == "nan":
        pi[0, 0] = np.nan
    elif kind == "shape":
        pi = pi[:, :0]

    def call():
        V = policy_evaluation(mdp, pi, r)
        return V, q_values(mdp, V, r)

    def check(res):
        V, Q = res
        return V.shape == r.shape[:-1] and np.allclose((Q * pi).sum(-1), V, rtol=1e-6, atol=1e-6 * (1 + np.abs(V).max()))

    assert_typed_or_good("mmconcepts.tasks.policy_evaluation", call, check=check)


@fuzz_settings(300, **SETTINGS)
@given(data=st.data(), n=st.sampled_from([-1, 0] + [1, 5] * 4), length=st.sampled_from([-1, 0] + [1, 4] * 4),
       start_kind=st.sampled_from(["none", "valid"] * 4 + ["negative", "too_big", "float", "wrong_len", "nan"]))
def test_fuzz_sample_trajectories(data, n, length, start_kind):
    """Trajectories have the asked shape, valid indices, and only steps of positive probability."""
    mdp = data.draw(mdps())
    pi = data.draw(arrays(float, (mdp.n_states, mdp.n_actions), elements=st.floats(0, 1)))
    pi = pi + (pi.sum(axis=1, keepdims=True) == 0)
    pi = pi / pi.sum(axis=1, keepdims=True)
    k = max(n, 0)
    start = {"none": None, "valid": np.arange(k) % mdp.n_states, "negative": -np.ones(k, int),
             "too_big": np.full(k, mdp.n_states), "float": np.full(k, 0.5), "wrong_len": np.zeros(k + 1, int),
             "nan": np.full(k, np.nan)}[start_kind]

    def check(trajs):
        if len(trajs) != n:
            return False
        for t in trajs:
            if t.shape != (length, 2):
                return False
            s, a = t[:, 0], t[:, 1]
            if (s < 0).any() or (s >= mdp.n_states).any() or (a < 0).any() or (a >= mdp.n_actions).any():
                return False
            if (pi[s, a] <= 0).any() or (mdp.transitions[a[:-1], s[:-1], s[1:]] <= 0).any():
                return False
        if start is not None and not all(t[0, 0] == s0 for t, s0 in zip(trajs, start)):
            return False
        return True

    assert_typed_or_good("mmconcepts.tasks.sample_trajectories",
                         lambda: sample_trajectories(mdp, pi, n, length, start=start, random_state=0), check=check)


# ----------------------------------------------------------------------------- inverse RL on tiny problems


@st.composite
def demonstrations(draw, mdp, n_tasks_max=3):
    kind = draw(st.sampled_from(["valid"] * 12 + ["empty_task", "no_tasks", "bad_state", "bad_action", "float",
                                                 "wrong_shape", "nan"]))
    n_tasks = draw(st.integers(1, n_tasks_max))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    demos = [[np.stack([rng.integers(mdp.n_states, size=5), rng.integers(mdp.n_actions, size=5)], axis=1)
              for _ in range(2)] for _ in range(n_tasks)]
    if kind == "empty_task":
        demos[0] = []
    elif kind == "no_tasks":
        demos = []
    elif kind == "bad_state":
        demos[0][0][0, 0] = mdp.n_states
    elif kind == "bad_action":
        demos[0][0][0, 1] = -1
    elif kind == "float":
        demos[0][0] = demos[0][0] + 0.5
    elif kind == "wrong_shape":
        demos[0][0] = demos[0][0][:, :1]
    elif kind == "nan":
        demos[0][0] = np.full((3, 2), np.nan)
    return demos


def _irl_check(est, mdp, n_tasks):
    return (est.rewards_.shape == (n_tasks, mdp.n_states, mdp.n_actions) if hasattr(est, "rewards_") else True)


@fuzz_settings(40, **SETTINGS)
@given(data=st.data(), beta=st.sampled_from([1.0] * 4 + [0.0, -1.0, np.nan, 1e6]),
       max_iter=st.sampled_from([0] + [1, 3] * 3))
def test_fuzz_gradirl(data, beta, max_iter):
    mdp = grid_world(2, discount=0.5)
    demos = data.draw(demonstrations(mdp))

    def check(est):
        return est.theta_.shape[0] == len(demos) and np.all(est.loss_ >= 0)

    assert_typed_or_good("mmconcepts.tasks.GradIRL.fit",
                         lambda: GradIRL(beta=beta, max_iter=max_iter).fit(mdp, demos), check=check)


@fuzz_settings(40, **SETTINGS)
@given(data=st.data(), l2=st.sampled_from([0.01] * 4 + [0.0, -1.0, np.nan]),
       max_iter=st.sampled_from([0] + [1, 3] * 3))
def test_fuzz_maxent_irl(data, l2, max_iter):
    mdp = grid_world(2, discount=0.5)
    demos = data.draw(demonstrations(mdp))

    def check(est):
        return est.theta_.shape[0] == len(demos)

    assert_typed_or_good("mmconcepts.tasks.MaxEntIRL.fit",
                         lambda: MaxEntIRL(l2=l2, max_iter=max_iter).fit(mdp, demos), check=check)


@fuzz_settings(40, **SETTINGS)
@given(data=st.data(), k=st.sampled_from([0, 100] + [1, 2] * 3), init=st.sampled_from(["random", "pca"] * 3 + ["bad"]),
       max_iter=st.sampled_from([0] + [1, 2] * 3))
def test_fuzz_factorial_irl(data, k, init, max_iter):
    """The learnt rewards of every task are the coefficients times the dictionary."""
    mdp = grid_world(2, discount=0.5)
    demos = data.draw(demonstrations(mdp))

    def call():
        est = FactorialIRL(k, init=init, max_iter=max_iter, flat_max_iter=2, random_state=0).fit(mdp, demos)
        return est, est.transform(mdp, demos, max_iter=2)

    def check(res):
        est, coefs = res
        return (est.components_.shape[0] == k and est.coefficients_.shape == (len(demos), k)
                and coefs.shape == (len(demos), k))

    assert_typed_or_good("mmconcepts.tasks.FactorialIRL.fit", call, check=check)


# ----------------------------------------------------------------------------- inverse feedback control


@fuzz_settings(100, **SETTINGS)
@given(grid=st.sampled_from([-1, 0, 1] + [2, 3] * 4), sigma=st.sampled_from([0.0, -1.0, np.nan, np.inf] + [None, 0.3] * 4),
       beta=st.sampled_from(["nan", "huge", "wrong"] + ["ones"] * 6), n_steps=st.sampled_from([-1, 0] + [1, 5] * 4),
       dt=st.sampled_from([0.0, -1.0, np.nan, np.inf] + [0.01] * 8), method=st.sampled_from(["euler", "ode"] * 4 + ["rk"]),
       start=st.sampled_from([(np.nan, 0.0), (1e300, 0.0)] + [(0.5, 0.5)] * 6))
def test_fuzz_control_trajectories(grid, sigma, beta, n_steps, dt, method, start):
    def call():
        f = RBFFeatures(grid, sigma)
        b = {"ones": np.ones(f.n_features), "nan": np.full(f.n_features, np.nan),
             "huge": np.full(f.n_features, 1e300), "wrong": np.ones(f.n_features + 1)}[beta]
        return control_trajectories(f, b, start, n_steps=n_steps, dt=dt, method=method)

    def check(q):
        return q.shape == (1, n_steps + 1, 2) and np.allclose(q[0, 0], start)

    assert_typed_or_good("mmconcepts.tasks.control_trajectories", call, check=check)


@fuzz_settings(100, **SETTINGS)
@given(T=st.sampled_from([0, 1, 2, 20]), kind=st.sampled_from(["valid", "nan", "3d", "constant", "list_empty"]),
       regression=st.sampled_from(["lstsq", "ridge", "nnls", "other"]), alpha=st.sampled_from([1e-6, 0.0, -1.0]))
def test_fuzz_brillinger_regression(T, kind, regression, alpha):
    """On Euler trajectories of a known cost, the regression explains the steps (residual ~ 0 for lstsq)."""
    f = RBFFeatures(2)
    beta_true = np.array([1.0, 0.5, 0.2, 0.8])
    traj = control_trajectories(f, beta_true, (0.3, 0.7), n_steps=T - 1)[0] if T > 1 else np.full((T, 2), 0.5)
    arg = {"valid": traj, "nan": np.where(np.arange(traj.size).reshape(traj.shape) == 0, np.nan, traj),
           "3d": traj[..., None], "constant": np.ones_like(traj), "list_empty": []}[kind]

    def check(beta):
        if beta.shape != (f.n_features,):
            return False
        if kind == "valid" and regression == "lstsq" and T >= 5:
            again = control_trajectories(f, beta, traj[0], n_steps=T - 1)[0]
            return np.allclose(again, traj, atol=1e-8)
        return True

    assert_typed_or_good("mmconcepts.tasks.brillinger_regression",
                         lambda: brillinger_regression(f, arg, regression=regression, alpha=alpha), check=check)


@fuzz_settings(40, **SETTINGS)
@given(k=st.sampled_from([0, 50] + [1, 2] * 3), n_demos=st.sampled_from([0] + [1, 3] * 3),
       T=st.sampled_from([1, 2] + [15] * 4), kind=st.sampled_from(["valid"] * 6 + ["nan", "ragged_dims"]),
       max_iter=st.sampled_from([0] + [1, 3] * 3), solver=st.sampled_from(["steepest", "cg"] * 3 + ["x"]))
def test_fuzz_factorial_inverse_control(k, n_demos, T, kind, max_iter, solver):
    f = RBFFeatures(2)
    rng = np.random.default_rng(0)
    trajs = list(control_trajectories(f, rng.random((n_demos, f.n_features)), rng.random((n_demos, 2)),
                                      n_steps=T - 1)) if n_demos and T > 1 else [np.full((T, 2), 0.5)] * n_demos
    if kind == "nan" and trajs:
        trajs[0] = trajs[0].copy()
        trajs[0][0, 0] = np.nan
    elif kind == "ragged_dims" and trajs:
        trajs[0] = trajs[0][:, :1]

    def call():
        est = FactorialInverseControl(k, features=f, max_iter=max_iter, d_solver=solver, random_state=0).fit(trajs)
        return est, est.transform(trajs)

    def check(res):
        est, coefs = res
        return (est.components_.shape == (k, f.n_features) and coefs.shape == (len(trajs), k)
                and all(b >= a - 1e-9 * (1 + abs(a)) for a, b in zip(est.loss_history_[1:], est.loss_history_)))

    assert_typed_or_good("mmconcepts.tasks.FactorialInverseControl.fit", call, check=check)


def test_rewards_whose_values_overflow_are_refused():
    """|r| / (1 - gamma) beyond float64: a DataError before planning (value iteration gave inf values)."""
    from mmconcepts.errors import DataError

    mdp = MDP(np.ones((1, 1, 1)), discount=0.99)
    with pytest.raises(DataError, match="rescale the rewards"):
        value_iteration(mdp, [[1e307]])
    with pytest.raises(DataError, match="rescale the rewards"):
        policy_evaluation(mdp, [[1.0]], [[-1e307]])
    V, _ = value_iteration(mdp, [[1e290]])  # large but representable: the exact answer
    np.testing.assert_allclose(V, [1e292])


def test_boltzmann_policy_limits_and_overflow():
    """Known answers: +inf actions share their state, huge beta * Q does not overflow to NaN (found in a 10x run)."""
    pi = boltzmann_policy(np.array([[np.inf, 1e300], [1e300, 1e300], [1e300, -1e300], [-np.inf, -np.inf]]), 1e300)
    np.testing.assert_array_equal(pi, [[1, 0], [0.5, 0.5], [1, 0], [0.5, 0.5]])
    np.testing.assert_allclose(boltzmann_policy(np.array([[0.0, np.log(3.0)]]), 1.0), [[0.25, 0.75]])
    np.testing.assert_array_equal(boltzmann_policy(np.array([[np.inf, 0.0]]), 0.0), [[0.5, 0.5]])
