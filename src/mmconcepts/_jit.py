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

Some kernels take long to compile, and the process that compiles them keeps the compiler's
data for as long as it lives (numba keeps each compiled function's LLVM module, to link it
into later kernels); a worker process that compiled them stays that much larger than one
that loaded them from the cache (the sizes are in ``benchmarks/README.md``). Those kernels
are made with ``njit(compile_apart=True)``: when a process must compile one of them (its
argument types are neither compiled in the process nor in numba's disk cache), a short-lived
child process (:data:`sys.executable`) imports the kernel's module, compiles it for those
types and writes numba's cache, and the process then loads it from the cache. The child
costs its imports; where it cannot run, fails or takes longer than :data:`CHILD_TIMEOUT`,
the process compiles the kernel itself. In the child, kernels compile in place, without the
lock (which its caller holds) and without children of their own.

Compiling takes long the first time (a fresh install, an emptied cache), so the first
process that has to compile says so on stderr, once (:data:`COMPILE_NOTICE`): when numba
starts compiling (its ``numba:compile`` event) one of these kernels, or librosa's kernels in a
:func:`first_use` block; never when the code comes from numba's disk cache. The processes of
one command (a process group: the command, its worker processes) print it once between them,
through a marker file in the lock folder. Setting ``MMCONCEPTS_QUIET=1``
(:data:`mmconcepts._progress.QUIET_ENV`, as ``mmconcepts -q`` does) silences it.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numba as nb
import threadpoolctl
from numba.core import event as nb_event

from ._io import folder_lock
from ._progress import QUIET_ENV

__all__ = ["CHILD_TIMEOUT", "COMPILE_NOTICE", "compile_in_child", "compiles_apart", "first_use", "in_disk_cache",
           "lock_dir", "lock_file", "njit", "notice_compilation", "single_threaded"]

#: What a process prints on stderr when it starts compiling (once; see the module docstring).
COMPILE_NOTICE = ("mmconcepts: compiling numerical kernels on their first use (about a minute in all, once per "
                  "install; later runs load them from numba's cache) ...")

#: How long after a process printed the notice the other processes of its group stay silent (seconds): a
#: group id is a process id, which the system may give again, much later, to another command.
GROUP_NOTICE_SECONDS = 3600.0


def lock_dir() -> Path:
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
    return lock_dir() / f"{func.__module__}.{func.__qualname__}.{where}.lock"


def _shared(dispatcher: Any, apart: bool = False) -> Any:
    compile_for_args = getattr(dispatcher, "_compile_for_args", None)
    if compile_for_args is None:  # pragma: no cover - a numba without the hook
        return dispatcher

    @functools.wraps(compile_for_args)
    def locked(*args: Any, **kws: Any) -> Any:
        if _IN_CHILD:  # a compiling child: its caller holds the lock, and the child compiles everything itself
            return compile_for_args(*args, **kws)
        path = lock_file(dispatcher)
        with contextlib.ExitStack() as stack:
            with contextlib.suppress(OSError):  # no writable cache folder: compile unlocked
                stack.enter_context(folder_lock(path.parent, path.name))
            # numba looks in its disk cache before compiling: filled by whoever held the lock before
            with _noticing():
                if apart and not kws and not _IN_PLACE:
                    compile_in_child(dispatcher, args)
                return compile_for_args(*args, **kws)

    dispatcher._compile_for_args = locked
    locked.compile_apart = apart  # type: ignore[attr-defined]
    return dispatcher


def compiles_apart(dispatcher: Any) -> bool:
    """Whether ``dispatcher`` was made with ``njit(cache=True, compile_apart=True)``."""
    return bool(getattr(vars(dispatcher).get("_compile_for_args"), "compile_apart", False))


def njit(*args: Any, compile_apart: bool = False, **options: Any) -> Any:
    """``numba.njit`` whose compilation, when ``cache=True``, is shared between processes.

    Used as ``@njit(**options)`` or ``@njit``, exactly as ``numba.njit``. With
    ``cache=True`` the returned dispatcher compiles its first call for new argument types
    under an inter-process lock (see the module docstring); it is an ordinary numba
    dispatcher otherwise (other kernels call it, ``.py_func``, ``.signatures``).

    Parameters
    ----------
    *args, **options
        Those of ``numba.njit``.
    compile_apart : bool, default False
        With ``cache=True``: compile new argument types in a short-lived child process,
        which writes numba's disk cache, and load the code from there
        (:func:`compile_in_child`), so that the calling process does not keep the compiler's
        memory. For kernels that are called from Python and take long to compile; the
        kernels they call are compiled with them. A kernel must be an attribute of its module
        (``module.qualname``) for the child to find it.
    """
    if len(args) == 1 and callable(args[0]) and not options and not compile_apart:
        return nb.njit(args[0])
    decorate: Callable[[Any], Any] = nb.njit(*args, **options)
    if not options.get("cache", False):
        return decorate
    return lambda func: _shared(decorate(func), compile_apart)


def _argument_types(dispatcher: Any, args: tuple[Any, ...]) -> tuple[Any, ...]:
    """The numba types ``dispatcher`` compiles a call with ``args`` for (as its ``_compile_for_args`` types them)."""
    from numba.core import types
    from numba.core.dispatcher import OmittedArg

    return tuple(types.Omitted(a.value) if isinstance(a, OmittedArg) else dispatcher.typeof_pyval(a) for a in args)


def in_disk_cache(dispatcher: Any, argtypes: tuple[Any, ...]) -> bool | None:
    """Whether numba's disk cache holds ``dispatcher`` compiled for ``argtypes`` (None: cannot tell).

    Reads the cache's index as numba does before it loads an overload (the index key of the
    types and the machine, under the source file's stamp), without loading the code.

    Parameters
    ----------
    dispatcher : numba.core.registry.CPUDispatcher
        A kernel made with ``cache=True``.
    argtypes : tuple of numba types
        The types of a call's arguments.
    """
    try:
        cache = dispatcher._cache
        if not cache._enabled:
            return None
        dispatcher.targetctx.refresh()
        key = cache._index_key(tuple(argtypes), dispatcher.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - numba's private layout changed, or an unreadable index: cannot tell
        return None


def compile_in_child(dispatcher: Any, args: tuple[Any, ...]) -> bool:
    """Compile ``dispatcher`` for the types of ``args`` in a child process that writes numba's disk cache.

    Does nothing when the disk cache already holds those types, or when it cannot tell. The
    child is ``sys.executable`` with this process's ``sys.path`` and numba cache folder; it
    imports the kernel's module, compiles (printing :data:`COMPILE_NOTICE` as a compiling
    process does) and ends. The caller then loads the code from the cache; if the child
    could not write it (it failed, or could not start), the caller compiles the kernel itself,
    which also raises numba's own error for arguments it cannot type.

    Parameters
    ----------
    dispatcher : numba.core.registry.CPUDispatcher
        A kernel made with ``cache=True``, an attribute of its module.
    args : tuple
        The arguments of the call that needs the kernel.

    Returns
    -------
    bool
        Whether a child compiled the kernel and the disk cache now holds it.
    """
    import pickle
    import subprocess

    try:
        argtypes = _argument_types(dispatcher, args)
        if in_disk_cache(dispatcher, argtypes) is not False or not sys.executable:
            return False
        func = dispatcher.py_func
        # the path first: the child finds this package (and numba, to read the types) where this process does
        payload = pickle.dumps(list(sys.path)) + pickle.dumps((func.__module__, func.__qualname__, argtypes))
    except Exception:  # noqa: BLE001 - types numba cannot pickle: the caller compiles
        return False
    env = dict(os.environ)
    cache_dir = getattr(nb.config, "CACHE_DIR", "")  # set by NUMBA_CACHE_DIR, or in this process
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD], input=payload, stdout=subprocess.DEVNULL, env=env,
                              check=False, timeout=CHILD_TIMEOUT)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0 and in_disk_cache(dispatcher, argtypes) is True


#: How long a caller of :func:`compile_in_child` waits for its child (seconds) before it ends it and compiles the
#: kernel itself: far longer than the slowest kernel takes to compile.
CHILD_TIMEOUT = 600.0

#: Whether this process is a child of :func:`compile_in_child` (set by :func:`_child_main`).
_IN_CHILD = False

#: Whether this process compiles kernels made with ``compile_apart=True`` itself, under their lock, instead of in
#: a child: set by a process that ends once they are compiled (:mod:`mmconcepts._warmup`), whose memory does not
#: matter.
_IN_PLACE = False

_CHILD = ("import pickle, sys; sys.path[:] = pickle.load(sys.stdin.buffer); "
          "from mmconcepts._jit import _child_main; _child_main(sys.stdin.buffer)")


def _child_main(stream: Any) -> None:
    """The child of :func:`compile_in_child`: read ``(module, qualname, types)`` from ``stream`` and compile.

    Ends with exit status 1, silently, when the kernel cannot be compiled: the caller then
    compiles it itself and raises numba's error, once.
    """
    import importlib
    import pickle

    global _IN_CHILD
    _IN_CHILD = True  # a kernel the module calls as it is imported compiles here, without the caller's lock
    try:
        module, qualname, argtypes = pickle.load(stream)
        kernel: Any = importlib.import_module(module)
        for name in qualname.split("."):
            kernel = getattr(kernel, name)
        with _noticing():
            kernel.compile(tuple(argtypes))
    except Exception:  # noqa: BLE001 - reported by the caller's own compilation
        sys.exit(1)


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
    path = lock_dir() / f"first-use.{name}.lock"
    with contextlib.ExitStack() as stack:
        with contextlib.suppress(OSError):  # no writable temporary folder: run unlocked
            stack.enter_context(folder_lock(path.parent, path.name))
        with _noticing():
            yield
    _FIRST_USES.add(name)


_NOTICE_GIVEN = threading.Event()
_notice_lock = threading.Lock()


def notice_compilation() -> None:
    """Print :data:`COMPILE_NOTICE` on stderr, unless this process or its group already did, or ``MMCONCEPTS_QUIET``.

    Called when numba starts compiling under :func:`njit`'s lock or in a :func:`first_use`
    block; later calls in the process do nothing.
    """
    with _notice_lock:
        if _NOTICE_GIVEN.is_set():
            return
        _NOTICE_GIVEN.set()
    if os.environ.get(QUIET_ENV, "").strip() not in ("", "0") or not _first_in_group():
        return
    with contextlib.suppress(OSError, ValueError, AttributeError):  # no stderr, or a closed one
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)


def _first_in_group() -> bool:
    """Whether no other process of this one's process group gave the notice in the last :data:`GROUP_NOTICE_SECONDS`.

    The first to create the group's marker file (``compile-notice.<group id>`` in the lock
    folder) gives it; without a process group (Windows) or a writable lock folder, every
    process does.
    """
    getpgrp = getattr(os, "getpgrp", None)
    if getpgrp is None:  # pragma: no cover - not POSIX
        return True
    path = lock_dir() / f"compile-notice.{getpgrp()}"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        return True
    try:
        os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
        return True
    except FileExistsError:
        try:
            if time.time() - path.stat().st_mtime < GROUP_NOTICE_SECONDS:
                return False
            os.utime(path)  # a marker left by an earlier command of the same group id
        except OSError:
            pass
        return True
    except OSError:
        return True


class _CompileListener(nb_event.Listener):
    """Gives the notice when a ``numba:compile`` event starts."""

    def on_start(self, event: Any) -> None:
        notice_compilation()

    def on_end(self, event: Any) -> None:
        pass


_LISTENER = _CompileListener()


@contextlib.contextmanager
def _noticing() -> Iterator[None]:
    """Within the block, numba compiling anything in this process gives the notice (:func:`notice_compilation`)."""
    if _NOTICE_GIVEN.is_set():
        yield
        return
    with nb_event.install_listener("numba:compile", _LISTENER):
        yield


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
