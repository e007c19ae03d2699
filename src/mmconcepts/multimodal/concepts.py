"""What a learnt concept is: the examples that express each atom most, the labels it aligns with.

Thesis section 6.6.3 reads the learnt atoms through the concepts they carry information
about (:func:`~mmconcepts.multimodal.mutual_information_matrix`); these two functions give
what a person looks at or listens to for each atom: the training examples whose internal
representation is most made of that atom (:func:`top_examples`) and the share of the atom's
activation that falls on each label (:func:`atom_label_association`). The figures of
:mod:`mmconcepts.plot` and the report's concept explorer are built on them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import check_nonnegative_matrix, check_positive_int
from ..errors import DataError

__all__ = ["atom_label_association", "top_examples"]


def _dense_W(W: Any) -> np.ndarray:
    W = check_nonnegative_matrix(W, "W", accept_sparse=False)
    return np.asarray(W, dtype=np.float64)


def top_examples(W: Any, n: int = 3) -> np.ndarray:
    """The ``n`` examples that express each atom most, best first.

    An example expresses atom ``j`` by the share of its representation that atom ``j``
    holds, ``W[i, j] / sum_l W[i, l]`` (an example made of one atom shows that atom alone,
    whatever its loudness); ties are broken by the larger coefficient ``W[i, j]``, then by
    the smaller index. Examples whose representation is all zero express no atom and come
    last.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients (``model.transform(X)``; the thesis' columns of
        H in V ~ W H, one per example).
    n : int
        How many examples per atom; at most ``n_samples``.

    Returns
    -------
    ndarray of int, shape (n_components, n)
        Row ``j``: indices into the rows of ``W``, the example that expresses atom ``j``
        most first.

    Examples
    --------
    >>> import numpy as np
    >>> W = np.array([[1.0, 0.0], [2.0, 2.0], [0.0, 5.0], [3.0, 0.1]])
    >>> top_examples(W, n=2)
    array([[0, 3],
           [2, 1]])
    """
    W = _dense_W(W)
    n = check_positive_int(n, "n")
    if n > W.shape[0]:
        raise DataError(f"top_examples: expected n <= n_samples = {W.shape[0]}; got n={n}. Fix: ask for fewer "
                        "examples per atom.")
    total = W.sum(axis=1, keepdims=True)
    share = np.divide(W, total, out=np.full_like(W, -1.0), where=total > 0)
    rows = np.arange(W.shape[0])
    out = np.empty((W.shape[1], n), dtype=np.intp)
    for j in range(W.shape[1]):
        # lexsort sorts by its last key first: share (descending), then coefficient (descending), then index
        out[j] = np.lexsort((rows, -W[:, j], -share[:, j]))[:n]
    return out


def atom_label_association(W: Any, y: Any, *, labels: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """The share of each atom's activation that falls on the examples of each label.

    .. math::

        A_{jc} = \\frac{\\sum_{i: y_i = c} W_{ij}}{\\sum_i W_{ij}}

    Each row sums to one (an atom that is never active gets a row of zeros). A concept
    learnt without labels "aligns with" the labels of its largest shares.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients.
    y : array-like of shape (n_samples,)
        The label of each example (any hashable values).
    labels : array-like of shape (n_labels,), optional
        The labels, in the order of the columns; default: the sorted unique values of ``y``.
        Examples whose label is not among them are left out.

    Returns
    -------
    association : ndarray of shape (n_components, n_labels)
    labels : ndarray of shape (n_labels,)

    Examples
    --------
    >>> import numpy as np
    >>> W = np.array([[1.0, 0.0], [3.0, 1.0], [0.0, 1.0]])
    >>> A, labels = atom_label_association(W, ["a", "b", "b"])
    >>> A
    array([[0.25, 0.75],
           [0.  , 1.  ]])
    """
    W = _dense_W(W)
    y = np.asarray(y)
    if y.ndim != 1 or y.shape[0] != W.shape[0]:
        raise DataError(f"atom_label_association: expected y of shape ({W.shape[0]},), one label per row of W; "
                        f"got shape {y.shape}. Fix: pass the labels of the examples W was computed from.")
    labels = np.unique(y) if labels is None else np.asarray(labels)
    index = {v: i for i, v in enumerate(labels.tolist())}
    yi = np.array([index.get(v, -1) for v in y.tolist()], dtype=np.intp)
    keep = yi >= 0
    sums = np.zeros((labels.size, W.shape[1]))
    np.add.at(sums, yi[keep], W[keep])
    total = W.sum(axis=0)
    assoc = np.divide(sums.T, total[:, None], out=np.zeros((W.shape[1], labels.size)), where=total[:, None] > 0)
    return assoc, labels
