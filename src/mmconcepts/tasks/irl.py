"""Gradient inverse reinforcement learning (Neu and Szepesvari 2007) and a maxent baseline.

Thesis section 2.2.3, eq. (2.29)-(2.34). The reward of a task is linear in a parameter
``theta`` (d,): ``r_theta(s, a) = sum_j F[s, a, j] theta_j`` with a feature array ``F``
of shape (S, A, d); ``features=None`` means tabular rewards (``d = S A``,
``theta[s * A + a] = r(s, a)``), the setting of section 4.3.2.

The policy-matching loss of one task (eq. 2.30), on the empirical state occupation
``mu`` and policy ``pi_E`` of its demonstrations, is

.. math:: J(\\theta) = \\sum_{x, a} \\hat\\mu_E(x) \\left[\\pi_\\theta(a|x) - \\hat\\pi_E(a|x)\\right]^2,
          \\qquad \\pi_\\theta = G(Q^*_\\theta) \\text{ (Boltzmann, eq. 2.32)}.

Its gradient chains eq. (2.33) (Boltzmann derivative, with the inverse temperature
``beta`` written out) and the fixed point (2.34) for ``dQ*/dtheta``. Instead of the
full Jacobian (S A x d), the gradient is computed in adjoint form: with
``g = dJ/dQ`` (S, A) and ``pi`` greedy on Q*,

.. math:: w = (I - \\gamma P_\\pi^T)^{-1} \\sum_{x,a} P(\\cdot|x, a) g(x, a), \\quad
          \\nabla_\\theta J = F^T \\left(g + \\gamma\\, \\pi \\odot w\\right),

which is (2.34) transposed: one S x S solve per task (or a fixed-point iteration for
large S), batched over tasks. :func:`q_gradient` gives the forward Jacobian itself.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable, Sequence

import numpy as np
from sklearn.base import BaseEstimator

from .._persist import SaveLoadMixin
from .._validation import InstanceOf, Interval, Options, validate_params
from ..errors import ConvergenceWarning, DataError, ParameterError
from .mdp import (
    MDP,
    boltzmann_policy_unchecked,
    greedy_policy_unchecked,
    policy_iteration_unchecked,
    soft_value_iteration_unchecked,
    value_iteration_unchecked,
    check_trajectories,
    policy_transitions,
)

__all__ = [
    "empirical_policy",
    "check_features",
    "features_to_rewards",
    "gradirl_objective",
    "q_gradient",
    "adjoint_gradient",
    "maxent_objective",
    "armijo_descent",
    "GradIRL",
    "MaxEntIRL",
    "check_task_demonstrations",
]

# Parameters of the public functions, declared once and checked by one validate_params call at
# their start; the learners' inner loops call the unchecked twins (gradirl_objective_unchecked, ...), which
# do not check. A stopping test "change < tol" can never be met with tol = 0, hence tol > 0 for the
# fixed-point iterations; the descents stop on "relative decrease < tol", where tol = 0 means
# "run max_iter steps".
_MDP = [InstanceOf(MDP, description="an MDP")]
_PARAMETER_CONSTRAINTS: dict[str, dict[str, list]] = {
    "adjoint_gradient": {"mdp": _MDP, "method": [Options("auto", "solve", "iterate")],
                         "tol": [Interval("real", 0, None, closed="neither")], "max_iter": [Interval("int", 1, None)]},
    "q_gradient": {"mdp": _MDP, "method": [Options("solve", "iterate")],
                   "tol": [Interval("real", 0, None, closed="neither")], "max_iter": [Interval("int", 1, None)]},
    "gradirl_objective": {"mdp": _MDP, "beta": [Interval("real", 0, None)], "init": ["array-like", None],
                          "return_values": ["boolean"], "method": [Options("auto", "solve", "iterate")]},
    "maxent_objective": {"mdp": _MDP, "l2": [Interval("real", 0, None)], "init": ["array-like", None],
                         "return_values": ["boolean"]},
    "armijo_descent": {"fun": ["callable"], "max_iter": [Interval("int", 0, None)], "tol": [Interval("real", 0, None)],
                       "step0": [Interval("real", 0, None, closed="neither")],
                       "c": [Interval("real", 0, 1, closed="neither")],
                       "shrink": [Interval("real", 0, 1, closed="neither")], "grow": [Interval("real", 1, None)],
                       "max_backtracks": [Interval("int", 1, None)], "steps": ["array-like", None]},
}


def check_task_demonstrations(mdp: MDP, demonstrations: Any) -> list[list[np.ndarray]]:
    """Validate demonstrations of several tasks: a list (tasks) of lists of (T, 2) int arrays.

    A single task given as a list of arrays is accepted only through the estimators'
    documentation: here every element must itself be a list of trajectories.
    """
    if isinstance(demonstrations, np.ndarray) or not len(demonstrations):
        raise DataError("demonstrations must be a non-empty list with one entry per task, each a list of "
                        "(n_steps, 2) arrays of (state, action) pairs; for one task pass [trajectories].")
    out = []
    for i, task in enumerate(demonstrations):
        if isinstance(task, np.ndarray) and task.ndim == 2:
            raise DataError(f"demonstrations[{i}] is a single array; each task must be a list of trajectories "
                            "(wrap it: [[traj]] for one task with one trajectory).")
        out.append(check_trajectories(mdp, task, name=f"task {i} trajectory"))
    return out


def empirical_policy(mdp: MDP, trajectories: Any) -> tuple[np.ndarray, np.ndarray]:
    """Empirical state occupation and policy of demonstrations (the hats of eq. 2.30).

    Parameters
    ----------
    mdp : MDP
    trajectories : list of ndarray of shape (n_steps, 2)
        (state, action) pairs of one task.

    Returns
    -------
    mu : ndarray of shape (S,)
        Fraction of the demonstrated steps spent in each state (sums to one).
    pi_E : ndarray of shape (S, A)
        Action frequencies in each visited state; uniform in unvisited states (which
        ``mu = 0`` removes from the loss).
    """
    trajs = check_trajectories(mdp, trajectories)
    sa = np.concatenate(trajs)
    counts = np.zeros((mdp.n_states, mdp.n_actions))
    np.add.at(counts, (sa[:, 0], sa[:, 1]), 1.0)
    n_s = counts.sum(axis=1)
    mu = n_s / n_s.sum()
    pi = np.where(n_s[:, None] > 0, counts / np.maximum(n_s, 1)[:, None], 1.0 / mdp.n_actions)
    return mu, pi


def check_features(mdp: MDP, features: Any) -> np.ndarray | None:
    """Return features as (S, A, d) floats, ``None`` for tabular; accept (S*A, d) too."""
    if features is None:
        return None
    F = np.asarray(features, dtype=float)
    S, A = mdp.n_states, mdp.n_actions
    if F.ndim == 2 and F.shape[0] == S * A:
        F = F.reshape(S, A, -1)
    if F.ndim != 3 or F.shape[:2] != (S, A) or F.shape[2] < 1:
        raise ParameterError(f"features must have shape (n_states, n_actions, d) = ({S}, {A}, d) or ({S * A}, d); "
                             f"got {np.shape(features)}.")
    if not np.all(np.isfinite(F)):
        raise DataError("features contain NaN or infinite values.")
    return F


def features_to_rewards(mdp: MDP, theta: np.ndarray, features: np.ndarray | None) -> np.ndarray:
    """Rewards (..., S, A) from parameters ``theta`` (..., d)."""
    S, A = mdp.n_states, mdp.n_actions
    theta = np.asarray(theta, dtype=float)
    if features is None:
        return theta.reshape(theta.shape[:-1] + (S, A))
    return np.einsum("saj,...j->...sa", features, theta)


def _pullback(features: np.ndarray | None, z: np.ndarray) -> np.ndarray:
    """F^T z for z of shape (T, S, A): (T, d)."""
    if features is None:
        return z.reshape(z.shape[0], -1)
    return np.einsum("saj,tsa->tj", features, z)


def adjoint_gradient(mdp: MDP, g: np.ndarray, policy: np.ndarray, *, method: str = "auto",
                     tol: float = 1e-12, max_iter: int = 10_000) -> np.ndarray:
    """Given ``g = dJ/dQ`` (T, S, A) and a policy (T, S, A), return ``dJ/dr`` (T, S, A).

    ``dJ/dr = g + gamma pi * w`` with ``w = (I - gamma P_pi^T)^{-1} c``,
    ``c(y) = sum_{x,a} P(y|x,a) g(x,a)``: the transpose of the fixed point (2.34).
    ``method`` is 'solve' (batched S x S linear solve), 'iterate' (fixed-point
    iteration, one matrix product per sweep for all tasks) or 'auto' (solve when
    S <= 1500).
    """
    validate_params(dict(mdp=mdp, method=method, tol=tol, max_iter=max_iter),
                    _PARAMETER_CONSTRAINTS["adjoint_gradient"], owner="adjoint_gradient")
    return _adjoint_gradient(mdp, g, policy, method=method, tol=tol, max_iter=max_iter)


def _adjoint_gradient(mdp: MDP, g: np.ndarray, policy: np.ndarray, *, method: str = "auto",
                      tol: float = 1e-12, max_iter: int = 10_000) -> np.ndarray:
    """:func:`adjoint_gradient` without the parameter checks."""
    T, S, A = g.shape
    gamma = mdp.discount
    Pf = mdp.transitions.reshape(A * S, S)
    c = g.transpose(0, 2, 1).reshape(T, A * S) @ Pf  # (T, S)
    if method == "auto":
        method = "solve" if S <= 1500 else "iterate"
    if method == "solve":
        Ppi = policy_transitions(mdp, policy)  # (T, S, S)
        M = np.eye(S) - gamma * np.swapaxes(Ppi, -1, -2)
        w = np.linalg.solve(M, c[..., None])[..., 0]
    else:  # "iterate"
        w = c.copy()
        PT = mdp.transitions  # w_{k+1}(y) = c(y) + gamma sum_x P_pi[x, y] w_k(x)
        for _ in range(max_iter):
            u = (policy * w[:, :, None]).transpose(0, 2, 1).reshape(T, A * S) @ Pf
            w_new = c + gamma * u
            done = np.abs(w_new - w).max() < tol
            w = w_new
            if done:
                break
        else:
            warnings.warn("adjoint fixed-point iteration did not converge; use method='solve'.",
                          ConvergenceWarning, stacklevel=3)
        del PT
    return g + gamma * policy * w[:, :, None]


def q_gradient(mdp: MDP, features: Any, policy: Any, *, method: str = "solve", tol: float = 1e-12,
               max_iter: int = 10_000) -> np.ndarray:
    """Jacobian ``dQ*/dtheta`` by the fixed point of thesis eq. (2.34).

    .. math:: \\varphi(x, a) = \\nabla_\\theta r(x, a) + \\gamma \\sum_y P(y|x, a) \\sum_b \\pi(b|y) \\varphi(y, b)

    Parameters
    ----------
    mdp : MDP
    features : array-like of shape (S, A, d) or None (tabular, d = S A)
    policy : array-like of shape (S, A)
        A greedy policy on Q*_theta.
    method : {'solve', 'iterate'}
        Direct solve of ``psi = (I - gamma P_pi)^{-1} F_pi`` (S x S), or Picard iteration.

    Returns
    -------
    phi : ndarray of shape (S, A, d)
    """
    validate_params(dict(mdp=mdp, method=method, tol=tol, max_iter=max_iter), _PARAMETER_CONSTRAINTS["q_gradient"],
                    owner="q_gradient")
    S, A = mdp.n_states, mdp.n_actions
    F = check_features(mdp, features)
    if F is None:
        F = np.eye(S * A).reshape(S, A, S * A)
    pi = np.asarray(policy, dtype=float)
    gamma = mdp.discount
    Fpi = np.einsum("sa,saj->sj", pi, F)
    Ppi = policy_transitions(mdp, pi)
    if method == "solve":
        psi = np.linalg.solve(np.eye(S) - gamma * Ppi, Fpi)
    else:  # "iterate"
        psi = Fpi.copy()
        for _ in range(max_iter):
            new = Fpi + gamma * Ppi @ psi
            done = np.abs(new - psi).max() < tol
            psi = new
            if done:
                break
    return F + gamma * np.einsum("ast,tj->saj", mdp.transitions, psi)


def gradirl_objective(mdp: MDP, theta: np.ndarray, mu: np.ndarray, pi_E: np.ndarray, *,
                      features: np.ndarray | None = None, beta: float = 1.0, init: np.ndarray | None = None,
                      return_values: bool = False, method: str = "auto"):
    """Loss (2.30) and its gradient (2.33)-(2.34) for many tasks at once.

    Parameters
    ----------
    mdp : MDP
    theta : ndarray of shape (T, d)
    mu : ndarray of shape (T, S)
        Empirical state occupations.
    pi_E : ndarray of shape (T, S, A)
        Empirical expert policies.
    features : ndarray of shape (S, A, d) or None (tabular)
    beta : float
        Boltzmann inverse temperature of eq. (2.32).
    init : ndarray of shape (T, S), optional
        Warm start of the planner (its greedy policy starts policy iteration).
    method : {'auto', 'solve', 'iterate'}, default='auto'
        'solve': Q* by :func:`~mmconcepts.tasks.policy_iteration` and the adjoint (2.34)
        by a linear solve, both exact; 'iterate': value iteration and fixed-point
        iteration; 'auto': 'solve' when S <= 1500.

    Returns
    -------
    loss : ndarray of shape (T,)
    grad : ndarray of shape (T, d)
    V : ndarray of shape (T, S), only with ``return_values=True``
    """
    validate_params(dict(mdp=mdp, beta=beta, init=init, return_values=return_values, method=method),
                    _PARAMETER_CONSTRAINTS["gradirl_objective"], owner="gradirl_objective")
    return gradirl_objective_unchecked(mdp, theta, mu, pi_E, features=features, beta=beta, init=init,
                              return_values=return_values, method=method)


def gradirl_objective_unchecked(mdp: MDP, theta: np.ndarray, mu: np.ndarray, pi_E: np.ndarray, *,
                       features: np.ndarray | None = None, beta: float = 1.0, init: np.ndarray | None = None,
                       return_values: bool = False, method: str = "auto"):
    """:func:`gradirl_objective` without the parameter checks (for the learners' inner loops)."""
    r = features_to_rewards(mdp, theta, features)
    # Q* exactly by policy iteration when the S x S solves are cheap (the same rule as the
    # adjoint's 'auto'): warm-started from the last values it needs 1-3 iterations where
    # value iteration needed about 200 sweeps (measured on the chapter-4 grid world).
    small = mdp.n_states <= 1500 if method == "auto" else method == "solve"
    V, Q = policy_iteration_unchecked(mdp, r, init=init) if small else value_iteration_unchecked(mdp, r, init=init)
    pib = boltzmann_policy_unchecked(Q, beta)
    diff = pib - pi_E
    loss = (mu * (diff**2).sum(axis=2)).sum(axis=1)
    e = 2.0 * mu[:, :, None] * diff  # dJ/dpi
    g = beta * pib * (e - (e * pib).sum(axis=2, keepdims=True))  # dJ/dQ by eq. (2.33)
    z = _adjoint_gradient(mdp, g, greedy_policy_unchecked(Q), method=method)
    grad = _pullback(features, z)
    return (loss, grad, V) if return_values else (loss, grad)


def maxent_objective(mdp: MDP, theta: np.ndarray, counts: np.ndarray, *, features: np.ndarray | None = None,
                     l2: float = 0.0, init: np.ndarray | None = None, return_values: bool = False):
    """Negative log-likelihood of demonstrations under the soft-optimal policy (maxent IRL).

    ``L(theta) = -sum_{s,a} c(s,a) log pi_theta(a|s) / n + l2 / 2 |theta|^2`` with
    ``pi_theta = exp(Q_soft - V_soft)`` (maximum causal entropy IRL, Ziebart et al. 2010;
    a baseline beyond the thesis). Batched: ``theta`` (T, d), ``counts`` (T, S, A).
    Returns ``(loss (T,), grad (T, d))``.
    """
    validate_params(dict(mdp=mdp, l2=l2, init=init, return_values=return_values),
                    _PARAMETER_CONSTRAINTS["maxent_objective"], owner="maxent_objective")
    return _maxent_objective(mdp, theta, counts, features=features, l2=l2, init=init, return_values=return_values)


def _maxent_objective(mdp: MDP, theta: np.ndarray, counts: np.ndarray, *, features: np.ndarray | None = None,
                      l2: float = 0.0, init: np.ndarray | None = None, return_values: bool = False):
    """:func:`maxent_objective` without the parameter checks (for the learners' inner loops)."""
    r = features_to_rewards(mdp, theta, features)
    V, Q = soft_value_iteration_unchecked(mdp, r, init=init)
    logpi = Q - V[:, :, None]
    pi = np.exp(logpi)
    n = counts.sum(axis=(1, 2))
    loss = -(counts * logpi).sum(axis=(1, 2)) / n + 0.5 * l2 * (theta**2).sum(axis=1)
    g = -(counts - counts.sum(axis=2, keepdims=True) * pi) / n[:, None, None]  # dL/dQ (V's derivative is pi)
    z = _adjoint_gradient(mdp, g, pi)
    grad = _pullback(features, z) + l2 * theta
    return (loss, grad, V) if return_values else (loss, grad)


def armijo_descent(fun: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]], x0: np.ndarray, *,
                   max_iter: int = 100, tol: float = 1e-6, step0: float = 1.0, c: float = 1e-4, shrink: float = 0.5,
                   grow: float = 2.0, max_backtracks: int = 30, steps: np.ndarray | None = None):
    """Gradient descent with Armijo backtracking on many independent problems at once.

    ``fun(X, rows)`` returns ``(f (len(rows),), G (len(rows), d))`` for the rows ``rows`` of
    ``X`` (n, d). Each row keeps its own step, which shrinks until the Armijo condition
    ``f(x - t g) <= f(x) - c t |g|^2`` holds and grows by ``grow`` after a success. A row
    stops when its relative decrease falls below ``tol`` or its step underflows.

    Returns
    -------
    x : ndarray (n, d)
    f : ndarray (n,)
    n_iter : int
    steps : ndarray (n,)
        Last step sizes (to warm start a later call).

    Raises
    ------
    ParameterError
        If an option is out of its range: ``max_iter >= 0`` (0 returns the start point),
        ``tol >= 0``, ``step0 > 0``, ``0 < c < 1``, ``0 < shrink < 1``, ``grow >= 1``,
        ``max_backtracks >= 1``.
    """
    validate_params(dict(fun=fun, max_iter=max_iter, tol=tol, step0=step0, c=c, shrink=shrink, grow=grow,
                         max_backtracks=max_backtracks, steps=steps), _PARAMETER_CONSTRAINTS["armijo_descent"],
                    owner="armijo_descent")
    X = np.array(x0, dtype=float, copy=True)
    n = X.shape[0]
    rows = np.arange(n)
    f, G = fun(X, rows)
    t = np.full(n, float(step0)) if steps is None else np.array(steps, dtype=float)
    active = np.ones(n, dtype=bool)
    it = 0
    for it in range(1, max_iter + 1):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            it -= 1
            break
        gn2 = (G[idx] ** 2).sum(axis=1)
        todo = idx.copy()
        tt = t[idx].copy()
        new_f = f[idx].copy()
        accepted = np.zeros(idx.size, dtype=bool)
        pos = np.arange(idx.size)
        for _ in range(max_backtracks):
            trial = X[todo] - tt[pos, None] * G[todo]
            ft, Gt = fun(trial, todo)
            ok = ft <= f[todo] - c * tt[pos] * gn2[pos]
            if ok.any():
                good = todo[ok]
                X[good] = trial[ok]
                new_f[pos[ok]] = ft[ok]
                G[good] = Gt[ok]
                accepted[pos[ok]] = True
            todo, pos = todo[~ok], pos[~ok]
            tt[pos] *= shrink
            if todo.size == 0:
                break
        old = f[idx]
        f[idx] = new_f
        t[idx] = np.where(accepted, tt * grow, tt)
        rel = (old - new_f) / np.maximum(np.abs(old), 1e-12)
        stop = ~accepted | (rel < tol) | (gn2 < 1e-24)
        active[idx[stop]] = False
    return X, f, it, t


def demonstration_stats(mdp: MDP, demos: list[list[np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    mus, pis = zip(*(empirical_policy(mdp, task) for task in demos))
    return np.array(mus), np.array(pis)


class _WarmVI:
    """Keeps the last values of each task to warm-start the planner."""

    def __init__(self, n_tasks: int, n_states: int) -> None:
        self.V = np.zeros((n_tasks, n_states))


IRL_HINTS = {
    "beta": "beta is the Boltzmann inverse temperature of eq. (2.32); at beta = 0 every policy is uniform and the "
            "loss has no gradient.",
    "tol": "A task stops when its relative loss decrease falls below tol; tol = 0 runs max_iter steps.",
    "features": "Give an array of shape (n_states, n_actions, d), or None for tabular rewards.",
}


class GradIRL(SaveLoadMixin, BaseEstimator):
    """Flat gradient IRL (Neu and Szepesvari 2007; thesis section 2.2.3), one parameter per task.

    Minimises the policy-matching loss (2.30) of each task independently by gradient
    descent with Armijo steps; all tasks are processed together (batched planning: policy
    iteration for up to 1500 states, value iteration beyond).

    Parameters
    ----------
    features : array-like of shape (S, A, d), optional
        Reward features; None means tabular rewards (d = S A).
    beta : float, default=1.0
        Boltzmann inverse temperature (eq. 2.32), > 0.
    max_iter : int, default=100
        Gradient steps per task, >= 1.
    tol : float, default=1e-6
        Stop a task when its relative loss decrease is below ``tol`` (>= 0; 0 runs
        ``max_iter`` steps).
    step0 : float, default=1.0
        Initial step size, > 0.

    Attributes
    ----------
    theta_ : ndarray of shape (n_tasks, d)
    rewards_ : ndarray of shape (n_tasks, S, A)
    loss_ : ndarray of shape (n_tasks,)
    n_iter_ : int

    Notes
    -----
    A scikit-learn estimator (``get_params``, ``set_params``, ``clone``) whose ``fit`` takes
    an :class:`~mmconcepts.tasks.MDP` and demonstrations instead of ``(X, y)``. ``save`` and
    ``load`` keep the parameters and the learnt arrays above; the MDP is not part of the
    model (pass it again where it is needed).
    """

    _parameter_constraints: dict[str, list] = {
        "features": ["array-like", None],
        "beta": [Interval("real", 0, None, closed="neither")],
        "max_iter": [Interval("int", 1, None)],
        "tol": [Interval("real", 0, None)],
        "step0": [Interval("real", 0, None, closed="neither")],
    }

    def __init__(self, features: Any = None, *, beta: float = 1.0, max_iter: int = 100, tol: float = 1e-6,
                 step0: float = 1.0) -> None:
        self.features = features
        self.beta = beta
        self.max_iter = max_iter
        self.tol = tol
        self.step0 = step0

    def fit(self, mdp: MDP, demonstrations: Sequence[Sequence[Any]], *, theta0: Any = None) -> "GradIRL":
        """Learn one reward per task.

        Parameters
        ----------
        mdp : MDP
        demonstrations : list (tasks) of list of ndarray of shape (n_steps, 2)
            (state, action) pairs; ``[trajectories]`` for a single task.
        theta0 : array-like of shape (n_tasks, d), optional
            Starting parameters (default zeros).

        Raises
        ------
        ParameterError
            If a parameter is out of its range, or ``mdp``, ``features`` or ``theta0`` do not fit.
        DataError
            If the demonstrations are malformed.
        """
        validate_params(self, self._parameter_constraints, hints=IRL_HINTS)
        if not isinstance(mdp, MDP):
            raise ParameterError(f"mdp must be an MDP; got {type(mdp).__name__}.")
        beta = float(self.beta)
        F = check_features(mdp, self.features)
        demos = check_task_demonstrations(mdp, demonstrations)
        mu, pi_E = demonstration_stats(mdp, demos)
        d = mdp.n_states * mdp.n_actions if F is None else F.shape[2]
        x0 = np.zeros((len(demos), d)) if theta0 is None else np.asarray(theta0, dtype=float)
        if x0.shape != (len(demos), d):
            raise ParameterError(f"theta0 must have shape ({len(demos)}, {d}); got {x0.shape}.")
        warm = _WarmVI(len(demos), mdp.n_states)

        def fun(X, rows):
            loss, grad, V = gradirl_objective_unchecked(mdp, X, mu[rows], pi_E[rows], features=F, beta=beta,
                                               init=warm.V[rows], return_values=True)
            warm.V[rows] = V
            return loss, grad

        self.theta_, self.loss_, self.n_iter_, _ = armijo_descent(fun, x0, max_iter=int(self.max_iter), tol=self.tol,
                                                                   step0=self.step0)
        self.rewards_ = features_to_rewards(mdp, self.theta_, F)
        return self


class MaxEntIRL(SaveLoadMixin, BaseEstimator):
    """Maximum (causal) entropy IRL, one tabular or linear reward per task (baseline beyond the thesis).

    Maximises the likelihood of the demonstrated actions under the soft-optimal policy
    (Ziebart et al. 2010) with an L2 penalty, by Armijo gradient steps, batched over tasks.

    Parameters
    ----------
    features : array-like of shape (S, A, d), optional
    l2 : float, default=0.01
        L2 penalty, >= 0.
    max_iter : int, default=100
        Gradient steps per task, >= 1.
    tol : float, default=1e-6
        As in :class:`GradIRL`.
    step0 : float, default=1.0
        Initial step size, > 0.

    Attributes
    ----------
    theta_, rewards_, loss_, n_iter_ : as in :class:`GradIRL`

    Notes
    -----
    The estimator contract, ``save`` and ``load`` are those of :class:`GradIRL`.
    """

    _parameter_constraints: dict[str, list] = {
        "features": ["array-like", None],
        "l2": [Interval("real", 0, None)],
        "max_iter": [Interval("int", 1, None)],
        "tol": [Interval("real", 0, None)],
        "step0": [Interval("real", 0, None, closed="neither")],
    }

    def __init__(self, features: Any = None, *, l2: float = 0.01, max_iter: int = 100, tol: float = 1e-6,
                 step0: float = 1.0) -> None:
        self.features = features
        self.l2 = l2
        self.max_iter = max_iter
        self.tol = tol
        self.step0 = step0

    def fit(self, mdp: MDP, demonstrations: Sequence[Sequence[Any]]) -> "MaxEntIRL":
        """Learn one reward per task from ``demonstrations`` (as in :meth:`GradIRL.fit`)."""
        validate_params(self, self._parameter_constraints, hints=IRL_HINTS)
        if not isinstance(mdp, MDP):
            raise ParameterError(f"mdp must be an MDP; got {type(mdp).__name__}.")
        l2 = float(self.l2)
        F = check_features(mdp, self.features)
        demos = check_task_demonstrations(mdp, demonstrations)
        counts = np.zeros((len(demos), mdp.n_states, mdp.n_actions))
        for i, task in enumerate(demos):
            sa = np.concatenate(task)
            np.add.at(counts[i], (sa[:, 0], sa[:, 1]), 1.0)
        d = mdp.n_states * mdp.n_actions if F is None else F.shape[2]
        warm = _WarmVI(len(demos), mdp.n_states)

        def fun(X, rows):
            loss, grad, V = _maxent_objective(mdp, X, counts[rows], features=F, l2=l2, init=warm.V[rows],
                                              return_values=True)
            warm.V[rows] = V
            return loss, grad

        self.theta_, self.loss_, self.n_iter_, _ = armijo_descent(
            fun, np.zeros((len(demos), d)), max_iter=int(self.max_iter), tol=self.tol, step0=self.step0)
        self.rewards_ = features_to_rewards(mdp, self.theta_, F)
        return self
