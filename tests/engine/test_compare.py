"""Comparing two runs' records (`mmconcepts compare`): every number and verdict, clock metrics aside."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmconcepts.cli import main
from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import run_experiment
from mmconcepts.engine.compare import _same, compare_records, format_differences


def _edit(path, change):
    record = json.loads(path.read_text())
    change(record)
    path.write_text(json.dumps(record))


@pytest.fixture
def two_runs(toy, tmp_path):
    for name in ("old", "new"):
        run_experiment("toy-mean", output=tmp_path / name, progress=False)
    return tmp_path / "old", tmp_path / "new"


def test_the_same_run_twice_agrees(two_runs, capsys):
    old, new = two_runs
    assert compare_records(old, new) == []
    assert main(["compare", str(old), str(new)]) == 0
    assert "the two runs agree" in capsys.readouterr().out


def test_another_seed_differs_metric_by_metric(toy, two_runs, tmp_path):
    old, _ = two_runs
    run_experiment("toy-mean", output=tmp_path / "other", progress=False, seed=1)
    diffs = compare_records(old, tmp_path / "other")
    where = {d.where for d in diffs}
    assert {"metrics['mean']", "metrics['std']", "claim 'The sample mean is close to one half.' tests"} <= where
    before = json.loads((old / "toy-mean.json").read_text())["metrics"]["mean"]
    assert next(d for d in diffs if d.where == "metrics['mean']").old == before


def test_each_kind_of_edit_is_found_and_clock_metrics_are_not(two_runs, capsys):
    old, new = two_runs
    path = new / "toy-mean.json"

    def edits(record):
        record["metrics"]["fit_seconds"] = 1.0  # a clock metric: left out
        record["claims"][0]["verdict"] = "fails" if record["claims"][0]["verdict"] != "fails" else "holds"
        record["intervals"]["mean"] = [0.0, 1.0]
        record["elapsed_s"] = 123.0  # not compared

    _edit(path, edits)
    diffs = compare_records(old, new)
    assert sorted(d.where.split(" ")[-1] if d.where.startswith("claim") else d.where for d in diffs) == \
        ["intervals['mean']", "verdict"]
    assert main(["compare", str(old), str(new)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("2 difference(s):") and "toy-mean (synthetic): intervals['mean']" in out


def test_a_record_in_one_run_only_and_the_only_filter(toy, two_runs):
    old, new = two_runs
    (new / "toy-mean.json").unlink()
    assert [(d.where, d.old, d.new) for d in compare_records(old, new)] == [("record", "present", None)]
    with pytest.raises(ExperimentError, match="no result record of toy-other"):
        compare_records(old, new, ids=["toy-other"])
    with pytest.raises(ExperimentError, match="does not exist"):
        compare_records(old, new / "nowhere")


def test_tolerance_of_numbers(two_runs):
    old, new = two_runs
    _edit(new / "toy-mean.json", lambda r: r["metrics"].__setitem__("mean", r["metrics"]["mean"] * (1 + 1e-9)))
    assert [d.where for d in compare_records(old, new)] == ["metrics['mean']"]
    assert compare_records(old, new, rtol=1e-6) == []
    assert main(["compare", str(old), str(new), "--rtol", "-1"]) == 2


def test_the_listing_is_cut_at_its_limit():
    from mmconcepts.engine.compare import Difference

    diffs = [Difference("x (real)", f"metrics['m{i}']", i, i + 1) for i in range(5)]
    text = format_differences(diffs, limit=2)
    assert text.splitlines() == ["5 difference(s):", "x (real): metrics['m0']: 0 -> 1",
                                 "x (real): metrics['m1']: 1 -> 2", "... and 3 more"]


_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=4),
    max_leaves=20,
)


@given(_json)
def test_a_value_is_the_same_as_itself(value):
    assert _same(value, value, 0.0)
    assert _same(value, json.loads(json.dumps(value)), 0.0)


@given(st.floats(min_value=-1e300, max_value=1e300).filter(lambda x: abs(x) > 1e-300))
def test_a_changed_number_differs_and_a_bool_is_no_number(x):
    assert not _same(x, x * (1 + 1e-6) + math.copysign(1e-300, x), 1e-9)
    assert _same(x, x * (1 + 1e-12), 1e-9)
    assert not _same(True, 1, 0.0) and not _same(0, None, 0.0) and not _same([x], [x, x], 0.0)
