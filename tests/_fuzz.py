"""Fuzzing harness: what a public entry point does with one generated input.

Each call is put in one of five outcomes:

- ``"typed error"``: an mmconcepts error (:class:`~mmconcepts.errors.MMConceptsError`, or
  a type the caller allows, e.g. :class:`FileNotFoundError` for a missing file) with a
  message;
- ``"good result"``: it returned, everything numeric in the result is finite, and the
  caller's ``check`` (the result is right, not just finite) passes;
- ``"silent bad output"``: it returned something non-finite or that fails ``check``;
- ``"untyped error"``: any other exception (IndexError, a bare ValueError from numpy...);
- ``"hang"``: it ran longer than ``timeout`` seconds (SIGALRM, main thread, Linux).

A fuzz test calls :func:`assert_typed_or_good` once per example. Every call is counted in
:data:`CENSUS`; with ``MMCONCEPTS_FUZZ_CENSUS=<file.json>`` set, the counts are written there
at the end of the session (``tests/conftest.py``). With ``MMCONCEPTS_FUZZ_COUNT_ONLY=1`` as
well, the assertion is *not* made, so a census run counts the outcomes of every example
instead of stopping at the first bad one (how the counts before a fix are taken)::

    MMCONCEPTS_FUZZ_CENSUS=census.json MMCONCEPTS_FUZZ_COUNT_ONLY=1 pytest -m fuzz

Each fuzz test runs ``examples(n)`` examples: ``n`` (a few hundred) in CI, ``10 n`` with
``MMCONCEPTS_FUZZ_LONG=1`` (the long run). CI runs are derandomized (the same examples on
every run, so a rare case cannot fail one CI run and pass the next); a long run draws new
examples each time.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import signal
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from hypothesis import settings

from mmconcepts.errors import MMConceptsError

TYPED = "typed error"
GOOD = "good result"
SILENT_BAD = "silent bad output"
UNTYPED = "untyped error"
HANG = "hang"
OUTCOMES = (TYPED, GOOD, SILENT_BAD, UNTYPED, HANG)

#: entry point name -> Counter of outcomes, over the whole test session.
CENSUS: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
#: entry point name -> a few examples of bad outcomes (outcome, detail), for the census file.
BAD_EXAMPLES: dict[str, list[tuple[str, str]]] = collections.defaultdict(list)

CENSUS_FILE = os.environ.get("MMCONCEPTS_FUZZ_CENSUS")
COUNT_ONLY = os.environ.get("MMCONCEPTS_FUZZ_COUNT_ONLY") == "1"

_LONG = os.environ.get("MMCONCEPTS_FUZZ_LONG") == "1"


def examples(n: int) -> int:
    """``n`` examples in CI, ``10 n`` in a long run (``MMCONCEPTS_FUZZ_LONG=1``)."""
    return 10 * n if _LONG else n


def fuzz_settings(n: int, **kw: Any) -> settings:
    """Hypothesis settings of a fuzz test: ``examples(n)`` examples, no deadline, no example database,
    derandomized except in a long run."""
    kw.setdefault("derandomize", not _LONG)
    return settings(max_examples=examples(n), deadline=None, database=None, **kw)


class _Hang(BaseException):
    """Raised by the alarm; a BaseException so ``except Exception`` in the code under test cannot swallow it."""


@contextlib.contextmanager
def _deadline(seconds: float) -> Iterator[None]:
    def handler(signum, frame):
        raise _Hang(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def all_finite(obj: Any, _depth: int = 0) -> bool:
    """True when every number in ``obj`` (arrays, sparse matrices, scalars, nested containers,
    estimators' fitted ``*_`` attributes are not inspected) is finite."""
    if _depth > 20:
        return True
    if obj is None or isinstance(obj, (str, bytes, bool)):
        return True
    if isinstance(obj, (int, np.integer)):
        return True
    if isinstance(obj, (float, np.floating)):
        return math.isfinite(float(obj))
    if isinstance(obj, complex):
        return math.isfinite(obj.real) and math.isfinite(obj.imag)
    if hasattr(obj, "tocsr") and hasattr(obj, "data"):  # scipy.sparse
        return bool(np.all(np.isfinite(obj.data)))
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc":
            return bool(np.all(np.isfinite(obj)))
        if obj.dtype.kind == "O":
            return all(all_finite(x, _depth + 1) for x in obj.ravel())
        return True
    if isinstance(obj, dict):
        return all(all_finite(v, _depth + 1) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return all(all_finite(v, _depth + 1) for v in obj)
    return True


def outcome(
    name: str,
    call: Callable[[], Any],
    *,
    check: Callable[[Any], bool] | None = None,
    timeout: float = 20.0,
    typed: tuple[type[BaseException], ...] = (),
) -> tuple[str, str]:
    """Run ``call()`` and classify it (see the module docstring); count it in :data:`CENSUS`.

    Returns ``(outcome, detail)``; ``detail`` names the exception or what failed.
    """
    detail = ""
    try:
        with _deadline(timeout):
            result = call()
    except _Hang as exc:
        out, detail = HANG, str(exc)
    except (MMConceptsError, *typed) as exc:
        out, detail = (TYPED, repr(exc)) if str(exc).strip() else (UNTYPED, f"{type(exc).__name__} without a message")
    except Exception as exc:  # noqa: BLE001 - classifying every exception is the point
        out, detail = UNTYPED, f"{type(exc).__name__}: {exc}"
    else:
        if not all_finite(result):
            out, detail = SILENT_BAD, "non-finite output"
        elif check is not None and not check(result):
            out, detail = SILENT_BAD, "output fails the check"
        else:
            out = GOOD
    CENSUS[name][out] += 1
    if out not in (TYPED, GOOD) and len(BAD_EXAMPLES[name]) < 5:
        BAD_EXAMPLES[name].append((out, detail[:300]))
    return out, detail


def assert_typed_or_good(name: str, call: Callable[[], Any], **kw: Any) -> str:
    """:func:`outcome`, then assert it is a typed error or a good result (unless ``MMCONCEPTS_FUZZ_COUNT_ONLY=1``)."""
    out, detail = outcome(name, call, **kw)
    if not COUNT_ONLY:
        assert out in (TYPED, GOOD), f"{name}: {out}: {detail}"
    return out


def write_census(path: str) -> None:
    """Write :data:`CENSUS` (and a few bad examples) to ``path`` as JSON."""
    import json

    totals = collections.Counter()
    for counts in CENSUS.values():
        totals.update(counts)
    payload = {
        "totals": {k: totals.get(k, 0) for k in OUTCOMES} | {"cases": sum(totals.values())},
        "entry_points": {name: {k: c.get(k, 0) for k in OUTCOMES} for name, c in sorted(CENSUS.items())},
        "bad_examples": dict(BAD_EXAMPLES),
    }
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(payload, fh, indent=1)


class PickleBomb:
    """An object whose unpickling would run code (here it only sets ``PickleBomb.ran``).

    Planted in saved files by the fuzz tests: loading must never unpickle, so ``ran`` stays False.
    """

    ran = False

    def __reduce__(self):
        return (PickleBomb._run, ())

    @staticmethod
    def _run():
        PickleBomb.ran = True
        return "ran"
