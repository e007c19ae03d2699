"""How much the learnt coefficients say about the concepts (thesis section 6.6.3, Fig. 6.10)."""

from __future__ import annotations

import numpy as np

__all__ = ["mutual_information_matrix"]


def mutual_information_matrix(y: np.ndarray, W: np.ndarray, n_bins: int = 10) -> np.ndarray:
    """I(X_l; Y_j) in bits for every concept l (rows) and coefficient j (columns).

    X_l is the indicator "the example features concept l" and Y_j the coefficient j
    discretised into ``n_bins`` equal-width bins over its range (thesis section 6.6.3). The
    plug-in estimate from the joint counts, as :func:`sklearn.metrics.mutual_info_score`
    gives for each pair (in nats), computed for every concept at once from one contingency
    table per coefficient (sklearn's function takes one pair per call).

    Parameters
    ----------
    y : ndarray of int, shape (n_samples,)
        Concept of each example.
    W : ndarray of shape (n_samples, k)
        Internal coefficients.
    n_bins : int
        Equal-width bins over each coefficient's range.
    """
    concepts, yi = np.unique(np.asarray(y), return_inverse=True)
    n, n_concepts = yi.size, concepts.size
    out = np.zeros((n_concepts, W.shape[1]))
    n_c = np.bincount(yi, minlength=n_concepts)[:, None].astype(float)  # examples of each concept
    for j in range(W.shape[1]):
        col = W[:, j]
        edges = np.linspace(col.min(), col.max(), n_bins + 1)[1:-1]
        binned = np.digitize(col, edges)
        # joint[c, b]: examples of concept c in bin b; the examples of the other concepts in bin b are the rest
        joint = np.bincount(yi * n_bins + binned, minlength=n_concepts * n_bins).reshape(n_concepts, n_bins)
        n_b = joint.sum(axis=0)[None, :].astype(float)
        total = np.zeros(n_concepts)
        for counts, n_x in ((joint, n_c), (n_b - joint, n - n_c)):  # X_l = 1, then X_l = 0
            with np.errstate(divide="ignore", invalid="ignore"):
                terms = counts / n * np.log2(counts * n / (n_x * n_b))
            total += np.where(counts > 0, terms, 0.0).sum(axis=1)
        out[:, j] = np.maximum(total, 0.0)
    return out
