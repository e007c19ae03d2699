"""Fuzz a result record edited by hand: its numbers, verdicts, claims and keys changed at random.

Each example copies a toy run's folder and edits its record one to three times: a number anywhere in it made another
(metrics, samples, intervals, a claim's margins and ratio, table cells, the config), a verdict or ``holds`` turned,
a string changed (a claim's text or rule, a note), a key deleted, added or renamed, the digest replaced or deleted,
the schema version lowered. Whatever the edit, the record must not be reused as up to date by the runner, and the
report must either leave it out or show it with a mark (edited, or unverified).
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, assume, given, note
from hypothesis import strategies as st

pytestmark = pytest.mark.fuzz

#: Keys an edit leaves alone: the clock, which is no computed content.
CLOCK = ("elapsed_s", "started_at")
VERDICTS = ["holds", "fails", "depends", "inconclusive", "not evaluated", "matches", "below", "above"]
MARKS = ("edited", "unverified")


def _leaves(obj: Any, prefix: tuple = ()) -> list[tuple[tuple, Any]]:
    """(path, value) of every node below ``obj`` (dict keys and list indices), the clock left out."""
    out: list[tuple[tuple, Any]] = []
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for key, value in items:
        if prefix == () and key in CLOCK:
            continue
        out.append((prefix + (key,), value))
        out += _leaves(value, prefix + (key,))
    return out


def _parent(obj: Any, path: tuple) -> Any:
    for key in path[:-1]:
        obj = obj[key]
    return obj


@st.composite
def tampered(draw, base: dict) -> dict:
    record = json.loads(json.dumps(base))
    for _ in range(draw(st.integers(1, 3))):
        nodes = _leaves(record)
        kind = draw(st.sampled_from(["number", "number", "verdict", "string", "delete", "add", "rename", "digest",
                                     "schema"]))
        if kind == "number":
            numbers = [(p, v) for p, v in nodes if isinstance(v, (int, float)) and not isinstance(v, bool)]
            path, value = draw(st.sampled_from(numbers))
            new = draw(st.one_of(st.sampled_from([value + 1, -value, value * 1.5, 0, 1e9, value + 1e-12]),
                                 st.floats(allow_nan=False, allow_infinity=False), st.integers(-10, 10)))
            _parent(record, path)[path[-1]] = new
        elif kind == "verdict" and [c for c in record.get("claims") or [] if isinstance(c, dict)]:
            claim = draw(st.sampled_from([c for c in record["claims"] if isinstance(c, dict)]))
            if draw(st.booleans()):
                claim["verdict"] = draw(st.sampled_from(VERDICTS))
            else:
                claim["holds"] = draw(st.sampled_from([True, False, None]))
        elif kind == "string":
            strings = [(p, v) for p, v in nodes if isinstance(v, str)]
            path, value = draw(st.sampled_from(strings))
            _parent(record, path)[path[-1]] = draw(st.sampled_from([value + "!", value.upper(), "", "holds"]))
        elif kind in ("delete", "rename"):
            keyed = [(p, v) for p, v in nodes if isinstance(_parent(record, p), dict)]
            path, value = draw(st.sampled_from(keyed))
            parent = _parent(record, path)
            del parent[path[-1]]
            if kind == "rename":
                parent[str(path[-1]) + "_"] = value
        elif kind == "add":
            dicts = [record] + [v for _, v in nodes if isinstance(v, dict)]
            draw(st.sampled_from(dicts))[draw(st.sampled_from(["x", "verdict", "mean", "note"]))] = \
                draw(st.sampled_from([1, "holds", None, [0.5]]))
        elif kind == "digest":
            record["digest"] = draw(st.one_of(st.text(alphabet="0123456789abcdef", min_size=64, max_size=64),
                                              st.none(), st.integers()))
        elif kind == "schema":
            record["schema_version"] = draw(st.sampled_from([1, 2, 3, 4]))
            if draw(st.booleans()):
                record.pop("digest", None)
    return record


def _content(record: dict) -> str:
    return json.dumps({k: v for k, v in record.items() if k not in CLOCK}, sort_keys=True)


_BASE: dict[str, Any] = {}


def _base(folder: Path) -> tuple[Path, dict]:
    """A toy run's folder (made once) and its record."""
    if "folder" not in _BASE:
        from mmconcepts.experiments import run_experiment

        run_experiment("toy-mean", output=folder, progress=False)
        _BASE.update(folder=folder, record=json.loads((folder / "toy-mean.json").read_text()))
    return _BASE["folder"], _BASE["record"]


def _reused_or_unmarked(folder: Path) -> tuple[bool, bool]:
    """Whether the runner takes the record in ``folder`` as up to date, and whether the report shows it unmarked."""
    from mmconcepts.engine import get
    from mmconcepts.engine.runner import current_record, new_record, plan_run
    from mmconcepts.report._model import collect

    exp = get("toy-mean")
    config, preset, target, out = plan_run(exp, None, None, None, folder, "auto", None)
    reused = current_record(target.json_path, new_record(exp, preset, config, target), out) is not None
    problems: list[tuple[str, str]] = []
    views = [v for v in collect(folder, problems) if v.source == "toy-mean.json"]
    unmarked = bool(views) and not any(mark in views[0].status_label for mark in MARKS)
    note(f"reused: {reused}; shown as {views[0].status_label!r}" if views else f"reused: {reused}; left out")
    return reused, unmarked


@fuzz_settings(100, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_a_tampered_record_is_never_reused_nor_shown_unmarked(toy, tmp_path, data):
    base_folder, base = _base(tmp_path / "base")
    record = data.draw(tampered(base))
    assume(_content(record) != _content(base))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "out"
        shutil.copytree(base_folder, folder)
        (folder / "toy-mean.json").write_text(json.dumps(record, indent=data.draw(st.sampled_from([None, 2]))))
        assert_typed_or_good("tampered record", lambda: _reused_or_unmarked(folder),
                             check=lambda res: res == (False, False))
    assert toy.CALLS == [0]  # only the base run computed


@pytest.fixture(autouse=True)
def _fresh_base():
    _BASE.clear()
    yield
    _BASE.clear()
