"""Run every registered experiment (or some), on the real sets and on generated data, keeping going on
failures: :func:`reproduce`, one at a time in this process or several at a time on driver processes
(:mod:`mmconcepts.engine.lanes`)."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._io import check_output_dir
from .._paths import DEFAULT_RESULTS_DIR
from ..errors import ExperimentError, ParameterError
from .experiment import PRESETS, SMOKE, Experiment
from .cluster import parse_scheduler, scheduler_client
from .data import DataPlan, make_data_plan
from .outputs import record_path
from .runfiles import RESULTS_ROOM, remove_secondary_record
from .runner import clear_results, config_and_preset, new_record, plan_target, run_experiment
from .record import ResultRecord
from .registry import all_experiments, get


__all__ = ["reproduce"]

logger = logging.getLogger("mmconcepts.experiments")




def reproduce(
    *,
    preset: str = "quick",
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    data_plan: DataPlan | None = None,
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
    preset : {"quick", "full", "smoke"}, default="quick"
        ``"smoke"`` runs only the experiments that have a smoke preset (all of ``ids`` when given).
    output : str or path-like, default="results"
    data : mapping of str to path, optional
        Real data sets by name; each name must be known (declared by some registered
        experiment or in :data:`mmconcepts.datasets.DATASETS`) and each path must exist.
    data_root : str or path-like, optional
        Folder holding the real sets by name (default ``$MMCONCEPTS_DATA_ROOT``); one given
        must be an existing folder.
    data_plan : DataPlan, optional
        The plan made from ``data`` and ``data_root`` beforehand (not with them), covering the
        experiments to run. Without it, the plan is made here, once: the data root is resolved
        and looked at once for all the experiments, and each run gets its experiment's entry
        (:class:`~mmconcepts.engine.data.DataPlan`).
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
        the records are the same as one at a time. Without a cluster, a process of its own
        compiles the package's slowest numerical kernels meanwhile, when they are not compiled
        yet (:mod:`mmconcepts._warmup`). An experiment whose process dies (a
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
    if preset not in (*PRESETS, SMOKE):
        raise ParameterError(f"preset must be one of {', '.join((*PRESETS, SMOKE))}; got {preset!r}.")
    experiments = [get(i) for i in dict.fromkeys(ids)] if ids else all_experiments()
    if preset == SMOKE:  # the experiments that have a smoke preset (all of ``ids``, which must have one)
        experiments = [e for e in experiments if e.has_smoke or ids]
    if not experiments:
        raise ExperimentError("no experiments are registered; nothing to reproduce.")
    if isinstance(concurrent, bool) or not isinstance(concurrent, int) or concurrent < 1:
        raise ParameterError(f"concurrent must be an int >= 1 (experiments run at the same time); got {concurrent!r}.")
    if isinstance(scheduler, str):
        parse_scheduler(scheduler)
    check_output_dir(output, room=RESULTS_ROOM)
    plan = make_data_plan(experiments, data, data_root, data_plan)
    runs: list[tuple[Experiment, str]] = []
    for exp in experiments:
        runs.append((exp, "auto"))  # its default variant: on the real sets found, else on generated data
        if synthetic and "synthetic" in plan.entry(exp).variants[1:]:
            runs.append((exp, "synthetic"))
        else:  # a secondary record this run does not refresh would be shown as current
            if record_path(output, exp.id, secondary=True).exists():
                logger.info("%s: removing its record on generated data (not part of this run)", exp.id)
                remove_secondary_record(output, exp.id)
    with scheduler_client(scheduler) as client:
        common: dict[str, Any] = dict(preset=preset, output=output, data_plan=plan, workers=workers, scheduler=client,
                                      force=force, progress=progress, raise_errors=False)
        if concurrent == 1 or len(runs) <= 1:
            records = [run_experiment(exp, variant=variant, **common) for exp, variant in runs]
        else:
            from .._warmup import in_background

            # without a cluster, the slowest kernels compile meanwhile, beside the first experiments
            with in_background() if client is None else contextlib.nullcontext():
                records = run_concurrently(runs, concurrent, common)
    counts = {s: sum(r.status == s for r in records) for s in ("ok", "failed", "skipped")}
    logger.info("reproduce: %d ok, %d failed, %d skipped", counts["ok"], counts["failed"], counts["skipped"])
    return records


def run_concurrently(runs: list[tuple[Experiment, str]], concurrent: int,
                      common: Mapping[str, Any]) -> list[ResultRecord]:
    """Run ``runs`` (experiment, variant) up to ``concurrent`` at a time, on as many driver processes.

    Each driver runs one experiment after another (:mod:`.lanes`), with the arguments
    ``mmconcepts run --quiet`` would get: the same records as one at a time in this process.
    """
    import threading

    from tqdm.auto import tqdm

    from .lanes import run_lanes
    from .workers import progress_enabled

    client = common["scheduler"]
    kwargs = dict(
        preset=common["preset"], output=str(Path(common["output"]).resolve()),
        data_plan=common["data_plan"],  # the same plan for every driver (its paths are absolute)
        workers=common["workers"], scheduler=None if client is None else str(client.scheduler.address),
        force=common["force"], progress=False, raise_errors=False,
    )
    bar = tqdm(total=len(runs), desc="experiments", leave=False,
               disable=not progress_enabled(bool(common["progress"])))
    lock = threading.Lock()

    def done(i: int, record: ResultRecord | None, why: str | None) -> ResultRecord:
        exp, variant = runs[i]
        if record is None:
            config, preset = config_and_preset(exp, common["preset"], None, None)
            target = plan_target(exp, variant, common["data_plan"].entry(exp), Path(common["output"]))
            record = new_record(exp, preset, config, target)
            record.status, record.message = "failed", why
            clear_results(record)
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
