"""The multimodal NMF learner (Thesis section 6.4, eq. 6.3, Fig. 6.2).

Examples observed in several named modalities are stacked side by side,
``X = [X_1 / s_1, X_2 / s_2, ...]`` with ``s_m`` the average L1 norm of modality ``m``
over the training examples (so "the error in each modality is treated on a fair level"),
and factorized by I-divergence NMF, ``X ~ W H``: the rows of H = ``components_`` are the
multimodal atoms, ``H = [H_1, H_2, ...]`` split by modality. The coefficients ``w`` of an
example are the learner's *internal representation*. Orientation: the thesis writes
``V = (V_mod1; V_mod2; ...) ~ W H`` with examples as columns; its ``W_mod`` is our
``H_m.T`` and its internal representation ``h`` is our ``w``.

From any subset of modalities, :meth:`MultimodalNMF.transform` fits ``w`` with the
dictionary fixed, on the sub-dictionary of the observed modalities (eq. 6.3):

.. math:: w^* = \\arg\\min_{w \\ge 0} D_I\\big([x_m / s_m]_{m \\in S} \\,\\big|\\, w\\,[H_m]_{m \\in S}\\big)

and :meth:`MultimodalNMF.reconstruct` gives the expected perception in any modality,
``x_hat_m = s_m (w H_m)``, in the modality's own units.

:meth:`MultimodalNMF.partial_fit` learns the same dictionary from a stream of mini-batches
(beyond the thesis, whose "Discussion and perspectives" names the learner's not being
incremental as a shortcoming): online multiplicative updates with accumulated statistics
and a forgetting factor (Lefevre, Bach & Fevotte 2011), the scales ``s_m`` estimated online.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import InstanceOf, Interval, Options, check_nonnegative_matrix, validate_params
from ..errors import DataError, DataFormatError, MMConceptsError, ParameterError
from ..nmf import NMF
from ..nmf._beta import EPSILON
from ..nmf._dask import check_row_chunks, hstack_row_chunks, is_dask_array
from .matching import matching_success_rate, pairwise_divergence

__all__ = ["MultimodalNMF", "FORMAT_VERSION", "SCORE_METRIC", "SCORE_DRAWS"]

#: The metric of :meth:`MultimodalNMF.score` (see :func:`~mmconcepts.multimodal.pairwise_divergence`).
SCORE_METRIC = "cosine"
#: Reference draws per example in :meth:`MultimodalNMF.score`.
SCORE_DRAWS = 10
#: Mixed with an int ``random_state`` into the seed of :meth:`MultimodalNMF.score`'s reference draws, so they
#: come from a stream of their own, not the learner's initialisation stream.
_SCORE_STREAM = 0x5C0E

#: Version of the save format written by :meth:`MultimodalNMF.save` (version 1 files still load).
FORMAT_VERSION = 2


def _mean_l1(X: Any) -> float:
    """The average L1 norm of the rows of X (a dask array: summed chunk by chunk, never loaded whole)."""
    if is_dask_array(X):
        totals = X.map_blocks(lambda b: np.full((1, 1), float(abs(b).sum())), chunks=((1,) * X.numblocks[0], (1,)),
                              dtype=np.float64)
        return float(totals.sum().compute()) / X.shape[0] if X.shape[0] else float("nan")
    return float(np.asarray(abs(X).sum(axis=1)).ravel().mean())


class MultimodalNMF(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """NMF over any number of named modalities (Thesis section 6.4).

    Parameters
    ----------
    n_components : int, default=50
        Number of atoms k (the thesis uses k = 50).
    modalities : mapping of str to slice or array of int, optional
        The columns of each modality when X is one 2-D table (n_samples, n_features), dense
        or sparse, e.g. ``{"sound": slice(0, 300), "image": slice(300, None)}`` (or arrays of
        column indices): :meth:`fit`, :meth:`partial_fit`, :meth:`transform` and
        :meth:`score` then take such a table and split it by these columns, and the learner
        is a plain scikit-learn estimator (``GridSearchCV``, ``cross_val_score``,
        ``Pipeline``). Each modality needs at least one column and no column belongs to two
        modalities; columns of no modality are ignored. The modalities are stacked in this
        mapping's order. A mapping X (one matrix per modality) is still taken: its names must
        be among these (at fit, all of them), and it is read in this mapping's order, so a
        table and the mapping of its column blocks give the same fit; a mapping is how to
        :meth:`transform` from a subset of the modalities. None (the default): X is always
        a mapping, as read in its own order.
    beta_loss : float or str, default="kullback-leibler"
        The beta-divergence (the thesis: I-divergence, beta = 1).
    max_iter : int, default=50
        Multiplicative-update iterations for fitting (the thesis: 50).
    transform_max_iter : int, optional
        Iterations for :meth:`transform` (default ``max_iter``).
    tol : float, default=0.0
        Stopping tolerance; 0 runs exactly ``max_iter`` iterations, as the thesis does.
    normalize : {"l1", None}, default="l1"
        "l1": each modality is divided by its average L1 norm over the training examples
        (the same factor is applied at transform and undone at reconstruction); None
        keeps the data as given.
    init : {"random", "nndsvd", "nndsvda", "nndsvdar"} or None, default="random"
        Initialization of the factorization (see :func:`mmconcepts.nmf.beta_nmf`). Random
        (seeded) factors scaled to the data, as in the thesis' experiments; "nndsvda"
        costs a truncated SVD of the stacked matrix, a large part of the fit on HAC vectors
        (``benchmarks/README.md``).
    random_state : int, Generator or None
    forget_factor : float in (0, 1], default=1.0
        :meth:`partial_fit` only: the weight ``rho`` of the statistics of earlier batches
        (the dictionary's accumulated numerator and denominator, and the running L1 norm
        behind ``scales_``) when a batch arrives. 1 keeps every example with the same
        weight (no forgetting, the setting for a stationary stream); smaller values let a
        drifting stream forget its past (an example seen ``t`` batches ago weighs
        ``rho ** t``). The same parameter as :class:`~mmconcepts.nmf.NMF`'s.
    partial_max_iter : int, optional
        :meth:`partial_fit` only: alternating multiplicative updates per call after the
        first (default ``max_iter``). The first call always runs ``max_iter`` iterations,
        the iterations of :meth:`fit`.
    forget : float in (0, 1], optional
        Deprecated: the former name of ``forget_factor``, still taken (with a
        ``FutureWarning``) and to be removed in 0.3.

    Attributes
    ----------
    modalities_ : list of str
        Modality names, in the order of the stacked columns.
    n_features_ : dict of str to int
    scales_ : dict of str to float
        ``s_m``, the average L1 norm of each modality on the training data (1 when
        ``normalize`` is None).
    components_ : ndarray of shape (n_components, sum of n_features)
        The multimodal dictionary H (the same array as ``nmf_.components_``).
    nmf_ : NMF
        The underlying factorization (it also carries :meth:`partial_fit`'s statistics), with
        this learner's NMF parameters (:meth:`NMF.from_params <mmconcepts.nmf.NMF.from_params>`;
        ``forget`` taken as ``forget_factor``); each :meth:`partial_fit` call gives it the
        learner's current ones.
    n_samples_seen_ : float
        Examples seen, weighted by the forgetting factor (``sum_t rho ** (T - t) n_t`` over
        the batches; the number of examples after :meth:`fit`): the weight of the running
        L1 norms behind ``scales_``.

    n_features_in_ : int
        Only after fitting on a 2-D table (``modalities`` given): its number of columns.

    Notes
    -----
    Without ``modalities``, X is a mapping of modality names to matrices, not one 2-D
    array, and the tags say so: scikit-learn's ``check_estimator`` cannot feed it, though
    the learner is still a scikit-learn estimator (``clone``, ``get_params``/``set_params``,
    ``NotFittedError``). With ``modalities``, it takes 2-D tables and runs
    ``check_estimator``. :meth:`save` writes
    format version 2 (the inner :class:`~mmconcepts.nmf.NMF` saved as a nested model);
    :meth:`load` also reads the version-1 files of earlier mmconcepts (the dictionary and
    a header with the modalities, their widths and scales).
    """

    _parameter_constraints: ClassVar[dict] = {
        "n_components": [Interval("int", 1)],  # NMF's None (min(n_samples, n_features)) is not offered
        "modalities": [InstanceOf(Mapping, description="a mapping of modality names to column slices or arrays of "
                                                       "column indices"), None],
        **{name: NMF._parameter_constraints[name]
           for name in ("beta_loss", "max_iter", "transform_max_iter", "tol", "random_state")},
        "normalize": [Options("l1", None)],
        "init": [Options("random", "nndsvd", "nndsvda", "nndsvdar"), None],  # no 'custom': fit takes no factors
        "forget_factor": [Interval("real", 0, 1, closed="right")],  # NMF's [0, 1] without 0
        "partial_max_iter": [Interval("int", 1), None],
        "forget": [Interval("real", 0, 1, closed="right"), Options("deprecated")],
    }
    _hints: ClassVar[dict] = {
        "init": "'custom' is not available: MultimodalNMF.fit takes no starting factors.",
        "modalities": "e.g. modalities={'sound': slice(0, 300), 'image': slice(300, None)}, or None to give X as a "
                      "mapping of modality names to matrices.",
    }
    _save_format_version: ClassVar[int] = FORMAT_VERSION

    def __init__(
        self,
        n_components: int = 50,
        *,
        modalities: Mapping[str, slice | Sequence[int] | np.ndarray] | None = None,
        beta_loss: float | str = "kullback-leibler",
        max_iter: int = 50,
        transform_max_iter: int | None = None,
        tol: float = 0.0,
        normalize: str | None = "l1",
        init: str | None = "random",
        random_state: Any = None,
        forget_factor: float = 1.0,
        partial_max_iter: int | None = None,
        forget: float | str = "deprecated",
    ) -> None:
        self.n_components = n_components
        self.modalities = modalities
        self.beta_loss = beta_loss
        self.max_iter = max_iter
        self.transform_max_iter = transform_max_iter
        self.tol = tol
        self.normalize = normalize
        self.init = init
        self.random_state = random_state
        self.forget_factor = forget_factor
        self.partial_max_iter = partial_max_iter
        self.forget = forget

    def _forget_factor(self) -> float:
        """``forget_factor``, or the deprecated ``forget`` when it is given (with a FutureWarning)."""
        if isinstance(self.forget, str) and self.forget == "deprecated":
            return float(self.forget_factor)
        warnings.warn("MultimodalNMF's 'forget' is now 'forget_factor', as NMF's; 'forget' will be removed in 0.3. "
                      "Pass forget_factor=... instead.", FutureWarning, stacklevel=3)
        return float(self.forget)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        # X is a mapping of modality names to matrices; with ``modalities``, also one 2-D table
        tags.input_tags.two_d_array = self.modalities is not None
        tags.input_tags.dict = True
        tags.input_tags.sparse = True
        tags.input_tags.positive_only = True
        return tags

    # ------------------------------------------------------------------ helpers
    def _nmf(self) -> NMF:
        """The inner NMF: this learner's NMF parameters, ``forget`` resolved to ``forget_factor``."""
        return NMF.from_params(self, forget_factor=self._forget_factor())

    @staticmethod
    def _check_modalities(X: Any) -> dict[str, Any]:
        if not isinstance(X, Mapping) or not X:
            raise DataError(
                "X must be a non-empty mapping of modality names to (n_samples, n_features) arrays, "
                f"e.g. {{'sound': X_sound, 'motion': X_motion}}; got {type(X).__name__}."
            )
        out: dict[str, Any] = {}
        n = None
        for name, Xm in X.items():
            if not isinstance(name, str):
                raise DataError(f"modality names must be strings; got {name!r}.")
            if is_dask_array(Xm):  # checked chunk by chunk by the distributed solver (negative values name the chunk)
                check_row_chunks(Xm, f"modality {name!r}")
            else:
                try:
                    Xm = check_nonnegative_matrix(Xm, f"modality {name!r}")
                except MMConceptsError:
                    raise
                except (TypeError, ValueError) as exc:  # e.g. an object array holding text
                    raise DataError(f"modality {name!r} must be a numeric matrix ({exc}).") from None
            if n is None:
                n = Xm.shape[0]
            elif Xm.shape[0] != n:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[0]} examples but the first modality has {n}; "
                    "every modality needs one row per example."
                )
            out[name] = Xm
        return out

    def _column_groups(self, n_columns: int) -> dict[str, np.ndarray]:
        """The column indices of each modality of ``modalities`` in a table of ``n_columns`` columns."""
        if not self.modalities:  # called with modalities given: only an empty mapping comes here
            raise ParameterError("MultimodalNMF: modalities must name at least one modality; got an empty mapping. "
                                 + self._hints["modalities"])
        out: dict[str, np.ndarray] = {}
        owner = np.full(n_columns, -1)
        for i, (name, cols) in enumerate(self.modalities.items()):
            if not isinstance(name, str):
                raise ParameterError(f"MultimodalNMF: modality names must be strings; got {name!r} in modalities.")
            if isinstance(cols, slice):
                idx = np.arange(n_columns)[cols]
            else:
                idx = np.asarray(cols)
                if idx.ndim != 1 or idx.dtype.kind not in "iu":
                    raise ParameterError(
                        f"MultimodalNMF: modalities[{name!r}] must be a slice or a 1-D array of column indices; got "
                        f"{type(cols).__name__} of dtype {idx.dtype} and shape {idx.shape}. For a boolean mask, give "
                        "np.flatnonzero(mask).")
                if idx.size and (idx.min() < -n_columns or idx.max() >= n_columns):
                    raise DataError(
                        f"X has {n_columns} features, but modality {name!r} takes columns {idx.min()} to {idx.max()}; "
                        f"give a table with the columns of modalities, or column indices in [-{n_columns}, "
                        f"{n_columns}).")
                idx = np.arange(n_columns)[idx]
            if idx.size == 0:
                raise DataError(f"modality {name!r} has no column in X's {n_columns} feature(s) (modalities[{name!r}] "
                                f"= {cols!r}); give a table holding the columns of every modality.")
            taken = owner[idx]
            if (taken >= 0).any() or np.unique(idx).size != idx.size:
                other = list(self.modalities)[taken.max()] if (taken >= 0).any() else name
                raise ParameterError(f"MultimodalNMF: modalities {other!r} and {name!r} share columns; each column "
                                     "belongs to at most one modality.")
            owner[idx] = i
            out[name] = idx
        return out

    def _by_modality(self, X: Any, *, fitting: bool) -> tuple[Any, int | None]:
        """X as a mapping of modality names to matrices, and the width of X when it is a table (else None).

        A table is split by ``modalities``; a mapping is taken as given (with ``modalities``: checked against it and
        put in its order). Anything else is left to ``_check_modalities``."""
        if isinstance(X, Mapping) and not sp.issparse(X):  # a scipy.sparse dok matrix is a dict
            if self.modalities is None:
                return X, None
            unknown = [k for k in X if k not in self.modalities]
            missing = [k for k in self.modalities if k not in X] if fitting else []
            if unknown or missing:
                raise DataError(
                    f"X names the modalities {list(X)}, but modalities names {list(self.modalities)} "
                    f"({'unknown: ' + repr(unknown) if unknown else 'missing: ' + repr(missing)}); give a mapping with "
                    f"{'these' if fitting else 'some of these'} names, or one 2-D table.")
            return {name: X[name] for name in self.modalities if name in X}, None
        if self.modalities is None:
            raise DataError(
                "X must be a non-empty mapping of modality names to (n_samples, n_features) arrays, e.g. "
                f"{{'sound': X_sound, 'motion': X_motion}}; got {type(X).__name__}. To give one 2-D table, say which columns are which "
                "modality: MultimodalNMF(modalities={'sound': slice(0, 300), 'motion': slice(300, None)}).")
        if not is_dask_array(X):
            X = check_nonnegative_matrix(X, "X")
        expected = None if fitting else getattr(self, "n_features_in_", None)
        if expected is not None and X.shape[1] != expected:
            raise DataError(f"X has {X.shape[1]} features, but MultimodalNMF is expecting {expected} features as "
                            "input (the width of the table it was fitted on); give a table with the same columns.")
        return {name: X[:, idx] for name, idx in self._column_groups(X.shape[1]).items()}, int(X.shape[1])

    def _remember_width(self, width: int | None) -> None:
        """After fitting: ``n_features_in_`` is the width of a fitted table; a mapping X has none."""
        if width is None:
            self.__dict__.pop("n_features_in_", None)
        else:
            self.n_features_in_ = width

    @staticmethod
    def _columns(modalities: Sequence[str], n_features: Mapping[str, int]) -> dict[str, slice]:
        """The columns of each modality in the stacked matrix, in the order of ``modalities``."""
        out, start = {}, 0
        for name in modalities:
            out[name] = slice(start, start + int(n_features[name]))
            start += int(n_features[name])
        return out

    @staticmethod
    def _stack(X: Mapping[str, Any], modalities: Sequence[str], n_features: Mapping[str, int],
               scales: Mapping[str, float]) -> tuple[Any, np.ndarray]:
        """The weighted stacked matrix of the given modalities and its columns in the full dictionary."""
        columns = MultimodalNMF._columns(modalities, n_features)
        blocks, cols, names = [], [], []
        for name in modalities:
            if name not in X:
                continue
            Xm = X[name]
            if Xm.shape[1] != n_features[name]:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[1]} features; the learner was fitted with {n_features[name]}."
                )
            blocks.append(Xm)
            names.append(name)
            cols.append(np.arange(columns[name].start, columns[name].stop))
        if any(is_dask_array(b) for b in blocks):  # side by side chunk by chunk: a dask array with the same row chunks
            stacked = hstack_row_chunks(blocks, [1.0 / scales[n] for n in names],
                                        names=[f"modality {n!r}" for n in names])
            return stacked, np.concatenate(cols)
        blocks = [b * (1.0 / scales[n]) for b, n in zip(blocks, names)]
        if any(sp.issparse(b) for b in blocks):
            stacked = sp.hstack([sp.csr_matrix(b) for b in blocks], format="csr")
        else:
            stacked = np.hstack(blocks)
        return stacked, np.concatenate(cols)

    def _slice(self, modality: str) -> slice:
        if modality not in self.n_features_:
            raise DataError(f"unknown modality {modality!r}; the learner knows {self.modalities_}.")
        return self._columns(self.modalities_, self.n_features_)[modality]

    # ------------------------------------------------------------------ API
    def fit(self, X: Mapping[str, Any], y: Any = None) -> MultimodalNMF:
        """Learn the multimodal dictionary from examples observed in every modality.

        Parameters
        ----------
        X : mapping of str to {array-like, sparse matrix} of shape (n_samples, n_features_m), or {array-like, sparse matrix} of shape (n_samples, n_features)
            One nonnegative matrix per modality, rows aligned (row i of every modality is
            example i); or, with ``modalities``, one table whose columns it splits. Or one ``dask.array`` per modality, split by rows only, the same row
            chunks for all (dense or sparse chunks): the modalities are stacked chunk by chunk
            and fitted by the distributed solver (:mod:`mmconcepts.nmf`), with the same
            iterates as in memory; ``fit_transform`` and ``transform`` then return dask arrays.
        y : ignored

        Returns
        -------
        self
        """
        self._fit(X, transform=False)
        return self

    def fit_transform(self, X: Mapping[str, Any], y: Any = None) -> np.ndarray:
        """Fit, and return the internal representations of the training examples.

        Returns
        -------
        ndarray of shape (n_samples, n_components)
        """
        return self._fit(X, transform=True)

    def _fit(self, X: Mapping[str, Any], *, transform: bool) -> Any:
        """Fit; with ``transform``, return the training examples' coefficients solved for the final dictionary."""
        validate_params(self, self._parameter_constraints, hints=self._hints)
        split, width = self._by_modality(X, fitting=True)
        mods = self._check_modalities(split)
        scales = {}
        for name, Xm in mods.items():
            l1 = _mean_l1(Xm) if self.normalize == "l1" else 1.0
            if not l1 > 0:
                raise DataError(f"modality {name!r} is all zeros on the training data; it cannot be normalised.")
            scales[name] = float(l1)
        names = list(mods)
        n_features = {name: int(Xm.shape[1]) for name, Xm in mods.items()}
        stacked, _ = self._stack(mods, names, n_features, scales)
        nmf = self._nmf()
        W = nmf.fit_transform(stacked) if transform else nmf.fit(stacked)
        self.modalities_, self.n_features_, self.scales_ = names, n_features, scales
        self.nmf_ = nmf
        self.components_ = nmf.components_
        self.n_samples_seen_ = float(stacked.shape[0])
        self._remember_width(width)
        return W

    def partial_fit(self, X: Mapping[str, Any], y: Any = None) -> MultimodalNMF:
        """Update the multimodal dictionary with one mini-batch of examples (online learning).

        Beyond the thesis (its "Discussion and perspectives": the learner "is not
        incremental"). Each call:

        1. updates the running average L1 norm of each modality with the batch,
           ``s_m = (rho S_m + sum_i |x_im|_1) / (rho N + n_batch)`` (``rho`` = ``forget_factor``,
           ``S_m = s_m N`` the weighted L1 mass and ``N`` = ``n_samples_seen_`` so far);
        2. floors the dictionary's entries at ``eps * mean(H_m)`` (float32's eps), so that a
           feature absent from the batches so far (a zero column, which multiplicative
           updates would never move) can be learnt when it appears; when ``s_m`` changed,
           rescales the dictionary's columns of modality ``m`` and the
           accumulated statistics to the new units (exact: with ``c = s_old / s_new``, the
           normalised data and ``H_m`` both scale by ``c``; the MM numerator
           ``H^{1/gamma} * W^T[X (WH)^{beta-2}]`` by ``c^{1/gamma + beta - 1}`` and the
           denominator ``W^T (WH)^{beta-1}`` by ``c^{beta-1}``, at the same coefficients);
        3. runs online multiplicative updates on the stacked, normalised batch
           (:meth:`mmconcepts.nmf.NMF.partial_fit`, Lefevre, Bach & Fevotte 2011): the
           batch's coefficients and the dictionary alternate, the dictionary update
           pooling the batch's numerator and denominator with ``rho`` times those
           accumulated from earlier batches,

           .. math:: H \\leftarrow \\Big(\\frac{\\rho A + H^{1/\\gamma} \\odot N_t}
                     {\\rho B + D_t}\\Big)^{\\gamma}

           (thesis eq. 2.16 for N_t, D_t on the batch; our ``H`` is the thesis' ``W``
           transposed). ``A`` and ``B`` are (n_features, n_components): the memory does
           not grow with the number of examples seen.

        The first call (on a new or cloned learner) starts from ``init`` and runs the
        ``max_iter`` iterations of :meth:`fit`, so one call on all the data gives
        :meth:`fit`'s dictionary and scales (to rounding). Later calls start the batch's
        coefficients flat and run ``partial_max_iter`` iterations (default ``max_iter``).
        After :meth:`fit`, partial_fit continues from the fitted dictionary and scales (fit
        counts as ``n_samples`` examples seen) but fit keeps no statistics, so the first
        batch after it is not pooled with fit's data.

        Every beta of :meth:`fit` is supported (the rescaling above holds for any beta
        with the exponent ``gamma`` of thesis Table 2.2); beta <= 0 refuses zeros in the
        data, as fit does.

        Parameters
        ----------
        X : mapping of str to {array-like, sparse matrix} of shape (n_batch, n_features_m), or {array-like, sparse matrix} of shape (n_batch, n_features)
            One nonnegative matrix per modality, rows aligned; the same modalities, with
            the same numbers of features, at every call. Or, with ``modalities``, one table
            whose columns it splits.
        y : ignored

        Returns
        -------
        self

        Raises
        ------
        DataError
            A modality the learner does not know or one it misses, modalities with
            different numbers of rows, a modality whose number of features changed, a
            modality that is all zeros on the first batch.
        """
        validate_params(self, self._parameter_constraints, hints=self._hints)
        fitted = hasattr(self, "components_")
        X, width = self._by_modality(X, fitting=not fitted)
        if fitted and isinstance(X, Mapping):
            unknown = [k for k in X if k not in self.modalities_]
            missing = [k for k in self.modalities_ if k not in X]
            if unknown or missing:
                raise DataError(
                    f"partial_fit needs the modalities the learner was fitted with, {self.modalities_}; got "
                    f"{list(X)} ({'unknown: ' + repr(unknown) if unknown else ''}"
                    f"{'; ' if unknown and missing else ''}{'missing: ' + repr(missing) if missing else ''}). "
                    "Give every batch the same modalities, or learn other modalities with a new learner "
                    "(sklearn.base.clone(model)) or fit."
                )
        mods = self._check_modalities(X)
        dask_mods = [name for name, Xm in mods.items() if is_dask_array(Xm)]
        if dask_mods:
            raise DataError(
                f"partial_fit takes in-memory batches; modality {dask_mods[0]!r} is a dask array. Give the batches as "
                "numpy arrays or sparse matrices (batch.compute()), or fit the whole dask array with fit."
            )
        if fitted:
            for name, Xm in mods.items():
                if Xm.shape[1] != self.n_features_[name]:
                    raise DataError(
                        f"modality {name!r} has {Xm.shape[1]} features in this batch; the learner was fitted with "
                        f"{self.n_features_[name]}. Give every batch the same features (e.g. the same codebook), or "
                        "start a new learner."
                    )
        rho = float(self._forget_factor())
        n_batch = next(iter(mods.values())).shape[0]
        names = list(self.modalities_) if fitted else list(mods)
        n_features = dict(self.n_features_) if fitted else {name: int(Xm.shape[1]) for name, Xm in mods.items()}
        seen = float(getattr(self, "n_samples_seen_", 0.0)) if fitted else 0.0
        old_scales = dict(self.scales_) if fitted else {}
        scales = {}
        for name in names:
            Xm = mods[name]
            if self.normalize == "l1":
                l1 = float(np.asarray(abs(Xm).sum(axis=1)).ravel().sum())
                s = (rho * old_scales.get(name, 0.0) * seen + l1) / (rho * seen + n_batch)
            else:
                s = 1.0
            if not s > 0:
                raise DataError(f"modality {name!r} is all zeros on the first batch; it cannot be normalised. "
                                "Start the stream with a batch in which every modality has a nonzero value.")
            scales[name] = float(s)
        # This call's NMF parameters: the learner's, with the resolved forgetting factor and this call's iterations.
        iterations = self.max_iter if not fitted or self.partial_max_iter is None else self.partial_max_iter
        step = NMF.from_params(self, forget_factor=rho, max_iter=iterations)
        nmf = self.nmf_ if fitted else step
        if fitted:
            self._rescale(nmf, names, n_features, old_scales, scales)  # in the units of the statistics kept so far
            nmf.set_params(**step.get_params(deep=False))
        stacked, _ = self._stack(mods, names, n_features, scales)
        try:
            nmf.partial_fit(stacked)
        finally:  # transform uses max_iter when transform_max_iter is None: give it back fit's value
            nmf.set_params(max_iter=self.max_iter)
        self.modalities_, self.n_features_, self.scales_ = names, n_features, scales
        self.nmf_ = nmf
        self.components_ = nmf.components_
        self.n_samples_seen_ = rho * seen + n_batch
        self._remember_width(width)
        return self

    def _rescale(self, nmf: NMF, names: Sequence[str], n_features: Mapping[str, int],
                 old: Mapping[str, float], new: Mapping[str, float]) -> None:
        """Bring the dictionary and partial_fit's statistics from the scales ``old`` to ``new`` (see partial_fit),
        and floor the dictionary's zero entries (see the comment below)."""
        columns = self._columns(names, n_features)
        for name in names:
            nmf.rescale_features(columns[name], old[name] / new[name])
        H = np.array(nmf.components_, dtype=np.float64, copy=True)
        # Multiplicative updates never move an exact zero: a feature absent from every batch so far
        # (most HAC columns are absent from a small batch) has a zero column, and would stay zero when
        # it appears, with an infinite divergence for beta <= 1. Entries are floored at a tiny fraction
        # of their modality's mean (float32's eps), so a feature seen later gets its share of the
        # dictionary from the batches it appears in.
        for name in names:
            cols = columns[name]
            floor = EPSILON * float(H[:, cols].mean())
            if floor > 0:
                np.maximum(H[:, cols], floor, out=H[:, cols])
        nmf.components_ = H

    def _observed(self, X: Any) -> dict[str, Any]:
        """The checked matrices of the modalities X observes, for a fitted learner (transform, score)."""
        check_is_fitted(self)
        X, _ = self._by_modality(X, fitting=False)
        if isinstance(X, Mapping):
            unknown = [k for k in X if k not in self.modalities_]
            if unknown:
                raise DataError(f"unknown modality {unknown[0]!r}; the learner knows {self.modalities_}.")
        return self._check_modalities(X)

    def transform(self, X: Any) -> np.ndarray:
        """Internal representations from any subset of the modalities (eq. 6.3).

        Parameters
        ----------
        X : mapping of str to array-like, or {array-like, sparse matrix} of shape (n_samples, n_features)
            The observed modalities (any non-empty subset of ``modalities_``), rows aligned;
            or, with ``modalities``, one table holding every modality.

        Returns
        -------
        ndarray of shape (n_samples, n_components)
        """
        mods = self._observed(X)
        stacked, cols = self._stack(mods, self.modalities_, self.n_features_, self.scales_)
        return self.nmf_.transform(stacked, features=cols)

    def score(self, X: Any, y: Any) -> float:
        """Cross-modal success on held-out pairs: the matching of thesis section 6.6.1 (Fig. 6.3).

        Every example of X is seen in one modality ``a`` (its internal representation from
        ``a`` alone, :meth:`transform`) and matched against references seen in another
        modality ``b``: for each concept present among the *other* examples of X, one of
        them is drawn at random and represented from ``b`` alone; the example succeeds when
        the nearest reference (cosine dissimilarity of the internal representations,
        :data:`SCORE_METRIC`) has its concept. This is chapter 6's "internal space"
        comparison (:func:`~mmconcepts.multimodal.matching_success_rate` over
        :data:`SCORE_DRAWS` draws per example), except that an example's own view in ``b`` is
        never among its references, so the score measures concepts shared across
        modalities, not the recognition of a pair. The score is the mean over every ordered
        pair of distinct modalities (a -> b and b -> a both count) of the fraction of
        successes. Higher is better, as scikit-learn's model selection expects.

        Chance level: ``1 / K``, K the number of concepts among the other examples (the
        number of concepts in ``y`` when each has at least two examples), for a learner whose
        representations say nothing of the concepts. An example whose concept has no other
        example in X cannot be matched and is left out.

        The draws are seeded: from an int ``random_state`` (on a stream of its own, not the
        learner's), else from a fixed seed, so a fitted learner's score is deterministic and
        every candidate of a grid search is scored on the same draws.

        Parameters
        ----------
        X : mapping of str to array-like, or {array-like, sparse matrix} of shape (n_samples, n_features)
            Held-out examples in at least two modalities, as :meth:`transform` takes them.
        y : array-like of shape (n_samples,)
            The concept of each example.

        Returns
        -------
        float
            In [0, 1].

        Raises
        ------
        DataError
            Without ``y``, with ``y`` of another length than X, with fewer than two
            modalities, or when no example's concept has another example in X.
        """
        mods = self._observed(X)
        names = [m for m in self.modalities_ if m in mods]
        if len(names) < 2:
            raise DataError(f"score matches examples across modalities: X needs at least two of {self.modalities_}; "
                            f"got {names}.")
        if y is None:
            raise DataError("score needs y, the concept of each example of X (an array of shape (n_samples,)).")
        y = np.asarray(y)
        n = next(iter(mods.values())).shape[0]
        if y.shape != (n,):
            raise DataError(f"y must have one concept per example of X, shape ({n},); got shape {y.shape}.")
        labels, inverse, counts = np.unique(y, return_inverse=True, return_counts=True)
        scored = np.flatnonzero(counts[inverse] >= 2)  # an example whose concept has another example in X
        if scored.size == 0:
            raise DataError(f"score needs concepts with at least two examples in X; every concept of y has one "
                            f"({labels.size} example(s)).")
        W = {m: self.transform({m: mods[m]}) for m in names}
        directions = [(a, b) for a in names for b in names if a != b]
        seed = ([int(self.random_state), _SCORE_STREAM] if isinstance(self.random_state, (int, np.integer))
                else _SCORE_STREAM)
        rates = []
        for (a, b), stream in zip(directions, np.random.SeedSequence(seed).spawn(len(directions))):
            D = pairwise_divergence(W[a], W[b], SCORE_METRIC)
            rng = np.random.default_rng(stream)
            wins = 0.0
            for i in scored:
                others = np.flatnonzero(np.arange(n) != i)
                wins += matching_success_rate(D[i:i + 1, others], y[i:i + 1], y[others], n_draws=SCORE_DRAWS,
                                              random_state=rng)
            rates.append(wins / scored.size)
        return float(np.mean(rates))

    def reconstruct(self, W: Any, modality: str | Sequence[str]) -> np.ndarray:
        """Expected perception in ``modality`` from internal representations, in its own units.

        Parameters
        ----------
        W : array-like of shape (n_samples, n_components)
        modality : str or sequence of str
            One modality, or several (their reconstructions side by side).

        Returns
        -------
        ndarray of shape (n_samples, sum of the modalities' n_features)
        """
        check_is_fitted(self)
        if isinstance(modality, str):
            names = [modality]
        elif isinstance(modality, Sequence) and modality and all(isinstance(m, str) for m in modality):
            names = list(modality)
        else:
            raise DataError(f"modality must be a modality name or a non-empty sequence of names among "
                            f"{self.modalities_}; got {modality!r}.")
        try:
            W = np.asarray(W, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise DataError(f"W must be a numeric array of shape (n_samples, {self.components_.shape[0]}) ({exc}).") \
                from None
        if W.ndim != 2 or W.shape[1] != self.components_.shape[0]:
            raise DataError(f"W must be (n_samples, {self.components_.shape[0]}); got shape {W.shape}.")
        if not np.isfinite(W).all() or (W < 0).any():
            raise DataError("W must be finite and nonnegative (internal representations from transform).")
        out = []
        for name in names:
            part = W @ self.components_[:, self._slice(name)]
            part *= self.scales_[name]
            out.append(part)
        return out[0] if len(out) == 1 else np.hstack(out)

    @property
    def n_iter_(self) -> int:
        """Iterations of the last :meth:`fit` or :meth:`partial_fit` call (``nmf_.n_iter_``)."""
        check_is_fitted(self, "nmf_")
        return int(self.nmf_.n_iter_)

    def component_slice(self, modality: str) -> slice:
        """Columns of ``components_`` belonging to ``modality``."""
        check_is_fitted(self)
        return self._slice(modality)

    # ------------------------------------------------------------------ persistence
    def _get_state(self) -> dict[str, Any]:
        state = super()._get_state()
        state.pop("components_", None)  # the same array as nmf_.components_, saved once with nmf_
        return state

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        self.components_ = self.nmf_.components_

    def _check_loaded_state(self) -> None:
        """The loaded modalities, widths, scales and dictionary agree (an edited file fails here, naming itself)."""
        names = self.modalities_
        if not (isinstance(names, list) and names and all(isinstance(m, str) for m in names)
                and len(set(names)) == len(names)):
            raise DataError(f"modalities_ must be a non-empty list of distinct names; got {names!r}.")
        for what, table in (("n_features_", self.n_features_), ("scales_", self.scales_)):
            if not isinstance(table, dict) or sorted(table) != sorted(names):
                raise DataError(f"{what} must have one entry per modality {names}; got {table!r}.")
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in self.n_features_.values()):
            raise DataError(f"n_features_ must be positive integers; got {self.n_features_!r}.")
        if not all(isinstance(v, float) and np.isfinite(v) and v > 0 for v in self.scales_.values()):
            raise DataError(f"scales_ must be finite positive numbers; got {self.scales_!r}.")
        if not isinstance(self.nmf_, NMF):
            raise DataError(f"nmf_ must be a fitted NMF; got {type(self.nmf_).__name__}.")
        H = self.components_
        want = (int(self.n_components), sum(self.n_features_.values()))
        if not isinstance(H, np.ndarray) or H.dtype.kind != "f" or H.shape != want:
            raise DataError(f"the dictionary must be a float array of shape {want}; got "
                            f"{getattr(H, 'shape', type(H).__name__)}.")
        if not np.isfinite(H).all() or (H < 0).any():
            raise DataError("the dictionary holds negative, NaN or infinite values.")

    @classmethod
    def _load_other_version(cls, path: Path, header: dict, z: Any) -> MultimodalNMF:
        """Read a version-1 file: ``components`` and a header with modalities, n_features, scales."""
        if header.get("format_version") != 1:
            return super()._load_other_version(path, header, z)
        try:
            components = np.asarray(z["components"], dtype=np.float64)
            model = cls(**header["params"])
            names = list(header["modalities"])
            n_features = {m: int(header["n_features"][m]) for m in names}
            scales = {m: float(header["scales"][m]) for m in names}
        except (KeyError, TypeError, ValueError) as e:
            raise DataFormatError(f"{path}: a corrupt saved MultimodalNMF ({type(e).__name__}: {e}).") from None
        if components.shape != (model.n_components, sum(n_features.values())):
            raise DataFormatError(f"{path}: dictionary of shape {components.shape} does not match its header.")
        # A version-1 file holds only the inner NMF's dictionary: the NMF is restored from
        # the part of a saved NMF's state that its transform uses (dictionary and shape).
        nmf = model._nmf()
        nmf._set_state({"components_": components, "n_components_": components.shape[0],
                        "n_features_in_": components.shape[1]})
        model._set_state({"modalities_": names, "n_features_": n_features, "scales_": scales, "nmf_": nmf})
        try:
            model._check_loaded_state()
        except ValueError as e:
            raise DataFormatError(f"{path}: a corrupt saved MultimodalNMF ({e}).") from None
        return model
