"""The registry of experiments, filled by scanning the packages that hold them.

An experiment module calls :func:`register` when imported. :func:`load_experiments` imports
every module found under the packages of :data:`EXPERIMENT_PACKAGES` (the thesis' chapters,
``mmconcepts.experiments.ch2`` ... ``ch7``), in name order: a new module placed in a chapter's
folder is found without being listed anywhere. The modules are imported lazily, on the first
call of :func:`get` or :func:`all_experiments`, so importing the package stays cheap. A module
that fails to import is an error, never silently skipped.

Your own experiments: a module (or a package, scanned the same way) of yours that calls
:func:`register` on import is loaded with the package's when its name is in the environment
variable ``MMCONCEPTS_EXPERIMENT_MODULES`` (comma-separated names, importable from
``sys.path``); the command line (``mmconcepts run``, ``reproduce``, ``list``) then knows
them, and so do the processes ``reproduce --concurrent`` starts.
"""

from __future__ import annotations

import difflib
import importlib
import logging
import os
import pkgutil
from collections.abc import Iterator

from ..errors import ExperimentError
from .experiment import Experiment

__all__ = ["register", "unregister", "get", "all_experiments", "load_experiments", "EXTRA_MODULES_ENV",
           "EXPERIMENT_PACKAGES", "experiment_modules"]

#: Environment variable naming more experiment modules to load (comma-separated).
EXTRA_MODULES_ENV = "MMCONCEPTS_EXPERIMENT_MODULES"

#: Packages whose modules register experiments when imported; every module under them is imported.
EXPERIMENT_PACKAGES: tuple[str, ...] = ("mmconcepts.experiments",)

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


def experiment_modules(names: tuple[str, ...] | list[str]) -> Iterator[str]:
    """The modules to import for ``names``: each name, then, for a package, every module under it (in name order).

    Importing a package to scan it may fail; the error is raised as it is.
    """
    for name in names:
        yield name
        module = importlib.import_module(name)
        path = getattr(module, "__path__", None)
        if path is not None:
            found = pkgutil.walk_packages(path, prefix=f"{name}.", onerror=_raise)
            yield from sorted(info.name for info in found)


def _raise(name: str) -> None:
    raise ImportError(f"could not scan the package {name!r}")


def load_experiments() -> None:
    """Import every module under :data:`EXPERIMENT_PACKAGES` and ``$MMCONCEPTS_EXPERIMENT_MODULES`` (once).

    Raises
    ------
    ExperimentError
        If a module cannot be imported; the cause is chained.
    """
    global _LOADED
    if _LOADED:
        return
    extra = [m.strip() for m in os.environ.get(EXTRA_MODULES_ENV, "").split(",") if m.strip()]
    names = list(dict.fromkeys([*EXPERIMENT_PACKAGES, *extra]))
    name = names[0]
    try:
        for name in experiment_modules(names):
            importlib.import_module(name)
    except ExperimentError:
        raise
    except Exception as exc:
        raise ExperimentError(
            f"could not import the experiment module {name!r} or a module under it ({type(exc).__name__}: {exc}). "
            f"Fix it, or remove it from its package or from ${EXTRA_MODULES_ENV}."
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
