"""Factorial inverse feedback control (thesis section 4.2, eq. 4.1-4.7).

An agent in Q = [0, 1]^2 descends a cost ``f(q) = beta . phi(q)`` on Gaussian radial
basis features ``phi`` (a 5 x 5 grid: F = 25):

.. math:: \\frac{\\partial q}{\\partial t} = -\\lambda J(q)^T \\beta        \\qquad (4.1)

with J the Jacobian of phi (F x 2). On trajectories sampled every ``delta t`` the thesis
approximates (4.1) by ``(q_{t+1} - q_t) / delta t = -lambda J(q_t)^T beta``; Brillinger's
regression (4.2)-(4.3) then estimates beta from one trajectory: ``Y = Phi beta`` with
``Y`` the stacked finite-difference velocities and ``Phi`` the stacked ``-lambda J(q_t)^T``. The dictionary learner (4.4)-(4.7) writes
``beta_i = D a_i`` and alternates regressions on the coefficients with gradient steps on D.

Orientation: the thesis' D is F x K with tasks as columns; here ``components_`` is
(K, F) = D^T and coefficients are rows (n_tasks, K), so ``beta = coefficients @ components_``.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import nnls
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import InstanceOf, Interval, Options, check_random_state, validate_params
from ..errors import DataError, ParameterError

__all__ = ["RBFFeatures", "control_trajectories", "brillinger_regression", "FactorialInverseControl",
           "relative_l2_error"]

_POSITIVE = [Interval("real", 0, None, closed="neither")]
# Parameters of the public functions, declared once and checked by one validate_params call at their start.
_PARAMETER_CONSTRAINTS: dict[str, dict[str, list]] = {
    "RBFFeatures": {"grid_size": [Interval("int", 2, None)], "sigma": [*_POSITIVE, None]},
    "control_trajectories": {"n_steps": [Interval("int", 1, None)], "lam": _POSITIVE, "dt": _POSITIVE,
                             "settle_tol": [Interval("real", 0, None)], "method": [Options("euler", "ode")],
                             "rtol": _POSITIVE, "atol": _POSITIVE},
    "brillinger_regression": {"lam": _POSITIVE, "dt": _POSITIVE, "regression": [Options("lstsq", "ridge", "nnls")],
                              "alpha": [Interval("real", 0, None)]},
}


class RBFFeatures(SaveLoadMixin):
    """Gaussian radial basis features on a regular grid of [0, 1]^2 (section 4.2.2).

    ``phi_f(q) = exp(-|q - mu_f|^2 / (2 sigma^2)) / (2 pi sigma)``.

    Parameters
    ----------
    grid_size : int, default=5
        Centres on a grid_size x grid_size grid (F = grid_size^2), >= 2.
    sigma : float, optional
        Width (> 0); default the grid spacing ``1 / (grid_size - 1)`` (the thesis does not give it).

    Attributes
    ----------
    sigma : float
        The width in use (the grid spacing when the parameter is None).
    centres : ndarray of shape (F, 2)
        The centres, row-major over the grid (x varies fastest).

    Notes
    -----
    A fixed feature map, not a learner: nothing is fitted from data, so it has no ``fit``
    and is never "not fitted". Like scikit-learn's kernels it is a parameter object of the
    learners that use it: ``get_params``/``set_params`` give and change its constructor
    parameters (``get_params()["sigma"]`` is the parameter, None by default, while the
    attribute ``sigma`` is the width in use), so that ``sklearn.base.clone`` of a
    :class:`FactorialInverseControl` clones it and ``save``/``load`` store it by its
    parameters.
    """

    def __init__(self, grid_size: int = 5, sigma: float | None = None) -> None:
        self._setup(grid_size, sigma)

    def _setup(self, grid_size: int, sigma: float | None) -> None:
        """Check and store the parameters, then compute the width and the centres."""
        validate_params({"grid_size": grid_size, "sigma": sigma}, _PARAMETER_CONSTRAINTS["RBFFeatures"],
                        owner="RBFFeatures")
        self.grid_size = grid_size
        self._sigma_param = sigma
        g = int(grid_size)
        self.sigma = 1.0 / (g - 1) if sigma is None else float(sigma)
        u = np.linspace(0.0, 1.0, g)
        self.centres = np.array([(x, y) for y in u for x in u])

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor parameters ``{"grid_size": ..., "sigma": ...}`` (``deep`` has no effect)."""
        return {"grid_size": self.grid_size, "sigma": self._sigma_param}

    def set_params(self, **params: Any) -> "RBFFeatures":
        """Change constructor parameters; the centres and the width are recomputed (and checked)."""
        unknown = set(params) - {"grid_size", "sigma"}
        if unknown:
            raise ParameterError(f"RBFFeatures has no parameter {sorted(unknown)[0]!r}; its parameters are "
                                 "'grid_size' and 'sigma'.")
        self._setup(**{**self.get_params(), **params})
        return self

    def __repr__(self) -> str:
        return f"RBFFeatures(grid_size={self.grid_size!r}, sigma={self._sigma_param!r})"

    def _is_fitted_for_save(self) -> bool:
        return True  # nothing to fit: the parameters are the whole model

    @property
    def n_features(self) -> int:
        return self.centres.shape[0]

    def value(self, q: Any) -> np.ndarray:
        """phi(q): (..., 2) -> (..., F)."""
        d = np.asarray(q, dtype=float)[..., None, :] - self.centres
        return np.exp(-(d**2).sum(-1) / (2 * self.sigma**2)) / (2 * np.pi * self.sigma)

    def jacobian(self, q: Any) -> np.ndarray:
        """J(q): (..., 2) -> (..., F, 2), rows are gradients of the features."""
        d = np.asarray(q, dtype=float)[..., None, :] - self.centres
        return -(d / self.sigma**2) * self.value(q)[..., None]

    def cost(self, beta: Any, q: Any) -> np.ndarray:
        """f(q) = beta . phi(q)."""
        return self.value(q) @ np.asarray(beta, dtype=float)


def control_trajectories(features: RBFFeatures, beta: Any, start: Any, *, n_steps: int = 100, lam: float = 1.0,
                         dt: float = 0.01, settle_tol: float = 0.0, method: str = "euler",
                         rtol: float = 1e-8, atol: float = 1e-10) -> np.ndarray:
    """Trajectories of eq. (4.1) observed every ``dt``, batched: ``beta`` (n, F), ``start`` (n, 2) -> (n, n_steps + 1, 2).

    .. math:: \\frac{\\partial q}{\\partial t} = -\\lambda J(q)^T \\beta        \\qquad (4.1)

    Parameters
    ----------
    features : RBFFeatures
    beta : array-like of shape (n, F) or (F,)
    start : array-like of shape (n, 2) or (2,)
    n_steps : int
        Observations after the start point, at times ``dt, 2 dt, ..., n_steps dt``.
    lam, dt : float
        Gain and sampling interval.
    settle_tol : float, default=0.0
        ``method='euler'`` only: with ``settle_tol > 0``, a trajectory whose step is shorter
        than ``settle_tol`` stays put from then on (it has settled); arrays keep the full
        length so that trajectories compare.
    method : {'euler', 'ode'}, default='euler'
        'euler': the discrete approximation of section 4.2.1,
        ``q_{t+1} = q_t - lambda dt J(q_t)^T beta`` (the model the regression (4.2) inverts
        exactly). 'ode': the continuous-time agent of eq. (4.1), integrated by
        :func:`scipy.integrate.solve_ivp` and sampled every ``dt``; the regression (4.2) is
        then an approximation, as in the thesis. The solver is LSODA (it switches to a stiff
        method when needed: badly estimated costs can have huge weights, hence stiff
        dynamics) with a banded Jacobian, since trajectories are independent 2-D systems.
    rtol, atol : float
        Integration tolerances of ``method='ode'``.

    Returns
    -------
    trajectories : ndarray of shape (n, n_steps + 1, 2)
    """
    validate_params(dict(n_steps=n_steps, lam=lam, dt=dt, settle_tol=settle_tol, method=method, rtol=rtol, atol=atol),
                    _PARAMETER_CONSTRAINTS["control_trajectories"], owner="control_trajectories")
    B = np.atleast_2d(np.asarray(beta, dtype=float))
    q = np.atleast_2d(np.asarray(start, dtype=float)).copy()
    if B.ndim != 2 or B.shape[1] != features.n_features or q.shape != (B.shape[0], 2):
        raise ParameterError(f"beta must be (n, {features.n_features}) and start (n, 2); got {B.shape} and {q.shape}.")
    if not (np.isfinite(B).all() and np.isfinite(q).all()):
        raise DataError("beta and start must be finite; they hold NaN or infinite values.")
    T = int(n_steps)
    if method == "ode":
        if settle_tol > 0:
            raise ParameterError("settle_tol applies to method='euler' only; pass settle_tol=0 with method='ode'.")
        n = q.shape[0]
        calls = [0]
        max_calls = max(_MAX_RHS_CALLS, 50 * (T + 1))

        def rhs(_t, y):
            calls[0] += 1
            if calls[0] > max_calls:
                raise _TooStiff
            return (-lam * np.einsum("nfk,nf->nk", features.jacobian(y.reshape(n, 2)), B)).reshape(-1)

        times = dt * np.arange(T + 1)
        try:
            sol = solve_ivp(rhs, (0.0, times[-1]), q.reshape(-1), method="LSODA", t_eval=times, rtol=rtol, atol=atol,
                            lband=1, uband=1)  # (x, y) pairs: a block-diagonal, hence banded, Jacobian
        except _TooStiff:
            raise DataError(
                f"integrating eq. (4.1) needed more than {max_calls} evaluations of the dynamics: the costs "
                f"(|beta| up to {np.abs(B).max():.3g}, lam={lam:g}) make them too stiff. Use smaller costs, or "
                "method='euler'."
            ) from None
        if not sol.success:  # pragma: no cover - smooth RBF dynamics do not fail
            raise ParameterError(f"integrating eq. (4.1) failed: {sol.message}")
        return sol.y.T.reshape(T + 1, n, 2).transpose(1, 0, 2)
    out = np.empty((q.shape[0], T + 1, 2))
    out[:, 0] = q
    moving = np.ones(q.shape[0], dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):
        for t in range(T):
            step = -lam * dt * np.einsum("nfk,nf->nk", features.jacobian(q), B)
            if settle_tol > 0:
                moving &= np.linalg.norm(step, axis=1) >= settle_tol
                step[~moving] = 0.0
            q = q + step
            out[:, t + 1] = q
    if not np.isfinite(out).all():
        raise DataError(f"the Euler steps of eq. (4.1) overflowed (|beta| up to {np.abs(B).max():.3g}, lam={lam:g}, "
                        f"dt={dt:g}); use smaller costs or a smaller dt.")
    return out


class _TooStiff(Exception):
    """Raised inside the ODE right-hand side when the integration takes too many evaluations."""


#: Evaluations of the dynamics allowed per call of control_trajectories(method='ode') (at least 50 per
#: sampled step): LSODA needs a few per step even for stiff costs (|beta| = 1e9); tens of thousands
#: mean costs so large (|beta| ~ 1e300) that the integration would run for hours.
_MAX_RHS_CALLS = 20_000


def _design(features: RBFFeatures, traj: np.ndarray, lam: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Y (2(T-1),) and Phi (2(T-1), F) of eq. (4.2) for one trajectory (T, 2)."""
    traj = np.asarray(traj, dtype=float)
    if traj.ndim != 2 or traj.shape[1] != 2 or traj.shape[0] < 2:
        raise DataError(f"a trajectory must be an array of shape (n_points >= 2, 2); got {traj.shape}.")
    if not np.all(np.isfinite(traj)):
        raise DataError("a trajectory contains NaN or infinite values.")
    Y = (np.diff(traj, axis=0) / dt).reshape(-1)
    Phi = (-lam * features.jacobian(traj[:-1])).transpose(0, 2, 1).reshape(-1, features.n_features)
    return Y, Phi


def _regress(Phi: np.ndarray, Y: np.ndarray, regression: str, alpha: float) -> np.ndarray:
    """Coefficients of ``Y ~ Phi b``; ``regression`` was checked by the caller."""
    if regression == "lstsq":  # eq. (4.3); minimum-norm solution when Phi^T Phi is singular
        return np.linalg.lstsq(Phi, Y, rcond=None)[0]
    if regression == "ridge":
        try:
            return np.linalg.solve(Phi.T @ Phi + alpha * np.eye(Phi.shape[1]), Phi.T @ Y)
        except np.linalg.LinAlgError:  # alpha = 0 and too few independent steps: the minimum-norm solution
            return np.linalg.lstsq(Phi, Y, rcond=None)[0]
    return nnls(Phi, Y)[0]  # "nnls"


def brillinger_regression(features: RBFFeatures, trajectories: Any, *, lam: float = 1.0, dt: float = 0.01,
                          regression: str = "lstsq", alpha: float = 1e-6) -> np.ndarray:
    """The flat imitator: beta from one demonstration by eq. (4.2)-(4.3).

    Parameters
    ----------
    features : RBFFeatures
    trajectories : ndarray of shape (T, 2) or list of them (same task)
    regression : {'lstsq', 'ridge', 'nnls'}
    alpha : float
        Ridge penalty.

    Returns
    -------
    beta : ndarray of shape (F,)
    """
    validate_params(dict(lam=lam, dt=dt, regression=regression, alpha=alpha),
                    _PARAMETER_CONSTRAINTS["brillinger_regression"], owner="brillinger_regression")
    try:
        trajs = [trajectories] if np.ndim(trajectories) == 2 else list(trajectories)
    except (TypeError, ValueError):  # ragged nesting or not a sequence
        trajs = list(trajectories) if isinstance(trajectories, Sequence) else [trajectories]
    if not trajs:
        raise DataError("no trajectory given; pass an array of shape (T, 2) or a list of them.")
    parts = [_design(features, t, lam, dt) for t in trajs]
    return _regress(np.concatenate([p[1] for p in parts]), np.concatenate([p[0] for p in parts]), regression, alpha)


def relative_l2_error(reference: Any, other: Any) -> np.ndarray:
    """``|q_ref - q|_2 / |q_ref|_2`` per trajectory, for arrays (n, T, 2) or (T, 2)."""
    a, b = np.asarray(reference, dtype=float), np.asarray(other, dtype=float)
    axes = tuple(range(a.ndim - 2, a.ndim))
    return np.sqrt(((a - b) ** 2).sum(axes) / (a**2).sum(axes))


class FactorialInverseControl(SaveLoadMixin, BaseEstimator):
    """Dictionary of primitive costs from mixed demonstrations (eq. 4.4-4.7).

    Parameters
    ----------
    n_components : int, default=6
        Dictionary size K, >= 1.
    features : RBFFeatures, optional
        Default: the 5 x 5 grid.
    lam, dt : float
        The agent's gain and time step of eq. (4.1), both > 0.
    regression : {'lstsq', 'ridge', 'nnls'}, default='lstsq'
        Regression of the coefficients (eq. 4.6 is 'lstsq').
    alpha : float, default=1e-6
        Ridge penalty, >= 0.
    max_iter : int, default=100
        Alternations (unsupervised) or gradient steps on D (supervised), >= 1.
    d_steps : int, default=5
        Gradient steps on D per alternation (exact line search: the loss is quadratic in D), >= 1.
    d_solver : {'steepest', 'cg'}, default='steepest'
        The gradient descent on D of eq. (4.7). 'steepest': steepest descent with exact
        line search (the loss is quadratic in D). 'cg': linear conjugate gradient on the
        same quadratic, restarted whenever the coefficients change; it reaches the minimiser
        in at most K F steps in exact arithmetic, where steepest descent crawls along the
        ill-conditioned directions (one demonstration excites few features).
    tol : float, default=1e-8
        Stop when a step lowers the loss (4.5) by at most ``tol`` times its value (>= 0).
    random_state : int, Generator or None
        Random initial dictionary (both learners start from it).

    Attributes
    ----------
    components_ : ndarray of shape (K, F)
        The dictionary D^T.
    coefficients_ : ndarray of shape (n_demos, K)
    init_components_ : ndarray of shape (K, F)
        The random initial dictionary.
    loss_history_ : list of float
        Loss (4.5) after each alternation.
    n_iter_ : int
        Length of ``loss_history_``.

    Notes
    -----
    A scikit-learn estimator (``get_params``, ``set_params``, ``clone``) whose input is a
    list of trajectories of different lengths, not a 2-D array. ``save`` and ``load`` keep
    the parameters (the :class:`RBFFeatures` by its parameters; a ``random_state``
    generator is saved as None) and the learnt arrays above, so a loaded model's
    :meth:`transform` gives the coefficients the saved one gave.
    """

    _parameter_constraints: dict[str, list] = {
        "n_components": [Interval("int", 1, None)],
        "features": [None, InstanceOf(RBFFeatures)],
        "lam": _POSITIVE,
        "dt": _POSITIVE,
        "regression": [Options("lstsq", "ridge", "nnls")],
        "alpha": [Interval("real", 0, None)],
        "max_iter": [Interval("int", 1, None)],
        "d_steps": [Interval("int", 1, None)],
        "d_solver": [Options("steepest", "cg")],
        "tol": [Interval("real", 0, None)],
        "random_state": ["random_state"],
    }
    _hints = {"d_solver": "'steepest' is steepest descent with exact line search, 'cg' linear conjugate gradient.",
              "tol": "tol = 0 runs max_iter steps."}

    def __init__(self, n_components: int = 6, *, features: RBFFeatures | None = None, lam: float = 1.0,
                 dt: float = 0.01, regression: str = "lstsq", alpha: float = 1e-6, max_iter: int = 100,
                 d_steps: int = 5, d_solver: str = "steepest", tol: float = 1e-8,
                 random_state: Any = None) -> None:
        self.n_components = n_components
        self.features = features
        self.lam = lam
        self.dt = dt
        self.regression = regression
        self.alpha = alpha
        self.max_iter = max_iter
        self.d_steps = d_steps
        self.d_solver = d_solver
        self.tol = tol
        self.random_state = random_state

    def _feats(self) -> RBFFeatures:
        return self.features if self.features is not None else RBFFeatures()

    def _designs(self, trajectories):
        if isinstance(trajectories, np.ndarray) and trajectories.ndim == 2:
            raise DataError("trajectories must be a list (or (n, T, 2) array) of demonstrations, one per task.")
        f = self._feats()
        designs = [_design(f, t, self.lam, self.dt) for t in trajectories]
        if not designs:
            raise DataError("no demonstration given; pass a list of trajectories of shape (T >= 2, 2).")
        return designs

    @staticmethod
    def _loss(designs, D, A):
        return float(sum(((Y - Phi @ (D.T @ a)) ** 2).sum() for (Y, Phi), a in zip(designs, A)))

    def _d_steps(self, designs, D, A, n_steps):
        for _ in range(n_steps):
            # eq. (4.7) in row orientation: grad wrt D^T = -2 sum_i a_i (Phi_i^T r_i)^T
            G = np.zeros_like(D)
            for (Y, Phi), a in zip(designs, A):
                G -= 2.0 * np.outer(a, Phi.T @ (Y - Phi @ (D.T @ a)))
            denom = 2.0 * sum(((Phi @ (G.T @ a)) ** 2).sum() for (Y, Phi), a in zip(designs, A))
            if denom <= 0 or not np.any(G):
                break
            D = D - ((G**2).sum() / denom) * G  # exact line search on the quadratic loss
        return D

    @staticmethod
    def _cg_steps(designs, D, A, n_steps, tol=0.0, history=None):
        """``n_steps`` linear conjugate-gradient steps on the quadratic (4.5) in D, from D (A fixed).

        Stops early when the loss decreases by at most ``tol`` times its value; appends the loss
        after each step to ``history`` when given.
        """
        # (4.5) = sum_i |Y_i - Phi_i D^T a_i|^2; with G_i = Phi_i^T Phi_i and c_i = Phi_i^T Y_i its
        # gradient (4.7) is -2 (b - H(D)) with b = sum_i a_i c_i^T and H(P) = sum_i a_i (G_i P^T a_i)^T,
        # and its value is y - <b, D> - <b - H(D), D> with y = sum_i |Y_i|^2.
        Gs = np.array([Phi.T @ Phi for _, Phi in designs])
        b = A.T @ np.array([Phi.T @ Y for Y, Phi in designs])
        y = float(sum((Y**2).sum() for Y, _ in designs))

        def hess(P):
            return A.T @ np.einsum("nfg,ng->nf", Gs, A @ P)

        r = b - hess(D)
        p, rr = r.copy(), float((r**2).sum())
        loss = y - float((b * D).sum()) - float((r * D).sum())
        for _ in range(n_steps):
            Hp = hess(p)
            pHp = float((p * Hp).sum())
            if rr == 0.0 or pHp <= 0.0:
                break
            step = rr / pHp
            D = D + step * p
            r = r - step * Hp
            rr_new = float((r**2).sum())
            p = r + (rr_new / rr) * p
            rr = rr_new
            new_loss = max(y - float((b * D).sum()) - float((r * D).sum()), 0.0)
            if history is not None:
                history.append(new_loss)
            done = loss - new_loss <= tol * loss
            loss = new_loss
            if done:
                break
        return D

    def _coefs(self, designs, D):
        return np.array([_regress(Phi @ D.T, Y, self.regression, self.alpha) for Y, Phi in designs])

    def fit(self, trajectories: Sequence[Any], coefficients: Any = None) -> "FactorialInverseControl":
        """Learn the dictionary from one demonstration per task.

        Parameters
        ----------
        trajectories : list of ndarray of shape (T_i, 2)
        coefficients : array-like of shape (n_demos, K), optional
            Known mixing coefficients (the supervised "dictionary from coefficients"
            learner): then only D is learnt, by gradient steps (4.7).
        """
        validate_params(self, self._parameter_constraints, hints=self._hints)
        K, max_iter = int(self.n_components), int(self.max_iter)
        designs = self._designs(trajectories)
        F = self._feats().n_features
        d_step = self._d_steps if self.d_solver == "steepest" else self._cg_steps
        rng = check_random_state(self.random_state)
        D = rng.standard_normal((K, F))
        self.init_components_ = D.copy()
        history: list[float] = []
        if coefficients is not None:
            A = np.asarray(coefficients, dtype=float)
            if A.shape != (len(designs), K):
                raise ParameterError(f"coefficients must have shape (n_demos, n_components) = ({len(designs)}, {K}); "
                                     f"got {A.shape}.")
            if self.d_solver == "cg":  # one conjugate-gradient run: A is fixed, so conjugacy holds throughout
                D = self._cg_steps(designs, D, A, max_iter, self.tol, history)
            else:
                for _ in range(max_iter):
                    D = self._d_steps(designs, D, A, 1)
                    history.append(self._loss(designs, D, A))
                    if len(history) > 1 and history[-2] - history[-1] <= self.tol * history[-2]:
                        break
        else:
            A = self._coefs(designs, D)
            for _ in range(max_iter):
                D = d_step(designs, D, A, self.d_steps)
                A = self._coefs(designs, D)
                history.append(self._loss(designs, D, A))
                if len(history) > 1 and history[-2] - history[-1] <= self.tol * history[-2]:
                    break
        self.components_, self.coefficients_, self.loss_history_ = D, A, history
        self.n_iter_ = len(history)
        return self

    def transform(self, trajectories: Sequence[Any]) -> np.ndarray:
        """Coefficients (n, K) of demonstrations on the learnt dictionary (eq. 4.6).

        Raises
        ------
        NotFittedError
            Before :meth:`fit`.
        """
        check_is_fitted(self)
        return self._coefs(self._designs(trajectories), self.components_)
