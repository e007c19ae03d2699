"""The pieces an experiment is made of: Experiment, Claim, Result, Table, RunContext.

An experiment reproduces one table or figure of the thesis. It has a stable id, a frozen
dataclass config with ``quick()`` and ``full()`` presets (declared as data with
:class:`~mmconcepts.experiments.config.PresetConfig`) and a ``seed`` field, the thesis'
reference numbers and its claims, each with a rule checked on our numbers (see
:mod:`mmconcepts.experiments.rules`), and two functions:

- ``compute(config, ctx) -> Result``: the numbers. Everything the result record keeps
  (metrics, their samples and units, tables, notes, extras) and, in
  :attr:`Result.figure_data`, whatever else the figures are drawn from (curves, maps).
  It draws nothing, so a test can check the numbers without matplotlib doing any work.
- ``present(result, config) -> dict of Figure``: the presentation. It draws the figures
  from the result alone (its metrics, tables and ``figure_data``) and computes nothing
  that the record keeps; an experiment without figures has no ``present``.

The runner calls ``compute`` and then ``present`` (:meth:`Experiment.run` does both);
tests that check numbers call ``compute``.

Example
-------
A complete experiment module (``src/mmconcepts/experiments/ch2_example.py``)::

    from dataclasses import dataclass

    import numpy as np
    from matplotlib.figure import Figure

    from mmconcepts.experiments import Claim, Experiment, Result, RunContext, Table, register
    from mmconcepts.experiments.config import PresetConfig


    @dataclass(frozen=True)
    class Config(PresetConfig):             # quick() and full() from the presets below
        n_trials: int = 100                 # the defaults: the full protocol
        seed: int = 0

        QUICK = {"n_trials": 3}             # what the quick preset changes (FULL: none)


    def _trial(seed):                       # module level, so it pickles for ctx.parallel
        return float(np.random.default_rng(seed).random())


    def compute(config: Config, ctx: RunContext) -> Result:
        seeds = np.random.SeedSequence(config.seed).generate_state(config.n_trials)
        scores = ctx.parallel(_trial, list(seeds), desc="trials")
        return Result(
            metrics={"score": float(np.mean(scores))},
            samples={"score": scores},
            tables={"scores": Table("Per-trial scores", ["trial", "score"],
                                    [[i, s] for i, s in enumerate(scores)])},
        )


    def present(result: Result, config: Config) -> dict[str, Figure]:
        fig = Figure()
        fig.subplots().plot(result.samples["score"])
        return {"scores": fig}


    EXPERIMENT = register(Experiment(
        id="ch2-example", title="An example", thesis_ref="Section 2.1, Table 2.1",
        config_cls=Config, compute=compute, present=present, reference={"score": 0.5},
        claims=[Claim("The score is about one half.", "abs(score - 0.5) < 0.1")],
    ))
    run = EXPERIMENT.run                    # compute, then present: a Result with its figures
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import numbers
import os
import re
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar, cast

import numpy as np

from .._paths import data_home
from ..errors import ExperimentError, ParameterError
from .rules import is_valid_metric_name, parse_rule
from ._workers import WarningsCarried, progress_enabled, workers_end_with_this_process
from .uncertainty import SampleUnit

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from ._store import CacheStore

__all__ = [
    "CLAIM_KINDS",
    "fill_thesis_numbers",
    "Streams",
    "array_digest",
    "cached_call",
    "child_seeds",
    "streams",
    "Claim",
    "Experiment",
    "ExperimentSkipped",
    "Result",
    "RunContext",
    "Table",
    "PRESETS",
]

#: The preset names every experiment config provides.
PRESETS = ("quick", "full")

_ID = re.compile(r"[a-z0-9]+(?:-[a-z0-9]+)*\Z")
_FIGURE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")
_T = TypeVar("_T")
_R = TypeVar("_R")


class Streams(NamedTuple):
    """Seeds (ints) of the independent random streams of one experiment run.

    ``data`` draws or composes the data, ``learner`` initialises the learners, ``splits``
    draws cross-validation folds and train/test parts, ``reference`` draws reference
    examples and random baselines, ``composition`` assembles derived test material (composed
    utterances, streams). The seed that drew the data never reaches a learner.
    """

    data: int
    learner: int
    splits: int
    reference: int
    composition: int = 0


def child_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent seeds spawned from ``seed`` (one per fold or repetition)."""
    return [int(k.generate_state(1, dtype=np.uint32)[0]) for k in np.random.SeedSequence(int(seed)).spawn(n)]


def streams(seed: int) -> Streams:
    """Spawn the independent streams of an experiment from its seed.

    ``numpy.random.SeedSequence(seed).spawn(5)``, each child turned into an int seed in
    ``[0, 2**31 - 1)`` (so that it can be passed as any library's ``random_state``). A
    child depends only on ``seed`` and its index, so adding a stream never changes the
    others.

    Parameters
    ----------
    seed : int
        The experiment's seed (``config.seed``).

    Returns
    -------
    Streams
    """
    kids = np.random.SeedSequence(int(seed)).spawn(len(Streams._fields))
    return Streams(*(int(k.generate_state(1)[0] % (2**31 - 1)) for k in kids))


class ExperimentSkipped(ExperimentError):
    """Raised by an experiment's ``run`` when it cannot run here, e.g. real data is absent.

    The runner records the experiment as ``"skipped"`` with this message instead of as a
    failure. :meth:`RunContext.require_data` raises it for a missing ``--data`` set.
    """


#: The kinds of claims, in the order the report counts them (see :class:`Claim`).
CLAIM_KINDS = ("thesis", "magnitude", "ours", "check")

_THESIS_NUMBER = re.compile(r"\{thesis:([A-Za-z0-9_.]+)\}")


def _format_thesis_number(value: float) -> str:
    return f"{value:.6g}" if abs(value) >= 0.01 or value == 0 else f"{value:.4g}"


def fill_thesis_numbers(text: str, reference: Mapping[str, float]) -> str:
    """``text`` with each ``{thesis:NAME}`` replaced by the thesis' number ``reference[NAME]``.

    For claim texts (done when an experiment is made) and notes, so that each thesis number is
    written once, in the experiment's reference table.

    Raises
    ------
    ExperimentError
        If a name is not in ``reference``.

    Examples
    --------
    >>> fill_thesis_numbers("NMF {thesis:a} vs SVM {thesis:b}", {"a": 0.854, "b": 0.818})
    'NMF 0.854 vs SVM 0.818'
    """
    def fill(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in reference:
            raise ExperimentError(f"{text!r:.60} cites {{thesis:{name}}}, which is not in the reference table (known: "
                                  f"{', '.join(sorted(reference)) or 'none'}).")
        return _format_thesis_number(float(reference[name]))

    return _THESIS_NUMBER.sub(fill, text)


@dataclass(frozen=True)
class Claim:
    """A statement checked on our metrics, and what kind of statement it is.

    Parameters
    ----------
    text : str
        The claim in words, e.g. "NMF with the Frobenius loss beats the SVM". A thesis
        number is written ``{thesis:NAME}``, filled in from the experiment's reference table
        (so that each thesis number is written once, in that table).
    rule : str
        For kinds ``thesis``, ``ours`` and ``check``: a boolean expression over metric names,
        e.g. ``"nmf_frobenius.l_full > svm.l_full"`` (see
        :mod:`mmconcepts.experiments.rules`), its syntax checked when the claim is made. For
        kind ``magnitude``: the name of the metric set beside the thesis' number of the same
        name in the reference table. Empty when ``settings`` is given.
    kind : {"thesis", "magnitude", "ours", "check"}, default="ours"
        ``thesis``: a statement the thesis makes (an order, a trend, "X beats Y"), tested at
        the thesis' own comparison; ``magnitude``: our number against the thesis' number, as
        a ratio with its interval (:func:`~mmconcepts.experiments.uncertainty.magnitude_verdict`);
        ``ours``: a check we added (a control, a bar of our own); ``check``: a property of the
        code kept in the record only to show that the run is sane (never evidence).
    source : str, default=""
        Where the thesis says it: section, table or figure, and the line of the thesis' text
        (``"Section 3.3.4, Table 3.2 (line 2790)"``). Required for kinds ``thesis`` and
        ``magnitude``.
    settings : mapping of str to str, optional
        For a statement whose verdict depends on a setting we had to choose (features,
        dynamics, noise): one rule per setting, by the setting's label. The claim is decided
        under each, and its verdict says "holds under all", "holds only under X" or "fails
        under all" (:func:`~mmconcepts.experiments.uncertainty.combine_settings`).
    """

    text: str
    rule: str = ""
    kind: str = "ours"
    source: str = ""
    settings: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.text, str) or not self.text.strip():
            raise ExperimentError(f"Claim.text must be a non-empty string; got {self.text!r}.")
        if self.kind not in CLAIM_KINDS:
            raise ExperimentError(f"Claim.kind must be one of {', '.join(CLAIM_KINDS)}; got {self.kind!r} "
                                  f"(claim {self.text!r:.60}).")
        if self.kind in ("thesis", "magnitude") and (not isinstance(self.source, str) or not self.source.strip()):
            raise ExperimentError(f"a {self.kind} claim needs its source: where the thesis says it (section, table or "
                                  f"figure, and the line of the thesis' text); claim {self.text!r:.60}.")
        if not isinstance(self.settings, Mapping):
            raise ExperimentError(f"Claim.settings must map a setting's label to a rule; got {self.settings!r:.60}.")
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))
        if self.settings:
            if self.rule:
                raise ExperimentError(f"claim {self.text!r:.60}: give a rule or settings (a rule per setting), "
                                      "not both.")
            if self.kind == "magnitude":
                raise ExperimentError(f"claim {self.text!r:.60}: a magnitude claim has no settings.")
            for label, rule in self.settings.items():
                if not isinstance(label, str) or not label.strip():
                    raise ExperimentError(f"claim {self.text!r:.60}: a setting's label must be a non-empty string; "
                                          f"got {label!r}.")
                parse_rule(rule)
        elif self.kind == "magnitude":
            if not is_valid_metric_name(self.rule):
                raise ExperimentError(f"a magnitude claim's rule is the metric set beside the thesis' number of the "
                                      f"same name; got {self.rule!r} (claim {self.text!r:.60}).")
        else:
            parse_rule(self.rule)  # syntax and type check; metric names are checked at run time

    @property
    def rules(self) -> dict[str, str]:
        """The rule under each setting (``{"": rule}`` without settings)."""
        return dict(self.settings) if self.settings else {"": self.rule}

    def with_thesis_numbers(self, reference: Mapping[str, float], exp_id: str = "") -> "Claim":
        """This claim with each ``{thesis:NAME}`` of its text replaced by ``reference[NAME]``.

        Raises
        ------
        ExperimentError
            If a name is not in ``reference``, or a magnitude claim's metric has no thesis number.
        """
        if self.kind == "magnitude" and self.rule not in reference:
            raise ExperimentError(f"experiment {exp_id!r}: magnitude claim {self.text!r:.60} sets {self.rule!r} beside "
                                  "the thesis' number, but the reference table has none of that name.")
        try:
            text = fill_thesis_numbers(self.text, reference)
        except ExperimentError as exc:
            raise ExperimentError(f"experiment {exp_id!r}: claim {exc}") from None
        return self if text == self.text else dataclasses.replace(self, text=text)


@dataclass
class Table:
    """A result table, kept JSON-friendly.

    Parameters
    ----------
    title : str
        Caption, e.g. "Table 3.2: classification scores".
    columns : list of str
        Column headers.
    rows : list of list
        One list per row, each with ``len(columns)`` cells (numbers, strings or None).
    note : str, default=""
        A remark shown under the table.
    """

    title: str
    columns: list[str]
    rows: list[list[Any]]
    note: str = ""

    def __post_init__(self) -> None:
        self.columns = [str(c) for c in self.columns]
        self.rows = [list(row) for row in self.rows]
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ExperimentError(
                    f"table {self.title!r}: row {i} has {len(row)} cells but there are "
                    f"{len(self.columns)} columns ({', '.join(self.columns)})."
                )

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"title", "columns", "rows", "note"}`` (cells not yet JSON-cleaned)."""
        return {"title": self.title, "columns": list(self.columns), "rows": [list(r) for r in self.rows], "note": self.note}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Table":
        """Rebuild a table from :meth:`to_dict` output (as read back from JSON)."""
        return cls(title=d.get("title", ""), columns=list(d["columns"]), rows=[list(r) for r in d["rows"]], note=d.get("note", "") or "")


@dataclass
class Result:
    """What an experiment's ``run`` returns.

    Parameters
    ----------
    metrics : dict of str to float
        Named numbers; names are runs of ``[A-Za-z0-9_.]`` (``"16.nmf_kl.l_full"``), the
        ones claim rules and the reference use. NaN means "not measured".
    tables : dict of str to Table
        Result tables, by a short name.
    figures : dict of str to matplotlib.figure.Figure
        Figures, by a file-name-safe name; the runner saves each as ``<id>/<name>.png``
        and closes it. Prefer :class:`matplotlib.figure.Figure` over pyplot.
    notes : list of str
        Remarks for the report (what differs from the thesis and why, ...).
    extra : dict
        Anything else JSON-able worth keeping (per-trial scores, ...).
    samples : dict of str to list of float
        The per-fold, per-seed or per-draw values behind a metric, by the metric's name
        (each name must also be in ``metrics``). The runner turns them into a 95 %
        interval and uses them to decide claims beyond their uncertainty: metrics whose
        samples have the same length are taken to come from the same folds or seeds and
        are resampled together (a paired bootstrap), unless ``sample_units`` says
        otherwise.
    sample_units : dict of str to str
        Optional: the unit of a metric's samples (``"16-label folds"``, ``"seeds"``). Metrics
        with the same unit are paired (their samples must then have the same length and
        order); metrics with different units are resampled independently, even when their
        samples have the same length. A metric without an entry is paired with every other
        metric without one whose samples have the same length.
    units : dict of str to SampleUnit
        What each unit named in ``sample_units`` is
        (:class:`~mmconcepts.experiments.uncertainty.SampleUnit`): independent seeds or
        repetitions, the folds of one cross-validation (whose intervals and verdicts use the
        corrected resampled t), or blocks of one fit (whose verdicts are marked "within one
        fit"). A unit not declared here is taken as independent.
    split_groups : dict
        For each split of the data into training and test parts, what its examples are
        grouped by so that no source recording behind a test example feeds a training
        example, e.g. ``{"mixtures": {"by": "source recordings", "n_groups": 40}}``
        (JSON-able; stored in the record).
    figure_data : dict
        What an experiment's ``present`` draws beyond the metrics and tables (loss curves,
        per-unit curves, value maps, ...), set by its ``compute``. Kept in memory only: the
        runner never writes it to the record.
    """

    metrics: dict[str, float] = field(default_factory=dict)
    tables: dict[str, Table] = field(default_factory=dict)
    figures: dict[str, "Figure"] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    samples: dict[str, list[float]] = field(default_factory=dict)
    sample_units: dict[str, str] = field(default_factory=dict)
    figure_data: dict[str, Any] = field(default_factory=dict)
    units: dict[str, SampleUnit] = field(default_factory=dict)
    split_groups: dict[str, Any] = field(default_factory=dict)

    def validate(self) -> None:
        """Check names and types; raise :class:`ExperimentError` naming the culprit."""
        for name, value in self.metrics.items():
            if not is_valid_metric_name(name):
                raise ExperimentError(
                    f"metric name {name!r} is not allowed: use letters, digits, '_' and '.', "
                    "not a plain number nor one of and/or/not/abs/min/max."
                )
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ExperimentError(f"metric {name!r} must be a real number; got {value!r} ({type(value).__name__}).")
        for name, table in self.tables.items():
            if not isinstance(table, Table):
                raise ExperimentError(f"table {name!r} must be a Table; got {type(table).__name__}.")
        for name, fig in self.figures.items():
            if not isinstance(name, str) or not _FIGURE_NAME.fullmatch(name):
                raise ExperimentError(f"figure name {name!r} must be a file-name-safe word ([A-Za-z0-9_.-]).")
            if not hasattr(fig, "savefig"):
                raise ExperimentError(f"figure {name!r} must be a matplotlib Figure; got {type(fig).__name__}.")
        if isinstance(self.notes, str) or not all(isinstance(n, str) for n in self.notes):
            raise ExperimentError("Result.notes must be a list of strings.")
        if not isinstance(self.figure_data, Mapping):
            raise ExperimentError(f"Result.figure_data must be a dict; got {type(self.figure_data).__name__}.")
        for name, values in self.samples.items():
            if name not in self.metrics:
                raise ExperimentError(
                    f"samples given for {name!r}, which is not a metric; add metrics[{name!r}] (their summary) "
                    "or rename the samples to the metric they belong to."
                )
            if isinstance(values, (str, bytes)) or not all(
                isinstance(v, numbers.Real) and not isinstance(v, bool) for v in values
            ):
                raise ExperimentError(f"samples[{name!r}] must be a list of real numbers; got {values!r:.80}.")
        lengths: dict[str, tuple[str, int]] = {}
        for name, unit in self.sample_units.items():
            if name not in self.samples:
                raise ExperimentError(
                    f"sample_units gives a unit for {name!r}, which has no samples; give samples[{name!r}] or drop "
                    "the entry."
                )
            if not isinstance(unit, str) or not unit:
                raise ExperimentError(f"sample_units[{name!r}] must be a non-empty string; got {unit!r}.")
            first = lengths.setdefault(unit, (name, len(self.samples[name])))
            if first[1] != len(self.samples[name]):
                raise ExperimentError(
                    f"metrics of unit {unit!r} are paired, so their samples must have the same length: "
                    f"{first[0]!r} has {first[1]}, {name!r} has {len(self.samples[name])}; give them different units "
                    "if they do not come from the same folds or seeds."
                )
        if not isinstance(self.units, Mapping):
            raise ExperimentError(f"Result.units must map a unit's name to a SampleUnit; got {type(self.units).__name__}.")
        named = set(self.sample_units.values())
        for unit, kind in self.units.items():
            if not isinstance(kind, SampleUnit):
                raise ExperimentError(f"units[{unit!r}] must be a SampleUnit (SampleUnit.folds(k), .seeds(), "
                                      f".within_fit()); got {kind!r:.60}.")
            if unit not in named:
                raise ExperimentError(f"units declares {unit!r}, which no metric's samples have (sample_units names "
                                      f"{', '.join(sorted(named)) or 'none'}).")
        if not isinstance(self.split_groups, Mapping):
            raise ExperimentError(f"Result.split_groups must be a dict; got {type(self.split_groups).__name__}.")


@dataclass
class RunContext:
    """What an experiment's ``run`` gets besides its config.

    Parameters
    ----------
    workers : int, default=1
        Processes for :meth:`parallel`; -1 means one per CPU.
    data : mapping of str to Path
        Real data sets given with ``--data NAME=PATH``, restricted to the experiment's
        ``datasets``. Use :meth:`require_data` to get one or skip.
    cache_dir : Path, optional
        Folder for generated data and caches (default :func:`mmconcepts._paths.data_home`).
    logger : logging.Logger, optional
        Where to log (default ``logging.getLogger("mmconcepts.experiments")``).
    show_progress : bool, default=True
        Show progress bars; they are shown only when stderr is a terminal.
    client : distributed.Client, optional
        A Dask client: :meth:`parallel` then runs its items on that cluster's workers
        (``workers`` is not used). See :mod:`mmconcepts.experiments.cluster`.
    """

    workers: int = 1
    data: Mapping[str, Path] = field(default_factory=dict)
    cache_dir: Path = field(default_factory=lambda: data_home())
    logger: logging.Logger = field(default_factory=lambda: logging.getLogger("mmconcepts.experiments"))
    show_progress: bool = True
    client: Any = None

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, numbers.Integral):
            raise ParameterError(f"workers must be an int >= 1 or -1; got {self.workers!r}.")
        if self.workers == -1:
            self.workers = os.cpu_count() or 1
        if self.workers < 1:
            raise ParameterError(f"workers must be an int >= 1 or -1 (all CPUs); got {self.workers}.")
        self.workers = int(self.workers)
        self.data = MappingProxyType({str(k): Path(v) for k, v in self.data.items()})
        self.cache_dir = Path(self.cache_dir)

    def progress(self, iterable: Iterable[_T], *, total: int | None = None, desc: str | None = None) -> Iterable[_T]:
        """Wrap ``iterable`` in a tqdm progress bar (silent when quiet or not on a terminal).

        Parameters
        ----------
        iterable : iterable
        total : int, optional
            Number of items, when ``len(iterable)`` is not available.
        desc : str, optional
            Label shown before the bar.
        """
        from tqdm.auto import tqdm

        return tqdm(iterable, total=total, desc=desc, disable=not progress_enabled(self.show_progress), leave=False)

    def parallel(self, fn: Callable[[_T], _R], items: Iterable[_T], *, desc: str | None = None,
                 on_result: Callable[[int, _R], None] | None = None) -> list[_R]:
        """Return ``[fn(item) for item in items]``, computed over :attr:`workers` processes.

        With ``workers == 1`` this is a plain loop in this process. Otherwise joblib's
        process pool is used, so ``fn`` and the items must pickle (define ``fn`` at
        module level) and each item must carry its own seed. With a :attr:`client`, the
        items run on the Dask cluster's workers instead (even a single item), each result
        fetched as soon as it is ready (:func:`~mmconcepts.experiments.cluster.map_in_order`).
        Order is preserved. Warnings
        raised in a worker process are raised again here, in this process, so that the
        caller (and the runner's record of the run's warnings) sees the same warnings
        whatever the number of workers. The worker processes end with this process, even
        when it is killed (SIGKILL) in the middle of a task: at once on Linux, elsewhere
        within about a second (as soon as the worker runs Python code).

        Parameters
        ----------
        fn : callable
        items : iterable
        desc : str, optional
            Progress-bar label.
        on_result : callable, optional
            ``on_result(i, result)`` is called as soon as item ``i``'s result is back, in
            order, before the next one is awaited (e.g. to cache it, so that an interrupted
            run keeps what it has computed).
        """
        items = list(items)
        out: list[_R] = []
        if self.client is not None:
            return self._parallel_dask(fn, items, desc=desc, on_result=on_result)
        if self.workers == 1 or len(items) <= 1:
            for item in self.progress(items, total=len(items), desc=desc):
                out.append(fn(item))
                if on_result is not None:
                    on_result(len(out) - 1, out[-1])
            return out
        from joblib import Parallel, delayed

        n_jobs = min(self.workers, len(items))
        with workers_end_with_this_process():
            gen = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(WarningsCarried(fn))(item) for item in items)
            for result, caught in self.progress(gen, total=len(items), desc=desc):
                for category, message, filename, lineno in caught:
                    warnings.warn_explicit(message, category, filename, lineno)
                out.append(result)
                if on_result is not None:
                    on_result(len(out) - 1, result)
        return out

    def _parallel_dask(self, fn: Callable[[_T], _R], items: list[_T], *, desc: str | None,
                       on_result: Callable[[int, _R], None] | None) -> list[_R]:
        from .cluster import map_in_order

        def emit(i: int, carried: tuple[_R, list]) -> None:
            result, caught = carried
            for category, message, filename, lineno in caught:
                warnings.warn_explicit(message, category, filename, lineno)
            if on_result is not None:
                on_result(i, result)

        carried = map_in_order(self.client, WarningsCarried(fn), items,
                               progress=lambda it, n: self.progress(it, total=n, desc=desc), on_result=emit)
        return [result for result, _ in carried]

    def memory(self, name: str) -> CacheStore:
        """A disk cache under ``cache_dir/name`` that never unpickles (a ``CacheStore``).

        ``ctx.memory(name).cache(f, ignore=[...])`` is ``f`` with its results kept on disk:
        an entry is reused only for the same arguments (hashed; leave out with ``ignore=``
        the ones the others stand for, such as this context or data summarised by a
        digest) and the same source of ``f``. Only ``f``'s own source is watched, so a
        cached function also takes :func:`~mmconcepts._fingerprint.code_fingerprint` as an
        argument: a change anywhere in the package then recomputes. Each entry is one
        ``.npz`` file (the result's arrays, and its structure as JSON) written atomically
        and read with ``allow_pickle=False``: ``f`` may return None, bools, ints, floats,
        strings, numpy arrays and scalars, and lists, tuples, the package's named tuples
        and str-keyed dicts of these (anything else raises
        :class:`~mmconcepts.errors.ExperimentError`). An entry that cannot be read (torn,
        or not in this format, such as a planted pickle) is computed again, never
        loaded. Call the cached function through :func:`cached_call`.

        Parameters
        ----------
        name : str
            The cache's folder under :attr:`cache_dir` (e.g. ``"ch3-folds"``).
        """
        from ._store import CacheStore

        return CacheStore(self.cache_dir / name)

    def parallel_cached(self, cached: Callable[..., _R], calls: Sequence[tuple], *, desc: str | None = None) -> list[_R]:
        """Return ``[cached(*args) for args in calls]`` for a function cached with :meth:`memory`.

        The calls already in the cache are read here; the others run through
        :meth:`parallel`, where each worker writes its call's entry as soon as that call
        ends, so an interrupted run keeps every call it finished (and resumes from there).
        An entry that cannot be read is computed again.

        Parameters
        ----------
        cached : CachedFunction
            ``ctx.memory(name).cache(f, ignore=...)``, ``f`` defined at module level.
        calls : sequence of tuple
            The positional arguments of each call.
        desc : str, optional
            Progress-bar label.
        """
        out: list[Any] = [None] * len(calls)
        todo = []
        lookup = getattr(cached, "lookup", None)
        for i, args in enumerate(calls):
            found, value = lookup(*args) if lookup is not None else (False, None)
            if found:
                out[i] = value
            else:
                todo.append(i)
        done = self.parallel(_cached_item, [(cached, *calls[i]) for i in todo], desc=desc)
        for i, result in zip(todo, done):
            out[i] = result
        return out

    def require_data(self, name: str, *, hint: str = "") -> Path:
        """Return the path given for data set ``name``, or skip the experiment.

        Raises
        ------
        ExperimentSkipped
            If ``--data name=PATH`` was not given.
        """
        if name in self.data:
            return self.data[name]
        more = f" {hint}" if hint else ""
        raise ExperimentSkipped(
            f"needs the real data set {name!r}: put it under the data root (--data-root DIR or "
            f"$MMCONCEPTS_DATA_ROOT; see `mmconcepts data list`) or pass --data {name}=PATH.{more}"
        )


def cached_call(cached: Callable[..., _R], *args: Any) -> _R:
    """``cached(*args)`` for a function cached with :meth:`RunContext.memory`.

    The one way the experiments call a cached function (kept as the place to change how
    cached calls are made, e.g. to silence a note of the cache about itself).
    """
    return cached(*args)


def _cached_item(item: tuple) -> Any:
    """``cached(*args)`` of ``item = (cached, *args)``, a call :meth:`RunContext.parallel_cached` found
    missing: computed and its entry written (unless another process wrote it meanwhile: read under its lock)."""
    cached, *args = item
    compute = getattr(cached, "compute", None)
    return compute(*args) if compute is not None else cached_call(cached, *args)


def array_digest(arrays: Iterable[np.ndarray]) -> str:
    """A digest (hex SHA-1) of a sequence of arrays: their shapes, dtypes and values.

    For cache keys that stand for data too large to hash on every call (see
    :meth:`RunContext.memory`).
    """
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.shape}{a.dtype.str}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def check_seed(seed: Any) -> int:
    """Return ``seed`` as an int, or raise :class:`ParameterError` if it is no non-negative int."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ParameterError(f"seed must be a non-negative int; got {seed!r}.")
    return int(seed)


def _check_config_cls(exp_id: str, config_cls: Any) -> None:
    if not (isinstance(config_cls, type) and dataclasses.is_dataclass(config_cls)):
        raise ExperimentError(f"experiment {exp_id!r}: config_cls must be a dataclass type; got {config_cls!r}.")
    if not config_cls.__dataclass_params__.frozen:  # type: ignore[attr-defined]
        raise ExperimentError(f"experiment {exp_id!r}: config_cls {config_cls.__name__} must be frozen (@dataclass(frozen=True)).")
    if "seed" not in {f.name for f in dataclasses.fields(config_cls)}:
        raise ExperimentError(f"experiment {exp_id!r}: config_cls {config_cls.__name__} needs a field 'seed: int'.")
    for preset in PRESETS:
        if not callable(getattr(config_cls, preset, None)):
            raise ExperimentError(
                f"experiment {exp_id!r}: config_cls {config_cls.__name__} needs a classmethod {preset}() returning the preset."
            )


@dataclass(frozen=True, eq=False)
class Experiment:
    """One thesis table or figure, reproducible from the command line.

    An experiment is given as ``compute`` (the numbers) and ``present`` (the figures), see
    the module docstring; :attr:`run` is then both in turn. An experiment given as a single
    ``run`` that computes and draws at once is still accepted (its ``compute`` is that
    ``run``, and it has no ``present``).

    Parameters
    ----------
    id : str
        Stable identifier, lowercase words joined by ``-``, e.g. ``"ch2-nmf-recovery"``.
    title : str
        One-line title.
    thesis_ref : str
        Where the thesis reports it, e.g. ``"Section 2.1, Appendix A.2"``.
    config_cls : type
        A frozen dataclass with a ``seed: int`` field and classmethods ``quick()`` and
        ``full()`` returning the presets.
    run : callable, optional
        ``run(config, ctx: RunContext) -> Result`` with its figures, for an experiment not
        split into ``compute`` and ``present``; give either ``run`` or ``compute``. Prints
        nothing.
    reference : mapping of str to float, optional
        The thesis' values, by the metric names ``compute`` reports.
    claims : sequence of Claim, optional
        The thesis' claims, each with a rule over metric names.
    datasets : tuple of str, optional
        Names of the data sets it runs on when present (see :mod:`mmconcepts.datasets`):
        found under the data root or given with ``--data NAME=PATH`` (empty if it only
        runs on generated data).
    description : str, optional
        A paragraph for ``mmconcepts list`` and the report.
    synthetic : bool, default=True
        Whether it also runs without real data, on generated stand-ins (its *synthetic
        variant*). An experiment that only exists on a real set sets this to False.
    compute : callable, optional
        ``compute(config, ctx: RunContext) -> Result``: every number of the result, no
        figures (``Result.figures`` empty). Prints nothing.
    present : callable, optional
        ``present(result: Result, config) -> dict of str to Figure``: the figures, drawn
        from what ``compute`` returned. Only with ``compute``; omitted when the experiment
        has no figure.

    Attributes
    ----------
    run : callable
        ``run(config, ctx) -> Result``: ``compute`` and then ``present``, the figures in
        ``Result.figures`` (the ``run`` given, for an experiment defined by one).
    compute : callable
        The ``compute`` given (the ``run`` given, for an experiment defined by one).
    """

    id: str
    title: str
    thesis_ref: str
    config_cls: type
    run: Callable[[Any, RunContext], Result] | None = None
    reference: Mapping[str, float] = field(default_factory=dict)
    claims: Sequence[Claim] = ()
    datasets: tuple[str, ...] = ()
    description: str = ""
    synthetic: bool = True
    compute: Callable[[Any, RunContext], Result] | None = None
    present: Callable[[Result, Any], Mapping[str, Figure]] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _ID.fullmatch(self.id):
            raise ExperimentError(
                f"experiment id {self.id!r} must be lowercase letters and digits joined by '-', e.g. 'ch2-nmf-recovery'."
            )
        _check_config_cls(self.id, self.config_cls)
        self._check_functions()
        reference: dict[str, Any] = {}
        for name, value in dict(self.reference).items():
            if not is_valid_metric_name(name):
                raise ExperimentError(f"experiment {self.id!r}: reference key {name!r} is not a valid metric name.")
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ExperimentError(f"experiment {self.id!r}: reference value for {name!r} must be a number; got {value!r}.")
            reference[name] = float(value)
        object.__setattr__(self, "reference", MappingProxyType(reference))
        claims = tuple(self.claims)
        for claim in claims:
            if not isinstance(claim, Claim):
                raise ExperimentError(f"experiment {self.id!r}: claims must be Claim objects; got {claim!r}.")
        claims = tuple(claim.with_thesis_numbers(reference, self.id) for claim in claims)
        texts = [claim.text for claim in claims]
        twice = sorted({t for t in texts if texts.count(t) > 1})
        if twice:
            raise ExperimentError(f"experiment {self.id!r}: two claims read {twice[0]!r:.80}; each claim's text must "
                                  "be its own (the report tells claims apart by their text).")
        object.__setattr__(self, "claims", claims)
        if isinstance(self.datasets, str):
            raise ExperimentError(f"experiment {self.id!r}: datasets must be a tuple of names, e.g. ('choreo1',), not a string.")
        datasets = tuple(self.datasets)
        for name in datasets:
            if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
                raise ExperimentError(f"experiment {self.id!r}: dataset name {name!r} must be a word ([A-Za-z0-9_.-]).")
        object.__setattr__(self, "datasets", datasets)

    def _check_functions(self) -> None:
        """Check run / compute / present and set ``run`` and ``compute`` (see the class docstring)."""
        given = {name: getattr(self, name) for name in ("run", "compute", "present")}
        for name, fn in given.items():
            if fn is not None and not callable(fn):
                signature = {"run": "run(config, ctx) -> Result", "compute": "compute(config, ctx) -> Result",
                             "present": "present(result, config) -> figures"}[name]
                raise ExperimentError(f"experiment {self.id!r}: {name} must be callable {signature}; got {fn!r}.")
        if given["run"] is not None and given["compute"] is not None:
            raise ExperimentError(
                f"experiment {self.id!r}: give either run (numbers and figures at once) or compute (and present), "
                "not both."
            )
        if given["run"] is None and given["compute"] is None:
            raise ExperimentError(
                f"experiment {self.id!r}: needs compute(config, ctx) -> Result (and present(result, config) -> "
                "figures), or a run(config, ctx) -> Result that does both."
            )
        if given["run"] is not None:
            if given["present"] is not None:
                raise ExperimentError(f"experiment {self.id!r}: present goes with compute, not with run.")
            object.__setattr__(self, "compute", given["run"])
        else:
            object.__setattr__(self, "run", self._compute_and_present)

    def _compute_and_present(self, config: Any, ctx: RunContext) -> Result:
        """Run ``compute``, then draw the figures with ``present``: the result with its figures.

        Raises
        ------
        ExperimentError
            If ``compute`` returns no :class:`Result` or draws figures itself, or
            ``present`` returns no mapping of figures.
        """
        result = self.compute(config, ctx)  # type: ignore[misc]
        if not isinstance(result, Result):
            raise ExperimentError(f"{self.id}: compute() must return a Result; got {type(result).__name__}.")
        if self.present is None:
            return result
        if result.figures:
            raise ExperimentError(
                f"{self.id}: compute() returned figures ({', '.join(result.figures)}); draw them in present(result, "
                "config), from the numbers compute keeps in the result (figure_data for the rest)."
            )
        figures = self.present(result, config)
        if not isinstance(figures, Mapping):
            raise ExperimentError(f"{self.id}: present() must return a dict of figures; got {type(figures).__name__}.")
        result.figures = dict(figures)
        return result

    def make_config(self, preset: str = "quick", *, seed: int | None = None) -> Any:
        """Return the ``preset`` config, with ``seed`` replaced when given.

        Parameters
        ----------
        preset : {"quick", "full"}
        seed : int, optional
            A non-negative seed replacing the preset's.
        """
        if preset not in PRESETS:
            raise ParameterError(f"preset must be one of {', '.join(PRESETS)}; got {preset!r}.")
        config = getattr(self.config_cls, preset)()
        if not isinstance(config, self.config_cls):
            raise ExperimentError(
                f"experiment {self.id!r}: {self.config_cls.__name__}.{preset}() returned "
                f"{type(config).__name__}, not a {self.config_cls.__name__}."
            )
        if seed is not None:
            config = dataclasses.replace(cast(Any, config), seed=check_seed(seed))
        return config

    def __repr__(self) -> str:
        return f"Experiment(id={self.id!r}, title={self.title!r}, thesis_ref={self.thesis_ref!r})"
