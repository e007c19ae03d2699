"""The registry of experiments, filled by importing the experiment modules.

Each module named in :data:`mmconcepts.experiments.EXPERIMENT_MODULES` calls
:func:`register` when imported. The modules are imported lazily, on the first call of
:func:`get` or :func:`all_experiments`, so importing :mod:`mmconcepts.experiments` stays
cheap. A module that fails to import is an error, never silently skipped.

Your own experiments: a module of yours that calls :func:`register` on import is loaded
with the package's when its name is in the environment variable
``MMCONCEPTS_EXPERIMENT_MODULES`` (comma-separated module names, importable from
``sys.path``); the command line (``mmconcepts run``, ``reproduce``, ``list``) then knows
them, and so do the processes ``reproduce --concurrent`` starts.
"""

from __future__ import annotations

import difflib
import importlib
import logging
import os

from ..errors import ExperimentError
from .base import Experiment

__all__ = ["register", "unregister", "get", "all_experiments", "load_experiments", "EXTRA_MODULES_ENV"]

#: Environment variable naming more experiment modules to load (comma-separated).
EXTRA_MODULES_ENV = "MMCONCEPTS_EXPERIMENT_MODULES"

logger = logging.getLogger("mmconcepts.experiments")

_REGISTRY: dict[str, Experiment] = {}
_LOADED = False


def register(experiment: Experiment) -> Experiment:
    """Add ``experiment`` to the registry and return it.

    Raises
    ------
    ExperimentError
        If another experiment is registered under the same id. Registering the same
        object twice is a no-op.
    """
    if not isinstance(experiment, Experiment):
        raise ExperimentError(f"register() takes an Experiment; got {type(experiment).__name__}.")
    existing = _REGISTRY.get(experiment.id)
    if existing is experiment:
        return experiment
    if existing is not None:
        raise ExperimentError(
            f"an experiment with id {experiment.id!r} is already registered "
            f"({existing.title!r}, run={getattr(existing.run, '__module__', '?')}); ids must be unique."
        )
    _REGISTRY[experiment.id] = experiment
    return experiment


def unregister(experiment_id: str) -> None:
    """Remove an experiment from the registry (for tests); unknown ids are an error."""
    if experiment_id not in _REGISTRY:
        raise ExperimentError(f"no experiment {experiment_id!r} is registered.")
    del _REGISTRY[experiment_id]


def load_experiments() -> None:
    """Import every module of ``EXPERIMENT_MODULES`` and of ``$MMCONCEPTS_EXPERIMENT_MODULES`` (once).

    Raises
    ------
    ExperimentError
        If a module cannot be imported; the cause is chained.
    """
    global _LOADED
    if _LOADED:
        return
    package = importlib.import_module("mmconcepts.experiments")
    extra = [m.strip() for m in os.environ.get(EXTRA_MODULES_ENV, "").split(",") if m.strip()]
    for name in dict.fromkeys([*package.EXPERIMENT_MODULES, *extra]):
        try:
            importlib.import_module(name)
        except ExperimentError:
            raise
        except Exception as exc:
            raise ExperimentError(
                f"could not import the experiment module {name!r} ({type(exc).__name__}: {exc}). "
                f"Fix it or remove it from mmconcepts.experiments.EXPERIMENT_MODULES or ${EXTRA_MODULES_ENV}."
            ) from exc
    _LOADED = True
    logger.debug("loaded %d experiment(s)", len(_REGISTRY))


def get(experiment_id: str) -> Experiment:
    """Return the experiment registered under ``experiment_id``.

    Raises
    ------
    ExperimentError
        If no experiment has that id; the message lists the known ids and close matches.
    """
    load_experiments()
    try:
        return _REGISTRY[experiment_id]
    except (KeyError, TypeError):
        known = sorted(_REGISTRY)
        close = difflib.get_close_matches(str(experiment_id), known, n=3, cutoff=0.5)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        listing = ", ".join(known) if known else "none"
        raise ExperimentError(
            f"unknown experiment {experiment_id!r}.{hint} Known experiments: {listing}. "
            "See `mmconcepts list`."
        ) from None


def all_experiments() -> list[Experiment]:
    """Return every registered experiment, sorted by id."""
    load_experiments()
    return [_REGISTRY[k] for k in sorted(_REGISTRY)]
