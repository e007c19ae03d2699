"""The package's no-pickle codec: a value as JSON plus numpy arrays, in one ``.npz`` file (internal).

Everything the package keeps on disk that is not a data set goes through this module: saved
models (:class:`mmconcepts._persist.SaveLoadMixin`), the experiments' cache entries and the
figure data of a run (:mod:`mmconcepts._store`). Reading never runs code: files are opened
with ``numpy.load(..., allow_pickle=False)`` and :func:`json.loads` only, and the only
classes ever built are the package's named tuples and its :class:`Stateful` objects.

Values
    :func:`encode` turns a value into a JSON-able *structure* and puts the arrays it holds in
    a mapping of named arrays; :func:`decode` rebuilds the value from both. Supported, with
    their type and bits kept:

    - None, bool, int, str, and float (a non-finite float is a marked node; a NaN keeps its
      sign and payload);
    - numpy arrays of any dtype that holds no Python objects (an array of the file; an array
      subclass comes back as a plain array), and object arrays of strings only (in the JSON);
    - numpy scalars (bool, integer, floating, complex, string, datetime): a 0-d array;
    - slices (of integers or None);
    - lists, tuples, the package's named tuples, and dicts (string keys as a JSON object,
      other keys, themselves values of this list, as a list of pairs);
    - the package's :class:`Stateful` objects (the fitted estimators): their class, their
      constructor parameters and their state, recursively.

    Anything else raises :class:`~mmconcepts.errors.ParameterError`, naming the type and
    where it is in the value.

Structure
    Plain JSON for None, bools, numbers, strings, lists and string-keyed dicts; every other
    node is a JSON object whose key ``"__mmconcepts__"`` names its kind: ``array`` and
    ``scalar`` (``"entry"``: the array's name), ``str-object-array`` (``"shape"``,
    ``"items"``), ``float`` (``"value"``: ``"inf"``, ``"-inf"`` or ``"nan"``, and ``"bits"``
    for a NaN), ``tuple`` and ``slice`` (``"items"``: start, stop, step), ``namedtuple`` (``"class"``: ``module:qualname``,
    ``"fields"``, ``"items"``), ``dict`` (``"items"``: key-value pairs) and ``estimator``
    (``"class"``, ``"params"``, ``"state"``). A string-keyed dict that holds the key
    ``"__mmconcepts__"`` is written as a ``dict`` node.

Files
    :func:`write_npz` writes a header (a JSON object, stored as the member ``header``) and
    the arrays as one ``numpy.savez`` archive, atomically; :func:`read_npz` opens one and
    returns the header and the archive. A file that is not such an archive, or a structure
    :func:`encode` does not write, raises :class:`CorruptFile`.
"""

from __future__ import annotations

import abc
import importlib
import io
import json
import math
import os
import re
import struct
import zipfile
from collections.abc import Mapping
from typing import Any

import numpy as np

from ._io import atomic_path
from .errors import DataFormatError, ParameterError

__all__ = ["CorruptFile", "HEADER", "MARK", "Stateful", "decode", "encode", "npz_bytes", "read_npz", "write_npz"]

#: The key naming the kind of a structure node that is not plain JSON.
MARK = "__mmconcepts__"
#: The member of an archive holding its JSON header.
HEADER = "header"
_ZIP_MAGIC = b"PK\x03\x04"


class CorruptFile(DataFormatError):
    """A file or structure that the codec did not write (torn, edited, planted)."""


class Stateful(abc.ABC):
    """Base of the objects the codec keeps by class: constructor parameters and state.

    :class:`mmconcepts._persist.SaveLoadMixin` implements the three methods; the codec builds
    an object again as ``cls(**params)`` followed by ``obj._set_state(state)``, and only for
    subclasses defined in the package.
    """

    @abc.abstractmethod
    def _saved_params(self) -> dict[str, Any]:
        """The constructor parameters to save."""

    @abc.abstractmethod
    def _get_state(self) -> dict[str, Any]:
        """The state to save (attribute name -> value)."""

    @abc.abstractmethod
    def _set_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`_get_state` returned."""


def _in_package(module: str) -> bool:
    return module == "mmconcepts" or module.startswith("mmconcepts.")


# --------------------------------------------------------------------------- encoding


def encode(value: Any, arrays: dict[str, np.ndarray], *, where: str = "value") -> Any:
    """The JSON-able structure of ``value``; the arrays it holds are added to ``arrays``.

    Parameters
    ----------
    value : object
        A value of the types listed in the module docstring.
    arrays : dict of str to ndarray
        Receives the arrays, named ``a0``, ``a1``, ... in the order met (several values may
        share one mapping, as the parameters and the state of a saved model do).
    where : str, default="value"
        How the value is named in error messages.

    Raises
    ------
    ParameterError
        For a value (or a part of it) of another type, naming the type and where it is.
    """
    def add(a: np.ndarray) -> str:
        name = f"a{len(arrays)}"
        arrays[name] = a
        return name

    def enc(x: Any, at: str) -> Any:
        t = type(x)
        if x is None or t is bool or t is int or t is str:
            return x
        if t is float:
            if math.isfinite(x):
                return x  # json writes repr(x), which reads back exactly
            if x != x:
                return {MARK: "float", "value": "nan", "bits": struct.pack("<d", x).hex()}
            return {MARK: "float", "value": repr(x)}
        if isinstance(x, np.ndarray):
            if x.dtype.hasobject:
                if x.dtype == object and all(type(v) is str for v in x.ravel()):
                    # in the JSON: numpy's fixed-width strings would drop trailing NUL characters
                    return {MARK: "str-object-array", "shape": list(x.shape), "items": [str(v) for v in x.ravel()]}
                raise ParameterError(f"{at}: an array of Python objects that are not all strings cannot be saved "
                                     "without pickle.")
            return {MARK: "array", "entry": add(np.asarray(x))}
        if isinstance(x, np.generic) and not isinstance(x, (np.object_, np.void)):
            return {MARK: "scalar", "entry": add(np.asarray(x))}
        if t is list:
            return [enc(v, f"{at}[{i}]") for i, v in enumerate(x)]
        if t is tuple:
            return {MARK: "tuple", "items": [enc(v, f"{at}[{i}]") for i, v in enumerate(x)]}
        if t is slice:
            return {MARK: "slice", "items": [enc(v, f"{at}.{f}") for f, v in
                                             (("start", x.start), ("stop", x.stop), ("step", x.step))]}
        if isinstance(x, tuple) and hasattr(t, "_fields") and _in_package(getattr(t, "__module__", "") or ""):
            return {MARK: "namedtuple", "class": f"{t.__module__}:{t.__qualname__}", "fields": list(t._fields),
                    "items": [enc(v, f"{at}.{f}") for f, v in zip(t._fields, x)]}
        if t is dict:
            if all(type(k) is str for k in x) and MARK not in x:
                return {k: enc(v, f"{at}.{k}") for k, v in x.items()}
            return {MARK: "dict", "items": [[enc(k, f"{at}<key {k!r}>"), enc(v, f"{at}[{k!r}]")] for k, v in x.items()]}
        if isinstance(x, Stateful) and _in_package(t.__module__):
            return {MARK: "estimator", "class": f"{t.__module__}.{t.__qualname__}",
                    "params": enc(x._saved_params(), f"{at}.params"), "state": enc(x._get_state(), f"{at}.state")}
        what = t.__name__ if t.__module__ == "builtins" else f"{t.__module__}.{t.__qualname__}"
        article = "an" if what[:1].lower() in "aeiou" else "a"
        raise ParameterError(
            f"{at}: {article} {what} cannot be saved without pickle; expected "
            "None, bools, ints, floats, strings, numpy arrays and scalars, and lists, tuples, dicts of them, the "
            "package's named tuples and estimators."
        )

    return enc(value, where)


# --------------------------------------------------------------------------- decoding


def _package_object(spec: Any, sep: str) -> Any:
    """The object named ``spec`` (``module<sep>qualname``), only if its module is one of the package's."""
    if not isinstance(spec, str) or not re.fullmatch(r"[\w.:]+", spec):
        raise CorruptFile(f"a bad class name {str(spec)[:60]!r}")
    if sep == ":":
        if spec.count(":") != 1:
            raise CorruptFile(f"a bad class name {spec!r}")
        module, qualname = spec.split(":")
    else:
        module, _, qualname = spec.rpartition(".")
    if not _in_package(module):
        raise CorruptFile(f"the class {spec!r} is not one of the package's; only mmconcepts classes are loaded")
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise CorruptFile(f"the class {spec!r} is not in this mmconcepts ({exc})") from None
    return obj


def decode(structure: Any, arrays: Mapping[str, Any]) -> Any:
    """Rebuild the value :func:`encode` turned into ``structure`` and ``arrays``.

    Parameters
    ----------
    structure : object
        What :func:`encode` returned, after a JSON round trip.
    arrays : mapping of str to ndarray
        The arrays (a dict, or the ``NpzFile`` of an archive opened with ``allow_pickle=False``).

    Raises
    ------
    CorruptFile
        If the structure is not one :func:`encode` writes, names an absent array, or names a
        class that is not one of the package's.
    """
    def array(name: Any) -> np.ndarray:
        if not isinstance(name, str) or name == HEADER or name not in arrays:
            raise CorruptFile(f"no array {str(name)[:60]!r}")
        try:
            a = arrays[name]
        except Exception as exc:  # noqa: BLE001 - a member torn or edited, or of Python objects (never unpickled)
            raise CorruptFile(f"array {name!r} cannot be read ({type(exc).__name__}: {exc})") from None
        if not isinstance(a, np.ndarray) or a.dtype.hasobject:
            raise CorruptFile(f"array {name!r} is no plain array")
        return np.asarray(a)

    def items(node: dict, key: str = "items") -> list:
        body = node.get(key)
        if type(body) is not list:
            raise CorruptFile(f"a {node.get(MARK)} node without its {key}")
        return body

    def dec(x: Any) -> Any:
        if x is None or type(x) in (bool, int, float, str):
            return x
        if type(x) is list:
            return [dec(v) for v in x]
        if type(x) is not dict:
            raise CorruptFile(f"unexpected node {str(x)[:60]!r}")
        kind = x.get(MARK)
        if kind is None:
            return {k: dec(v) for k, v in x.items()}
        if kind == "array":
            return array(x.get("entry"))
        if kind == "scalar":
            a = array(x.get("entry"))
            if a.ndim != 0:
                raise CorruptFile("a scalar that is no 0-d array")
            return a[()]
        if kind == "str-object-array":
            if "entry" in x:  # written by an older version, which kept the strings as an array
                return array(x["entry"]).astype(object)
            values, shape = items(x), x.get("shape")
            if not all(type(v) is str for v in values) or type(shape) is not list or not all(
                    type(n) is int and n >= 0 for n in shape) or math.prod(shape) != len(values):
                raise CorruptFile("a bad string array")
            out = np.empty(len(values), dtype=object)
            out[:] = values
            return out.reshape(shape)
        if kind == "float":
            text = x.get("value")
            if text not in ("nan", "inf", "-inf"):
                raise CorruptFile(f"a bad float {str(text)[:20]!r}")
            if "bits" not in x:
                return float(text)
            try:
                value = struct.unpack("<d", bytes.fromhex(x["bits"]))[0]
            except (TypeError, ValueError, struct.error) as exc:
                raise CorruptFile("a bad NaN") from exc
            if value == value:
                raise CorruptFile("a NaN that is a number")
            return value
        if kind == "tuple":
            return tuple(dec(v) for v in items(x))
        if kind == "slice":
            bounds = [dec(v) for v in items(x)]
            if len(bounds) != 3 or not all(b is None or (isinstance(b, (int, np.integer)) and type(b) is not bool)
                                           for b in bounds):
                raise CorruptFile(f"a bad slice {bounds!r:.60}")
            return slice(*bounds)
        if kind == "namedtuple":
            cls = _package_object(x.get("class"), ":")
            fields, values = x.get("fields"), items(x)
            if not (isinstance(cls, type) and issubclass(cls, tuple) and list(getattr(cls, "_fields", ())) == fields
                    and len(values) == len(fields)):
                raise CorruptFile(f"{x.get('class')!r} is no named tuple with the fields {fields!r}")
            make: Any = getattr(cls, "_make")  # a named tuple class of the package
            return make(dec(v) for v in values)
        if kind == "dict":
            mapping: dict[Any, Any] = {}
            for pair in items(x):
                if type(pair) is not list or len(pair) != 2:
                    raise CorruptFile("a bad dict item")
                key = dec(pair[0])
                try:
                    mapping[key] = dec(pair[1])
                except TypeError:  # an unhashable key
                    raise CorruptFile("a dict key that is no key") from None
            return mapping
        if kind == "estimator":
            cls = _package_object(x.get("class"), ".")
            if not (isinstance(cls, type) and issubclass(cls, Stateful)):
                raise CorruptFile(f"{x.get('class')!r} is not a model that can be loaded")
            params, state = dec(x.get("params")), dec(x.get("state"))
            if type(params) is not dict or type(state) is not dict:
                raise CorruptFile(f"an estimator {x.get('class')!r} without its parameters and state")
            build: Any = cls
            obj = build(**params)
            obj._set_state(state)
            return obj
        raise CorruptFile(f"unknown node kind {str(kind)[:40]!r}")

    try:
        return dec(structure)
    except RecursionError:
        raise CorruptFile("a structure nested too deeply") from None


# --------------------------------------------------------------------------- files


def _members(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    if HEADER in arrays:
        raise ParameterError(f"an array cannot be named {HEADER!r}: the header is stored under that name.")
    return {HEADER: np.array(json.dumps(dict(header), allow_nan=False)), **arrays}


def write_npz(path: str | os.PathLike[str], header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> None:
    """Write ``header`` (JSON, the member :data:`HEADER`) and ``arrays`` to the archive ``path``, atomically.

    The file is written beside ``path`` and renamed into place (:func:`mmconcepts._io.atomic_path`),
    flushed to disk first.

    Raises
    ------
    ParameterError
        If an array is named :data:`HEADER`.
    """
    members = _members(header, arrays)
    with atomic_path(path, suffix=".tmp.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, allow_pickle=False, **members)
            fh.flush()
            os.fsync(fh.fileno())


def npz_bytes(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> bytes:
    """The bytes of the archive :func:`write_npz` writes for ``header`` and ``arrays`` (for a file written later).

    Raises
    ------
    ParameterError
        If an array is named :data:`HEADER`.
    """
    buf = io.BytesIO()
    np.savez(buf, allow_pickle=False, **_members(header, arrays))
    return buf.getvalue()


def read_npz(path: str | os.PathLike[str]) -> tuple[dict[str, Any], Any]:
    """The header and the open archive of a file :func:`write_npz` wrote (close the archive when done).

    Never unpickles: the file must be a zip archive of ``.npy`` members, read with
    ``allow_pickle=False``, whose :data:`HEADER` member is a JSON object.

    Raises
    ------
    FileNotFoundError
        If there is no file.
    CorruptFile
        If the file is not such an archive.
    """
    with open(path, "rb") as fh:
        if fh.read(4) != _ZIP_MAGIC:
            raise CorruptFile(f"{path}: not an npz archive")
    try:
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise CorruptFile(f"{path}: {type(exc).__name__}: {exc}") from None
    try:
        if HEADER not in npz.files:
            raise CorruptFile(f"{path}: no header")
        raw = npz[HEADER]
        if raw.dtype.kind != "U" or raw.ndim != 0:
            raise CorruptFile(f"{path}: a header that is no string")
        header = json.loads(str(raw))
        if type(header) is not dict:
            raise CorruptFile(f"{path}: a header that is no JSON object")
    except CorruptFile:
        npz.close()
        raise
    except Exception as exc:  # noqa: BLE001 - torn or edited: numpy's parsers raise OSError, ValueError, KeyError,
        # EOFError, BadZipFile, zlib.error, UnicodeDecodeError...
        npz.close()
        raise CorruptFile(f"{path}: {type(exc).__name__}: {exc}") from None
    return header, npz
