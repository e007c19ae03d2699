"""The files of a run: where a record goes, reading one back, whether it is up to date, its figures
written and stale ones removed (everything written atomically).

Run experiments, write their results as JSON + PNG, skip what is up to date.

A result record is a JSON object with a stable schema (``schema_version`` 5)::

    schema_version  5
    experiment      id                       title, thesis_ref
    status          "ok" | "failed" | "skipped"
    message         why it failed or was skipped (null when ok)
    traceback       the traceback text of a failure (else null)
    preset          "quick" | "full" | "custom"  config (the dataclass as a dict), seed
                    ("custom": a config given to run_experiment that is no preset)
    variant         "real" | "synthetic"     which data it ran on: the real sets found
                                             (data root or --data) or generated stand-ins
    data            name -> absolute path of each real set used: the sets of the run's entry of
                    the data plan (:class:`~mmconcepts.engine.data.DataPlan`); empty when synthetic
    data_signature  name -> "<n> files, <bytes> bytes, newest <mtime>" of each set (part of
                    the up-to-date key: changed recordings recompute the result)
    version         mmconcepts.__version__
    code            fingerprint of the code that produced it (package sources and
                    dependency versions, :func:`mmconcepts._fingerprint.code_fingerprint`)
    metrics         name -> number (null for NaN or infinite, read back as NaN)
    intervals       name -> [low, high], the 95 % interval of a metric with samples (the
                    corrected resampled t for folds, :mod:`.uncertainty`)
    samples         name -> the per-fold / per-seed values behind a metric
    sample_units    name -> the unit of its samples, where the experiment names one
                    (metrics of one unit are paired)
    units           unit -> {kind, test_train_ratio, description}: independent seeds,
                    resampled folds or splits, or blocks within one fit
    split_groups    split -> what its examples are grouped by (no source recording on
                    both sides of a split) and how many groups
    reference       name -> the thesis' number
    claims          [{text, rule, kind, source, holds, verdict, basis, tests, scope,
                      ratio, ratio_interval, settings, detail, support}]
                    kind: "thesis" | "magnitude" | "ours" | "check"; source: where the
                    thesis says it; holds: the rule on the reported numbers; verdict:
                    "holds" | "fails" | "depends" | "inconclusive" | "not evaluated" (a
                    magnitude: "matches" | "below" | "above" | "inconclusive"), decided by
                    the 95 % interval of each comparison's margin, stored in ``tests``
                    (:mod:`.uncertainty`); ratio and ratio_interval: a magnitude's ours /
                    thesis; settings and detail: a claim decided under several settings
    tables          name -> {title, columns, rows, note}
    figures         name -> path of the PNG, relative to the results folder
    explorer        {} or {note, cards: [{title, note, labels: [{label, share}], clips: [{path, seconds,
                    sample_rate, caption}], images: [{path, width, height, caption}], motions: [{path,
                    frames, seconds, caption}]}]}: the concept explorer (:mod:`.explorer`), its files
                    (WAV, PNG, animated SVG) relative to the results folder
    notes, extra    remarks and JSON-able extras
    warnings        the distinct warnings raised during the run ("RuntimeWarning: 2 file(s)
                    of ... could not be read and were skipped ..."), so that the report
                    records what a loader skipped
    elapsed_s, started_at (ISO 8601, UTC), python, platform
    digest          the SHA-256 of every key above but elapsed_s and started_at, as canonical JSON
                    (:mod:`.digest`): a record whose content does not match it was edited after it
                    was written, and is computed again rather than reused (the report marks it)

The record of an experiment's default run is ``<output>/<id>.json`` (on the real sets
when any is found, else on generated data); when real sets were found, its run on
generated data is ``<output>/<id>.synthetic.json``. Figures go to ``<output>/<id>/`` (and
``<output>/<id>.synthetic/``), the explorer's files to ``<output>/<id>/explorer/``. Everything
is written atomically (a temporary file in the same folder, then :func:`os.replace`; the
explorer's folder built beside and moved into place), figures and explorer first, so a JSON
file on disk always describes complete results. Records of schemas 1 and 2 (before variants,
verdicts and claim kinds) are still read: their claims are of kind "unclassified"; records of
schema 3 (before the explorer) are read without one; records of schema 4 and older have no digest
(nothing to check: they are read, but computed again rather than reused).

In Python a record is a :class:`~mmconcepts.engine.record.ResultRecord`, whose
``to_json``/``from_json`` write and read this JSON (and which reads like its JSON dict:
``record["status"]``).
"""

from __future__ import annotations

import io
import logging
import os
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .._io import atomic_write
from ..errors import ExperimentError
from .media import EXPLORER_DIR, explorer_files
from .record import SCHEMA_VERSION, ResultRecord


__all__ = ["FIGURE_DATA", "load_record", "record_path", "same_run", "up_to_date", "figure_png", "save_figures", "close_figures",
           "remove_stale_figures"]

logger = logging.getLogger("mmconcepts.experiments")


#: The file beside a record's figures that keeps what its experiment's ``present`` draws them from
#: (:mod:`mmconcepts.engine.redraw`).
FIGURE_DATA = "figure_data.npz"

def load_record(path: str | os.PathLike[str]) -> ResultRecord | None:
    """Read a result record, or return None if ``path`` does not hold one.

    Metric values stored as null are read back as NaN; records of schema version 1 and
    records without the keys added since are read with their defaults
    (:meth:`ResultRecord.from_dict`).

    Parameters
    ----------
    path : str or path-like
        A ``<id>.json`` file written by :func:`run_experiment`.

    Returns
    -------
    ResultRecord or None
        The record; None when the file is not valid JSON, not a result record, or of a
        newer schema version.
    """
    path = Path(path)
    try:
        return ResultRecord.from_json(path.read_bytes())
    except OSError as exc:
        logger.debug("%s: not readable (%s)", path, exc)
    except ExperimentError as exc:
        logger.debug("%s: %s", path, exc)
    return None


def record_path(output: str | os.PathLike[str], exp_id: str, *, secondary: bool = False) -> Path:
    """Where a record goes: ``<output>/<id>.json``, or ``<output>/<id>.synthetic.json`` for
    the run on generated data of an experiment whose default run is on real data."""
    return Path(output) / (f"{exp_id}.synthetic.json" if secondary else f"{exp_id}.json")


def same_run(existing: ResultRecord, fresh: ResultRecord) -> bool:
    """Whether ``existing`` is a successful record, as it was written (its digest matches), of the run ``fresh``
    describes: the same schema, experiment, config, code, data, preset and variant."""
    if existing.status != "ok" or existing.digest_ok is not True:
        return False
    if existing.schema_version != SCHEMA_VERSION or existing.experiment != fresh.experiment:
        return False
    return all(getattr(existing, key) == getattr(fresh, key)
               for key in ("config", "code", "data", "data_signature", "preset", "variant"))


def up_to_date(existing: ResultRecord | None, fresh: ResultRecord, output: Path) -> bool:
    """Whether ``existing`` can stand for the run ``fresh`` describes (:func:`same_run`) and its files are in
    ``output``."""
    if existing is None or not same_run(existing, fresh):
        return False
    files = [*existing.figures.values(), *explorer_files(existing.explorer)]
    return all(isinstance(rel, str) and (output / rel).is_file() for rel in files)


def close_figures(figures: Mapping[str, Any]) -> None:
    if not figures:
        return
    import matplotlib.pyplot as plt

    for fig in figures.values():
        try:
            plt.close(fig)
        except Exception:  # pragma: no cover - a non-pyplot figure or already closed
            pass


def remove_stale_figures(fig_dir: Path, keep: Iterable[str]) -> None:
    """Delete the figures of ``fig_dir`` not named in ``keep`` (and its kept figure data and explorer folder, unless
    named)."""
    if not fig_dir.is_dir():
        return
    keep = set(keep)
    for png in fig_dir.glob("*.png"):
        if png.name not in keep:
            png.unlink()
    if FIGURE_DATA not in keep:
        (fig_dir / FIGURE_DATA).unlink(missing_ok=True)
    if EXPLORER_DIR not in keep:
        shutil.rmtree(fig_dir / EXPLORER_DIR, ignore_errors=True)
    try:
        fig_dir.rmdir()  # only succeeds when empty
    except OSError:
        pass


def figure_png(fig: Any) -> bytes:
    """The figure as the PNG file the runner writes (100 dpi, tight bounding box)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    return buf.getvalue()


def save_figures(figures: Mapping[str, Any], fig_dir: Path) -> dict[str, str]:
    """Write each figure as ``<fig_dir>/<name>.png`` (atomically); return name -> path relative to the output."""
    saved = {}
    for name, fig in figures.items():
        atomic_write(fig_dir / f"{name}.png", figure_png(fig))
        saved[name] = f"{fig_dir.name}/{name}.png"
    return saved
