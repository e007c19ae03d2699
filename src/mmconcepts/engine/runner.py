"""Run one experiment: its config and data planned, ``compute`` and ``present`` run, the claims decided,
the record and figures written (:func:`run_experiment`); the record's schema is in
:mod:`mmconcepts.engine.outputs`."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import logging
import math
import os
import platform
import time
import traceback
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from .. import __version__
from .._fingerprint import code_fingerprint
from .._io import check_output_dir
from .._paths import DEFAULT_RESULTS_DIR, data_home
from ..errors import ExperimentError, MissingExtraError, ParameterError
from .experiment import PRESETS, SMOKE, Experiment, check_seed
from .spec import ExperimentSkipped, Result, Table
from .context import RunContext
from .workers import workers_end_with_this_process
from .cluster import parse_scheduler, scheduler_client
from .data import VARIANTS, DataPlan, PlanEntry, data_signature, make_data_plan
from .outputs import close_figures, record_path
from .record import ClaimRecord, ResultRecord, to_jsonable
from .registry import get
from .runfiles import (RESULTS_ROOM, current_record, record_lock, remove_secondary_record, render_files, restore_kept,
                       write_record)
from .uncertainty import metric_interval
from .verdicts import decide_claim, pending_claim

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = ["CUSTOM_PRESET", "run_experiment", "plan_run", "config_and_preset", "plan_target", "RunTarget", "new_record",
           "clear_results"]

logger = logging.getLogger("mmconcepts.experiments")


#: The ``preset`` of a record whose config was given to :func:`run_experiment` and is no preset.
CUSTOM_PRESET = "custom"


def _resolve(exp_or_id: Experiment | str) -> Experiment:
    if isinstance(exp_or_id, Experiment):
        return exp_or_id
    if isinstance(exp_or_id, str):
        return get(exp_or_id)
    raise ExperimentError(f"expected an Experiment or an experiment id; got {type(exp_or_id).__name__}.")


def config_and_preset(exp: Experiment, preset: str | None, config: Any, seed: int | None) -> tuple[Any, str]:
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
    names = (*PRESETS, SMOKE) if exp.has_smoke else PRESETS
    name = next((p for p in names if exp.make_config(p, seed=check_seed(config.seed)) == config), CUSTOM_PRESET)
    return config, name


@dataclass(frozen=True)
class RunTarget:
    """On which data one run goes and where its record is written."""

    variant: str  # "real" or "synthetic": the variant chosen
    data: dict[str, Path]  # the real sets it runs on (empty on generated data)
    json_path: Path
    secondary: bool  # the run on generated data of an experiment that has real data
    cannot_run: str | None  # why the chosen variant cannot run here (None: it can)

    @property
    def fig_dir(self) -> Path:
        return self.json_path.with_suffix("")


def plan_target(exp: Experiment, variant: str, entry: PlanEntry, output: Path) -> RunTarget:
    """Where a run of ``exp`` asked for ``variant`` goes: its data from ``entry``, its entry of the data plan."""
    chosen = entry.chosen(variant)
    exp_data = entry.data(chosen)
    secondary = entry.secondary(chosen)
    cannot_run = None
    if chosen == "real" and not exp_data:
        cannot_run = (f"no real data set of {', '.join(exp.datasets) or '(none declared)'} was found: "
                      "give a data root (--data-root DIR) or --data NAME=PATH (see `mmconcepts data list`).")
    elif chosen == "synthetic" and not exp.synthetic:
        cannot_run = f"{exp.id} runs only on real data ({', '.join(exp.datasets)})."
    return RunTarget(chosen, exp_data, record_path(output, exp.id, secondary=secondary), secondary, cannot_run)


def new_record(exp: Experiment, preset: str, config: Any, target: RunTarget) -> ResultRecord:
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


def clear_results(record: ResultRecord) -> None:
    """A run that did not finish has no numbers, figures or verdicts."""
    record.metrics, record.intervals, record.samples, record.sample_units = {}, {}, {}, {}
    record.units, record.split_groups = {}, {}
    record.tables, record.figures, record.explorer, record.notes, record.extra = {}, {}, {}, [], {}
    record.claims = [ClaimRecord(text=c.text, rule=c.rule, kind=c.kind, source=c.source, settings=[
        {"label": s["label"], "rule": s["rule"]} for s in c.settings]) for c in record.claims]


def _execute(exp: Experiment, config: Any, ctx: RunContext, record: ResultRecord,
             target: RunTarget) -> tuple[Exception | None, dict[str, bytes]]:
    """Run the experiment and fill ``record`` (status, numbers, verdicts, the figures it will write).

    Returns the experiment's error when it failed (the record says so), else None, and the run's files as bytes
    (:func:`~mmconcepts.engine.runfiles.render_files`; nothing is written here).
    """
    result: Any = None
    files: dict[str, bytes] = {}
    try:
        if target.cannot_run is not None:
            raise ExperimentSkipped(target.cannot_run)
        result = _run_recording_warnings(exp, config, ctx, record.warnings)
        if not isinstance(result, Result):
            raise ExperimentError(f"{exp.id}: run() must return a Result; got {type(result).__name__}.")
        result.validate()
        _record_result(record, exp, result)
        files = render_files(exp, result, record, target.fig_dir.name)
    except (ExperimentSkipped, MissingExtraError) as exc:  # a missing optional extra: skipped, naming the extra
        why = "needs an optional extra that is not installed: " if isinstance(exc, MissingExtraError) else ""
        record.status, record.message = "skipped", f"{why}{exc}"
        logger.warning("%s: skipped: %s", exp.id, record.message)
    except Exception as exc:
        record.status, record.message = "failed", f"{type(exc).__name__}: {exc}"
        record.traceback = traceback.format_exc()
        logger.error("%s: failed: %s", exp.id, record.message)
        return exc, {}
    finally:
        if isinstance(result, Result):
            close_figures(result.figures)
        if record.status != "ok":
            clear_results(record)
    return None, (files if record.status == "ok" else {})


def run_experiment(
    exp_or_id: Experiment | str,
    *,
    preset: str | None = None,
    config: Any = None,
    seed: int | None = None,
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    data_plan: DataPlan | None = None,
    variant: str = "auto",
    workers: int = 1,
    scheduler: Any = None,
    force: bool = False,
    progress: bool = True,
    raise_errors: bool = True,
) -> ResultRecord:
    """Run one experiment and write its record (see the module docstring) and figures.

    If the record file already holds a successful result for the same config, code
    fingerprint, data, variant and preset, as it was written (its digest matches), it is
    returned without recomputing (unless ``force``). The run holds its record's lock from
    that look until its record is written, so that a second run of the same experiment into
    the same folder waits and returns the first's record; see
    :mod:`mmconcepts.engine.runfiles`, which also says what happens when the files cannot
    be written.

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
        none); see :mod:`mmconcepts.datasets`. One given must be an existing folder.
    data_plan : DataPlan, optional
        Which real sets each experiment of a larger run gets, resolved once for it
        (:func:`reproduce` makes one); not with ``data`` or ``data_root``. Without it, the
        plan is made here from them (:class:`~mmconcepts.engine.data.DataPlan`).
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
        as it is (see :mod:`mmconcepts.engine.cluster`). The numbers are the same.
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
        On an unknown id, a bad preset, config, variant or data argument (a ``data_root``
        given that is no folder; a :class:`ParameterError` for a config of another class, a
        preset and a config both given, or a data plan with ``data`` or ``data_root``; for an
        output folder that is a file, cannot be written or whose disk has less than
        :data:`~mmconcepts.engine.runfiles.RESULTS_ROOM` bytes free, checked before any work),
        when the run's files cannot be written (whatever ``raise_errors``; what it computed is
        kept for the next run), or (with ``raise_errors``) the experiment's own error.
    """
    exp = _resolve(exp_or_id)
    config, preset, target, output = plan_run(exp, preset, config, seed, output, variant, scheduler, data=data,
                                              data_root=data_root, data_plan=data_plan)
    record = new_record(exp, preset, config, target)
    with record_lock(target.json_path):  # a second run of it into this folder waits here, then reuses the record
        if not force and (existing := current_record(target.json_path, record, output)) is not None:
            logger.info("%s (%s data): skipped: up to date (%s)", exp.id, target.variant, target.json_path)
            return existing
        if target.cannot_run is not None and variant != "auto":
            # an explicitly asked variant that cannot run here: say so, but never overwrite a record
            logger.warning("%s: skipped: %s", exp.id, target.cannot_run)
            record.status, record.message = "skipped", target.cannot_run
            return record
        output.mkdir(parents=True, exist_ok=True)
        if target.variant == "synthetic" and not target.secondary:  # it supersedes an older run on generated data
            remove_secondary_record(output, exp.id)
        if not force and (kept := restore_kept(target.json_path, record, data_home())) is not None:
            return kept
        logger.info("%s: running on %s data (%s preset, seed %s)", exp.id, target.variant, preset, config.seed)
        ctx = RunContext(workers=workers, data=target.data, cache_dir=data_home(), show_progress=progress,
                         logger=logging.getLogger(f"mmconcepts.experiments.{exp.id}"), datasets=tuple(exp.datasets))
        t0 = time.perf_counter()
        # every joblib call of the run (RunContext.parallel's and the library's own n_jobs) under one
        # config: loky keeps the same worker processes from one to the next instead of starting new ones
        with scheduler_client(scheduler) as client, workers_end_with_this_process():
            ctx.client = client
            error, files = _execute(exp, config, ctx, record, target)
        record.elapsed_s = round(time.perf_counter() - t0, 3)
        write_record(record, files, target.json_path, data_home())
    if error is not None and raise_errors:
        raise error
    return record


def plan_run(exp: Experiment, preset: str | None, config: Any, seed: int | None, output: str | os.PathLike[str],
             variant: str, scheduler: Any, *, data: Mapping[str, str | os.PathLike[str]] | None = None,
             data_root: str | os.PathLike[str] | None = None,
             data_plan: DataPlan | None = None) -> tuple[Any, str, RunTarget, Path]:
    """Check :func:`run_experiment`'s arguments before any work; return the config, its preset name, the target
    (which data, by the experiment's entry of the data plan: ``data_plan``, else one made here from ``data`` and
    ``data_root``; which record file) and the output folder."""
    if variant not in ("auto", *VARIANTS):
        raise ParameterError(f"variant must be 'auto', 'real' or 'synthetic'; got {variant!r}.")
    config, preset_name = config_and_preset(exp, preset, config, seed)
    if isinstance(scheduler, str):
        parse_scheduler(scheduler)  # a malformed address fails before any work
    plan = make_data_plan([exp], data, data_root, data_plan)
    out = check_output_dir(output, room=RESULTS_ROOM)  # before any work: a file, an unwritable or full folder
    return config, preset_name, plan_target(exp, variant, plan.entry(exp), out), out
