"""The tests behind a verdict: a claim's comparisons decided beyond the noise of their units
(:func:`claim_verdict`), and a magnitude set beside the thesis' number (:func:`magnitude_verdict`).

The units, intervals and verdict words are :mod:`mmconcepts.engine.uncertainty`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ExperimentError
from .rules import Comparison, parse_rule
from .uncertainty import (
    INDEPENDENT,
    LEVEL,
    MAX_RATIO_SPREAD,
    MIN_UNITS,
    SampleUnit,
    finite_samples,
    metric_interval,
    t_quantile,
)

__all__ = ["ComparisonTest", "Verdict", "MagnitudeVerdict", "claim_verdict", "magnitude_verdict"]


@dataclass(frozen=True)
class ComparisonTest:
    """How one comparison of a rule was decided.

    Attributes
    ----------
    comparison : str
        The comparison (``a > b``).
    margin : float or None
        Its margin on the reported numbers (positive when it holds).
    interval : (float, float) or None
        The margin's interval at :data:`LEVEL` (None without samples).
    decided : bool or None
        True (holds beyond the interval), False (fails beyond it), None (undecided).
    n_units : int
        The fewest units behind it (0 without samples).
    df : float or None
        The t's degrees of freedom.
    note : str
        Why it is undecided when not for its interval ("fewer than 5 units"), or "no spread".
    """

    comparison: str
    margin: float | None
    interval: tuple[float, float] | None
    decided: bool | None
    n_units: int = 0
    df: float | None = None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """As stored in a claim of the record."""
        return {"comparison": self.comparison, "margin": self.margin,
                "interval": None if self.interval is None else list(self.interval),
                "decided": self.decided, "n_units": self.n_units, "df": self.df, "note": self.note}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ComparisonTest:
        """Read one back from a record."""
        interval = d.get("interval")
        return cls(str(d.get("comparison", "")), d.get("margin"),
                   None if not interval else (float(interval[0]), float(interval[1])),
                   d.get("decided"), int(d.get("n_units") or 0), d.get("df"), str(d.get("note", "")))


@dataclass(frozen=True)
class Verdict:
    """A rule's verdict.

    Attributes
    ----------
    holds : bool or None
        The rule on the reported numbers (None: not evaluated).
    verdict : str
        ``"holds"``, ``"fails"``, ``"inconclusive"`` or ``"not evaluated"``.
    basis : str
        How it was decided, for the report.
    tests : tuple of ComparisonTest
        One per comparison of the rule: its margin and interval.
    scope : str
        ``"within one fit"`` when a sample behind it is of a within-fit unit, else ``""``.
    support : None
        Kept for records of earlier versions (the share of bootstrap replicates); None now.
    """

    holds: bool | None
    verdict: str
    basis: str
    tests: tuple[ComparisonTest, ...] = ()
    scope: str = ""
    support: float | None = None


def _unit_of(name: str, units: Mapping[str, str] | None, size: int) -> tuple[str, int]:
    return ((units or {}).get(name, ""), size)


def _aligned_groups(names: Sequence[str], samples: Mapping[str, Sequence[float]] | None,
                    units: Mapping[str, str] | None) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """The sampled metrics among ``names`` grouped by unit (same unit: paired), NaN units dropped from a group."""
    raw: dict[str, np.ndarray] = {}
    for name in sorted(names):
        values = (samples or {}).get(name)
        if values is not None and len(values) >= 2:
            raw[name] = np.asarray([np.nan if v is None else float(v) for v in values], dtype=float)
    groups: dict[tuple[str, int], list[str]] = {}
    for name, x in raw.items():
        groups.setdefault(_unit_of(name, units, x.size), []).append(name)
    out: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for key, members in groups.items():
        keep = np.logical_and.reduce([np.isfinite(raw[name]) for name in members])
        out[key] = {name: raw[name][keep] for name in members}
    return out


def _margin_test(comparison: Comparison, metrics: Mapping[str, float],
                 groups: Mapping[tuple[str, int], Mapping[str, np.ndarray]],
                 kinds: Mapping[str, SampleUnit], *, level: float, min_units: int) -> tuple[ComparisonTest, bool]:
    """Decide one comparison on its margin's interval; also say whether a within-fit unit was behind it."""
    point_metrics = {k: float(v) for k, v in metrics.items()}
    margin = comparison.margin(point_metrics)
    if not math.isfinite(margin):
        return ComparisonTest(comparison.text, None, None, None, note="not measured"), False
    variance = 0.0
    welch_denominator = 0.0
    n_min = 0
    within = False
    sampled = False
    for (unit_name, _size), members in groups.items():
        names = [name for name in members if name in comparison.metrics]
        if not names:
            continue
        # the margin's per-unit values, linearised at the reported numbers (exact for a linear margin)
        weights = {}
        for name in names:
            x0 = point_metrics[name]
            h = 1e-6 * max(1.0, abs(x0))
            up, down = dict(point_metrics), dict(point_metrics)
            up[name], down[name] = x0 + h, x0 - h
            weights[name] = (comparison.margin(up) - comparison.margin(down)) / (2 * h)
        weights = {name: w for name, w in weights.items() if math.isfinite(w) and w != 0.0}
        n = int(next(iter(members.values())).size)
        if not weights:
            continue
        sampled = True
        values = sum(w * members[name] for name, w in weights.items())
        if n < 2:
            n_min = n if n_min == 0 else min(n_min, n)
            continue
        unit = kinds.get(unit_name, INDEPENDENT)
        within = within or unit.kind == "within-fit"
        v = float(np.var(values, ddof=1)) * (1 / n + unit.variance_factor)
        variance += v
        welch_denominator += v * v / (n - 1)
        n_min = n if n_min == 0 else min(n_min, n)
    if not sampled:
        decided = comparison.holds_at(margin)
        return ComparisonTest(comparison.text, margin, None, decided, note="no spread"), False
    if n_min < min_units:
        return ComparisonTest(comparison.text, margin, None, None, n_min,
                              note=f"fewer than {min_units} units ({n_min})"), within
    if variance == 0.0:
        decided = comparison.holds_at(margin)
        return ComparisonTest(comparison.text, margin, (margin, margin), decided, n_min, None,
                              note="no spread across units"), within
    df = variance * variance / welch_denominator if welch_denominator > 0 else math.inf
    half = t_quantile(level, df) * math.sqrt(variance)
    lo, hi = margin - half, margin + half
    if comparison.op in ("==", "!="):
        decided_eq: bool | None = None if lo <= 0 <= hi else (comparison.op == "!=")
        return ComparisonTest(comparison.text, margin, (lo, hi), decided_eq, n_min, df), within
    side: bool | None = True if lo > 0 else (False if hi < 0 else None)
    return ComparisonTest(comparison.text, margin, (lo, hi), side, n_min, df), within


def claim_verdict(
    rule: str,
    metrics: Mapping[str, float],
    samples: Mapping[str, Sequence[float]] | None = None,
    *,
    units: Mapping[str, str] | None = None,
    unit_kinds: Mapping[str, SampleUnit] | None = None,
    level: float = LEVEL,
    min_units: int = MIN_UNITS,
) -> Verdict:
    """Decide a claim rule by the intervals of its comparisons' margins (see the module docstring).

    Parameters
    ----------
    rule : str
        A claim rule (:mod:`mmconcepts.engine.rules`).
    metrics : mapping of str to float
        The reported numbers.
    samples : mapping of str to sequence of float, optional
        Per-unit values of some metrics.
    units : mapping of str to str, optional
        The unit name of a metric's samples: metrics of one unit are paired (the same folds or
        seeds, in the same order), metrics of different units independent. A metric without
        a unit is paired with the other metrics without one whose samples have the same length.
    unit_kinds : mapping of str to SampleUnit, optional
        What each unit name is (default: independent; the unit of metrics without a unit
        name is ``""``).
    level : float, default=0.95
        The two-sided level of the intervals.
    min_units : int, default=5
        The fewest units behind a decided comparison.

    Returns
    -------
    Verdict

    Raises
    ------
    ExperimentError
        If the rule does not parse or names an unknown metric.

    Examples
    --------
    >>> a = [0.80, 0.72, 0.91, 0.66, 0.85]
    >>> b = [x - 0.05 for x in a]   # paired: b is 0.05 below a on every fold
    >>> claim_verdict("a > b", {"a": sum(a) / 5, "b": sum(b) / 5}, {"a": a, "b": b}).verdict
    'holds'
    """
    parsed = parse_rule(rule, metrics.keys())
    point = parsed.evaluate(metrics)
    if point is None:
        return Verdict(None, "not evaluated", "a metric it uses was not measured")
    groups = _aligned_groups(sorted(parsed.metrics), samples, units)
    kinds = dict(unit_kinds or {})
    tests, within = [], False
    for comparison in parsed.comparisons():
        test, w = _margin_test(comparison, metrics, groups, kinds, level=level, min_units=min_units)
        tests.append(test)
        within = within or w
    decided = parsed.combine([t.decided for t in tests])
    verdict = "holds" if decided is True else ("fails" if decided is False else "inconclusive")
    if decided is not None and decided != point:  # cannot happen: each interval is centred on its margin
        verdict = "inconclusive"  # pragma: no cover
    sizes = sorted({t.n_units for t in tests if t.n_units})
    if not sizes:
        basis = "reported numbers (no per-fold or per-seed samples)"
    else:
        what = {k.kind for key, k in kinds.items() if any(g[0] == key for g in groups)}
        corrected = " (corrected resampled t)" if "resampled" in what else ""
        basis = (f"{level * 100:g} % interval of each comparison's margin over {', '.join(map(str, sizes))} "
                 f"units{corrected}")
    return Verdict(point, verdict, basis, tuple(tests), "within one fit" if within else "")


@dataclass(frozen=True)
class MagnitudeVerdict:
    """Our number against the thesis' (see the module docstring).

    Attributes
    ----------
    verdict : str
        One of :data:`MAGNITUDE_VERDICTS`.
    ratio : float or None
        Ours / thesis.
    ratio_interval : (float, float) or None
        Our interval divided by the thesis' number.
    basis : str
    scope : str
        ``"within one fit"`` for samples of a within-fit unit.
    n_units : int
    """

    verdict: str
    ratio: float | None
    ratio_interval: tuple[float, float] | None
    basis: str
    scope: str = ""
    n_units: int = 0


def magnitude_verdict(
    metric: str,
    thesis: float,
    metrics: Mapping[str, float],
    samples: Mapping[str, Sequence[float]] | None = None,
    *,
    units: Mapping[str, str] | None = None,
    unit_kinds: Mapping[str, SampleUnit] | None = None,
    level: float = LEVEL,
    min_units: int = MIN_UNITS,
    max_spread: float = MAX_RATIO_SPREAD,
) -> MagnitudeVerdict:
    """Our ``metric`` against the thesis' number ``thesis``.

    Parameters
    ----------
    metric : str
        The metric's name.
    thesis : float
        The thesis' number (non-zero).
    metrics, samples, units, unit_kinds, level, min_units
        As in :func:`claim_verdict`.
    max_spread : float, default=2.0
        The widest interval (high / low) that still places our number.

    Returns
    -------
    MagnitudeVerdict

    Examples
    --------
    >>> folds = [0.80, 0.84, 0.79, 0.83, 0.82]
    >>> magnitude_verdict("acc", 0.9, {"acc": 0.816}, {"acc": folds}).verdict
    'below'
    """
    if metric not in metrics:
        raise ExperimentError(f"magnitude claim on {metric!r}: no such metric (known: {', '.join(sorted(metrics))}).")
    thesis = float(thesis)
    if not math.isfinite(thesis) or thesis == 0:
        raise ExperimentError(f"magnitude claim on {metric!r}: the thesis' number must be finite and non-zero; "
                              f"got {thesis!r}.")
    value = float(metrics[metric])
    if not math.isfinite(value):
        return MagnitudeVerdict("not evaluated", None, None, "the metric was not measured")
    ratio = value / thesis
    unit_name = (units or {}).get(metric, "")
    unit = (unit_kinds or {}).get(unit_name, INDEPENDENT)
    scope = "within one fit" if unit.kind == "within-fit" else ""
    x = finite_samples((samples or {}).get(metric))
    if x is None:
        return MagnitudeVerdict("inconclusive", ratio, None, "no per-fold or per-seed samples: no interval", scope)
    if x.size < min_units:
        return MagnitudeVerdict("inconclusive", ratio, None, f"fewer than {min_units} units ({x.size})", scope,
                                int(x.size))
    interval = metric_interval(value, x.tolist(), unit, level=level)
    assert interval is not None
    lo, hi = sorted((interval[0] / thesis, interval[1] / thesis))
    corrected = " (corrected resampled t)" if unit.kind == "resampled" else ""
    basis = f"{level * 100:g} % interval of our number over {x.size} units{corrected}, divided by the thesis' {thesis:g}"
    if hi < 1:
        verdict = "below"
    elif lo > 1:
        verdict = "above"
    elif lo > 0 and hi / lo <= max_spread:
        verdict = "matches"
    else:
        verdict = "inconclusive"
        basis += f"; the interval spans more than a factor {max_spread:g}"
    return MagnitudeVerdict(verdict, ratio, (lo, hi), basis, scope, int(x.size))
