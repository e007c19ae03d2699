"""The claim-rule language: parsing, precedence, NaN handling and error messages."""

from __future__ import annotations

import math

import pytest

from mmconcepts.errors import ExperimentError
from mmconcepts.engine.rules import evaluate_rule, is_valid_metric_name, parse_rule

M = {
    "16.nmf_kl.l_full": 0.9,
    "bins_20.l_single": 0.5,
    "nmf_frobenius.l_full": 0.8,
    "svm.l_full": 0.7,
    "a": 2.0,
    "b": 3.0,
    "neg": -4.0,
    "zero": 0.0,
}


@pytest.mark.parametrize(
    "rule, expected",
    [
        ("16.nmf_kl.l_full > bins_20.l_single", True),
        ("16.nmf_kl.l_full < bins_20.l_single", False),
        ("nmf_frobenius.l_full > svm.l_full", True),
        ("16.nmf_kl.l_full - 0.4 == bins_20.l_single", True),
        ("bins_20.l_single*2 >= 1", True),
    ],
)
def test_digit_led_and_dotted_metric_names(rule, expected):
    assert evaluate_rule(rule, M) is expected


def test_known_metric_wins_over_number_and_numbers_parse():
    # "16" is a number unless it is a metric name.
    assert evaluate_rule("16 > 3", {"a": 1.0}) is True
    assert evaluate_rule("16 > 3", {"16": 1.0}) is False
    assert evaluate_rule("a < 1e-3", {"a": 1e-4}) is True
    assert evaluate_rule("a > 1.5e+3", {"a": 1501.0}) is True
    assert evaluate_rule("a == .5", {"a": 0.5}) is True
    assert evaluate_rule("a == 2.", {"a": 2.0}) is True


@pytest.mark.parametrize(
    "rule, expected",
    [
        ("0 < a < 3", True),
        ("0 < a < 1", False),  # would be True if read as (0 < a) < 1
        ("1 < a < b < 4", True),
        ("1 < a > b", False),
        ("a < b > 1", True),
        ("a == 2 != b", True),
        ("3 > a > neg", True),
    ],
)
def test_chained_comparisons_follow_python(rule, expected):
    assert evaluate_rule(rule, M) is expected
    # Cross-check against Python itself on the same expression.
    py = rule
    for name, value in M.items():
        py = py.replace(name, repr(value)) if name.isidentifier() else py
    assert eval(py) is expected  # noqa: S307 - test oracle on a fixed string


@pytest.mark.parametrize(
    "rule, expected",
    [
        ("a + b * 2 == 8", True),
        ("(a + b) * 2 == 10", True),
        ("a - b - 1 == -2", True),  # left associative
        ("b / a / 2 == 0.75", True),
        ("-a * -b == 6", True),
        ("- -a == 2", True),
        ("not a > b", True),
        ("not a > b and b > a", True),
        ("a > b or b > a and neg > 0", False),  # and binds tighter than or
        ("(a > b or b > a) and neg < 0", True),
        ("not not a < b", True),
        ("a > b or not (neg > 0)", True),
    ],
)
def test_arithmetic_and_boolean_precedence(rule, expected):
    assert evaluate_rule(rule, M) is expected


@pytest.mark.parametrize(
    "rule, expected",
    [
        ("abs(neg) == 4", True),
        ("abs(a - b) < 1.5", True),
        ("min(a, b, neg) == neg", True),
        ("max(a, b) == b", True),
        ("max(a) == a", True),
        ("abs(min(neg, a)) > max(a, b)", True),
    ],
)
def test_functions(rule, expected):
    assert evaluate_rule(rule, M) is expected


def test_nan_metric_means_not_evaluated():
    metrics = {"a": math.nan, "b": 1.0}
    assert evaluate_rule("a > b", metrics) is None
    assert evaluate_rule("a > b or b > 0", metrics) is None  # any NaN metric used
    assert evaluate_rule("b > 0", metrics) is True  # an unused NaN does not matter
    assert evaluate_rule("a > b", {"a": None, "b": 1.0}) is None


def test_division_follows_ieee():
    assert evaluate_rule("a / zero > 1e300", M) is True
    assert evaluate_rule("neg / zero < 0", M) is True
    assert evaluate_rule("zero / zero > 1", M) is None  # NaN computed by the rule


def test_unknown_metric_lists_close_matches():
    with pytest.raises(ExperimentError) as info:
        evaluate_rule("nmf_frobenius.l_ful > svm.l_full", M)
    msg = str(info.value)
    assert "unknown metric 'nmf_frobenius.l_ful'" in msg
    assert "nmf_frobenius.l_full" in msg
    with pytest.raises(ExperimentError, match="unknown metric '17.nmf_kl.l_full'"):
        evaluate_rule("17.nmf_kl.l_full > 0", M)


@pytest.mark.parametrize(
    "rule, fragment",
    [
        ("", "empty"),
        ("a >", "end of rule"),
        ("(a > b", "expected ')'"),
        ("a > > b", "'>'"),
        ("a $ b", "unexpected character '$'"),
        ("a + b", "must be true or false"),
        ("abs(a > b)", "position"),
        ("min()", "at least one argument"),
        ("abs(a, b) > 0", "exactly 1"),
        ("a > b c", "unexpected"),
        ("abs a > 1", "followed by '('"),
        ("(a > b) + 1 > 0", "expected a number"),
        ("a and b", "true/false"),
        ("not a", "true/false"),
        ("a = b", "unexpected character '='"),
    ],
)
def test_syntax_and_type_errors_are_clear(rule, fragment):
    with pytest.raises(ExperimentError) as info:
        parse_rule(rule, {"a", "b"} if rule != "a > b c" else None)
    assert fragment in str(info.value)
    assert "claim rule" in str(info.value)


def test_syntax_check_without_names_and_used_metrics():
    rule = parse_rule("0 < 16.nmf_kl.l_full - svm.l_full < 2e-1 and abs(x) > 0")
    assert rule.metrics == {"16.nmf_kl.l_full", "svm.l_full", "x"}
    assert rule.evaluate({"16.nmf_kl.l_full": 0.9, "svm.l_full": 0.8, "x": -1.0}) is True
    with pytest.raises(ExperimentError, match="unknown metric 'x'"):
        rule.evaluate({"16.nmf_kl.l_full": 0.9, "svm.l_full": 0.8})


def test_result_is_a_python_bool():
    assert type(evaluate_rule("a < b", M)) is bool


@pytest.mark.parametrize(
    "name, ok",
    [("16.nmf_kl.l_full", True), ("bins_20.l_single", True), ("a", True), ("16", False),
     ("1e5", False), ("and", False), ("max", False), ("a-b", False), ("", False)],
)
def test_valid_metric_names(name, ok):
    assert is_valid_metric_name(name) is ok


@pytest.mark.parametrize(
    "rule, fragment",
    [("a ** b > 1", "unexpected '*'"), ("a // b > 1", "unexpected '/'"), ("a, b", "unexpected ','"),
     ("a > b, a", "unexpected ','"), ("min(a, b=1) > 0", "unexpected character '='")],
)
def test_python_syntax_outside_the_language_is_refused(rule, fragment):
    with pytest.raises(ExperimentError) as info:
        parse_rule(rule, {"a", "b"})
    assert fragment in str(info.value)


def test_every_registered_claim_rule_parses():
    from mmconcepts.engine import registry

    claims = [claim for exp in registry.all_experiments() for claim in exp.claims]
    rules = [rule for claim in claims if claim.kind != "magnitude" for rule in claim.rules.values()]
    assert len(rules) > 40
    for rule in rules:
        assert parse_rule(rule).metrics  # every claim reads at least one metric
    for claim in claims:  # a magnitude's rule is one metric name
        if claim.kind == "magnitude":
            assert parse_rule(f"{claim.rule} > 0").metrics == {claim.rule}


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_VALUES = {"a": 2.0, "b": 3.0, "neg": -4.0, "half": 0.5}


def _num():
    leaf = st.sampled_from(sorted(_VALUES) + ["1", "0.5", "2e-1", "3"])
    return st.recursive(
        leaf,
        lambda inner: st.one_of(
            st.tuples(inner, st.sampled_from(["+", "-", "*"]), inner).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
            inner.map(lambda x: f"-{x}"),
            inner.map(lambda x: f"abs({x})"),
            st.lists(inner, min_size=1, max_size=3).map(lambda xs: f"min({', '.join(xs)})"),
            st.lists(inner, min_size=1, max_size=3).map(lambda xs: f"max({', '.join(xs)})"),
        ),
        max_leaves=6,
    )


def _bool():
    cmp = st.tuples(_num(), st.lists(st.tuples(st.sampled_from(["<", "<=", ">", ">=", "==", "!="]), _num()),
                                     min_size=1, max_size=2)).map(
        lambda t: t[0] + "".join(f" {op} {x}" for op, x in t[1]))
    return st.recursive(
        cmp,
        lambda inner: st.one_of(
            st.tuples(inner, st.sampled_from(["and", "or"]), inner).map(lambda t: f"{t[0]} {t[1]} {t[2]}"),
            inner.map(lambda x: f"not ({x})"),
            inner.map(lambda x: f"({x})"),
        ),
        max_leaves=4,
    )


@settings(max_examples=300, deadline=None)
@given(_bool())
def test_rules_agree_with_python_on_random_expressions(rule):
    # the outside answer: Python itself, on names that are identifiers (no division: IEEE rules differ)
    # (min and max of one argument are that argument in rules, as in numpy, not an error as in Python)
    funcs = {"abs": abs, "min": lambda *xs: min(xs), "max": lambda *xs: max(xs)}
    assert evaluate_rule(rule, _VALUES) is bool(eval(rule, funcs, dict(_VALUES)))  # noqa: S307
