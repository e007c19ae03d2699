"""Numba's ``njit`` with compilation shared between the processes of one machine (internal).

Every kernel of the package is compiled with ``cache=True``: the first process to call it
compiles it (the cluster tree's DTW search is the slowest to compile) and writes the
machine code to numba's on-disk cache, and later processes load it instead. But
processes that start together, such as the worker processes of one experiment or two
experiments run side by side on a fresh install, all miss the cache at once and each
compiles the same kernel. :func:`njit` adds an inter-process lock around numba's
compile-on-first-call: the first process compiles and writes the cache, and the others wait
for it, then load the cached code instead of compiling it again.

The lock is a file per kernel under ``<cache>/.locks/numba`` in the user's cache folder
(:func:`mmconcepts._io.folder_lock`: ``fcntl.flock``, released when the process ends). It
is taken only when a call finds no compiled version of the kernel for its argument types in
this process, so calls after the first cost nothing more. It hooks numba's
``Dispatcher._compile_for_args`` (what a call runs when no compiled version matches); with a
numba that does not have it, kernels compile as plain ``numba.njit`` would.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numba as nb
import threadpoolctl

from ._io import folder_lock

__all__ = ["njit", "lock_file", "first_use", "single_threaded"]


def _lock_dir() -> Path:
    """``<cache>/.locks/numba``: the user's cache folder (:func:`mmconcepts._paths.data_home`), where every lock of
    the package is (:data:`mmconcepts._store.LOCKS`), never a folder shared with other users."""
    from ._paths import data_home
    from ._store import LOCKS

    return data_home(create=False) / LOCKS / "numba"


def lock_file(dispatcher: Any) -> Path:
    """The lock file under which ``dispatcher`` compiles (one per kernel and source file).

    Parameters
    ----------
    dispatcher : numba.core.registry.CPUDispatcher
        A kernel made by :func:`njit`.
    """
    func = dispatcher.py_func
    where = hashlib.sha1(os.path.abspath(func.__code__.co_filename).encode()).hexdigest()[:12]
    return _lock_dir() / f"{func.__module__}.{func.__qualname__}.{where}.lock"


def _shared(dispatcher: Any) -> Any:
    compile_for_args = getattr(dispatcher, "_compile_for_args", None)
    if compile_for_args is None:  # pragma: no cover - a numba without the hook
        return dispatcher

    @functools.wraps(compile_for_args)
    def locked(*args: Any, **kws: Any) -> Any:
        path = lock_file(dispatcher)
        with contextlib.ExitStack() as stack:
            with contextlib.suppress(OSError):  # no writable cache folder: compile unlocked
                stack.enter_context(folder_lock(path.parent, path.name))
            # numba looks in its disk cache before compiling: filled by whoever held the lock before
            return compile_for_args(*args, **kws)

    dispatcher._compile_for_args = locked
    return dispatcher


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` whose compilation, when ``cache=True``, is shared between processes.

    Used as ``@njit(**options)`` or ``@njit``, exactly as ``numba.njit``. With
    ``cache=True`` the returned dispatcher compiles its first call for new argument types
    under an inter-process lock (see the module docstring); it is an ordinary numba
    dispatcher otherwise (other kernels call it, ``.py_func``, ``.signatures``).

    Parameters
    ----------
    *args, **options
        Those of ``numba.njit``.
    """
    if len(args) == 1 and callable(args[0]) and not options:
        return nb.njit(args[0])
    decorate: Callable[[Any], Any] = nb.njit(*args, **options)
    if not options.get("cache", False):
        return decorate
    return lambda func: _shared(decorate(func))


_FIRST_USES: set[str] = set()


@contextlib.contextmanager
def first_use(name: str) -> Iterator[None]:
    """Run the block under the machine-wide lock ``name`` until it has once completed in this process.

    For libraries that compile numba kernels of their own with ``cache=True``, outside
    :func:`njit`'s lock: librosa compiles its ufuncs when its modules are first imported on a
    fresh install (the cost is in ``benchmarks/README.md``), and worker processes that start
    together would each compile them. Under this lock the first process compiles and writes numba's cache,
    the others wait and then load it. Once a block has run to its end in a process, later
    blocks of the same ``name`` in that process take no lock; a block that raised leaves it
    to be taken again next time.

    Parameters
    ----------
    name : str
        What the lock is for (a file ``first-use.<name>.lock`` in the lock folder of
        :func:`lock_file`).
    """
    if name in _FIRST_USES:
        yield
        return
    path = _lock_dir() / f"first-use.{name}.lock"
    with contextlib.ExitStack() as stack:
        with contextlib.suppress(OSError):  # no writable temporary folder: run unlocked
            stack.enter_context(folder_lock(path.parent, path.name))
        yield
    _FIRST_USES.add(name)


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """BLAS (threadpoolctl) and numba's parallel kernels limited to one thread, then restored.

    The experiments run their folds and repetitions side by side (``ctx.parallel``), one per
    worker process: a fit that also spread over every core would only compete with the
    other tasks. The NMF kernels give the same numbers, bit for bit, with any number of
    threads (the kernels sum every entry in the same order), so this changes the time, never the result.
    """
    before = nb.get_num_threads()
    nb.set_num_threads(1)
    try:
        with threadpoolctl.threadpool_limits(1):
            yield
    finally:
        nb.set_num_threads(before)
