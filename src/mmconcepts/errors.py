"""Exceptions and warnings shared by every part of mmconcepts.

Every error raised on bad user input is a subclass of :class:`ValueError` (or of
:class:`OSError` for files), so ``except ValueError`` keeps working for code written
against scikit-learn. Messages say what was expected, what came, and how to fix it.
"""

from __future__ import annotations

from sklearn.exceptions import ConvergenceWarning as _SklearnConvergenceWarning

__all__ = [
    "MMConceptsError",
    "ParameterError",
    "DataError",
    "DataFormatError",
    "VersionMismatchError",
    "ExperimentError",
    "MissingExtraError",
    "ClusterError",
    "ConvergenceWarning",
    "DataWarning",
    "ParameterWarning",
]


class MMConceptsError(Exception):
    """Base class of every exception raised by mmconcepts."""


class ParameterError(MMConceptsError, ValueError):
    """A parameter has a value that is not allowed (wrong range, type or choice)."""


class DataError(MMConceptsError, ValueError):
    """Input data is unusable: negative, NaN or infinite values, empty or mismatched arrays."""


class DataFormatError(MMConceptsError, ValueError):
    """A file or record cannot be read: corrupt, truncated, or in an unknown format."""


class VersionMismatchError(MMConceptsError, ValueError):
    """A saved object was written by an incompatible version of mmconcepts."""


class ExperimentError(MMConceptsError, RuntimeError):
    """An experiment cannot run (unknown id, missing data, a claim rule that does not parse)."""


class MissingExtraError(MMConceptsError, ImportError):
    """A package of an optional extra is not installed; the message names the extra to install
    (``pip install "mmconcepts[<extra>]"``).

    Subclass of :class:`ImportError`, so ``except ImportError`` keeps working.
    """


class ClusterError(MMConceptsError, RuntimeError):
    """A computation on a ``distributed`` cluster lost one of its workers, or one worker's part of it failed
    and stopped the others' (the message names the worker and the first error)."""


class ConvergenceWarning(_SklearnConvergenceWarning):
    """An iterative solver stopped at its iteration limit before meeting its tolerance.

    Subclass of scikit-learn's ``ConvergenceWarning`` so existing warning filters apply.
    """


class ParameterWarning(UserWarning):
    """A parameter combination is allowed but probably not what was meant."""


class DataWarning(UserWarning):
    """Some of the data given was left out (the message counts what and says why)."""
