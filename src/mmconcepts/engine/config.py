"""The presets of the experiments' configs, declared once as data.

Every experiment has a frozen dataclass config with a ``seed`` field and two presets,
``Config.quick()`` and ``Config.full()`` (see :mod:`mmconcepts.engine.experiment`). Rather
than writing both classmethods in each config, a config subclasses :class:`PresetConfig`
and states what each preset changes from its field defaults::

    @dataclass(frozen=True)
    class Config(PresetConfig):
        n_trials: int = 100          # the defaults: the thesis' protocol
        seed: int = 0

        QUICK = {"n_trials": 3}      # what the quick preset changes
        # FULL defaults to {}: the full preset is the defaults

A third preset, ``Config.smoke()``, is the quick one made as small as the experiment can run:
seconds, to check that everything runs and that its records stay the same from one commit to
the next (its numbers mean nothing). ``SMOKE`` states what it changes from the quick preset.

``QUICK``, ``FULL`` and ``SMOKE`` are class attributes (not dataclass fields: they are left out of
``dataclasses.asdict``, of the result record and of equality). A subclass of a config
inherits its presets, and may extend them: ``QUICK = {**Base.QUICK, "sensitivity": False}``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar, TypeVar

from ..errors import ParameterError

__all__ = ["PresetConfig"]

_C = TypeVar("_C", bound="PresetConfig")

#: The preset names, in the order :data:`mmconcepts.engine.experiment.PRESETS` lists them.
_PRESET_NAMES = ("quick", "full", "smoke")


def _attribute(cls: type, name: str, unknown: list[str]) -> str:
    """The class attribute that sets the ``unknown`` fields of preset ``name`` (the smoke preset has two)."""
    if name == "smoke":
        return "SMOKE" if set(unknown) & set(getattr(cls, "SMOKE", {})) else "QUICK"
    return name.upper()


class PresetConfig:
    """Mixin for an experiment's frozen dataclass config: ``quick()``/``full()`` from data.

    Attributes
    ----------
    QUICK : mapping of str to object
        Field values of the quick preset that differ from the field defaults.
    FULL : mapping of str to object, default={}
        Field values of the full preset that differ from the field defaults (usually none:
        the defaults are the thesis' protocol).
    SMOKE : mapping of str to object, default={}
        Field values of the smoke preset that differ from the quick preset's.
    """

    QUICK: ClassVar[Mapping[str, Any]] = {}
    FULL: ClassVar[Mapping[str, Any]] = {}
    SMOKE: ClassVar[Mapping[str, Any]] = {}

    @classmethod
    def preset(cls: type[_C], name: str) -> _C:
        """The config of preset ``name`` ("quick", "full" or "smoke").

        Raises
        ------
        ParameterError
            If ``name`` is no preset, or the preset names a field the config does not have.
        """
        if name not in _PRESET_NAMES:
            raise ParameterError(f"preset must be one of {', '.join(_PRESET_NAMES)}; got {name!r}.")
        values = {**cls.QUICK, **cls.SMOKE} if name == "smoke" else dict(getattr(cls, name.upper()))
        fields = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]  # subclasses are dataclasses; the mixin itself is not one, which mypy cannot see
        unknown = sorted(set(values) - fields)
        if unknown:
            raise ParameterError(
                f"{cls.__qualname__}.{_attribute(cls, name, unknown)} sets {unknown}, which are not fields of {cls.__qualname__}; "
                f"fields: {sorted(fields)}."
            )
        return cls(**values)

    @classmethod
    def quick(cls: type[_C]) -> _C:
        """The quick preset (minutes on two cores): the defaults changed by :attr:`QUICK`."""
        return cls.preset("quick")

    @classmethod
    def full(cls: type[_C]) -> _C:
        """The full preset (the thesis' protocol): the defaults changed by :attr:`FULL`."""
        return cls.preset("full")

    @classmethod
    def smoke(cls: type[_C]) -> _C:
        """The smoke preset (seconds; its numbers mean nothing): the quick preset changed by :attr:`SMOKE`."""
        return cls.preset("smoke")
