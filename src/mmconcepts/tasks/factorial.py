"""Factorial inverse reinforcement learning: a dictionary of rewards shared by many tasks.

Thesis section 4.3.1, eq. (4.8)-(4.10). Task ``i`` has parameters
``theta_i = D h_i``; the learner minimises the cumulated GradIRL loss

.. math:: J_\\Xi(D, H) = \\sum_{i=1}^n J_{\\xi_i}(D h^{(i)})            \\qquad (4.8)

by alternating Armijo gradient steps on H (separable over tasks) and on D, with

.. math:: \\nabla_D J_\\Xi = \\left(\\nabla_\\theta J_{\\xi_1}(D h^{(1)}) | \\dots | \\nabla_\\theta J_{\\xi_n}(D h^{(n)})\\right) H^T  \\qquad (4.9)
.. math:: \\nabla_H J_\\Xi = D^T \\left(\\nabla_\\theta J_{\\xi_1}(D h^{(1)}) | \\dots \\right)  \\qquad (4.10)

Orientation: the thesis stacks tasks as columns (D is d x k, H is k x n). Here, as in
the rest of mmconcepts, tasks are rows: ``theta_`` (n_tasks, d) ~= ``coefficients_``
(n_tasks, k) @ ``components_`` (k, d), so ``components_ = D^T`` and
``coefficients_ = H^T``.
"""

from __future__ import annotations

import warnings
from typing import Any, Sequence

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import InstanceOf, Interval, Options, check_random_state, validate_params
from ..errors import ConvergenceWarning, ParameterError
from .irl import (
    IRL_HINTS,
    GradIRL,
    gradirl_objective_unchecked,
    demonstration_stats,
    armijo_descent,
    check_features,
    check_task_demonstrations,
    features_to_rewards,
)
from .mdp import MDP

__all__ = ["FactorialIRL", "factorial_objective", "component_features"]

_OBJECTIVE_CONSTRAINTS: dict[str, list] = {"mdp": [InstanceOf(MDP, description="an MDP")],
                                           "beta": [Interval("real", 0, None)], "init": ["array-like", None]}


def component_features(mdp: MDP, components: np.ndarray, features: np.ndarray | None = None) -> np.ndarray:
    """Reward features (S, A, k) of dictionary atoms ``components`` (k, d) over base ``features``."""
    components = np.asarray(components, dtype=float)
    return np.moveaxis(features_to_rewards(mdp, components, features), 0, -1)


def factorial_objective(mdp: MDP, components: np.ndarray, coefficients: np.ndarray, mu: np.ndarray,
                        pi_E: np.ndarray, *, features: np.ndarray | None = None, beta: float = 1.0,
                        init: np.ndarray | None = None):
    """Cumulated loss (4.8) and its gradients (4.9), (4.10) in row orientation.

    Parameters
    ----------
    components : ndarray of shape (k, d)      (D^T)
    coefficients : ndarray of shape (n, k)    (H^T)
    mu, pi_E : empirical statistics of the n tasks, (n, S) and (n, S, A)

    Returns
    -------
    loss : float
    grad_components : ndarray of shape (k, d)
    grad_coefficients : ndarray of shape (n, k)
    """
    validate_params(dict(mdp=mdp, beta=beta, init=init), _OBJECTIVE_CONSTRAINTS, owner="factorial_objective")
    theta = coefficients @ components
    losses, G = gradirl_objective_unchecked(mdp, theta, mu, pi_E, features=features, beta=beta, init=init)
    return float(losses.sum()), coefficients.T @ G, G @ components.T


class FactorialIRL(SaveLoadMixin, BaseEstimator):
    """Factorial IRL (thesis section 4.3.1): learn k primitive rewards from many tasks.

    Parameters
    ----------
    n_components : int, default=5
        Dictionary size k (>= 1, at most min(n_tasks, d)).
    features : array-like of shape (S, A, d), optional
        Base reward features; None means tabular rewards (d = S A).
    beta : float, default=1.0
        Boltzmann inverse temperature (eq. 2.32), > 0.
    max_iter : int, default=30
        Alternations (one H phase and one D phase each), >= 0 (0 keeps the initialisation).
    inner_steps : int, default=5
        Armijo gradient steps per phase, >= 1.
    tol : float, default=1e-4
        Stop when an alternation lowers the cumulated loss by less than ``tol`` (relative; >= 0).
    init : {'pca', 'random'} or ndarray of shape (k, d), default='pca'
        'pca': flat GradIRL on every task, then the first k right singular vectors of the
        learnt parameters (an uncentred PCA, since theta = D h has no offset) as the
        initial dictionary, the projections as coefficients (section 4.3.1).
    flat_max_iter : int, default=100
        Gradient steps of the flat learners used by ``init='pca'``, >= 1.
    random_state : int, Generator or None
        Used by ``init='random'``.

    Attributes
    ----------
    components_ : ndarray of shape (k, d)
        The dictionary (D^T).
    coefficients_ : ndarray of shape (n_tasks, k)
        Mixing coefficients of the training tasks (H^T).
    theta_ : ndarray of shape (n_tasks, d)
    rewards_ : ndarray of shape (n_tasks, S, A)
    flat_theta_ : ndarray of shape (n_tasks, d) or None
        Flat GradIRL parameters used for the PCA initialisation.
    init_components_ : ndarray of shape (k, d)
    loss_history_ : list of float
        Cumulated loss (4.8) after the initialisation and after each alternation.
    n_iter_ : int

    Notes
    -----
    A scikit-learn estimator (``get_params``, ``set_params``, ``clone``) whose ``fit`` takes
    an :class:`~mmconcepts.tasks.MDP` and demonstrations instead of ``(X, y)``. ``save`` and
    ``load`` keep the parameters (a ``random_state`` generator is saved as None), the learnt
    arrays above and the (n_states, n_actions) of the training MDP; the MDP itself is not
    saved, so a loaded model's :meth:`reward_features` and :meth:`transform` take it as
    before (an MDP of another size is refused).
    """

    _parameter_constraints: dict[str, list] = {
        "n_components": [Interval("int", 1, None)],
        "features": ["array-like", None],
        "beta": [Interval("real", 0, None, closed="neither")],
        "max_iter": [Interval("int", 0, None)],
        "inner_steps": [Interval("int", 1, None)],
        "tol": [Interval("real", 0, None)],
        "init": [Options("pca", "random"), "array-like"],
        "flat_max_iter": [Interval("int", 1, None)],
        "random_state": ["random_state"],
    }
    _hints = {**IRL_HINTS,
              "tol": "The learner stops when an alternation lowers the loss by less than tol (relative); tol = 0 runs "
                     "max_iter alternations.",
              "init": "An array has shape (n_components, d)."}
    _persisted_private = ("_mdp_shape",)

    def __init__(self, n_components: int = 5, *, features: Any = None, beta: float = 1.0, max_iter: int = 30,
                 inner_steps: int = 5, tol: float = 1e-4, init: Any = "pca", flat_max_iter: int = 100,
                 random_state: Any = None) -> None:
        self.n_components = n_components
        self.features = features
        self.beta = beta
        self.max_iter = max_iter
        self.inner_steps = inner_steps
        self.tol = tol
        self.init = init
        self.flat_max_iter = flat_max_iter
        self.random_state = random_state

    def fit(self, mdp: MDP, demonstrations: Sequence[Sequence[Any]], *, flat_theta: Any = None) -> "FactorialIRL":
        """Learn the dictionary and the coefficients of the demonstrated tasks.

        Parameters
        ----------
        mdp : MDP
        demonstrations : list (tasks) of list of ndarray of shape (n_steps, 2)
        flat_theta : array-like of shape (n_tasks, d), optional
            Already learnt flat parameters for the PCA initialisation (skips refitting).
        """
        validate_params(self, self._parameter_constraints, hints=self._hints)
        if not isinstance(mdp, MDP):
            raise ParameterError(f"mdp must be an MDP; got {type(mdp).__name__}.")
        k, beta, max_iter, inner = int(self.n_components), float(self.beta), int(self.max_iter), int(self.inner_steps)
        F = check_features(mdp, self.features)
        demos = check_task_demonstrations(mdp, demonstrations)
        n = len(demos)
        d = mdp.n_states * mdp.n_actions if F is None else F.shape[2]
        if k > min(n, d):
            raise ParameterError(f"n_components={k} must be at most min(n_tasks, d) = {min(n, d)}.")
        mu, pi_E = demonstration_stats(mdp, demos)

        self.flat_theta_ = None
        if isinstance(self.init, str) and self.init == "pca":
            if flat_theta is None:
                flat = GradIRL(F, beta=beta, max_iter=self.flat_max_iter).fit(mdp, demos)
                flat_theta = flat.theta_
            flat_theta = np.asarray(flat_theta, dtype=float)
            if flat_theta.shape != (n, d):
                raise ParameterError(f"flat_theta must have shape ({n}, {d}); got {flat_theta.shape}.")
            self.flat_theta_ = flat_theta
            _, _, Vt = np.linalg.svd(flat_theta, full_matrices=False)
            D = Vt[:k].copy()
        elif isinstance(self.init, str) and self.init == "random":
            rng = check_random_state(self.random_state)
            D = rng.standard_normal((k, d)) / np.sqrt(d)
            flat_theta = None
        else:  # an array (validate_params allowed nothing else)
            D = np.asarray(self.init, dtype=float).copy()
            if D.shape != (k, d):
                raise ParameterError(f"init array must have shape (n_components, d) = ({k}, {d}); got {D.shape}.")
        self.init_components_ = D.copy()
        Hc = (flat_theta @ D.T) if flat_theta is not None else np.zeros((n, k))
        V_warm = np.zeros((n, mdp.n_states))

        def fun_h(X, rows):
            loss, grad, V = gradirl_objective_unchecked(mdp, X @ D, mu[rows], pi_E[rows], features=F, beta=beta,
                                               init=V_warm[rows], return_values=True)
            V_warm[rows] = V
            return loss, grad @ D.T

        def fun_d(X, rows):
            Dx = X.reshape(k, d)
            loss, grad, V = gradirl_objective_unchecked(mdp, Hc @ Dx, mu, pi_E, features=F, beta=beta, init=V_warm,
                                               return_values=True)
            V_warm[:] = V
            return np.array([loss.sum()]), (Hc.T @ grad).reshape(1, -1)

        def total():
            loss, _, V = gradirl_objective_unchecked(mdp, Hc @ D, mu, pi_E, features=F, beta=beta, init=V_warm,
                                            return_values=True)
            V_warm[:] = V
            return float(loss.sum())

        history = [total()]
        h_steps = np.ones(n)
        d_step = np.ones(1)
        converged = False
        for _ in range(max_iter):
            Hc, _, _, h_steps = armijo_descent(fun_h, Hc, max_iter=inner, tol=0.0, steps=h_steps)
            h_steps = np.maximum(h_steps, 1e-8)
            Dflat, _, _, d_step = armijo_descent(fun_d, D.reshape(1, -1), max_iter=inner, tol=0.0, steps=d_step)
            d_step = np.maximum(d_step, 1e-10)
            D = Dflat.reshape(k, d)
            history.append(total())
            if history[-2] - history[-1] <= self.tol * max(abs(history[-2]), 1e-12):
                converged = True
                break
        if max_iter and not converged:
            warnings.warn(f"FactorialIRL stopped after max_iter={max_iter} alternations before the relative loss "
                          f"decrease fell below tol={self.tol:g}; raise max_iter.", ConvergenceWarning, stacklevel=2)
        self.components_ = D
        self.coefficients_ = Hc
        self.theta_ = Hc @ D
        self.rewards_ = features_to_rewards(mdp, self.theta_, F)
        self.loss_history_ = history
        self.n_iter_ = len(history) - 1  # alternations run (history also holds the initial loss)
        self._mdp_shape = (mdp.n_states, mdp.n_actions)
        return self

    def reward_features(self, mdp: MDP) -> np.ndarray:
        """The learnt dictionary as reward features (S, A, k), for :class:`GradIRL` on new tasks.

        Raises
        ------
        NotFittedError
            Before :meth:`fit`.
        ParameterError
            If ``mdp`` is not an MDP with the numbers of states and actions of the training MDP.
        """
        check_is_fitted(self)
        if not isinstance(mdp, MDP) or (mdp.n_states, mdp.n_actions) != tuple(self._mdp_shape):
            got = f"{mdp.n_states} states and {mdp.n_actions} actions" if isinstance(mdp, MDP) else type(mdp).__name__
            raise ParameterError(f"mdp must be an MDP with the {self._mdp_shape[0]} states and {self._mdp_shape[1]} "
                                 f"actions of the training MDP; got {got}.")
        return component_features(mdp, self.components_, check_features(mdp, self.features))

    def transform(self, mdp: MDP, demonstrations: Sequence[Sequence[Any]], *, max_iter: int = 100) -> np.ndarray:
        """Coefficients (n_new, k) of new tasks on the learnt dictionary (GradIRL on its features)."""
        est = GradIRL(self.reward_features(mdp), beta=self.beta, max_iter=max_iter).fit(mdp, demonstrations)
        return est.theta_
