"""Intervals of reported numbers and verdicts on claims, decided by the interval shown.

An experiment reports a metric (``metrics[name]``) and, where it comes from folds, seeds
or repetitions, the per-unit values behind it (``samples[name]``, see
:class:`~mmconcepts.engine.Result`). Each group of samples has a *unit*
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
A claim's rule (:mod:`mmconcepts.engine.rules`) is a combination of comparisons
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
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ..errors import ExperimentError

__all__ = [
    "LEVEL",
    "MIN_UNITS",
    "MAX_RATIO_SPREAD",
    "VERDICTS",
    "MAGNITUDE_VERDICTS",
    "UNIT_KINDS",
    "SampleUnit",
    "metric_interval",
    "t_interval",
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


INDEPENDENT = SampleUnit()


def finite_samples(samples: Sequence[float] | None) -> np.ndarray | None:
    if samples is None:
        return None
    x = np.asarray([float(v) for v in samples if v is not None], dtype=float)
    x = x[np.isfinite(x)]
    return x if x.size >= 2 else None


def t_quantile(level: float, df: float) -> float:
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
    x = finite_samples(samples)
    if x is None or metric is None or not math.isfinite(float(metric)):
        return None
    r = (unit or INDEPENDENT).variance_factor
    half = t_quantile(level, x.size - 1) * x.std(ddof=1) * math.sqrt(1 / x.size + r)
    return float(metric) - float(half), float(metric) + float(half)


def t_interval(metric: float, samples: Sequence[float] | None, *, level: float = LEVEL) -> tuple[float, float] | None:
    """The interval of :func:`metric_interval` for independent samples (the plain Student t)."""
    return metric_interval(metric, samples, None, level=level)
