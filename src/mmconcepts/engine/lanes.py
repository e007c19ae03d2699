"""Processes that run experiments one after another, for ``reproduce --concurrent`` (internal).

:func:`run_lanes` runs a list of experiments ``concurrent`` at a time. Each lane owns one
driver: a process (started with ``spawn``) that imports the package once, then runs the
experiments it is sent, in turn, with :func:`~mmconcepts.engine.runner.run_experiment`.
What one experiment paid for stays for the next: the imports (scikit-learn, SciPy, numba),
numba's kernels loaded from its cache, and the loky worker
processes of :meth:`~mmconcepts.engine.context.RunContext.parallel` (loky reuses them
while the joblib config is the same, which it is within one driver). A fresh process per
experiment paid for all of them again, in it and in each of its workers.

A driver's stdout and stderr (with log messages at WARNING and above, as ``mmconcepts run
--quiet`` prints them) go to a file; when a driver dies in the middle of an experiment (a
crash, the out-of-memory killer), that experiment gets a failed record quoting its exit
code and the file's last lines, and the lane starts a new driver for the next one. A
driver ends with the process that started it, even when that one is killed
(:func:`~mmconcepts.engine.workers.end_with_parent`), and so do its workers. On
Ctrl-C (or any error in the caller), the drivers are stopped and nothing more is started.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import queue
import sys
import tempfile
import threading
import traceback
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["Driver", "run_lanes"]

#: Lines of a dead driver's output quoted in the failed record.
TAIL_LINES = 20


class Driver:
    """One process that runs experiments when asked, one at a time.

    Parameters
    ----------
    log_dir : path-like
        Where its output file goes (removed by :meth:`close`).
    """

    def __init__(self, log_dir: str | os.PathLike[str]) -> None:
        fd, path = tempfile.mkstemp(prefix="driver-", suffix=".log", dir=log_dir)
        os.close(fd)
        self.log_path = Path(path)
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_main, args=(child, os.getpid(), str(self.log_path)),
                                   name="mmconcepts-experiments", daemon=False)
        self.process.start()
        child.close()

    def run(self, exp_id: str, variant: str, kwargs: Mapping[str, Any]) -> tuple[Any, str | None]:
        """Run experiment ``exp_id`` there: ``(record, None)``, or ``(None, why)`` if it could not.

        ``kwargs`` are passed to :func:`~mmconcepts.engine.runner.run_experiment`. When
        the driver dies on the way, ``why`` gives its exit code and the end of its output,
        and the driver is closed.
        """
        try:
            self._conn.send((exp_id, variant, dict(kwargs)))
            status, payload = self._conn.recv()
        except (EOFError, OSError):
            self.process.join(timeout=30)
            why = f"the run's process ended with exit code {self.process.exitcode} and no record: {self.tail()}"
            self.close()
            return None, why
        return (payload, None) if status == "ok" else (None, payload)

    def tail(self, n: int = TAIL_LINES) -> str:
        """The last ``n`` lines of the driver's output."""
        try:
            text = self.log_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""
        return "\n".join(text.strip().splitlines()[-n:])

    def close(self, *, wait: float = 30.0) -> None:
        """Stop the driver (at once if it is busy, else when asked to) and remove its output file."""
        with contextlib.suppress(OSError, ValueError):
            self._conn.send(None)
        self.process.join(timeout=wait)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
        if self.process.is_alive():  # pragma: no cover - a driver that ignores SIGTERM
            self.process.kill()
            self.process.join()
        self._conn.close()
        self.log_path.unlink(missing_ok=True)

    def kill(self) -> None:
        """End the driver now (and, through their parent-death signal, its workers)."""
        with contextlib.suppress(OSError, ValueError, AttributeError):
            self.process.terminate()


def _main(conn: Any, parent_pid: int, log_path: str) -> None:
    """A driver's loop: run each (id, variant, kwargs) received, answer ("ok", record) or ("error", text)."""
    from .workers import allocate_from_heap, end_with_parent

    end_with_parent(parent_pid)
    allocate_from_heap()
    fd = os.open(log_path, os.O_WRONLY | os.O_APPEND)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    root = logging.getLogger("mmconcepts")
    root.addHandler(handler)
    root.setLevel(logging.WARNING)

    from .registry import get
    from .runner import run_experiment

    try:
        while True:
            try:
                message = conn.recv()
            except EOFError:
                return
            if message is None:
                return
            exp_id, variant, kwargs = message
            os.ftruncate(fd, 0)  # the output of this experiment only (O_APPEND: writes go to the new end)
            try:
                reply: tuple[str, Any] = ("ok", run_experiment(get(exp_id), variant=variant, **kwargs))
            except Exception:  # not the experiment's own errors (they are in its record): arguments, registry
                reply = ("error", traceback.format_exc())
            conn.send(reply)
    finally:
        _end_workers()


def _end_workers() -> None:
    """End this process's idle worker processes (loky's), which it would otherwise wait for.

    A ``multiprocessing`` child joins its own children when it returns, and loky's idle
    workers only end after their idle timeout (300 s): the driver would outlive its last
    experiment by that much.
    """
    children = multiprocessing.active_children()
    for child in children:
        child.terminate()
    for child in children:
        child.join(timeout=10)


def run_lanes(runs: Sequence[tuple[str, str]], concurrent: int, kwargs: Mapping[str, Any], *,
              on_done: Callable[[int, Any, str | None], Any]) -> list[Any]:
    """Run ``runs`` (experiment id, variant) on ``concurrent`` drivers; return what ``on_done`` makes of each.

    Each lane takes the next run not yet started, so the runs start in their order.
    ``on_done(i, record, why)`` is called in the lane's thread when run ``i`` ends, with its
    record, or with ``None`` and why there is none; its return values, in the order of
    ``runs``, are returned.

    Parameters
    ----------
    runs : sequence of (str, str)
    concurrent : int
        Drivers (at most ``len(runs)``).
    kwargs : mapping
        For :func:`~mmconcepts.engine.runner.run_experiment` (picklable).
    on_done : callable
    """
    todo: queue.SimpleQueue[int] = queue.SimpleQueue()
    for i in range(len(runs)):
        todo.put(i)
    out: list[Any] = [None] * len(runs)
    stop = threading.Event()
    live: set[Driver] = set()
    lock = threading.Lock()
    errors: list[BaseException] = []

    def lane(log_dir: str, finished: threading.Event) -> None:
        driver: Driver | None = None
        try:
            while not stop.is_set():
                try:
                    i = todo.get_nowait()
                except queue.Empty:
                    return
                if driver is None:
                    with lock:
                        if stop.is_set():
                            return
                        driver = Driver(log_dir)
                        live.add(driver)
                record, why = driver.run(*runs[i], kwargs)
                if record is None and not driver.process.is_alive():
                    with lock:
                        live.discard(driver)
                    driver = None  # closed by run(); the next run gets a new driver
                if stop.is_set():
                    return
                out[i] = on_done(i, record, why)
        except BaseException as exc:  # pragma: no cover - a bug here must not hang the other lanes
            errors.append(exc)
            stop.set()
        finally:
            if driver is not None:
                with lock:
                    live.discard(driver)
                driver.close(wait=0 if stop.is_set() else 30)
            finished.set()

    with tempfile.TemporaryDirectory(prefix="mmconcepts-drivers-") as log_dir:
        # the drivers are started by the lanes' threads: a driver's parent-death signal is tied to that thread
        # (waited for through events: a Thread.join interrupted by Ctrl-C can take a running thread for ended)
        lanes = [threading.Event() for _ in range(min(concurrent, len(runs)))]
        try:
            for k, finished in enumerate(lanes):
                threading.Thread(target=lane, args=(log_dir, finished), name=f"mmconcepts-lane-{k}",
                                 daemon=True).start()
            for finished in lanes:
                while not finished.wait(timeout=0.5):
                    pass
        except BaseException:
            stop.set()
            with lock:
                for d in list(live):
                    d.kill()
            for finished in lanes:
                finished.wait(timeout=60)
            raise
    if errors:  # pragma: no cover
        raise errors[0]
    return out
