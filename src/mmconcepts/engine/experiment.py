"""The pieces an experiment is made of: Experiment, Claim, Result, Table, RunContext.

An experiment reproduces one table or figure of the thesis. It has a stable id, a frozen
dataclass config with ``quick()`` and ``full()`` presets (declared as data with
:class:`~mmconcepts.engine.config.PresetConfig`) and a ``seed`` field, the thesis'
reference numbers and its claims, each with a rule checked on our numbers (see
:mod:`mmconcepts.engine.rules`), and two functions:

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
A complete experiment module (``src/mmconcepts/experiments/ch2/example.py``)::

    from dataclasses import dataclass

    import numpy as np
    from matplotlib.figure import Figure

    from mmconcepts.experiments import Claim, Experiment, Result, RunContext, Table, register, streams
    from mmconcepts.engine.config import PresetConfig


    @dataclass(frozen=True)
    class Config(PresetConfig):             # quick() and full() from the presets below
        n_trials: int = 100                 # the defaults: the full protocol
        seed: int = 0

        QUICK = {"n_trials": 3}             # what the quick preset changes (FULL: none)


    def _trial(seed):                       # module level, so it pickles for ctx.parallel
        return float(np.random.default_rng(seed).random())


    def compute(config: Config, ctx: RunContext) -> Result:
        seeds = streams(config.seed).seeds_for("data", config.n_trials)  # one per trial
        scores = ctx.parallel(_trial, seeds, desc="trials")
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
import numbers
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, cast

from ..errors import ExperimentError, ParameterError
from .context import RunContext
from .spec import Claim, Result
from .rules import is_valid_metric_name

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["PRESETS", "SMOKE", "Experiment", "check_seed"]

#: The preset names every experiment config provides.
PRESETS = ("quick", "full")

#: A preset a config may provide (:meth:`~mmconcepts.engine.PresetConfig.smoke`): the quick one made as small as
#: the experiment can run, to check that everything runs and that its records stay the same.
SMOKE = "smoke"

_ID = re.compile(r"[a-z0-9]+(?:-[a-z0-9]+)*\Z")


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
        preset : {"quick", "full", "smoke"}
            ``"smoke"`` only for a config that has that preset (see :attr:`has_smoke`).
        seed : int, optional
            A non-negative seed replacing the preset's.
        """
        if preset not in (*PRESETS, SMOKE):
            raise ParameterError(f"preset must be one of {', '.join((*PRESETS, SMOKE))}; got {preset!r}.")
        if preset == SMOKE and not self.has_smoke:
            raise ParameterError(f"experiment {self.id!r} has no smoke preset ({self.config_cls.__name__} declares no "
                                 "SMOKE); run it with the quick preset, or declare SMOKE in its config.")
        config = getattr(self.config_cls, preset)()
        if not isinstance(config, self.config_cls):
            raise ExperimentError(
                f"experiment {self.id!r}: {self.config_cls.__name__}.{preset}() returned "
                f"{type(config).__name__}, not a {self.config_cls.__name__}."
            )
        if seed is not None:
            config = dataclasses.replace(cast(Any, config), seed=check_seed(seed))
        return config

    @property
    def has_smoke(self) -> bool:
        """Whether the config declares a smoke preset (a non-empty ``SMOKE``)."""
        return bool(getattr(self.config_cls, "SMOKE", None)) and callable(getattr(self.config_cls, SMOKE, None))

    def __repr__(self) -> str:
        return f"Experiment(id={self.id!r}, title={self.title!r}, thesis_ref={self.thesis_ref!r})"
