"""Experiments: one module per thesis table or figure, and the machinery to run them.

An experiment (:class:`Experiment`) has a stable id, a frozen config dataclass with
``quick()`` and ``full()`` presets and a seed, a ``compute(config, ctx) -> Result``
function (the numbers) and a ``present(result, config) -> figures`` function (the
figures), the thesis' reference numbers, and claims whose rules are checked on our numbers.
Experiment modules register themselves when imported; the modules are listed in
:data:`EXPERIMENT_MODULES` and imported on the first call of :func:`get` or
:func:`all_experiments`.

Run one with :func:`run_experiment` (``mmconcepts run ID``) or all with
:func:`reproduce` (``mmconcepts reproduce``); results are JSON records
(:class:`ResultRecord`; see :mod:`mmconcepts.experiments.runner` for the schema) plus PNG
figures, turned into an HTML and Markdown report by :func:`mmconcepts.report.write_report`.

See :mod:`mmconcepts.experiments.base` for a complete example module.
"""

from __future__ import annotations

from .base import CLAIM_KINDS, PRESETS, Claim, Experiment, ExperimentSkipped, Result, RunContext, Table
from .registry import all_experiments, get, load_experiments, register, unregister
from .record import ClaimRecord, ResultRecord
from .rules import Rule, evaluate_rule, parse_rule
from .compare import compare_records
from .splits import describe_split, shared_sources
from .uncertainty import SampleUnit
from .runner import (
    RECORD_KEYS,
    SCHEMA_VERSION,
    check_data,
    load_record,
    parse_data_args,
    reproduce,
    run_experiment,
)

#: Modules that register experiments when imported, in no particular order
#: (experiments are listed and run sorted by id).
EXPERIMENT_MODULES: tuple[str, ...] = (
    "mmconcepts.experiments.ch2_nmf_recovery",
    "mmconcepts.experiments.ch3_choreography",
    "mmconcepts.experiments.ch3_unseen",
    "mmconcepts.experiments.ch3_representations",
    "mmconcepts.experiments.ch3_threshold",
    "mmconcepts.experiments.ch3_combinations",
    "mmconcepts.experiments.ch3_msr_action3d",
    "mmconcepts.experiments.ch4_factorial_irl",
    "mmconcepts.experiments.ch4_inverse_control",
    "mmconcepts.experiments.ch5_incremental",
    "mmconcepts.experiments.ch5_nmf_keywords",
    "mmconcepts.experiments.ch5_tree",
    "mmconcepts.experiments.ch5_label_sets",
    "mmconcepts.experiments.ch5_word_discovery",
    "mmconcepts.experiments.ch6_motion_sound",
    "mmconcepts.experiments.ch6_image_features",
    "mmconcepts.experiments.ch6_concepts",
    "mmconcepts.experiments.ch6_modalities",
    "mmconcepts.experiments.ch6_sliding",
    "mmconcepts.experiments.ch7_compositional",
    "mmconcepts.experiments.ch7_online",
)

__all__ = [
    "CLAIM_KINDS",
    "EXPERIMENT_MODULES",
    "PRESETS",
    "RECORD_KEYS",
    "SCHEMA_VERSION",
    "Claim",
    "ClaimRecord",
    "Experiment",
    "ExperimentSkipped",
    "Result",
    "ResultRecord",
    "Rule",
    "RunContext",
    "SampleUnit",
    "Table",
    "all_experiments",
    "check_data",
    "compare_records",
    "describe_split",
    "evaluate_rule",
    "get",
    "load_experiments",
    "load_record",
    "parse_data_args",
    "parse_rule",
    "register",
    "reproduce",
    "run_experiment",
    "shared_sources",
    "unregister",
]
