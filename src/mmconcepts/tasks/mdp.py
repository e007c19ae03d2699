"""Tabular Markov decision processes, the grid world of section 4.3.2, and planning.

Thesis section 2.2.1 (MDPs, Bellman equations 2.25-2.28, value iteration; policy
iteration, exact and faster for the small worlds of chapter 4) and the
Boltzmann policy of eq. (2.32).

Shapes
------
* transitions ``P`` : (n_actions, n_states, n_states), ``P[a, s, s'] = P(s' | s, a)``;
* rewards ``r`` : (n_states, n_actions), or (n_tasks, n_states, n_actions) for many tasks
  on the same world at once (every planning function is vectorised over the leading
  task axis: one array operation per sweep for all tasks);
* values ``V`` : (..., n_states); action values ``Q`` : (..., n_states, n_actions);
* policies ``pi`` : (..., n_states, n_actions), rows summing to one.

Each solver and policy function checks its arguments; its ``*_unchecked`` twin
(``value_iteration_unchecked``, ...) does the same without the checks, for the learners'
inner loops (:mod:`mmconcepts.tasks.irl`), and is not part of the public API.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from .._validation import InstanceOf, Interval, check_random_state, validate_params
from ..errors import ConvergenceWarning, DataError, ParameterError

__all__ = [
    "MDP",
    "grid_world",
    "value_iteration",
    "policy_iteration",
    "soft_value_iteration",
    "policy_evaluation",
    "q_values",
    "greedy_policy",
    "boltzmann_policy",
    "uniform_policy",
    "policy_transitions",
    "sample_trajectories",
    "check_trajectories",
]

GRID_MOVES = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]])  # up, down, left, right (row, col)
GRID_ACTION_NAMES = ("up", "down", "left", "right")

# Parameters of the public functions, declared once and checked by one validate_params call at
# their start (the private solvers under them, called in the learners' inner loops, do not check).
# A stopping test "change < tol" can never be met with tol = 0, hence tol > 0 for the iterations.
_MDP_CONSTRAINTS: dict[str, list] = {"discount": [Interval("real", 0, 1, closed="left")]}
_TOL = [Interval("real", 0, None, closed="neither")]
_SWEEPS = [Interval("int", 1, None)]
_PARAMETER_CONSTRAINTS: dict[str, dict[str, list]] = {
    "grid_world": {"size": [Interval("int", 2, None)], "success_prob": [Interval("real", 0, 1)],
                   "random_includes_intended": ["boolean"]},
    "value_iteration": {"tol": _TOL, "max_iter": _SWEEPS, "init": ["array-like", None]},
    "policy_iteration": {"max_iter": _SWEEPS, "init": ["array-like", None]},
    "soft_value_iteration": {"tol": _TOL, "max_iter": _SWEEPS, "init": ["array-like", None]},
    "greedy_policy": {"tie_tol": [Interval("real", 0, None)]},
    "boltzmann_policy": {"beta": [Interval("real", 0, None)]},
    "sample_trajectories": {"n_trajectories": [Interval("int", 1, None)], "length": [Interval("int", 1, None)],
                            "start": ["array-like", None], "random_state": ["random_state"]},
}
_HINTS = {
    "max_iter": "Zero iterations leave no converged values to return; for one Bellman backup of given values "
                "use q_values(mdp, values, rewards).",
    "tol": "The loop stops when the largest change of the values falls below tol, which tol <= 0 never allows.",
}


def _check(function: str, mdp: Any, **params: Any) -> None:
    """Check ``mdp`` and the options of a public function against ``_PARAMETER_CONSTRAINTS``."""
    validate_params({"mdp": mdp, **params}, {"mdp": [InstanceOf(MDP, description="an MDP")],
                                              **_PARAMETER_CONSTRAINTS[function]}, owner=function, hints=_HINTS)


class MDP:
    """A finite MDP without reward: states, actions, transitions and a discount factor.

    The reward is kept apart (an argument of the planning functions) because inverse
    reinforcement learning compares many rewards on one world (thesis section 2.2.2).

    Parameters
    ----------
    transitions : array-like of shape (n_actions, n_states, n_states)
        ``transitions[a, s, s'] = P(s' | s, a)``; every row ``transitions[a, s]`` must be a
        probability distribution (nonnegative, sums to one within 1e-8).
    discount : float, default=0.9
        Discount factor gamma in [0, 1).
    rewards : array-like of shape (n_states, n_actions), optional
        A default reward, used when a planning function is called without one.

    Attributes
    ----------
    transitions : ndarray of shape (n_actions, n_states, n_states)
    discount : float
    rewards : ndarray of shape (n_states, n_actions) or None
    n_states, n_actions : int
    """

    def __init__(self, transitions: Any, *, discount: float = 0.9, rewards: Any = None) -> None:
        P = _float_array(transitions, "transitions", "probabilities P[a, s, s']")
        if P.ndim != 3 or P.shape[1] != P.shape[2] or P.shape[0] < 1 or P.shape[1] < 1:
            raise ParameterError(
                "transitions must have shape (n_actions, n_states, n_states) with "
                f"transitions[a, s, s'] = P(s'|s, a); got shape {P.shape}."
            )
        if not np.all(np.isfinite(P)):
            raise ParameterError("transitions contain NaN or infinite values; give probabilities in [0, 1].")
        if (P < 0).any():
            a, s, t = np.argwhere(P < 0)[0]
            raise ParameterError(f"transitions must be nonnegative; P[{a}, {s}, {t}] = {P[a, s, t]:g}.")
        sums = P.sum(axis=2)
        bad = np.abs(sums - 1.0) > 1e-8
        if bad.any():
            a, s = np.argwhere(bad)[0]
            raise ParameterError(
                f"every row transitions[a, s, :] must sum to one; {int(bad.sum())} rows do not, e.g. "
                f"transitions[{a}, {s}, :].sum() = {sums[a, s]:.6g}. Normalise the rows "
                "(P / P.sum(axis=2, keepdims=True)) or check the axis order (action, state, next state)."
            )
        validate_params({"discount": discount}, _MDP_CONSTRAINTS, owner="MDP",
                        hints={"discount": "Future rewards are worth gamma^t; gamma = 1 has no finite values."})
        self.transitions = P
        self.discount = float(discount)
        self.rewards = None if rewards is None else check_rewards(self, rewards, allow_batch=False)

    @property
    def n_states(self) -> int:
        return int(self.transitions.shape[1])

    @property
    def n_actions(self) -> int:
        return int(self.transitions.shape[0])

    def __repr__(self) -> str:
        return f"MDP(n_states={self.n_states}, n_actions={self.n_actions}, discount={self.discount})"


def _float_array(value: Any, name: str, what: str) -> np.ndarray:
    """``value`` as a float array, or a :class:`ParameterError` naming ``name`` (text, ragged rows, complex numbers)."""
    try:
        arr = np.asarray(value)
        if np.iscomplexobj(arr):
            raise TypeError("it holds complex numbers")
        return arr.astype(float, copy=False)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name} must be an array of {what} (real numbers, every row the same length); "
                             f"got {type(value).__name__} that is not: {exc}.") from None


def check_rewards(mdp: MDP, rewards: Any, *, allow_batch: bool = True) -> np.ndarray:
    """Return ``rewards`` as a float array of shape (S, A) or (n_tasks, S, A), or raise."""
    if rewards is None:
        if mdp.rewards is None:
            raise ParameterError("no rewards given and the MDP has no default reward; pass rewards=(n_states, n_actions).")
        return mdp.rewards
    r = _float_array(rewards, "rewards", "numbers")
    ok_shapes = r.shape[-2:] == (mdp.n_states, mdp.n_actions) and (r.ndim == 2 or (allow_batch and r.ndim == 3))
    if not ok_shapes:
        want = "(n_states, n_actions)" + (" or (n_tasks, n_states, n_actions)" if allow_batch else "")
        raise ParameterError(f"rewards must have shape {want} = ({mdp.n_states}, {mdp.n_actions}); got {r.shape}.")
    if not np.all(np.isfinite(r)):
        raise DataError("rewards contain NaN or infinite values.")
    big = float(np.abs(r).max()) if r.size else 0.0
    if big > _MAX_REWARD * (1.0 - mdp.discount):
        raise DataError(
            f"rewards up to {big:.3g} with discount {mdp.discount:g} give values up to {big / (1 - mdp.discount):.3g}, "
            f"beyond what float64 holds safely ({_MAX_REWARD:.0e}); rescale the rewards (the optimal policy does not "
            "change when every reward is multiplied by the same positive number)."
        )
    return r


#: Largest |value| a planning function is asked to compute: values are sums of S rewards over an
#: effective horizon 1 / (1 - gamma), and intermediate sums must not overflow float64.
_MAX_REWARD = 1e300


def grid_world(size: int = 10, *, success_prob: float = 0.7, discount: float = 0.9,
               random_includes_intended: bool = True) -> MDP:
    """The grid world of thesis section 4.3.2.

    States are the cells of a ``size`` x ``size`` grid, numbered row-major
    (``s = row * size + col``); the 4 actions are up, down, left, right. With probability
    ``success_prob`` the intended move happens; otherwise the agent makes a move drawn
    uniformly among the *feasible* moves (those that stay on the grid). When the intended
    move is not feasible (e.g. up on the top border) the move is drawn uniformly among the
    feasible ones.

    Parameters
    ----------
    size : int, default=10
    success_prob : float, default=0.7
    discount : float, default=0.9
    random_includes_intended : bool, default=True
        Whether the intended move is among the random ones (then it happens with
        probability ``success_prob + (1 - success_prob) / n_feasible``). The thesis does
        not say; ``False`` draws the random move among the other feasible moves.

    Returns
    -------
    MDP
        With ``size**2`` states, 4 actions and no default reward.
    """
    validate_params({"size": size, "success_prob": success_prob, "random_includes_intended": random_includes_intended},
                    _PARAMETER_CONSTRAINTS["grid_world"], owner="grid_world")
    n = int(size)
    p = float(success_prob)
    S = n * n
    P = np.zeros((4, S, S))
    for r in range(n):
        for c in range(n):
            s = r * n + c
            feasible = [k for k, (dr, dc) in enumerate(GRID_MOVES) if 0 <= r + dr < n and 0 <= c + dc < n]
            dest = {k: (r + GRID_MOVES[k, 0]) * n + (c + GRID_MOVES[k, 1]) for k in feasible}
            for a in range(4):
                if a not in feasible:
                    for k in feasible:
                        P[a, s, dest[k]] += 1.0 / len(feasible)
                    continue
                pool = feasible if random_includes_intended else [k for k in feasible if k != a]
                P[a, s, dest[a]] += p
                for k in pool:
                    P[a, s, dest[k]] += (1.0 - p) / len(pool)
    return MDP(P, discount=discount)


def _flat(mdp: MDP) -> np.ndarray:
    """Transitions as a (A * S, S) matrix, row ``a * S + s``."""
    A, S = mdp.n_actions, mdp.n_states
    return mdp.transitions.reshape(A * S, S)


def q_values(mdp: MDP, values: Any, rewards: Any = None) -> np.ndarray:
    """Action values ``Q(s, a) = r(s, a) + gamma sum_s' P(s'|s, a) V(s')`` (thesis eq. 2.26-2.28).

    Parameters
    ----------
    mdp : MDP
    values : array-like of shape (S,) or (n_tasks, S)
    rewards : array-like of shape (S, A) or (n_tasks, S, A), optional

    Returns
    -------
    Q : ndarray of shape (..., S, A)
    """
    r = check_rewards(mdp, rewards)
    V = np.asarray(values, dtype=float)
    A, S = mdp.n_actions, mdp.n_states
    if V.shape[-1] != S:
        raise ParameterError(f"values must have {S} states on the last axis; got shape {V.shape}.")
    EV = (_flat(mdp) @ V.reshape(-1, S).T).T.reshape(V.shape[:-1] + (A, S))  # (..., A, S)
    return r + mdp.discount * np.swapaxes(EV, -1, -2)


def _check_init(init: Any, batch: tuple[int, ...], S: int, discount: float) -> np.ndarray:
    """Starting values ``init`` broadcast to ``batch + (S,)``, finite and within the values' range, or raise."""
    V0 = _float_array(init, "init", "numbers")
    try:
        V0 = np.broadcast_to(V0, batch + (S,))
    except ValueError:
        raise ParameterError(f"init must have shape ({S},) or (n_tasks, {S}), one start shared by every task or one "
                             f"per task (the rewards have {batch[0] if batch else 1}); got {V0.shape}.") from None
    if not np.all(np.isfinite(V0)):
        raise DataError("init contains NaN or infinite values; give finite starting values (or init=None for zeros).")
    big = float(np.abs(V0).max()) if V0.size else 0.0
    if big > _MAX_REWARD:
        raise DataError(f"init holds values up to {big:.3g}, beyond what float64 holds safely ({_MAX_REWARD:.0e}); "
                        "values of rewards within the same bound never go there: give init=None or the values of a "
                        "previous solve.")
    return V0


def _batched_setup(mdp: MDP, rewards: Any, init: Any):
    """Shared start of the batched value and policy iterations.

    Returns ``(batch, V, Pf, RT)``: the batch shape of the rewards, the starting values
    (T, S), the flattened transitions and the rewards laid out as r[t, a*S + s].
    """
    r = check_rewards(mdp, rewards)
    A, S = mdp.n_actions, mdp.n_states
    batch = r.shape[:-2]
    R = r.reshape(-1, S, A)
    T = R.shape[0]
    V = np.zeros((T, S)) if init is None else _check_init(init, batch, S, mdp.discount).reshape(T, S).copy()
    RT = np.ascontiguousarray(R.transpose(0, 2, 1).reshape(T, A * S))
    return batch, V, _flat(mdp), RT


def value_iteration(mdp: MDP, rewards: Any = None, *, tol: float = 1e-10, max_iter: int = 10_000,
                    init: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Optimal values by value iteration (Picard iteration of eq. 2.27), batched over tasks.

    .. math:: V_{k+1}(s) = \\max_a \\left[ r(s, a) + \\gamma \\sum_{s'} P(s'|s, a) V_k(s') \\right]

    Each sweep is one matrix product ``(A S, S) @ (S, n_tasks)`` for all tasks together.
    The loop stops when the sup-norm change of every task is below ``tol``; the error
    of V is then below ``tol * gamma / (1 - gamma)``.

    Parameters
    ----------
    mdp : MDP
    rewards : array-like of shape (S, A) or (n_tasks, S, A), optional
        Default: ``mdp.rewards``.
    tol : float, default=1e-10
    max_iter : int, default=10000
    init : array-like of shape (S,) or (n_tasks, S), optional
        Starting values (warm start); default zeros.

    Returns
    -------
    V : ndarray of shape (..., S)
        Optimal values V*.
    Q : ndarray of shape (..., S, A)
        Optimal action values Q*, consistent with V (``V = Q.max(-1)``).

    Raises
    ------
    ParameterError
        If ``max_iter < 1`` (zero sweeps would leave no converged values to return; use
        :func:`q_values` for one Bellman backup), ``tol <= 0`` (never met), or ``init`` or
        ``rewards`` not numbers or of the wrong shape.
    DataError
        If ``init`` or ``rewards`` hold NaN or infinite values, or values beyond what float64
        holds safely (``|init| > 1e300``, rewards whose discounted sums would pass it).
    """
    _check("value_iteration", mdp, tol=tol, max_iter=max_iter, init=init)
    return value_iteration_unchecked(mdp, rewards, tol=tol, max_iter=max_iter, init=init)


def value_iteration_unchecked(mdp: MDP, rewards: Any, *, tol: float = 1e-10, max_iter: int = 10_000,
                              init: Any = None):
    """:func:`value_iteration` without the parameter checks (for the learners' inner loops)."""
    batch, V, Pf, RT = _batched_setup(mdp, rewards, init)
    T, A, S = V.shape[0], mdp.n_actions, mdp.n_states
    gamma = mdp.discount
    for _ in range(max_iter):
        Qf = RT + gamma * (V @ Pf.T)  # (T, A*S)
        V_new = Qf.reshape(T, A, S).max(axis=1)
        delta = np.abs(V_new - V).max() if T else 0.0
        V = V_new
        if delta < tol:
            break
    else:
        warnings.warn(f"value iteration stopped after max_iter={max_iter} sweeps with change {delta:.3g} > tol={tol:g}; "
                      "raise max_iter or tol.", ConvergenceWarning, stacklevel=3)
    Qf = RT + gamma * (V @ Pf.T)
    Q = Qf.reshape(T, A, S).transpose(0, 2, 1)
    V = Q.max(axis=2)
    return V.reshape(batch + (S,)), Q.reshape(batch + (S, A))


def policy_iteration(mdp: MDP, rewards: Any = None, *, max_iter: int = 1000,
                     init: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Optimal values by policy iteration (Howard), batched over tasks; exact up to round-off.

    Each iteration evaluates the current deterministic policies of all tasks exactly
    (Bellman equation 2.25: one batched S x S linear solve per task) and makes them greedy
    on the resulting action values (eq. 2.26); an action changes only where it improves
    its state's value by more than round-off, so ties cannot make the loop cycle. It ends
    when no policy changes: the values then satisfy the optimality equation (2.27)
    exactly, where value iteration stops at a tolerance. A few iterations suffice
    (usually 3-6 from scratch on the grid worlds here, 1-2 when warm-started from nearby
    rewards), against hundreds of value-iteration sweeps at discount 0.9 and tolerance 1e-10;
    each iteration costs ``n_tasks`` S x S solves, so this is the faster choice for the
    small state spaces of chapter 4 (S = 100) and value iteration for large S.

    Parameters
    ----------
    mdp : MDP
    rewards : array-like of shape (S, A) or (n_tasks, S, A), optional
        Default: ``mdp.rewards``.
    max_iter : int, default=1000
    init : array-like of shape (S,) or (n_tasks, S), optional
        Values whose greedy policy starts the iteration (warm start); default: the policy
        greedy on the immediate rewards.

    Returns
    -------
    V, Q : as :func:`value_iteration`.
    """
    _check("policy_iteration", mdp, max_iter=max_iter, init=init)
    return policy_iteration_unchecked(mdp, rewards, max_iter=max_iter, init=init)


def policy_iteration_unchecked(mdp: MDP, rewards: Any, *, max_iter: int = 1000, init: Any = None):
    """:func:`policy_iteration` without the parameter checks (for the learners' inner loops)."""
    batch, V, Pf, RT = _batched_setup(mdp, rewards, init)
    T, A, S = V.shape[0], mdp.n_actions, mdp.n_states
    gamma = mdp.discount
    P = mdp.transitions
    states = np.arange(S)
    RT3 = RT.reshape(T, A, S)
    Q = (RT + gamma * (V @ Pf.T)).reshape(T, A, S)
    act = Q.argmax(axis=1)  # (T, S)
    active = np.arange(T)  # tasks whose policy changed in the last improvement
    diag = (slice(None), states, states)
    for _ in range(max_iter):
        a = act[active]
        M = P[a, states[None, :], :]  # (n, S, S): row s is P(. | s, a[s])
        M *= -gamma
        M[diag] += 1.0  # I - gamma P_pi
        rpi = np.take_along_axis(RT3[active], a[:, None, :], axis=1)[:, 0, :]
        Va = np.linalg.solve(M, rpi[..., None])[..., 0]
        V[active] = Va
        Qa = (RT[active] + gamma * (Va @ Pf.T)).reshape(-1, A, S)
        Q[active] = Qa
        best = Qa.argmax(axis=1)
        q_cur = np.take_along_axis(Qa, a[:, None, :], axis=1)[:, 0, :]
        q_best = np.take_along_axis(Qa, best[:, None, :], axis=1)[:, 0, :]
        better = q_best > q_cur + 1e-12 * (1.0 + np.abs(q_cur))
        changed = better.any(axis=1)
        act[active[changed]] = np.where(better[changed], best[changed], a[changed])
        active = active[changed]
        if active.size == 0:
            break
    else:
        warnings.warn(f"policy iteration stopped after max_iter={max_iter} iterations with policies still changing.",
                      ConvergenceWarning, stacklevel=3)
    Q = Q.transpose(0, 2, 1)
    V = Q.max(axis=2)
    return V.reshape(batch + (S,)), Q.reshape(batch + (S, A))


def _logsumexp(Q: np.ndarray, axis: int) -> np.ndarray:
    """``log sum exp Q`` along ``axis``, shifted by the maximum (scipy's ``special.logsumexp`` to rounding).

    Parameters
    ----------
    Q : ndarray
        At least one entry along ``axis``; entries may be infinite.
    axis : int

    Returns
    -------
    ndarray
        ``Q``'s shape without ``axis``: ``m + log sum exp(Q - m)`` with m the maximum along ``axis``
        (0 where that maximum is infinite: -inf where every entry is -inf, inf where one is inf).
        The soft values' inner loop calls it at every sweep on small arrays, where scipy's general
        function costs several times the arithmetic (``benchmarks/mdp.py``).
    """
    m = Q.max(axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(Q - m).sum(axis=axis)) + np.squeeze(m, axis)


def soft_value_iteration(mdp: MDP, rewards: Any = None, *, tol: float = 1e-10, max_iter: int = 10_000,
                         init: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Soft (maximum causal entropy) values: ``V(s) = log sum_a exp Q(s, a)``, batched.

    Used by the maximum-entropy IRL baseline (Ziebart et al. 2010; not in the thesis).
    Returns ``(V, Q)`` with the shapes of :func:`value_iteration`; the parameters and the
    errors are those of :func:`value_iteration` (``max_iter >= 1``, ``tol > 0``).
    """
    _check("soft_value_iteration", mdp, tol=tol, max_iter=max_iter, init=init)
    return soft_value_iteration_unchecked(mdp, rewards, tol=tol, max_iter=max_iter, init=init)


def soft_value_iteration_unchecked(mdp: MDP, rewards: Any, *, tol: float = 1e-10, max_iter: int = 10_000,
                                   init: Any = None):
    """:func:`soft_value_iteration` without the parameter checks (for the learners' inner loops)."""
    batch, V, Pf, RT = _batched_setup(mdp, rewards, init)
    T, A, S = V.shape[0], mdp.n_actions, mdp.n_states
    for _ in range(max_iter):
        Q = (RT + mdp.discount * (V @ Pf.T)).reshape(T, A, S)
        V_new = _logsumexp(Q, axis=1)
        delta = np.abs(V_new - V).max() if T else 0.0
        V = V_new
        if delta < tol:
            break
    else:
        warnings.warn(f"soft value iteration stopped after max_iter={max_iter} sweeps with change {delta:.3g}.",
                      ConvergenceWarning, stacklevel=3)
    Q = (RT + mdp.discount * (V @ Pf.T)).reshape(T, A, S).transpose(0, 2, 1)
    V = _logsumexp(Q, axis=2)
    return V.reshape(batch + (S,)), Q.reshape(batch + (S, A))


def greedy_policy(Q: Any, *, tie_tol: float = 1e-8) -> np.ndarray:
    """Greedy policy on ``Q``: uniform over the actions within ``tie_tol`` of the best.

    Parameters
    ----------
    Q : array-like of shape (..., S, A)
    tie_tol : float, default=1e-8
        Actions whose value is within ``tie_tol * (1 + |max Q|)`` of the maximum are tied
        and share the probability (so a constant reward gives the uniform policy). Where
        the best value is +inf, the +inf actions share it; where every action is -inf,
        the policy is uniform.

    Returns
    -------
    pi : ndarray of shape (..., S, A)

    Raises
    ------
    DataError
        If Q holds NaN.
    """
    validate_params({"tie_tol": tie_tol}, _PARAMETER_CONSTRAINTS["greedy_policy"], owner="greedy_policy")
    return greedy_policy_unchecked(_check_q(Q), tie_tol=tie_tol)


def _check_q(Q: Any) -> np.ndarray:
    """``Q`` as a float array of shape (..., S, A) with S, A >= 1 and no NaN, or a DataError."""
    try:
        Q = np.asarray(Q, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"Q must be an array of action values of shape (..., n_states, n_actions) ({exc}).") from None
    if Q.ndim < 2 or Q.shape[-1] < 1 or Q.shape[-2] < 1:
        raise DataError(f"Q must have shape (..., n_states, n_actions) with at least one state and one action; "
                        f"got {Q.shape}.")
    if np.isnan(Q).any():
        raise DataError(f"Q holds NaN at {np.argwhere(np.isnan(Q))[0].tolist()}: the values are undefined there.")
    return Q


def greedy_policy_unchecked(Q: Any, *, tie_tol: float = 1e-8) -> np.ndarray:
    """:func:`greedy_policy` without the parameter check."""
    Q = np.asarray(Q, dtype=float)
    best = Q.max(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore"):  # inf - inf where the best value is infinite: replaced below
        threshold = best - tie_tol * (1.0 + np.abs(best))
    # an infinite best value: +inf actions win outright, and a state whose actions are all -inf is uniform
    threshold = np.where(np.isinf(best), best, threshold)
    mask = Q >= threshold
    return mask / mask.sum(axis=-1, keepdims=True)


def boltzmann_policy(Q: Any, beta: float = 1.0) -> np.ndarray:
    """Boltzmann policy of thesis eq. (2.32): ``pi(a|s) = exp(beta Q(s,a)) / sum_a' exp(beta Q(s,a'))``.

    Parameters
    ----------
    Q : array-like of shape (..., S, A)
    beta : float, default=1.0
        Inverse temperature (nonnegative); beta -> inf gives the greedy policy.
    """
    validate_params({"beta": beta}, _PARAMETER_CONSTRAINTS["boltzmann_policy"], owner="boltzmann_policy")
    Q = _check_q(Q)
    beta = float(beta)
    if beta == 0.0:  # 0 * inf is undefined; the limit is the uniform policy whatever Q
        return np.full(Q.shape, 1.0 / Q.shape[-1])
    if np.isinf(beta):  # the limit is the greedy policy, ties shared
        return greedy_policy_unchecked(Q, tie_tol=0.0)
    if np.isinf(Q).any():
        # limits: +inf actions share the state; -inf actions get 0; a state whose actions are all -inf is uniform
        best = Q.max(axis=-1, keepdims=True)
        finite_rows = np.isfinite(best)
        Qf = np.where(finite_rows, Q, 0.0)
        with np.errstate(over="ignore"):  # shifted by the row maximum: beta * Qf cannot overflow to +inf
            pi = boltzmann_policy_unchecked(Qf - Qf.max(axis=-1, keepdims=True), beta)
        return np.where(finite_rows, pi, greedy_policy_unchecked(Q, tie_tol=0.0))
    with np.errstate(over="ignore"):
        if not np.isfinite(beta * Q).all():  # beta Q overflows: shift first (-inf differences weigh 0, as they should)
            return boltzmann_policy_unchecked(Q - Q.max(axis=-1, keepdims=True), beta)
    return boltzmann_policy_unchecked(Q, beta)


def boltzmann_policy_unchecked(Q: Any, beta: float) -> np.ndarray:
    """:func:`boltzmann_policy` without the parameter check (finite Q and beta)."""
    with np.errstate(over="ignore"):
        Z = float(beta) * np.asarray(Q, dtype=float)
    Z = Z - Z.max(axis=-1, keepdims=True)
    E = np.exp(Z)
    return E / E.sum(axis=-1, keepdims=True)


def uniform_policy(mdp: MDP) -> np.ndarray:
    """The uniformly random policy, shape (S, A)."""
    return np.full((mdp.n_states, mdp.n_actions), 1.0 / mdp.n_actions)


def policy_transitions(mdp: MDP, policy: Any) -> np.ndarray:
    """State-to-state transitions under ``policy``: ``P_pi[s, s'] = sum_a pi(a|s) P(s'|s, a)``.

    ``policy`` (..., S, A) gives P_pi of shape (..., S, S).
    """
    pi = _check_policy(mdp, policy)
    return np.einsum("...sa,ast->...st", pi, mdp.transitions)


def _check_policy(mdp: MDP, policy: Any) -> np.ndarray:
    pi = np.asarray(policy, dtype=float)
    if pi.ndim < 2 or pi.shape[-2:] != (mdp.n_states, mdp.n_actions):
        raise ParameterError(f"policy must have shape (..., n_states, n_actions) = (..., {mdp.n_states}, "
                             f"{mdp.n_actions}); got {pi.shape}.")
    if not np.isfinite(pi).all():
        raise ParameterError("policy holds NaN or infinite probabilities; rows must be distributions over actions.")
    if (pi < -1e-12).any() or np.abs(pi.sum(axis=-1) - 1.0).max() > 1e-8:
        raise ParameterError("policy rows must be probability distributions over actions (nonnegative, summing to one).")
    return pi


def policy_evaluation(mdp: MDP, policy: Any, rewards: Any = None) -> np.ndarray:
    """Exact value of a policy: solve the Bellman equation (2.25), batched over tasks.

    .. math:: V^\\pi = (I - \\gamma P_\\pi)^{-1} r_\\pi, \\quad r_\\pi(s) = \\sum_a \\pi(a|s) r(s, a)

    Parameters
    ----------
    mdp : MDP
    policy : array-like of shape (S, A) or (n_tasks, S, A)
    rewards : array-like of shape (S, A) or (n_tasks, S, A), optional

    Returns
    -------
    V : ndarray of shape (..., S)
        Broadcast over the task axes of ``policy`` and ``rewards``.
    """
    r = check_rewards(mdp, rewards)
    pi = _check_policy(mdp, policy)
    Ppi = np.einsum("...sa,ast->...st", pi, mdp.transitions)
    rpi = (pi * r).sum(axis=-1)
    Ppi, rpi = np.broadcast_arrays(Ppi, rpi[..., None])
    M = np.eye(mdp.n_states) - mdp.discount * Ppi
    return np.linalg.solve(M, rpi[..., :1])[..., 0]


def check_trajectories(mdp: MDP, trajectories: Any, *, name: str = "trajectory") -> list[np.ndarray]:
    """Validate a list of trajectories, each an int array of (state, action) rows.

    Raises :class:`DataError` naming the trajectory and step with an unknown state or
    action, a wrong shape, or no step at all.
    """
    if isinstance(trajectories, np.ndarray) and trajectories.ndim == 2:
        trajectories = [trajectories]
    out = []
    for i, xi in enumerate(trajectories):
        arr = np.asarray(xi)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
            raise DataError(f"{name} {i} must be an array of shape (n_steps >= 1, 2) of (state, action) pairs; "
                            f"got shape {arr.shape}.")
        if not np.issubdtype(arr.dtype, np.integer):
            if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)):
                raise DataError(f"{name} {i} must hold integer state and action indices; got dtype {arr.dtype}.")
            arr = arr.astype(int)
        s, a = arr[:, 0], arr[:, 1]
        if (s < 0).any() or (s >= mdp.n_states).any():
            t = int(np.argmax((s < 0) | (s >= mdp.n_states)))
            raise DataError(f"{name} {i}, step {t}: unknown state {s[t]}; states are 0..{mdp.n_states - 1}. "
                            "Number states as the MDP does (grid cells row-major).")
        if (a < 0).any() or (a >= mdp.n_actions).any():
            t = int(np.argmax((a < 0) | (a >= mdp.n_actions)))
            raise DataError(f"{name} {i}, step {t}: unknown action {a[t]}; actions are 0..{mdp.n_actions - 1}.")
        out.append(arr.astype(np.int64))
    if not out:
        raise DataError(f"no {name} given; pass at least one array of (state, action) pairs.")
    return out


def sample_trajectories(mdp: MDP, policy: Any, n_trajectories: int, length: int, *, start: Any = None,
                        random_state: Any = None) -> list[np.ndarray]:
    """Sample trajectories ``[(s_t, a_t)]_{t < length}`` following ``policy`` (vectorised over trajectories).

    Parameters
    ----------
    mdp : MDP
    policy : array-like of shape (S, A)
    n_trajectories, length : int
    start : array-like of int of shape (n_trajectories,), optional
        Start states; default uniform over states.
    random_state : int, Generator or None

    Returns
    -------
    list of ndarray of shape (length, 2)
    """
    _check("sample_trajectories", mdp, n_trajectories=n_trajectories, length=length, start=start,
           random_state=random_state)
    rng = check_random_state(random_state)
    pi = _check_policy(mdp, policy)
    if pi.ndim != 2:
        raise ParameterError(f"policy must have shape (n_states, n_actions) here; got {pi.shape}.")
    n, L = int(n_trajectories), int(length)
    if start is None:
        s = rng.integers(mdp.n_states, size=n)
    else:
        given = np.asarray(start)
        if given.shape != (n,):
            raise ParameterError(f"start must have shape ({n},); got {given.shape}.")
        if given.size and (given.dtype.kind not in "iu" or given.min() < 0 or given.max() >= mdp.n_states):
            raise ParameterError(
                f"start must hold state indices (integers in [0, {mdp.n_states})); got {given.tolist()!r:.80}."
            )
        s = given.astype(np.int64)
    cpi = np.cumsum(pi, axis=1)
    cP = np.cumsum(mdp.transitions, axis=2)
    out = np.empty((n, L, 2), dtype=np.int64)
    for t in range(L):
        a = np.minimum((rng.random(n)[:, None] > cpi[s]).sum(axis=1), mdp.n_actions - 1)
        out[:, t, 0], out[:, t, 1] = s, a
        s = np.minimum((rng.random(n)[:, None] > cP[a, s]).sum(axis=1), mdp.n_states - 1)
    return list(out)
