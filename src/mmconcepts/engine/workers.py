"""The worker processes of a run (internal): they end with their parent, keep what they load, and carry
their warnings back.

:meth:`~mmconcepts.engine.context.RunContext.parallel` and the batch runner run tasks on joblib's loky
worker processes (or a Dask cluster) under :func:`workers_end_with_this_process`; each task is wrapped in
:class:`WarningsCarried` so that the warnings it raises reach the caller.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any, cast

__all__ = ["HEAP_THRESHOLD", "WORKER_GC_INTERVAL", "WORKER_MEMORY_GROWTH", "WarningsCarried", "allocate_from_heap",
           "end_with_parent", "init_worker", "progress_enabled", "release_free_memory", "workers_end_with_this_process"]


class WarningsCarried:
    """Call ``fn`` in a worker process and return its result with the warnings it raised.

    After each call the worker gives the memory its task freed back to the system
    (:func:`release_free_memory`), so that what one task or experiment needed at its peak
    does not stay counted against the worker through the next ones.
    """

    def __init__(self, fn: Callable[[Any], Any]) -> None:
        self.fn = fn

    def __call__(self, item: Any) -> tuple[Any, list[tuple[type[Warning], str, str, int]]]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = self.fn(item)
        release_free_memory()
        return result, [(w.category, str(w.message), w.filename, w.lineno) for w in caught]


def release_free_memory() -> bool:
    """Return the free memory of the C heap to the system: glibc's ``malloc_trim(0)``.

    numpy's arrays of the size a task allocates (a few MB and more) come from ``mmap`` and go
    back to the system when freed, but glibc raises its mmap threshold up to 32 MB as such
    blocks are freed, after which blocks under it come from the heap's arenas (one per thread
    that allocated: numba's and the BLAS's threads too), which keep their freed pages
    until trimmed. Elsewhere than on glibc (musl, macOS, Windows) this does nothing.

    Returns
    -------
    bool
        Whether memory was returned (False also where there is no ``malloc_trim``).
    """
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


#: The size below which a run's processes take memory blocks from the C heap rather than from ``mmap``, and the
#: free memory the heap may keep at its top before giving it back (:func:`allocate_from_heap`).
HEAP_THRESHOLD = 2**30

# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def allocate_from_heap(threshold: int = HEAP_THRESHOLD) -> bool:
    """Take the blocks of a run's arrays from the C heap and keep the memory they free for the next ones.

    glibc serves a block of more than 32 MB (and, until blocks of its size have been freed,
    of more than 128 kB) with a fresh ``mmap``, and unmaps it when it is freed; it also gives
    back free memory at the heap's top beyond 128 kB or so. The next array of that size then
    faults in new zeroed pages, and an experiment that allocates and frees such arrays in each
    iteration spends much of its system time there. This sets glibc's ``M_MMAP_THRESHOLD``
    and ``M_TRIM_THRESHOLD`` (``mallopt``) to ``threshold``: blocks under it come from the
    heap, and freed ones are reused without faults. A worker still gives its free memory
    back after each task (:func:`release_free_memory`). The numbers computed are the same.
    Elsewhere than on glibc this does nothing.

    Parameters
    ----------
    threshold : int, default=:data:`HEAP_THRESHOLD`
        Bytes.

    Returns
    -------
    bool
        Whether glibc took both settings.
    """
    mallopt = _mallopt()
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, int(threshold))) & bool(mallopt(_M_TRIM_THRESHOLD, int(threshold)))


@functools.cache
def _glibc(name: str) -> Callable[..., int] | None:
    """glibc's function ``name`` (None elsewhere)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        return cast("Callable[..., int]", getattr(ctypes.CDLL(None), name))
    except (OSError, AttributeError):  # not glibc
        return None


def _mallopt() -> Callable[[int, int], int] | None:
    return _glibc("mallopt")


def _malloc_trim() -> Callable[[int], int] | None:
    return _glibc("malloc_trim")


def workers_end_with_this_process() -> contextlib.AbstractContextManager[Any]:
    """A joblib config under which the (loky) worker processes end when this process ends.

    loky's workers outlive a parent killed with SIGKILL: one busy with a task finishes it, and
    an idle one waits for its idle timeout (300 s). Under this config each worker runs
    :func:`init_worker` when it starts. Another joblib back end chosen by the caller
    (``joblib.parallel_config``) is left as it is.
    """
    try:
        from joblib import parallel_config
        from joblib.parallel import get_active_backend

        backend, _ = get_active_backend()
    except ImportError:  # pragma: no cover - an older joblib
        return contextlib.nullcontext()
    if type(backend).__name__ != "LokyBackend":
        return contextlib.nullcontext()
    return cast("contextlib.AbstractContextManager[Any]",
                parallel_config(backend="loky", initializer=init_worker, initargs=(os.getpid(),)))


#: How much a worker's memory may grow after its first task before loky replaces it (loky's
#: own guard against leaks is 300 MB). A run's workers keep what they load on purpose, from one
#: task and one experiment to the next: the numba kernels, librosa, the text-to-speech voice
#: (its size is in ``benchmarks/README.md``); at 300 MB loky kept replacing them, and each new
#: worker imported and loaded all of it again. loky measures a worker's memory only where psutil is
#: installed (it comes with the ``dask`` and ``dev`` extras, not with ``all``): without it, loky
#: replaces no worker, whatever its memory.
WORKER_MEMORY_GROWTH = 2**30


#: The least time between two of loky's checks of a worker for leaks (s), each a full garbage collection where
#: psutil is not installed (loky's own delay is 1 s: a collection after nearly every task). A run's worker holds
#: what it loaded (the modules, numba's kernels, the voice), hundreds of thousands of objects that every full
#: collection visits again (``benchmarks/README.md``). Python's own collections of the young generations still
#: free the reference cycles a task leaves.
WORKER_GC_INTERVAL = 60.0


def init_worker(parent_pid: int) -> None:
    """Initializer of a worker process: :func:`end_with_parent`, :func:`allocate_from_heap`, and loky's leak
    guard at :data:`WORKER_MEMORY_GROWTH`, checked at most every :data:`WORKER_GC_INTERVAL` seconds (private loky
    settings, read by the worker after each task)."""
    end_with_parent(parent_pid)
    allocate_from_heap()
    with contextlib.suppress(ImportError):
        from joblib.externals.loky import process_executor

        if isinstance(getattr(process_executor, "_MAX_MEMORY_LEAK_SIZE", None), int):
            process_executor._MAX_MEMORY_LEAK_SIZE = max(process_executor._MAX_MEMORY_LEAK_SIZE,
                                                         WORKER_MEMORY_GROWTH)
        if isinstance(getattr(process_executor, "_MEMORY_LEAK_CHECK_DELAY", None), (int, float)):
            process_executor._MEMORY_LEAK_CHECK_DELAY = max(process_executor._MEMORY_LEAK_CHECK_DELAY,
                                                            WORKER_GC_INTERVAL)


def end_with_parent(parent_pid: int) -> None:
    """Initializer of a worker process: end this worker as soon as ``parent_pid`` (its parent) ends.

    On Linux the kernel sends the worker SIGKILL when its parent dies (``prctl`` with
    ``PR_SET_PDEATHSIG``), even while the worker computes; everywhere a daemon thread also
    checks every half second that the parent is still the same process.
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - no libc prctl
            pass
    if os.getppid() != parent_pid:  # the parent ended before the worker got here
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="mmconcepts-watch-parent", daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(0.5)
    os._exit(1)


def progress_enabled(show: bool) -> bool:
    try:
        return bool(show) and sys.stderr is not None and sys.stderr.isatty()
    except (AttributeError, ValueError):  # closed or replaced stream
        return False
