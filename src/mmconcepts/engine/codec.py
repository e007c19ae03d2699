"""The no-pickle codec of cache entries: a result as numpy arrays plus its structure as JSON.

:func:`encode` splits a value (nested dicts with string keys, lists, tuples, named tuples of the
package, arrays, numpy scalars, Python numbers, strings, None) into a JSON structure and named
arrays; :func:`decode` rebuilds it. :func:`write_entry` writes both as one ``numpy.savez``
archive, atomically; :func:`read_entry` reads it with ``numpy.load(..., allow_pickle=False)`` and
:func:`json.loads` only, so reading never runs code, and raises :class:`CorruptEntry` for anything
that is not such an entry. The caches of :mod:`mmconcepts.engine.cache` store their entries so.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import struct
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_path
from ..errors import ExperimentError

__all__ = ["CorruptEntry", "FORMAT", "MISSING", "encode", "decode", "read_entry", "write_entry"]


#: The format name written in every entry; an entry with another is recomputed.
FORMAT = "mmconcepts-cache/1"

_STRUCTURE = "__structure__"  # the npz member holding the JSON structure
_ZIP_MAGIC = b"PK\x03\x04"
#: What :func:`read_entry` returns when there is no entry.
MISSING = object()


class CorruptEntry(Exception):
    """An entry that is not in :data:`FORMAT` (torn, edited, planted): recompute it."""


# --------------------------------------------------------------------------- encoding


def encode(value: Any) -> tuple[Any, dict[str, np.ndarray]]:
    """Split ``value`` into a JSON-able structure and the arrays it refers to.

    Supported: None, bool, int, float, str (Python's own types), numpy arrays of any dtype
    without Python objects, numpy scalars (bool, integer, floating, complex, str), and
    lists, tuples, named tuples defined in :mod:`mmconcepts` and dicts with string keys of
    these.

    Raises
    ------
    ExperimentError
        For any other type (naming it and where it is in ``value``).
    """
    arrays: dict[str, np.ndarray] = {}

    def add(a: np.ndarray) -> str:
        name = f"a{len(arrays)}"
        arrays[name] = a
        return name

    def enc(x: Any, where: str) -> Any:
        t = type(x)
        if x is None or t is bool or t is int or t is str:
            return x
        if t is float:
            if x != x:  # NaN: its bits (sign and payload), which JSON's NaN does not keep
                return {"nan": struct.pack("<d", x).hex()}
            return x  # json writes repr(x), which reads back exactly (and Infinity / -Infinity)
        if t is np.ndarray:
            if x.dtype.hasobject:
                raise ExperimentError(f"a cached result cannot hold an array of Python objects (at {where}).")
            return {"array": add(x)}
        if isinstance(x, np.generic) and not isinstance(x, (np.object_, np.void)):
            return {"scalar": add(np.asarray(x))}
        if t is list:
            return {"list": [enc(v, f"{where}[{i}]") for i, v in enumerate(x)]}
        if t is tuple:
            return {"tuple": [enc(v, f"{where}[{i}]") for i, v in enumerate(x)]}
        if isinstance(x, tuple) and hasattr(t, "_fields") and _package_class(t):
            return {"namedtuple": f"{t.__module__}:{t.__qualname__}", "fields": list(t._fields),
                    "items": [enc(v, f"{where}.{f}") for f, v in zip(t._fields, x)]}
        if t is dict:
            items = []
            for k, v in x.items():
                if type(k) is not str:
                    raise ExperimentError(f"a cached result's dict keys must be strings; got {k!r} at {where}.")
                items.append([k, enc(v, f"{where}[{k!r}]")])
            return {"dict": items}
        raise ExperimentError(
            f"a cached result cannot hold a {t.__module__}.{t.__qualname__} (at {where}): the disk caches keep "
            "None, bool, int, float, str, numpy arrays and scalars, and lists, tuples, the package's named tuples "
            "and str-keyed dicts of these."
        )

    return enc(value, "result"), arrays


def _package_class(t: type) -> bool:
    module = getattr(t, "__module__", "") or ""
    return module == "mmconcepts" or module.startswith("mmconcepts.")


def _named_tuple(spec: Any, fields: Any) -> Any:
    """The named tuple class ``spec`` (``"module:qualname"``), only if it is one of the package's."""
    if not isinstance(spec, str) or spec.count(":") != 1:
        raise CorruptEntry(f"bad named tuple {spec!r}")
    module, qualname = spec.split(":")
    if not (module == "mmconcepts" or module.startswith("mmconcepts.")) or not re.fullmatch(r"[\w.]+", module + qualname):
        raise CorruptEntry(f"named tuple {spec!r} is not one of the package's")
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise CorruptEntry(f"named tuple {spec!r} not found") from exc
    if not (isinstance(obj, type) and issubclass(obj, tuple) and list(getattr(obj, "_fields", ())) == fields):
        raise CorruptEntry(f"{spec!r} is no named tuple with fields {fields!r}")
    return obj


def decode(structure: Any, arrays: Any) -> Any:
    """Rebuild the value :func:`encode` split into ``structure`` and ``arrays`` (a mapping of name to array).

    Raises
    ------
    CorruptEntry
        If the structure is not one :func:`encode` writes, or names an array that is absent.
    """
    def array(name: Any) -> np.ndarray:
        if not isinstance(name, str) or name == _STRUCTURE or name not in arrays:
            raise CorruptEntry(f"no array {name!r}")
        a = arrays[name]
        if type(a) is not np.ndarray or a.dtype.hasobject:
            raise CorruptEntry(f"array {name!r} is no plain array")
        return a

    def dec(x: Any) -> Any:
        if x is None or type(x) in (bool, int, float, str):
            return x
        if type(x) is not dict or len(x) not in (1, 3):
            raise CorruptEntry(f"unexpected node {str(x)[:60]!r}")
        (tag, body), *_ = x.items()
        if tag == "namedtuple" and len(x) == 3:
            cls = _named_tuple(body, x.get("fields"))
            items = x.get("items")
            if type(items) is not list or len(items) != len(cls._fields):
                raise CorruptEntry("bad named tuple items")
            return cls._make(dec(v) for v in items)
        if len(x) != 1:
            raise CorruptEntry(f"unexpected node {str(x)[:60]!r}")
        if tag == "array":
            return array(body)
        if tag == "nan":
            try:
                value = struct.unpack("<d", bytes.fromhex(body))[0]
            except (TypeError, ValueError, struct.error) as exc:
                raise CorruptEntry("bad NaN") from exc
            if value == value:
                raise CorruptEntry("a NaN that is a number")
            return value
        if tag == "scalar":
            a = array(body)
            if a.ndim != 0:
                raise CorruptEntry("a scalar that is no 0-d array")
            return a[()]
        if tag in ("list", "tuple"):
            if type(body) is not list:
                raise CorruptEntry(f"bad {tag}")
            items = [dec(v) for v in body]
            return items if tag == "list" else tuple(items)
        if tag == "dict":
            if type(body) is not list:
                raise CorruptEntry("bad dict")
            out = {}
            for pair in body:
                if type(pair) is not list or len(pair) != 2 or type(pair[0]) is not str:
                    raise CorruptEntry("bad dict item")
                out[pair[0]] = dec(pair[1])
            return out
        raise CorruptEntry(f"unknown tag {tag!r}")

    return dec(structure)


# --------------------------------------------------------------------------- files


def write_entry(path: Path, value: Any, key: str) -> None:
    """Write ``value`` as the entry ``path`` (atomically), recording ``key`` in it."""
    structure, arrays = encode(value)
    text = json.dumps({"format": FORMAT, "key": key, "value": structure}, allow_nan=True, ensure_ascii=True)
    members: dict[str, np.ndarray] = {_STRUCTURE: np.frombuffer(text.encode("ascii"), dtype=np.uint8)}
    members.update(arrays)
    with atomic_path(path, suffix=".tmp.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **members)  # type: ignore[arg-type]  # savez takes arrays as keyword arguments
            fh.flush()
            os.fsync(fh.fileno())


def read_entry(path: Path, key: str) -> Any:
    """The value of the entry ``path``, or :data:`MISSING` if there is none.

    Never unpickles: the file must be a zip archive of ``.npy`` members (read with
    ``allow_pickle=False``) whose structure member is JSON in :data:`FORMAT` for ``key``.

    Raises
    ------
    CorruptEntry
        If the file exists but is not such an entry.
    """
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        return MISSING
    except OSError as exc:
        raise CorruptEntry(f"cannot open: {exc}") from exc
    with fh:
        if fh.read(4) != _ZIP_MAGIC:
            raise CorruptEntry("not an npz archive")
        fh.seek(0)
        try:
            with np.load(fh, allow_pickle=False) as npz:
                if _STRUCTURE not in npz.files:
                    raise CorruptEntry("no structure")
                raw = npz[_STRUCTURE]
                if raw.dtype != np.uint8 or raw.ndim != 1:
                    raise CorruptEntry("bad structure member")
                doc = json.loads(raw.tobytes().decode("ascii"))
                if type(doc) is not dict or doc.get("format") != FORMAT:
                    raise CorruptEntry("not in the format " + FORMAT)
                if doc.get("key") != key:
                    raise CorruptEntry("an entry of another key")
                arrays = {name: npz[name] for name in npz.files if name != _STRUCTURE}
                return decode(doc.get("value"), arrays)
        except CorruptEntry:
            raise
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, UnicodeDecodeError, RecursionError,
                NotImplementedError, OverflowError, MemoryError) as exc:
            raise CorruptEntry(f"{type(exc).__name__}: {exc}") from exc
