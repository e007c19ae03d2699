"""The beta-divergence (thesis eq. 2.2-2.3) and its derivative (eq. 2.13).

Elementwise helpers work on arrays, and the sums of the divergence over blocks of a dense
or sparse X; :func:`mmconcepts.nmf.beta_divergence` (in :mod:`._problem`) evaluates it between a
data matrix and a low-rank product, with an optional mask, without ever densifying a sparse X.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import DataError, ParameterError
from ._kernels import EPSILON, lowrank_at_nonzeros

__all__ = ["EPSILON", "elementwise_beta_divergence", "mm_exponent", "resolve_beta"]


_BETA_ALIASES = {
    "frobenius": 2.0,
    "euclidean": 2.0,
    "kullback-leibler": 1.0,
    "kl": 1.0,
    "i-divergence": 1.0,
    "itakura-saito": 0.0,
    "is": 0.0,
}

#: Rows of the low-rank product computed at once when a dense block is unavoidable.
_BLOCK_CELLS = 4_000_000


def resolve_beta(beta: Any) -> float:
    """Return beta as a float; accepts the names 'frobenius', 'kullback-leibler', 'itakura-saito'."""
    if isinstance(beta, str):
        key = beta.lower()
        if key not in _BETA_ALIASES:
            raise ParameterError(
                f"beta_loss must be a real number or one of {sorted(_BETA_ALIASES)}; got {beta!r}."
            )
        return _BETA_ALIASES[key]
    if isinstance(beta, bool) or not isinstance(beta, (int, float, np.integer, np.floating)) or not np.isfinite(beta):
        raise ParameterError(f"beta_loss must be a finite real number or a name; got {beta!r}.")
    return float(beta)


class BetaLoss:
    """Constraint form of a ``beta_loss`` parameter: a finite real number or a name (any case).

    Used in the constraints tables (:func:`mmconcepts._validation.validate_params`).
    """

    def is_satisfied_by(self, value: Any) -> bool:
        try:
            resolve_beta(value)
        except ParameterError:
            return False
        return True

    def __str__(self) -> str:
        return f"a finite real number or one of {sorted(_BETA_ALIASES)}"


def mm_exponent(beta: float) -> float:
    """The maximization-minimization exponent gamma(beta) of thesis Table 2.2.

    .. math:: \\gamma(\\beta) = 1/(2-\\beta) \\ (\\beta < 1),\\quad 1 \\ (1 \\le \\beta \\le 2),
              \\quad 1/(\\beta - 1) \\ (\\beta > 2)
    """
    if beta < 1.0:
        return 1.0 / (2.0 - beta)
    if beta > 2.0:
        return 1.0 / (beta - 1.0)
    return 1.0


def elementwise_beta_divergence(x: np.ndarray, y: np.ndarray, beta: float) -> np.ndarray:
    """d_beta(x | y) elementwise (thesis eq. 2.3), with 0 log 0 = 0.

    .. math::
        d_\\beta(x|y) = \\begin{cases}
            x/y - \\log(x/y) - 1 & \\beta = 0 \\\\
            x \\log(x/y) - x + y & \\beta = 1 \\\\
            \\frac{1}{\\beta(\\beta-1)}(x^\\beta + (\\beta-1) y^\\beta - \\beta x y^{\\beta-1}) & \\text{otherwise}
        \\end{cases}
    """
    x = np.asarray(x)
    y = np.asarray(y)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if beta == 2.0:
            return 0.5 * (x - y) ** 2
        if beta == 1.0:
            return np.where(x > 0, x * np.log(np.where(x > 0, x, 1.0) / y), 0.0) - x + y
        if beta == 0.0:
            r = x / y
            return np.where(r == np.inf, np.inf, r - np.log(r) - 1.0)  # inf - log(inf) would be NaN
        cross = np.where(x > 0, x * y ** (beta - 1.0), 0.0)  # 0 * y**(beta-1) = 0, even at y = 0
        return (x**beta + (beta - 1.0) * y**beta - beta * cross) / (beta * (beta - 1.0))


def dense_blocks(n_rows: int, n_cols: int):
    step = max(1, _BLOCK_CELLS // max(1, n_cols))
    for start in range(0, n_rows, step):
        yield slice(start, min(n_rows, start + step))


def mask_block(mask, rows: slice) -> np.ndarray:
    block = mask[rows]
    return block.toarray() if sp.issparse(block) else block


def sum_power_lowrank(W: np.ndarray, Ht: np.ndarray, power: float, mask=None) -> float:
    """sum_ij m_ij (W Ht.T)_ij ** power, without forming W Ht.T at once."""
    if power == 1.0:
        if mask is None:
            return float(W.sum(axis=0) @ Ht.sum(axis=0))
        return float(np.sum(np.asarray(mask @ Ht) * W))
    if power == 2.0 and mask is None:
        return float(np.sum((W.T @ W) * (Ht.T @ Ht)))
    if sp.issparse(mask):  # only at the observed cells: a sparse mask is never densified
        M = sp.csr_matrix(mask)
        Y = lowrank_at_nonzeros(M.indptr, M.indices, W, Ht, np.empty(M.nnz, dtype=W.dtype))
        np.maximum(Y, 0.0, out=Y)
        return float(np.sum(Y**power * M.data, dtype=np.float64))
    total = 0.0
    for rows in dense_blocks(W.shape[0], Ht.shape[0]):
        Y = W[rows] @ Ht.T
        np.maximum(Y, 0.0, out=Y)
        Y **= power
        if mask is not None:
            Y *= mask_block(mask, rows)
        total += float(Y.sum())
    return total


def zero_product_cells(X, W: np.ndarray, Ht: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the cells where X > 0 and W @ Ht.T is exactly 0, in row-major order.

    X is dense or sparse (never densified; the product is taken at its stored entries only) and
    zero where it is not observed (``validate_data``); W is (n, k), Ht (m, k), of one dtype.
    """
    if sp.issparse(X):
        Xc = sp.csr_matrix(X)
        W, Ht = np.ascontiguousarray(W), np.ascontiguousarray(Ht)
        Y = lowrank_at_nonzeros(Xc.indptr, Xc.indices, W, Ht, np.empty(Xc.nnz, dtype=W.dtype))
        hit = (Xc.data > 0) & (Y == 0)
        rows = np.repeat(np.arange(Xc.shape[0]), np.diff(Xc.indptr))[hit]
        cols = Xc.indices[hit].astype(np.intp)
        order = np.lexsort((cols, rows))
        return rows[order], cols[order]
    found_r, found_c = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
    for rows in dense_blocks(W.shape[0], Ht.shape[0]):
        r, c = np.nonzero((X[rows] > 0) & (W[rows] @ Ht.T == 0))
        found_r.append(r + rows.start)
        found_c.append(c)
    return np.concatenate(found_r), np.concatenate(found_c)


def check_beta_zeros(X, beta: float, mask=None, name: str = "X") -> None:
    """Raise :class:`DataError` when beta <= 0 and an observed cell of X is zero."""
    if beta > 0:
        return
    if sp.issparse(X):
        n_cells = X.shape[0] * X.shape[1]
        zero_stored = X.data == 0
        if mask is None:
            has_zero = X.nnz < n_cells or bool(zero_stored.any())
        else:
            observed = int(mask.sum()) if not sp.issparse(mask) else int(mask.count_nonzero())
            rows, cols = X.nonzero()
            observed_nonzero = int(np.asarray(gather(mask, rows, cols)).astype(bool).sum())
            has_zero = observed_nonzero < observed
    else:
        zeros = X == 0
        if mask is not None:
            zeros &= mask.toarray().astype(bool) if sp.issparse(mask) else mask.astype(bool)
        has_zero = bool(zeros.any())
    if has_zero:
        raise DataError(
            f"beta_loss={beta:g} is undefined where {name} is zero (the divergence is infinite), and {name} has "
            "observed zeros. Use beta_loss > 0 (e.g. 1 for the I-divergence), add a small positive offset to "
            f"{name}, or mask the zero cells."
        )


def gather(mask, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Mask values at the given cells (dense or sparse mask)."""
    if sp.issparse(mask):
        if rows.size == 0:
            return np.zeros(0, dtype=mask.dtype)
        return np.asarray(mask.tocsr()[rows, cols]).ravel()
    return mask[rows, cols]


