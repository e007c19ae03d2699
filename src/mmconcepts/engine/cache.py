"""The experiments' disk caches: numpy arrays and JSON, never pickle (internal).

:meth:`mmconcepts.engine.RunContext.memory` returns a :class:`CacheStore`, a folder
under the cache folder (``ch3-folds``, ``ch5-mfcc``, ...). ``store.cache(f, ignore=[...])``
returns a :class:`CachedFunction`: called like ``f``, it returns the result kept for the same
arguments, or calls ``f`` and keeps what it returns.

The store is a thin layer over the package's cache facility (:mod:`mmconcepts._store`):

- an entry is one file, ``<store>/<module>.<function>/<key>.npz``, written atomically by the
  process that computed it (:func:`mmconcepts._store.write_entry`: the package's no-pickle
  codec, the one saved models use) and read without ever unpickling, so that reading the
  cache never runs code, whatever a file planted in the cache folder holds; anything that
  is not an entry of this format (a torn file, an older cache's entry or ``output.pkl``, a
  pickle planted under an entry's name) is ignored and the value computed again;
- the key is :func:`mmconcepts._store.cache_key` of the function's module, qualified name
  and source and of the arguments not in ``ignore``, under the code fingerprint;
- a missing entry is computed under its own exclusive lock
  (:func:`mmconcepts._store.store_lock`: ``<cache folder>/.locks/<store>/<module>.<function>/<key>.lock``,
  the cache folder being the store's parent), so that processes sharing the cache folder
  (``reproduce --concurrent``, cluster workers) compute it once: the others wait, then read it.
"""

from __future__ import annotations

import contextlib
import hashlib
import inspect
import logging
import os
import re
import shutil
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, Generic, TypeVar

from .._codec import CorruptFile
from .._store import MISSING, cache_key, read_entry, remove_stale_temporaries, store_lock, write_entry
from ..errors import ExperimentError, ParameterError

__all__ = ["CacheStore", "CachedFunction"]

logger = logging.getLogger("mmconcepts.experiments")
_R = TypeVar("_R")


def _source_digest(func: Callable[..., Any]) -> str:
    try:
        source = inspect.getsource(func)
    except (OSError, TypeError):  # no source file (a function made at run time)
        code = getattr(func, "__code__", None)
        source = repr((code.co_code, code.co_consts)) if code is not None else repr(func)
    return hashlib.sha1(source.encode("utf-8", "surrogatepass")).hexdigest()


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
        remove_stale_temporaries(self.location)

    def key(self, *args: Any, **kwargs: Any) -> str:
        """The entry's key of a call with these arguments (a hex digest)."""
        bound = inspect.signature(self.func).bind(*args, **kwargs)
        bound.apply_defaults()
        hashed = [(n, v) for n, v in bound.arguments.items() if n not in self.ignore]
        return cache_key(self._name, self._source, hashed)

    def path(self, key: str) -> Path:
        """The entry file of ``key``."""
        return self.location / f"{key}.npz"

    def lookup(self, *args: Any, **kwargs: Any) -> tuple[bool, Any]:
        """``(True, value)`` for a call kept in the cache, else ``(False, None)`` (an unreadable entry: a miss)."""
        key = self.key(*args, **kwargs)
        value = self._read(key)
        return (False, None) if value is MISSING else (True, value)

    def _read(self, key: str) -> Any:
        path = self.path(key)
        try:
            return read_entry(path, key)
        except CorruptFile as exc:
            logger.warning("cache entry %s cannot be used (%s): computing it again", path, exc)
            return MISSING

    def check_call_in_cache(self, *args: Any, **kwargs: Any) -> bool:
        """Whether a readable entry exists for these arguments."""
        return self.lookup(*args, **kwargs)[0]

    def __call__(self, *args: Any, **kwargs: Any) -> _R:
        key = self.key(*args, **kwargs)
        value = self._read(key)
        if value is not MISSING:
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
            if value is not MISSING:
                return value
            return self._compute(key, args, kwargs)

    def _lock(self, key: str) -> contextlib.ExitStack:
        """An exclusive lock on ``key``'s entry (see the module docstring), or no lock if it cannot be made."""
        stack = contextlib.ExitStack()
        try:
            stack.enter_context(store_lock(self.location.parent.parent, self.path(key)))
        except OSError:  # a cache that cannot be written: nothing to share, go on unlocked
            pass
        return stack

    def _compute(self, key: str, args: tuple, kwargs: dict[str, Any]) -> _R:
        value = self.func(*args, **kwargs)
        path = self.path(key)
        try:
            write_entry(path, value, key)
        except ParameterError as exc:
            raise ExperimentError(f"{self._name}() returned a result the cache cannot keep: {exc}") from None
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
