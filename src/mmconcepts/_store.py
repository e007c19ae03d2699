"""The package's disk caches: one key scheme, one lock place, one codec, one atomic writer (internal).

What the package keeps in a cache folder (the data/cache folder of
:func:`mmconcepts._paths.data_home`, or the ``cache_dir`` of an experiment run) is of two
kinds, both made here:

- *generated folders* (:func:`generated_folder`): a data set a generator writes (the
  synthetic caregiver corpus, the synthetic dancers' choreographies, composed utterances);
- *entries* (:func:`write_entry`, :func:`read_entry`): one computed value in one ``.npz``
  file of the codec (:mod:`mmconcepts._codec`, which saved models use too); the
  experiments' cached calls (:mod:`mmconcepts.engine.cache`) and the figure data of a run
  are kept so.

Code
    What a kept thing depends on besides its parameters is the *code* that made it. By
    default that is :func:`~mmconcepts._fingerprint.code_fingerprint`: any change of the
    package's source, or of a dependency's version, makes the thing again. A generator whose
    output takes long to make names its own version instead (:func:`versioned`:
    ``"<generator>/v<N>"``, from its ``GENERATOR_VERSION``): the synthetic caregiver corpus
    (speech synthesis of thousands of utterances, minutes of work per speaker, which the
    fingerprint would redo after every edit anywhere in the package) and, under the same
    rule, the synthetic choreographies of :mod:`mmconcepts.motion.synthetic`. The price of a
    version is that it must be raised by hand whenever the generator's output changes; until
    it is, the data made by the earlier code is reused. Composed utterances (concatenations
    of recordings, made in moments) and the experiments' cached calls follow the fingerprint.

Keys
    :func:`cache_key` is the one key scheme: a digest (:func:`joblib.hash`, which pickles to
    hash and never unpickles) of :data:`KEY_SCHEME`, the code and the parts given (names,
    parameters, arrays). The engine's entries are named by it; a generated folder is named
    by its caller (a readable name, or :func:`cache_key` of what it holds) and records its
    *manifest* (the code and the parameters, JSON) in :data:`MANIFEST`: the folder is
    complete when that file holds the manifest asked for and the folder the files and
    bytes it lists.

Locks
    Whatever is made at ``<home>/<path>`` (``home`` being the cache folder) is made under the
    exclusive lock ``<home>/.locks/<path>.lock`` (:func:`store_lock`), so that processes
    sharing the cache folder (``reproduce --concurrent``, cluster workers) make it once: the
    others wait, then read it. The lock files stay in ``.locks`` (empty files), which
    ``mmconcepts cache list`` does not show as an entry.

Atomic writes
    A generated folder is built in a temporary sibling and renamed into place
    (:func:`mmconcepts._io.atomic_dir`); an entry is written beside its file and renamed
    (:func:`mmconcepts._io.atomic_path`). A failure leaves nothing half-written, and the
    leftovers of a killed process are removed by the next build of the same folder.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from ._codec import MARK, CorruptFile, decode, encode, npz_bytes, read_npz, write_npz
from ._fingerprint import code_fingerprint
from ._io import atomic_dir, atomic_write, folder_lock, leftover_dirs
from .errors import ParameterError

__all__ = ["ENTRY_FORMAT", "KEY_SCHEME", "LOCKS", "MANIFEST", "MISSING", "cache_key", "entry_bytes", "generated_folder",
           "read_entry", "remove_stale_temporaries", "store_lock", "versioned", "write_entry"]

#: Named in every key and manifest; raised when the scheme changes, which makes everything again.
KEY_SCHEME = "mmconcepts-store/1"
#: The folder of a cache folder that holds the lock files.
LOCKS = ".locks"
#: The file of a generated folder that records what it holds.
MANIFEST = "manifest.json"
#: The format name in every entry; an entry in another format is computed again.
ENTRY_FORMAT = "mmconcepts-cache/2"
#: What :func:`read_entry` returns when there is no entry.
MISSING = object()


# --------------------------------------------------------------------------- keys and locks


def versioned(generator: str, version: int) -> str:
    """The code of a generator pinned by a version number: ``"<generator>/v<version>"``."""
    return f"{generator}/v{int(version)}"


def cache_key(*parts: Any, code: str | None = None) -> str:
    """The key of a kept value or folder: a hex digest of the key scheme, the code and ``parts``.

    Parameters
    ----------
    *parts : object
        What the kept thing is a function of: names, parameters, arrays (anything
        :func:`joblib.hash` hashes).
    code : str, optional
        The code that makes it (default: :func:`~mmconcepts._fingerprint.code_fingerprint`;
        a generator's :func:`versioned` code for the generators named in the module docstring).
    """
    import joblib

    return str(joblib.hash([KEY_SCHEME, code_fingerprint() if code is None else str(code), list(parts)]))


def _relative(home: Path, path: Path) -> Path:
    home_abs, path_abs = Path(os.path.abspath(home)), Path(os.path.abspath(path))
    try:
        rel = path_abs.relative_to(home_abs)
    except ValueError:
        raise ParameterError(f"{path} is not inside the cache folder {home}; pass the folder that holds it.") from None
    if not rel.parts:
        raise ParameterError(f"{path} is the cache folder itself; name something inside it.")
    return rel


@contextlib.contextmanager
def store_lock(home: str | os.PathLike[str], path: str | os.PathLike[str]) -> Iterator[None]:
    """Hold the exclusive lock of ``path`` (inside the cache folder ``home``) for the block.

    The lock file is ``<home>/.locks/<path relative to home>.lock``
    (:func:`mmconcepts._io.folder_lock`: advisory, released when the block ends or the process
    dies).

    Raises
    ------
    ParameterError
        If ``path`` is not inside ``home``.
    OSError
        If the lock file cannot be made (a cache folder that cannot be written).
    """
    rel = _relative(Path(home), Path(path))
    where = Path(home) / LOCKS / rel.parent
    with folder_lock(where, f"{rel.name}.lock"):
        yield


# --------------------------------------------------------------------------- generated folders


def _manifest(manifest: Mapping[str, Any], code: str | None) -> dict[str, Any]:
    try:
        params = json.loads(json.dumps(dict(manifest), sort_keys=True, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"a manifest must be JSON (str keys; strings, numbers, lists, dicts); {exc}.") from None
    return {"scheme": KEY_SCHEME, "code": code_fingerprint() if code is None else str(code), "manifest": params}


def _contents(folder: Path) -> tuple[int, int]:
    """Regular files below ``folder`` (the manifest left out) and their bytes."""
    n = size = 0
    for dirpath, _dirs, files in os.walk(folder):
        for name in files:
            if dirpath == str(folder) and name == MANIFEST:
                continue
            n += 1
            size += os.stat(os.path.join(dirpath, name)).st_size
    return n, size


def _complete(root: Path, want: dict[str, Any]) -> bool:
    try:
        have = json.loads((root / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if type(have) is not dict or {k: have.get(k) for k in want} != want:
        return False
    try:
        return [have.get("files"), have.get("bytes")] == list(_contents(root))
    except OSError:  # removed while being counted
        return False


def generated_folder(root: str | os.PathLike[str], manifest: Mapping[str, Any], build: Callable[[Path], object], *,
                     code: str | None = None, home: str | os.PathLike[str] | None = None,
                     force: bool = False) -> Path:
    """The folder ``root`` holding what ``build`` writes for ``manifest``, built once.

    When ``root`` is complete for this manifest and code (its :data:`MANIFEST` says so and
    its files are all there), nothing is done. Otherwise, under the lock of ``root``
    (:func:`store_lock`), ``build(tmp)`` fills an empty temporary folder beside ``root``, the
    manifest is written into it, and it replaces ``root`` (an older content included). A
    failure in ``build`` leaves ``root`` as it was and no temporary folder; one left by a
    killed process is removed by the next build. A second process asking for the same folder
    meanwhile waits for the first, then finds it complete.

    Parameters
    ----------
    root : path-like
        The folder to make.
    manifest : mapping
        What the folder holds, as JSON (the parameters of the generator): a folder made for
        another manifest is made again.
    build : callable
        ``build(folder)`` writes the content into the empty ``folder`` (its return value is
        ignored).
    code : str, optional
        The code that makes it (default: :func:`~mmconcepts._fingerprint.code_fingerprint`;
        see :func:`versioned`).
    home : path-like, optional
        The cache folder ``root`` is in, whose ``.locks`` holds the lock (default: the
        parent of ``root``).
    force : bool, default=False
        Make it again even if it is complete.

    Returns
    -------
    pathlib.Path
        ``root``.
    """
    root = Path(root)
    home = root.parent if home is None else Path(home)
    want = _manifest(manifest, code)
    if not force and _complete(root, want):
        return root
    with store_lock(home, root):
        if not force and _complete(root, want):  # made by another process while this one waited
            return root
        for leftover in leftover_dirs(root):  # under the lock: a dead process' build
            shutil.rmtree(leftover, ignore_errors=True)
        with atomic_dir(root) as tmp:
            build(tmp)
            n_files, n_bytes = _contents(tmp)
            atomic_write(tmp / MANIFEST, json.dumps({**want, "files": n_files, "bytes": n_bytes}, indent=1,
                                                    sort_keys=True))
    return root


# --------------------------------------------------------------------------- entries


def _entry(value: Any, key: str) -> tuple[dict[str, Any], dict[str, Any]]:
    arrays: dict[str, Any] = {}
    structure = encode(value, arrays, where="result")
    return {"format": ENTRY_FORMAT, "key": key, "value": structure}, arrays


def write_entry(path: str | os.PathLike[str], value: Any, key: str) -> None:
    """Write ``value`` to the entry file ``path`` (atomically), recording ``key`` in it.

    Raises
    ------
    ParameterError
        If ``value`` holds something the codec does not store (see :mod:`mmconcepts._codec`).
    """
    write_npz(path, *_entry(value, key))


def entry_bytes(value: Any, key: str) -> bytes:
    """The bytes of the entry file :func:`write_entry` writes (for a file written later, read by :func:`read_entry`).

    Raises
    ------
    ParameterError
        If ``value`` holds something the codec does not store.
    """
    return npz_bytes(*_entry(value, key))


def read_entry(path: str | os.PathLike[str], key: str) -> Any:
    """The value of the entry file ``path`` written for ``key``, or :data:`MISSING` if there is none.

    Never unpickles (:func:`mmconcepts._codec.read_npz`). An entry of the previous format
    (:data:`ENTRY_FORMAT_V1`, the figure data of older runs) is read too.

    Raises
    ------
    CorruptFile
        If the file exists but is not an entry for ``key`` (torn, edited, planted).
    """
    try:
        header, npz = read_npz(path)
    except FileNotFoundError:
        return MISSING
    except OSError as exc:  # a folder in the way, no permission
        raise CorruptFile(f"{path}: cannot be read ({exc})") from None
    except CorruptFile as exc:
        try:
            header, npz = _read_v1(path)
        except CorruptFile:
            raise exc from None
    with npz:
        if header.get("format") not in (ENTRY_FORMAT, ENTRY_FORMAT_V1):
            raise CorruptFile(f"{path}: not in the format {ENTRY_FORMAT}")
        if header.get("key") != key:
            raise CorruptFile(f"{path}: an entry of another key")
        value = header.get("value")
        return decode(value if header["format"] == ENTRY_FORMAT else _from_v1(value), npz)


# The previous entry format: the structure as ASCII JSON bytes in the member ``__structure__``, its nodes
# one-key objects: {"array": name}, {"scalar": name}, {"nan": bits}, {"list": [...]}, {"tuple": [...]},
# {"dict": [[key, value], ...]}, {"namedtuple": "module:qualname", "fields": [...], "items": [...]}.

#: The format name of entries written before :data:`ENTRY_FORMAT`.
ENTRY_FORMAT_V1 = "mmconcepts-cache/1"
_V1_MEMBER = "__structure__"


def _read_v1(path: str | os.PathLike[str]) -> tuple[dict[str, Any], Any]:
    import numpy as np

    npz = None
    try:
        npz = np.load(path, allow_pickle=False)
        if _V1_MEMBER not in npz.files:
            raise CorruptFile(f"{path}: no header")
        raw = npz[_V1_MEMBER]
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise CorruptFile(f"{path}: a bad structure member")
        header = json.loads(raw.tobytes().decode("ascii"))
        if type(header) is not dict or header.get("format") != ENTRY_FORMAT_V1:
            raise CorruptFile(f"{path}: not in the format {ENTRY_FORMAT_V1}")
    except Exception as exc:  # noqa: BLE001 - torn or edited (see mmconcepts._codec.read_npz)
        if npz is not None:
            npz.close()
        raise exc if isinstance(exc, CorruptFile) else CorruptFile(f"{path}: {type(exc).__name__}: {exc}") from None
    return header, npz


def _from_v1(x: Any) -> Any:
    """The structure of :func:`mmconcepts._codec.encode` for a structure of the previous entry format."""
    if x is None or type(x) in (bool, int, float, str):
        return x
    if type(x) is not dict or not x:
        raise CorruptFile(f"unexpected node {str(x)[:60]!r}")
    (tag, body), *_ = x.items()
    if tag == "namedtuple" and len(x) == 3 and type(x.get("items")) is list:
        return {MARK: "namedtuple", "class": body, "fields": x.get("fields"),
                "items": [_from_v1(v) for v in x["items"]]}
    if len(x) != 1:
        raise CorruptFile(f"unexpected node {str(x)[:60]!r}")
    if tag in ("array", "scalar"):
        if body == _V1_MEMBER:
            raise CorruptFile("the structure is no array")
        return {MARK: tag, "entry": body}
    if tag == "nan":
        return {MARK: "float", "value": "nan", "bits": body}
    if tag in ("list", "tuple") and type(body) is list:
        items = [_from_v1(v) for v in body]
        return items if tag == "list" else {MARK: "tuple", "items": items}
    if tag == "dict" and type(body) is list:
        if not all(type(p) is list and len(p) == 2 and type(p[0]) is str for p in body):
            raise CorruptFile("a bad dict item")
        return {MARK: "dict", "items": [[k, _from_v1(v)] for k, v in body]}
    raise CorruptFile(f"unknown tag {str(tag)[:40]!r}")


def remove_stale_temporaries(folder: str | os.PathLike[str], age: float = 3600.0) -> None:
    """Delete the temporary files of entries whose writer was killed (older than ``age`` seconds)."""
    try:
        with os.scandir(folder) as it:
            for entry in it:
                if entry.name.startswith(".") and entry.name.endswith(".tmp.npz") and entry.is_file():
                    with contextlib.suppress(OSError):
                        if time.time() - entry.stat().st_mtime > age:
                            os.unlink(entry.path)
    except OSError:  # no folder yet
        pass
