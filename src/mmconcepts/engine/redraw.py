"""Draw an experiment's figures again from what its run kept, without recomputing.

A run whose experiment draws its figures in ``present(result, config)`` keeps what
``present`` reads (the result's metrics, samples, units, tables, notes, extras and
``figure_data``) beside its figures, in ``<id>/figure_data.npz`` (the no-pickle format of
:mod:`mmconcepts._codec`). :func:`redraw_figures` reads it back with the record's
config and calls ``present`` again (``mmconcepts report --redraw``): a figure restyled in
the code is redrawn in seconds, the numbers untouched. The verdicts are the record's; they
are never decided again here.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._io import atomic_write
from .._codec import CorruptFile
from .._store import MISSING, entry_bytes, read_entry
from ..errors import ExperimentError, ParameterError
from .experiment import Experiment
from .media import EXPLORER_DIR
from .outputs import FIGURE_DATA, close_figures, load_record, remove_stale_figures, save_figures
from .record import ResultRecord
from .registry import get
from .spec import Result, Table
from .uncertainty import SampleUnit

__all__ = ["figure_data_bytes", "redraw_figures"]

logger = logging.getLogger("mmconcepts.experiments")


def figure_data_bytes(result: Result, exp_id: str) -> bytes | None:
    """The file ``<fig_dir>/figure_data.npz`` that keeps what ``present`` draws ``result`` from; None if it cannot
    be kept.

    A result whose ``figure_data`` holds something the codec does not store (an object of
    another library, a set) is not kept: its figures can then only be drawn by running it.
    """
    value = {
        "metrics": {k: float(v) for k, v in result.metrics.items()},
        "samples": {k: [float(x) for x in v] for k, v in result.samples.items()},
        "sample_units": dict(result.sample_units),
        "units": {k: u.to_dict() for k, u in result.units.items()},
        "tables": {k: t.to_dict() for k, t in result.tables.items()},
        "notes": list(result.notes),
        "extra": result.extra,
        "split_groups": result.split_groups,
        "figure_data": result.figure_data,
    }
    try:
        return entry_bytes(value, exp_id)
    except ParameterError as exc:
        logger.info("%s: its figures cannot be redrawn without running it (%s)", exp_id, exc)
        return None


def _result(kept: Mapping[str, Any]) -> Result:
    return Result(
        metrics=dict(kept["metrics"]),
        samples={k: list(v) for k, v in kept["samples"].items()},
        sample_units=dict(kept["sample_units"]),
        units={k: SampleUnit.from_dict(u) for k, u in kept["units"].items()},
        tables={k: Table.from_dict(t) for k, t in kept["tables"].items()},
        notes=list(kept["notes"]),
        extra=kept["extra"],
        split_groups=kept["split_groups"],
        figure_data=kept["figure_data"],
    )


def _config(exp: Experiment, record: ResultRecord) -> Any:
    """The record's config as the experiment's config class (JSON lists back to the tuples of its fields)."""
    template = exp.make_config("quick")
    values = {}
    for f in dataclasses.fields(template):
        if f.name not in record.config:
            raise ExperimentError(f"{exp.id}: the record's config has no field {f.name!r}; run the experiment again.")
        value = record.config[f.name]
        values[f.name] = _like(value, getattr(template, f.name))
    return dataclasses.replace(template, **values)


def _like(value: Any, example: Any) -> Any:
    if isinstance(example, tuple) and isinstance(value, list):
        inner = example[0] if example else None
        return tuple(_like(v, inner) for v in value)
    return value


def redraw_figures(output: str | os.PathLike[str], ids: Sequence[str] | None = None) -> dict[str, list[str]]:
    """Draw again the figures of every successful record in ``output`` (or of ``ids``) from what its run kept.

    Parameters
    ----------
    output : path-like
        A results folder.
    ids : sequence of str, optional
        Only these experiments.

    Returns
    -------
    dict of str to list of str
        Record file name -> the figures drawn (the record's ``figures`` rewritten when
        ``present`` now draws others); records without kept figure data (older runs, failed
        or skipped ones, experiments without ``present``) and records edited after they were
        written (their digest does not match) are left as they are and not listed.

    Raises
    ------
    ExperimentError
        If ``output`` is no folder, or a kept file is damaged (run that experiment again).
    """
    folder = Path(output)
    if not folder.is_dir():
        raise ExperimentError(f"no results folder {str(folder)!r}; expected the --output folder of a run.")
    drawn: dict[str, list[str]] = {}
    for path in sorted(folder.glob("*.json")):
        record = load_record(path)
        if record is None or record.status != "ok" or (ids and record.experiment not in ids):
            continue
        if record.digest_ok is False:  # rewritten here, an edited record would get a digest of its edits
            logger.warning("%s: not redrawn: its content does not match its digest (it was edited after it was "
                           "written); run %s again", path, record.experiment)
            continue
        fig_dir = path.with_suffix("")
        try:
            kept = read_entry(fig_dir / FIGURE_DATA, record.experiment)
        except CorruptFile as exc:
            raise ExperimentError(f"{fig_dir / FIGURE_DATA} is damaged ({exc}); run {record.experiment} again.") from exc
        if kept is MISSING:
            continue
        exp = get(record.experiment)
        if exp.present is None:
            continue
        figures = dict(exp.present(_result(kept), _config(exp, record)))
        try:
            saved = save_figures(figures, fig_dir)
        finally:
            close_figures(figures)
        if saved != record.figures:  # present draws other figures now: the record lists them
            record.figures = saved
            atomic_write(path, record.to_json().encode("utf-8"))
            remove_stale_figures(fig_dir, [*(Path(p).name for p in saved.values()), FIGURE_DATA, EXPLORER_DIR])
        drawn[path.name] = sorted(saved)
        logger.info("%s: redrew %d figure(s) in %s", record.experiment, len(saved), fig_dir)
    return drawn
