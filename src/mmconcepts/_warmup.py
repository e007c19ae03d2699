"""Compile the slowest kernels ahead of their first use, in a process of their own (internal).

On a fresh install (or after numba's cache was emptied) the first call of a numba kernel
compiles it, under the kernel's inter-process lock (:mod:`mmconcepts._jit`), and every
process that needs it meanwhile waits. Where one computation needs several such kernels in
turn (the cluster tree inserts, splits by k-means, then searches; an MFCC front end loads
librosa, whose kernels compile when its modules are first imported), they compile one after
another while the processes that wait for them leave the other cores idle.

``python -m mmconcepts._warmup`` runs, one after another, the :data:`WARMERS`: each calls the
package's public functions on a few made-up values, which makes numba compile the kernels
they call, for the argument types the package's own computations give them, and write them
to its disk cache. A process that needs one of them later loads it from there, or, if the
warm-up is compiling it at that moment, waits for its lock as it would wait for any other
process. The warm-up compiles the kernels made with ``compile_apart=True`` itself (it ends
once they are compiled, so the compiler's memory does not matter). Nothing it computes is
kept: results do not depend on whether it ran.

:func:`in_background` starts it beside other work (``mmconcepts reproduce`` with
``--concurrent`` does, so that the kernels compile while the first experiments run rather
than one after another later, while the experiments that need them wait), unless it already
ran to its end for this code, this numba and this interpreter (a marker file in the lock
folder :func:`mmconcepts._jit.lock_dir`), or ``MMCONCEPTS_WARMUP=0`` is set.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

__all__ = ["STOP_TIMEOUT", "WARMERS", "WARMUP_ENV", "in_background", "marker_path", "warm_up"]

#: The warm-up's steps (``module:function`` of this module), in the order run.
WARMERS: tuple[str, ...] = (
    "mmconcepts._warmup:_mfcc",
    "mmconcepts._warmup:_cluster_tree",
    "mmconcepts._warmup:_dtw_matrix",
    "mmconcepts._warmup:_sparse_kl_nmf",
)

#: The environment variable that, set to ``0``, keeps :func:`in_background` from starting the warm-up.
WARMUP_ENV = "MMCONCEPTS_WARMUP"

#: How long :func:`in_background` waits, when its block ends, for a warm-up still running before it ends it (s).
STOP_TIMEOUT = 10.0


def _mfcc() -> None:
    """librosa's kernels: an MFCC sequence of a quarter of a second of a tone."""
    import numpy as np

    from .sound.features import MFCCConfig, mfcc

    sr = MFCCConfig().sr
    t = np.arange(sr // 4) / sr
    mfcc((0.1 * np.sin(2 * np.pi * 440.0 * t)).astype(np.float32))


def _cluster_tree() -> None:
    """The cluster tree's insertion, k-means split and search: a DTW tree over 40 windows, and a query."""
    import numpy as np

    from .sound.tree import ClusterTree

    X = np.random.default_rng(0).random((40, 6, 3))
    tree = ClusterTree(0.05, n_max=4, k=2, metric="dtw", search="restart", backtrack=2, random_state=0).fit(X)
    tree.query_batch(X[:3])


def _dtw_matrix() -> None:
    """The DTW distance matrix of a few short sequences (the serial kernel)."""
    import numpy as np

    from .sound.dtw import dtw_distance_matrix

    rng = np.random.default_rng(0)
    dtw_distance_matrix([rng.random((n, 3)) for n in (5, 6, 7)])


def _sparse_kl_nmf() -> None:
    """The sparse I-divergence updates and the coefficients' products at the nonzeros: a fit and a transform."""
    import scipy.sparse as sp

    from .nmf import NMF

    X = sp.random(30, 40, density=0.3, format="csr", random_state=0)
    NMF(2, beta_loss="kullback-leibler", max_iter=3, random_state=0).fit(X).transform(X)


def warm_up(warmers: tuple[str, ...] = WARMERS) -> list[str]:
    """Run ``warmers`` (``module:function``) one after another; the names of those that raised.

    A step that raises (an optional package missing, say) is skipped; its kernels then compile
    on their first use, as without the warm-up. Warnings are not shown.

    Parameters
    ----------
    warmers : tuple of str, default=WARMERS

    Returns
    -------
    list of str
        The steps that raised, in the order run.
    """
    failed = []
    for name in warmers:
        module, _, func = name.partition(":")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                getattr(importlib.import_module(module), func)()
        except Exception:  # noqa: BLE001 - best effort: the kernels compile on first use instead
            failed.append(name)
    return failed


def marker_path() -> Path:
    """The file that says the warm-up ran to its end for this code, this numba and this interpreter.

    In the lock folder (:func:`mmconcepts._jit.lock_dir`); its name is a digest of the package's code
    (:func:`mmconcepts._fingerprint.code_fingerprint`), numba's version and cache folder, and the
    interpreter.
    """
    import numba

    from ._fingerprint import code_fingerprint
    from ._jit import lock_dir

    key = "\0".join((code_fingerprint(), numba.__version__, str(getattr(numba.config, "CACHE_DIR", "")),
                     sys.executable, ",".join(WARMERS)))
    return lock_dir() / f"warm.{hashlib.sha1(key.encode()).hexdigest()[:16]}"


@contextlib.contextmanager
def in_background() -> Iterator[subprocess.Popen | None]:
    """Run the warm-up in a process of its own while the block runs (yields it, or None when not started).

    Not started when :func:`marker_path` exists (it ran to its end before), when
    ``$MMCONCEPTS_WARMUP`` (:data:`WARMUP_ENV`) is ``0``, or when the interpreter cannot be
    started. When the block ends, a warm-up still running is given :data:`STOP_TIMEOUT`
    seconds, then ended; when the block raises (Ctrl-C), the warm-up is ended at once (a kernel
    it was compiling compiles again on its next use; numba writes its cache files whole).
    """
    proc = None
    with contextlib.suppress(Exception):  # no marker folder, no interpreter: no warm-up
        if os.environ.get(WARMUP_ENV, "").strip() != "0" and sys.executable and not marker_path().exists():
            proc = subprocess.Popen([sys.executable, "-m", "mmconcepts._warmup"], stdin=subprocess.DEVNULL,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield proc
    except BaseException:
        if proc is not None and proc.poll() is None:  # interrupted: no reason to wait
            proc.kill()
            proc.wait()
        raise
    if proc is not None and proc.poll() is None:
        try:
            proc.wait(timeout=STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main() -> int:
    """Run the warm-up; write :func:`marker_path` when every step ran. Exit status 0, or 1 if a step raised."""
    from . import _jit
    from ._progress import QUIET_ENV

    _jit._IN_PLACE = True
    # silent, and leaving the notice to the processes that wait for a kernel (its output goes nowhere)
    os.environ.setdefault(QUIET_ENV, "1")
    failed = warm_up()
    if failed:
        return 1
    with contextlib.suppress(OSError):
        path = marker_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()
    return 0


if __name__ == "__main__":
    sys.exit(main())
