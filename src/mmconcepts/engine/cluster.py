"""Running experiments on a Dask cluster (``--scheduler``).

The repetitions, folds and sweep points an experiment submits through
:meth:`RunContext.parallel <mmconcepts.engine.RunContext.parallel>` go to the
workers of a ``dask.distributed`` cluster instead of local processes:

- ``local:N`` starts a ``LocalCluster`` of N single-threaded worker processes on
  127.0.0.1 for the duration of the command;
- ``tcp://HOST:PORT`` (or ``HOST:PORT``, ``tls://...``) connects to a running scheduler
  (``dask scheduler`` and ``dask worker ADDRESS`` on the machines, or dask-jobqueue,
  Kubernetes...).

The workers must run the same mmconcepts and see the data root and the cache folder at
the same paths (a shared file system): the tasks carry paths, never data sets. Each task
carries its own seed, so a run gives the same numbers whatever runs it. Results come back
as soon as each task ends; a worker that dies mid-task has that task run again elsewhere
by the scheduler (Dask's ``distributed.scheduler.allowed-failures``, default 3 attempts),
and results already received are kept.
"""

from __future__ import annotations

import contextlib
import logging
import re
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

from .._optional import optional_import
from ..errors import ExperimentError, ParameterError

__all__ = ["parse_scheduler", "open_client", "local_cluster", "map_in_order", "DEFAULT_CONNECT_TIMEOUT",
           "LOCAL_CLUSTER_CONFIG"]

_T = TypeVar("_T")
_R = TypeVar("_R")

#: Seconds to wait for a remote scheduler before giving up.
DEFAULT_CONNECT_TIMEOUT = 10.0

#: The dask settings of the clusters :func:`local_cluster` starts (and so ``--scheduler local:N``): the periodic
#: work of the cluster's own processes made rarer. With as many busy workers as cores, that work (the workers'
#: sampling profiler every 10 ms, the event loops' tick every 20 ms, the system monitor every 0.5 s and the
#: memory monitors every 0.1 s, distributed's defaults) takes its CPU from the tasks. Here the profiler (shown
#: only on a dashboard, which these clusters do not open) is off, and the memory limits are checked every half
#: second. A cluster started otherwise (``dask worker``) can be given the same settings in its dask configuration.
LOCAL_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "200ms",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "500ms",
}

_LOCAL = re.compile(r"^local:(\d+)$")
_ADDRESS = re.compile(r"^(?:(tcp|tls|inproc|ucx|ws|wss)://)?([^\s/:]+|\[[0-9a-fA-F:]+\]):(\d{1,5})$")

logger = logging.getLogger("mmconcepts.experiments")


def parse_scheduler(spec: str) -> tuple[str, Any]:
    """Check a ``--scheduler`` value and say what it asks for.

    Parameters
    ----------
    spec : str
        ``"local:N"`` (N >= 1 worker processes on this machine) or a scheduler address,
        ``"tcp://HOST:PORT"``, ``"tls://HOST:PORT"`` or ``"HOST:PORT"`` (tcp).

    Returns
    -------
    (kind, value) : ("local", int) or ("address", str)
        The number of local workers, or the full address (``tcp://`` added when missing).

    Raises
    ------
    ParameterError
        For anything else.
    """
    if not isinstance(spec, str):
        raise ParameterError(f"scheduler must be a string, 'local:N' or 'tcp://HOST:PORT'; got {spec!r}.")
    text = spec.strip()
    m = _LOCAL.match(text)
    if m:
        n = int(m.group(1))
        if n < 1:
            raise ParameterError(f"scheduler 'local:N' needs N >= 1 worker processes; got {spec!r}.")
        return "local", n
    m = _ADDRESS.match(text)
    if m and 0 < int(m.group(3)) < 65536:
        proto = m.group(1) or "tcp"
        return "address", f"{proto}://{m.group(2)}:{m.group(3)}"
    raise ParameterError(
        f"scheduler must be 'local:N' (N worker processes on this machine) or the address of a running "
        f"dask.distributed scheduler, 'tcp://HOST:PORT' or 'HOST:PORT'; got {spec!r}."
    )


def _distributed() -> Any:
    return optional_import("distributed", "dask", "a Dask cluster (--scheduler)")


def local_cluster(n_workers: int, **kwargs: Any) -> Any:
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes on 127.0.0.1.

    No dashboard, distributed's log messages below ERROR silenced, and the settings of
    :data:`LOCAL_CLUSTER_CONFIG` (given to the scheduler, the nannies and the worker
    processes when they start; the caller's dask configuration is left as it was).

    Parameters
    ----------
    n_workers : int
        Worker processes, each with one thread.
    **kwargs
        Passed on to ``LocalCluster`` (e.g. ``memory_limit``), over the defaults above.

    Returns
    -------
    distributed.LocalCluster
        Started; the caller closes it.
    """
    import dask

    distributed = _distributed()
    options: dict[str, Any] = dict(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=None, silence_logs=logging.ERROR)
    options.update(kwargs)
    with dask.config.set(LOCAL_CLUSTER_CONFIG), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # distributed's notes about ports and memory limits
        return distributed.LocalCluster(**options)


@contextlib.contextmanager
def open_client(spec: str, *, timeout: float | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` for ``spec`` (see :func:`parse_scheduler`), closed on exit.

    ``local:N`` starts a ``LocalCluster`` of N single-threaded worker processes listening
    on 127.0.0.1 only, without a dashboard (:func:`local_cluster`), and stops it on exit. ``timeout`` (seconds)
    bounds the wait for a remote scheduler (default :data:`DEFAULT_CONNECT_TIMEOUT`).

    Raises
    ------
    ParameterError
        If ``spec`` is not a scheduler specification.
    ExperimentError
        If the scheduler cannot be reached within ``timeout`` seconds (the message names
        the address), or dask.distributed is not installed.
    """
    kind, value = parse_scheduler(spec)
    timeout = DEFAULT_CONNECT_TIMEOUT if timeout is None else timeout
    distributed = _distributed()
    if kind == "local":
        cluster = local_cluster(value)
        try:
            with distributed.Client(cluster) as client:
                logger.info("started a local Dask cluster of %d worker(s) at %s", value, cluster.scheduler_address)
                yield client
        finally:
            cluster.close()
        return
    try:
        client = distributed.Client(value, timeout=f"{float(timeout)}s")
    except (OSError, TimeoutError) as exc:
        raise ExperimentError(
            f"could not reach the Dask scheduler at {value} within {float(timeout):g} s ({type(exc).__name__}: "
            f"{exc}). Start one there (`dask scheduler`, then `dask worker {value}` on each machine), check the "
            f"address, or use --scheduler local:N to start one on this machine."
        ) from None
    try:
        n = len(client.scheduler_info().get("workers", {}))
        logger.info("connected to the Dask scheduler at %s (%d worker(s))", value, n)
        if n == 0:
            logger.warning("the Dask scheduler at %s has no workers yet: tasks wait until one joins", value)
        yield client
    finally:
        client.close()


def map_in_order(client: Any, fn: Callable[[_T], _R], items: Iterable[_T], *,
                 progress: Callable[[Iterable[Any], int], Iterable[Any]] | None = None,
                 on_result: Callable[[int, _R], None] | None = None) -> list[_R]:
    """``[fn(item) for item in items]`` computed on the cluster of ``client``, in order.

    Each result is fetched as soon as its task ends and its future released (a worker
    that dies later loses nothing already received); ``on_result(i, result)`` is called
    in the items' order as soon as every earlier result is in.

    Parameters
    ----------
    client : distributed.Client
    fn : callable
        Must pickle (a module-level function), as must the items.
    progress : callable, optional
        ``progress(iterable, total)`` wraps the stream of finished tasks (a progress bar).
    on_result : callable, optional
    """
    distributed = _distributed()
    items = list(items)
    if not items:
        return []
    futures = client.map(fn, items, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    results: dict[int, Any] = {}
    next_out = 0
    out: list[_R] = []
    stream: Iterable[Any] = distributed.as_completed(futures)
    if progress is not None:
        stream = progress(stream, len(items))
    try:
        for fut in stream:
            i = index[fut.key]
            results[i] = fut.result()  # raises the task's own error
            fut.release()
            while next_out in results:
                out.append(results.pop(next_out))
                if on_result is not None:
                    on_result(next_out, out[-1])
                next_out += 1
    finally:
        for f in futures:
            if not f.done():
                f.cancel()
    return out


def scheduler_client(scheduler: Any) -> contextlib.AbstractContextManager[Any]:
    """A context giving the Dask client of ``scheduler`` (None: no cluster; a str: opened and closed here)."""
    if isinstance(scheduler, str):
        return open_client(scheduler)
    return contextlib.nullcontext(scheduler)
