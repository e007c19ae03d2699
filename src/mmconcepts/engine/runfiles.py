"""A run's files in its results folder: under its record's lock, reused only as written, written all at once or
not at all, kept in the cache when they cannot be written.

Lock
    :func:`record_lock` is the exclusive lock ``<output>/.locks/<id>.json.lock`` (``<id>.synthetic.json.lock``
    for the run on generated data beside a real-data one; :func:`mmconcepts._store.store_lock`), held by
    :func:`~mmconcepts.engine.run_experiment` from the look at the record on disk until the new record is
    written: a second run of the same experiment into the same folder waits, then finds the first's record up to
    date and returns it instead of computing it again.
Reuse
    :func:`current_record` returns the record on disk when it is up to date
    (:func:`~mmconcepts.engine.outputs.up_to_date`). A record whose content does not match its digest
    (:mod:`.digest`: edited after it was written) never is: it is computed again, with a warning naming the file.
    A record of a schema before digests is computed again once (said at level INFO).
Room
    Before computing, the results folder's disk must have :data:`RESULTS_ROOM` bytes free
    (:func:`mmconcepts._io.check_output_dir`).
Writing
    :func:`render_files` turns a run's figures, explorer files and figure data into bytes before anything is
    written; :func:`write_run` writes them and the record: the record's JSON to a temporary file first, then the
    figure folder built beside and moved into place, then the JSON renamed into place. A failure at any step
    leaves the folder as it was (no record, no figure folder, no temporary file of the run).
Keeping
    When a run's files cannot be written (a full disk, a folder made read-only meanwhile), :func:`write_record`
    keeps the record and its files in the cache folder (``<cache>/kept-runs/<key>.npz``, the package's no-pickle
    codec, keyed by the record file and the code) and raises a one-line :class:`~mmconcepts.errors.ExperimentError`;
    the next run of the same experiment into the same folder writes them (:func:`restore_kept`) instead of
    computing them again. When they cannot be kept either, the metrics are logged (level WARNING).
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from .._codec import CorruptFile
from .._io import atomic_dir, atomic_write, leftover_dirs
from .._store import MISSING, cache_key, read_entry, store_lock, write_entry
from ..errors import ExperimentError
from .experiment import Experiment
from .media import EXPLORER_DIR, render_explorer
from .outputs import FIGURE_DATA, figure_png, load_record, record_path, remove_stale_figures, same_run, up_to_date
from .record import ResultRecord
from .redraw import figure_data_bytes
from .spec import Result

__all__ = ["RESULTS_ROOM", "KEPT_RUNS", "record_lock", "current_record", "render_files", "write_run", "write_record",
           "restore_kept", "remove_secondary_record"]

logger = logging.getLogger("mmconcepts.experiments")

#: The free bytes a results folder's disk must have before an experiment is computed into it.
RESULTS_ROOM = 32 * 2**20
#: The folder of the cache that keeps the runs whose files could not be written.
KEPT_RUNS = "kept-runs"


@contextlib.contextmanager
def record_lock(json_path: Path) -> Iterator[None]:
    """Hold the lock of the record ``json_path`` (see the module docstring); no lock where none can be made."""
    stack = contextlib.ExitStack()
    with stack:
        try:
            stack.enter_context(store_lock(json_path.parent, json_path))
        except OSError as exc:  # a folder that cannot be written: the writes will say so
            logger.debug("%s: no lock (%s)", json_path, exc)
        yield


def current_record(json_path: Path, fresh: ResultRecord, output: Path) -> ResultRecord | None:
    """The record at ``json_path`` when it is up to date with ``fresh`` (same config, code, data; as written), else
    None; one edited after it was written is named in a warning."""
    if not json_path.exists():
        return None
    existing = load_record(json_path)
    if existing is None:
        return None
    if existing.digest_ok is False:
        logger.warning("%s: its content does not match its digest (it was edited after it was written): computing "
                       "it again", json_path)
    elif existing.digest_ok is None and existing.status == "ok":
        logger.info("%s: written by an older version of the record schema (%s), which has no digest: computing it "
                    "again", json_path, existing.schema_version)
    return existing if up_to_date(existing, fresh, output) else None


def render_files(exp: Experiment, result: Result, record: ResultRecord, stem: str) -> dict[str, bytes]:
    """The files of a run as bytes, by their path relative to the results folder (``<stem>/hist.png``): its figures,
    its explorer's files and the figure data its ``present`` draws from; ``record``'s ``figures`` and ``explorer``
    set to list them."""
    files = {f"{stem}/{name}.png": figure_png(fig) for name, fig in result.figures.items()}
    record.figures = {name: f"{stem}/{name}.png" for name in result.figures}
    record.explorer, explorer = render_explorer(result.explorer, stem)
    files.update({f"{stem}/{EXPLORER_DIR}/{name}": data for name, data in explorer.items()})
    if exp.present is not None and result.figures:
        data = figure_data_bytes(result, exp.id)
        if data is not None:
            files[f"{stem}/{FIGURE_DATA}"] = data
    return files


def write_run(record: ResultRecord, files: Mapping[str, bytes], json_path: Path) -> None:
    """Write ``record`` to ``json_path`` and ``files`` (:func:`render_files`) to its figure folder, all or nothing.

    Raises
    ------
    OSError
        If something cannot be written; the folder is then as it was.
    """
    fig_dir = json_path.with_suffix("")
    pending = json_path.with_name(f".{json_path.name}.pending")
    for leftover in leftover_dirs(fig_dir):  # under the record's lock: a killed run's
        shutil.rmtree(leftover, ignore_errors=True)
    try:
        atomic_write(pending, record.to_json().encode("utf-8"))
        if files:
            with atomic_dir(fig_dir) as tmp:
                for rel, data in files.items():
                    atomic_write(tmp / rel.split("/", 1)[1], data)
        else:
            remove_stale_figures(fig_dir, ())
        try:
            os.replace(pending, json_path)
        except OSError:  # the figures are the new run's: an older record would not describe them
            json_path.unlink(missing_ok=True)
            raise
    finally:
        pending.unlink(missing_ok=True)


def _kept_entry(json_path: Path, cache_dir: Path) -> tuple[Path, str]:
    key = cache_key(KEPT_RUNS, str(json_path.resolve()))
    return cache_dir / KEPT_RUNS / f"{key}.npz", key


def write_record(record: ResultRecord, files: Mapping[str, bytes], json_path: Path, cache_dir: Path, *,
                 keep: bool = True) -> None:
    """:func:`write_run`; when it fails, keep the run in the cache (unless ``keep`` is False) and raise.

    Raises
    ------
    ExperimentError
        If the run's files cannot be written (one line: why, where the run is kept, what to do).
    """
    try:
        write_run(record, files, json_path)
    except OSError as exc:
        kept = _keep(record, files, json_path, cache_dir) if keep else _kept_entry(json_path, cache_dir)[0]
        where = f" ({exc.filename})" if exc.filename else ""
        then = (f"what it computed is kept in {kept}, and its next run into this folder writes it: it will not be "
                "computed again" if kept is not None else
                "what it computed could not be kept either (its metrics are logged above)")
        raise ExperimentError(
            f"{record.experiment}: its results cannot be written to {json_path.parent}: {exc.strerror or exc}{where}. "
            f"Nothing was written there; {then}. Fix: make room on that disk (or make the folder writable), or pass "
            "--output a folder on another disk.") from exc
    with contextlib.suppress(OSError):  # superseded (written, or a forced run after a failed write)
        _kept_entry(json_path, cache_dir)[0].unlink(missing_ok=True)
    if record.status == "ok" and keep:
        logger.info("%s: done in %.1f s, wrote %s", record.experiment, record.elapsed_s or 0.0, json_path)


def _keep(record: ResultRecord, files: Mapping[str, bytes], json_path: Path, cache_dir: Path) -> Path | None:
    path, key = _kept_entry(json_path, cache_dir)
    value = {"record": record.to_json(), "files": {rel: np.frombuffer(data, dtype=np.uint8)
                                                   for rel, data in files.items()}}
    try:
        write_entry(path, value, key)
        return path
    except OSError as exc:
        metrics = "; ".join(f"{name} = {value:.6g}" for name, value in record.metrics.items())
        logger.warning("%s: computed but neither written nor kept (%s): %s", record.experiment, exc, metrics)
        return None


def _kept_run(json_path: Path, fresh: ResultRecord, cache_dir: Path) -> tuple[ResultRecord, dict[str, bytes]] | None:
    path, key = _kept_entry(json_path, cache_dir)
    try:
        value = read_entry(path, key)
    except CorruptFile as exc:
        logger.warning("%s cannot be used (%s): computing it again", path, exc)
        return None
    if value is MISSING:
        return None
    try:
        record = ResultRecord.from_json(value["record"])
        files = {str(rel): np.asarray(data, dtype=np.uint8).tobytes() for rel, data in value["files"].items()}
    except (ExperimentError, KeyError, TypeError, ValueError, AttributeError) as exc:
        logger.warning("%s cannot be used (%s): computing it again", path, exc)
        return None
    stem = json_path.stem
    safe = all(rel.startswith(f"{stem}/") and ".." not in Path(rel).parts for rel in files)
    return (record, files) if safe and same_run(record, fresh) else None


def restore_kept(json_path: Path, fresh: ResultRecord, cache_dir: Path) -> ResultRecord | None:
    """Write the run kept in the cache for ``json_path`` when it stands for ``fresh``; return its record (None when
    there is none).

    Raises
    ------
    ExperimentError
        If it cannot be written now either (it stays kept).
    """
    found = _kept_run(json_path, fresh, cache_dir)
    if found is None:
        return None
    record, files = found
    write_record(record, files, json_path, cache_dir, keep=False)
    logger.info("%s: wrote %s from what its run computed before (kept when its files could not be written); not "
                "computed again", record.experiment, json_path)
    return record


def remove_secondary_record(output: str | os.PathLike[str], exp_id: str) -> None:
    """Delete ``exp_id``'s record on generated data beside a real-data run (and its figures), if there is one."""
    stale = record_path(output, exp_id, secondary=True)
    if stale.exists():
        with record_lock(stale):
            stale.unlink(missing_ok=True)
            remove_stale_figures(stale.with_suffix(""), ())
