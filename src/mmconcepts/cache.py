"""The data/cache folder: what it holds, and clearing it (``mmconcepts cache``).

The folder (:func:`mmconcepts._paths.data_home`: ``$MMCONCEPTS_DATA``, else
``$XDG_CACHE_HOME/mmconcepts``, else ``~/.cache/mmconcepts``) holds generated data sets (the
synthetic caregiver corpus, the synthetic dancers) and the experiments' caches (fold
results, MFCC, image features), one top-level folder each, all made by
:mod:`mmconcepts._store`, and the lock files of what is being made, in ``.locks`` (not an
entry). Everything in it can be recomputed; clearing it only costs time.
"""

from __future__ import annotations

import os
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from ._paths import data_home
from ._store import LOCKS
from .errors import ParameterError

__all__ = ["CacheEntry", "LOCKS", "cache_entries", "clear_cache", "parse_age"]

_AGE = re.compile(r"(\d+(?:\.\d*)?|\.\d+)\s*([smhdw])")
_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86400, "w": 7 * 86400}


@dataclass(frozen=True)
class CacheEntry:
    """One top-level item of the cache folder.

    Attributes
    ----------
    name : str
        Its name (a folder such as ``ch3-folds`` or ``caregiver-synth-...``, or a file).
    n_files : int
        Regular files under it (symbolic links are not followed nor counted).
    n_bytes : int
        Their total size in bytes.
    newest : float or None
        The newest modification time among them (seconds since the epoch); None when empty.
    """

    name: str
    n_files: int
    n_bytes: int
    newest: float | None


def parse_age(text: str) -> float:
    """Seconds in an age such as ``"30m"``, ``"12h"``, ``"7d"``, ``"2w"`` or ``"1d12h"``.

    Units: s, m (minutes), h, d, w. Raises :class:`~mmconcepts.errors.ParameterError` for
    anything else.
    """
    compact = str(text).replace(" ", "")
    parts = _AGE.findall(compact)
    if not compact or "".join(n + u for n, u in parts) != compact:
        raise ParameterError(
            f"an age must be numbers with units s, m, h, d or w, e.g. '12h', '7d' or '1d12h'; got {text!r}."
        )
    return sum(float(n) * _UNITS[u] for n, u in parts)


def _files(path: Path):
    if path.is_symlink() or path.is_file():
        if path.is_file() and not path.is_symlink():
            yield path
        return
    for dirpath, _dirnames, filenames in os.walk(path):  # os.walk does not follow links to folders
        for f in filenames:
            p = Path(dirpath) / f
            if not p.is_symlink():
                yield p


def cache_entries(path: str | os.PathLike[str] | None = None) -> list[CacheEntry]:
    """What the cache folder holds, one entry per top-level item, sorted by name.

    Parameters
    ----------
    path : str or path-like, optional
        The folder (default: :func:`~mmconcepts._paths.data_home`). A missing folder holds nothing.
    """
    home = data_home(path, create=False)
    if not home.is_dir():
        return []
    out = []
    for item in sorted(home.iterdir()):
        if item.name == LOCKS:  # the empty lock files of what is being made, not data
            continue
        sizes = [(p.stat().st_size, p.stat().st_mtime) for p in _files(item)]
        out.append(CacheEntry(item.name, len(sizes), sum(s for s, _ in sizes), max((m for _, m in sizes), default=None)))
    return out


def clear_cache(path: str | os.PathLike[str] | None = None, *, older_than: float | None = None,
                names: list[str] | None = None, now: float | None = None) -> tuple[int, int]:
    """Delete cached files; return how many files and bytes were removed.

    Parameters
    ----------
    path : str or path-like, optional
        The folder (default: :func:`~mmconcepts._paths.data_home`).
    older_than : float, optional
        Only files last modified more than this many seconds ago (see :func:`parse_age`);
        folders left empty are removed too. Default: everything.
    names : list of str, optional
        Only these top-level items (see :func:`cache_entries`); an unknown name is an error.
    now : float, optional
        The reference time (default: ``time.time()``).
    """
    home = data_home(path, create=False)
    if older_than is not None and not older_than >= 0:
        raise ParameterError(f"older_than must be a non-negative number of seconds; got {older_than!r}.")
    if not home.is_dir():
        if names:
            raise ParameterError(f"no cache folder at {home}, so nothing named {', '.join(names)}.")
        return 0, 0
    items = sorted(home.iterdir())
    if names is not None:
        known = {p.name for p in items}
        unknown = sorted(set(names) - known)
        if unknown:
            raise ParameterError(
                f"{home} holds no {', '.join(map(repr, unknown))}; it holds: {', '.join(sorted(known)) or 'nothing'}. "
                "See `mmconcepts cache list`."
            )
        items = [p for p in items if p.name in set(names)]
    limit = None if older_than is None else (time.time() if now is None else now) - older_than
    n_files = n_bytes = 0
    for item in items:
        for f in list(_files(item)):
            st = f.stat()
            if limit is None or st.st_mtime < limit:
                f.unlink()
                n_files += 1
                n_bytes += st.st_size
        if item.is_dir() and not item.is_symlink():
            if limit is None:
                shutil.rmtree(item)
            else:
                for dirpath, _dirs, _names in os.walk(item, topdown=False):  # deepest first
                    if not os.listdir(dirpath):
                        os.rmdir(dirpath)
        elif item.is_symlink() and limit is None:
            item.unlink()
    return n_files, n_bytes
