"""Saving and loading fitted models without pickle (internal).

A saved model is one ``.npz`` archive written by the package's codec
(:func:`mmconcepts._codec.write_npz`): the arrays of the model, and a JSON header holding the
format name (``mmconcepts.<ClassName>``), the format version, the mmconcepts version that
wrote it, and the constructor parameters and the fitted state as structures of
:func:`mmconcepts._codec.encode`. Nested fitted estimators (an ``NMF`` inside a
``MultimodalNMF``) are saved the same way, recursively. Loading never unpickles
(``allow_pickle=False``) and only rebuilds classes of mmconcepts.

Estimators get ``save``/``load`` from :class:`SaveLoadMixin`. By default the state is every
fitted attribute (a name ending in ``_``) plus the private names listed in
``_persisted_private``; a class whose state is not made of what the codec stores (arrays,
numbers, strings, lists, tuples, dicts of them, estimators) overrides
:meth:`SaveLoadMixin._get_state` and :meth:`SaveLoadMixin._set_state`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from sklearn.exceptions import NotFittedError

from . import __version__
from ._codec import Stateful, decode, encode, read_npz, write_npz
from .errors import DataFormatError, VersionMismatchError

__all__ = ["SaveLoadMixin"]


class SaveLoadMixin(Stateful):
    """``save(path)`` and ``load(path)`` for a fitted estimator, as one ``.npz`` with a JSON header.

    Class attributes
    ----------------
    _save_format_version : int
        Raised when the saved state of the class changes incompatibly.
    _persisted_private : tuple of str
        Private attributes (not ending in ``_``) that belong to the fitted state.
    """

    _save_format_version: ClassVar[int] = 1
    _persisted_private: ClassVar[tuple[str, ...]] = ()

    # -- state ------------------------------------------------------------------------------
    def _saved_params(self) -> dict[str, Any]:
        """The constructor parameters to save (a random generator is saved as None)."""
        params = self.get_params(deep=False)  # type: ignore[attr-defined]  # every subclass is an estimator
        return {k: (None if isinstance(v, (np.random.Generator, np.random.RandomState)) else v)
                for k, v in params.items()}

    def _is_fitted_for_save(self) -> bool:
        return any(k.endswith("_") and not k.startswith("__") for k in vars(self))

    def _get_state(self) -> dict[str, Any]:
        """The fitted state: attribute name -> value (default: fitted and ``_persisted_private`` attributes)."""
        return {k: v for k, v in vars(self).items()
                if (k.endswith("_") and not k.startswith("__")) or k in self._persisted_private}

    def _set_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`_get_state` returned."""
        for k, v in state.items():
            setattr(self, k, v)

    # -- files ------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Save the fitted model to ``path`` (``.npz`` is appended if missing); no pickle.

        The file holds the arrays of the fitted state and a JSON header with the format
        name and version, the mmconcepts version, the constructor parameters (a
        ``random_state`` generator is saved as None) and the rest of the state. The write
        is atomic (a temporary file renamed into place).

        Returns
        -------
        pathlib.Path
            The file written.
        """
        if not self._is_fitted_for_save():
            raise NotFittedError(f"This {type(self).__name__} instance is not fitted yet; call fit before save.")
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        arrays: dict[str, np.ndarray] = {}
        cls = type(self)
        header = {
            "format": f"mmconcepts.{cls.__name__}",
            "format_version": cls._save_format_version,
            "mmconcepts_version": __version__,
            "params": encode(self._saved_params(), arrays, where="params"),
            "state": encode(self._get_state(), arrays, where="state"),
        }
        write_npz(path, header, arrays)
        return path

    @classmethod
    def _read_header(cls, path: Path) -> tuple[dict, Any]:
        try:
            header, z = read_npz(path)
        except (OSError, DataFormatError) as e:  # absent, empty, truncated, bytes flipped, not an archive
            message = str(e).removeprefix(f"{path}: ")
            raise DataFormatError(f"{path}: not a saved mmconcepts {cls.__name__} ({message}).") from None
        if header.get("format") != f"mmconcepts.{cls.__name__}":
            fmt = header.get("format")
            z.close()
            raise DataFormatError(
                f"{path}: not a saved {cls.__name__} (its format is {fmt!r}); load it with the class that saved it.")
        return header, z

    @classmethod
    def load(cls, path: str | Path):
        """Load a model written by :meth:`save`.

        Raises
        ------
        DataFormatError
            If the file is not a saved model of this class, or is corrupt.
        VersionMismatchError
            If it was written in another save-format version of this class.
        """
        path = Path(path)
        header, z = cls._read_header(path)
        with z:
            version = header.get("format_version")
            if version != cls._save_format_version:
                return cls._load_other_version(path, header, z)
            try:
                params = decode(header["params"], z)
                if not isinstance(params, dict):
                    raise TypeError(f"the parameters are a {type(params).__name__}, not a mapping")
                obj = cls(**params)
                state = decode(header["state"], z)
                if not isinstance(state, dict):
                    raise TypeError(f"the fitted state is a {type(state).__name__}, not a mapping")
                obj._set_state(state)
                obj._check_loaded_state()
            except Exception as e:  # noqa: BLE001 - an edited header, an array cut short or damaged, a bad state
                if isinstance(e, DataFormatError) and str(path) in str(e):
                    raise
                raise DataFormatError(f"{path}: a corrupt saved {cls.__name__} ({type(e).__name__}: {e}).") from None
        return obj

    def _check_loaded_state(self) -> None:
        """Check a loaded state for consistency; raise ``ValueError`` (or a subclass) if it is not.

        Called by :meth:`load` after :meth:`_set_state`, whose errors it turns into a
        :class:`~mmconcepts.errors.DataFormatError` naming the file, so that an edited file
        fails at load time rather than at the first use of the model. The default checks
        nothing; classes whose state has invariants (shapes that must agree) override it.
        """

    @classmethod
    def _load_other_version(cls, path: Path, header: dict, z: Any):
        """Read an older save-format version; by default no other version is readable."""
        raise VersionMismatchError(
            f"{path}: saved with format version {header.get('format_version')} (mmconcepts "
            f"{header.get('mmconcepts_version')}); this mmconcepts reads version {cls._save_format_version} of "
            f"{cls.__name__}. Refit the model, or load it with the mmconcepts version that saved it."
        )
