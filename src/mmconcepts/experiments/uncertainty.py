"""Intervals of reported numbers and verdicts on claims, decided by the interval shown.

An experiment reports a metric (``metrics[name]``) and, where it comes from folds, seeds
or repetitions, the per-unit values behind it (``samples[name]``, see
:class:`~mmconcepts.experiments.Result`). Each group of samples has a *unit*
(:class:`SampleUnit`) that says how the units relate to one another:

- ``independent``: independent replications (seeds, repetitions that share no data);
- ``resampled``: folds or random splits of one data set, whose training sets overlap.
  They are not independent, and the variance of their mean is larger than ``s^2 / n``.
  The *corrected resampled t* of Nadeau and Bengio (2003) replaces ``1 / n`` by
  ``1 / n + n_test / n_train`` (for k folds, ``n_test / n_train = 1 / (k - 1)``);
- ``within-fit``: values measured inside one fit (per query block, per utterance of one
  fitted model). Their spread is within one fit only: verdicts on them say so
  (``scope``), and they are no replication of the experiment.

Intervals
---------
:func:`metric_interval` gives a metric's interval at :data:`LEVEL`: ``metric +- t(1 -
alpha/2, n - 1) * s * sqrt(1/n + r)``, with ``r = n_test / n_train`` for resampled units and
0 otherwise, centred on the reported metric (a pooled score need not equal the mean of the
per-fold scores).

Verdicts
--------
A claim's rule (:mod:`mmconcepts.experiments.rules`) is a combination of comparisons
(``a > b``). Each comparison has a *margin* (``a - b``: positive when it holds), and the
margin's interval at :data:`LEVEL` is computed exactly as a metric's: the per-unit values of
the margin (paired over the metrics of one unit, linearised by the delta method for
nonlinear rules), its corrected variance, and a Student t with Welch-Satterthwaite degrees
of freedom when metrics of different units (independent samples) meet in one comparison.
A comparison **holds** when its whole interval lies on the side where it holds, **fails**
when its whole interval lies on the other side, and is undecided otherwise; the rule
combines its comparisons with three-valued logic (``and`` fails when a part fails and holds
when all hold; ``or`` the converse). The verdict is **holds**, **fails** or
**inconclusive**, and **not evaluated** when a metric it needs was not measured. So a
verdict is exactly what the interval shown for its margin says: with a 95 % two-sided
interval, a comparison with no true difference is called "holds" in 2.5 % of runs and
"holds" or "fails" in 5 %.

A comparison is decided only on at least :data:`MIN_UNITS` units (folds, seeds or
repetitions); on fewer it is undecided, whatever its interval. A comparison whose metrics
have no samples is decided on the reported numbers alone (``basis`` says "no spread": a fact
of the data, an analytic chance level).

Magnitudes
----------
:func:`magnitude_verdict` sets one of our numbers beside the thesis' number: the ratio
ours / thesis and its interval (the metric's interval divided by the thesis' number), and
the verdict **matches** (the thesis' number lies inside our interval, and the interval spans
no more than a factor :data:`MAX_RATIO_SPREAD`), **below** or **above** (beyond the
interval), or **inconclusive** (an interval too wide to place our number, or too few units).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from ..errors import ExperimentError
from .rules import Comparison, parse_rule

__all__ = [
    "LEVEL",
    "MIN_UNITS",
    "MAX_RATIO_SPREAD",
    "VERDICTS",
    "MAGNITUDE_VERDICTS",
    "UNIT_KINDS",
    "SampleUnit",
    "ComparisonTest",
    "Verdict",
    "MagnitudeVerdict",
    "metric_interval",
    "t_interval",
    "claim_verdict",
    "magnitude_verdict",
    "combine_settings",
]

#: The verdict words of a rule (kinds ``thesis``, ``ours``, ``check``), in the order the report counts
#: them; "depends" is the verdict of a claim evaluated under several settings that do not agree.
VERDICTS = ("holds", "fails", "depends", "inconclusive", "not evaluated")

#: The verdict words of a magnitude (our number against the thesis').
MAGNITUDE_VERDICTS = ("matches", "below", "above", "inconclusive", "not evaluated")

#: Confidence level of every interval shown and of every verdict (two-sided).
LEVEL = 0.95

#: The fewest units (folds, seeds, repetitions) behind a decided comparison.
MIN_UNITS = 5

#: A magnitude "matches" only when our interval spans at most this factor (high / low).
MAX_RATIO_SPREAD = 2.0

#: The kinds of sample units.
UNIT_KINDS = ("independent", "resampled", "within-fit")


@dataclass(frozen=True)
class SampleUnit:
    """How the samples of one unit relate to one another (see the module docstring).

    Parameters
    ----------
    kind : {"independent", "resampled", "within-fit"}
    test_train_ratio : float, default=0.0
        ``n_test / n_train`` of a resampled unit (the corrected resampled t's correction);
        0 for the other kinds.
    description : str, default=""
        What a unit is, for the report ("10 folds of the 16-label set").

    Examples
    --------
    >>> SampleUnit.folds(10).test_train_ratio == 1 / 9
    True
    """

    kind: str = "independent"
    test_train_ratio: float = 0.0
    description: str = ""

    def __post_init__(self) -> None:
        if self.kind not in UNIT_KINDS:
            raise ExperimentError(f"a sample unit's kind must be one of {', '.join(UNIT_KINDS)}; got {self.kind!r}.")
        ratio = self.test_train_ratio
        if isinstance(ratio, bool) or not isinstance(ratio, (int, float)) or not math.isfinite(ratio) or ratio < 0:
            raise ExperimentError(f"a sample unit's test_train_ratio must be a finite number >= 0; got {ratio!r}.")
        if self.kind != "resampled" and ratio:
            raise ExperimentError(f"only resampled units (folds, splits) have a test_train_ratio; got {ratio!r} for "
                                  f"a unit of kind {self.kind!r}.")

    @classmethod
    def seeds(cls, description: str = "independent seeds") -> SampleUnit:
        """Independent replications: a new draw of the data, the splits and the learners each."""
        return cls("independent", 0.0, description)

    @classmethod
    def folds(cls, k: int, description: str = "") -> SampleUnit:
        """The ``k`` folds of one k-fold cross-validation (``n_test / n_train = 1 / (k - 1)``).

        Leave-one-out over ``n`` examples is ``folds(n)``.
        """
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
            raise ExperimentError(f"a cross-validation has k >= 2 folds; got {k!r}.")
        return cls("resampled", 1.0 / (int(k) - 1), description or f"{int(k)} cross-validation folds")

    @classmethod
    def splits(cls, test_fraction: float, description: str = "") -> SampleUnit:
        """Repeated random train/test splits of one data set, ``test_fraction`` of it tested each time."""
        if not 0 < test_fraction < 1:
            raise ExperimentError(f"a split's test fraction is in (0, 1); got {test_fraction!r}.")
        return cls("resampled", test_fraction / (1 - test_fraction),
                   description or f"random splits ({test_fraction:.0%} tested)")

    @classmethod
    def within_fit(cls, description: str = "blocks of one fit") -> SampleUnit:
        """Values measured inside one fit: their spread is within that fit only."""
        return cls("within-fit", 0.0, description)

    def to_dict(self) -> dict[str, Any]:
        """``{"kind", "test_train_ratio", "description"}``, as in the record."""
        return {"kind": self.kind, "test_train_ratio": self.test_train_ratio, "description": self.description}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SampleUnit:
        """Read a unit of a record."""
        return cls(str(d.get("kind", "independent")), float(d.get("test_train_ratio") or 0.0),
                   str(d.get("description", "")))

    @property
    def variance_factor(self) -> float:
        """``r``: the mean's variance is ``s^2 (1/n + r)`` (0 unless resampled)."""
        return self.test_train_ratio if self.kind == "resampled" else 0.0


_INDEPENDENT = SampleUnit()


def _clean(samples: Sequence[float] | None) -> np.ndarray | None:
    if samples is None:
        return None
    x = np.asarray([float(v) for v in samples if v is not None], dtype=float)
    x = x[np.isfinite(x)]
    return x if x.size >= 2 else None


def _quantile(level: float, df: float) -> float:
    return float(stats.t.ppf(0.5 + level / 2, df))


def metric_interval(metric: float, samples: Sequence[float] | None, unit: SampleUnit | None = None, *,
                    level: float = LEVEL) -> tuple[float, float] | None:
    """The ``level`` interval of a metric from its per-unit samples.

    ``metric +- t(1 - alpha/2, n - 1) * s * sqrt(1/n + r)``, with ``r`` the unit's
    :attr:`SampleUnit.variance_factor` (the corrected resampled t for folds and splits).

    Parameters
    ----------
    metric : float
        The reported value (the interval is centred on it).
    samples : sequence of float, optional
        The values behind it; NaN and None are dropped.
    unit : SampleUnit, optional
        How the samples relate (default: independent).
    level : float, default=0.95

    Returns
    -------
    (low, high) or None
        None when fewer than two finite samples or the metric is NaN.

    Examples
    --------
    >>> lo, hi = metric_interval(2.0, [1.0, 2.0, 3.0])
    >>> round(lo, 3), round(hi, 3)
    (-0.484, 4.484)
    >>> lo, hi = metric_interval(2.0, [1.0, 2.0, 3.0], SampleUnit.folds(3))
    >>> round(hi - 2.0, 3)  # sqrt(1/3 + 1/2) / sqrt(1/3) = 1.58 times wider
    3.928
    """
    x = _clean(samples)
    if x is None or metric is None or not math.isfinite(float(metric)):
        return None
    r = (unit or _INDEPENDENT).variance_factor
    half = _quantile(level, x.size - 1) * x.std(ddof=1) * math.sqrt(1 / x.size + r)
    return float(metric) - float(half), float(metric) + float(half)


def t_interval(metric: float, samples: Sequence[float] | None, *, level: float = LEVEL) -> tuple[float, float] | None:
    """The interval of :func:`metric_interval` for independent samples (the plain Student t)."""
    return metric_interval(metric, samples, None, level=level)


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
        unit = kinds.get(unit_name, _INDEPENDENT)
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
    half = _quantile(level, df) * math.sqrt(variance)
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
        A claim rule (:mod:`mmconcepts.experiments.rules`).
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
    unit = (unit_kinds or {}).get(unit_name, _INDEPENDENT)
    scope = "within one fit" if unit.kind == "within-fit" else ""
    x = _clean((samples or {}).get(metric))
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


@dataclass(frozen=True)
class SettingsVerdict:
    """A claim evaluated under several settings: its overall verdict and how each setting went."""

    verdict: str
    detail: str
    per_setting: dict[str, str] = field(default_factory=dict)


def combine_settings(verdicts: Mapping[str, str]) -> SettingsVerdict:
    """The overall verdict of a claim evaluated under several settings (label -> verdict).

    ``holds`` when it holds under every setting, ``fails`` when it fails under every one,
    ``inconclusive`` when it is inconclusive under every one, ``not evaluated`` when no
    setting was evaluated, and ``depends`` otherwise; ``detail`` says which: "holds under
    all", "holds only under X", "fails under all", ...

    Examples
    --------
    >>> combine_settings({"KDE": "holds", "VQ": "fails"}).detail
    'holds only under KDE; fails under VQ'

    A label that holds a comma is put in parentheses, to keep the labels of a list apart:

    >>> combine_settings({"KDE, plain SVM": "holds", "VQ, plain SVM": "fails", "VQ, scaled SVM": "fails"}).detail
    'holds only under (KDE, plain SVM); fails under (VQ, plain SVM), (VQ, scaled SVM)'
    """
    if not verdicts:
        raise ExperimentError("combine_settings needs at least one setting.")
    by_word: dict[str, list[str]] = {}
    for label, verdict in verdicts.items():
        by_word.setdefault(verdict, []).append(label)
    evaluated = {w: labels for w, labels in by_word.items() if w != "not evaluated"}
    if not evaluated:
        return SettingsVerdict("not evaluated", "not evaluated under any setting", dict(verdicts))
    if len(evaluated) == 1 and len(by_word) == 1:
        word = next(iter(evaluated))
        return SettingsVerdict(word, f"{word} under all", dict(verdicts))
    parts = []
    for word in ("holds", "fails", "inconclusive", "not evaluated"):
        labels = by_word.get(word)
        if labels:
            only = "only " if word == "holds" and len(labels) < len(verdicts) else ""
            parts.append(f"{word} {only}under {', '.join(f'({x})' if ',' in x else x for x in labels)}")
    overall = "depends"
    if set(evaluated) == {"inconclusive"}:
        overall = "inconclusive"
    return SettingsVerdict(overall, "; ".join(parts), dict(verdicts))
