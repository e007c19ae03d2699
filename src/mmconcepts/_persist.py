"""Saving and loading fitted models without pickle (internal).

A saved model is one ``.npz`` file (:func:`numpy.savez`): its arrays, and a JSON header in
the entry ``header`` that holds the format name (``mmconcepts.<ClassName>``), the format
version, the mmconcepts version that wrote it, the constructor parameters and the fitted
state. Arrays in the state are references to other entries of the file; nested fitted
estimators (an ``NMF`` inside a ``MultimodalNMF``) are saved the same way, recursively.
Loading never unpickles (``allow_pickle=False``) and only rebuilds classes of mmconcepts.

Estimators get ``save``/``load`` from :class:`SaveLoadMixin`. By default the state is every
fitted attribute (a name ending in ``_``) plus the private names listed in
``_persisted_private``; a class whose state is not made of arrays, numbers, strings, lists,
tuples and dicts of them overrides :meth:`SaveLoadMixin._get_state` and
:meth:`SaveLoadMixin._set_state`.
"""

from __future__ import annotations

import importlib
import json
import numbers
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from sklearn.exceptions import NotFittedError

from . import __version__
from ._io import atomic_path
from .errors import DataFormatError, ParameterError, VersionMismatchError

__all__ = ["SaveLoadMixin", "encode", "decode"]

_MARK = "__mmconcepts__"  # key of the dicts that stand for an array, a tuple, an estimator, ...


def encode(value: Any, key: str, arrays: dict[str, np.ndarray]) -> Any:
    """A JSON-able image of ``value``; its arrays go to ``arrays`` under names derived from ``key``.

    Raises
    ------
    ParameterError
        If ``value`` (or something inside it) cannot be saved without pickle.
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (numbers.Integral, np.integer)):
        return int(value)
    if isinstance(value, (numbers.Real, np.floating)):
        v = float(value)
        return v if np.isfinite(v) else {_MARK: "float", "value": repr(v)}
    if isinstance(value, np.ndarray):
        arr = value
        if arr.dtype == object:
            if all(isinstance(x, str) for x in arr.ravel()):
                # in the JSON header: numpy's fixed-width strings would drop trailing NUL characters
                return {_MARK: "str-object-array", "shape": list(arr.shape), "items": [str(x) for x in arr.ravel()]}
            raise ParameterError(f"{key}: an object array that is not all strings cannot be saved without pickle.")
        name = f"a{len(arrays)}"
        arrays[name] = arr
        return {_MARK: "array", "entry": name}
    if isinstance(value, tuple):
        return {_MARK: "tuple", "items": [encode(v, f"{key}[{i}]", arrays) for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [encode(v, f"{key}[{i}]", arrays) for i, v in enumerate(value)]
    if isinstance(value, dict):
        if all(isinstance(k, str) for k in value) and _MARK not in value:
            return {k: encode(v, f"{key}.{k}", arrays) for k, v in value.items()}
        return {_MARK: "dict", "items": [[encode(k, f"{key}<key>", arrays), encode(v, f"{key}[{k!r}]", arrays)]
                                         for k, v in value.items()]}
    if isinstance(value, SaveLoadMixin):
        cls = type(value)
        return {_MARK: "estimator", "class": f"{cls.__module__}.{cls.__qualname__}",
                "params": encode(_saveable_params(value), f"{key}.params", arrays),
                "state": encode(value._get_state(), f"{key}.state", arrays)}
    if isinstance(value, (np.random.Generator, np.random.RandomState)):
        return None  # a generator's state is not a parameter a user keeps; it is saved as None
    raise ParameterError(
        f"{key}: a {type(value).__name__} cannot be saved without pickle; expected arrays, numbers, strings, "
        "lists, tuples, dicts of them or mmconcepts estimators."
    )


def decode(value: Any, arrays: Any) -> Any:
    """Inverse of :func:`encode`; ``arrays`` maps entry names to arrays (an open npz file)."""
    if isinstance(value, list):
        return [decode(v, arrays) for v in value]
    if not isinstance(value, dict):
        return value
    kind = value.get(_MARK)
    if kind is None:
        return {k: decode(v, arrays) for k, v in value.items()}
    if kind == "array":
        return np.asarray(arrays[value["entry"]])
    if kind == "str-object-array" and "entry" in value:  # written before the strings moved to the header
        return np.asarray(arrays[value["entry"]]).astype(object)
    if kind == "str-object-array":
        out = np.empty(len(value["items"]), dtype=object)
        out[:] = value["items"]
        return out.reshape(value["shape"])
    if kind == "float":
        return float(value["value"])
    if kind == "tuple":
        return tuple(decode(v, arrays) for v in value["items"])
    if kind == "dict":
        return {_hashable(decode(k, arrays)): decode(v, arrays) for k, v in value["items"]}
    if kind == "estimator":
        cls = _resolve_class(value["class"])
        obj = cls(**decode(value["params"], arrays))
        obj._set_state(decode(value["state"], arrays))
        return obj
    raise DataFormatError(f"unknown entry kind {kind!r} in a saved model.")


def _hashable(k: Any) -> Any:
    return tuple(_hashable(x) for x in k) if isinstance(k, (list, tuple)) else k


def _resolve_class(path: str) -> type:
    module, _, name = path.rpartition(".")
    if not (module == "mmconcepts" or module.startswith("mmconcepts.")):
        raise DataFormatError(f"a saved model names the class {path!r}; only mmconcepts classes are loaded.")
    try:
        obj: Any = importlib.import_module(module)
        for part in name.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as e:
        raise DataFormatError(f"a saved model names the class {path!r}, which this mmconcepts lacks ({e}).") from None
    if not (isinstance(obj, type) and issubclass(obj, SaveLoadMixin)):
        raise DataFormatError(f"a saved model names {path!r}, which is not a model that can be loaded.")
    return obj


def _saveable_params(est: Any) -> dict:
    params = est.get_params(deep=False)
    return {k: (None if isinstance(v, (np.random.Generator, np.random.RandomState)) else v) for k, v in params.items()}


class SaveLoadMixin:
    """``save(path)`` and ``load(path)`` for a fitted estimator, as one ``.npz`` with a JSON header.

    Class attributes
    ----------------
    _save_format_version : int
        Raised when the saved state of the class changes incompatibly.
    _persisted_private : tuple of str
        Private attributes (not ending in ``_``) that belong to the fitted state.
    """

    _save_format_version: ClassVar[int] = 1
    _persisted_private: ClassVar[tuple[str, ...]] = ()

    # -- state ------------------------------------------------------------------------------
    def _is_fitted_for_save(self) -> bool:
        return any(k.endswith("_") and not k.startswith("__") for k in vars(self))

    def _get_state(self) -> dict[str, Any]:
        """The fitted state: attribute name -> value (default: fitted and ``_persisted_private`` attributes)."""
        return {k: v for k, v in vars(self).items()
                if (k.endswith("_") and not k.startswith("__")) or k in self._persisted_private}

    def _set_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`_get_state` returned."""
        for k, v in state.items():
            setattr(self, k, v)

    # -- files ------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Save the fitted model to ``path`` (``.npz`` is appended if missing); no pickle.

        The file holds the arrays of the fitted state and a JSON header with the format
        name and version, the mmconcepts version, the constructor parameters (a
        ``random_state`` generator is saved as None) and the rest of the state. The write
        is atomic (a temporary file renamed into place).

        Returns
        -------
        pathlib.Path
            The file written.
        """
        if not self._is_fitted_for_save():
            raise NotFittedError(f"This {type(self).__name__} instance is not fitted yet; call fit before save.")
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        arrays: dict[str, np.ndarray] = {}
        cls = type(self)
        header = {
            "format": f"mmconcepts.{cls.__name__}",
            "format_version": cls._save_format_version,
            "mmconcepts_version": __version__,
            "params": encode(_saveable_params(self), "params", arrays),
            "state": encode(self._get_state(), "state", arrays),
        }
        with atomic_path(path, suffix=".tmp.npz") as tmp:
            np.savez(tmp, header=np.array(json.dumps(header)), allow_pickle=False, **arrays)
        return path

    @classmethod
    def _read_header(cls, path: Path) -> tuple[dict, Any]:
        try:
            z = np.load(path, allow_pickle=False)
            header = json.loads(str(z["header"]))
        except Exception as e:  # noqa: BLE001 - empty, truncated, bytes flipped: numpy's parsers raise OSError,
            # ValueError, KeyError, EOFError, BadZipFile, zlib.error, tokenize.TokenError, SyntaxError...
            raise DataFormatError(f"{path}: not a saved mmconcepts {cls.__name__} ({e}).") from None
        if not isinstance(header, dict) or header.get("format") != f"mmconcepts.{cls.__name__}":
            fmt = header.get("format") if isinstance(header, dict) else None
            z.close()
            raise DataFormatError(
                f"{path}: not a saved {cls.__name__} (its format is {fmt!r}); load it with the class that saved it.")
        return header, z

    @classmethod
    def load(cls, path: str | Path):
        """Load a model written by :meth:`save`.

        Raises
        ------
        DataFormatError
            If the file is not a saved model of this class, or is corrupt.
        VersionMismatchError
            If it was written in another save-format version of this class.
        """
        path = Path(path)
        header, z = cls._read_header(path)
        with z:
            version = header.get("format_version")
            if version != cls._save_format_version:
                return cls._load_other_version(path, header, z)
            try:
                params = decode(header["params"], z)
                if not isinstance(params, dict):
                    raise TypeError(f"the parameters are a {type(params).__name__}, not a mapping")
                obj = cls(**params)
                state = decode(header["state"], z)
                if not isinstance(state, dict):
                    raise TypeError(f"the fitted state is a {type(state).__name__}, not a mapping")
                obj._set_state(state)
                obj._check_loaded_state()
            except Exception as e:  # noqa: BLE001 - an edited header, an array cut short or damaged, a bad state
                if isinstance(e, DataFormatError) and str(path) in str(e):
                    raise
                raise DataFormatError(f"{path}: a corrupt saved {cls.__name__} ({type(e).__name__}: {e}).") from None
        return obj

    def _check_loaded_state(self) -> None:
        """Check a loaded state for consistency; raise ``ValueError`` (or a subclass) if it is not.

        Called by :meth:`load` after :meth:`_set_state`, whose errors it turns into a
        :class:`~mmconcepts.errors.DataFormatError` naming the file, so that an edited file
        fails at load time rather than at the first use of the model. The default checks
        nothing; classes whose state has invariants (shapes that must agree) override it.
        """

    @classmethod
    def _load_other_version(cls, path: Path, header: dict, z: Any):
        """Read an older save-format version; by default no other version is readable."""
        raise VersionMismatchError(
            f"{path}: saved with format version {header.get('format_version')} (mmconcepts "
            f"{header.get('mmconcepts_version')}); this mmconcepts reads version {cls._save_format_version} of "
            f"{cls.__name__}. Refit the model, or load it with the mmconcepts version that saved it."
        )
