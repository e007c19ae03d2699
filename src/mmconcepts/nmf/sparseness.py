"""Hoyer's sparseness measure and projection (thesis eq. 2.20).

Hoyer, P. O. (2004). Non-negative matrix factorization with sparseness constraints.
JMLR 5, 1457-1469. The projection is written by hand: no maintained library ships it.
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError, ParameterError

__all__ = ["hoyer_sparseness", "project_hoyer", "l1_for_sparseness"]


def hoyer_sparseness(x: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    """Hoyer's sparseness of a nonzero vector (thesis eq. 2.20).

    .. math:: \\mathrm{sparseness}(x) = \\frac{\\sqrt{n} - \\|x\\|_1 / \\|x\\|_2}{\\sqrt{n} - 1}

    It is 0 for a constant vector and 1 for a vector with a single nonzero entry.

    Parameters
    ----------
    x : ndarray
        A vector, or a matrix with ``axis`` giving the direction of the vectors.
    axis : int, optional
        Axis along which the vectors lie (``None``: ``x`` is flattened).

    Returns
    -------
    float or ndarray
        In [0, 1]; NaN for an all-zero vector (the measure is undefined there).

    Raises
    ------
    DataError
        For NaN or infinite values, or vectors shorter than 2.
    """
    x = _finite_vector(x, "hoyer_sparseness")
    if axis is None:
        x = x.ravel()
        axis = 0
    n = x.shape[axis]
    if n < 2:
        raise DataError(f"sparseness needs vectors of length >= 2; got length {n}.")
    peak = np.abs(x).max(axis=axis, keepdims=True) if x.size else np.ones(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = x / np.where(peak > 0, peak, 1.0)  # the measure is scale-invariant; unit scale keeps the squares finite
        l1 = np.abs(x).sum(axis=axis)
        l2 = np.sqrt((x * x).sum(axis=axis))
        s = (np.sqrt(n) - l1 / l2) / (np.sqrt(n) - 1.0)
    s = np.clip(s, 0.0, 1.0)  # rounding can step just outside [0, 1] (NaN stays NaN)
    return float(s) if np.ndim(s) == 0 else s


def _finite_vector(x, owner: str) -> np.ndarray:
    try:
        x = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{owner} needs an array of numbers; {exc}") from exc
    if not np.isfinite(x).all():
        raise DataError(f"{owner} needs finite values; got NaN or infinite entries.")
    return x


def l1_for_sparseness(sparseness: float, n: int, l2: float = 1.0) -> float:
    """The L1 norm a length-``n`` vector of L2 norm ``l2`` has at the given sparseness."""
    return l2 * (np.sqrt(n) - (np.sqrt(n) - 1.0) * sparseness)


def project_hoyer(x: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Closest nonnegative vector with the given L1 and L2 norms (Hoyer 2004, Fig. 1).

    Parameters
    ----------
    x : ndarray of shape (n,)
        The vector to project.
    l1 : float
        Target L1 norm, with ``l2 <= l1 <= sqrt(n) * l2``.
    l2 : float
        Target L2 norm (not squared), > 0.

    Returns
    -------
    ndarray of shape (n,)
        Nonnegative, with ``sum(s) == l1`` and ``norm(s) == l2`` up to rounding.

    Raises
    ------
    DataError
        An empty x, NaN or infinite entries, or entries beyond 1e150 times l2 (their squares
        overflow).
    ParameterError
        l1, l2 not finite, l2 <= 0, or no vector of length n with these norms.
    """
    x = _finite_vector(x, "project_hoyer").ravel()
    n = x.size
    if n == 0:
        raise DataError("project_hoyer needs a vector of length >= 1; got an empty one.")
    if not (l2 > 0) or not np.isfinite(l1) or not np.isfinite(l2):
        raise ParameterError(f"project_hoyer needs finite l1 and l2 > 0; got l1={l1}, l2={l2}.")
    if l1 < l2 * (1 - 1e-12) or l1 > np.sqrt(n) * l2 * (1 + 1e-12):
        raise ParameterError(
            f"no vector of length {n} has L1={l1:g} and L2={l2:g}: need l2 <= l1 <= sqrt(n) * l2."
        )
    if l1 >= np.sqrt(n) * l2 * (1 - 1e-12):  # sparseness 0: the constant vector is the only feasible one
        return np.full(n, l1 / n)
    if l2 != 1.0:  # equivariant: P(x; l1, l2) = l2 P(x / l2; l1 / l2, 1), computed at unit scale (no overflow)
        with np.errstate(over="ignore", under="ignore"):
            unit = x / l2
        if np.isfinite(unit).all():
            return l2 * project_hoyer(unit, l1 / l2, 1.0)
    if np.abs(x).max() > 1e150 * l2:  # its squares overflow
        raise DataError(
            f"project_hoyer: x is too large relative to l2 (max |x| = {np.abs(x).max():.3g}, l2 = {l2:g}); "
            "divide x by a constant first."
        )
    l2sq = l2 * l2
    if np.ptp(x) <= 1e-12 * max(float(np.abs(x).max()), l1 / n):
        # x is constant up to rounding: every direction is as close; start from the exact midpoint so the
        # zero-sum tie-break direction below is taken (rounding noise of x - mean(x), scaled by |x|, would
        # otherwise pick an arbitrary direction and may zero every entry).
        v = np.full(n, l1 / n)
    else:
        v = x + (l1 - x.sum()) / n
    zero = np.zeros(n, dtype=bool)
    for _ in range(n + 1):
        n_free = n - int(zero.sum())
        if n_free == 1:  # sparseness 1 (l1 == l2): the one entry left carries all of l1 (0/0 below)
            return np.where(zero, 0.0, l1)
        midpoint = np.where(zero, 0.0, l1 / n_free)
        w = v - midpoint
        # w sums to zero up to rounding; a large step (v near the midpoint) would scale that rounding into the
        # sum, so the free entries are re-centred
        w[~zero] -= w[~zero].mean()
        a = float(w @ w)
        b = 2.0 * float(w @ v)
        c = float(v @ v) - l2sq
        # v is the midpoint (up to rounding, which leaves w a noise vector of arbitrary sum):
        # move along a zero-sum direction of the free entries
        if a <= 1e-24 * float(v @ v):
            free = np.flatnonzero(~zero)
            w = np.zeros(n)
            w[free] = -1.0 / n_free
            w[free[0]] += 1.0
            a = float(w @ w)
            b = 2.0 * float(w @ v)
        disc = max(b * b - 4.0 * a * c, 0.0)
        alpha = (-b + np.sqrt(disc)) / (2.0 * a)
        v = v + alpha * w
        if (v >= 0).all():
            return v
        zero |= v <= 0
        v[zero] = 0.0
        n_free = n - int(zero.sum())
        v = v + np.where(zero, 0.0, (l1 - v.sum()) / n_free)
    return np.maximum(v, 0.0)
