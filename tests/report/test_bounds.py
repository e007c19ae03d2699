"""The report's work is bounded: what a record holds beyond the report's limits is left out and counted.

A hand-edited record can hold anything: 100 000 claims, a 10 MB string in a note or a table
cell. The report shows at most ``MAX_TEXT`` characters of a string (``MAX_PROSE`` of a note,
message or traceback), ``MAX_ITEMS`` items of a list (``MAX_COLUMNS`` columns of a table) and
``MAX_RECORD_TEXT`` characters of one record, says what it left out, takes time linear in the
record's size and memory a small multiple of it; a record larger than ``MAX_RECORD_BYTES`` is
listed, not read. No real record comes near a limit: the golden records render the same with
the limits lifted.
"""

from __future__ import annotations

import copy
import json
import re
import time
import tracemalloc
from pathlib import Path

import pytest

from mmconcepts.engine.digest import content_digest
from mmconcepts.report import _model, write_report
from mmconcepts.report.verdict_page import verdict_page

TESTS = Path(__file__).resolve().parents[1]
GOLDEN = TESTS / "golden"
RECORDS = TESTS / "data" / "records"
#: A schema-3 record with thesis, ours and magnitude claims (each with its test), metrics, samples and tables.
BASE = json.loads((GOLDEN / "ch6-symbolic.json").read_text(encoding="utf-8"))
BIG = 10_000_000  # characters of the huge strings


def _record(**changes) -> dict:
    record = copy.deepcopy(BASE)
    record.update(changes)
    return record


def _claims(n: int) -> list[dict]:
    """``n`` distinct claims, cycling through the base record's (each is decided again from the samples)."""
    claims = BASE["claims"]
    return [dict(claims[i % len(claims)], text=f"claim {i}: {claims[i % len(claims)]['text']}") for i in range(n)]


def _report(folder: Path, record: dict | None = None) -> tuple[str, str, float]:
    """Write ``record`` as ``a.json`` in ``folder`` (when given) and the report; (html, md, seconds)."""
    folder.mkdir(exist_ok=True)
    if record is not None:
        (folder / "a.json").write_text(json.dumps(record), encoding="utf-8")
    start = time.perf_counter()
    html_path, md_path = write_report(folder)
    seconds = time.perf_counter() - start
    return html_path.read_text(encoding="utf-8"), md_path.read_text(encoding="utf-8"), seconds


def _left_out(text: str, what: str) -> int:
    """The count of ``what`` a report says it left out (``N more <what>``), 0 when it says none."""
    found = re.findall(rf"(\d+) more {re.escape(what)}\b", text)
    assert len(set(found)) <= 1, found
    return int(found[0]) if found else 0


def test_ten_thousand_claims_take_seconds_and_the_report_says_how_many_it_left_out(tmp_path):
    n = 10_000
    html, md, seconds = _report(tmp_path, _record(claims=_claims(n)))
    assert seconds < 10, f"{n} claims took {seconds:.1f} s"
    assert len(html) < 3_000_000 and len(md) < 3_000_000, (len(html), len(md))
    for text in (html, md):
        shown = len(set(re.findall(r"claim (\d+): ", text)))
        assert 0 < shown <= _model.MAX_ITEMS
        assert shown + _left_out(text, "claims") == n, (shown, _left_out(text, "claims"))


def _grown(what: str, n: int) -> dict:
    if what == "claims":
        return _record(claims=_claims(n))
    if what == "metrics":
        return _record(metrics={f"m{i}": i / 7 for i in range(n)})
    if what == "tables":  # names that all make the same anchor (every character not ASCII)
        return _record(tables={chr(0x4E00 + i) * 2: {"title": "", "columns": ["a"], "rows": [[i]], "note": ""}
                               for i in range(n)})
    if what == "notes":
        return _record(notes=[f"note {i}" for i in range(n)])
    raise AssertionError(what)


@pytest.mark.parametrize("what, n", [("claims", 2_000), ("metrics", 2_000), ("tables", 500), ("notes", 5_000)])
def test_ten_times_the_record_takes_at_most_about_ten_times_as_long(tmp_path, what, n):
    _report(tmp_path / "warm", _grown(what, 10))
    small = min(_report(tmp_path / f"small{k}", _grown(what, n))[2] for k in range(2))
    large = _report(tmp_path / "large", _grown(what, 10 * n))[2]
    assert large < 15 * small + 1.0, f"{n} {what}: {small:.2f} s; {10 * n}: {large:.2f} s"


def _with_huge_string(where: str) -> tuple[dict, str]:
    """A record holding a string of BIG characters at ``where``; (record, the marker that starts the string)."""
    mark = "HUGE<b>"
    big = mark + "x" * (BIG - len(mark))
    record = _record()
    if where == "note":
        record["notes"] = record["notes"] + [big]
    elif where == "claim text":
        record["claims"][0]["text"] = big
    elif where == "claim text and rule":  # two huge strings in one claim
        record["claims"][0]["text"] = big
        record["claims"][0]["rule"] = big + "y"
    elif where == "metric name":
        record["metrics"][big] = 1.0
    elif where == "table cell":
        next(iter(record["tables"].values()))["rows"][0][0] = big
    elif where == "warning":
        record["warnings"] = [big]
    elif where == "traceback":
        record.update(status="failed", message=big, traceback=big)
    elif where == "config value":
        record["config"]["huge"] = big
    elif where == "title":
        record["title"] = big
    elif where == "explorer":
        record["explorer"] = {"note": big, "cards": [{"title": big, "labels": [{"label": big, "share": 0.5}],
                                                      "clips": [{"path": "a.wav", "caption": "a clip"}]}]}
    else:
        raise AssertionError(where)
    return record, mark


@pytest.mark.parametrize("where", ["note", "claim text", "claim text and rule", "metric name", "table cell", "warning",
                                   "traceback", "config value", "title", "explorer"])
def test_a_huge_string_is_cut_with_a_note_in_bounded_time_and_memory(tmp_path, where):
    record, mark = _with_huge_string(where)
    raw = json.dumps(record)
    (tmp_path / "a.json").write_text(raw, encoding="utf-8")
    tracemalloc.start()
    try:
        html, md, seconds = _report(tmp_path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(html) < 1_000_000 and len(md) < 1_000_000, (len(html), len(md))
    assert peak < 5 * len(raw), f"peak {peak / 1e6:.0f} MB for a record of {len(raw) / 1e6:.0f} MB"
    for text in (html, md):
        assert "HUGE" in text
        cuts = [int(n) for n in re.findall(r"… \((\d+) more characters\)", text)]
        hidden = [int(n) for n in re.findall(r"\((\d+) characters before\) …", text)]
        assert cuts or hidden, "no note of the characters left out"
        # the huge strings were cut (a message quoting one is cut too), at their limit, and nothing else was
        limits = (_model.MAX_TEXT, _model.MAX_PROSE)
        assert any(BIG - n in limits for n in cuts + hidden) and min(cuts + hidden) > BIG - 2 * _model.MAX_PROSE, (
            cuts, hidden)


def test_a_traceback_keeps_its_end(tmp_path):
    """The end of a traceback says what went wrong: it is the part kept."""
    tb = "Traceback (most recent call last):\n" + '  File "x.py", line 1\n' * 100_000 + "ValueError: the cause"
    html, md, _ = _report(tmp_path, _record(status="failed", message="it failed", traceback=tb))
    for text in (html, md):
        assert "ValueError: the cause" in text
        assert f"({len(tb) - _model.MAX_PROSE} characters before) …" in text


def _many(what: str, n: int) -> dict:
    record = _record()
    table = next(iter(record["tables"].values()))
    if what == "claims":
        record["claims"] = _claims(n)
    elif what == "metrics":
        record["metrics"] = {f"m{i}": float(i) for i in range(n)}
        record["reference"] = {}
    elif what == "tables":
        record["tables"] = {f"t{i}": {"title": "", "columns": ["a"], "rows": [[i]], "note": ""} for i in range(n)}
    elif what == "rows":
        table["rows"] = [list(table["rows"][0]) for _ in range(n)]
    elif what == "columns":
        table["columns"] = [f"c{i}" for i in range(n)]
        table["rows"] = [list(range(n))]
    elif what == "notes":
        record["notes"] = [f"note {i}" for i in range(n)]
    elif what == "warnings":
        record["warnings"] = [f"warning {i}" for i in range(n)]
    elif what == "configuration entries":
        record["config"] = {f"p{i}": i for i in range(n)}
    elif what == "figures":
        record["figures"] = {f"f{i}": f"a/f{i}.png" for i in range(n)}
    elif what == "concept cards":
        record["explorer"] = {"cards": [{"title": f"card {i}", "labels": [{"label": "a", "share": 0.5}]}
                                        for i in range(n)]}
    elif what == "labels and files of concept cards":
        record["explorer"] = {"cards": [{"title": "c", "labels": [{"label": f"l{i}", "share": 0.5} for i in range(n)]}]}
    else:
        raise AssertionError(what)
    return record


LISTS = ["claims", "metrics", "tables", "rows", "columns", "notes", "warnings", "configuration entries", "figures",
         "concept cards", "labels and files of concept cards"]


@pytest.mark.parametrize("what", LISTS)
def test_a_list_past_the_limit_is_cut_and_the_report_counts_what_it_left_out(tmp_path, what):
    cap = _model.MAX_COLUMNS if what == "columns" else _model.MAX_ITEMS
    html, md, _ = _report(tmp_path, _many(what, cap + 7))
    for text in (html, md):
        assert _left_out(text, what) == 7, re.findall(r"\d+ more [a-z ]+", text)[:5]
        run_note = text.split("Past the report's limits, ", 1)[1].split("see the record", 1)[0]
        assert f"7 more {what}" in run_note, run_note
    if what == "rows" or what == "columns":
        assert "7 more " + what + " not shown" in html.split("Table: ", 1)[1].split("</table>", 2)[1]


def test_a_list_within_the_limit_is_shown_whole(tmp_path):
    html, md, _ = _report(tmp_path, _many("notes", _model.MAX_ITEMS))
    assert f"note {_model.MAX_ITEMS - 1}" in html and "more notes" not in html and "more notes" not in md


def test_a_record_shows_at_most_its_budget_of_characters(tmp_path):
    """Many strings each within MAX_TEXT: the record's budget stops them, and the report counts the rest."""
    n = 3 * _model.MAX_RECORD_TEXT // _model.MAX_TEXT
    record = _record(warnings=[f"w{i:05d}" + "x" * (_model.MAX_TEXT - 6) for i in range(min(n, _model.MAX_ITEMS))])
    html, md, _ = _report(tmp_path, record)
    shown = len(set(re.findall(r"w(\d{5})x", html)))
    assert shown * _model.MAX_TEXT <= _model.MAX_RECORD_TEXT + _model.MAX_TEXT
    assert shown + _left_out(html, "warnings") == len(record["warnings"]) and _left_out(html, "warnings") > 0
    assert _left_out(md, "warnings") == _left_out(html, "warnings")


def test_a_string_in_place_of_a_list_is_bounded(tmp_path):
    """``notes`` edited into a 10 MB string: read as that many one-character notes, the report shows MAX_ITEMS."""
    html, md, seconds = _report(tmp_path, _record(notes="n" * BIG))
    assert seconds < 10 and len(html) < 1_000_000
    assert _left_out(html, "notes") == BIG - _model.MAX_ITEMS


def test_a_record_file_larger_than_the_limit_is_listed_not_read(tmp_path, monkeypatch):
    monkeypatch.setattr(_model, "MAX_RECORD_BYTES", 100_000)
    (tmp_path / "small.json").write_text(json.dumps(_record(experiment="small-one")), encoding="utf-8")
    html, md, _ = _report(tmp_path, _record(notes=["n" * 200_000]))
    listed = html.split('id="records-left-out"', 1)[1].split("</table>", 1)[0]
    assert "<td>a.json</td>" in listed and "larger than" in listed and "100000 bytes" in listed
    assert 'id="exp-small-one"' in html
    (tmp_path / "other.json").write_text(json.dumps({"data": "d" * 200_000}))  # no record: ignored
    html, md, _ = _report(tmp_path)
    assert "other.json" not in html


def _normalised(text: str) -> str:
    return re.sub(r"Generated \S+ by mmconcepts", "Generated by mmconcepts", text)


@pytest.mark.parametrize("folder", [GOLDEN, RECORDS])
def test_no_real_record_comes_near_a_limit(tmp_path, monkeypatch, folder):
    """The real records render identically with the limits lifted, and each within a fifth of each limit."""
    out = tmp_path / "r"
    out.mkdir()
    for path in folder.glob("*.json"):
        (out / path.name).write_bytes(path.read_bytes())
    html, md, _ = _report(out)
    assert "more characters" not in html + md and "not shown" not in html + md
    for name in ("MAX_TEXT", "MAX_PROSE", "MAX_ITEMS", "MAX_COLUMNS", "MAX_RECORD_TEXT", "MAX_RECORD_BYTES"):
        monkeypatch.setattr(_model, name, getattr(_model, name) // 5)
    small_html, small_md, _ = _report(out)
    monkeypatch.undo()
    for name in ("MAX_TEXT", "MAX_PROSE", "MAX_ITEMS", "MAX_COLUMNS", "MAX_RECORD_TEXT", "MAX_RECORD_BYTES"):
        monkeypatch.setattr(_model, name, 10**12)
    free_html, free_md, _ = _report(out)
    assert _normalised(free_html) == _normalised(html) == _normalised(small_html)
    assert _normalised(free_md) == _normalised(md) == _normalised(small_md)


def test_the_verdict_page_says_which_claims_it_left_out(tmp_path):
    record = _record(claims=_claims(_model.MAX_ITEMS + 3))
    record["digest"] = content_digest(record)  # a computed record: the page refuses edited ones
    (tmp_path / "a.json").write_text(json.dumps(record), encoding="utf-8")
    page = verdict_page(tmp_path, allow_stale=True, commit="x")
    assert _left_out(page, "claims") == 3 and f"`{record['experiment']}`" in page.split("3 more claims")[0][-300:]


def test_anchors_that_coincide_are_made_in_linear_time():
    """Many runs, tables or figures whose names make one anchor (every character not ASCII) get -2, -3, ... at once."""
    anchors = _model._Anchors(["exp--"])
    start = time.perf_counter()
    made = [anchors.make("exp--") for _ in range(20_000)] + [anchors.make("exp---3")]
    seconds = time.perf_counter() - start
    assert made[:3] == ["exp---2", "exp---3", "exp---4"] and made[-2] == "exp---20001" and made[-1] == "exp---3-2"
    assert seconds < 2, f"{seconds:.1f} s"
