"""The experiments' disk caches: numpy arrays and JSON, never pickle (internal).

:meth:`mmconcepts.experiments.RunContext.memory` returns a :class:`CacheStore`, a folder
under the cache folder (``ch3-folds``, ``ch5-mfcc``, ...). ``store.cache(f, ignore=[...])``
returns a :class:`CachedFunction`: called like ``f``, it returns the result kept for the same
arguments, or calls ``f`` and keeps what it returns.

An entry is one file, ``<store>/<module>.<function>/<key>.npz``, written atomically (a
temporary file beside it, then :func:`os.replace`) by the process that computed it: a
``numpy.savez`` archive of the result's arrays plus one member holding the result's
structure as JSON (nested dicts with string keys, lists, tuples, named tuples of the
package, arrays, numpy scalars, Python numbers, strings, None). It is read with
``numpy.load(..., allow_pickle=False)`` and :func:`json.loads` only, so reading the cache
never runs code, whatever a file planted in the cache folder holds. A missing entry is
computed under an exclusive lock of its own (a file in ``<store>/<module>.<function>/.locks``),
so that processes sharing the cache folder (``reproduce --concurrent``, cluster workers)
compute it once: the others wait, then read it. Anything that is not an
entry in this format (a torn file, an older cache's ``output.pkl``, a pickle planted under
an entry's name) is ignored and the value recomputed.

The key is a hash (:func:`joblib.hash`, which pickles to hash and never unpickles) of the
function's module, qualified name and source, and of the arguments not in ``ignore``.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import inspect
import json
import logging
import os
import re
import shutil
import struct
import zipfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from .._io import atomic_path, folder_lock
from ..errors import ExperimentError

__all__ = ["CacheStore", "CachedFunction", "encode", "decode", "FORMAT"]

logger = logging.getLogger("mmconcepts.experiments")

#: The format name written in every entry; an entry with another is recomputed.
FORMAT = "mmconcepts-cache/1"

_STRUCTURE = "__structure__"  # the npz member holding the JSON structure
_ZIP_MAGIC = b"PK\x03\x04"
_R = TypeVar("_R")
_MISSING = object()


class CorruptEntry(Exception):
    """An entry that is not in :data:`FORMAT` (torn, edited, planted): recompute it."""


# --------------------------------------------------------------------------- encoding


def encode(value: Any) -> tuple[Any, dict[str, np.ndarray]]:
    """Split ``value`` into a JSON-able structure and the arrays it refers to.

    Supported: None, bool, int, float, str (Python's own types), numpy arrays of any dtype
    without Python objects, numpy scalars (bool, integer, floating, complex, str), and
    lists, tuples, named tuples defined in :mod:`mmconcepts` and dicts with string keys of
    these.

    Raises
    ------
    ExperimentError
        For any other type (naming it and where it is in ``value``).
    """
    arrays: dict[str, np.ndarray] = {}

    def add(a: np.ndarray) -> str:
        name = f"a{len(arrays)}"
        arrays[name] = a
        return name

    def enc(x: Any, where: str) -> Any:
        t = type(x)
        if x is None or t is bool or t is int or t is str:
            return x
        if t is float:
            if x != x:  # NaN: its bits (sign and payload), which JSON's NaN does not keep
                return {"nan": struct.pack("<d", x).hex()}
            return x  # json writes repr(x), which reads back exactly (and Infinity / -Infinity)
        if t is np.ndarray:
            if x.dtype.hasobject:
                raise ExperimentError(f"a cached result cannot hold an array of Python objects (at {where}).")
            return {"array": add(x)}
        if isinstance(x, np.generic) and not isinstance(x, (np.object_, np.void)):
            return {"scalar": add(np.asarray(x))}
        if t is list:
            return {"list": [enc(v, f"{where}[{i}]") for i, v in enumerate(x)]}
        if t is tuple:
            return {"tuple": [enc(v, f"{where}[{i}]") for i, v in enumerate(x)]}
        if isinstance(x, tuple) and hasattr(t, "_fields") and _package_class(t):
            return {"namedtuple": f"{t.__module__}:{t.__qualname__}", "fields": list(t._fields),
                    "items": [enc(v, f"{where}.{f}") for f, v in zip(t._fields, x)]}
        if t is dict:
            items = []
            for k, v in x.items():
                if type(k) is not str:
                    raise ExperimentError(f"a cached result's dict keys must be strings; got {k!r} at {where}.")
                items.append([k, enc(v, f"{where}[{k!r}]")])
            return {"dict": items}
        raise ExperimentError(
            f"a cached result cannot hold a {t.__module__}.{t.__qualname__} (at {where}): the disk caches keep "
            "None, bool, int, float, str, numpy arrays and scalars, and lists, tuples, the package's named tuples "
            "and str-keyed dicts of these."
        )

    return enc(value, "result"), arrays


def _package_class(t: type) -> bool:
    module = getattr(t, "__module__", "") or ""
    return module == "mmconcepts" or module.startswith("mmconcepts.")


def _named_tuple(spec: Any, fields: Any) -> Any:
    """The named tuple class ``spec`` (``"module:qualname"``), only if it is one of the package's."""
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise CorruptEntry(f"bad named tuple {spec!r}")
    module, qualname = spec.split(":")
    if not (module == "mmconcepts" or module.startswith("mmconcepts.")) or not re.fullmatch(r"[\w.]+", module + qualname):
        raise CorruptEntry(f"named tuple {spec!r} is not one of the package's")
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise CorruptEntry(f"named tuple {spec!r} not found") from exc
    if not (isinstance(obj, type) and issubclass(obj, tuple) and list(getattr(obj, "_fields", ())) == fields):
        raise CorruptEntry(f"{spec!r} is no named tuple with fields {fields!r}")
    return obj


def decode(structure: Any, arrays: Any) -> Any:
    """Rebuild the value :func:`encode` split into ``structure`` and ``arrays`` (a mapping of name to array).

    Raises
    ------
    CorruptEntry
        If the structure is not one :func:`encode` writes, or names an array that is absent.
    """
    def array(name: Any) -> np.ndarray:
        if not isinstance(name, str) or name == _STRUCTURE or name not in arrays:
            raise CorruptEntry(f"no array {name!r}")
        a = arrays[name]
        if type(a) is not np.ndarray or a.dtype.hasobject:
            raise CorruptEntry(f"array {name!r} is no plain array")
        return a

    def dec(x: Any) -> Any:
        if x is None or type(x) in (bool, int, float, str):
            return x
        if type(x) is not dict or len(x) not in (1, 3):
            raise CorruptEntry(f"unexpected node {str(x)[:60]!r}")
        (tag, body), *_ = x.items()
        if tag == "namedtuple" and len(x) == 3:
            cls = _named_tuple(body, x.get("fields"))
            items = x.get("items")
            if type(items) is not list or len(items) != len(cls._fields):
                raise CorruptEntry("bad named tuple items")
            return cls._make(dec(v) for v in items)
        if len(x) != 1:
            raise CorruptEntry(f"unexpected node {str(x)[:60]!r}")
        if tag == "array":
            return array(body)
        if tag == "nan":
            try:
                value = struct.unpack("<d", bytes.fromhex(body))[0]
            except (TypeError, ValueError, struct.error) as exc:
                raise CorruptEntry("bad NaN") from exc
            if value == value:
                raise CorruptEntry("a NaN that is a number")
            return value
        if tag == "scalar":
            a = array(body)
            if a.ndim != 0:
                raise CorruptEntry("a scalar that is no 0-d array")
            return a[()]
        if tag in ("list", "tuple"):
            if type(body) is not list:
                raise CorruptEntry(f"bad {tag}")
            items = [dec(v) for v in body]
            return items if tag == "list" else tuple(items)
        if tag == "dict":
            if type(body) is not list:
                raise CorruptEntry("bad dict")
            out = {}
            for pair in body:
                if type(pair) is not list or len(pair) != 2 or type(pair[0]) is not str:
                    raise CorruptEntry("bad dict item")
                out[pair[0]] = dec(pair[1])
            return out
        raise CorruptEntry(f"unknown tag {tag!r}")

    return dec(structure)


# --------------------------------------------------------------------------- files


def write_entry(path: Path, value: Any, key: str) -> None:
    """Write ``value`` as the entry ``path`` (atomically), recording ``key`` in it."""
    structure, arrays = encode(value)
    text = json.dumps({"format": FORMAT, "key": key, "value": structure}, allow_nan=True, ensure_ascii=True)
    members: dict[str, np.ndarray] = {_STRUCTURE: np.frombuffer(text.encode("ascii"), dtype=np.uint8)}
    members.update(arrays)
    with atomic_path(path, suffix=".tmp.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **members)  # type: ignore[arg-type]  # savez takes arrays as keyword arguments
            fh.flush()
            os.fsync(fh.fileno())


def read_entry(path: Path, key: str) -> Any:
    """The value of the entry ``path``, or :data:`_MISSING` if there is none.

    Never unpickles: the file must be a zip archive of ``.npy`` members (read with
    ``allow_pickle=False``) whose structure member is JSON in :data:`FORMAT` for ``key``.

    Raises
    ------
    CorruptEntry
        If the file exists but is not such an entry.
    """
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        return _MISSING
    except OSError as exc:
        raise CorruptEntry(f"cannot open: {exc}") from exc
    with fh:
        if fh.read(4) != _ZIP_MAGIC:
            raise CorruptEntry("not an npz archive")
        fh.seek(0)
        try:
            with np.load(fh, allow_pickle=False) as npz:
                if _STRUCTURE not in npz.files:
                    raise CorruptEntry("no structure")
                raw = npz[_STRUCTURE]
                if raw.dtype != np.uint8 or raw.ndim != 1:
                    raise CorruptEntry("bad structure member")
                doc = json.loads(raw.tobytes().decode("ascii"))
                if type(doc) is not dict or doc.get("format") != FORMAT:
                    raise CorruptEntry("not in the format " + FORMAT)
                if doc.get("key") != key:
                    raise CorruptEntry("an entry of another key")
                arrays = {name: npz[name] for name in npz.files if name != _STRUCTURE}
                return decode(doc.get("value"), arrays)
        except CorruptEntry:
            raise
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, UnicodeDecodeError, RecursionError,
                NotImplementedError, OverflowError, MemoryError) as exc:
            raise CorruptEntry(f"{type(exc).__name__}: {exc}") from exc


# --------------------------------------------------------------------------- the cache


def _source_digest(func: Callable[..., Any]) -> str:
    try:
        source = inspect.getsource(func)
    except (OSError, TypeError):  # no source file (a function made at run time)
        code = getattr(func, "__code__", None)
        source = repr((code.co_code, code.co_consts)) if code is not None else repr(func)
    return hashlib.sha1(source.encode("utf-8", "surrogatepass")).hexdigest()


def _remove_stale_temporaries(folder: Path, age: float = 3600.0) -> None:
    """Delete the temporary files of entries whose writer was killed (older than ``age`` seconds)."""
    import time

    try:
        with os.scandir(folder) as it:
            for entry in it:
                if entry.name.startswith(".") and entry.name.endswith(".tmp.npz") and entry.is_file():
                    with contextlib.suppress(OSError):
                        if time.time() - entry.stat().st_mtime > age:
                            os.unlink(entry.path)
    except OSError:  # no folder yet
        pass


class CachedFunction(Generic[_R]):
    """``func`` with its results kept on disk (see the module docstring). Made by :meth:`CacheStore.cache`.

    Parameters
    ----------
    func : callable
        A module-level function (so that it pickles, for worker processes).
    location : Path
        The store's folder.
    ignore : sequence of str
        Names of arguments left out of the key (the others stand for them).
    """

    def __init__(self, func: Callable[..., _R], location: Path, ignore: Sequence[str] = ()) -> None:
        self.func = func
        self.ignore = tuple(ignore)
        params = inspect.signature(func).parameters
        unknown = [n for n in self.ignore if n not in params]
        if unknown:
            raise ExperimentError(f"ignore names {unknown} that {func.__qualname__}() does not take.")
        name = f"{func.__module__}.{func.__qualname__}"
        self.location = Path(location) / re.sub(r"[^A-Za-z0-9_.-]", "_", name)
        self._name = name
        self._source = _source_digest(func)
        _remove_stale_temporaries(self.location)

    def key(self, *args: Any, **kwargs: Any) -> str:
        """The entry's key of a call with these arguments (a hex digest)."""
        import joblib

        bound = inspect.signature(self.func).bind(*args, **kwargs)
        bound.apply_defaults()
        hashed = [(n, v) for n, v in bound.arguments.items() if n not in self.ignore]
        return str(joblib.hash([FORMAT, self._name, self._source, hashed]))

    def path(self, key: str) -> Path:
        """The entry file of ``key``."""
        return self.location / f"{key}.npz"

    def lookup(self, *args: Any, **kwargs: Any) -> tuple[bool, Any]:
        """``(True, value)`` for a call kept in the cache, else ``(False, None)`` (an unreadable entry: a miss)."""
        key = self.key(*args, **kwargs)
        value = self._read(key)
        return (False, None) if value is _MISSING else (True, value)

    def _read(self, key: str) -> Any:
        path = self.path(key)
        try:
            return read_entry(path, key)
        except CorruptEntry as exc:
            logger.warning("cache entry %s cannot be used (%s): computing it again", path, exc)
            return _MISSING

    def check_call_in_cache(self, *args: Any, **kwargs: Any) -> bool:
        """Whether a readable entry exists for these arguments."""
        return self.lookup(*args, **kwargs)[0]

    def __call__(self, *args: Any, **kwargs: Any) -> _R:
        key = self.key(*args, **kwargs)
        value = self._read(key)
        if value is not _MISSING:
            return value
        return self._compute_locked(key, args, kwargs)

    def compute(self, *args: Any, **kwargs: Any) -> _R:
        """Call the function and write its entry (for a call :meth:`lookup` found missing).

        The entry is read once more under its lock first: another process may have written
        it since (see :meth:`_compute_locked`).
        """
        return self._compute_locked(self.key(*args, **kwargs), args, kwargs)

    def _compute_locked(self, key: str, args: tuple, kwargs: dict[str, Any]) -> _R:
        """A miss: compute under the entry's lock, so that a concurrent process asking for the same
        entry (``reproduce --concurrent``) waits for it and reads it instead of computing it again."""
        with self._lock(key):
            value = self._read(key)
            if value is not _MISSING:
                return value
            return self._compute(key, args, kwargs)

    def _lock(self, key: str) -> contextlib.ExitStack:
        """An exclusive lock on ``key``'s entry (a file under ``<store>/.locks``), or no lock if it cannot be made."""
        stack = contextlib.ExitStack()
        try:
            stack.enter_context(folder_lock(self.location / ".locks", f"{key}.lock"))
        except OSError:  # a cache that cannot be written: nothing to share, go on unlocked
            pass
        return stack

    def _compute(self, key: str, args: tuple, kwargs: dict[str, Any]) -> _R:
        value = self.func(*args, **kwargs)
        path = self.path(key)
        try:
            write_entry(path, value, key)
        except OSError as exc:  # a cache that cannot be written (read-only, full, a folder in the way): go on
            logger.warning("cache entry %s not written (%s): it will be computed again next time", path, exc)
        return value

    def clear(self) -> None:
        """Delete every entry of this function."""
        shutil.rmtree(self.location, ignore_errors=True)

    def __repr__(self) -> str:
        return f"CachedFunction({self._name}, location={str(self.location)!r})"


class CacheStore:
    """A folder of cached function results (what :meth:`RunContext.memory` returns).

    Parameters
    ----------
    location : path-like
        The folder (created when the first entry is written).
    """

    def __init__(self, location: str | os.PathLike[str]) -> None:
        self.location = Path(location)

    def cache(self, func: Callable[..., _R], ignore: Iterable[str] | None = None) -> CachedFunction[_R]:
        """``func`` cached in this folder, keyed on its arguments except those named in ``ignore``."""
        return CachedFunction(func, self.location, tuple(ignore or ()))

    def __repr__(self) -> str:
        return f"CacheStore({str(self.location)!r})"
