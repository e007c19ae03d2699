"""The data of a beta-NMF fit checked: X and its mask, a given factor, whether an array is a dask array."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import scipy.sparse as sp

from .._validation import check_nonnegative_matrix, check_not_complex
from ..errors import DataError


__all__ = ["check_mask", "validate_data", "check_factor", "is_dask_array"]


def check_mask(mask: Any, shape: tuple[int, int], name: str = "mask"):
    """Validate a mask of observed cells: a boolean (or 0/1) array or sparse matrix of X's shape."""
    if mask is None:
        return None
    if sp.issparse(mask):
        mask = sp.csr_matrix(mask)
        values = mask.data
    else:
        mask = np.asarray(mask)
        values = mask
    if mask.ndim != 2 or mask.shape != tuple(shape):
        raise DataError(f"{name} must have the shape of X, {tuple(shape)}; got {mask.shape}.")
    if values.dtype != bool:
        if not np.issubdtype(values.dtype, np.number) or not np.isin(values, (0, 1)).all():
            raise DataError(f"{name} must be boolean (True where X is observed) or hold only 0 and 1.")
    if sp.issparse(mask):
        mask = mask.astype(bool)
        mask.eliminate_zeros()
        if mask.nnz == 0:
            raise DataError(f"{name} observes no cell of X; at least one cell must be True.")
        return mask
    mask = mask.astype(bool)
    if not mask.any():
        raise DataError(f"{name} observes no cell of X; at least one cell must be True.")
    return mask


def validate_data(X: Any, mask: Any = None, name: str = "X"):
    """Validate X (and its mask). With a mask, unobserved cells may hold anything (NaN too); they are zeroed."""
    if mask is None:
        try:
            return check_nonnegative_matrix(X, name), None
        except ValueError as exc:  # a TypeError (objects that are not numbers) stays one, as scikit-learn's
            if isinstance(exc, DataError):
                raise
            raise DataError(f"{name} must be a nonnegative matrix of numbers; {exc}") from exc
    check_not_complex(X if sp.issparse(X) else np.asarray(X), name)
    if sp.issparse(X):
        X = sp.csr_matrix(X, dtype=X.dtype if X.dtype in (np.float32, np.float64) else np.float64, copy=True)
        X.sum_duplicates()
    else:
        X = np.array(X, dtype=None, copy=True)
        if X.dtype not in (np.float32, np.float64):
            try:
                X = X.astype(np.float64)
            except (TypeError, ValueError) as exc:
                raise DataError(f"{name} must hold numbers; got dtype {X.dtype}.") from exc
    if X.ndim != 2:
        raise DataError(f"{name} must be 2-D (n_samples, n_features); got an array of shape {X.shape}.")
    mask = check_mask(mask, X.shape)
    if sp.issparse(X):
        if X.nnz:
            rows = np.repeat(np.arange(X.shape[0]), np.diff(X.indptr))
            observed = np.asarray(mask[rows, X.indices]).ravel() if sp.issparse(mask) else mask[rows, X.indices]
            X.data[~observed.astype(bool)] = 0.0
            X.eliminate_zeros()
    else:
        dense_mask = mask.toarray() if sp.issparse(mask) else mask
        X[~dense_mask] = 0.0
    return check_nonnegative_matrix(X, name), mask


def check_factor(A: Any, shape: tuple[int, int], name: str, dtype) -> np.ndarray:
    A = check_nonnegative_matrix(A, name, accept_sparse=False)
    if A.shape != shape:
        raise DataError(f"{name} must have shape {shape}; got {A.shape}.")
    return np.array(A, dtype=dtype, copy=True)


def is_dask_array(x: Any) -> bool:
    """Whether x is a dask array; dask is never imported here (an array of it means it is loaded)."""
    mod = sys.modules.get("dask.array")
    return mod is not None and isinstance(x, mod.Array)
