"""What an experiment's ``compute`` gets besides its config: the :class:`RunContext` (workers,
the real data sets, caches, progress), and the helpers of its cached calls."""

from __future__ import annotations

import difflib
import hashlib
import logging
import numbers
import os
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from .._paths import data_home
from .._progress import progress as progress_bar
from ..errors import ExperimentError, ParameterError
from .spec import ExperimentSkipped
from .workers import WarningsCarried, progress_enabled, workers_end_with_this_process

if TYPE_CHECKING:  # pragma: no cover
    from .cache import CacheStore

__all__ = ["RunContext", "array_digest", "cached_call"]

_T = TypeVar("_T")
_R = TypeVar("_R")


@dataclass
class RunContext:
    """What an experiment's ``run`` gets besides its config.

    Parameters
    ----------
    workers : int, default=1
        Processes for :meth:`parallel`; -1 means one per CPU.
    data : mapping of str to Path
        The real data sets of the run: its experiment's entry of the data plan
        (:class:`~mmconcepts.engine.data.DataPlan`: sets found under the data root or given with
        ``--data NAME=PATH``, among the experiment's ``datasets``; none on generated data). Ask
        for one by its registry name: :meth:`has_dataset`, :meth:`dataset`, or
        :meth:`require_data` to get it or skip.
    cache_dir : Path, optional
        Folder for generated data and caches (default :func:`mmconcepts._paths.data_home`).
    logger : logging.Logger, optional
        Where to log (default ``logging.getLogger("mmconcepts.experiments")``).
    show_progress : bool, default=True
        Show progress bars; they are shown only when stderr is a terminal (:attr:`verbose`).
    client : distributed.Client, optional
        A Dask client: :meth:`parallel` then runs its items on that cluster's workers
        (``workers`` is not used). See :mod:`mmconcepts.engine.cluster`.
    datasets : tuple of str, default=()
        The names of the real data sets the experiment declares (the runner sets them):
        :meth:`has_dataset` accepts them beside the registry's.
    """

    workers: int = 1
    data: Mapping[str, Path] = field(default_factory=dict)
    cache_dir: Path = field(default_factory=lambda: data_home())
    logger: logging.Logger = field(default_factory=lambda: logging.getLogger("mmconcepts.experiments"))
    show_progress: bool = True
    client: Any = None
    datasets: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, numbers.Integral):
            raise ParameterError(f"workers must be an int >= 1 or -1; got {self.workers!r}.")
        if self.workers == -1:
            self.workers = os.cpu_count() or 1
        if self.workers < 1:
            raise ParameterError(f"workers must be an int >= 1 or -1 (all CPUs); got {self.workers}.")
        self.workers = int(self.workers)
        self.data = MappingProxyType({str(k): Path(v) for k, v in self.data.items()})
        self.cache_dir = Path(self.cache_dir)

    @property
    def verbose(self) -> bool:
        """Whether this run shows progress: :attr:`show_progress` asked for it and stderr is a terminal.

        The ``verbose=`` to give the package's feature extractors and data generators that an
        experiment calls in this process (a task run by :meth:`parallel` draws no bar of its
        own: bars from several processes would write over each other).
        """
        return progress_enabled(self.show_progress)

    def progress(self, iterable: Iterable[_T], *, total: int | None = None, desc: str | None = None) -> Iterable[_T]:
        """Wrap ``iterable`` in a tqdm progress bar on stderr when :attr:`verbose` (else return it as it is).

        Parameters
        ----------
        iterable : iterable
        total : int, optional
            Number of items, when ``len(iterable)`` is not available.
        desc : str, optional
            Label shown before the bar.
        """
        return progress_bar(iterable, verbose=self.verbose, total=total, desc=desc)

    def parallel(self, fn: Callable[[_T], _R], items: Iterable[_T], *, desc: str | None = None,
                 on_result: Callable[[int, _R], None] | None = None) -> list[_R]:
        """Return ``[fn(item) for item in items]``, computed over :attr:`workers` processes.

        With ``workers == 1`` this is a plain loop in this process. Otherwise joblib's
        process pool is used, so ``fn`` and the items must pickle (define ``fn`` at
        module level) and each item must carry its own seed. With a :attr:`client`, the
        items run on the Dask cluster's workers instead (even a single item), each result
        fetched as soon as it is ready (:func:`~mmconcepts.engine.cluster.map_in_order`).
        Order is preserved. Warnings
        raised in a worker process are raised again here, in this process, so that the
        caller (and the runner's record of the run's warnings) sees the same warnings
        whatever the number of workers. The worker processes end with this process, even
        when it is killed (SIGKILL) in the middle of a task: at once on Linux, elsewhere
        within about a second (as soon as the worker runs Python code).

        Parameters
        ----------
        fn : callable
        items : iterable
        desc : str, optional
            Progress-bar label.
        on_result : callable, optional
            ``on_result(i, result)`` is called as soon as item ``i``'s result is back, in
            order, before the next one is awaited (e.g. to cache it, so that an interrupted
            run keeps what it has computed).
        """
        items = list(items)
        out: list[_R] = []
        if self.client is not None:
            return self._parallel_dask(fn, items, desc=desc, on_result=on_result)
        if self.workers == 1 or len(items) <= 1:
            for item in self.progress(items, total=len(items), desc=desc):
                out.append(fn(item))
                if on_result is not None:
                    on_result(len(out) - 1, out[-1])
            return out
        from joblib import Parallel, delayed

        n_jobs = min(self.workers, len(items))
        with workers_end_with_this_process():
            gen = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(WarningsCarried(fn))(item) for item in items)
            for result, caught in self.progress(gen, total=len(items), desc=desc):
                for category, message, filename, lineno in caught:
                    warnings.warn_explicit(message, category, filename, lineno)
                out.append(result)
                if on_result is not None:
                    on_result(len(out) - 1, result)
        return out

    def _parallel_dask(self, fn: Callable[[_T], _R], items: list[_T], *, desc: str | None,
                       on_result: Callable[[int, _R], None] | None) -> list[_R]:
        from .cluster import map_in_order

        def emit(i: int, carried: tuple[_R, list]) -> None:
            result, caught = carried
            for category, message, filename, lineno in caught:
                warnings.warn_explicit(message, category, filename, lineno)
            if on_result is not None:
                on_result(i, result)

        carried = map_in_order(self.client, WarningsCarried(fn), items,
                               progress=lambda it, n: self.progress(it, total=n, desc=desc), on_result=emit)
        return [result for result, _ in carried]

    def memory(self, name: str) -> CacheStore:
        """A disk cache under ``cache_dir/name`` that never unpickles (a ``CacheStore``).

        ``ctx.memory(name).cache(f, ignore=[...])`` is ``f`` with its results kept on disk:
        an entry is reused only for the same arguments (hashed; leave out with ``ignore=``
        the ones the others stand for, such as this context or data summarised by a
        digest), the same source of ``f`` and the same
        :func:`~mmconcepts._fingerprint.code_fingerprint` (the key scheme of
        :mod:`mmconcepts._store`): a change anywhere in the package recomputes. Each entry
        is one ``.npz`` file of the package's no-pickle codec (:mod:`mmconcepts._codec`)
        written atomically and read with ``allow_pickle=False``: ``f`` may return None,
        bools, ints, floats, strings, numpy arrays and scalars, and lists, tuples, dicts,
        the package's named tuples and fitted estimators of these (anything else raises
        :class:`~mmconcepts.errors.ExperimentError`). An entry that cannot be read (torn,
        or not in this format, such as a planted pickle) is computed again, never
        loaded. Call the cached function through :func:`cached_call`.

        Parameters
        ----------
        name : str
            The cache's folder under :attr:`cache_dir` (e.g. ``"ch3-folds"``).
        """
        from .cache import CacheStore

        return CacheStore(self.cache_dir / name)

    def parallel_cached(self, cached: Callable[..., _R], calls: Sequence[tuple], *, desc: str | None = None) -> list[_R]:
        """Return ``[cached(*args) for args in calls]`` for a function cached with :meth:`memory`.

        The calls already in the cache are read here; the others run through
        :meth:`parallel`, where each worker writes its call's entry as soon as that call
        ends, so an interrupted run keeps every call it finished (and resumes from there).
        An entry that cannot be read is computed again.

        Parameters
        ----------
        cached : CachedFunction
            ``ctx.memory(name).cache(f, ignore=...)``, ``f`` defined at module level.
        calls : sequence of tuple
            The positional arguments of each call.
        desc : str, optional
            Progress-bar label.
        """
        out: list[Any] = [None] * len(calls)
        todo = []
        lookup = getattr(cached, "lookup", None)
        for i, args in enumerate(calls):
            found, value = lookup(*args) if lookup is not None else (False, None)
            if found:
                out[i] = value
            else:
                todo.append(i)
        done = self.parallel(_cached_item, [(cached, *calls[i]) for i in todo], desc=desc)
        for i, result in zip(todo, done):
            out[i] = result
        return out

    def has_dataset(self, name: str) -> bool:
        """Whether this run has the real data set ``name``.

        Raises
        ------
        ExperimentError
            If ``name`` is neither a data set of the registry (:data:`mmconcepts.datasets.DATASETS`)
            nor one the experiment declares (:attr:`datasets`): a misspelt name fails here instead
            of falling back to generated data without a word.
        """
        if name in self.data:
            return True
        from ..datasets import DATASETS

        known = list(dict.fromkeys([*DATASETS, *self.datasets]))
        if name not in known:
            close = difflib.get_close_matches(str(name), known, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ExperimentError(f"no data set named {name!r} among {', '.join(known)}.{hint}")
        return False

    def dataset(self, name: str) -> Path:
        """The folder (or file) of the real data set ``name`` this run has (see :meth:`has_dataset`).

        Raises
        ------
        ExperimentError
            If ``name`` is no data set of the registry or of the experiment, or this run lacks it (ask
            :meth:`has_dataset` first, or :meth:`require_data` to skip without it).
        """
        if not self.has_dataset(name):
            raise ExperimentError(f"this run has no real data set {name!r}; ask ctx.has_dataset({name!r}) first.")
        return Path(self.data[name])

    def require_data(self, name: str, *, hint: str = "") -> Path:
        """Return the path given for data set ``name``, or skip the experiment.

        Raises
        ------
        ExperimentSkipped
            If this run has no real set ``name`` (none found under the data root, nor given with
            ``--data name=PATH``).
        """
        if self.has_dataset(name):
            return self.dataset(name)
        more = f" {hint}" if hint else ""
        raise ExperimentSkipped(
            f"needs the real data set {name!r}: put it under the data root (--data-root DIR or "
            f"$MMCONCEPTS_DATA_ROOT; see `mmconcepts data list`) or pass --data {name}=PATH.{more}"
        )


def cached_call(cached: Callable[..., _R], *args: Any) -> _R:
    """``cached(*args)`` for a function cached with :meth:`RunContext.memory`.

    The one way the experiments call a cached function (kept as the place to change how
    cached calls are made, e.g. to silence a note of the cache about itself).
    """
    return cached(*args)


def _cached_item(item: tuple) -> Any:
    """``cached(*args)`` of ``item = (cached, *args)``, a call :meth:`RunContext.parallel_cached` found
    missing: computed and its entry written (unless another process wrote it meanwhile: read under its lock)."""
    cached, *args = item
    compute = getattr(cached, "compute", None)
    return compute(*args) if compute is not None else cached_call(cached, *args)


def array_digest(arrays: Iterable[np.ndarray]) -> str:
    """A digest (hex SHA-1) of a sequence of arrays: their shapes, dtypes and values.

    For cache keys that stand for data too large to hash on every call (see
    :meth:`RunContext.memory`).
    """
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.shape}{a.dtype.str}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


