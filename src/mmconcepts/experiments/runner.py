"""Run experiments, write their results as JSON + PNG, skip what is up to date.

A result record is a JSON object with a stable schema (``schema_version`` 2)::

    schema_version  2
    experiment      id                       title, thesis_ref
    status          "ok" | "failed" | "skipped"
    message         why it failed or was skipped (null when ok)
    traceback       the traceback text of a failure (else null)
    preset          "quick" | "full"         config (the dataclass as a dict), seed
    variant         "real" | "synthetic"     which data it ran on: the real sets found
                                             (data root or --data) or generated stand-ins
    data            name -> absolute path of each real set used (empty when synthetic)
    data_signature  name -> "<n> files, <bytes> bytes, newest <mtime>" of each set (part of
                    the up-to-date key: changed recordings recompute the result)
    version         mmconcepts.__version__
    code            fingerprint of the code that produced it (package sources and
                    dependency versions, :func:`mmconcepts._fingerprint.code_fingerprint`)
    metrics         name -> number (null for NaN or infinite, read back as NaN)
    intervals       name -> [low, high], the 95 % t interval of a metric with samples
    samples         name -> the per-fold / per-seed values behind a metric
    sample_units    name -> the unit of its samples, where the experiment names one
                    (metrics of one unit are paired in the bootstrap)
    reference       name -> the thesis' number
    claims          [{text, rule, holds, verdict, support, basis}]
                    holds: the rule on the reported numbers (true, false or null);
                    verdict: "holds" | "fails" | "inconclusive" | "not evaluated", decided
                    beyond the samples' uncertainty (:mod:`.uncertainty`)
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
describes complete results. Schema-1 records (before variants and verdicts) are still read.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
import io
import json
import logging
import math
import numbers
import os
import platform
import re
import tempfile
import time
import traceback
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from .. import __version__
from .._fingerprint import code_fingerprint
from .._paths import DEFAULT_RESULTS_DIR, data_home
from ..errors import ExperimentError, ParameterError
from .base import PRESETS, Experiment, ExperimentSkipped, Result, RunContext
from .registry import all_experiments, get
from .uncertainty import claim_verdict, t_interval

__all__ = [
    "SCHEMA_VERSION",
    "RECORD_KEYS",
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

#: Version of the result-record schema written by :func:`run_experiment`.
SCHEMA_VERSION = 2

#: The data variants of a run: on the real sets found, or on generated stand-ins.
VARIANTS = ("real", "synthetic")

#: Keys present in every result record, whatever its status.
RECORD_KEYS = (
    "schema_version",
    "experiment",
    "title",
    "thesis_ref",
    "status",
    "message",
    "traceback",
    "preset",
    "config",
    "seed",
    "variant",
    "version",
    "code",
    "data",
    "data_signature",
    "metrics",
    "intervals",
    "samples",
    "sample_units",
    "reference",
    "claims",
    "tables",
    "figures",
    "notes",
    "extra",
    "warnings",
    "elapsed_s",
    "started_at",
    "python",
    "platform",
)

_DATA_NAME = re.compile(r"[A-Za-z0-9_.-]+\Z")


# --------------------------------------------------------------------------- JSON


def to_jsonable(obj: Any, *, where: str = "value") -> Any:
    """Convert ``obj`` to plain JSON types.

    Dataclasses become dicts, tuples and sets lists, numpy scalars and arrays Python
    numbers and lists, paths strings; NaN and infinite floats become None (JSON null).

    Raises
    ------
    ExperimentError
        If something cannot be represented (the message says where).
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), where=where)
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item(), where=where)
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value, where=where)
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name), where=f"{where}.{f.name}") for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, (str, int, float, bool)) and not isinstance(key, np.generic):
                raise ExperimentError(f"{where}: dictionary key {key!r} cannot be a JSON key; use strings.")
            out[str(key)] = to_jsonable(value, where=f"{where}[{key!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, where=f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (set, frozenset)):
        return [to_jsonable(v, where=where) for v in sorted(obj, key=repr)]
    raise ExperimentError(
        f"{where}: a {type(obj).__name__} value ({obj!r:.60}) cannot be stored in a JSON result; "
        "convert it to numbers, strings, lists or dicts."
    )


def _dumps(record: Mapping[str, Any]) -> str:
    return json.dumps(record, indent=2, allow_nan=False, ensure_ascii=False) + "\n"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder and os.replace."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def load_record(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """Read a result record, or return None if ``path`` does not hold one.

    Metric values stored as null are read back as NaN.

    Parameters
    ----------
    path : str or path-like
        A ``<id>.json`` file written by :func:`run_experiment`.

    Returns
    -------
    dict or None
        The record; None when the file is not valid JSON, not a result record, or of a
        newer schema version.
    """
    path = Path(path)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        logger.debug("%s: not readable as JSON (%s)", path, exc)
        return None
    if not isinstance(obj, dict) or not {"schema_version", "experiment", "status"} <= obj.keys():
        return None
    if not isinstance(obj["schema_version"], int) or obj["schema_version"] > SCHEMA_VERSION:
        logger.debug("%s: schema version %r is not supported", path, obj.get("schema_version"))
        return None
    metrics = obj.get("metrics") or {}
    if not isinstance(metrics, dict):
        return None
    obj["metrics"] = {k: (math.nan if v is None else float(v)) for k, v in metrics.items()}
    if obj["schema_version"] < 2:  # before variants, fingerprints and three-valued verdicts
        obj.setdefault("variant", "real" if obj.get("data") else "synthetic")
        obj.setdefault("code", None)
        for claim in obj.get("claims") or []:
            if isinstance(claim, dict):
                claim.setdefault("verdict", {True: "holds", False: "fails"}.get(claim.get("holds"), "not evaluated"))
    obj.setdefault("intervals", {})
    obj.setdefault("samples", {})
    obj.setdefault("sample_units", {})
    obj.setdefault("warnings", [])
    return obj


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


def _up_to_date(existing: Mapping[str, Any] | None, fresh: Mapping[str, Any], output: Path) -> bool:
    if existing is None or existing.get("status") != "ok":
        return False
    if existing.get("schema_version") != SCHEMA_VERSION or existing.get("experiment") != fresh["experiment"]:
        return False
    for key in ("config", "code", "data", "data_signature", "preset", "variant"):
        if existing.get(key) != fresh[key]:
            return False
    figures = existing.get("figures") or {}
    return all((output / rel).is_file() for rel in figures.values())


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


def run_experiment(
    exp_or_id: Experiment | str,
    *,
    preset: str = "quick",
    seed: int | None = None,
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    variant: str = "auto",
    workers: int = 1,
    force: bool = False,
    progress: bool = True,
    raise_errors: bool = True,
) -> dict[str, Any]:
    """Run one experiment and write its record (see the module docstring) and figures.

    If the record file already holds a successful result for the same config, code
    fingerprint, data, variant and preset, it is returned without recomputing (unless
    ``force``).

    Parameters
    ----------
    exp_or_id : Experiment or str
        The experiment or its registered id.
    preset : {"quick", "full"}, default="quick"
        Which config preset to run.
    seed : int, optional
        Replaces the preset's seed.
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
    force : bool, default=False
        Recompute even if an up-to-date result exists.
    progress : bool, default=True
        Show progress bars (only on a terminal).
    raise_errors : bool, default=True
        If the experiment raises (other than :class:`ExperimentSkipped`), re-raise after
        writing the failure record. When False, return the failure record instead.

    Returns
    -------
    dict
        The result record (see the module docstring); ``record["status"]`` is ``"ok"``,
        ``"skipped"`` (the experiment raised :class:`ExperimentSkipped`, or the variant
        cannot run here) or ``"failed"``.

    Raises
    ------
    ExperimentError
        On an unknown id, a bad preset, variant or data argument, or (with
        ``raise_errors``) the experiment's own error.
    """
    exp = _resolve(exp_or_id)
    if variant not in ("auto", *VARIANTS):
        raise ParameterError(f"variant must be 'auto', 'real' or 'synthetic'; got {variant!r}.")
    config = exp.make_config(preset, seed=seed)
    check_data(data, [exp])
    real_sets = resolve_data(exp, data, data_root)
    chosen = ("real" if real_sets else "synthetic") if variant == "auto" else variant
    exp_data = real_sets if chosen == "real" else {}
    secondary = chosen == "synthetic" and bool(real_sets)

    output = Path(output)
    json_path = record_path(output, exp.id, secondary=secondary)
    fig_dir = json_path.with_suffix("")
    config_json = json.loads(json.dumps(to_jsonable(config, where="config"), allow_nan=False))
    record: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "experiment": exp.id,
        "title": exp.title,
        "thesis_ref": exp.thesis_ref,
        "status": "ok",
        "message": None,
        "traceback": None,
        "preset": preset,
        "config": config_json,
        "seed": to_jsonable(config.seed),
        "variant": chosen,
        "version": __version__,
        "code": code_fingerprint(),
        "data": {name: str(path) for name, path in sorted(exp_data.items())},
        "data_signature": {name: data_signature(path) for name, path in sorted(exp_data.items())},
        "metrics": {},
        "intervals": {},
        "samples": {},
        "sample_units": {},
        "reference": dict(exp.reference),
        "claims": [
            {"text": c.text, "rule": c.rule, "holds": None, "verdict": "not evaluated", "support": None, "basis": ""}
            for c in exp.claims
        ],
        "tables": {},
        "figures": {},
        "notes": [],
        "extra": {},
        "warnings": [],
        "elapsed_s": 0.0,
        "started_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "platform": platform.platform(),
    }

    ctx = RunContext(
        workers=workers,
        data=exp_data,
        cache_dir=data_home(),
        logger=logging.getLogger(f"mmconcepts.experiments.{exp.id}"),
        show_progress=progress,
    )
    if not force and json_path.exists():
        existing = load_record(json_path)
        if existing is not None and _up_to_date(existing, record, output):
            logger.info("%s (%s data): skipped: up to date (%s)", exp.id, chosen, json_path)
            return existing

    cannot_run = None
    if chosen == "real" and not exp_data:
        cannot_run = (f"no real data set of {', '.join(exp.datasets) or '(none declared)'} was found: "
                      "give a data root (--data-root DIR) or --data NAME=PATH (see `mmconcepts data list`).")
    elif chosen == "synthetic" and not exp.synthetic:
        cannot_run = f"{exp.id} runs only on real data ({', '.join(exp.datasets)})."
    if cannot_run is not None and variant != "auto":
        # an explicitly asked variant that cannot run here: say so, but never overwrite a record
        logger.warning("%s: skipped: %s", exp.id, cannot_run)
        record.update(status="skipped", message=cannot_run)
        return record

    output.mkdir(parents=True, exist_ok=True)
    if not secondary:  # a default run on generated data supersedes an older run on generated data
        stale = record_path(output, exp.id, secondary=True)
        if chosen == "synthetic" and stale.exists():
            stale.unlink()
            _remove_stale_figures(stale.with_suffix(""), ())
    logger.info("%s: running on %s data (%s preset, seed %s)", exp.id, chosen, preset, config.seed)
    t0 = time.perf_counter()
    result: Any = None
    error: BaseException | None = None
    try:
        if cannot_run is not None:
            raise ExperimentSkipped(cannot_run)
        with warnings.catch_warnings(record=True) as caught:  # filters still apply ("error" raises)
            try:
                result = exp.run(config, ctx)
            finally:
                for w in caught:
                    text = f"{w.category.__name__}: {w.message}"
                    if text not in record["warnings"]:
                        record["warnings"].append(text)
        for w in caught:  # shown as usual, after being recorded
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if not isinstance(result, Result):
            raise ExperimentError(f"{exp.id}: run() must return a Result; got {type(result).__name__}.")
        result.validate()
        metrics = {name: float(value) for name, value in result.metrics.items()}
        samples = {name: [float(v) for v in values] for name, values in result.samples.items()}
        for claim in record["claims"]:
            verdict = claim_verdict(claim["rule"], metrics, samples, units=result.sample_units)
            claim.update(holds=verdict.holds, verdict=verdict.verdict, support=verdict.support, basis=verdict.basis)
        intervals = {}
        for name, values in samples.items():
            interval = t_interval(metrics[name], values)
            if interval is not None:
                intervals[name] = list(interval)
        missing = sorted(set(exp.reference) - set(metrics))
        if missing:
            logger.warning("%s: reference values without a metric of ours: %s", exp.id, ", ".join(missing))
        bad = sorted(k for k, v in metrics.items() if math.isinf(v))
        if bad:
            logger.warning("%s: infinite metric(s) stored as null: %s", exp.id, ", ".join(bad))
        record["metrics"] = to_jsonable(metrics, where="metrics")
        record["samples"] = to_jsonable(samples, where="samples")
        record["sample_units"] = {str(k): str(v) for k, v in result.sample_units.items()}
        record["intervals"] = to_jsonable(intervals, where="intervals")
        record["tables"] = {
            str(name): to_jsonable(table.to_dict(), where=f"tables[{name!r}]") for name, table in result.tables.items()
        }
        record["notes"] = list(result.notes)
        record["extra"] = to_jsonable(result.extra, where="extra")
        for name, fig in result.figures.items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
            _atomic_write(fig_dir / f"{name}.png", buf.getvalue())
            record["figures"][name] = f"{fig_dir.name}/{name}.png"
    except ExperimentSkipped as exc:
        record["status"] = "skipped"
        record["message"] = str(exc)
        logger.warning("%s: skipped: %s", exp.id, exc)
    except Exception as exc:
        error = exc
        record["status"] = "failed"
        record["message"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc()
        logger.error("%s: failed: %s", exp.id, record["message"])
    finally:
        if isinstance(result, Result):
            _close_figures(result.figures)

    if record["status"] != "ok":
        for key, empty in (("metrics", {}), ("intervals", {}), ("samples", {}), ("sample_units", {}), ("tables", {}),
                           ("figures", {}), ("notes", []), ("extra", {})):
            record[key] = empty
        for claim in record["claims"]:
            claim.update(holds=None, verdict="not evaluated", support=None, basis="")
    record["elapsed_s"] = round(time.perf_counter() - t0, 3)
    _atomic_write(json_path, _dumps(record).encode("utf-8"))
    _remove_stale_figures(fig_dir, (Path(p).name for p in record["figures"].values()))
    if record["status"] == "ok":
        logger.info("%s: done in %.1f s, wrote %s", exp.id, record["elapsed_s"], json_path)
    if error is not None and raise_errors:
        raise error
    record["metrics"] = {k: (math.nan if v is None else float(v)) for k, v in record["metrics"].items()}
    return record


def reproduce(
    *,
    preset: str = "quick",
    output: str | os.PathLike[str] = DEFAULT_RESULTS_DIR,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
    synthetic: bool = True,
    workers: int = 1,
    force: bool = False,
    ids: Sequence[str] | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
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
    force : bool, default=False
        Recompute up-to-date results too.
    ids : sequence of str, optional
        Run only these experiments, in this order (default: all, sorted by id).
    progress : bool, default=True

    Returns
    -------
    list of dict
        One record per run, in the order run (the real-data run of an experiment first).
    """
    if preset not in PRESETS:
        raise ParameterError(f"preset must be one of {', '.join(PRESETS)}; got {preset!r}.")
    experiments = [get(i) for i in dict.fromkeys(ids)] if ids else all_experiments()
    if not experiments:
        raise ExperimentError("no experiments are registered; nothing to reproduce.")
    checked = check_data(data, all_experiments())
    records = []
    common = dict(preset=preset, output=output, data=checked, data_root=data_root, workers=workers, force=force,
                  progress=progress, raise_errors=False)
    for exp in experiments:
        has_real = bool(resolve_data(exp, checked, data_root))
        records.append(run_experiment(exp, variant="auto", **common))
        if has_real and synthetic and exp.synthetic:
            records.append(run_experiment(exp, variant="synthetic", **common))
        else:  # a secondary record this run does not refresh would be shown as current
            stale = record_path(output, exp.id, secondary=True)
            if stale.exists():
                logger.info("%s: removing %s (not part of this run)", exp.id, stale)
                stale.unlink()
                _remove_stale_figures(stale.with_suffix(""), ())
    counts = {s: sum(r["status"] == s for r in records) for s in ("ok", "failed", "skipped")}
    logger.info("reproduce: %d ok, %d failed, %d skipped", counts["ok"], counts["failed"], counts["skipped"])
    return records
