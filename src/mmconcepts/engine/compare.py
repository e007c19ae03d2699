"""Compare two runs' result records: every metric, interval, sample and verdict.

A change of the code that should not change the science (a refactoring, a faster kernel that
computes the same numbers) is checked by running the same experiments before and after it and
comparing the records with :func:`compare_records`: it lists every metric, interval, sample,
split, unit and claim field that differs, and nothing else. Wall-clock measurements (metric
names matching :data:`CLOCK_PATTERNS`) differ from run to run and are left out.

``mmconcepts compare OLD NEW`` is the command-line form (exit status 1 when the runs differ).
"""

from __future__ import annotations

import fnmatch
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ExperimentError
from .outputs import load_record

__all__ = ["CLOCK_PATTERNS", "Difference", "compare_records", "format_differences"]

#: ``fnmatch`` patterns of metric names that measure wall-clock time (they differ between runs).
CLOCK_PATTERNS: tuple[str, ...] = ("*time*", "*seconds*", "*ms_per_query*")

#: The record fields compared as name -> value maps (names matching the clock patterns are left out).
_NAMED_FIELDS = ("metrics", "intervals", "samples", "sample_units", "units", "split_groups")

#: The claim fields compared, claim by claim (claims are matched by their text).
_CLAIM_FIELDS = ("kind", "source", "holds", "verdict", "tests", "scope", "ratio", "ratio_interval", "settings",
                 "detail")


@dataclass(frozen=True)
class Difference:
    """One difference between two runs.

    Attributes
    ----------
    record : str
        ``"<experiment> (<variant>)"``.
    where : str
        What differs: ``"metrics['16.svm.l_full']"``, ``"claim 'text...' verdict"``, ``"record"``.
    old, new : object
        The two values (``None`` where one run does not have it).
    """

    record: str
    where: str
    old: Any
    new: Any

    def __str__(self) -> str:
        return f"{self.record}: {self.where}: {_short(self.old)} -> {_short(self.new)}"


def _short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _same(a: Any, b: Any, rtol: float) -> bool:
    """Equal values, nested, with floats equal within ``rtol`` (NaN equals NaN)."""
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a == b and type(a) is type(b)
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        fa, fb = float(a), float(b)
        if math.isnan(fa) or math.isnan(fb):
            return math.isnan(fa) and math.isnan(fb)
        if rtol == 0.0:
            return fa == fb
        return math.isclose(fa, fb, rel_tol=rtol, abs_tol=0.0)
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_same(a[k], b[k], rtol) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y, rtol) for x, y in zip(a, b))
    return bool(a == b)


def _records(folder: Path, ids: Sequence[str] | None) -> dict[str, dict[str, Any]]:
    if not folder.is_dir():
        raise ExperimentError(f"results folder {str(folder)!r} does not exist; expected the output folder of a run.")
    out: dict[str, dict[str, Any]] = {}
    for path in sorted(folder.glob("*.json")):
        loaded = load_record(path)
        if loaded is None:
            continue  # not a result record (a report's side file, a config)
        record = loaded.to_dict()
        if ids is not None and record["experiment"] not in ids:
            continue
        out[f"{record['experiment']} ({record.get('variant') or 'synthetic'})"] = record
    return out


def _compare_one(name: str, old: Mapping[str, Any], new: Mapping[str, Any], rtol: float,
                 ignore: Sequence[str]) -> Iterable[Difference]:
    if old.get("status") != new.get("status"):
        yield Difference(name, "status", old.get("status"), new.get("status"))
    for field in _NAMED_FIELDS:
        a, b = old.get(field) or {}, new.get(field) or {}
        for key in sorted(set(a) | set(b)):
            if any(fnmatch.fnmatchcase(key, p) for p in ignore):
                continue
            if not _same(a.get(key), b.get(key), rtol):
                yield Difference(name, f"{field}[{key!r}]", a.get(key), b.get(key))
    claims_a = {c["text"]: c for c in old.get("claims") or []}
    claims_b = {c["text"]: c for c in new.get("claims") or []}
    for text in sorted(set(claims_a) | set(claims_b)):
        a, b = claims_a.get(text), claims_b.get(text)
        label = f"claim {_short(text, 60)}"
        if a is None or b is None:
            yield Difference(name, label, a and a.get("verdict"), b and b.get("verdict"))
            continue
        for field in _CLAIM_FIELDS:
            if not _same(a.get(field), b.get(field), rtol):
                yield Difference(name, f"{label} {field}", a.get(field), b.get(field))


def compare_records(old_dir: str | os.PathLike[str], new_dir: str | os.PathLike[str], *,
                    ids: Sequence[str] | None = None, rtol: float = 0.0,
                    ignore: Sequence[str] = CLOCK_PATTERNS) -> list[Difference]:
    """Every difference between the result records of two runs.

    Records are matched by experiment and variant (real or generated data); a record in one
    run only is a difference. Compared: the status, every metric, interval, sample, sample
    unit, unit and split description (names matching ``ignore`` left out), and every claim's
    kind, source, verdict, tests, ratio, settings and detail (claims matched by their text).
    Not compared: the code fingerprint, timestamps, elapsed time, figures and notes.

    Parameters
    ----------
    old_dir, new_dir : path-like
        Two results folders (the ``--output`` of two runs).
    ids : sequence of str, optional
        Compare only these experiments.
    rtol : float, default=0.0
        Relative tolerance of numbers (0: equal to the bit; NaN equals NaN).
    ignore : sequence of str, default=CLOCK_PATTERNS
        ``fnmatch`` patterns of names left out of the named fields.

    Returns
    -------
    list of Difference
        Empty when the two runs agree.

    Raises
    ------
    ExperimentError
        If a folder does not exist or holds no result record of ``ids``.
    """
    old, new = _records(Path(old_dir), ids), _records(Path(new_dir), ids)
    if not old and not new:
        raise ExperimentError(f"no result record{' of ' + ', '.join(ids) if ids else ''} in {str(old_dir)!r} or "
                              f"{str(new_dir)!r}; expected the output folders of two runs of the same experiments.")
    diffs: list[Difference] = []
    for name in sorted(set(old) | set(new)):
        if name not in old or name not in new:
            diffs.append(Difference(name, "record", "present" if name in old else None,
                                    "present" if name in new else None))
            continue
        diffs.extend(_compare_one(name, old[name], new[name], rtol, ignore))
    return diffs


def format_differences(diffs: Sequence[Difference], limit: int = 50) -> str:
    """The differences one per line (at most ``limit``, then how many more), or that there are none."""
    if not diffs:
        return "the two runs agree: every metric, interval, sample and verdict is the same"
    lines = [str(d) for d in diffs[:limit]]
    if len(diffs) > limit:
        lines.append(f"... and {len(diffs) - limit} more")
    return "\n".join([f"{len(diffs)} difference(s):", *lines])
