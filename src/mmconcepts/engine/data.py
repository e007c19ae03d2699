"""Which real data sets a run uses: ``--data NAME=PATH`` arguments checked, a data root resolved per
experiment, and a set's signature (part of a record's up-to-date key)."""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from ..errors import ExperimentError
from .experiment import Experiment
from .registry import all_experiments


__all__ = ["VARIANTS", "parse_data_args", "check_data", "resolve_data", "data_signature"]

logger = logging.getLogger("mmconcepts.experiments")


#: The data variants of a run: on the real sets found, or on generated stand-ins.
VARIANTS = ("real", "synthetic")


_DATA_NAME = re.compile(r"[A-Za-z0-9_.-]+\Z")


def parse_data_args(items: Iterable[str] | None) -> dict[str, Path]:
    """Parse ``--data NAME=PATH`` arguments into ``{name: path}``.

    Raises
    ------
    ExperimentError
        On an item without ``=``, an empty or malformed name, an empty path, or a name
        given twice.
    """
    out: dict[str, Path] = {}
    for item in items or ():
        name, sep, path = str(item).partition("=")
        name = name.strip()
        if not sep or not name or not path:
            raise ExperimentError(f"--data expects NAME=PATH (e.g. choreo1=/data/choreo1); got {item!r}.")
        if not _DATA_NAME.fullmatch(name):
            raise ExperimentError(f"--data {item!r}: the name {name!r} must be a word ([A-Za-z0-9_.-]).")
        if name in out:
            raise ExperimentError(f"--data {name}=... is given twice ({out[name]} and {path}); give each data set once.")
        out[name] = Path(path).expanduser()
    return out


def check_data(
    data: Mapping[str, str | os.PathLike[str]] | None, experiments: Sequence[Experiment] | None = None
) -> dict[str, Path]:
    """Validate ``--data`` names and paths; return ``{name: absolute path}``.

    Parameters
    ----------
    data : mapping of str to path, optional
    experiments : sequence of Experiment, optional
        Experiments whose declared data-set names are accepted without consulting the
        registry; any other name must be declared by some registered experiment.

    Raises
    ------
    ExperimentError
        If no experiment declares a name, or a path does not exist (both are named).
    """
    if not data:
        return {}
    if isinstance(data, (str, bytes)) or not isinstance(data, Mapping):
        raise ExperimentError(f"data must be a mapping of data-set names to paths; got {type(data).__name__}.")
    from ..datasets import DATASETS

    resolved = {str(name): Path(path).expanduser() for name, path in data.items()}
    declared = {n for exp in experiments or () for n in exp.datasets} | set(DATASETS)
    if any(name not in declared for name in resolved):
        registered = all_experiments()
        declared |= {n for exp in registered for n in exp.datasets}
    unknown = sorted(name for name in resolved if name not in declared)
    if unknown:
        known = ", ".join(sorted(declared)) or "none"
        raise ExperimentError(
            f"--data {unknown[0]}=...: no experiment uses a data set named {unknown[0]!r}. "
            f"Known data-set names: {known} (see `mmconcepts list`)."
        )
    for name, path in resolved.items():
        if not path.exists():
            raise ExperimentError(f"--data {name}={path}: the path {str(path)!r} does not exist.")
    return {name: path.resolve() for name, path in resolved.items()}


def resolve_data(
    exp: Experiment,
    data: Mapping[str, str | os.PathLike[str]] | None = None,
    data_root: str | os.PathLike[str] | None = None,
) -> dict[str, Path]:
    """The real data sets ``exp`` runs on: those of its ``datasets`` found under the data
    root, overridden by the ones given explicitly (``--data NAME=PATH``).

    Parameters
    ----------
    exp : Experiment
    data : mapping of str to path, optional
        Explicit sets; names the experiment does not declare are ignored.
    data_root : path, optional
        The data root (default: ``$MMCONCEPTS_DATA_ROOT``; none if unset). See
        :func:`mmconcepts.datasets.data_root`.

    Returns
    -------
    dict of str to Path
        ``{name: absolute folder}`` for the sets found, in the order of ``exp.datasets``.
    """
    from ..datasets import DATASETS, find_datasets
    from ..datasets import data_root as _data_root

    root = _data_root(data_root)
    known = [name for name in exp.datasets if name in DATASETS]
    found = find_datasets(root, names=known) if root is not None and known else {}
    given = {str(k): Path(v).expanduser().resolve() for k, v in (data or {}).items() if str(k) in exp.datasets}
    merged = {**{k: Path(v).resolve() for k, v in found.items()}, **given}
    return {name: merged[name] for name in exp.datasets if name in merged}


def data_signature(path: str | os.PathLike[str]) -> str:
    """A cheap signature of a data set's contents: number of files, total bytes, newest change.

    Part of a result's up-to-date key, so that adding, repairing or re-fetching recordings
    recomputes the result even though the set's folder is the same.
    """
    path = Path(path)
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    n = size = newest = 0
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        n, size, newest = n + 1, size + st.st_size, max(newest, st.st_mtime_ns)
    return f"{n} files, {size} bytes, newest {newest}"
