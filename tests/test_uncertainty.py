"""Intervals and three-valued verdicts (mmconcepts.experiments.uncertainty), and how the
runner and the report use them."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from mmconcepts.experiments.uncertainty import VERDICTS, claim_verdict, t_interval


def test_t_interval_equals_scipy_on_the_mean(rng):
    x = rng.normal(0.7, 0.1, size=7)
    lo, hi = t_interval(float(x.mean()), x)
    ref = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert lo == pytest.approx(ref[0], rel=1e-12) and hi == pytest.approx(ref[1], rel=1e-12)


def test_t_interval_is_centred_on_the_reported_metric(rng):
    x = rng.normal(0.7, 0.1, size=5)
    lo, hi = t_interval(0.5, x)  # a pooled score need not be the mean of the folds
    assert (lo + hi) / 2 == pytest.approx(0.5)
    assert hi - lo == pytest.approx(np.diff(stats.t.interval(0.95, 4, scale=stats.sem(x)))[0])


@pytest.mark.parametrize("samples", [None, [], [1.0], [float("nan"), 2.0]])
def test_no_interval_without_two_samples(samples):
    assert t_interval(1.0, samples) is None


def test_verdict_is_paired_over_folds():
    # the two learners differ a lot between folds but one is always 0.02 ahead: paired, this is decisive
    a = [0.90, 0.60, 0.75, 0.82, 0.68]
    b = [v - 0.02 for v in a]
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    paired = claim_verdict("a > b", metrics, {"a": a, "b": b})
    assert paired.verdict == "holds" and paired.support == 1.0
    # the same means with the folds of b shuffled: no longer the same folds, not decisive
    unpaired = claim_verdict("a > b", metrics, {"a": a, "b": [b[3], b[1], b[4], b[0], b[2]]})
    assert unpaired.verdict == "inconclusive"


def test_verdict_fails_beyond_uncertainty_and_is_exact_without_samples():
    a, b = [0.5, 0.52, 0.49, 0.51], [0.7, 0.69, 0.72, 0.71]
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    assert claim_verdict("a > b", metrics, {"a": a, "b": b}).verdict == "fails"
    exact = claim_verdict("a > b", metrics)
    assert exact.verdict == "fails" and exact.support is None and "no per-fold" in exact.basis
    assert claim_verdict("a > c", {"a": 1.0, "c": float("nan")}).verdict == "not evaluated"


def test_a_small_lead_within_the_noise_is_inconclusive():
    a = [0.80, 0.70, 0.90]
    b = [0.78, 0.74, 0.85]  # a ahead on average, behind on one fold of three
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    v = claim_verdict("a > b", metrics, {"a": a, "b": b})
    assert v.holds is True and v.verdict == "inconclusive"


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(0, 1, allow_nan=False), min_size=2, max_size=12),
    st.floats(-0.5, 0.5, allow_nan=False),
)
def test_verdict_agrees_with_the_point_estimate_or_is_inconclusive(values, delta):
    a = np.asarray(values)
    metrics = {"a": float(a.mean()), "t": float(a.mean() + delta)}
    v = claim_verdict("a > t", metrics, {"a": list(a)})
    assert v.verdict in VERDICTS
    if v.verdict == "holds":
        assert v.holds is True and v.support >= 0.95
    if v.verdict == "fails":
        assert v.holds is False and v.support <= 0.05
    # a threshold outside the t interval is decided, one inside is not
    interval = t_interval(metrics["a"], a)
    if interval is not None and interval[1] - interval[0] > 0:
        if metrics["t"] < interval[0] - 1e-9:
            assert v.verdict == "holds"
        if metrics["t"] > interval[1] + 1e-9:
            assert v.verdict == "fails"


def test_a_nan_fold_is_dropped_from_the_whole_pair():
    # fold 2 of a is missing: dropping it only from a would pair a's fold 3 with b's fold 2
    a = [0.80, 0.62, float("nan"), 0.71, 0.90]
    b = [0.78, 0.60, 0.99, 0.69, 0.88]
    metrics = {"a": 0.7575, "b": 0.7375}
    v = claim_verdict("a > b", metrics, {"a": a, "b": b})
    assert v.verdict == "holds" and v.support == 1.0


def test_units_decide_what_is_paired():
    # a leads b by 0.01 on every fold, across folds that differ by 0.3: paired, the lead is sure;
    # declared as coming from different folds (units), it is lost in the spread between folds
    folds = [0.2, 0.5, 0.8, 0.35, 0.65]
    samples = {"a": [f + 0.01 for f in folds], "b": folds}
    metrics = {"a": float(np.mean(samples["a"])), "b": float(np.mean(folds))}
    assert claim_verdict("a > b", metrics, samples).verdict == "holds"
    assert claim_verdict("a > b", metrics, samples, units={"a": "u", "b": "u"}).verdict == "holds"
    apart = claim_verdict("a > b", metrics, samples, units={"a": "16-label folds", "b": "47-label folds"})
    assert apart.verdict == "inconclusive" and 0.5 < apart.support < 0.95


def test_result_checks_sample_units():
    from mmconcepts.errors import ExperimentError
    from mmconcepts.experiments import Result

    ok = Result(metrics={"a": 1.0, "b": 2.0}, samples={"a": [1, 1], "b": [2, 2, 2]}, sample_units={"a": "x", "b": "y"})
    ok.validate()
    with pytest.raises(ExperimentError, match="same length"):
        Result(metrics={"a": 1.0, "b": 2.0}, samples={"a": [1, 1], "b": [2, 2, 2]},
               sample_units={"a": "x", "b": "x"}).validate()
    with pytest.raises(ExperimentError, match="has no samples"):
        Result(metrics={"a": 1.0}, sample_units={"a": "x"}).validate()


def test_runner_stores_units_and_the_report_uses_them(toy, tmp_path):
    import json

    from mmconcepts.experiments import Claim, Result, run_experiment
    from mmconcepts.report import write_report

    folds = [0.2, 0.5, 0.8, 0.35, 0.65]
    exp = toy.make_experiment(
        "toy-units",
        lambda c, x: Result(metrics={"a": float(np.mean(folds)) + 0.01, "b": float(np.mean(folds))},
                            samples={"a": [f + 0.01 for f in folds], "b": folds},
                            sample_units={"a": "first folds", "b": "other folds"}),
        claims=[Claim("a beats b", "a > b")],
    )
    record = run_experiment(exp, output=tmp_path, progress=False)
    assert record["sample_units"] == {"a": "first folds", "b": "other folds"}
    assert record["claims"][0]["verdict"] == "inconclusive"
    assert json.loads((tmp_path / "toy-units.json").read_text())["sample_units"]["a"] == "first folds"
    assert "| a beats b | a &gt; b | inconclusive |" in write_report(tmp_path)[1].read_text()
