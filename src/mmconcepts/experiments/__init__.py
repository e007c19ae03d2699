"""The thesis' experiments: one folder per chapter (``ch2`` ... ``ch7``), one module per table or figure.

Each module declares an :class:`~mmconcepts.engine.Experiment` and registers it when
imported; each chapter's shared protocol (data, splits, the folds its experiments share)
is its ``protocol`` module, beside its experiments. The engine finds the modules by scanning
this package (:func:`~mmconcepts.engine.registry.load_experiments`): a new module in a
chapter's folder needs no list. No chapter imports another.

Run one with :func:`run_experiment` (``mmconcepts run ID``) or all with :func:`reproduce`
(``mmconcepts reproduce``); results are JSON records (:class:`ResultRecord`; the schema is in
:mod:`mmconcepts.engine.outputs`) plus PNG figures, turned into an HTML and Markdown report by
:func:`mmconcepts.report.write_report`. The engine's names are importable from here too, for
convenience; see :mod:`mmconcepts.engine` and ``docs/architecture.rst`` for the smallest
complete experiment.
"""

from __future__ import annotations

from ..engine import (
    CLAIM_KINDS,
    PRESETS,
    RECORD_KEYS,
    SCHEMA_VERSION,
    Claim,
    ClaimRecord,
    Experiment,
    ExperimentSkipped,
    Result,
    ResultRecord,
    Rule,
    RunContext,
    SampleUnit,
    Table,
    all_experiments,
    check_data,
    compare_records,
    describe_split,
    evaluate_rule,
    get,
    load_experiments,
    load_record,
    parse_data_args,
    parse_rule,
    register,
    reproduce,
    run_experiment,
    shared_sources,
    unregister,
)

#: Nothing of its own: the engine's names above are importable from here for convenience, and documented once,
#: under :mod:`mmconcepts.engine`.
__all__: list[str] = []
