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

from ..engine import *  # noqa: F401,F403  (the engine's names, importable from here for convenience)

#: Nothing of its own: the engine's names above are documented once, under :mod:`mmconcepts.engine`.
__all__: list[str] = []
