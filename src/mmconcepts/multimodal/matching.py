"""Cross-modal matching (Thesis section 6.6.1, Fig. 6.3).

A learner trained on several modalities observes a *test example* in its test
modalities and must choose, among *reference examples* observed in other modalities
(one per semantic class), the one of the same class. The comparison happens in one of
three spaces:

- ``"internal"``: internal representations of the test and of the reference examples
  (:meth:`MultimodalNMF.transform` of each);
- ``"reference"``: the test example's expected perception in the reference modalities
  (:meth:`MultimodalNMF.reconstruct`) against the reference examples as observed;
- ``"test"``: each reference example's expected perception in the test modalities
  against the test example as observed.

Metrics (smaller is closer): ``"idiv"``, the I-divergence (generalised Kullback-Leibler
divergence, eq. 2.8) from the test side to the reference side on the data as they are,
which the thesis uses when the data are not normalised (section 6.6.1); ``"kl"``, the
Kullback-Leibler divergence after normalising both sides to sum to one; ``"kl_reversed"``;
``"kl_symmetric"`` (their sum); ``"euclidean"``; ``"cosine"`` (1 - cosine similarity).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import Interval, Options, check_random_state, validate_params
from ..errors import DataError


class CrossmodalModel(Protocol):
    """What the matching needs of a fitted learner (:class:`~mmconcepts.multimodal.MultimodalNMF`)."""

    def transform(self, X: Mapping[str, Any]) -> np.ndarray: ...

    def reconstruct(self, W: Any, modality: str | Sequence[str]) -> np.ndarray: ...

__all__ = ["METRICS", "SPACES", "pairwise_divergence", "crossmodal_distances", "matching_success_rate"]

METRICS = ("idiv", "kl", "kl_reversed", "kl_symmetric", "euclidean", "cosine")
SPACES = ("internal", "test", "reference")
_EPS = 1e-12

#: Parameters of the public functions, checked by :func:`~mmconcepts._validation.validate_params`.
_PAIRWISE_CONSTRAINTS: dict[str, list] = {"metric": [Options(*METRICS)]}
_CROSSMODAL_CONSTRAINTS: dict[str, list] = {"space": [Options(*SPACES)], "metric": [Options(*METRICS)]}
_SUCCESS_RATE_CONSTRAINTS: dict[str, list] = {"n_draws": [Interval("int", 1)], "random_state": ["random_state"]}


def _dense(X: Any) -> np.ndarray:
    return X.toarray() if sp.issparse(X) else np.asarray(X, dtype=np.float64)


def _kl(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """KL(p_i || q_j) for all pairs of rows (rows normalised to distributions)."""
    P = P + _EPS
    P /= P.sum(1, keepdims=True)
    log_q = Q + _EPS
    log_q /= log_q.sum(1, keepdims=True)
    np.log(log_q, out=log_q)
    plogp = np.log(P)
    plogp *= P
    return plogp.sum(1)[:, None] - P @ log_q.T


def _idiv(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """I-divergence D(p_i || q_j) = sum p log(p / q) - p + q for all pairs of rows (no normalisation)."""
    if (P < 0).any() or (Q < 0).any():
        raise DataError("the I-divergence needs nonnegative data.")
    Pe, Qe = P + _EPS, Q + _EPS
    q_sum = Qe.sum(1)
    log_q = np.log(Qe, out=Qe)
    plogp = np.log(Pe)
    plogp *= Pe
    return (plogp.sum(1) - Pe.sum(1))[:, None] - Pe @ log_q.T + q_sum[None, :]


def pairwise_divergence(A: Any, B: Any, metric: str = "kl") -> np.ndarray:
    """Dissimilarity of every row of A (test side) to every row of B (reference side).

    Parameters
    ----------
    A : array-like of shape (n_a, d)
    B : array-like of shape (n_b, d)
    metric : str
        One of :data:`METRICS`.

    Returns
    -------
    ndarray of shape (n_a, n_b)
    """
    validate_params({"metric": metric}, _PAIRWISE_CONSTRAINTS, owner="pairwise_divergence")
    try:
        A, B = _dense(A), _dense(B)
    except (TypeError, ValueError) as exc:
        raise DataError(f"A and B must be numeric arrays ({exc}).") from None
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[1]:
        raise DataError(f"A and B must be 2-D with the same number of columns; got {A.shape} and {B.shape}.")
    for name, M in (("A", A), ("B", B)):
        if not np.isfinite(M).all():
            raise DataError(f"{name} holds NaN or infinite values.")
        if metric != "euclidean" and metric != "cosine" and (M < 0).any():
            raise DataError(f"{name} holds negative values; the {metric!r} divergence compares nonnegative "
                            "histograms (use 'euclidean' or 'cosine' for signed data).")
        if metric == "euclidean" and M.size and np.abs(M).max() > _MAX_EUCLIDEAN:
            raise DataError(f"{name} holds values up to {np.abs(M).max():.3g}, whose squares overflow; rescale it.")
    if metric == "idiv":
        with np.errstate(over="ignore"):
            D = _idiv(A, B)
        if not np.isfinite(D).all():
            raise DataError("the I-divergence overflows on these values; rescale A and B.")
        return D
    if metric == "kl":
        return _kl(A, B)
    if metric == "kl_reversed":
        return _kl(B, A).T
    if metric == "kl_symmetric":
        return _kl(A, B) + _kl(B, A).T
    if metric == "euclidean":
        sq = (A * A).sum(1)[:, None] + (B * B).sum(1)[None, :] - 2 * A @ B.T
        return np.sqrt(np.maximum(sq, 0.0))
    # "cosine", the last metric the constraints admit; scale-invariant, so rows too large to square are scaled first
    if max(np.abs(A).max(initial=0.0), np.abs(B).max(initial=0.0)) > _MAX_EUCLIDEAN:
        A = A / np.maximum(np.abs(A).max(axis=1, keepdims=True), _EPS)
        B = B / np.maximum(np.abs(B).max(axis=1, keepdims=True), _EPS)
    na = np.linalg.norm(A, axis=1)[:, None]
    nb = np.linalg.norm(B, axis=1)[None, :]
    return 1.0 - (A @ B.T) / np.maximum(na * nb, _EPS)


#: Largest |value| the Euclidean distance takes: its squares (and their sums) must stay finite.
_MAX_EUCLIDEAN = 1e150


def _names(X: Mapping[str, Any], what: str) -> list[str]:
    if not isinstance(X, Mapping) or not X:
        raise DataError(f"{what} must be a non-empty mapping of modality names to arrays.")
    return list(X)


def crossmodal_distances(
    model: CrossmodalModel,
    X_test: Mapping[str, Any],
    X_ref: Mapping[str, Any],
    *,
    space: str = "internal",
    metric: str = "kl",
) -> np.ndarray:
    """Distances between test examples (test modalities) and reference examples (reference modalities).

    Parameters
    ----------
    model : MultimodalNMF
        A fitted learner that knows every modality used.
    X_test, X_ref : mapping of str to array-like
        Test examples in the test modalities; reference examples in the reference
        modalities (disjoint sets of modalities).
    space : {"internal", "test", "reference"}
    metric : str, one of :data:`METRICS`

    Returns
    -------
    ndarray of shape (n_test, n_ref)
    """
    validate_params({"space": space, "metric": metric}, _CROSSMODAL_CONSTRAINTS, owner="crossmodal_distances")
    test_mods, ref_mods = _names(X_test, "X_test"), _names(X_ref, "X_ref")
    if set(test_mods) & set(ref_mods):
        raise DataError(f"test and reference modalities must differ; both have {sorted(set(test_mods) & set(ref_mods))}.")
    if space == "internal":
        return pairwise_divergence(model.transform(X_test), model.transform(X_ref), metric)
    if space == "reference":
        expected = model.reconstruct(model.transform(X_test), ref_mods)
        observed = np.hstack([_dense(X_ref[m]) for m in ref_mods])
        return pairwise_divergence(expected, observed, metric)
    expected = model.reconstruct(model.transform(X_ref), test_mods)
    observed = np.hstack([_dense(X_test[m]) for m in test_mods])
    return pairwise_divergence(observed, expected, metric)


def matching_success_rate(
    D: ArrayLike,
    y_test: ArrayLike,
    y_ref: ArrayLike,
    *,
    n_draws: int = 10,
    random_state: Any = None,
) -> float:
    """Success rate of the Fig. 6.3 protocol from a test x reference distance matrix.

    For each test example and each draw, one reference example of every class is drawn
    at random among the candidates (``y_ref``); the test example succeeds when the
    closest of them has its class. With one candidate per class there is nothing to draw.

    Parameters
    ----------
    D : ndarray of shape (n_test, n_ref)
        From :func:`crossmodal_distances`.
    y_test : array-like of shape (n_test,)
    y_ref : array-like of shape (n_ref,)
    n_draws : int, default=10
        Draws of the reference set per test example (the rate is averaged over them).
    random_state : int, Generator or None

    Returns
    -------
    float
        The fraction of successes (chance is 1 / number of classes).
    """
    validate_params({"n_draws": n_draws, "random_state": random_state}, _SUCCESS_RATE_CONSTRAINTS,
                    owner="matching_success_rate")
    D = np.asarray(D, dtype=np.float64)
    y_test, y_ref = np.asarray(y_test), np.asarray(y_ref)
    if D.shape != (len(y_test), len(y_ref)):
        raise DataError(f"D must be (len(y_test), len(y_ref)) = ({len(y_test)}, {len(y_ref)}); got {D.shape}.")
    if np.isnan(D).any():
        raise DataError("D contains NaN distances.")
    if len(y_test) == 0 or len(y_ref) == 0:
        raise DataError(f"need at least one test and one reference example; got {len(y_test)} and {len(y_ref)}.")
    classes = np.unique(y_ref)
    missing = set(np.unique(y_test)) - set(classes)
    if missing:
        raise DataError(f"test classes {sorted(missing)} have no reference example.")
    rng = check_random_state(random_state)
    members = [np.flatnonzero(y_ref == c) for c in classes]
    true = np.searchsorted(classes, y_test)
    wins = 0.0
    for _ in range(n_draws):
        # one random reference per class, per test example: (n_test, n_classes) column indices
        pick = np.stack([m[rng.integers(0, m.size, size=len(y_test))] for m in members], axis=1)
        d = np.take_along_axis(D, pick, axis=1)
        wins += float(np.mean(d.argmin(axis=1) == true))
    return wins / n_draws
