"""Fuzz ``mmconcepts report`` with edited and corrupted result records.

Each example writes one damaged record beside good ones (copies of the records in
``tests/data/records``) and runs the command line's ``report`` in this process. The damage:
keys deleted anywhere in the record, values replaced by the wrong type, NaN, infinities,
huge numbers and strings, HTML and backticks, deeply nested lists, non-UTF-8 bytes spliced
into the file, the file cut short, and a list, object or string grown to tens of thousands of
items or millions of characters (its own content repeated: 20 000 claims, a 3 MB note). The
outcome must be a good one: exit code 0, no traceback, ``report.html`` and ``report.md`` both
written and each under :data:`REPORT_BOUND` characters, every good record shown, the damaged
one either shown or listed under "Records left out" (by file name), and nothing the record
holds reaching either file as markup.
"""

from __future__ import annotations

import contextlib
import copy
import io
import itertools
import json
import math
import re
import shutil
import tempfile
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given, note
from hypothesis import strategies as st

from mmconcepts.cli import main
from mmconcepts.engine.record import RECORD_KEYS
from mmconcepts.report._model import MAX_TEXT

pytestmark = pytest.mark.fuzz

RECORDS = Path(__file__).resolve().parents[1] / "data" / "records"
GOOD = {  # file name -> experiment id of the good records put beside the damaged one
    "ch2-nmf-recovery.json": "ch2-nmf-recovery",
    "ch3-combinations.synthetic.json": "ch3-combinations",
}
BASES = [json.loads((RECORDS / name).read_text(encoding="utf-8")) for name in GOOD]

#: Markup a damaged field tries to smuggle into the report.
INJECTED = ("<script>alert(1)</script>", "</table></section><h1>x", '"><img src=x onerror=alert(1)>',
            "``a`b``", "]]>", "<!--", "| a | b |\n|---|", "# heading\n", "[link](javascript:alert(1))",
            "\ud800 a lone surrogate")


def _paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path in a JSON tree (dict keys and list indices), the root excluded, 6 levels deep at most."""
    out: list[tuple] = []
    if len(prefix) >= 6:
        return out
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out.append(prefix + (i,))
            out += _paths(v, prefix + (i,))
    return out


def _value(obj: Any, path: tuple) -> Any:
    for key in path:
        obj = obj[key]
    return obj


def _parent(obj: Any, path: tuple) -> Any:
    for key in path[:-1]:
        obj = obj[key]
    return obj


#: The most characters each report file may have: the good records take about 60 000; a damaged record, however
#: large, shows a bounded part of itself.
REPORT_BOUND = 4_000_000


def _grown(value: Any, n: int) -> Any:
    """``value`` grown to ``n`` items (a list or object: its own items repeated, keys made unique) or ``n``
    characters (a string: itself repeated); other values as they are."""
    if isinstance(value, (list, str)) and value:
        return (value * (n // len(value) + 1))[:n]
    if isinstance(value, dict) and value:
        items = list(value.items())
        return {key if i < len(items) else f"{key}~{i}": v
                for i, (key, v) in enumerate(itertools.islice(itertools.cycle(items), n))}
    return value


def _nested(depth: int) -> Any:
    value: Any = 1
    for _ in range(depth):
        value = [value]
    return value


weird_values = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(10**30), max_value=10**30),
    st.just(10**400),  # an int no float holds
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -0.0, 5e-324]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=40), st.sampled_from(INJECTED),
    st.integers(min_value=10_000, max_value=300_000).map(lambda n: "<b>" + "x" * n),  # a huge string
    st.lists(st.one_of(st.integers(), st.text(max_size=5), st.floats()), max_size=4),
    st.dictionaries(st.text(max_size=6), st.one_of(st.integers(), st.text(max_size=5)), max_size=3),
    # copied: a later edit must not change the strategy's own constant (hypothesis then sees flaky data)
    st.sampled_from([[], {}, "", [[1, 2], [3]], {"a": {"b": {}}}]).map(copy.deepcopy),
    st.integers(min_value=900, max_value=5000).map(_nested),  # deeper than json/Python like
)


@st.composite
def damaged_records(draw) -> tuple[str, bytes]:
    """(file name, bytes) of a good record damaged by one to three edits."""
    record = json.loads(json.dumps(draw(st.sampled_from(BASES))))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(record)
        if not paths or not isinstance(record, dict):
            break
        path = draw(st.sampled_from(paths))
        parent = _parent(record, path)
        edit = draw(st.sampled_from(["delete", "replace", "grow"]))
        if edit == "delete":
            del parent[path[-1]]
        elif edit == "replace":
            parent[path[-1]] = draw(weird_values)
        else:  # a list or object grown to 10 000+ items, a string to 2 000 000+ characters (often one of the top)
            growable = [p for p in paths if isinstance(_value(record, p), (list, dict, str)) and _value(record, p)]
            top = [p for p in growable if len(p) <= 2]
            path = draw(st.sampled_from(top if top and draw(st.booleans()) else growable or paths))
            parent, value = _parent(record, path), _value(record, path)
            size = draw(st.integers(2 * 10**6, 4 * 10**6) if isinstance(value, str) else st.integers(10**4, 3 * 10**4))
            parent[path[-1]] = _grown(value, size)
            break  # (the grown copies share their items: a later edit would change them all)
    if draw(st.integers(0, 9)) == 0:  # not even an object
        record = draw(weird_values)
    try:
        raw = json.dumps(record, indent=draw(st.sampled_from([None, 1]))).encode("utf-8", "surrogatepass")
    except (ValueError, RecursionError):
        raw = b"[" * 10_000
    damage = draw(st.sampled_from(["none", "none", "bytes", "truncate"]))
    if damage == "bytes":  # non-UTF-8 bytes spliced in
        at = draw(st.integers(0, len(raw)))
        raw = raw[:at] + draw(st.sampled_from([b"\xff\xfe", b"\xc3(", b"\x80", b"\xed\xa0\x80", b"\x00"])) + raw[at:]
    elif damage == "truncate":
        raw = raw[: draw(st.integers(0, max(0, len(raw) - 1)))]
    name = draw(st.sampled_from(["zz-edited.json", "ch2-nmf-recovery.synthetic.json", "a b&<c>.json"]))
    return name, raw


class _Balanced(HTMLParser):
    VOID = {"meta", "img", "br", "hr", "link", "input", "wbr"}

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.tags: set[str] = set()

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack.pop() != tag:
            self.errors.append(tag)


def _report(folder: Path) -> tuple[int, str, str, str]:
    """Run ``mmconcepts report -q FOLDER`` here; (exit code, stdout+stderr, html, md)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        code = main(["report", "-q", str(folder)])
    html_path, md_path = folder / "report.html", folder / "report.md"
    html_text = html_path.read_text(encoding="utf-8") if html_path.is_file() else ""
    md = md_path.read_text(encoding="utf-8") if md_path.is_file() else ""
    return code, buf.getvalue(), html_text, md


def _good_report(bad_name: str, bad_id: Any, unrecognisable: bool):
    def check(res: tuple[int, str, str, str]) -> bool:
        try:
            _check(res)
        except AssertionError as exc:
            note(f"the report is not right: {exc}")  # shown by hypothesis with the failing example
            return False
        return True

    def _check(res: tuple[int, str, str, str]) -> None:
        code, output, html_text, md = res
        assert code == 0, f"exit code {code}: {output[-2000:]}"
        assert "Traceback" not in output, output[-2000:]
        assert html_text and md, "report.html or report.md not written"
        assert len(html_text) < REPORT_BOUND and len(md) < REPORT_BOUND, f"reports of {len(html_text)}, {len(md)} chars"
        for exp_id in GOOD.values():
            assert f'id="exp-{exp_id}"' in html_text, f"good record {exp_id} not shown in the HTML"
            assert f"`{exp_id}`" in md, f"good record {exp_id} not shown in the Markdown"
        left_out = html_text.split('id="records-left-out"', 1)
        listed = len(left_out) == 2 and f"<td>{_esc(bad_name)}</td>" in left_out[1].split("</table>", 1)[0]
        # (a lone surrogate is written as "?")
        # (an id longer than the report shows is cut)
        shown = isinstance(bad_id, str) and bad_id and _esc(
            bad_id[:MAX_TEXT].encode("utf-8", "replace").decode()) in html_text
        if not unrecognisable:
            assert listed or shown, "the damaged record is neither listed nor shown"
        parser = _Balanced()
        parser.feed(html_text)
        parser.close()
        assert not parser.errors and not parser.stack, f"unbalanced HTML: {parser.errors} {parser.stack[-5:]}"
        assert parser.tags <= ALLOWED_TAGS, f"unexpected tags in the HTML: {parser.tags - ALLOWED_TAGS}"
        prose = re.sub(r"(`+)[^\n]*?\1", "", md)  # inside a code span (an id, a path) text is verbatim, not HTML
        for snippet in ("<script>alert", "<img src=x", "<b>xxx", "<h1>x", "<!--"):
            assert snippet not in prose, f"raw HTML {snippet!r} in report.md"
            assert snippet not in html_text, f"raw HTML {snippet!r} in report.html"

    return check


def _esc(text: str) -> str:
    from html import escape

    return escape(text, quote=True)


#: Every tag the report may contain; anything else came from a record.
ALLOWED_TAGS = {"html", "head", "meta", "title", "style", "body", "h1", "h2", "h3", "h4", "p", "span", "a", "code",
                "pre", "table", "caption", "thead", "tbody", "tr", "th", "td", "ul", "ol", "li", "details", "summary",
                "section", "figure", "img", "figcaption", "strong", "em", "nav", "main", "header", "div", "wbr",
                "small", "script", "noscript", "button", "aside", "sup"}


@fuzz_settings(120, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example])
@given(damaged_records())
def test_report_lists_a_damaged_record_and_shows_the_good_ones(damaged):
    name, raw = damaged
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for good in GOOD:
            shutil.copy(RECORDS / good, folder / good)
        (folder / name).write_bytes(raw)
        try:
            content = json.loads(raw)
        except Exception:  # noqa: BLE001 - whatever the damage
            content = None
        bad_id = content.get("experiment") if isinstance(content, dict) else None
        # a JSON object with none of a record's keys is some other file: ignored (and logged)
        unrecognisable = isinstance(content, dict) and not set(content) & set(RECORD_KEYS)
        assert_typed_or_good("mmconcepts report", lambda: _report(folder),
                             check=_good_report(name, bad_id, unrecognisable))


def test_a_metric_no_float_holds_is_listed_not_a_traceback(tmp_path):
    """Found by the census: a metric of 10**400 (valid JSON) raised OverflowError out of `mmconcepts report`."""
    for good in GOOD:
        shutil.copy(RECORDS / good, tmp_path / good)
    record = dict(BASES[0], experiment="toy-huge", metrics={"a": 10**400})
    (tmp_path / "huge.json").write_text(json.dumps(record))
    code, output, html_text, md = _report(tmp_path)
    assert code == 0 and "Traceback" not in output
    assert "<td>huge.json</td><td>not a valid result record" in html_text and "OverflowError" in html_text
    _good_report("huge.json", "toy-huge", False)((code, output, html_text, md))



@pytest.mark.parametrize("name, raw, reason", [
    # found by the fuzz test before the fixes: each crashed the report or was silently dropped
    ("surrogate.json", json.dumps(BASES[0]).replace('"quick"', '"\\ud800quick"').encode(), "written"),
    ("cesu.json", json.dumps(BASES[0]).encode().replace(b'"quick"', b'"\xed\xa0\x80quick"'), "not valid UTF-8"),
    ("null-id.json", json.dumps(dict(BASES[0], experiment=None)).encode(), "experiment id must be a non-empty string"),
    ("null.json", b"null", "not a valid result record"),
    ("no-id.json", json.dumps({k: v for k, v in BASES[0].items() if k != "experiment"}).encode(),
     "not a valid result record"),
])
def test_damaged_records_found_by_fuzzing(tmp_path, name, raw, reason):
    for good in GOOD:
        shutil.copy(RECORDS / good, tmp_path / good)
    (tmp_path / name).write_bytes(raw)
    code, output, html_text, md = _report(tmp_path)
    assert code == 0 and "Traceback" not in output, output
    if reason == "written":  # a lone surrogate from a JSON escape: shown, written as "?"
        assert "?quick" in md
    else:
        assert f"| {name} | " in md and reason in md.split("### Records left out", 1)[1].split("## Summary", 1)[0]


@pytest.mark.parametrize("text", INJECTED)
def test_markup_in_every_shown_field_stays_text(tmp_path, text):
    """Markup in the fields the report shows (id, title, status, variant, preset, thesis, message) is shown as text."""
    for good in GOOD:
        shutil.copy(RECORDS / good, tmp_path / good)
    fields = ("experiment", "title", "status", "variant", "preset", "thesis_ref", "message")
    record = dict(BASES[0], **{field: text for field in fields})
    (tmp_path / "zz-markup.json").write_text(json.dumps(record))
    check = _good_report("zz-markup.json", text, False)
    notes: list[str] = []
    global note
    saved, note = note, notes.append
    try:
        assert check(_report(tmp_path)), notes
    finally:
        note = saved
