"""The :class:`NMF` estimator: scikit-learn's contract over :func:`beta_nmf`."""

from __future__ import annotations

import warnings
from typing import Any, Literal, cast

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, ClassNamePrefixFeaturesOutMixin, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import Interval, check_random_state, validate_params
from ..errors import ConvergenceWarning, DataError, ParameterError
from ._beta import EPSILON, check_beta_zeros, mm_exponent, resolve_beta
from ._coefficients import solve_coefficients, solves_coefficients
from ._init import initialize
from ._problem import Problem
from ._data import is_dask_array, validate_data
from ._solver import beta_nmf
from ._updates import (
    BETA_NMF_CONSTRAINTS,
    NMFResult,
    check_fit_in_range,
    check_objective_range,
    constant_coefficients,
    data_scale,
    in_units_of_X,
    mu_update,
    resolve_penalties,
    scale_penalties,
)

__all__ = ["NMF", "resolve_features"]


def resolve_features(features: Any, n_features: int, name: str = "features") -> np.ndarray:
    """Turn indices, a slice or a boolean mask over ``n_features`` columns into sorted-as-given indices."""
    if features is None:
        return np.arange(n_features)
    if isinstance(features, slice):
        idx = np.arange(n_features)[features]
    else:
        arr = np.asarray(features)
        if arr.dtype == bool:
            if arr.ndim != 1 or arr.shape[0] != n_features:
                raise ParameterError(
                    f"{name} as a boolean mask must have length n_features={n_features}; got shape {arr.shape}."
                )
            idx = np.flatnonzero(arr)
        elif arr.ndim == 1 and (arr.size == 0 or np.issubdtype(arr.dtype, np.integer)):
            idx = arr.astype(np.intp)
            if idx.size and (idx.min() < -n_features or idx.max() >= n_features):
                raise ParameterError(
                    f"{name} holds indices out of range for {n_features} features: "
                    f"min {idx.min()}, max {idx.max()}."
                )
            idx = np.where(idx < 0, idx + n_features, idx)
            if idx.size and np.bincount(idx, minlength=n_features).max() > 1:  # linear, where a sort is not
                raise ParameterError(f"{name} holds repeated indices; give each feature once.")
        else:
            raise ParameterError(
                f"{name} must be None, a slice, integer indices or a boolean mask; got {arr.dtype} of shape {arr.shape}."
            )
    if idx.size == 0:
        raise ParameterError(f"{name} selects no feature; select at least one.")
    return idx


def _live_features(H: np.ndarray) -> np.ndarray | None:
    """The columns of H where some atom is nonzero, or None when that is all of them (or none).

    The other columns carry no information on the coefficients: their loss D(x | 0) does not
    depend on them (and is infinite for beta <= 1 when x > 0, which would void the stopping
    rule). Leaving them out leaves the minimiser unchanged.
    """
    live = H.sum(axis=0) > 0
    return None if live.all() or not live.any() else np.flatnonzero(live)


def _live_columns(H: np.ndarray, X: Any, mask: Any):
    """(H, X, mask) restricted to :func:`_live_features`."""
    cols = _live_features(H)
    if cols is None:
        return H, X, mask
    return H[:, cols], X[:, cols], None if mask is None else mask[:, cols]


def _broadcast_row(a: np.ndarray) -> np.ndarray | None:
    """The row that ``a`` repeats when it is a broadcast view of one row (stride 0 along rows), else None."""
    if a.ndim == 2 and a.shape[0] > 1 and a.strides[0] == 0:
        return np.asarray(a[0])
    return None


def _touched_columns(X: Any, mask: Any, beta: float, gamma: float, pen_H: Any,
                     stats: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """The columns of a sparse batch that have a nonzero, when partial_fit may update only those.

    Under the I-divergence (beta = 1, gamma = 1) without a mask or a penalty on H, a column j
    that is all zero in the batch has a zero numerator, so every iteration sets it to
    rho A_j / B, with the pooled denominator B one row broadcast over the columns: it moves only
    through B, and its dictionary entries enter the coefficients' update only through their sum.
    partial_fit then iterates on the touched columns plus that sum, and sets the others once at
    the end (the same numbers up to the rounding of the sums). None when this does not apply, or
    when most columns are touched (no gain).
    """
    if mask is not None or beta != 1.0 or gamma != 1.0 or pen_H.l1 or pen_H.l2:
        return None
    if not sp.issparse(X) or X.format != "csr" or _broadcast_row(stats[1]) is None:
        return None
    m = X.shape[1]
    touched = np.flatnonzero(np.bincount(X.indices, minlength=m))
    return touched if touched.size <= m // 2 else None


def _online_iterations(problem: Problem, W: np.ndarray, Ht: np.ndarray, stats: tuple[np.ndarray, np.ndarray] | None,
                       rho: float, beta: float, gamma: float, pen_W: Any, pen_H: Any, max_iter: int):
    """partial_fit's alternating updates on one batch; returns W, Ht and the pooled statistics A, B."""
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    for _ in range(max_iter):
        W = mu_update(problem.sides[0], W, Ht, beta, gamma, pen_W)
        num, den = problem.sides[1].numerator_denominator(Ht, W, beta)
        den = pen_H.add_to(den, Ht)
        eps = Ht.dtype.type(EPSILON)
        # in place: no fresh m x k block (page faults) per iteration; the dense KL numerator is a transposed
        # view of the side's scratch buffer, which this batch's problem no longer needs after the loop
        if gamma == 1.0 and num.flags.writeable and (num.flags.owndata or num.flags.f_contiguous) and num.dtype == Ht.dtype:
            A = np.multiply(num, Ht, out=num)
        else:
            A = (Ht ** (1.0 / gamma) if gamma != 1.0 else Ht) * num
        if stats is not None:
            A += stats[0] if rho == 1.0 else rho * stats[0]  # x * 1.0 == x: the same numbers, one pass less
        # The KL denominator without a mask is one row broadcast over the features (sum of W's
        # columns), and so is its pooled statistic: kept as a row, it costs k operations, not m x k.
        row, old_row = _broadcast_row(den), None if stats is None else _broadcast_row(stats[1])
        if row is not None and (stats is None or old_row is not None):
            b = np.where(row == 0, eps, row)
            if stats is not None and old_row is not None:
                b = b + (old_row if rho == 1.0 else rho * old_row)
            B = np.broadcast_to(b, den.shape)
        else:
            B = np.where(den == 0, eps, den)
            if stats is not None:
                B += stats[1] if rho == 1.0 else rho * stats[1]
        if Ht.flags.owndata and Ht.flags.writeable and Ht.dtype == np.result_type(A, B):
            np.divide(A, B, out=Ht)  # the old dictionary is no longer needed: its buffer takes the new one
        else:
            Ht = A / B
        if gamma != 1.0:
            Ht **= gamma
    return W, Ht, A, B


class NMF(SaveLoadMixin, ClassNamePrefixFeaturesOutMixin, TransformerMixin, BaseEstimator):
    """Beta-divergence nonnegative matrix factorization, X ~ W @ H (thesis section 2.1).

    X is (n_samples, n_features); the dictionary ``components_`` (H) is
    (n_components, n_features), one atom per row; :meth:`transform` returns the
    coefficients W (n_samples, n_components). The thesis writes V ~ W H with examples
    as columns: its W is our ``components_.T``.

    .. math:: \\min_{W, H \\ge 0} D_\\beta(X | WH) + \\text{penalties}
              \\quad \\text{(thesis eq. 2.2-2.3)}

    Beyond scikit-learn's NMF: any real beta with the maximization-minimization exponent
    of thesis Table 2.2 (or the heuristic update, eq. 2.17), a projected-gradient solver
    (eq. 2.9-2.13), Hoyer sparseness constraints (eq. 2.20), masks of observed cells in
    :meth:`fit` and :meth:`transform`, and transforms and reconstructions restricted to a
    subset of features (e.g. from motion features only, to reconstruct labels).

    The coefficients of :meth:`transform` minimise the objective in W with the dictionary
    fixed, one problem per row. For 1 <= beta <= 2 it is convex: the multiplicative updates
    (``transform_max_iter`` of them, or fewer by ``tol``) start a projected Newton method that
    solves it to convergence (Bertsekas 1982), and :meth:`fit_transform` returns the fit's
    last W solved so for the final dictionary, so that ``fit_transform(X)`` is
    ``fit(X).transform(X)``. Multiplicative updates alone stop percents away from that
    minimum, more where coefficients are zero at it. For other betas, where the problem in W
    need not be convex, and under ``sparseness_W``, the coefficients are the multiplicative
    updates' (or the Hoyer steps'), as in the thesis.

    A ``dask.array`` X of row chunks (dense or scipy.sparse chunks) is fitted by the
    distributed solver (see :func:`~mmconcepts.nmf.beta_nmf`): :meth:`fit_transform` and
    :meth:`transform` return a dask array with X's row chunks (W stays in the cluster),
    ``components_`` is a numpy array, and the iterates equal those of the in-memory fit from the
    same start. ``solver='pg'``, the Hoyer constraints and :meth:`partial_fit` take in-memory
    data only.

    Parameters
    ----------
    n_components : int, optional
        Number of atoms. Default: min(n_samples, n_features).
    beta_loss : float or {'frobenius', 'kullback-leibler', 'itakura-saito'}, default='frobenius'
    solver : {'mu', 'pg'}, default='mu'
    update_rule : {'mm', 'heuristic'}, default='mm'
    init : {'random', 'nndsvd', 'nndsvda', 'nndsvdar', 'custom'}, optional
        See :func:`~mmconcepts.nmf.beta_nmf`; 'custom' takes ``W`` and ``H`` given to ``fit``.
    max_iter : int, default=200
    tol : float, default=1e-4
    alpha_W, alpha_H, l1_ratio : float
        L1/L2 penalties as scikit-learn (scaled by n_features and n_samples).
    sparseness_W, sparseness_H : float in [0, 1], optional
        Hoyer's sparseness of each column of W and each atom.
    forget_factor : float in [0, 1], default=0.7
        :meth:`partial_fit`: weight of the statistics of earlier batches (1 keeps them all).
    transform_max_iter : int, optional
        Multiplicative updates of :meth:`transform` (default: ``max_iter``); for
        1 <= beta <= 2 they start the Newton steps that solve the coefficients.
    loss_every : int, default=10
        The objective is evaluated (and recorded) every this many iterations.
    random_state : int, numpy.random.Generator or None

    Attributes
    ----------
    components_ : ndarray of shape (n_components, n_features)
        The dictionary H.
    n_components_ : int
    n_iter_ : int
        Iterations of the last fit (or partial_fit call).
    reconstruction_err_ : float
        sqrt(2 * D_beta(X | WH)) at the fit's last iterate, as scikit-learn.
    loss_history_ : ndarray
        Objective at the iterations in ``loss_iterations_``.
    loss_iterations_ : ndarray of int
    n_features_in_ : int
    n_steps_ : int
        Number of :meth:`partial_fit` calls since the last :meth:`fit`.

    A fitted model saves to one ``.npz`` without pickle (:meth:`save`, :meth:`load`),
    with the statistics :meth:`partial_fit` carries between batches.

    Examples
    --------
    >>> import numpy as np
    >>> from mmconcepts.nmf import NMF
    >>> X = np.random.default_rng(0).random((20, 8))
    >>> model = NMF(3, beta_loss="kullback-leibler", random_state=0).fit(X)
    >>> model.components_.shape
    (3, 8)
    >>> W = model.transform(X[:, :5], features=slice(0, 5))   # from the first 5 features
    >>> model.inverse_transform(W, features=[5, 6, 7]).shape   # reconstruct the others
    (20, 3)
    """

    _parameter_constraints: dict = {
        **{name: BETA_NMF_CONSTRAINTS[name] for name in (
            "n_components", "beta_loss", "solver", "update_rule", "init", "max_iter", "tol", "alpha_W", "alpha_H",
            "l1_ratio", "sparseness_W", "sparseness_H", "loss_every", "random_state")},
        "forget_factor": [Interval("real", 0, 1)],
        "transform_max_iter": [Interval("int", 0), None],
    }
    _persisted_private = ("_stats", "_scale")

    _stats: tuple[np.ndarray, np.ndarray] | None  # partial_fit's pooled statistics (A, B); None before
    _scale: float  # partial_fit: the power of two the batches are divided by (fixed by the first one)

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        # A saved broadcast row (partial_fit's I-divergence denominator) is written out whole; loaded
        # back as one row broadcast again, partial_fit keeps updating only a batch's nonzero columns.
        stats = getattr(self, "_stats", None)
        if stats is not None and stats[1].ndim == 2 and stats[1].shape[0] > 1 and bool((stats[1] == stats[1][:1]).all()):
            self._stats = (stats[0], np.broadcast_to(np.array(stats[1][0]), stats[1].shape))

    def __init__(
        self,
        n_components: int | None = None,
        *,
        beta_loss: float | str = "frobenius",
        solver: Literal["mu", "pg"] = "mu",
        update_rule: Literal["mm", "heuristic"] = "mm",
        init: str | None = None,
        max_iter: int = 200,
        tol: float = 1e-4,
        alpha_W: float = 0.0,
        alpha_H: float | str = "same",
        l1_ratio: float = 0.0,
        sparseness_W: float | None = None,
        sparseness_H: float | None = None,
        forget_factor: float = 0.7,
        transform_max_iter: int | None = None,
        loss_every: int = 10,
        random_state: Any = None,
    ):
        self.n_components = n_components
        self.beta_loss = beta_loss
        self.solver = solver
        self.update_rule = update_rule
        self.init = init
        self.max_iter = max_iter
        self.tol = tol
        self.alpha_W = alpha_W
        self.alpha_H = alpha_H
        self.l1_ratio = l1_ratio
        self.sparseness_W = sparseness_W
        self.sparseness_H = sparseness_H
        self.forget_factor = forget_factor
        self.transform_max_iter = transform_max_iter
        self.loss_every = loss_every
        self.random_state = random_state

    @classmethod
    def from_params(cls, owner: Any, /, **overrides: Any) -> NMF:
        """An unfitted NMF with the NMF parameters of another estimator, and ``overrides``.

        Estimators built on an NMF (:class:`~mmconcepts.nmf.LabelNMF`,
        :class:`~mmconcepts.multimodal.MultimodalNMF`) take NMF's parameters under NMF's
        names. This reads ``owner.get_params(deep=False)``, keeps the entries whose name is
        a parameter of this class (``n_components``, ``beta_loss``, ``max_iter``, ...),
        replaces them by ``overrides`` where given, and leaves the parameters ``owner``
        does not have at this class's defaults. The owner's other parameters (a label
        weight, a threshold, ...) are not NMF's and are left out.

        Parameters
        ----------
        owner : estimator
            Any object with scikit-learn's ``get_params(deep=False)``.
        **overrides
            NMF parameters to set to another value than the owner's (e.g. one seed per
            fit as ``random_state``); each name must be a parameter of this class.

        Returns
        -------
        NMF
            Unfitted; its parameters are checked by :meth:`fit`, as any NMF's.

        Raises
        ------
        ParameterError
            ``owner`` has no ``get_params``; an override is not a parameter of this class.

        Examples
        --------
        >>> from mmconcepts.nmf import NMF, LabelNMF
        >>> owner = LabelNMF(8, beta_loss="kullback-leibler", max_iter=50, threshold=0.3)
        >>> nmf = NMF.from_params(owner, random_state=0)
        >>> nmf.n_components, nmf.beta_loss, nmf.max_iter, nmf.random_state
        (8, 'kullback-leibler', 50, 0)
        >>> nmf.alpha_W   # not a LabelNMF parameter: NMF's default
        0.0
        """
        get_params = getattr(owner, "get_params", None)
        if not callable(get_params):
            raise ParameterError(
                f"{cls.__name__}.from_params expects an estimator with get_params(deep=False) as owner; got "
                f"{type(owner).__name__}. For a dict of parameters, use {cls.__name__}(**params)."
            )
        names = cls._get_param_names()
        unknown = sorted(set(overrides) - set(names))
        if unknown:
            raise ParameterError(
                f"{cls.__name__}.from_params takes {cls.__name__} parameters as overrides ({', '.join(names)}); got "
                f"{', '.join(map(repr, unknown))}. Set the owner's other parameters on the owner itself."
            )
        params = {name: value for name, value in get_params(deep=False).items() if name in names}
        params.update(overrides)
        return cls(**params)

    # ------------------------------------------------------------------ scikit-learn
    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.positive_only = True
        tags.input_tags.sparse = True
        tags.transformer_tags.preserves_dtype = ["float64", "float32"]
        return tags

    @property
    def _n_features_out(self) -> int:
        return self.components_.shape[0]

    def _solver_kwargs(self) -> dict:
        return dict(
            beta_loss=self.beta_loss,
            solver=self.solver,
            update_rule=self.update_rule,
            tol=self.tol,
            alpha_W=self.alpha_W,
            alpha_H=self.alpha_H,
            l1_ratio=self.l1_ratio,
            sparseness_W=self.sparseness_W,
            loss_every=self.loss_every,
        )

    # ------------------------------------------------------------------ fitting
    def fit(self, X: Any, y: Any = None, *, mask: Any = None, W: Any = None, H: Any = None) -> NMF:
        """Learn the dictionary from X.

        Parameters
        ----------
        X : {array-like, sparse matrix, dask.array.Array} of shape (n_samples, n_features)
            A dask array has row chunks only (one chunk of all the columns).
        y : ignored
        mask : {array-like of bool, dask.array.Array} of shape (n_samples, n_features), optional
            True where X is observed; unobserved cells have no influence. A dask mask has X's chunks.
        W, H : ndarray, optional
            Starting factors for ``init='custom'``.

        Returns
        -------
        self
        """
        self._fit(X, mask, W, H)
        return self

    def fit_transform(self, X: Any, y: Any = None, *, mask: Any = None, W: Any = None, H: Any = None) -> np.ndarray:
        """Learn the dictionary and return the coefficients W of X, shape (n_samples, n_components).

        For 1 <= beta <= 2 (without ``sparseness_W``), W is the fit's last W solved to
        convergence for the final dictionary, as :meth:`transform` solves it:
        ``fit_transform(X)`` is ``fit(X).transform(X)`` up to that solution's tolerance.
        W is a dask array with X's row chunks when X is a dask array.
        """
        res = self._fit(X, mask, W, H)
        if not self._solves_coefficients():
            return res.W
        # The coefficients of the final dictionary, solved as transform solves them (from the fit's W):
        # fit_transform(X) is fit(X).transform(X) up to the tolerance of the solution.
        if is_dask_array(X):
            columns = _live_features(res.H)
            return self._solve_coefficients_dask(X, mask, res.H if columns is None else res.H[:, columns], res.W,
                                                 columns)
        H, Xv, maskv = _live_columns(res.H, *validate_data(X, mask))
        return self._solve_coefficients(Xv, maskv, H, res.W)

    def _fit(self, X: Any, mask: Any, W: Any, H: Any) -> NMFResult:
        """Fit the dictionary, set the fitted attributes and return the solver's result (its last W included).

        :meth:`fit` stops here: only :meth:`fit_transform` solves the coefficients to convergence.
        """
        validate_params(self, self._parameter_constraints)
        res = beta_nmf(  # a dask array goes to the distributed solver (nmf/_dask.py); W is then a dask array
            X,
            self.n_components,
            init=self.init,
            W=W,
            H=H,
            mask=mask,
            max_iter=self.max_iter,
            sparseness_H=self.sparseness_H,
            random_state=self.random_state,
            **self._solver_kwargs(),
        )
        self._set_fitted(res.H, X)
        self.n_iter_ = res.n_iter
        self.loss_history_ = res.loss_history
        self.loss_iterations_ = res.loss_iterations
        # the divergence of the final factors, evaluated by the solver's last objective: X is not read again
        self.reconstruction_err_ = float(np.sqrt(2.0 * max(res.extra["divergence"], 0.0)))
        self.n_steps_ = 0
        self._stats = None
        return res

    def _set_fitted(self, H: np.ndarray, X: Any) -> None:
        self.components_ = H
        self.n_components_ = H.shape[0]
        self.n_features_in_ = H.shape[1]
        names = getattr(X, "columns", None)
        if names is not None:
            self.feature_names_in_ = np.asarray(names, dtype=object)

    def partial_fit(self, X: Any, y: Any = None, *, mask: Any = None) -> NMF:
        """Update the dictionary with one mini-batch (online multiplicative updates).

        Each call fits the batch's coefficients and the dictionary by ``max_iter``
        alternating multiplicative updates in which the dictionary update pools the
        batch's statistics with those kept from earlier batches, weighted by
        ``forget_factor`` (Lefevre, Bach & Fevotte, 2011):

        .. math:: H \\leftarrow \\left(\\frac{\\rho A + H^{1/\\gamma} \\odot N_t}{\\rho B + D_t}\\right)^{\\gamma}

        with N_t, D_t the numerator and denominator of thesis eq. (2.16) on the batch.
        The first call starts from ``init``; with no earlier statistics it performs exactly
        the iterations of :meth:`fit`, so one call on all the data equals :meth:`fit`
        with ``solver='mu'``. partial_fit always uses multiplicative updates, whatever
        ``solver`` says; ``tol`` is not used (each call runs ``max_iter`` iterations).
        """
        validate_params(self, self._parameter_constraints)
        if is_dask_array(X) or is_dask_array(mask):
            raise DataError(
                "partial_fit takes one in-memory batch; got a dask array. Pass X.compute() for a batch, or fit the "
                "whole dask array with fit (each pass goes over all its chunks)."
            )
        if self.sparseness_W is not None or self.sparseness_H is not None:
            raise ParameterError("partial_fit does not support Hoyer sparseness constraints; use fit.")
        beta = resolve_beta(self.beta_loss)
        rho = float(self.forget_factor)
        max_iter = int(self.max_iter)
        Xv, maskv = validate_data(X, mask)
        check_beta_zeros(Xv, beta, maskv)
        n, m = Xv.shape
        # As beta_nmf, the updates run on X / scale (a power of two, 1 at ordinary scales); the scale
        # is fixed by the first batch, so that the pooled statistics of all batches share it.
        stats: tuple[np.ndarray, np.ndarray] | None = getattr(self, "_stats", None) if hasattr(self, "components_") else None
        scale = float(getattr(self, "_scale", 1.0)) if stats is not None else data_scale(Xv, beta)
        if scale != 1.0:
            Xv = Xv / scale if sp.issparse(Xv) else np.divide(Xv, Xv.dtype.type(scale))
        gamma = mm_exponent(beta) if self.update_rule == "mm" else 1.0
        pen_W, pen_H = resolve_penalties(self.alpha_W, self.alpha_H, self.l1_ratio, n, m)
        if scale != 1.0:
            pen_W, pen_H = scale_penalties(pen_W, pen_H, scale, 1.0, scale, beta)
        touched = None if stats is None or max_iter == 0 else _touched_columns(Xv, maskv, beta, gamma, pen_H, stats)
        if not hasattr(self, "components_"):
            k = int(self.n_components if self.n_components is not None else min(n, m))
            init = self.init or ("nndsvda" if k <= min(n, m) else "random")
            W, H = initialize(Xv, k, init, check_random_state(self.random_state), mask=maskv)
            self.n_steps_ = 0
            self._stats = None
        else:
            self._check_n_features(m)
            if touched is None:
                H = self.components_.astype(Xv.dtype, copy=True) / Xv.dtype.type(scale)
                W = constant_coefficients(Xv, H, maskv)
        if touched is not None and stats is not None:
            # Only the batch's nonzero columns T move other than by the pooled statistics (see
            # _touched_columns): the loop runs on X[:, T] and one extra all-zero column standing for the
            # sum of the others, whose dictionary column is their sum (the updates are linear in it).
            Xv = cast(sp.csr_matrix, Xv)
            H_all = self.components_
            h_sum = H_all.sum(axis=1, dtype=np.float64)
            Ht = np.empty((touched.size + 1, H_all.shape[0]), dtype=Xv.dtype)
            Ht[:-1] = H_all[:, touched].T
            Ht[-1] = np.maximum(h_sum - Ht[:-1].sum(axis=0, dtype=np.float64), 0.0)
            Ht /= Xv.dtype.type(scale)
            A_prev, b_prev = stats[0], _broadcast_row(stats[1])
            assert b_prev is not None  # _touched_columns checked it
            a_rest = np.maximum(A_prev.sum(axis=0, dtype=np.float64) - A_prev[touched].sum(axis=0, dtype=np.float64), 0.0)
            stats_T = (np.vstack([A_prev[touched], a_rest[None, :].astype(A_prev.dtype)]),
                       np.broadcast_to(b_prev, (touched.size + 1, Ht.shape[1])))
            X_T = sp.csr_matrix((Xv.data, np.searchsorted(touched, Xv.indices).astype(Xv.indices.dtype), Xv.indptr),
                                shape=(n, touched.size + 1))
            problem = Problem(X_T, None)
            W = constant_coefficients(X_T, Ht.T, None)  # the same flat value: mean(X) / mean(H) does not depend on m
            W, Ht, A, B = _online_iterations(problem, W, Ht, stats_T, rho, beta, gamma, pen_W, pen_H, max_iter)
            # Back to all columns: the others' statistics are rho times the old ones, and every column of the
            # dictionary is A / B, as the loop leaves it.
            b = _broadcast_row(B)
            assert A is not None and b is not None  # max_iter >= 1 under the touched-columns path; B stays a row
            A_full = A_prev * A_prev.dtype.type(rho) if rho != 1.0 else A_prev.copy()
            A_full[touched] = A[:-1]
            A, B = A_full, np.broadcast_to(b, A_full.shape)
            internal_loss = problem.divergence(W, Ht, beta)
            check_fit_in_range(X_T, beta, W, Ht, [internal_loss])
            Ht = np.divide(A, b)
        else:
            problem = Problem(Xv, maskv)
            W, Ht, A, B = _online_iterations(problem, np.ascontiguousarray(W), np.ascontiguousarray(H.T), stats, rho,
                                             beta, gamma, pen_W, pen_H, max_iter)
            internal_loss = problem.divergence(W, Ht, beta)
            check_fit_in_range(Xv, beta, W, Ht, [internal_loss])  # before any state changes
        if scale != 1.0:
            check_objective_range(internal_loss, scale, beta)
        if A is not None and B is not None:
            self._stats = (A, B)
        self._scale = scale
        self._set_fitted(np.ascontiguousarray(Ht.T) * Ht.dtype.type(scale), X)
        self.n_iter_ = max_iter
        self.n_steps_ = getattr(self, "n_steps_", 0) + 1
        loss = float(in_units_of_X(internal_loss, scale, beta))
        self.loss_history_ = np.array([loss])
        self.loss_iterations_ = np.array([max_iter])
        self.reconstruction_err_ = float(np.sqrt(2.0 * max(loss, 0.0)))
        return self

    # ------------------------------------------------------------------ using the dictionary
    def _check_n_features(self, n: int) -> None:
        if n != self.n_features_in_:
            raise DataError(
                f"X has {n} features, but {type(self).__name__} is expecting {self.n_features_in_} features as input."
            )

    def rescale_features(self, columns: Any, factor: float) -> NMF:
        """Multiply the fitted dictionary's ``columns`` by ``factor``, and ``partial_fit``'s statistics with them.

        For data whose features are divided by a scale that changes between ``partial_fit``
        calls (the modality scales of :class:`~mmconcepts.multimodal.MultimodalNMF`): when the
        scale of a feature goes from ``s`` to ``s'``, its dictionary column is multiplied by
        ``factor = s / s'``, and the pooled statistics (A, B) of the multiplicative updates by
        ``factor ** (1 / gamma + beta - 1)`` and ``factor ** (beta - 1)``, so that the next
        ``partial_fit`` goes on as if every past batch had been scaled so.

        Parameters
        ----------
        columns : slice, int array or boolean mask over the ``n_features`` columns
        factor : float
            Positive; 1 changes nothing.

        Returns
        -------
        NMF
            ``self``, its ``components_`` now a float64 array.
        """
        check_is_fitted(self)
        factor = float(factor)
        if not factor > 0 or not np.isfinite(factor):
            raise ParameterError(f"factor must be a positive finite number; got {factor!r}.")
        if factor == 1.0:
            return self
        H = np.array(self.components_, dtype=np.float64, copy=True)
        H[:, columns] *= factor
        stats = getattr(self, "_stats", None)
        if stats is not None:
            beta = resolve_beta(self.beta_loss)
            gamma = mm_exponent(beta) if self.update_rule == "mm" else 1.0
            A = np.array(stats[0], copy=True)
            A[columns] *= factor ** (1.0 / gamma + beta - 1.0)
            # The I-divergence's pooled denominator does not scale (factor ** (beta - 1) = 1): it stays as it is,
            # and so keeps its form of one row broadcast over the features, which partial_fit relies on.
            B = stats[1]
            if beta != 1.0:
                B = np.array(B, copy=True)
                B[columns] *= factor ** (beta - 1.0)
            self._stats = (A, B)
        self.components_ = H
        return self

    def transform(self, X: Any, *, features: Any = None, mask: Any = None) -> np.ndarray:
        """Coefficients W of X with the dictionary fixed.

        Parameters
        ----------
        X : {array-like, sparse matrix, dask.array.Array} of shape (n_samples, n_features) or (n_samples, n_selected)
            With ``features``, X holds only the selected columns, in that order. A dask array
            of row chunks is transformed chunk by chunk (the updates between two evaluations of
            the stopping rule run in one pass over each chunk).
        features : slice, array of int or array of bool, optional
            Which columns of ``components_`` X corresponds to. The coefficients are fit on
            that sub-dictionary with the full multiplicative update, whose denominator
            uses the sub-dictionary's own sums (no bias when its atoms do not sum to one).
        mask : array-like of bool, optional
            True where X is observed.

        Returns
        -------
        W : ndarray or dask.array.Array of shape (n_samples, n_components)
            A dask array with X's row chunks when X is one.

        Notes
        -----
        Each row's coefficients minimise its objective with the dictionary fixed,

        .. math:: \\min_{w \\ge 0} \\sum_j m_j\\, d_\\beta(x_j | (wH)_j) + \\text{penalties on } w

        For 1 <= beta <= 2 the problem is convex; the multiplicative updates (thesis eq. 2.16,
        from a flat start, ``transform_max_iter`` at most) are followed by projected Newton
        steps with an Armijo search along the projection arc (Bertsekas 1982) until each row
        meets the optimality conditions, to about 1e-7 of its largest coefficient (far less
        once the convergence is quadratic). This is done where the minimiser is unique: the
        atoms that the selected features see are linearly independent and each row observes
        at least as many features as there are such atoms, for beta = 1 as many with x > 0
        (or ``alpha_W`` sets an L2 penalty); there the result does not depend on the start (for 1 < beta < 2 with zeros
        in X, whose curvature is infinite where a product vanishes, up to about 1e-3). Elsewhere
        (e.g. more atoms than features) the minimisers form a set, and the updates'
        coefficients are kept. For other betas, and with ``sparseness_W``, the coefficients are
        those of the updates alone.
        """
        check_is_fitted(self)
        idx = resolve_features(features, self.n_features_in_)
        if is_dask_array(X) or is_dask_array(mask):
            return self._transform_dask(X, idx, features is None, mask)
        Xv, maskv = validate_data(X, mask)
        if features is None:
            self._check_n_features(Xv.shape[1])
        elif Xv.shape[1] != idx.size:
            raise DataError(
                f"X has {Xv.shape[1]} columns but features selects {idx.size}; give X only the selected columns."
            )
        H, Xv, maskv = _live_columns(self.components_[:, idx].astype(Xv.dtype, copy=False), Xv, maskv)
        max_iter = self.transform_max_iter if self.transform_max_iter is not None else self.max_iter
        solves = self._solves_coefficients()
        with warnings.catch_warnings():
            if solves:  # the updates only start the Newton steps: their stopping early is no concern
                warnings.simplefilter("ignore", ConvergenceWarning)
            res = beta_nmf(
                Xv,
                self.components_.shape[0],
                H=H,
                update_H=False,
                mask=maskv,
                max_iter=max_iter,
                **self._solver_kwargs(),
            )
        return self._solve_coefficients(Xv, maskv, H, res.W) if solves else res.W

    def _solves_coefficients(self) -> bool:
        """Whether the coefficients are solved to convergence: a convex problem per row, no Hoyer constraint."""
        return self.sparseness_W is None and solves_coefficients(resolve_beta(self.beta_loss))

    def _coefficient_penalty(self, n_features: int):
        """The penalty on W of a transform on ``n_features`` columns (scikit-learn's scaling, as beta_nmf's)."""
        return resolve_penalties(self.alpha_W, self.alpha_H, self.l1_ratio, 1, n_features)[0]

    def _solve_coefficients(self, X: Any, mask: Any, H: np.ndarray, W: np.ndarray) -> np.ndarray:
        """W solved to convergence from the start W, for the fixed H (columns of X already selected)."""
        W, converged = solve_coefficients(X, H, W, resolve_beta(self.beta_loss), mask=mask,
                                          penalty=self._coefficient_penalty(H.shape[1]))
        if not converged:
            warnings.warn(
                "the coefficients' projected Newton steps did not converge; they are the last iterate. Rows whose "
                "values span hundreds of orders of magnitude (kernel-density histograms) converge slowly; values at "
                "the edge of the float range can stop them.",
                ConvergenceWarning,
                stacklevel=3,
            )
        return W

    def _transform_dask(self, X: Any, idx: np.ndarray, all_features: bool, mask: Any) -> Any:
        """transform() of a dask array of row chunks: the same steps, chunk by chunk (nmf/_dask.py)."""
        from ._dask import beta_nmf_dask

        if not is_dask_array(X):
            raise DataError(
                "mask is a dask array but X is not; give X as a dask array chunked like the mask "
                "(dask.array.from_array(X, chunks=mask.chunks)), or the mask in memory."
            )
        if X.ndim != 2:
            raise DataError(f"X must be 2-D (n_samples, n_features); got a dask array of shape {X.shape}.")
        if all_features:
            self._check_n_features(X.shape[1])
        elif X.shape[1] != idx.size:
            raise DataError(
                f"X has {X.shape[1]} columns but features selects {idx.size}; give X only the selected columns."
            )
        H = self.components_[:, idx]
        columns = _live_features(H)  # as in memory
        if columns is not None:
            H = H[:, columns]
        max_iter = self.transform_max_iter if self.transform_max_iter is not None else self.max_iter
        kwargs = self._solver_kwargs()
        beta = resolve_beta(kwargs.pop("beta_loss"))
        solves = self._solves_coefficients()
        with warnings.catch_warnings():
            if solves:  # as in memory: the updates only start the Newton steps
                warnings.simplefilter("ignore", ConvergenceWarning)
            res = beta_nmf_dask(X, self.components_.shape[0], beta=beta, H=H, update_H=False, mask=mask,
                                max_iter=int(max_iter), columns=columns, **kwargs)
        return self._solve_coefficients_dask(X, mask, H, res.W, columns) if solves else res.W

    def _solve_coefficients_dask(self, X: Any, mask: Any, H: np.ndarray, W: Any, columns: np.ndarray | None) -> Any:
        """:meth:`_solve_coefficients` of a dask array, chunk by chunk (lazy; nmf/_dask.py)."""
        from ._dask import solve_coefficients_dask

        return solve_coefficients_dask(X, W, H, resolve_beta(self.beta_loss), mask=mask, columns=columns,
                                       penalty=self._coefficient_penalty(H.shape[1]))

    def inverse_transform(self, W: Any, *, features: Any = None) -> np.ndarray:
        """Reconstruction W @ H, restricted to the selected features when given.

        Parameters
        ----------
        W : array-like of shape (n_samples, n_components)
        features : slice, array of int or array of bool, optional

        Returns
        -------
        ndarray or dask.array.Array of shape (n_samples, n_selected)
            A dask array when W is one.
        """
        check_is_fitted(self)
        if is_dask_array(W):  # a dask array of coefficients (transform of a dask array): stays one
            if W.ndim != 2 or W.shape[1] != self.components_.shape[0]:
                raise DataError(f"W must have shape (n_samples, {self.components_.shape[0]}); got {W.shape}.")
            return W @ self.components_[:, resolve_features(features, self.n_features_in_)]
        W = np.asarray(W.toarray() if sp.issparse(W) else W)
        if W.ndim != 2 or W.shape[1] != self.components_.shape[0]:
            raise DataError(
                f"W must have shape (n_samples, {self.components_.shape[0]}); got {W.shape}."
            )
        idx = resolve_features(features, self.n_features_in_)
        return W @ self.components_[:, idx]
