"""Score functions for label reconstruction (thesis section 3.3.3).

A learner reconstructs, for each example, a vector of label activations
``scores[i]`` (continuous) that is compared with the ground truth ``Y_true[i]``
(binary). Each score below is 1 or 0 for one example and is averaged over the
examples, giving a number in [0, 1] (thesis: "the score function defined above for
one example is averaged over all examples from the test set").

Orientation: one example per row. ``Y_true`` and ``scores`` are (n_samples, n_labels);
the thesis writes its label vectors y, y-hat as columns of V_language.

Ties. The thesis defines the scores with ``argmax`` and ``best(n, y_hat)``, "the set
containing the n labels having the best activation", which is ambiguous when scores
tie. Here an example counts as correct only when the choice is unambiguous: every true
label scores *strictly* higher than every other label. So a constant score vector is
never credited by luck of index order.

Contents
--------
l_single
    Single-label examples: is the highest-scored label the true one?
l_given_number
    The number n of true labels is given: are the n best-scored labels the true set?
l_full
    Exact match of the predicted label set (after thresholding) with the true set.
l_full_curve
    l_full of thresholded scores for many thresholds at once (thesis Fig. 3.7).
threshold_scores
    The thesis' ``threshold(y_hat, eta)_j = [y_hat_j >= eta]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import DataError

__all__ = ["l_full", "l_full_curve", "l_given_number", "l_single", "threshold_scores"]


def _dense(A: Any) -> np.ndarray:
    return np.asarray(A.toarray() if sp.issparse(A) else A)


def _check_indicator(Y: Any, name: str) -> np.ndarray:
    """A 2-D binary (0/1 or bool) matrix as a bool array, or a DataError saying what is wrong."""
    Y = _dense(Y)
    if Y.ndim != 2:
        raise DataError(
            f"{name} must be a 2-D binary indicator matrix (n_samples, n_labels); got shape {Y.shape}. "
            "Build one from label sets with sklearn.preprocessing.MultiLabelBinarizer."
        )
    if Y.dtype == bool:
        return Y
    if not np.issubdtype(Y.dtype, np.number):
        raise DataError(f"{name} must hold 0/1 values; got dtype {Y.dtype}.")
    if not np.isin(Y, (0, 1)).all():
        bad = np.unique(Y[~np.isin(Y, (0, 1))])[:5]
        raise DataError(
            f"{name} must be binary (0/1); found other values, e.g. {bad.tolist()}. "
            "To score continuous predictions, threshold them first (threshold_scores) or pass threshold=."
        )
    return Y.astype(bool)


def _check_scores(scores: Any, shape: tuple[int, ...] | None, name: str = "scores") -> np.ndarray:
    S = _dense(scores)
    if S.ndim != 2:
        raise DataError(f"{name} must be 2-D (n_samples, n_labels); got shape {S.shape}.")
    if not (np.issubdtype(S.dtype, np.number) or S.dtype == bool):
        raise DataError(f"{name} must hold numbers; got dtype {S.dtype}.")
    S = S.astype(np.float64, copy=False)
    if np.isnan(S).any():
        raise DataError(f"{name} contains NaN; scores must be comparable numbers.")
    if shape is not None and S.shape != shape:
        raise DataError(f"{name} has shape {S.shape} but the true labels have shape {shape}; they must match.")
    return S


def _masked_extremes(S: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row: the lowest score among true labels (+inf if none) and the highest among the others (-inf if none)."""
    if S.shape[1] == 0:
        raise DataError("the label matrix has 0 labels (columns); scores need at least one label.")
    min_true = np.where(Y, S, np.inf).min(axis=1)
    max_other = np.where(Y, -np.inf, S).max(axis=1)
    return min_true, max_other


def threshold_scores(scores: Any, threshold: float) -> np.ndarray:
    """Binary label sets from scores: ``threshold(y_hat, eta)_j = 1 if y_hat_j >= eta`` (thesis section 3.3.3).

    Parameters
    ----------
    scores : array-like of shape (n_samples, n_labels)
    threshold : float
        eta; a label is predicted when its score is greater than or equal to it.

    Returns
    -------
    ndarray of int of shape (n_samples, n_labels)
    """
    S = _check_scores(scores, None)
    return (S >= float(threshold)).astype(np.int64)


def l_single(y_true: Any, scores: Any) -> float:
    """Fraction of single-label examples whose highest-scored label is the true one.

    Thesis section 3.3.3, "Score function for the single gesture experiment":

    .. math:: l_{single}(\\hat y, y) = 1 \\text{ if } \\arg\\max_i \\hat y_i = \\arg\\max_i y_i,
              \\text{ else } 0,

    averaged over examples. Implemented: example i counts 1 when the score of its true
    label is strictly greater than the score of every other label (a tie for the
    maximum counts 0).

    Parameters
    ----------
    y_true : array-like of int of shape (n_samples,), or binary array of shape (n_samples, n_labels)
        The true label of each example, as an index into the columns of ``scores``, or
        as a one-hot indicator matrix with exactly one 1 per row.
    scores : array-like of shape (n_samples, n_labels)
        Reconstructed label activations (any real values).

    Returns
    -------
    float in [0, 1]
    """
    S = _check_scores(scores, None)
    y = _dense(y_true)
    if y.ndim == 2:
        Y = _check_indicator(y, "y_true")
        if Y.shape != S.shape:
            raise DataError(f"y_true has shape {Y.shape} but scores has shape {S.shape}; they must match.")
        counts = Y.sum(axis=1)
        if not (counts == 1).all():
            i = int(np.flatnonzero(counts != 1)[0])
            raise DataError(
                f"l_single needs exactly one true label per example; example {i} has {int(counts[i])}. "
                "Use l_given_number or l_full for examples with several labels."
            )
    elif y.ndim == 1:
        if y.shape[0] != S.shape[0]:
            raise DataError(f"y_true has {y.shape[0]} examples but scores has {S.shape[0]}; they must match.")
        if not np.issubdtype(y.dtype, np.integer) or (y.size and (y.min() < 0 or y.max() >= S.shape[1])):
            raise DataError(
                f"y_true as a 1-D array must hold label indices in [0, {S.shape[1]}) (columns of scores); "
                f"got dtype {y.dtype}" + (f", range [{y.min()}, {y.max()}]." if y.size else ".")
            )
        Y = np.zeros(S.shape, dtype=bool)
        Y[np.arange(S.shape[0]), y] = True
    else:
        raise DataError(f"y_true must be 1-D label indices or a 2-D one-hot matrix; got shape {y.shape}.")
    if S.shape[0] == 0:
        raise DataError("l_single got 0 examples; it needs at least one.")
    min_true, max_other = _masked_extremes(S, Y)
    return float(np.mean(min_true > max_other))


def l_given_number(Y_true: Any, scores: Any) -> float:
    """Fraction of examples whose n best-scored labels are exactly the true labels, n = number of true labels.

    Thesis section 3.3.3, "the number of gestures is given": with #(y) the number of
    true labels and best(n, y_hat) the set of the n labels with the highest activations,

    .. math:: l_{given\\ number}(\\hat y, y) = 1 \\text{ if }
              best(\\#(y), y) = best(\\#(y), \\hat y), \\text{ else } 0,

    averaged over examples. Implemented: example i counts 1 when every true label scores
    strictly higher than every other label (min over true > max over others), which is
    best(n, y_hat) = true set with no tie at the boundary. An example with no true label
    (n = 0) or with all labels true counts 1 (best(0, .) is the empty set).

    Parameters
    ----------
    Y_true : binary array-like or sparse matrix of shape (n_samples, n_labels)
    scores : array-like of shape (n_samples, n_labels)

    Returns
    -------
    float in [0, 1]
    """
    Y = _check_indicator(Y_true, "Y_true")
    S = _check_scores(scores, Y.shape)
    if Y.shape[0] == 0:
        raise DataError("l_given_number got 0 examples; it needs at least one.")
    min_true, max_other = _masked_extremes(S, Y)
    return float(np.mean(min_true > max_other))


def l_full(Y_true: Any, Y_pred: Any, *, threshold: float | None = None) -> float:
    """Fraction of examples whose predicted label set equals the true set exactly.

    Thesis section 3.3.3, "exact reconstruction":

    .. math:: l_{full}(\\hat y, y) = 1 \\text{ if } y = threshold(\\hat y, \\eta),
              \\text{ else } 0, \\qquad threshold(\\hat y, \\eta)_j = [\\hat y_j \\ge \\eta],

    averaged over examples. This is scikit-learn's subset accuracy
    (``accuracy_score`` on indicator matrices).

    Parameters
    ----------
    Y_true : binary array-like or sparse matrix of shape (n_samples, n_labels)
    Y_pred : array-like or sparse matrix of shape (n_samples, n_labels)
        Binary predicted label sets; or, with ``threshold``, continuous scores y_hat.
    threshold : float, optional
        eta: when given, ``Y_pred`` holds scores and is thresholded with ``>= eta``.

    Returns
    -------
    float in [0, 1]
    """
    Y = _check_indicator(Y_true, "Y_true")
    if threshold is None:
        P = _check_indicator(Y_pred, "Y_pred")
    else:
        P = _check_scores(Y_pred, Y.shape, "Y_pred") >= float(threshold)
    if P.shape != Y.shape:
        raise DataError(f"Y_pred has shape {P.shape} but Y_true has shape {Y.shape}; they must match.")
    if Y.shape[0] == 0:
        raise DataError("l_full got 0 examples; it needs at least one.")
    return float(np.mean((P == Y).all(axis=1)))


def l_full_curve(Y_true: Any, scores: Any, thresholds: Any) -> np.ndarray:
    """l_full of ``threshold_scores(scores, eta)`` for every eta in ``thresholds`` (thesis Fig. 3.7).

    Computed exactly without thresholding each time: example i is reconstructed exactly
    at threshold eta iff max(scores of its other labels) < eta <= min(scores of its true
    labels), an interval found once per example. Hence, for every eta,
    ``l_full_curve <= l_given_number``: thresholding can only lose examples whose
    true labels are already the best ones.

    Parameters
    ----------
    Y_true : binary array-like or sparse matrix of shape (n_samples, n_labels)
    scores : array-like of shape (n_samples, n_labels)
    thresholds : array-like of shape (n_thresholds,)

    Returns
    -------
    ndarray of shape (n_thresholds,)
    """
    Y = _check_indicator(Y_true, "Y_true")
    S = _check_scores(scores, Y.shape)
    if Y.shape[0] == 0:
        raise DataError("l_full_curve got 0 examples; it needs at least one.")
    t = np.asarray(thresholds, dtype=np.float64).ravel()
    min_true, max_other = _masked_extremes(S, Y)
    ok = (max_other[:, None] < t[None, :]) & (t[None, :] <= min_true[:, None])
    return ok.mean(axis=0)
