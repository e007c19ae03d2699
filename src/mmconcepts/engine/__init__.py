"""The experiment engine: declare an experiment, run it, record and judge its numbers.

The engine knows nothing of the thesis: its chapters live in :mod:`mmconcepts.experiments`
(``ch2/`` ... ``ch7/``), above it, and are found by scanning
(:data:`~mmconcepts.engine.registry.EXPERIMENT_PACKAGES`). What an experiment module uses is
importable from here:

- declare: :class:`Experiment` (id, config class, ``compute``, ``present``, the thesis'
  numbers, claims), :class:`PresetConfig` (``quick()``/``full()`` as data), :class:`Claim`,
  :func:`register`;
- compute: :class:`RunContext` (workers, real data sets, caches, progress), :func:`streams`
  (independent random streams from the seed), :class:`Result`, :class:`Table`,
  :class:`SampleUnit` (what the repetitions behind a metric are), :func:`describe_split`
  (no source recording on both sides of a split), :class:`ExperimentSkipped`; :class:`Explorer`
  (:class:`ConceptCard`, :class:`AudioClip`, :class:`Thumbnail`, :class:`MotionClip`: the cards of
  the concepts a run learnt, written beside its figures);
- run: :func:`run_experiment`, :func:`reproduce`, :class:`DataPlan` (which real sets each
  experiment of a run uses, resolved once per run), :func:`load_record`,
  :func:`compare_records`, :func:`redraw_figures` (figures drawn again from what a run kept).

The modules, from the bottom up: ``rule_syntax``/``rules`` (the claim language),
``uncertainty`` (units and intervals), ``evidence`` (the tests behind a verdict),
``verdicts`` (a claim decided once, when its record is made), ``spec``, ``context``,
``streams``, ``experiment``, ``config``, ``splits``, ``explorer`` (what an experiment declares and uses),
``codec``/``cache`` (the no-pickle disk caches), ``workers``/``cluster`` (processes, Dask),
``registry``, ``record``/``digest``/``outputs``/``media``/``data`` (records, the digest of their content,
their files, the explorer's files, the data plan), ``runfiles`` (a run's files under its record's lock, all
or nothing, kept when they cannot be written), ``runner`` (one experiment), ``lanes``/``batch`` (many),
``compare`` (two runs' records), ``redraw`` (figures again, without recomputing).
See ``docs/architecture.rst`` for the picture and the import rules.
"""

from __future__ import annotations

from .batch import reproduce
from .compare import compare_records
from .config import PresetConfig
from .context import RunContext, array_digest, cached_call
from .data import DataPlan, check_data, parse_data_args
from .experiment import PRESETS, Experiment
from .explorer import AudioClip, ConceptCard, Explorer, MotionClip, Thumbnail
from .outputs import load_record
from .record import RECORD_KEYS, SCHEMA_VERSION, ClaimRecord, ResultRecord
from .redraw import redraw_figures
from .registry import all_experiments, get, load_experiments, register, unregister
from .rules import FAIR_AGREEMENT, Rule, above_chance_rule, evaluate_rule, fair_bar, parse_rule
from .runner import run_experiment
from .spec import CLAIM_KINDS, Claim, ExperimentSkipped, Result, Table, fill_thesis_numbers
from .splits import concept_parts, describe_split, shared_sources
from .streams import STREAMS, Streams, streams
from .uncertainty import SampleUnit

__all__ = [
    "AudioClip",
    "CLAIM_KINDS",
    "ConceptCard",
    "FAIR_AGREEMENT",
    "MotionClip",
    "PRESETS",
    "RECORD_KEYS",
    "SCHEMA_VERSION",
    "Claim",
    "ClaimRecord",
    "DataPlan",
    "Experiment",
    "ExperimentSkipped",
    "Explorer",
    "PresetConfig",
    "Result",
    "ResultRecord",
    "Rule",
    "RunContext",
    "SampleUnit",
    "STREAMS",
    "Streams",
    "Table",
    "Thumbnail",
    "above_chance_rule",
    "all_experiments",
    "array_digest",
    "cached_call",
    "check_data",
    "compare_records",
    "concept_parts",
    "describe_split",
    "evaluate_rule",
    "fair_bar",
    "fill_thesis_numbers",
    "get",
    "load_experiments",
    "load_record",
    "parse_data_args",
    "parse_rule",
    "redraw_figures",
    "register",
    "reproduce",
    "run_experiment",
    "shared_sources",
    "streams",
    "unregister",
]
