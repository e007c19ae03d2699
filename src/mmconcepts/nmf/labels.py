"""Learning labels from weak supervision by label sets with NMF (thesis sections 3.3.2, 5.4).

Each training example comes with a *set* of labels (the gestures of a choreography,
thesis section 3.3; the keywords of an utterance, section 5.4) without saying which
part of the example each label describes. :class:`LabelNMF` factorizes the stacked
matrix [features, labels]; its dictionary ties feature patterns to labels, and new
examples are labelled by reconstructing their label part from their features alone.

Orientation: X is (n_samples, n_features), Y is (n_samples, n_labels), one example per
row, and [X, Y] ~ W @ H. The thesis writes V = (V_motion; V_language) ~ W H with
examples as columns: its V_motion, V_language are our X.T, Y.T, its W_motion,
W_language are our ``components_[:, :n_features].T`` and ``components_[:, n_features:].T``,
its H is our W.T.

Contents
--------
LabelNMF
    The multi-label classifier (scikit-learn API).
make_svm_baseline
    The thesis' baseline: one linear SVM per label (section 3.3.4).
DEFAULT_THRESHOLD_GRID
    The thresholds tried by cross-validation.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
from sklearn.base import (
    BaseEstimator,
    ClassifierMixin,
    ClassNamePrefixFeaturesOutMixin,
    TransformerMixin,
    clone,
)
from sklearn.exceptions import DataConversionWarning
from sklearn.model_selection import KFold
from sklearn.utils.multiclass import type_of_target
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import (
    HasMethods,
    Interval,
    Options,
    check_nonnegative_matrix,
    check_random_state,
    validate_params,
)
from ..errors import DataError, ParameterError
from ._estimator import NMF
from .scores import l_full_curve

__all__ = ["DEFAULT_THRESHOLD_GRID", "LabelNMF", "make_svm_baseline"]

#: Thresholds tried when ``threshold='cv'``: 0.05, 0.075, ..., 0.95 (37 values), in the
#: units of the label vectors (a label present with weight 1 and perfectly reconstructed
#: scores 1, an absent one 0), since :meth:`LabelNMF.label_activations` undoes the
#: label weight.
DEFAULT_THRESHOLD_GRID = np.round(np.linspace(0.05, 0.95, 37), 4)

#: The thresholds eta that decide something: the activations are >= 0, so eta <= 0 predicts every
#: label of every example; a perfectly reconstructed present label scores 1.
_THRESHOLD = Interval("real", 0, 1, closed="right")
_THRESHOLD_HINT = ("Label activations are >= 0 (eta <= 0 predicts every label) and a perfectly reconstructed "
                   "present label scores 1; the thesis' thresholds are in (0, 1), 'cv' chooses one.")


def _check_label_matrix(Y: Any, n_samples: int | None = None) -> np.ndarray:
    """Y as a float 0/1 array of shape (n_samples, n_labels), or a DataError naming the problem."""
    Y = np.asarray(Y.toarray() if sp.issparse(Y) else Y)
    if Y.ndim != 2:
        raise DataError(
            f"Y must be a 2-D binary indicator matrix (n_samples, n_labels); got shape {Y.shape}. "
            "Build it from label sets with sklearn.preprocessing.MultiLabelBinarizer().fit_transform(label_sets), "
            "or pass a 1-D vector of class labels for single-label data."
        )
    if Y.dtype != bool:
        if not np.issubdtype(Y.dtype, np.number):
            raise DataError(f"Y must hold 0/1 values; got dtype {Y.dtype}.")
        ok = np.isin(Y, (0, 1))
        if not ok.all():
            bad = np.unique(Y[~ok])[:5]
            raise DataError(
                f"Y must be binary (0/1 indicator of each label); found other values, e.g. {bad.tolist()}. "
                "Use sklearn.preprocessing.MultiLabelBinarizer on the label sets."
            )
    if Y.shape[1] == 0:
        raise DataError("Y has 0 label columns; give at least one label.")
    if n_samples is not None and Y.shape[0] != n_samples:
        raise DataError(
            f"X has {n_samples} samples but Y has {Y.shape[0]} rows; give one label row per example."
        )
    return Y.astype(np.float64)


class LabelNMF(SaveLoadMixin, ClassNamePrefixFeaturesOutMixin, ClassifierMixin, TransformerMixin, BaseEstimator):
    """Multi-label classification from label sets by NMF on stacked [features, labels].

    Thesis sections 3.3.2 (choreographies: motion + gesture labels) and 5.4 (utterances:
    sound + keyword labels). Training factorizes

    .. math:: [X,\\ \\lambda Y] \\approx W H = W\\,[H_{feat},\\ H_{lab}],
              \\qquad \\min_{W, H \\ge 0} D_\\beta([X, \\lambda Y] \\,|\\, WH)

    (thesis: V = (V_motion; V_language) ~ W H with examples as columns, so its
    W_motion = our H_feat.T and W_language = our H_lab.T). A new example x is labelled in
    the thesis' two steps: its coefficients are fitted on the feature part of the
    dictionary alone, ``w_x = argmin_{w >= 0} D_beta(x | w H_feat)`` (multiplicative
    updates of the coefficients only, the dictionary fixed), then its label activations
    are reconstructed, ``y_hat = w_x H_lab / lambda``. Those are continuous; a label set
    is obtained by the thesis' threshold, ``y_hat_j >= eta``, with eta chosen by
    cross-validation on the training data (section 3.3.3).

    Scaling of the two parts. The beta-divergence sums the errors on the feature and the
    label columns, so their relative magnitude decides how much each part shapes the
    dictionary (thesis section 6.4: "in order for the error in each modality to be
    treated on a fair level by the algorithm it is important that the average values in
    the representations are of similar magnitude", obtained there by normalizing each
    modality by its average L1 norm; chapter 3 does not say how its two parts were
    scaled). ``label_weight='l1'`` applies that rule: X is left as given and Y is
    multiplied by ``lambda = mean_i ||x_i||_1 / mean_i ||y_i||_1`` so that
    both parts have the same average L1 norm per example. Scaling only Y is equivalent to
    normalizing both parts (the minimisers of a beta-divergence scale with the data) and
    lets :meth:`label_activations` take raw features. The reconstruction is divided by
    lambda again, so scores are in label units whatever the weight.

    Parameters
    ----------
    n_components : int, default=150
        Number of atoms k (thesis: k = 150 for the choreographies).
    beta_loss : float or {'frobenius', 'kullback-leibler', 'itakura-saito'}, default=2.0
        The thesis compares Frobenius (2) and Kullback-Leibler (1), Table 3.2. beta <= 0
        is refused: the label part holds zeros.
    max_iter : int, default=200
        Multiplicative-update iterations of the training factorization.
    tol : float, default=1e-4
        Stopping tolerance of :class:`~mmconcepts.nmf.NMF`.
    label_weight : 'l1' or float > 0, default='l1'
        Weight lambda of the label part (see above); a float is used as is.
    threshold : 'cv' or float in (0, 1], default='cv'
        eta (label activations are >= 0, so eta <= 0 would predict every label; a perfectly
        reconstructed present label scores 1). 'cv' chooses it by ``cv``-fold
        cross-validation on the training data: each inner fold is fitted once, its
        validation examples are scored, and l_full is
        evaluated on them for every threshold of ``threshold_grid`` at once (each inner
        fit is a full LabelNMF fit of the fold, with its own label weight); the
        threshold with the best l_full pooled over the validation folds is kept (among
        ties, the median one, the middle of the plateau of thesis Fig. 3.7).
    threshold_grid : array-like of float in (0, 1], optional
        Thresholds tried by 'cv'. Default :data:`DEFAULT_THRESHOLD_GRID`,
        0.05 to 0.95 by 0.025.
    cv : int or scikit-learn splitter, default=5
        An int k uses ``KFold(k, shuffle=True)`` seeded from ``random_state``.
    init : str, optional
        Initialization of the training factorization (see :func:`~mmconcepts.nmf.beta_nmf`).
    solver, update_rule : str
        Passed to :class:`~mmconcepts.nmf.NMF` (default: multiplicative updates with the
        MM exponent, which for 1 <= beta <= 2 are the thesis' plain updates).
    transform_max_iter : int, optional
        Iterations used to fit the coefficients of new examples (default ``max_iter``).
    random_state : int, numpy.random.Generator or None
        Resolved once in :meth:`fit`; seeds the cross-validation split and each fit.
    n_jobs : int, optional
        Inner folds fitted in parallel by joblib (None: one at a time).

    Attributes
    ----------
    nmf_ : NMF
        The factorization of the stacked training matrix; ``nmf_.components_`` is
        ``(n_components, n_features_in_ + n_labels_)``. Built by
        :meth:`NMF.from_params <mmconcepts.nmf.NMF.from_params>`: this estimator's NMF
        parameters, with a seed drawn from ``random_state``.
    label_weight_ : float
        The weight lambda used.
    threshold_ : float
        The threshold eta used by :meth:`predict` (None after a single-label fit, where
        :meth:`predict` takes the best-scored class).
    threshold_grid_ : ndarray or None
        The thresholds tried by cross-validation (None without it).
    cv_scores_ : ndarray of shape (n_folds, n_thresholds) or None
        l_full of each validation fold at each threshold.
    cv_mean_scores_ : ndarray of shape (n_thresholds,) or None
        l_full pooled over all validation examples (weighted by fold size).
    classes_ : ndarray
        ``arange(n_labels)`` for an indicator Y, the sorted classes for a 1-D y.
    n_labels_ : int
    n_features_in_ : int
    n_iter_ : int
        Iterations of the final training factorization.

    Notes
    -----
    Label sets to an indicator matrix::

        from sklearn.preprocessing import MultiLabelBinarizer
        mlb = MultiLabelBinarizer()
        Y = mlb.fit_transform([{"clap", "walk"}, {"punch", "squat", "wave"}, ...])
        model = LabelNMF(150).fit(X, Y)
        mlb.inverse_transform(model.predict(X_new))   # back to label sets

    A 1-D y of class labels (one label per example, the thesis' single-gesture
    experiment) is accepted too: it is one-hot encoded, and :meth:`predict` returns the
    best-scored class (the l_single decision), so no threshold is needed.

    Examples
    --------
    >>> import numpy as np
    >>> from mmconcepts.nmf import LabelNMF
    >>> rng = np.random.default_rng(0)
    >>> patterns = rng.random((4, 30)) ** 4
    >>> Y = np.zeros((60, 4), int)
    >>> for row in Y:
    ...     row[rng.choice(4, 2, replace=False)] = 1
    >>> X = Y @ patterns + 0.01 * rng.random((60, 30))
    >>> model = LabelNMF(8, random_state=0).fit(X, Y)
    >>> model.label_activations(X).shape
    (60, 4)
    >>> bool(np.all((model.decision_function(X) >= 0) == model.predict(X)))
    True
    """

    _parameter_constraints: dict = {
        "n_components": [Interval("int", 1)],  # NMF's None (min(n_samples, n_features)) is not offered
        **{name: NMF._parameter_constraints[name] for name in (
            "beta_loss", "max_iter", "tol", "init", "solver", "update_rule", "transform_max_iter", "random_state")},
        "label_weight": [Interval("real", 0, None, closed="neither"), Options("l1")],
        "threshold": [_THRESHOLD, Options("cv")],
        "threshold_grid": ["array-like", None],
        "cv": [Interval("int", 2), HasMethods("split")],
        "n_jobs": [Interval("int"), None],
    }
    _persisted_private = ("_single_label",)
    # fitted attributes that may be None (the threshold search did not run)
    threshold_: float | None
    threshold_grid_: np.ndarray | None
    cv_scores_: np.ndarray | None
    cv_mean_scores_: np.ndarray | None

    def __init__(
        self,
        n_components: int = 150,
        *,
        beta_loss: float | str = 2.0,
        max_iter: int = 200,
        tol: float = 1e-4,
        label_weight: float | str = "l1",
        threshold: float | str = "cv",
        threshold_grid: Any = None,
        cv: Any = 5,
        init: str | None = None,
        solver: Literal["mu", "pg"] = "mu",
        update_rule: Literal["mm", "heuristic"] = "mm",
        transform_max_iter: int | None = None,
        random_state: Any = None,
        n_jobs: int | None = None,
    ):
        self.n_components = n_components
        self.beta_loss = beta_loss
        self.max_iter = max_iter
        self.tol = tol
        self.label_weight = label_weight
        self.threshold = threshold
        self.threshold_grid = threshold_grid
        self.cv = cv
        self.init = init
        self.solver = solver
        self.update_rule = update_rule
        self.transform_max_iter = transform_max_iter
        self.random_state = random_state
        self.n_jobs = n_jobs

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.positive_only = True
        tags.input_tags.sparse = True
        tags.classifier_tags.multi_label = True
        tags.target_tags.multi_output = True
        tags.transformer_tags.preserves_dtype = ["float64", "float32"]
        return tags

    @property
    def _n_features_out(self) -> int:
        return self.nmf_.components_.shape[0]

    # ------------------------------------------------------------------ fitting
    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints,
                        hints={"cv": "Give a number of folds or a splitter such as sklearn's KFold.",
                               "threshold": _THRESHOLD_HINT})
        from ._beta import resolve_beta

        if resolve_beta(self.beta_loss) <= 0:
            raise ParameterError(
                f"beta_loss must be > 0 for LabelNMF: the label part holds zeros; got {self.beta_loss!r}. "
                "Use 'frobenius' (2) or 'kullback-leibler' (1)."
            )

    def _grid(self) -> np.ndarray:
        if self.threshold_grid is None:
            return DEFAULT_THRESHOLD_GRID.copy()
        grid = np.asarray(self.threshold_grid, dtype=np.float64).ravel()
        if grid.size == 0 or not np.isfinite(grid).all():
            raise ParameterError(f"threshold_grid must be a non-empty array of finite floats; got {self.threshold_grid!r}.")
        outside = grid[(grid <= 0) | (grid > 1)]
        if outside.size:
            raise ParameterError(f"threshold_grid must hold thresholds in (0, 1]; got {outside.tolist()}. "
                                 + _THRESHOLD_HINT)
        return np.unique(grid)

    def fit(self, X: Any, y: Any) -> LabelNMF:
        """Learn the dictionary from examples X and their label sets, and choose the threshold.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)
            Nonnegative features (histograms, bags of words...).
        y : {array-like, sparse matrix} of shape (n_samples, n_labels), or array-like of shape (n_samples,)
            Binary indicator of the labels of each example (see Notes of the class for
            label sets), or one class label per example.

        Returns
        -------
        self

        Raises
        ------
        DataError
            Negative, NaN or infinite X; Y not binary; different numbers of rows; no
            label at all in Y.
        ParameterError
            A parameter out of range; ``cv`` larger than the number of samples.
        """
        self._check_params()
        X = check_nonnegative_matrix(X, "X")
        n = X.shape[0]
        if y is None:
            raise DataError(
                f"{type(self).__name__} requires y to be passed, but the target y is None: give the label "
                "indicator matrix Y (or one class label per example)."
            )
        yv = y.toarray() if sp.issparse(y) else np.asarray(y)
        kind = type_of_target(yv) if yv.size else "unknown"
        if kind == "continuous":
            raise DataError(
                "Unknown label type: continuous. y must be a binary indicator matrix of label sets or one "
                "class label per example, not real values."
            )
        if yv.ndim == 2 and yv.shape[1] == 1 and kind == "multiclass":
            warnings.warn(
                "A column-vector y was passed when a 1-D array was expected; it is read as one class label "
                "per example. Please use y.ravel().",
                DataConversionWarning,
                stacklevel=2,
            )
            yv = yv.ravel()
        if yv.ndim == 1:
            if yv.shape[0] != n:
                raise DataError(f"X has {n} samples but y has {yv.shape[0]}; give one label per example.")
            if yv.dtype.kind == "f" and not np.isfinite(yv).all():
                raise DataError("y contains NaN or infinite values; give a class label to every example.")
            self.classes_, codes = np.unique(yv, return_inverse=True)
            Y = np.zeros((n, self.classes_.size))
            Y[np.arange(n), codes] = 1.0
            self._single_label = True
        else:
            Y = _check_label_matrix(yv, n)
            self.classes_ = np.arange(Y.shape[1])
            self._single_label = False
        self.n_labels_ = Y.shape[1]

        rng = check_random_state(self.random_state)
        fit_seed, split_seed = (int(s) for s in rng.integers(0, 2**31 - 1, size=2))
        search = not self._single_label and self.threshold == "cv"
        splitter = self._splitter(n, split_seed) if search else None  # bad cv fails before any fit
        self._fit_factorization(X, Y, fit_seed)

        self.threshold_grid_ = self.cv_scores_ = self.cv_mean_scores_ = None
        if self._single_label:
            self.threshold_ = None
        elif search:
            self._choose_threshold(X, Y, splitter, rng)
        else:
            self.threshold_ = float(self.threshold)
        return self

    def _fit_factorization(self, X, Y: np.ndarray, seed: int) -> None:
        if self.label_weight == "l1":
            y_norm = Y.sum() / Y.shape[0]
            if y_norm == 0:
                raise DataError("Y has no positive label at all; every example needs its label set.")
            x_norm = float(X.sum()) / X.shape[0]
            if x_norm == 0:
                raise DataError("X is all zeros; the features carry no information to learn labels from.")
            weight = x_norm / y_norm
        else:
            weight = float(self.label_weight)
        if sp.issparse(X):
            V = sp.hstack([X, sp.csr_matrix(weight * Y, dtype=X.dtype)], format="csr")
        else:
            V = np.hstack([X, (weight * Y).astype(X.dtype)])
        self.label_weight_ = weight
        self.n_features_in_ = X.shape[1]
        self.nmf_ = NMF.from_params(self, random_state=seed).fit(V)
        self.n_iter_ = self.nmf_.n_iter_

    def _splitter(self, n: int, split_seed: int):
        if isinstance(self.cv, (numbers.Integral, np.integer)) and not isinstance(self.cv, bool):
            k = int(self.cv)
            if k > n:
                raise ParameterError(f"cv={k} folds need at least {k} training samples; got {n}. Lower cv.")
            splitter = KFold(k, shuffle=True, random_state=split_seed)
        else:  # a splitter (validated by the constraints table)
            splitter = self.cv
        self._grid()  # validated before any fit too
        return splitter

    def _choose_threshold(self, X, Y: np.ndarray, splitter, rng: np.random.Generator) -> None:
        from joblib import Parallel, delayed

        grid = self._grid()
        n = X.shape[0]
        folds = list(splitter.split(np.zeros((n, 1))))
        seeds = [int(s) for s in rng.integers(0, 2**31 - 1, size=len(folds))]
        inner = clone(self).set_params(threshold=0.5, n_jobs=None)
        curves = Parallel(n_jobs=self.n_jobs)(
            delayed(_fold_curve)(inner, X, Y, train, val, seed, grid) for (train, val), seed in zip(folds, seeds)
        )
        sizes = np.array([len(val) for _, val in folds], dtype=np.float64)
        self.cv_scores_ = np.vstack(curves)
        self.cv_mean_scores_ = sizes @ self.cv_scores_ / sizes.sum()
        best = np.flatnonzero(self.cv_mean_scores_ >= self.cv_mean_scores_.max() - 1e-12)
        self.threshold_ = float(grid[best[len(best) // 2]])
        self.threshold_grid_ = grid

    # ------------------------------------------------------------------ using the dictionary
    def _check_X(self, X: Any):
        check_is_fitted(self, "nmf_")
        X = check_nonnegative_matrix(X, "X")
        if X.shape[1] != self.n_features_in_:
            raise DataError(
                f"X has {X.shape[1]} features, but {type(self).__name__} is expecting {self.n_features_in_} "
                "features as input."
            )
        return X

    def transform(self, X: Any) -> np.ndarray:
        """Internal representation: coefficients of X on the feature part of the dictionary.

        Thesis section 3.3.2 step 1: ``argmin_w D_beta(x | w H_feat)`` with the
        dictionary fixed.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)

        Returns
        -------
        ndarray of shape (n_samples, n_components)
        """
        X = self._check_X(X)
        return self.nmf_.transform(X, features=slice(0, self.n_features_in_))

    def label_activations(self, X: Any) -> np.ndarray:
        """Reconstructed label activations y_hat (thesis section 3.3.2 step 2), in label units.

        ``transform(X) @ H_lab / label_weight_``: a label present with weight 1 and
        perfectly reconstructed scores 1, an absent one 0. This is the score the thesis
        thresholds (:meth:`predict`) and ranks (:meth:`predict_given_number`).

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)

        Returns
        -------
        ndarray of shape (n_samples, n_labels)
            One column per label (per class after a single-label fit).
        """
        W = self.transform(X)
        labels = slice(self.n_features_in_, self.n_features_in_ + self.n_labels_)
        return self.nmf_.inverse_transform(W, features=labels) / self.label_weight_

    def decision_function(self, X: Any) -> np.ndarray:
        """Confidence scores in scikit-learn's convention: positive means predicted.

        After a multi-label fit, ``label_activations(X) - threshold_``, so that
        ``decision_function(X) >= 0`` is exactly :meth:`predict`. After a single-label
        fit (1-D y), the label activations themselves (the best-scored class is
        predicted), or for two classes the second's minus the first's.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)

        Returns
        -------
        ndarray of shape (n_samples, n_labels), or (n_samples,) after a 2-class single-label fit

        Notes
        -----
        Earlier development versions returned y_hat itself after a multi-label fit; it
        is :meth:`label_activations` now.
        """
        scores = self.label_activations(X)
        if self._single_label:
            return scores[:, 1] - scores[:, 0] if self.n_labels_ == 2 else scores
        return scores - self.threshold_

    def predict(self, X: Any) -> np.ndarray:
        """Label sets: ``y_hat >= threshold_`` (thesis section 3.3.3).

        After a single-label fit (1-D y), the best-scored class instead.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)

        Returns
        -------
        ndarray of int of shape (n_samples, n_labels), or of shape (n_samples,) after a 1-D y
        """
        scores = self.label_activations(X)
        if self._single_label:
            return self.classes_[np.argmax(scores, axis=1)]
        return (scores >= self.threshold_).astype(np.int64)

    def predict_given_number(self, X: Any, n_labels_per_sample: Any) -> np.ndarray:
        """The n best-scored labels of each example, n given (the decision of l_given_number).

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)
        n_labels_per_sample : int or array-like of int of shape (n_samples,)
            How many labels to give each example, in [0, n_labels]; e.g. ``Y.sum(1)``.

        Returns
        -------
        ndarray of int of shape (n_samples, n_labels)
            1 for the n highest scores of each row. Equal scores are ranked by label
            index (lowest first), whereas :func:`~mmconcepts.nmf.scores.l_given_number`
            counts a tie at the boundary as a failure.
        """
        scores = self.label_activations(X)
        n, L = scores.shape
        counts = np.asarray(n_labels_per_sample)
        if counts.dtype.kind == "f" and np.all(np.isfinite(counts)) and np.all(counts == np.round(counts)):
            counts = counts.astype(np.int64)  # e.g. Y.sum(axis=1) of a float Y
        if counts.ndim == 0:
            counts = np.full(n, counts)
        if counts.shape != (n,) or not (np.issubdtype(counts.dtype, np.integer) or counts.dtype == bool):
            raise DataError(
                f"n_labels_per_sample must be an int or {n} ints (one per example); got {np.asarray(n_labels_per_sample)!r:.80}."
            )
        if counts.size and (counts.min() < 0 or counts.max() > L):
            raise DataError(f"n_labels_per_sample must be in [0, {L}]; got values in [{counts.min()}, {counts.max()}].")
        order = np.argsort(-scores, axis=1, kind="stable")
        rank = np.empty_like(order)
        rank[np.arange(n)[:, None], order] = np.arange(L)[None, :]
        return (rank < counts[:, None]).astype(np.int64)


def _fold_curve(inner: LabelNMF, X, Y: np.ndarray, train, val, seed: int, grid: np.ndarray) -> np.ndarray:
    """Fit one inner fold once (fixed threshold: no nested search) and score all thresholds on its validation part."""
    model = clone(inner).set_params(random_state=seed).fit(X[train], Y[train])
    return l_full_curve(Y[val], model.label_activations(X[val]), grid)


_SVM_BASELINE_CONSTRAINTS: dict = {
    "C": [Interval("real", 0, None, closed="neither")],
    "max_iter": [Interval("int", 1)],
    "scale": ["boolean"],
    "random_state": ["random_state"],
}


def make_svm_baseline(*, C: float = 1.0, max_iter: int = 10000, scale: bool = True, random_state: Any = None):
    """The thesis' baseline: one linear SVM per label (thesis section 3.3.4, Tables 3.2, 3.3).

    ``OneVsRestClassifier(make_pipeline(StandardScaler(), LinearSVC(C)))`` from
    scikit-learn (the thesis used scikit-learn's SVMs). Features are standardised first,
    as usual for SVMs: on raw histograms (values summing to one per degree of freedom) an
    SVM with C = 1 is so strongly regularised that it predicts almost no label
    (``scale=False`` gives that plain SVM; ch3-choreography reports both side by side).
    Fitted on a binary indicator Y, :meth:`predict` gives the label
    set directly, each label's own SVM deciding (decision value > 0), "with no need for
    thresholding" as in the thesis, so it serves l_full; :meth:`decision_function`
    gives the per-label decision values for :func:`~mmconcepts.nmf.scores.l_given_number`
    or :func:`~mmconcepts.nmf.scores.l_single`. A label absent from the training data
    is never predicted.

    Parameters
    ----------
    C : float, default=1.0
        Regularisation of each SVM (scikit-learn's default; the thesis does not say).
    max_iter : int, default=10000
    scale : bool, default=True
        Standardise each feature on the training data (``StandardScaler``, which needs
        dense input) before the SVM.
    random_state : int, numpy.random.Generator or None

    Returns
    -------
    sklearn.multiclass.OneVsRestClassifier
    """
    from sklearn.multiclass import OneVsRestClassifier
    from sklearn.svm import LinearSVC

    validate_params(dict(C=C, max_iter=max_iter, scale=scale, random_state=random_state),
                    _SVM_BASELINE_CONSTRAINTS, owner="make_svm_baseline")
    seed = int(check_random_state(random_state).integers(0, 2**31 - 1))
    svm = LinearSVC(C=C, max_iter=max_iter, random_state=seed)
    if scale:
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        svm = make_pipeline(StandardScaler(), svm)
    return OneVsRestClassifier(svm)
