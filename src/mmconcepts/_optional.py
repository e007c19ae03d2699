"""Importing the packages of the optional extras (internal): one error naming the extra to install."""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingExtraError

__all__ = ["optional_import"]


def optional_import(name: str, extra: str, what: str) -> ModuleType:
    """Import the module ``name`` of the optional extra ``extra``.

    Parameters
    ----------
    name : str
        The module, e.g. ``"soundfile"`` or ``"skimage.segmentation"``.
    extra : str
        The extra of ``pyproject.toml`` that installs it (``"audio"``, ``"vision"``, ``"dask"``...).
    what : str
        What needs it, for the message (``"reading and writing audio"``).

    Returns
    -------
    module

    Raises
    ------
    MissingExtraError
        If the module cannot be imported; the message names the package, the extra and the
        command that installs it.
    """
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise MissingExtraError(
            f"{what} needs the package {name.partition('.')[0]!r} of the {extra!r} extra, which is not installed "
            f"({exc}). Fix: pip install \"mmconcepts[{extra}]\"."
        ) from exc
