"""Comparing two factorizations up to scaling and permutation (thesis section 2.1.1).

The only transformations that leave every nonnegative factorization unchanged are a
scaling and a permutation of the atoms. Atoms are therefore normalised (scaling), and
matched by the Hungarian (Kuhn-Munkres) algorithm, ``scipy.optimize.linear_sum_assignment``,
which solves

.. math:: \\min_{\\sigma \\in S_k} \\sum_i d(A_i, B_{\\sigma(i)})

in O(k^3) instead of the naive O(k!).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from ..errors import DataError, ParameterError

__all__ = ["ComponentMatching", "match_components", "dictionary_distance"]

_METRICS = ("cosine", "euclidean", "l1")


@dataclass(frozen=True)
class ComponentMatching:
    """The best matching of the atoms of A to those of B.

    Attributes
    ----------
    distance : float
        Mean distance between matched (normalised) atoms; 0 for a scaled, permuted copy.
    rows, cols : ndarray of int
        Atom ``rows[i]`` of A is matched to atom ``cols[i]`` of B.
    pair_distances : ndarray
        Distance of each matched pair.
    cost : ndarray of shape (k_A, k_B)
        All pairwise distances between normalised atoms.
    """

    distance: float
    rows: np.ndarray
    cols: np.ndarray
    pair_distances: np.ndarray
    cost: np.ndarray

    @property
    def permutation(self) -> np.ndarray:
        """``perm`` such that ``B[perm]`` lines up with ``A[rows]`` (``perm = cols``)."""
        return self.cols


def _normalise(A: np.ndarray, metric: str) -> np.ndarray:
    norms = np.abs(A).sum(axis=1, keepdims=True) if metric == "l1" else np.linalg.norm(A, axis=1, keepdims=True)
    if np.any(norms == 0):
        raise DataError("an atom is all zeros: it has no direction to compare; drop it before matching.")
    return A / norms


def match_components(
    A: np.ndarray,
    B: np.ndarray,
    *,
    metric: Literal["cosine", "euclidean", "l1"] = "cosine",
) -> ComponentMatching:
    """Match the atoms (rows) of two dictionaries, invariant to their scaling and order.

    Parameters
    ----------
    A : ndarray of shape (k_A, n_features)
        A dictionary, one atom per row (``NMF.components_``; the thesis' W transposed).
    B : ndarray of shape (k_B, n_features)
    metric : {'cosine', 'euclidean', 'l1'}, default='cosine'
        ``'cosine'``: 1 - cosine similarity; ``'euclidean'``: distance between atoms
        scaled to unit L2 norm; ``'l1'``: L1 distance between atoms scaled to unit sum.

    Returns
    -------
    ComponentMatching
        min(k_A, k_B) pairs.
    """
    if metric not in _METRICS:
        raise ParameterError(f"metric must be one of {_METRICS}; got {metric!r}.")
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    if A.ndim != 2 or B.ndim != 2:
        raise DataError(f"dictionaries must be 2-D (n_components, n_features); got {A.shape} and {B.shape}.")
    if A.shape[1] != B.shape[1]:
        raise DataError(f"dictionaries have different numbers of features: {A.shape[1]} and {B.shape[1]}.")
    if A.size == 0 or B.size == 0:
        raise DataError("cannot match an empty dictionary.")
    if not (np.isfinite(A).all() and np.isfinite(B).all()):
        raise DataError("dictionaries hold NaN or infinite values.")
    An, Bn = _normalise(A, metric), _normalise(B, metric)
    if metric == "cosine":
        cost = np.clip(1.0 - An @ Bn.T, 0.0, 2.0)
    elif metric == "euclidean":
        cost = cdist(An, Bn)
    else:
        cost = cdist(An, Bn, metric="cityblock")
    rows, cols = linear_sum_assignment(cost)
    pairs = cost[rows, cols]
    return ComponentMatching(float(pairs.mean()), rows, cols, pairs, cost)


def dictionary_distance(A: np.ndarray, B: np.ndarray, *,
                        metric: Literal["cosine", "euclidean", "l1"] = "cosine") -> float:
    """Distance between two dictionaries, invariant to scaling and permutation of atoms.

    Shorthand for ``match_components(A, B, metric=metric).distance``.
    """
    return match_components(A, B, metric=metric).distance
