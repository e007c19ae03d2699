"""Run experiments, write their results as JSON + PNG, skip what is up to date.

A result record is a JSON object with a stable schema (``schema_version`` 3)::

    schema_version  3
    experiment      id                       title, thesis_ref
    status          "ok" | "failed" | "skipped"
    message         why it failed or was skipped (null when ok)
    traceback       the traceback text of a failure (else null)
    preset          "quick" | "full" | "custom"  config (the dataclass as a dict), seed
                    ("custom": a config given to run_experiment that is no preset)
    variant         "real" | "synthetic"     which data it ran on: the real sets found
                                             (data root or --data) or generated stand-ins
    data            name -> absolute path of each real set used (empty when synthetic)
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
    notes, extra    remarks and JSON-able extras
    warnings        the distinct warnings raised during the run ("RuntimeWarning: 2 file(s)
                    of ... could not be read and were skipped ..."), so that the report
                    records what a loader skipped
    elapsed_s, started_at (ISO 8601, UTC), python, platform

The record of an experiment's default run is ``<output>/<id>.json`` (on the real sets
when any is found, else on generated data); when real sets were found, its run on
generated data is ``<output>/<id>.synthetic.json``. Figures go to ``<output>/<id>/`` (and
``<output>/<id>.synthetic/``). Everything is written atomically (a temporary file in the
same folder, then :func:`os.replace`), figures first, so a JSON file on disk always
describes complete results. Records of schemas 1 and 2 (before variants, verdicts and claim
kinds) are still read: their claims are of kind "unclassified".

In Python a record is a :class:`~mmconcepts.experiments.record.ResultRecord`, whose
``to_json``/``from_json`` write and read this JSON (and which reads like its JSON dict:
``record["status"]``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import io
import json
import logging
import math
import os
import platform
import re
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .. import __version__
from .._fingerprint import code_fingerprint
from .._io import atomic_write, check_output_dir
from .._paths import DEFAULT_RESULTS_DIR, data_home
from ..errors import ExperimentError, ParameterError
from .base import (
    PRESETS,
    Experiment,
    ExperimentSkipped,
    Result,
    RunContext,
    Table,
    check_seed,
)
from ._workers import workers_end_with_this_process
from .cluster import open_client, parse_scheduler
from .record import RECORD_KEYS, SCHEMA_VERSION, ClaimRecord, ResultRecord, to_jsonable
from .registry import all_experiments, get
from .uncertainty import metric_interval
from .verdicts import decide_claim, pending_claim

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "SCHEMA_VERSION",
    "RECORD_KEYS",
    "CUSTOM_PRESET",
    "ResultRecord",
    "run_experiment",
    "reproduce",
    "parse_data_args",
    "check_data",
    "load_record",
    "to_jsonable",
    "resolve_data",
    "record_path",
    "VARIANTS",
]

logger = logging.getLogger("mmconcepts.experiments")

#: The data variants of a run: on the real sets found, or on generated stand-ins.
VARIANTS = ("real", "synthetic")

#: The ``preset`` of a record whose config was given to :func:`run_experiment` and is no preset.
CUSTOM_PRESET = "custom"

_DATA_NAME = re.compile(r"[A-Za-z0-9_.-]+\Z")


# --------------------------------------------------------------------------- files


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


# --------------------------------------------------------------------------- data


def parse_data_args(items: Iterable[str] | None) -> dict[str, Path]:
    """Parse ``--data NAME=PATH`` arguments into ``{name: path}``.

    Raises
    ------
    ExperimentError
        On an item without ``=``, an empty or malformed name, an empty path, or a name
        given twice.
    """
    out: dict[str, Path] = {}
    for item in items or ():
        name, sep, path = str(item).partition("=")
        name = name.strip()
        if not sep or not name or not path:
            raise ExperimentError(f"--data expects NAME=PATH (e.g. choreo1=/data/choreo1); got {item!r}.")
        if not _DATA_NAME.fullmatch(name):
            raise ExperimentError(f"--data {item!r}: the name {name!r} must be a word ([A-Za-z0-9_.-]).")
        if name in out:
            raise ExperimentError(f"--data {name}=... is given twice ({out[name]} and {path}); give each data set once.")
        out[name] = Path(path).expanduser()
    return out


def check_data(
    data: Mapping[str, str | os.PathLike[str]] | None, experiments: Sequence[Experiment] | None = None
) -> dict[str, Path]:
    """Validate ``--data`` names and paths; return ``{name: absolute path}``.

    Parameters
    ----------
    data : mapping of str to path, optional
    experiments : sequence of Experiment, optional
        Experiments whose declared data-set names are accepted without consulting the
        registry; any other name must be declared by some registered experiment.

    Raises
    ------
    ExperimentError
        If no experiment declares a name, or a path does not exist (both are named).
    """
    if not data:
        return {}
    if isinstance(data, (str, bytes)) or not isinstance(data, Mapping):
        raise ExperimentError(f"data must be a mapping of data-set names to paths; got {type(data).__name__}.")
    from ..datasets import DATASETS

    resolved = {str(name): Path(path).expanduser() for name, path in data.items()}
    declared = {n for exp in experiments or () for n in exp.datasets} | set(DATASETS)
    if any(name not in declared for name in resolved):
        registered = all_experiments()
        declared |= {n for exp in registered for n in exp.datasets}
    unknown = sorted(name for name in resolved if name not in declared)
    if unknown:
        known = ", ".join(sorted(declared)) or "none"
        raise ExperimentError(
            f"--data {unknown[0]}=...: no experiment uses a data set named {unknown[0]!r}. "
            f"Known data-set names: {known} (see `mmconcepts list`)."
        )
    for name, path in resolved.items():
        if not path.exists():
            raise ExperimentError(f"--data {name}={path}: the path {str(path)!r} does not exist.")
    return {name: path.resolve() for name, path in resolved.items()}


def resolve_data(
    exp: Experiment,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
) -> dict[str, Path]:
    """The real data sets ``exp`` runs on: those of its ``datasets`` found under the data
    root, overridden by the ones given explicitly (``--data NAME=PATH``).

    Parameters
    ----------
    exp : Experiment
    data : mapping of str to path, optional
        Explicit sets; names the experiment does not declare are ignored.
    data_root : path, optional
        The data root (default: ``$MMCONCEPTS_DATA_ROOT``; none if unset). See
        :func:`mmconcepts.datasets.data_root`.

    Returns
    -------
    dict of str to Path
        ``{name: absolute folder}`` for the sets found, in the order of ``exp.datasets``.
    """
    from ..datasets import DATASETS, find_datasets
    from ..datasets import data_root as _data_root

    root = _data_root(data_root)
    known = [name for name in exp.datasets if name in DATASETS]
    found = find_datasets(root, names=known) if root is not None and known else {}
    given = {str(k): Path(v).expanduser().resolve() for k, v in (data or {}).items() if str(k) in exp.datasets}
    merged = {**{k: Path(v).resolve() for k, v in found.items()}, **given}
    return {name: merged[name] for name in exp.datasets if name in merged}


def data_signature(path: str | os.PathLike[str]) -> str:
    """A cheap signature of a data set's contents: number of files, total bytes, newest change.

    Part of a result's up-to-date key, so that adding, repairing or re-fetching recordings
    recomputes the result even though the set's folder is the same.
    """
    path = Path(path)
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    n = size = newest = 0
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        n, size, newest = n + 1, size + st.st_size, max(newest, st.st_mtime_ns)
    return f"{n} files, {size} bytes, newest {newest}"


def record_path(output: str | os.PathLike[str], exp_id: str, *, secondary: bool = False) -> Path:
    """Where a record goes: ``<output>/<id>.json``, or ``<output>/<id>.synthetic.json`` for
    the run on generated data of an experiment whose default run is on real data."""
    return Path(output) / (f"{exp_id}.synthetic.json" if secondary else f"{exp_id}.json")


# --------------------------------------------------------------------------- running


def _up_to_date(existing: ResultRecord | None, fresh: ResultRecord, output: Path) -> bool:
    if existing is None or existing.status != "ok":
        return False
    if existing.schema_version != SCHEMA_VERSION or existing.experiment != fresh.experiment:
        return False
    for key in ("config", "code", "data", "data_signature", "preset", "variant"):
        if getattr(existing, key) != getattr(fresh, key):
            return False
    return all((output / rel).is_file() for rel in existing.figures.values())


def _close_figures(figures: Mapping[str, Any]) -> None:
    if not figures:
        return
    import matplotlib.pyplot as plt

    for fig in figures.values():
        try:
            plt.close(fig)
        except Exception:  # pragma: no cover - a non-pyplot figure or already closed
            pass


def _remove_stale_figures(fig_dir: Path, keep: Iterable[str]) -> None:
    if not fig_dir.is_dir():
        return
    keep = set(keep)
    for png in fig_dir.glob("*.png"):
        if png.name not in keep:
            png.unlink()
    try:
        fig_dir.rmdir()  # only succeeds when empty
    except OSError:
        pass


def _resolve(exp_or_id: Experiment | str) -> Experiment:
    if isinstance(exp_or_id, Experiment):
        return exp_or_id
    if isinstance(exp_or_id, str):
        return get(exp_or_id)
    raise ExperimentError(f"expected an Experiment or an experiment id; got {type(exp_or_id).__name__}.")


def _config_and_preset(exp: Experiment, preset: str | None, config: Any, seed: int | None) -> tuple[Any, str]:
    """The config to run and the preset name recorded with it.

    Without ``config``: the ``preset`` config (default quick). With ``config``: that config
    (its seed replaced by ``seed`` when given), recorded as the preset it equals, if any,
    else as :data:`CUSTOM_PRESET`.
    """
    if config is None:
        preset = "quick" if preset is None else preset
        return exp.make_config(preset, seed=seed), preset
    if preset is not None:
        raise ParameterError(
            f"{exp.id}: give a preset or a config, not both (got preset={preset!r} and a "
            f"{type(config).__name__}); a config given is recorded under the preset it equals, or as "
            f"{CUSTOM_PRESET!r}."
        )
    if not isinstance(config, exp.config_cls):
        raise ParameterError(
            f"{exp.id}: config must be a {exp.config_cls.__module__}.{exp.config_cls.__qualname__} (the config "
            f"class of {exp.id}); got {type(config).__module__}.{type(config).__qualname__}. Build it with "
            f"dataclasses.replace({exp.config_cls.__name__}.quick(), ...)."
        )
    if seed is not None:
        # an instance of exp.config_cls, a frozen dataclass (checked when the experiment was declared)
        config = dataclasses.replace(cast("DataclassInstance", config), seed=check_seed(seed))
    name = next((p for p in PRESETS if exp.make_config(p, seed=check_seed(config.seed)) == config), CUSTOM_PRESET)
    return config, name


@dataclass(frozen=True)
class _Target:
    """On which data one run goes and where its record is written."""

    variant: str  # "real" or "synthetic": the variant chosen
    data: dict[str, Path]  # the real sets it runs on (empty on generated data)
    json_path: Path
    secondary: bool  # the run on generated data of an experiment that has real data
    cannot_run: str | None  # why the chosen variant cannot run here (None: it can)

    @property
    def fig_dir(self) -> Path:
        return self.json_path.with_suffix("")


def _target(exp: Experiment, variant: str, data: Mapping[str, str | os.PathLike[str]] | None,
            data_root: str | os.PathLike[str] | None, output: Path) -> _Target:
    real_sets = resolve_data(exp, data, data_root)
    chosen = ("real" if real_sets else "synthetic") if variant == "auto" else variant
    exp_data = real_sets if chosen == "real" else {}
    secondary = chosen == "synthetic" and bool(real_sets)
    cannot_run = None
    if chosen == "real" and not exp_data:
        cannot_run = (f"no real data set of {', '.join(exp.datasets) or '(none declared)'} was found: "
                      "give a data root (--data-root DIR) or --data NAME=PATH (see `mmconcepts data list`).")
    elif chosen == "synthetic" and not exp.synthetic:
        cannot_run = f"{exp.id} runs only on real data ({', '.join(exp.datasets)})."
    return _Target(chosen, exp_data, record_path(output, exp.id, secondary=secondary), secondary, cannot_run)


def _new_record(exp: Experiment, preset: str, config: Any, target: _Target) -> ResultRecord:
    """The record of a run about to start: who, what, on which data; no results yet."""
    return ResultRecord(
        experiment=exp.id,
        title=exp.title,
        thesis_ref=exp.thesis_ref,
        status="ok",
        preset=preset,
        config=json.loads(json.dumps(to_jsonable(config, where="config"), allow_nan=False)),
        seed=to_jsonable(config.seed),
        variant=target.variant,
        version=__version__,
        code=code_fingerprint(),
        data={name: str(path) for name, path in sorted(target.data.items())},
        data_signature={name: data_signature(path) for name, path in sorted(target.data.items())},
        reference=dict(exp.reference),
        claims=[pending_claim(c) for c in exp.claims],
        elapsed_s=0.0,
        started_at=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        python=platform.python_version(),
        platform=platform.platform(),
    )


def _run_recording_warnings(exp: Experiment, config: Any, ctx: RunContext, seen: list[str]) -> Any:
    """``exp.run(config, ctx)``, adding the distinct warnings it raises to ``seen`` (then showing them)."""
    with warnings.catch_warnings(record=True) as caught:  # filters still apply ("error" raises)
        try:
            run = cast("Callable[[Any, RunContext], Result]", exp.run)  # set by Experiment.__post_init__
            result = run(config, ctx)
        finally:
            for w in caught:
                text = f"{w.category.__name__}: {w.message}"
                if text not in seen:
                    seen.append(text)
    for w in caught:  # shown as usual, after being recorded
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return result


def _record_result(record: ResultRecord, exp: Experiment, result: Result) -> None:
    """Put a validated result's numbers in ``record`` and decide its claims on them."""
    metrics = {name: float(value) for name, value in result.metrics.items()}
    samples = {name: [float(v) for v in values] for name, values in result.samples.items()}
    record.claims = [decide_claim(claim, metrics, samples, reference=exp.reference, units=result.sample_units,
                                  unit_kinds=result.units) for claim in exp.claims]
    intervals = {}
    for name, values in samples.items():
        unit = result.units.get(result.sample_units.get(name, ""))
        interval = metric_interval(metrics[name], values, unit)
        if interval is not None:
            intervals[name] = list(interval)
    missing = sorted(set(exp.reference) - set(metrics))
    if missing:
        logger.warning("%s: reference values without a metric of ours: %s", exp.id, ", ".join(missing))
    bad = sorted(k for k, v in metrics.items() if math.isinf(v))
    if bad:
        logger.warning("%s: infinite metric(s) stored as null: %s", exp.id, ", ".join(bad))
    record.metrics = {name: value if math.isfinite(value) else math.nan for name, value in metrics.items()}
    record.samples = to_jsonable(samples, where="samples")
    record.sample_units = {str(k): str(v) for k, v in result.sample_units.items()}
    record.units = {str(k): v.to_dict() for k, v in result.units.items()}
    record.split_groups = to_jsonable(result.split_groups, where="split_groups")
    record.intervals = to_jsonable(intervals, where="intervals")
    record.tables = {str(name): Table.from_dict(to_jsonable(table.to_dict(), where=f"tables[{name!r}]"))
                     for name, table in result.tables.items()}
    record.notes = list(result.notes)
    record.extra = to_jsonable(result.extra, where="extra")


def _save_figures(figures: Mapping[str, Any], fig_dir: Path) -> dict[str, str]:
    """Write each figure as ``<fig_dir>/<name>.png`` (atomically); return name -> path relative to the output."""
    saved = {}
    for name, fig in figures.items():
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        atomic_write(fig_dir / f"{name}.png", buf.getvalue())
        saved[name] = f"{fig_dir.name}/{name}.png"
    return saved


def _clear_results(record: ResultRecord) -> None:
    """A run that did not finish has no numbers, figures or verdicts."""
    record.metrics, record.intervals, record.samples, record.sample_units = {}, {}, {}, {}
    record.units, record.split_groups = {}, {}
    record.tables, record.figures, record.notes, record.extra = {}, {}, [], {}
    record.claims = [ClaimRecord(text=c.text, rule=c.rule, kind=c.kind, source=c.source, settings=[
        {"label": s["label"], "rule": s["rule"]} for s in c.settings]) for c in record.claims]


def _execute(exp: Experiment, config: Any, ctx: RunContext, record: ResultRecord, target: _Target) -> Exception | None:
    """Run the experiment and fill ``record`` (status, numbers, verdicts, figures written).

    Returns the experiment's error when it failed (the record says so), else None.
    """
    result: Any = None
    try:
        if target.cannot_run is not None:
            raise ExperimentSkipped(target.cannot_run)
        result = _run_recording_warnings(exp, config, ctx, record.warnings)
        if not isinstance(result, Result):
            raise ExperimentError(f"{exp.id}: run() must return a Result; got {type(result).__name__}.")
        result.validate()
        _record_result(record, exp, result)
        record.figures = _save_figures(result.figures, target.fig_dir)
    except ExperimentSkipped as exc:
        record.status, record.message = "skipped", str(exc)
        logger.warning("%s: skipped: %s", exp.id, exc)
    except Exception as exc:
        record.status, record.message = "failed", f"{type(exc).__name__}: {exc}"
        record.traceback = traceback.format_exc()
        logger.error("%s: failed: %s", exp.id, record.message)
        return exc
    finally:
        if isinstance(result, Result):
            _close_figures(result.figures)
        if record.status != "ok":
            _clear_results(record)
    return None


def run_experiment(
    exp_or_id: Experiment | str,
    *,
    preset: str | None = None,
    config: Any = None,
    seed: int | None = None,
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    variant: str = "auto",
    workers: int = 1,
    scheduler: Any = None,
    force: bool = False,
    progress: bool = True,
    raise_errors: bool = True,
) -> ResultRecord:
    """Run one experiment and write its record (see the module docstring) and figures.

    If the record file already holds a successful result for the same config, code
    fingerprint, data, variant and preset, it is returned without recomputing (unless
    ``force``).

    Parameters
    ----------
    exp_or_id : Experiment or str
        The experiment or its registered id.
    preset : {"quick", "full"}, optional
        Which config preset to run (default quick). Not with ``config``.
    config : instance of the experiment's config class, optional
        The config to run instead of a preset, e.g.
        ``dataclasses.replace(Config.quick(), n_folds=3)``. It is recorded like a preset's
        (``config`` and ``seed``), under the name of the preset it equals, else
        ``"custom"``.
    seed : int, optional
        Replaces the preset's (or the config's) seed.
    output : str or path-like, default="results"
        Results folder (created if needed).
    data : mapping of str to path, optional
        Real data sets by name (``--data NAME=PATH``); they override the data root's.
        Names the experiment does not declare are ignored if another registered
        experiment, or the data-set registry, knows them.
    data_root : str or path-like, optional
        Folder holding the real sets by name (default ``$MMCONCEPTS_DATA_ROOT``, else
        none); see :mod:`mmconcepts.datasets`.
    variant : {"auto", "real", "synthetic"}, default="auto"
        ``"real"`` runs on the real sets found (skipped when there are none),
        ``"synthetic"`` on generated data, ``"auto"`` on the real sets when any is
        found, else on generated data. The run on generated data of an experiment that
        has real data is written to ``<id>.synthetic.json``.
    workers : int, default=1
        Processes for :meth:`RunContext.parallel`; -1 for one per CPU.
    scheduler : str or distributed.Client, optional
        Run the experiment's parallel parts on a Dask cluster instead (then ``workers``
        is not used): ``"local:N"`` starts N worker processes on this machine for the
        run, ``"tcp://HOST:PORT"`` connects to a running scheduler, a ``Client`` is used
        as it is (see :mod:`mmconcepts.experiments.cluster`). The numbers are the same.
    force : bool, default=False
        Recompute even if an up-to-date result exists.
    progress : bool, default=True
        Show progress bars (only on a terminal).
    raise_errors : bool, default=True
        If the experiment raises (other than :class:`ExperimentSkipped`), re-raise after
        writing the failure record. When False, return the failure record instead.

    Returns
    -------
    ResultRecord
        The result record (see the module docstring); ``record.status`` is ``"ok"``,
        ``"skipped"`` (the experiment raised :class:`ExperimentSkipped`, or the variant
        cannot run here) or ``"failed"``. It also reads as the JSON dict
        (``record["status"]``).

    Raises
    ------
    ExperimentError
        On an unknown id, a bad preset, config, variant or data argument (a
        :class:`ParameterError` for a config of another class, or a preset and a config
        both given; for an output folder that is a file or cannot be written, checked before
        any work), or (with ``raise_errors``) the experiment's own error.
    """
    exp = _resolve(exp_or_id)
    if variant not in ("auto", *VARIANTS):
        raise ParameterError(f"variant must be 'auto', 'real' or 'synthetic'; got {variant!r}.")
    config, preset = _config_and_preset(exp, preset, config, seed)
    if isinstance(scheduler, str):
        parse_scheduler(scheduler)  # a malformed address fails before any work
    check_data(data, [exp])
    output = check_output_dir(output)  # before any work: a file or an unwritable folder fails now
    target = _target(exp, variant, data, data_root, output)
    record = _new_record(exp, preset, config, target)
    ctx = RunContext(
        workers=workers,
        data=target.data,
        cache_dir=data_home(),
        logger=logging.getLogger(f"mmconcepts.experiments.{exp.id}"),
        show_progress=progress,
    )

    if not force and target.json_path.exists():
        existing = load_record(target.json_path)
        if existing is not None and _up_to_date(existing, record, output):
            logger.info("%s (%s data): skipped: up to date (%s)", exp.id, target.variant, target.json_path)
            return existing
    if target.cannot_run is not None and variant != "auto":
        # an explicitly asked variant that cannot run here: say so, but never overwrite a record
        logger.warning("%s: skipped: %s", exp.id, target.cannot_run)
        record.status, record.message = "skipped", target.cannot_run
        return record

    output.mkdir(parents=True, exist_ok=True)
    if not target.secondary:  # a default run on generated data supersedes an older run on generated data
        stale = record_path(output, exp.id, secondary=True)
        if target.variant == "synthetic" and stale.exists():
            stale.unlink()
            _remove_stale_figures(stale.with_suffix(""), ())
    logger.info("%s: running on %s data (%s preset, seed %s)", exp.id, target.variant, preset, config.seed)
    t0 = time.perf_counter()
    # every joblib call of the run (RunContext.parallel's and the library's own n_jobs) under one
    # config: loky keeps the same worker processes from one to the next instead of starting new ones
    with _client(scheduler) as client, workers_end_with_this_process():
        ctx.client = client
        error = _execute(exp, config, ctx, record, target)
    record.elapsed_s = round(time.perf_counter() - t0, 3)
    atomic_write(target.json_path, record.to_json().encode("utf-8"))
    _remove_stale_figures(target.fig_dir, (Path(p).name for p in record.figures.values()))
    if record.status == "ok":
        logger.info("%s: done in %.1f s, wrote %s", exp.id, record.elapsed_s, target.json_path)
    if error is not None and raise_errors:
        raise error
    return record


def _client(scheduler: Any) -> contextlib.AbstractContextManager[Any]:
    """A context giving the Dask client of ``scheduler`` (None: no cluster; a str: opened and closed here)."""
    if isinstance(scheduler, str):
        return open_client(scheduler)
    return contextlib.nullcontext(scheduler)


def reproduce(
    *,
    preset: str = "quick",
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    synthetic: bool = True,
    workers: int = 1,
    scheduler: Any = None,
    concurrent: int = 1,
    force: bool = False,
    ids: Sequence[str] | None = None,
    progress: bool = True,
) -> list[ResultRecord]:
    """Run every registered experiment (or those in ``ids``), keeping going on failures.

    Each experiment runs on the real sets found for it (data root, ``data``), and, when
    ``synthetic``, also on its generated stand-ins, so that the report can put the two
    side by side; an experiment with no real set found runs once, on generated data. An
    experiment that raises is recorded with ``status: "failed"`` and its traceback; one
    that raises :class:`ExperimentSkipped` with ``status: "skipped"``. The report is not
    written here (the report layer sits above this one): call
    :func:`mmconcepts.report.write_report` on ``output`` afterwards, as
    ``mmconcepts reproduce`` does.

    Parameters
    ----------
    preset : {"quick", "full"}, default="quick"
    output : str or path-like, default="results"
    data : mapping of str to path, optional
        Real data sets by name; each name must be known (declared by some registered
        experiment or in :data:`mmconcepts.datasets.DATASETS`) and each path must exist.
    data_root : str or path-like, optional
        Folder holding the real sets by name (default ``$MMCONCEPTS_DATA_ROOT``).
    synthetic : bool, default=True
        Also run the experiments that have real data on generated data.
    workers : int, default=1
    scheduler : str or distributed.Client, optional
        Run the experiments' parallel parts on a Dask cluster (see :func:`run_experiment`);
        a ``"local:N"`` cluster is started once for the whole reproduction.
    concurrent : int, default=1
        Run up to this many experiments at the same time, on as many processes that each
        run one experiment after another (sharing the cluster when there is one, else
        each with ``workers`` worker processes, kept from one experiment to the next);
        the records are the same as one at a time. An experiment whose process dies (a
        crash, the out-of-memory killer) gets a failed record with the process's exit
        code and last output lines, and the others still run.
    force : bool, default=False
        Recompute up-to-date results too.
    ids : sequence of str, optional
        Run only these experiments, in this order (default: all, sorted by id).
    progress : bool, default=True

    Returns
    -------
    list of ResultRecord
        One record per run, in the order run (the real-data run of an experiment first).
    """
    if preset not in PRESETS:
        raise ParameterError(f"preset must be one of {', '.join(PRESETS)}; got {preset!r}.")
    experiments = [get(i) for i in dict.fromkeys(ids)] if ids else all_experiments()
    if not experiments:
        raise ExperimentError("no experiments are registered; nothing to reproduce.")
    if isinstance(concurrent, bool) or not isinstance(concurrent, int) or concurrent < 1:
        raise ParameterError(f"concurrent must be an int >= 1 (experiments run at the same time); got {concurrent!r}.")
    if isinstance(scheduler, str):
        parse_scheduler(scheduler)
    check_output_dir(output)
    checked = check_data(data, all_experiments())
    runs: list[tuple[Experiment, str]] = []
    for exp in experiments:
        has_real = bool(resolve_data(exp, checked, data_root))
        runs.append((exp, "auto"))
        if has_real and synthetic and exp.synthetic:
            runs.append((exp, "synthetic"))
        else:  # a secondary record this run does not refresh would be shown as current
            stale = record_path(output, exp.id, secondary=True)
            if stale.exists():
                logger.info("%s: removing %s (not part of this run)", exp.id, stale)
                stale.unlink()
                _remove_stale_figures(stale.with_suffix(""), ())
    with _client(scheduler) as client:
        common: dict[str, Any] = dict(preset=preset, output=output, data=checked, data_root=data_root, workers=workers,
                                      scheduler=client, force=force, progress=progress, raise_errors=False)
        if concurrent == 1 or len(runs) <= 1:
            records = [run_experiment(exp, variant=variant, **common) for exp, variant in runs]
        else:
            records = _run_concurrently(runs, concurrent, common)
    counts = {s: sum(r.status == s for r in records) for s in ("ok", "failed", "skipped")}
    logger.info("reproduce: %d ok, %d failed, %d skipped", counts["ok"], counts["failed"], counts["skipped"])
    return records


def _run_concurrently(runs: list[tuple[Experiment, str]], concurrent: int,
                      common: Mapping[str, Any]) -> list[ResultRecord]:
    """Run ``runs`` (experiment, variant) up to ``concurrent`` at a time, on as many driver processes.

    Each driver runs one experiment after another (:mod:`._drivers`), with the arguments
    ``mmconcepts run --quiet`` would get: the same records as one at a time in this process.
    """
    import threading

    from tqdm.auto import tqdm

    from ._drivers import run_lanes
    from ._workers import progress_enabled

    client = common["scheduler"]
    kwargs = dict(
        preset=common["preset"], output=str(Path(common["output"]).resolve()),
        data={name: str(Path(path).resolve()) for name, path in (common["data"] or {}).items()},
        data_root=None if common["data_root"] is None else str(Path(common["data_root"]).resolve()),
        workers=common["workers"], scheduler=None if client is None else str(client.scheduler.address),
        force=common["force"], progress=False, raise_errors=False,
    )
    bar = tqdm(total=len(runs), desc="experiments", leave=False,
               disable=not progress_enabled(bool(common["progress"])))
    lock = threading.Lock()

    def done(i: int, record: ResultRecord | None, why: str | None) -> ResultRecord:
        exp, variant = runs[i]
        if record is None:
            config, preset = _config_and_preset(exp, common["preset"], None, None)
            target = _target(exp, variant, common["data"], common["data_root"], Path(common["output"]))
            record = _new_record(exp, preset, config, target)
            record.status, record.message = "failed", why
            _clear_results(record)
            logger.error("%s: failed: %s", exp.id, why)
        else:
            logger.info("%s (%s data): %s", exp.id, record.variant, record.status)
        with lock:
            bar.update(1)
        return record

    try:
        return run_lanes([(exp.id, variant) for exp, variant in runs], concurrent, kwargs, on_done=done)
    finally:
        bar.close()
