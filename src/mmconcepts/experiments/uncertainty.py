"""Uncertainty of reported numbers and three-valued verdicts on claims.

An experiment reports a metric (``metrics[name]``) and, where it comes from folds, seeds
or draws, the per-fold values behind it (``samples[name]``, see
:class:`~mmconcepts.experiments.Result`). From them:

- :func:`t_interval` gives the metric's 95 % interval: the Student-t interval of the mean
  of the samples, ``mean +- t(0.975, n-1) s / sqrt(n)``, shifted so that it is centred on
  the reported metric (a pooled score, say, need not equal the mean of the per-fold
  scores). A t interval rather than a percentile bootstrap, because quick protocols have
  3-10 folds, where the bootstrap's intervals are too narrow.
- :func:`claim_verdict` decides a claim beyond that uncertainty by a *t-calibrated paired
  bootstrap*: metrics of the same unit (``units``; by default, metrics whose samples have
  the same length) are taken to come from the same folds (or seeds) and are resampled
  together, so that a comparison of two learners on the
  same folds is judged on its paired differences. Each replicate moves every sampled metric
  by the mean of its resampled deviations from the sample mean, scaled by
  ``c = t(0.975, n-1) / z(0.975) * sqrt(n / (n-1))`` so that a single metric's replicates
  spread like its t interval (for n = 3, c = 2.7; for n = 20, c = 1.1). The rule is
  evaluated on every replicate. The claim **holds** when it holds on the reported numbers
  and on at least 95 % of the replicates, **fails** when it fails on the reported numbers
  and on at least 95 % of them, and is **inconclusive** otherwise. A rule whose metrics
  have no samples is decided on the reported numbers alone (``basis`` says so).

The replicates are drawn from a fixed stream, so a verdict is reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .rules import parse_rule

__all__ = ["t_interval", "claim_verdict", "Verdict", "VERDICTS", "LEVEL"]

#: The verdict words, in the order the report counts them.
VERDICTS = ("holds", "fails", "inconclusive", "not evaluated")

#: Confidence level of intervals and verdicts.
LEVEL = 0.95

_N_BOOT = 2000
_BOOT_SEED = 20140101  # a fixed stream of its own: verdicts are reproducible


def _clean(samples: Sequence[float] | None) -> np.ndarray | None:
    if samples is None:
        return None
    x = np.asarray([float(v) for v in samples if v is not None], dtype=float)
    x = x[np.isfinite(x)]
    return x if x.size >= 2 else None


def t_interval(metric: float, samples: Sequence[float] | None, *, level: float = LEVEL) -> tuple[float, float] | None:
    """The ``level`` interval of a metric from its per-fold/per-seed samples.

    Parameters
    ----------
    metric : float
        The reported value (the interval is centred on it).
    samples : sequence of float, optional
        The values behind it; NaN and None are dropped.
    level : float, default=0.95

    Returns
    -------
    (low, high) or None
        None when fewer than two finite samples or the metric is NaN.

    Examples
    --------
    >>> lo, hi = t_interval(2.0, [1.0, 2.0, 3.0])
    >>> round(lo, 3), round(hi, 3)
    (-0.484, 4.484)
    """
    x = _clean(samples)
    if x is None or metric is None or not math.isfinite(float(metric)):
        return None
    half = stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return float(metric) - float(half), float(metric) + float(half)


@dataclass(frozen=True)
class Verdict:
    """A claim's verdict.

    Attributes
    ----------
    holds : bool or None
        The rule on the reported numbers (None: not evaluated).
    verdict : str
        ``"holds"``, ``"fails"``, ``"inconclusive"`` or ``"not evaluated"``.
    support : float or None
        Fraction of the bootstrap replicates on which the rule holds (None without samples).
    basis : str
        How it was decided, for the report.
    """

    holds: bool | None
    verdict: str
    support: float | None
    basis: str


def claim_verdict(
    rule: str,
    metrics: Mapping[str, float],
    samples: Mapping[str, Sequence[float]] | None = None,
    *,
    level: float = LEVEL,
    n_boot: int = _N_BOOT,
    units: Mapping[str, str] | None = None,
) -> Verdict:
    """Decide a claim rule beyond the uncertainty of its metrics (see the module docstring).

    Parameters
    ----------
    rule : str
        A claim rule (:mod:`mmconcepts.experiments.rules`).
    metrics : mapping of str to float
        The reported numbers.
    samples : mapping of str to sequence of float, optional
        Per-fold/per-seed values of some metrics.
    level : float, default=0.95
    n_boot : int, default=2000
    units : mapping of str to str, optional
        The unit of a metric's samples: metrics of one unit are resampled together (paired),
        metrics of different units independently. A metric without a unit is paired with
        the other metrics without one whose samples have the same length.

    Returns
    -------
    Verdict

    Raises
    ------
    ExperimentError
        If the rule does not parse or names an unknown metric.
    """
    parsed = parse_rule(rule, metrics.keys())
    point = parsed.evaluate(metrics)
    if point is None:
        return Verdict(None, "not evaluated", None, "a metric it uses was not measured")
    raw = {}
    for name in sorted(parsed.metrics):
        values = (samples or {}).get(name)
        if values is not None and len(values) >= 2:
            raw[name] = np.asarray([np.nan if v is None else float(v) for v in values], dtype=float)
    # samples of one unit (by default: of the same length) are paired (same folds or seeds); a
    # fold that is NaN in one metric of a group is dropped from the whole group, so that the
    # pairs stay aligned
    groups: dict[tuple[str, int], list[str]] = {}
    for name, x in raw.items():
        groups.setdefault(((units or {}).get(name, ""), x.size), []).append(name)
    used: dict[str, np.ndarray] = {}
    paired: list[list[str]] = []
    for names in groups.values():
        keep = np.logical_and.reduce([np.isfinite(raw[name]) for name in names])
        if keep.sum() >= 2:
            used.update({name: raw[name][keep] for name in names})
            paired.append(names)
    if not used:
        return Verdict(point, "holds" if point else "fails", None, "reported numbers (no per-fold or per-seed samples)")
    rng = np.random.default_rng(_BOOT_SEED)
    shifts: dict[str, np.ndarray] = {}
    for names in paired:
        n = used[names[0]].size
        idx = rng.integers(0, n, size=(n_boot, n))
        c = stats.t.ppf(0.5 + level / 2, n - 1) / stats.norm.ppf(0.5 + level / 2) * math.sqrt(n / (n - 1))
        for name in names:
            dev = used[name] - used[name].mean()
            shifts[name] = c * dev[idx].mean(axis=1)
    replicate = dict(metrics)
    n_true = n_eval = 0
    for b in range(n_boot):
        for name, s in shifts.items():
            replicate[name] = float(metrics[name]) + float(s[b])
        value = parsed.evaluate(replicate)
        if value is None:
            continue
        n_eval += 1
        n_true += bool(value)
    support = n_true / n_eval if n_eval else None
    sizes = ", ".join(str(n) for n in sorted({used[names[0]].size for names in paired}))
    basis = f"t-calibrated paired bootstrap over {sizes} folds/seeds ({n_boot} replicates)"
    if support is None:
        return Verdict(point, "inconclusive", None, basis)
    if point and support >= level:
        verdict = "holds"
    elif not point and support <= 1 - level:
        verdict = "fails"
    else:
        verdict = "inconclusive"
    return Verdict(point, verdict, support, basis)
