"""Input checks and random-state handling shared by all subpackages (internal)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from .errors import DataError, ParameterError

__all__ = ["check_random_state", "check_not_complex", "check_nonnegative_matrix", "check_positive_int", "check_scalar",
           "check_subset_indices"]

RandomLike = "int | np.random.Generator | np.random.RandomState | None"


def is_finite_real(value: numbers.Real) -> bool:
    """Whether a real number is finite as a float (False for an int too large for a float).

    ``math.isfinite`` rather than ``np.isfinite``: the ufunc raises TypeError for real numbers
    that are not Python or numpy scalars (``fractions.Fraction``, an int beyond float range).
    """
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


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
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not is_finite_real(value):
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


def check_not_complex(X: Any, name: str = "X") -> None:
    """Raise :class:`DataError` if ``X`` (an array or sparse matrix) has a complex dtype.

    Checked before any conversion to float, which would drop the imaginary part with only a warning;
    an object array holding a complex number is complex too.
    """
    if sp.issparse(X):
        is_complex = X.dtype.kind == "c"
    else:
        values = np.asarray(X)
        is_complex = np.iscomplexobj(values) or (values.dtype == object and any(
            isinstance(v, (complex, np.complexfloating)) for v in values.ravel()))
    if is_complex:
        raise DataError(f"Complex data not supported: {name} holds complex numbers; give real nonnegative data "
                        f"(np.abs({name}) for magnitudes, or {name}.real when its imaginary part is zero).")


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
        If the matrix is complex, empty, not 2-D, or holds negative, NaN or infinite values.
    """
    check_not_complex(X, name)
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
        if X.dtype == object:
            try:  # a TypeError (kept, as scikit-learn's checks expect) names an element that is not a number
                X = X.astype(np.float64)
            except ValueError as exc:  # text that is not a number
                raise DataError(f"{name} must hold numbers; got an object array with {exc}.") from exc
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


# ---------------------------------------------------------------------------------------------
# Parameter constraints: each estimator (``_parameter_constraints``) and public function declares
# its parameters once, as scikit-learn does, and :func:`validate_params` checks them with messages
# that say what was expected, what came and how to fix it. Written here rather than imported from
# ``sklearn.utils._param_validation`` because that module is private and its messages do not say
# how to fix the value.


class Interval:
    """A numeric range: ``Interval("int", 1, None)`` is an int >= 1; ``Interval("real", 0, 1)`` [0, 1].

    Parameters
    ----------
    kind : {"int", "real"}
        "int" accepts integers only (not bool); "real" accepts any finite real number (ints too).
    low, high : float or None
        Bounds; None is unbounded.
    closed : {"both", "left", "right", "neither"}, default="both"
        Which bounds belong to the range.
    """

    def __init__(self, kind: str, low: float | None = None, high: float | None = None, *, closed: str = "both"):
        if kind not in ("int", "real"):
            raise ValueError(f"Interval kind must be 'int' or 'real'; got {kind!r}.")
        if closed not in ("both", "left", "right", "neither"):
            raise ValueError(f"closed must be 'both', 'left', 'right' or 'neither'; got {closed!r}.")
        self.kind, self.low, self.high, self.closed = kind, low, high, closed

    def is_satisfied_by(self, value: Any) -> bool:
        if isinstance(value, (bool, np.bool_)):
            return False
        if self.kind == "int":
            if not isinstance(value, (numbers.Integral, np.integer)):
                return False
        elif not isinstance(value, numbers.Real) or not is_finite_real(value):
            return False
        left = self.closed in ("both", "left")
        right = self.closed in ("both", "right")
        if self.low is not None and (value < self.low or (not left and value == self.low)):
            return False
        if self.high is not None and (value > self.high or (not right and value == self.high)):
            return False
        return True

    def __str__(self) -> str:
        what = "an int" if self.kind == "int" else "a real number"
        left = self.closed in ("both", "left")
        right = self.closed in ("both", "right")
        if self.low is not None and self.high is not None:
            return f"{what} in {'[' if left else '('}{self.low:g}, {self.high:g}{']' if right else ')'}"
        if self.low is not None:
            return f"{what} {'>=' if left else '>'} {self.low:g}"
        if self.high is not None:
            return f"{what} {'<=' if right else '<'} {self.high:g}"
        return what if self.kind == "int" else "a finite real number"


class Options:
    """One of a fixed set of values (strings, numbers, ...), compared with ``==``."""

    def __init__(self, *values: Any):
        self.values = tuple(values)

    def is_satisfied_by(self, value: Any) -> bool:
        for v in self.values:
            if v is None or isinstance(v, (bool, np.bool_)) or isinstance(value, (bool, np.bool_)):
                if value is v or (isinstance(value, np.bool_) and isinstance(v, bool) and bool(value) is v):
                    return True
                continue
            try:
                if bool(value == v):
                    return True
            except (TypeError, ValueError):  # an array compared with a string, ...
                continue
        return False

    def __str__(self) -> str:
        return "one of " + ", ".join(repr(v) for v in self.values)


class InstanceOf:
    """An instance of the given type(s); ``description`` names it in messages."""

    def __init__(self, *types: type, description: str | None = None):
        self.types = types
        self.description = description

    def is_satisfied_by(self, value: Any) -> bool:
        return isinstance(value, self.types)

    def __str__(self) -> str:
        return self.description or "an instance of " + " or ".join(t.__name__ for t in self.types)


class HasMethods:
    """An object with the given methods (a scikit-learn splitter: ``HasMethods("split")``)."""

    def __init__(self, *methods: str):
        self.methods = methods

    def is_satisfied_by(self, value: Any) -> bool:
        return all(callable(getattr(value, m, None)) for m in self.methods)

    def __str__(self) -> str:
        return "an object with " + " and ".join(f"a {m}() method" for m in self.methods)


class _Named:
    """A constraint known by name: "boolean", "verbose", "random_state", "callable", "array-like"."""

    _DESCRIPTIONS = {
        "boolean": "a bool",
        "verbose": "a bool or an int >= 0",
        "random_state": "an int >= 0, a numpy Generator or RandomState, or None",
        "callable": "a callable",
        "array-like": "an array-like",
        "sparse matrix": "a scipy.sparse matrix",
    }

    def __init__(self, name: str):
        if name not in self._DESCRIPTIONS:
            raise ValueError(f"unknown constraint {name!r}; known: {sorted(self._DESCRIPTIONS)}.")
        self.name = name

    def is_satisfied_by(self, value: Any) -> bool:
        if self.name == "boolean":
            return isinstance(value, (bool, np.bool_))
        if self.name == "verbose":  # scikit-learn's "verbose": a bool, or a level
            return isinstance(value, (bool, np.bool_)) or (isinstance(value, (numbers.Integral, np.integer))
                                                            and int(value) >= 0)
        if self.name == "random_state":
            return (value is None or isinstance(value, (np.random.Generator, np.random.RandomState))
                    or (isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, bool)
                        and int(value) >= 0))
        if self.name == "callable":
            return callable(value)
        if self.name == "sparse matrix":
            return sp.issparse(value)
        return (hasattr(value, "__array__") or hasattr(value, "__len__") or sp.issparse(value)) and not isinstance(
            value, (str, bytes))

    def __str__(self) -> str:
        return self._DESCRIPTIONS[self.name]


def _as_constraint(c: Any) -> Any:
    if c is None:
        return _NONE
    if isinstance(c, str):
        return _Named(c)
    if isinstance(c, type):
        return InstanceOf(c)
    if not hasattr(c, "is_satisfied_by"):
        raise TypeError(f"not a constraint: {c!r}")
    return c


class _NoneConstraint:
    def is_satisfied_by(self, value: Any) -> bool:
        return value is None

    def __str__(self) -> str:
        return "None"


_NONE = _NoneConstraint()


def describe_constraints(constraints: list[Any]) -> str:
    """The constraints of one parameter in words: "an int >= 1 or None"."""
    parts = [str(_as_constraint(c)) for c in constraints]
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " or " + parts[-1]


def validate_params(params: Any, constraints: Mapping[str, list[Any] | Literal["no_validation"]], *,
                    owner: str | None = None,
                    hints: dict[str, str] | None = None) -> None:
    """Check every parameter named in ``constraints`` against its list of accepted forms.

    Parameters
    ----------
    params : mapping or estimator
        The values (an estimator's ``get_params(deep=False)`` is taken when it has one).
    constraints : dict of str to list
        Per parameter, the accepted forms; a value is valid when it satisfies any of them.
        A form is None (the value None), a type (an instance of it), one of the strings
        "boolean", "verbose", "random_state", "callable", "array-like", "sparse matrix", or an
        :class:`Interval`, :class:`Options` or :class:`InstanceOf`. The string "no_validation"
        (instead of a list) skips the parameter.
    owner : str, optional
        Who takes the parameters (a class or function name), named in the message.
    hints : dict of str to str, optional
        How to fix a bad value of a parameter, appended to the message.

    Raises
    ------
    ParameterError
        "<owner>: <name> must be <expected>; got <value>. <hint>" for the first invalid parameter.
    """
    if hasattr(params, "get_params"):
        owner = owner or type(params).__name__
        params = params.get_params(deep=False)
    for name, accepted in constraints.items():
        if accepted == "no_validation" or name not in params:
            continue
        value = params[name]
        if any(_as_constraint(c).is_satisfied_by(value) for c in accepted):
            continue
        got = repr(value) if isinstance(value, (numbers.Number, str, type(None), bool)) else (
            f"{value!r} ({type(value).__name__})" if len(repr(value)) < 60 else f"a {type(value).__name__}")
        msg = f"{name} must be {describe_constraints(accepted)}; got {got}."
        if owner:
            msg = f"{owner}: {msg}"
        if hints and name in hints:
            msg += " " + hints[name]
        raise ParameterError(msg)


__all__ += ["Interval", "Options", "InstanceOf", "HasMethods", "validate_params", "describe_constraints"]
