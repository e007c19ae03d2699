"""Intervals and verdicts (mmconcepts.engine.uncertainty): a verdict is what the interval shown says."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import Claim, Result, SampleUnit, run_experiment
from mmconcepts.engine.uncertainty import LEVEL, MIN_UNITS, VERDICTS, metric_interval, t_interval
from mmconcepts.engine.evidence import claim_verdict, magnitude_verdict
from mmconcepts.engine.verdicts import combine_settings


# --------------------------------------------------------------------------- intervals


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


@pytest.mark.parametrize("k", [3, 5, 10])
def test_folds_use_the_corrected_resampled_t(rng, k):
    """Nadeau and Bengio (2003): the variance of a mean over k folds is s^2 (1/k + n_test/n_train), n_test/n_train
    = 1/(k-1); known answer from scipy's t quantile."""
    x = rng.normal(0.7, 0.1, size=k)
    lo, hi = metric_interval(0.7, x, SampleUnit.folds(k))
    half = stats.t.ppf(0.975, k - 1) * x.std(ddof=1) * math.sqrt(1 / k + 1 / (k - 1))
    assert hi - 0.7 == pytest.approx(half, rel=1e-12) and 0.7 - lo == pytest.approx(half, rel=1e-12)
    # wider than the plain t interval of independent samples, by sqrt(1 + k/(k-1))
    plain = metric_interval(0.7, x)
    assert (hi - lo) / (plain[1] - plain[0]) == pytest.approx(math.sqrt(1 + k / (k - 1)))
    # seeds and within-fit blocks are not corrected
    assert metric_interval(0.7, x, SampleUnit.seeds()) == plain == metric_interval(0.7, x, SampleUnit.within_fit())


def test_splits_ratio_and_bad_units():
    assert SampleUnit.splits(0.2).test_train_ratio == pytest.approx(0.25)
    assert SampleUnit.folds(10).test_train_ratio == pytest.approx(1 / 9)
    with pytest.raises(ExperimentError, match="k >= 2"):
        SampleUnit.folds(1)
    with pytest.raises(ExperimentError, match="kind"):
        SampleUnit("folds")
    with pytest.raises(ExperimentError, match="only resampled"):
        SampleUnit("independent", 0.5)
    assert SampleUnit.from_dict(SampleUnit.folds(4, "x").to_dict()) == SampleUnit.folds(4, "x")


# --------------------------------------------------------------------------- verdicts on rules


def test_verdict_is_paired_over_folds():
    # the two learners differ a lot between folds but one is always 0.02 ahead: paired, this is decisive
    a = [0.90, 0.60, 0.75, 0.82, 0.68]
    b = [v - 0.02 + e for v, e in zip(a, [0.001, -0.001, 0.002, 0.0, -0.002])]
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    paired = claim_verdict("a > b", metrics, {"a": a, "b": b})
    assert paired.verdict == "holds" and paired.support is None
    (test,) = paired.tests
    diff = np.subtract(a, b)
    assert test.margin == pytest.approx(diff.mean())
    assert test.interval == pytest.approx(stats.t.interval(0.95, 4, loc=diff.mean(), scale=stats.sem(diff)))
    assert test.df == pytest.approx(4) and test.n_units == 5
    # the same means with b's folds shuffled: no longer the same folds, not decisive
    unpaired = claim_verdict("a > b", metrics, {"a": a, "b": [b[3], b[1], b[4], b[0], b[2]]})
    assert unpaired.verdict == "inconclusive"


def test_verdict_fails_beyond_uncertainty_and_is_exact_without_samples():
    a, b = [0.5, 0.52, 0.49, 0.51, 0.5], [0.7, 0.69, 0.72, 0.71, 0.7]
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    assert claim_verdict("a > b", metrics, {"a": a, "b": b}).verdict == "fails"
    exact = claim_verdict("a > b", metrics)
    assert exact.verdict == "fails" and exact.tests[0].note == "no spread" and "no per-fold" in exact.basis
    assert claim_verdict("a > c", {"a": 1.0, "c": float("nan")}).verdict == "not evaluated"


def test_fewer_than_five_units_decide_nothing():
    a, b = [0.9, 0.91, 0.92], [0.1, 0.11, 0.12]  # far apart, but three units only
    metrics = {"a": 0.91, "b": 0.11}
    v = claim_verdict("a > b", metrics, {"a": a, "b": b})
    assert v.holds is True and v.verdict == "inconclusive" and "fewer than 5 units (3)" in v.tests[0].note
    assert claim_verdict("a > b", metrics, {"a": a, "b": b}, min_units=3).verdict == "holds"
    assert MIN_UNITS == 5


def test_welch_across_units_equals_scipy():
    """Metrics of different units are independent samples: Welch's t with Welch-Satterthwaite degrees of freedom."""
    a = [0.61, 0.72, 0.65, 0.70, 0.69, 0.74]
    b = [0.55, 0.60, 0.50, 0.66, 0.58]
    metrics = {"a": float(np.mean(a)), "b": float(np.mean(b))}
    v = claim_verdict("a > b", metrics, {"a": a, "b": b}, units={"a": "u1", "b": "u2"})
    ref = stats.ttest_ind(a, b, equal_var=False)
    (test,) = v.tests
    assert test.df == pytest.approx(ref.df)
    half = (test.interval[1] - test.interval[0]) / 2
    se = math.sqrt(np.var(a, ddof=1) / len(a) + np.var(b, ddof=1) / len(b))
    assert half == pytest.approx(stats.t.ppf(0.975, ref.df) * se)
    # holds exactly when scipy's one-sided p-value is below 2.5 %
    p_one = stats.ttest_ind(a, b, equal_var=False, alternative="greater").pvalue
    assert (v.verdict == "holds") == (p_one < 0.025)


def test_a_nonlinear_rule_uses_the_delta_method_and_is_exact_when_linear():
    a = [0.8, 0.82, 0.79, 0.81, 0.83]
    metrics = {"a": float(np.mean(a))}
    linear = claim_verdict("3 * a > 2", metrics, {"a": a})
    lo, hi = metric_interval(metrics["a"], a)
    assert linear.tests[0].interval == pytest.approx((3 * lo - 2, 3 * hi - 2))
    # 1 - a < 0.5 * (1 - a) is linear too; a ratio is linearised at the reported numbers
    ratio = claim_verdict("a / 2 > 0.3", metrics, {"a": a})
    assert ratio.tests[0].interval == pytest.approx((lo / 2 - 0.3, hi / 2 - 0.3))


def test_compound_rules_combine_their_comparisons_three_valued():
    x = [0.50, 0.52, 0.48, 0.51, 0.49]
    near = [0.51, 0.50, 0.50, 0.52, 0.47]  # no clear order with x
    far = [0.10, 0.12, 0.08, 0.11, 0.09]
    metrics = {"x": float(np.mean(x)), "near": float(np.mean(near)), "far": float(np.mean(far))}
    samples = {"x": x, "near": near, "far": far}
    assert claim_verdict("x > far and x > near", metrics, samples).verdict == "inconclusive"
    assert claim_verdict("x > far or x > near", metrics, samples).verdict == "holds"
    assert claim_verdict("x < far and x > near", metrics, samples).verdict == "fails"
    assert claim_verdict("not x < far", metrics, samples).verdict == "holds"
    v = claim_verdict("far < x < 1", metrics, samples)  # a chain is two comparisons
    assert [t.comparison for t in v.tests] == ["far < x", "x < 1.0"] and v.verdict == "holds"


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0, 1, allow_nan=False), min_size=5, max_size=12),
    st.floats(-0.5, 0.5, allow_nan=False),
)
def test_the_verdict_is_the_interval_shown(values, delta):
    """Holds exactly when the metric's interval (the one the report shows) lies wholly above the bar, fails exactly
    when it lies wholly below, inconclusive otherwise."""
    a = np.asarray(values)
    metrics = {"a": float(a.mean()), "t": float(a.mean() + delta)}
    v = claim_verdict("a > t", metrics, {"a": list(a)})
    assert v.verdict in VERDICTS
    interval = metric_interval(metrics["a"], a)
    if interval[1] - interval[0] > 1e-9:
        if metrics["t"] < interval[0] - 1e-9:
            assert v.verdict == "holds"
        elif metrics["t"] > interval[1] + 1e-9:
            assert v.verdict == "fails"
        elif interval[0] + 1e-9 < metrics["t"] < interval[1] - 1e-9:
            assert v.verdict == "inconclusive"


def test_a_nan_fold_is_dropped_from_the_whole_pair():
    # fold 2 of a is missing: dropping it only from a would pair a's fold 3 with b's fold 2
    a = [0.80, 0.62, float("nan"), 0.71, 0.90, 0.66]
    b = [0.78, 0.60, 0.99, 0.69, 0.88, 0.64]
    metrics = {"a": 0.738, "b": 0.718}
    v = claim_verdict("a > b", metrics, {"a": a, "b": b}, min_units=2)
    assert v.verdict == "holds" and v.tests[0].n_units == 5


def test_units_decide_what_is_paired():
    # a leads b by 0.01 on every fold, across folds that differ by 0.3: paired, the lead is sure;
    # declared as coming from different folds (units), it is lost in the spread between folds
    folds = [0.2, 0.5, 0.8, 0.35, 0.65]
    samples = {"a": [f + 0.01 + e for f, e in zip(folds, [0, 0.001, -0.001, 0.002, -0.002])], "b": folds}
    metrics = {"a": float(np.mean(samples["a"])), "b": float(np.mean(folds))}
    assert claim_verdict("a > b", metrics, samples).verdict == "holds"
    assert claim_verdict("a > b", metrics, samples, units={"a": "u", "b": "u"}).verdict == "holds"
    apart = claim_verdict("a > b", metrics, samples, units={"a": "16-label folds", "b": "47-label folds"})
    assert apart.verdict == "inconclusive"


def test_within_fit_units_mark_the_verdict():
    a = [0.8, 0.82, 0.79, 0.81, 0.83]
    v = claim_verdict("a > 0.5", {"a": 0.81}, {"a": a}, units={"a": "blocks"},
                      unit_kinds={"blocks": SampleUnit.within_fit()})
    assert v.verdict == "holds" and v.scope == "within one fit"
    assert claim_verdict("a > 0.5", {"a": 0.81}, {"a": a}).scope == ""


# --------------------------------------------------------------------------- the false "holds" rate under the null


@pytest.mark.parametrize("n", [3, 5, 10])
@pytest.mark.parametrize("paired", [True, False])
def test_false_holds_rate_is_at_the_stated_level(n, paired):
    """Null data (no true difference): a comparison is called "holds" in (1 - LEVEL) / 2 of runs, and "holds" or
    "fails" in 1 - LEVEL, within the Monte Carlo error; Welch's unpaired test is exact for n >= 5 and conservative
    (at most the level) at n = 3. The default of at least five units decides nothing at n = 3."""
    rng = np.random.default_rng(12345 + n + 100 * paired)
    n_sim = 6000
    alpha = (1 - LEVEL) / 2
    holds = decided = 0
    for _ in range(n_sim):
        common = rng.normal(0, 1, n) if paired else 0.0  # paired folds share a fold effect
        a = common + rng.normal(0, 0.5, n)
        b = common + rng.normal(0, 0.5, n)
        units = None if paired else {"a": "u1", "b": "u2"}
        v = claim_verdict("a > b", {"a": float(a.mean()), "b": float(b.mean())}, {"a": list(a), "b": list(b)},
                          units=units, min_units=2)
        holds += v.verdict == "holds"
        decided += v.verdict in ("holds", "fails")
    se = math.sqrt(alpha * (1 - alpha) / n_sim)
    rate, both = holds / n_sim, decided / n_sim
    if paired or n >= 5:
        assert abs(rate - alpha) < 4 * se, rate
        assert abs(both - 2 * alpha) < 4 * math.sqrt(2 * alpha * (1 - 2 * alpha) / n_sim), both
    else:
        assert rate < alpha + 4 * se, rate
    if n < MIN_UNITS:
        a, b = rng.normal(0, 1, n), rng.normal(0, 1, n)
        v = claim_verdict("a > b", {"a": float(a.mean()), "b": float(b.mean())}, {"a": list(a), "b": list(b)})
        assert v.verdict == "inconclusive"


def test_false_holds_rate_of_corrected_folds_on_cross_validation_null():
    """Two learners equal in truth (least squares on one of two exchangeable features), compared over the 10 folds
    of one cross-validation: the folds' training sets overlap, so their differences are not independent. The
    corrected resampled t keeps the false "holds" rate at or below its level, and below the plain paired t's
    (Nadeau and Bengio 2003: the corrected test is conservative for k-fold)."""
    rng = np.random.default_rng(7)
    k, n, n_sim = 10, 40, 600
    false_corrected = false_plain = 0
    unit = {"a": "f", "b": "f"}
    for _ in range(n_sim):
        X = rng.normal(0, 1, (n, 2))
        y = X[:, 0] + X[:, 1] + rng.normal(0, 1, n)
        score = {"a": [], "b": []}
        for test in np.array_split(rng.permutation(n), k):
            train = np.setdiff1d(np.arange(n), test)
            for j, name in enumerate("ab"):
                x = X[train, j]
                slope = np.dot(x, y[train]) / np.dot(x, x)
                score[name].append(float(np.mean((y[test] - slope * X[test, j]) ** 2)))
        metrics = {name: float(np.mean(v)) for name, v in score.items()}
        corrected = claim_verdict("a > b", metrics, score, units=unit, unit_kinds={"f": SampleUnit.folds(k)})
        plain = claim_verdict("a > b", metrics, score, units=unit, unit_kinds={"f": SampleUnit.seeds()})
        false_corrected += corrected.verdict == "holds"
        false_plain += plain.verdict == "holds"
    assert false_corrected < false_plain
    assert false_corrected / n_sim < 0.025 + 3 * math.sqrt(0.025 * 0.975 / n_sim)


# --------------------------------------------------------------------------- magnitudes and settings


def test_magnitude_is_a_ratio_with_its_interval():
    folds = [0.80, 0.84, 0.79, 0.83, 0.82]
    m = magnitude_verdict("acc", 0.9, {"acc": 0.816}, {"acc": folds})
    lo, hi = metric_interval(0.816, folds)
    assert m.verdict == "below" and m.ratio == pytest.approx(0.816 / 0.9)
    assert m.ratio_interval == pytest.approx((lo / 0.9, hi / 0.9))
    assert magnitude_verdict("acc", 0.816, {"acc": 0.816}, {"acc": folds}).verdict == "matches"
    assert magnitude_verdict("acc", 0.7, {"acc": 0.816}, {"acc": folds}).verdict == "above"
    # an interval spanning more than a factor of two cannot place our number
    wide = [0.1, 0.9, 0.2, 0.8, 0.5]
    assert magnitude_verdict("acc", 0.5, {"acc": 0.5}, {"acc": wide}).verdict == "inconclusive"
    # no samples, or fewer than five: no interval, no verdict
    assert magnitude_verdict("acc", 0.9, {"acc": 0.816}).verdict == "inconclusive"
    assert magnitude_verdict("acc", 0.9, {"acc": 0.816}, {"acc": folds[:3]}).verdict == "inconclusive"
    assert magnitude_verdict("acc", 0.9, {"acc": float("nan")}).verdict == "not evaluated"
    with pytest.raises(ExperimentError, match="non-zero"):
        magnitude_verdict("acc", 0.0, {"acc": 0.8})


def test_settings_say_under_which_the_claim_holds():
    assert combine_settings({"KDE": "holds", "VQ": "holds"}).verdict == "holds"
    assert combine_settings({"KDE": "holds", "VQ": "holds"}).detail == "holds under all"
    both = combine_settings({"KDE": "holds", "VQ": "fails"})
    assert both.verdict == "depends" and both.detail == "holds only under KDE; fails under VQ"
    assert combine_settings({"KDE": "fails", "VQ": "fails"}).detail == "fails under all"
    assert combine_settings({"KDE": "inconclusive", "VQ": "inconclusive"}).verdict == "inconclusive"
    assert combine_settings({"a": "holds", "b": "inconclusive"}).detail == "holds only under a; inconclusive under b"
    listed = combine_settings({"KDE, plain": "holds", "VQ, plain": "inconclusive", "VQ, scaled": "inconclusive"})
    assert listed.detail == "holds only under (KDE, plain); inconclusive under (VQ, plain), (VQ, scaled)"


# --------------------------------------------------------------------------- claims and the runner


def test_claims_declare_their_kind_and_source():
    with pytest.raises(ExperimentError, match="kind must be one of"):
        Claim("t", "a > 0", kind="other")
    with pytest.raises(ExperimentError, match="needs its source"):
        Claim("t", "a > 0", kind="thesis")
    with pytest.raises(ExperimentError, match="metric set beside"):
        Claim("t", "a > 0", kind="magnitude", source="Table 1 (line 3)")
    with pytest.raises(ExperimentError, match="not both"):
        Claim("t", "a > 0", settings={"x": "a > 1"})
    assert Claim("t", "a > 0").kind == "ours"


def test_thesis_numbers_come_from_the_reference_table(toy):
    exp = toy.make_experiment("toy-refs", lambda c, x: Result(metrics={"a": 1.0}), reference={"a": 0.625},
                              claims=[Claim("a reaches the thesis' {thesis:a}.", "a", kind="magnitude",
                                            source="Table 3.2 (line 2790)")])
    assert exp.claims[0].text == "a reaches the thesis' 0.625."
    with pytest.raises(ExperimentError, match="not in the reference table"):
        toy.make_experiment("toy-refs2", lambda c, x: Result(metrics={"a": 1.0}), reference={"a": 0.625},
                            claims=[Claim("b is {thesis:b}.", "a > 0")])
    with pytest.raises(ExperimentError, match="has none of that name"):
        toy.make_experiment("toy-refs3", lambda c, x: Result(metrics={"a": 1.0}), reference={"b": 0.625},
                            claims=[Claim("a", "a", kind="magnitude", source="T (line 1)")])


def test_result_checks_sample_units():
    ok = Result(metrics={"a": 1.0, "b": 2.0}, samples={"a": [1, 1], "b": [2, 2, 2]}, sample_units={"a": "x", "b": "y"},
                units={"x": SampleUnit.folds(2)})
    ok.validate()
    with pytest.raises(ExperimentError, match="same length"):
        Result(metrics={"a": 1.0, "b": 2.0}, samples={"a": [1, 1], "b": [2, 2, 2]},
               sample_units={"a": "x", "b": "x"}).validate()
    with pytest.raises(ExperimentError, match="has no samples"):
        Result(metrics={"a": 1.0}, sample_units={"a": "x"}).validate()
    with pytest.raises(ExperimentError, match="no metric's samples have"):
        Result(metrics={"a": 1.0}, samples={"a": [1, 2]}, sample_units={"a": "x"}, units={"y": SampleUnit()}).validate()
    with pytest.raises(ExperimentError, match="must be a SampleUnit"):
        Result(metrics={"a": 1.0}, samples={"a": [1, 2]}, sample_units={"a": "x"}, units={"x": "folds"}).validate()


def test_runner_stores_units_tests_and_settings(toy, tmp_path):
    folds = [0.2, 0.5, 0.8, 0.35, 0.65]
    lead = [f + 0.05 + e for f, e in zip(folds, [0.0, 0.01, -0.01, 0.005, -0.005])]
    exp = toy.make_experiment(
        "toy-units",
        lambda c, x: Result(metrics={"a": float(np.mean(lead)), "b": float(np.mean(folds)), "c": 5.0},
                            samples={"a": lead, "b": folds}, sample_units={"a": "folds", "b": "folds"},
                            units={"folds": SampleUnit.folds(5)}, split_groups={"folds": {"by": "recordings"}}),
        claims=[Claim("a beats b", "a > b", kind="thesis", source="Table 1 (line 2)"),
                Claim("a beats b or c", kind="thesis", source="Table 1 (line 2)", settings={"B": "a > b", "C": "a > c"})],
    )
    record = run_experiment(exp, output=tmp_path, progress=False)
    stored = json.loads((tmp_path / "toy-units.json").read_text())
    assert stored["units"] == {"folds": {"kind": "resampled", "test_train_ratio": 0.25,
                                         "description": "5 cross-validation folds"}}
    assert stored["split_groups"] == {"folds": {"by": "recordings"}}
    first, second = stored["claims"]
    assert first["verdict"] == "holds" and "corrected resampled t" in first["basis"]
    diff = np.subtract(lead, folds)
    half = stats.t.ppf(0.975, 4) * diff.std(ddof=1) * math.sqrt(1 / 5 + 1 / 4)
    assert first["tests"][0]["interval"] == pytest.approx([diff.mean() - half, diff.mean() + half])
    # the metric's interval in the record is the corrected one too
    lo, hi = metric_interval(record["metrics"]["a"], lead, SampleUnit.folds(5))
    assert stored["intervals"]["a"] == pytest.approx([lo, hi])
    assert second["verdict"] == "depends" and second["detail"] == "holds only under B; fails under C"
    assert [s["verdict"] for s in second["settings"]] == ["holds", "fails"]


def test_the_examples_in_the_docstrings_are_true():
    import doctest

    from mmconcepts.engine import uncertainty

    failed, tried = doctest.testmod(uncertainty, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failed == 0
