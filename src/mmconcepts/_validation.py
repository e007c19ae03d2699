"""Input checks and random-state handling shared by all subpackages (internal)."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np
import scipy.sparse as sp

from .errors import DataError, ParameterError

__all__ = ["check_random_state", "check_nonnegative_matrix", "check_positive_int", "check_scalar", "check_subset_indices"]

RandomLike = "int | np.random.Generator | np.random.RandomState | None"


def check_random_state(random_state: Any) -> np.random.Generator:
    """Resolve ``random_state`` once into a :class:`numpy.random.Generator`.

    Parameters
    ----------
    random_state : int, numpy.random.Generator, numpy.random.RandomState or None
        An int seeds a new generator; a generator is used as is (not copied), so
        successive calls draw different numbers; a legacy ``RandomState`` is wrapped
        (seeded from it); None draws fresh entropy from the OS.
    """
    if random_state is None or isinstance(random_state, (numbers.Integral, np.integer)):
        if random_state is not None and int(random_state) < 0:
            raise ParameterError(
                f"random_state must be a non-negative int, a numpy Generator or None; got {random_state}."
            )
        return np.random.default_rng(None if random_state is None else int(random_state))
    if isinstance(random_state, np.random.Generator):
        return random_state
    if isinstance(random_state, np.random.RandomState):
        return np.random.default_rng(random_state.randint(0, 2**31 - 1))
    raise ParameterError(
        "random_state must be an int, a numpy.random.Generator, a numpy.random.RandomState or None; "
        f"got {type(random_state).__name__}."
    )


def check_positive_int(value: Any, name: str, *, minimum: int = 1) -> int:
    """Return ``value`` as an int, or raise :class:`ParameterError` if it is not an int >= minimum."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        raise ParameterError(f"{name} must be an int >= {minimum}; got {value!r} ({type(value).__name__}).")
    if value < minimum:
        raise ParameterError(f"{name} must be an int >= {minimum}; got {value}.")
    return int(value)


def check_scalar(
    value: Any,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """Return ``value`` as a finite float in the given range, or raise :class:`ParameterError`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(value):
        raise ParameterError(f"{name} must be a finite real number; got {value!r}.")
    value = float(value)
    bad = (
        (low is not None and (value < low or (not low_inclusive and value == low)))
        or (high is not None and (value > high or (not high_inclusive and value == high)))
    )
    if bad:
        lo = "-inf" if low is None else f"{low}"
        hi = "inf" if high is None else f"{high}"
        lb = "[" if low_inclusive and low is not None else "("
        hb = "]" if high_inclusive and high is not None else ")"
        raise ParameterError(f"{name} must be in {lb}{lo}, {hi}{hb}; got {value}.")
    return value


def check_nonnegative_matrix(
    X: Any,
    name: str = "X",
    *,
    accept_sparse: bool = True,
    dtype: Any = None,
    copy: bool = False,
) -> np.ndarray | sp.csr_matrix:
    """Validate a nonnegative 2-D matrix (dense or sparse) of finite floats.

    Dense input becomes a C-contiguous float array; sparse input becomes CSR with
    sorted indices and no explicit zeros' duplicates. float32 is kept, everything else
    becomes float64 unless ``dtype`` is given.

    Raises
    ------
    DataError
        If the matrix is empty, not 2-D, or holds negative, NaN or infinite values.
    """
    if sp.issparse(X):
        if not accept_sparse:
            raise DataError(f"{name} must be a dense array here; got a scipy.sparse matrix. Use {name}.toarray().")
        X = sp.csr_matrix(X, copy=copy)
        if X.dtype not in (np.float32, np.float64) or (dtype is not None and X.dtype != dtype):
            X = X.astype(dtype or np.float64)
        if not X.has_canonical_format:
            X = X.copy() if not copy else X
            X.sum_duplicates()
        values = X.data
    else:
        X = np.asarray(X)
        if np.iscomplexobj(X):
            raise DataError(f"Complex data not supported: {name} holds complex numbers; give real nonnegative data.")
        if X.dtype == object:
            X = X.astype(np.float64)  # a TypeError names any element that is not a number
        elif not (np.issubdtype(X.dtype, np.number) or X.dtype == bool):
            raise DataError(f"{name} must hold numbers; got dtype {X.dtype}.")
        if dtype is None:
            dtype = X.dtype if X.dtype in (np.float32, np.float64) else np.float64
        X = np.array(X, dtype=dtype, order="C", copy=copy or None)
        values = X
    if X.ndim != 2:
        raise DataError(
            f"{name} must be 2-D (n_samples, n_features); got an array of shape {X.shape}. Reshape your data "
            "with X.reshape(-1, 1) for a single feature or X.reshape(1, -1) for a single sample."
        )
    if X.shape[0] == 0:
        raise DataError(f"{name} is empty: 0 sample(s) (shape={X.shape}) while a minimum of 1 is required.")
    if X.shape[1] == 0:
        raise DataError(f"{name} is empty: 0 feature(s) (shape={X.shape}) while a minimum of 1 is required.")
    if values.size:
        if not np.isfinite(values).all():
            n_bad = int(np.size(values) - np.isfinite(values).sum())
            raise DataError(f"{name} contains {n_bad} NaN or infinite value(s); remove or impute them first.")
        vmin = values.min()
        if vmin < 0:
            raise DataError(
                f"Negative values in data passed to {name}: its smallest value is {vmin:g}, but it must be "
                "nonnegative. Shift, clip or rescale it."
            )
    return X


def check_subset_indices(indices_or_mask: Any, n: int) -> np.ndarray:
    """Integer indices from integer indices or a boolean mask over ``n`` items.

    Raises
    ------
    ParameterError
        If a mask has the wrong shape, the dtype is neither integer nor boolean, or an
        index is out of ``[-n, n)``.
    """
    idx = np.asarray(list(indices_or_mask) if not isinstance(indices_or_mask, np.ndarray) else indices_or_mask)
    if idx.dtype == bool:
        if idx.shape != (n,):
            raise ParameterError(f"A boolean mask must have shape ({n},); got {idx.shape}.")
        idx = np.flatnonzero(idx)
    elif idx.size == 0:
        idx = idx.astype(int)
    elif not np.issubdtype(idx.dtype, np.integer):
        raise ParameterError(f"subset takes integer indices or a boolean mask; got dtype {idx.dtype}.")
    if idx.size and (idx.min() < -n or idx.max() >= n):
        raise ParameterError(f"Indices must be in [-{n}, {n}); got min {idx.min()}, max {idx.max()}.")
    return idx.ravel()
