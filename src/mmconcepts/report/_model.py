"""Read result records and turn them into what both report formats show (internal).

What a record shows is bounded, whatever it holds (a record edited by hand can hold 100 000
claims or a 10 MB string): each string is cut at :data:`MAX_TEXT` characters (notes, messages
and tracebacks at :data:`MAX_PROSE`), each list at :data:`MAX_ITEMS` items (a table at
:data:`MAX_COLUMNS` columns), and all the strings of one record together at
:data:`MAX_RECORD_TEXT` characters; the report says what it left out (``… (N more
characters)``, ``N more claims not shown``). A record file larger than :data:`MAX_RECORD_BYTES`
is listed under "Records left out" unread. The work is linear in the size of the records, and a
record renders to a few megabytes at most. No record an experiment writes comes near a limit.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
import stat
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Collection, Iterator, Sequence
from typing import Any, TypeVar

from .._fingerprint import code_fingerprint
from ..errors import ExperimentError
from ..engine.record import RECORD_KEYS, ClaimRecord, ResultRecord
from ..engine.uncertainty import LEVEL, VERDICTS
from ..engine.verdicts import TALLY_KINDS, redecide, tally_claims, verdict_words

logger = logging.getLogger("mmconcepts.report")

#: The most characters of one string of a record shown in a table cell, a heading or a list item (a claim's
#: text, rule or test, a metric's name, a table cell, a warning, a caption); the rest is left out and counted
#: (``… (N more characters)``). The longest such string a run writes is a claim's test (about 1 400 characters).
MAX_TEXT = 8_000

#: The most characters of a note, a table's note, a failure message or a traceback shown (a traceback keeps its
#: end, where the error is: ``(N characters before) …``). The longest a run writes is a traceback (about 3 000).
MAX_PROSE = 20_000

#: The most items of one list of a record shown: claims, metrics, tables, a table's rows, notes, warnings,
#: configuration entries, figures, data sets, concept cards, a card's labels and files, a claim's comparisons.
#: The longest list a run writes is 151 metrics.
MAX_ITEMS = 1_000

#: The most columns of one table shown (a run writes at most 14).
MAX_COLUMNS = 100

#: The most characters all the strings of one record shown add up to, each counted with :data:`MARKUP` more for
#: the markup around it (so that many empty cells are bounded too): once they are spent, the items of every list
#: still to come are left out and counted. A run's record counts 35 000 at most.
MAX_RECORD_TEXT = 1_000_000

#: What each string shown counts for its markup (a table cell, a list item) against :data:`MAX_RECORD_TEXT`.
MARKUP = 20

#: The largest record file read, in bytes; a larger one is listed under "Records left out" (a run writes at most
#: about 100 kB).
MAX_RECORD_BYTES = 32 * 2**20

STATUS_LABELS = {"ok": "ran", "failed": "FAILED", "skipped": "skipped"}
VARIANT_LABELS = {"real": "real data", "synthetic": "generated data"}


def clip(text: str, limit: int, *, tail: bool = False) -> str:
    """``text`` cut to ``limit`` characters, saying how many were left out.

    ``… (N more characters)`` follows the first ``limit`` characters; with ``tail``, the last ``limit`` are kept
    after ``(N characters before) …``.
    """
    if len(text) <= limit:
        return text
    if tail:
        return f"({len(text) - limit} characters before) … {text[len(text) - limit:]}"
    return f"{text[:limit]} … ({len(text) - limit} more characters)"


_T = TypeVar("_T")


class _Shown:
    """What one record shows within the report's bounds: strings cut (:func:`clip`), lists cut at
    :data:`MAX_ITEMS` items, every string charged to the record's :data:`MAX_RECORD_TEXT`; what is left out
    of each list counted in :attr:`omitted` (``{"claims": 9000}``)."""

    def __init__(self) -> None:
        self.left = MAX_RECORD_TEXT
        self.omitted: dict[str, int] = {}

    def text(self, value: Any, *, prose: bool = False, tail: bool = False) -> str:
        """``str(value)`` cut at :data:`MAX_TEXT` (:data:`MAX_PROSE` for ``prose``), charged to the budget."""
        shown = clip(value if isinstance(value, str) else str(value), MAX_PROSE if prose else MAX_TEXT, tail=tail)
        self.left -= len(shown) + MARKUP
        return shown

    def leave_out(self, what: str, n: int) -> None:
        """Count ``n`` more items of ``what`` left out."""
        if n > 0:
            self.omitted[what] = self.omitted.get(what, 0) + n

    def items(self, what: str, items: Collection[_T], *, limit: int | None = None) -> Iterator[_T]:
        """The items of ``items`` while fewer than ``limit`` (:data:`MAX_ITEMS`) are taken and the budget lasts;
        the others counted under ``what``."""
        limit = MAX_ITEMS if limit is None else limit
        taken = 0
        for item in items:
            if taken >= limit or self.left <= 0:
                break
            taken += 1
            yield item
        self.leave_out(what, len(items) - taken)


def format_number(value: Any) -> str:
    """Format a number for a table: 4 significant digits, '' for None, 'n/a' for NaN."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "n/a"
        if value.is_integer() and abs(value) < 1e6:
            return str(int(value))
        return f"{value:.4g}"
    return str(value)


def format_cell(value: Any) -> str:
    """Format a table cell or config value: numbers as :func:`format_number`, lists as JSON."""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return format_number(value)


def format_duration(seconds: Any) -> str:
    """Format a run time: ``0.4 s``, ``2 min 05 s``, ``1 h 02 min``."""
    try:
        s = float(seconds)
    except (TypeError, ValueError):
        return ""
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


#: How the report names each kind of claim, in the order it counts them.
#: The suffix of a metric that is the spread (standard deviation) of another: ``<name>_std``.
SPREAD_SUFFIX = "_std"

KIND_LABELS = {"thesis": "thesis statements", "magnitude": "magnitudes (ours / thesis)", "ours": "our checks",
               "check": "sanity checks (not evidence)", "unclassified": "unclassified (older records)"}


#: The sub-tables of "Every claim on each data", by kind: (kind, heading, what it says).
KIND_SECTIONS = (
    ("thesis", "Thesis statements: which replicate", "Each statement the thesis makes, tested at the thesis' own "
     "comparison, with its verdict on each data and where it holds."),
    ("magnitude", "Magnitudes: our numbers against the thesis'", "Our number divided by the thesis' number, with "
     "its interval: matches (the thesis' number inside our interval), below or above it, or inconclusive."),
    ("ours", "Our checks", "Controls and bars of our own, and the claims of the experiments beyond the thesis: "
     "not the thesis' statements."),
    ("check", "Sanity checks", "Properties of the code kept to show that a run is sane; never evidence."),
    ("unclassified", "Unclassified claims", "Claims of records written before claims had kinds: rerun them."),
)


@dataclass
class ClaimView:
    """One claim of a record as the report shows it: what the record stores, nothing re-decided."""

    text: str
    rule: str
    kind: str = "unclassified"
    source: str = ""
    verdict: str = "not evaluated"
    basis: str = ""
    scope: str = ""
    detail: str = ""
    test: str = ""  # the interval(s) behind the verdict, in words

    @property
    def cell(self) -> str:
        """The verdict with its qualifiers: ``holds (within one fit)``, ``depends (holds only under X)``."""
        notes = []
        if self.detail and (self.verdict not in ("holds", "fails", "inconclusive") or "stored as" in self.detail
                            or "cannot be checked" in self.detail):
            notes.append(self.detail)
        if self.scope:
            notes.append(self.scope)
        if self.basis.startswith("reported numbers") and self.verdict in ("holds", "fails"):
            notes.append("no spread")
        return self.verdict + (f" ({'; '.join(notes)})" if notes else "")


def _signed(value: Any) -> str:
    text = format_number(value)
    return f"+{text}" if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0 else text


def _more(items: Sequence[Any], what: str) -> list[str]:
    """``["N more <what>"]`` for the items of ``items`` past :data:`MAX_ITEMS` (none within it)."""
    return [f"{len(items) - MAX_ITEMS} more {what}"] if len(items) > MAX_ITEMS else []


def _test_text(tests: Sequence[Any]) -> str:
    parts = []
    for t in itertools.islice(tests, MAX_ITEMS):
        if not isinstance(t, dict):
            continue
        comparison = str(t.get("comparison", ""))
        interval = t.get("interval")
        if isinstance(interval, (list, tuple)) and len(interval) == 2:
            parts.append(f"{comparison}: margin {_signed(t.get('margin'))} "
                         f"[{format_number(interval[0])}, {format_number(interval[1])}]")
        elif t.get("note"):
            parts.append(f"{comparison}: margin {_signed(t.get('margin'))} ({t['note']})")
        else:
            parts.append(f"{comparison}: margin {_signed(t.get('margin'))}")
    return "; ".join(parts + _more(tests, "comparisons"))


def claim_test(claim: ClaimRecord) -> str:
    """The test behind a stored claim's verdict, in words: each comparison's margin and its interval, or a
    magnitude's ratio and its interval, or the verdict under each setting."""
    if claim.kind == "magnitude":
        if claim.ratio is None:
            return ""
        text = f"ours / thesis {format_number(claim.ratio)}"
        ri = claim.ratio_interval
        if isinstance(ri, (list, tuple)) and len(ri) == 2:
            text += f" [{format_number(ri[0])}, {format_number(ri[1])}]"
        return text
    if claim.settings:
        return " | ".join([f"{s.get('label', '')}: {s.get('verdict', '')}"
                           + (f" ({_test_text(s.get('tests') or [])})" if s.get("tests") else "")
                           for s in itertools.islice(claim.settings, MAX_ITEMS)] + _more(claim.settings, "settings"))
    return _test_text(claim.tests)


@dataclass
class MediaView:
    """One file of a concept card: its path relative to the results folder, whether it is there, its caption."""

    path: str
    exists: bool
    caption: str = ""
    seconds: str = ""  # a clip's or a motion's duration, formatted ("0.62 s")
    width: int = 0  # an image's size in pixels (0: unknown)
    height: int = 0


@dataclass
class CardView:
    """One card of a run's concept explorer, as the report shows it."""

    title: str
    note: str
    labels: list[tuple[str, str]]  # (label, share as "81 %")
    clips: list[MediaView]
    images: list[MediaView]
    motions: list[MediaView]


#: How the report names what a card lists beyond the limits.
_CARD_ITEMS = "labels and files of concept cards"


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a file (False, not an error, for a name the system refuses: too long, a NUL byte)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _usable(item: Any) -> bool:
    """Whether a card's entry is a dict with a relative path inside the results folder."""
    path = item.get("path") if isinstance(item, dict) else None
    return isinstance(path, str) and bool(path) and not Path(path).is_absolute() and ".." not in Path(path).parts


def _media(items: Any, results_dir: Path, shown: _Shown) -> list[MediaView]:
    """The files a card lists, in the order listed; entries without a usable relative path are left out."""
    out = []
    for item in shown.items(_CARD_ITEMS, [x for x in items if _usable(x)] if isinstance(items, list) else []):
        path = shown.text(item["path"])
        seconds = item.get("seconds")
        size = [item.get(k) for k in ("width", "height")]
        out.append(MediaView(path=path, exists=_is_file(results_dir / path),
                             caption=shown.text(item.get("caption") or ""),
                             seconds=f"{seconds:.2f} s" if isinstance(seconds, (int, float)) else "",
                             width=size[0] if isinstance(size[0], int) else 0,
                             height=size[1] if isinstance(size[1], int) else 0))
    return out


def explorer_cards(explorer: Any, results_dir: Path, shown: _Shown) -> list[CardView]:
    """The cards of a record's ``explorer`` entry (a malformed card is left out; a missing file is marked)."""
    listed = explorer.get("cards") if isinstance(explorer, dict) else None
    cards = [c for c in listed if isinstance(c, dict)] if isinstance(listed, list) else []
    out = []
    for card in shown.items("concept cards", cards):
        labels = [(shown.text(lab.get("label", "")), f"{100 * lab['share']:.0f} %"
                   if isinstance(lab.get("share"), (int, float)) else "")
                  for lab in shown.items(_CARD_ITEMS, [x for x in card.get("labels") or [] if isinstance(x, dict)])]
        out.append(CardView(title=shown.text(card.get("title") or "concept"), note=shown.text(card.get("note") or ""),
                            labels=labels, clips=_media(card.get("clips"), results_dir, shown),
                            images=_media(card.get("images"), results_dir, shown),
                            motions=_media(card.get("motions"), results_dir, shown)))
    return out


@dataclass
class ExperimentView:
    """Everything the report shows for one result record."""

    id: str
    title: str
    thesis_ref: str
    status: str
    message: str | None
    traceback: str | None
    metrics: list[tuple[str, str, str]]  # (name, ours, thesis)
    tables: list[dict[str, Any]]
    figures: list[tuple[str, str, bool]]  # (name, relative path, file exists)
    claims: list[ClaimView]
    config: list[tuple[str, str]]
    run_info: list[tuple[str, str]]
    notes: list[str]
    source: str
    elapsed: str = ""
    extra_keys: list[str] = field(default_factory=list)
    variant: str = "synthetic"
    data: list[tuple[str, str]] = field(default_factory=list)  # (set name, path)
    values: dict[str, str] = field(default_factory=dict)  # metric -> "0.81 [0.75, 0.87]"
    warnings: list[str] = field(default_factory=list)
    stale: bool = False  # produced by other code than the installed one
    preset: str = ""
    code: str = ""
    seed: str = ""
    cards: list[CardView] = field(default_factory=list)  # the concept explorer
    explorer_note: str = ""
    omitted: dict[str, int] = field(default_factory=dict)  # what the record holds past the report's limits
    digest_ok: bool | None = True  # False: edited after it was written; None: a record without a digest (older)
    elapsed_s: float | None = None  # the run's wall time in seconds, as recorded
    started_at: str = ""  # when it started (ISO 8601, UTC), as recorded

    def left_out(self, *whats: str) -> str:
        """``9000 more claims, 7 more notes``: what of ``whats`` (default: everything) the report leaves out."""
        return ", ".join(f"{n} more {what}" for what, n in self.omitted.items() if n and (not whats or what in whats))

    @property
    def status_label(self) -> str:
        label = STATUS_LABELS.get(self.status, self.status) + (" (older code)" if self.stale else "")
        if self.digest_ok is None:
            return f"{label} (unverified: no digest)"
        return label if self.digest_ok else f"{label} (edited after it was written: it does not match its digest)"

    @property
    def n_claims(self) -> int:
        return len(self.claims)

    def count(self, verdict: str, kind: str | None = None) -> int:
        return sum(c.verdict == verdict and (kind is None or c.kind == kind) for c in self.claims)

    def tally(self) -> dict[str, dict[str, int]]:
        """Its claims counted by kind, then verdict (all "not evaluated" when the run did not run)."""
        return tally_claims({"kind": c.kind, "verdict": c.verdict if self.status == "ok" else "not evaluated"}
                            for c in self.claims)

    @property
    def data_label(self) -> str:
        """``real data (fsdd, eth80)`` or ``generated data``."""
        label = VARIANT_LABELS.get(self.variant, self.variant)
        return f"{label} ({', '.join(n for n, _ in self.data)})" if self.data else label

    @property
    def data_sets(self) -> str:
        """The real sets' names (``fsdd, eth80``), or ``generated`` for generated data."""
        return ", ".join(n for n, _ in self.data) if self.data else ("generated" if self.variant == "synthetic" else "")

    def verdict_counts(self) -> dict[str, int]:
        """How many claims got each verdict word, all kinds together (all ``not evaluated`` when it did not run)."""
        words = list(dict.fromkeys(w for kind in TALLY_KINDS for w in verdict_words(kind)))
        if self.status != "ok":
            return {v: (self.n_claims if v == "not evaluated" else 0) for v in words}
        return {v: self.count(v) for v in words}

    def kind_summary(self, kind: str) -> str:
        """``2 holds, 1 fails`` for the claims of ``kind`` ('' when it has none)."""
        counts = self.tally().get(kind)
        if not counts:
            return ""
        return ", ".join(f"{n} {v}" for v, n in counts.items() if n)

    @property
    def claims_summary(self) -> str:
        if not self.claims:
            return "no claims"
        if self.status != "ok":
            return f"{self.n_claims} not evaluated"
        return "; ".join(f"{kind}: {self.kind_summary(kind)}" for kind in self.tally())


@dataclass
class ExperimentGroup:
    """One experiment's runs: on real data first, then on generated data."""

    id: str
    title: str
    thesis_ref: str
    views: list[ExperimentView]

    def metric_rows(self) -> tuple[list[str], list[list[str]]]:
        """Columns ``metric, thesis, <one per run>`` and one row per metric (values with their interval).

        A metric's spread (the metric ``<name>_std`` beside ``<name>``) is shown in its value's
        cell (``0.81 [0.75, 0.87], sd 0.04``), not as a row of its own; the ``thesis`` column is
        there only when the thesis has a number for one of the metrics.
        """
        reference: dict[str, str] = {}
        seen: dict[str, None] = {}  # the names in order of appearance (a dict: a list's `in` is linear)
        spreads: list[dict[str, str]] = []
        for view in self.views:
            spreads.append({name: ours for name, ours, _ in view.metrics})
            for name, _ours, thesis in view.metrics:
                seen.setdefault(name)
                if thesis and name not in reference:
                    reference[name] = thesis
        names = [n for n in seen if not (n.endswith(SPREAD_SUFFIX) and n[: -len(SPREAD_SUFFIX)] in seen)]

        def cell(view: ExperimentView, spread: dict[str, str], name: str) -> str:
            value, sd = view.values.get(name, ""), spread.get(name + SPREAD_SUFFIX, "")
            return f"{value}, sd {sd}" if value and sd else value

        has_thesis = any(reference.get(n) for n in names)
        columns = ["metric"] + (["thesis"] if has_thesis else []) + [v.data_label for v in self.views]
        rows = [[n] + ([reference.get(n, "")] if has_thesis else [])
                + [cell(v, sp, n) for v, sp in zip(self.views, spreads)] for n in names]
        return columns, rows

    def claim_rows(self) -> tuple[list[str], list[list[str]]]:
        """Columns ``claim, kind, thesis source, rule, <verdict per run>, <test per run>``."""
        labels = [v.data_label for v in self.views]
        columns = ["claim", "kind", "thesis source", "rule"] + labels + [f"test on {label}" for label in labels]
        rows: list[list[str]] = []
        index: dict[tuple[str, str], int] = {}
        n = len(self.views)
        for j, view in enumerate(self.views):
            for claim in view.claims:
                key = (claim.text, claim.rule)
                if key not in index:
                    index[key] = len(rows)
                    rows.append([claim.text, claim.kind, claim.source, claim.rule] + [""] * (2 * n))
                rows[index[key]][4 + j] = claim.cell if view.status == "ok" else "not evaluated"
                rows[index[key]][4 + n + j] = claim.test if view.status == "ok" else ""
        return columns, rows


def _claims(record: ResultRecord, shown: _Shown) -> list[ClaimView]:
    """The claims as the record stores them (the verdicts were decided when the record was made).

    Each stored verdict is checked against the record's own numbers: one that they do not give (a record edited by
    hand) is shown with what they give, and logged; a claim that cannot be checked is shown with why.
    """
    views = []
    for claim in shown.items("claims", record.claims):
        ok = record.status == "ok"
        view = ClaimView(
            text=shown.text(claim.text), rule=shown.text(claim.rule), kind=shown.text(claim.kind or "unclassified"),
            source=shown.text(claim.source or ""), verdict=shown.text(claim.verdict) if ok else "not evaluated",
            basis=shown.text(claim.basis or ""), scope=shown.text(claim.scope or ""),
            detail=shown.text(claim.detail or ""), test=shown.text(claim_test(claim)) if ok else "")
        if ok and view.kind != "unclassified":
            try:
                again = redecide(claim, metrics=record.metrics, samples=record.samples, reference=record.reference,
                                 units=record.sample_units, unit_kinds=record.units)
            except (ExperimentError, TypeError, ValueError, KeyError) as exc:
                view.detail = shown.text(f"cannot be checked: {(str(exc).splitlines() or [''])[0]}")
                view.verdict = "not evaluated"
            else:
                if again != view.verdict:
                    logger.warning("%s: claim %r is stored as %r but the record's numbers give %r",
                                   str(record.experiment)[:200], view.text[:200], view.verdict, again)
                    view.detail = f"stored as {view.verdict}; the record's numbers give {again}"
                    view.verdict = again
        views.append(view)
    return views


def _with_interval(value: Any, interval: Any) -> str:
    text = format_number(value)
    if isinstance(interval, (list, tuple)) and len(interval) == 2 and text:
        text += f" [{format_number(interval[0])}, {format_number(interval[1])}]"
    return text


def _check_shown_fields(record: ResultRecord) -> None:
    """Raise :class:`ExperimentError` when a field the report is organised by has the wrong type."""
    if not isinstance(record.experiment, str) or not record.experiment.strip():
        raise ExperimentError(f"its experiment id must be a non-empty string; got {record.experiment!r:.60}")
    for key in ("status", "variant"):
        value = getattr(record, key)
        if not isinstance(value, str):
            raise ExperimentError(f"its {key} must be a string; got {value!r:.60}")


def _table_view(name: Any, table: Any, shown: _Shown) -> dict[str, Any]:
    """One table as the report shows it: its rows cut at :data:`MAX_ITEMS`, its columns at :data:`MAX_COLUMNS`
    (``left_out`` says how many more there are: ``7 more rows, 2 more columns``)."""
    width = max([len(table.columns)] + [len(row) for row in table.rows])
    rows = [[shown.text(format_cell(c)) for c in itertools.islice(row, MAX_COLUMNS)]
            for row in shown.items("rows", table.rows)]
    shown.leave_out("columns", width - MAX_COLUMNS)
    return {"name": shown.text(name), "title": shown.text(table.title or name),
            "columns": [shown.text(c) for c in itertools.islice(table.columns, MAX_COLUMNS)], "rows": rows,
            "note": shown.text(table.note or "", prose=True),
            "left_out": ", ".join(f"{n} more {what}" for what, n in (("rows", len(table.rows) - len(rows)),
                                                                     ("columns", width - MAX_COLUMNS)) if n > 0)}


def build_view(record: ResultRecord, results_dir: Path, source: Path) -> ExperimentView:
    """Turn one result record into an :class:`ExperimentView`, within the report's bounds (see the module)."""
    _check_shown_fields(record)
    shown = _Shown()
    metrics, reference, data, intervals = record.metrics, record.reference, record.data, record.intervals
    text = shown.text
    # the fields shown whatever the budget, charged first
    exp_id, title = text(record.experiment), text(record.title or record.experiment)
    thesis_ref = text(record.thesis_ref or "")
    status, variant = text(record.status), text(record.variant or ("real" if data else "synthetic"))
    message = None if record.message is None else text(record.message, prose=True)
    traceback = None if record.traceback is None else text(record.traceback, prose=True, tail=True)
    preset, code, seed = text(record.preset), text(record.code or ""), text(format_cell(record.seed))
    explorer_note = text(record.explorer.get("note") or "", prose=True)
    run_info = [
        ("data", VARIANT_LABELS.get(record.variant, variant if record.variant else "")),
        ("preset", preset),
        ("seed", seed),
        ("run time", format_duration(record.elapsed_s)),
        ("started at", text(record.started_at)),
        ("mmconcepts version", text(record.version)),
        ("code fingerprint", code),
        ("python", text(record.python)),
        ("platform", text(record.platform)),
    ]
    claims = _claims(record, shown)
    # the metrics first, then the thesis' numbers that have no metric
    names = list(metrics) + [name for name in reference if name not in metrics]
    rows, values = [], {}
    for name in shown.items("metrics", names):
        label = text(name)
        if name in metrics:
            rows.append((label, format_number(metrics[name]), format_number(reference.get(name))))
            values[label] = _with_interval(metrics[name], intervals.get(name))
        else:
            rows.append((label, "", format_number(reference[name])))
    tables = [_table_view(name, table, shown) for name, table in shown.items("tables", record.tables.items())]
    figures = []
    for name, rel in shown.items("figures", record.figures.items()):
        path = text(rel)
        figures.append((text(name), path, _is_file(results_dir / path)))
    notes = [text(n, prose=True) for n in shown.items("notes", record.notes)]
    warnings = [text(w) for w in shown.items("warnings", record.warnings)]
    config = [(text(k), text(format_cell(v))) for k, v in shown.items("configuration entries", record.config.items())]
    data_sets = [(text(k), text(v)) for k, v in shown.items("data sets", data.items())]
    run_info += [(f"data: {name}", path) for name, path in data_sets]
    cards = explorer_cards(record.explorer, results_dir, shown)
    return ExperimentView(
        id=exp_id,
        title=title,
        thesis_ref=thesis_ref,
        status=status,
        message=message,
        traceback=traceback,
        metrics=rows,
        tables=tables,
        figures=figures,
        claims=claims,
        config=config,
        run_info=run_info,
        notes=notes,
        source=source.name,
        elapsed=format_duration(record.elapsed_s),
        extra_keys=sorted(str(k)[:MAX_TEXT] for k in itertools.islice(record.extra, MAX_ITEMS)),  # not shown
        variant=variant,
        data=data_sets,
        values=values,
        warnings=warnings,
        stale=record.code != code_fingerprint(),
        preset=preset,
        code=code,
        seed=seed,
        cards=cards,
        explorer_note=explorer_note,
        omitted=shown.omitted,
        digest_ok=record.digest_ok,
        elapsed_s=_seconds(record.elapsed_s),
        started_at=text(record.started_at),
    )


def _seconds(value: Any) -> float | None:
    """A recorded run time as a finite number of seconds >= 0, else None."""
    try:
        s = float(value)
    except (TypeError, ValueError):
        return None
    return s if math.isfinite(s) and s >= 0 else None


def _looks_like_a_record(raw: bytes) -> bool:
    """Whether a JSON file that is no valid record was meant to be one (a damaged record,
    listed in the report) rather than some other JSON file of the folder (ignored)."""
    try:
        content = json.loads(raw)
    except (ValueError, RecursionError):  # not JSON (truncated, edited): shown as unreadable
        return True
    if not isinstance(content, dict):  # a record edited into a list, a number, null...
        return True
    return any(key in content for key in RECORD_KEYS)


class _TooLarge(Exception):
    """A record file larger than :data:`MAX_RECORD_BYTES`."""


def _read(path: Path) -> bytes:
    """The bytes of ``path``, at most :data:`MAX_RECORD_BYTES` + 1 of them (more: a file too large to show).

    Raises
    ------
    OSError
        If it cannot be read, or is a pipe or a device (whose reading might never end).
    """
    info = path.stat()
    if not stat.S_ISREG(info.st_mode) and not stat.S_ISDIR(info.st_mode):  # a directory: the error of open() below
        raise OSError("not a regular file (a pipe or a device)")
    with path.open("rb") as fh:
        # read(n) makes room for n bytes first: ask for what the file holds, then for what it grew by, if anything
        chunks = [fh.read(min(info.st_size, MAX_RECORD_BYTES) + 1)]
        size = len(chunks[0])
        while chunks[-1] and size <= MAX_RECORD_BYTES:
            chunks.append(fh.read(min(2**20, MAX_RECORD_BYTES + 1 - size)))
            size += len(chunks[-1])
    return chunks[0] if len(chunks) == 1 else b"".join(chunks)


def collect(results_dir: Path, problems: list[tuple[str, str]] | None = None) -> list[ExperimentView]:
    """Read every result record of ``results_dir``, sorted by experiment id (real data first).

    A record that cannot be read or shown (truncated, edited by hand) does not stop the
    others: it is logged and, when ``problems`` is given, appended to it as
    ``(file name, reason)``, as is a file larger than :data:`MAX_RECORD_BYTES` that starts like a
    record. JSON files that are not result records are ignored (logged).
    """
    views = []
    for path in sorted(results_dir.glob("*.json")):
        try:
            raw = _read(path)
            if len(raw) > MAX_RECORD_BYTES:
                if not any(key in raw[:65536] for key in (b'"schema_version"', b'"experiment"')):
                    logger.info("ignoring %s: larger than %d bytes and not a result record", path, MAX_RECORD_BYTES)
                    continue
                raise _TooLarge(f"larger than the report reads (more than {MAX_RECORD_BYTES} bytes; an experiment "
                                "writes records of a few hundred kB at most): not shown; open the file itself")
            record = ResultRecord.from_json(raw.decode("utf-8"))  # strict: json.loads(bytes) lets surrogates in
        except _TooLarge as exc:
            reason = str(exc)
        except OSError as exc:
            reason = f"cannot be read ({exc.strerror or exc})"
        except UnicodeDecodeError as exc:
            reason = f"not valid UTF-8 text ({exc.reason} at byte {exc.start})"
        except (ExperimentError, RecursionError) as exc:
            logger.info("ignoring %s: not a result record (%s)", path, exc)
            if not _looks_like_a_record(raw):
                continue
            reason = f"not a valid result record: {exc}"
        except Exception as exc:  # noqa: BLE001 -- e.g. OverflowError from a metric of 10**400: never a traceback
            reason = f"not a valid result record ({type(exc).__name__}: {exc})"
        else:
            try:
                views.append(build_view(record, results_dir, path))
                continue
            except Exception as exc:  # noqa: BLE001 -- a record edited by hand must not take the report down
                reason = f"a result record that cannot be shown ({type(exc).__name__}: {exc})"
        reason = clip(reason, MAX_TEXT)  # an exception can quote a huge value
        logger.warning("%s: left out of the report: %s", path, reason)
        if problems is not None:
            problems.append((path.name, reason))
    views.sort(key=lambda v: (v.id, v.variant != "real"))
    return views


def group(views: list[ExperimentView]) -> list[ExperimentGroup]:
    """Group the views of one experiment (as :func:`collect` sorts them)."""
    groups: dict[str, ExperimentGroup] = {}
    for view in views:
        if view.id not in groups:
            groups[view.id] = ExperimentGroup(view.id, view.title, view.thesis_ref, [])
        groups[view.id].views.append(view)
    return list(groups.values())


def _replicates(cells: dict[str, str], variants: list[str]) -> str:
    """Where a thesis statement holds: ``both``, ``real data only``, ``generated data only`` or ``neither``."""
    held = [v for v in variants if cells.get(v, "").split(" (")[0] == "holds"]
    ran = [v for v in variants if cells.get(v)]
    if len(ran) < 2:
        return "holds" if held else ("not run" if not ran else "does not hold")
    if len(held) == len(ran):
        return "both"
    if held:
        return f"{VARIANT_LABELS[held[0]]} only"
    return "neither"


def claims_by_data(views: list[ExperimentView], kind: str | None = None) -> tuple[list[str], list[list[str]]]:
    """Every claim (of ``kind``, or all) of the runs that ran, with its verdict on each data: one row per claim.

    Columns ``experiment, claim, kind, thesis source, <one per data variant present>, agreement``; for thesis
    statements the last column is where they hold (``both``, ``real data only``, ``generated data only``,
    ``neither``), for the other kinds whether the verdicts on real and generated data agree (``same`` /
    ``differ``; empty when decided on one data only). Rows where the verdicts differ come first, then the others,
    each in experiment order.
    """
    variants = [v for v in ("real", "synthetic") if any(x.variant == v and x.status == "ok" for x in views)]
    last = "replicates on" if kind == "thesis" else "agreement"
    columns = ["experiment", "claim", "kind", "thesis source"] + [VARIANT_LABELS[v] for v in variants] + [last]
    rows: list[list[str]] = []
    cells: list[dict[str, str]] = []
    index: dict[tuple[str, str, str], int] = {}
    for view in views:
        if view.status != "ok" or view.variant not in variants:
            continue
        j = variants.index(view.variant)
        for claim in view.claims:
            if kind is not None and claim.kind != kind:
                continue
            key = (view.id, claim.text, claim.rule)
            if key not in index:
                index[key] = len(rows)
                rows.append([view.id, claim.text, claim.kind, claim.source] + [""] * len(variants) + [""])
                cells.append({})
            rows[index[key]][4 + j] = claim.cell
            cells[index[key]][view.variant] = claim.cell
    for row, by_variant in zip(rows, cells):
        if kind == "thesis":
            row[-1] = _replicates(by_variant, variants)
        else:
            decided = [c.split(" (")[0] for c in row[4:4 + len(variants)] if c]
            if len(decided) == 2:
                row[-1] = "same" if decided[0] == decided[1] else "differ"
    differ = ("real data only", "generated data only", "differ")
    order = sorted(range(len(rows)), key=lambda i: (rows[i][-1] not in differ, i))
    return columns, [rows[i] for i in order]


def chance_line(views: list[ExperimentView]) -> list[str]:
    """Per data: how many thesis-statement "holds" chance alone would give at the level used (plain text)."""
    alpha = (1 - LEVEL) / 2
    lines = []
    for variant in ("real", "synthetic"):
        decided = [c for v in views if v.variant == variant and v.status == "ok" for c in v.claims
                   if c.kind == "thesis" and c.verdict != "not evaluated"]
        if decided:
            held = sum(c.verdict == "holds" for c in decided)
            lines.append(
                f"On {VARIANT_LABELS[variant]}: {held} of {len(decided)} thesis statements hold. A comparison is called "
                f"\"holds\" when its {LEVEL * 100:g} % two-sided interval lies wholly on its side, so where there were no true "
                f"difference at all, chance alone would make about {len(decided)} x {alpha:g} = "
                f"{len(decided) * alpha:.1f} of them hold.")
    return lines


def slug(text: str) -> str:
    """The anchor of an experiment: ``exp-`` and its id, every character but ASCII letters, digits and ``-`` as ``-``."""
    return "exp-" + slug_part(text)


def slug_part(text: str) -> str:
    """``text`` with every character but ASCII letters, digits and ``-`` as ``-`` (safe in an id and a URL)."""
    return "".join(c if (c.isascii() and c.isalnum()) or c == "-" else "-" for c in str(text))


class _Anchors:
    """Hands out unique element ids (a second ``exp-a`` becomes ``exp-a-2``)."""

    def __init__(self, reserved: Sequence[str] = ()) -> None:
        self.used: set[str] = set(reserved)
        self.last: dict[str, int] = {}  # base -> the last n tried (ids are never freed: no smaller n is free)

    def make(self, base: str) -> str:
        n = self.last.get(base, 1)
        anchor = base if n == 1 else f"{base}-{n}"
        while anchor in self.used:
            n += 1
            anchor = f"{base}-{n}"
        self.used.add(anchor)
        self.last[base] = n
        return anchor


class Plan:
    """The anchors (element ids) of one report, decided before any link to them is written.

    Both formats use the same ones: ``exp-<id>`` per experiment, ``exp-<id>-claim-<n>`` per
    claim, ``exp-<id>-<variant>`` per run, ``...-table-<name>`` and ``...-fig-<name>`` per
    table and figure, ``...-explorer`` and ``...-card-<n>`` for a run's concept explorer and its
    cards (``-2``, ``-3`` appended where two would coincide).
    """

    def __init__(self, groups: list[ExperimentGroup]) -> None:
        self.groups = groups
        self.section_of: dict[str, str] = {}  # experiment id -> its section's anchor
        anchors = _Anchors(["toc", "top", "summary", "claims", "records-left-out", "main"])
        self.section: dict[int, str] = {}
        self.claim: dict[tuple[int, int], str] = {}
        self.claim_by_text: dict[tuple[str, str], str] = {}
        self.run: dict[int, str] = {}
        self.table: dict[tuple[int, int], str] = {}
        self.figure: dict[tuple[int, int], str] = {}
        self.explorer: dict[int, str] = {}
        self.card: dict[tuple[int, int], str] = {}
        for g in groups:
            self.section[id(g)] = sec = anchors.make(slug(g.id))
            self.section_of.setdefault(g.id, sec)
            for i, row in enumerate(g.claim_rows()[1]):
                self.claim[(id(g), i)] = anchor = anchors.make(f"{sec}-claim-{i + 1}")
                self.claim_by_text.setdefault((g.id, row[0]), anchor)
            for view in g.views:
                self.run[id(view)] = run = anchors.make(f"{sec}-{slug_part(view.variant)}")
                for j, table in enumerate(view.tables):
                    self.table[(id(view), j)] = anchors.make(f"{run}-table-{slug_part(table['name'])}")
                for j, (name, _rel, _ok) in enumerate(view.figures):
                    self.figure[(id(view), j)] = anchors.make(f"{run}-fig-{slug_part(name)}")
                if view.cards:
                    self.explorer[id(view)] = anchors.make(f"{run}-explorer")
                for j in range(len(view.cards)):
                    self.card[(id(view), j)] = anchors.make(f"{run}-card-{j + 1}")


def variant_summaries(views: "list[ExperimentView]") -> list[tuple[str, str]]:
    """One summary line per variant with runs, as ``(variant label, text)``; the text is plain (not escaped).

    E.g. ``("generated data", "5 run(s) ran (1 failed); thesis statements: 7 holds, 2 fails; magnitudes: 1
    below; ...")``: the claims counted by kind, never together.
    """
    lines = []
    for variant in ("real", "synthetic"):
        runs = [v for v in views if v.variant == variant]
        if runs:
            ran = [v for v in runs if v.status == "ok"]
            tally = tally_claims({"kind": c.kind, "verdict": c.verdict} for v in ran for c in v.claims)
            counts = "; ".join(f"{KIND_LABELS[kind]}: " + (", ".join(f"{n} {w}" for w, n in c.items() if n) or "none")
                               for kind, c in tally.items())
            others = ", ".join(f"{n} {label}" for label, n in (
                ("failed", sum(v.status == "failed" for v in runs)), ("skipped", sum(v.status == "skipped" for v in runs)))
                if n)
            left = sum(v.omitted.get("claims", 0) for v in ran)
            lines.append((VARIANT_LABELS[variant], f"{len(ran)} run(s) ran" + (f" ({others})" if others else "")
                          + (f"; {counts}" if counts else "; no claims")
                          + (f"; {left} more claims past the report's limits neither shown nor counted" if left
                             else "")))
    return lines


def kind_tally_rows(views: "list[ExperimentView]") -> tuple[list[str], list[list[str]]]:
    """The summary's table of tallies: one row per kind of claim and data, one column per verdict word.

    Columns ``kind, data, <verdict words of that kind>`` as one text cell (``3 holds, 1 fails, ...``), so that
    thesis statements, magnitudes, our checks and sanity checks are never added together.
    """
    rows = []
    for kind in TALLY_KINDS:
        for variant in ("real", "synthetic"):
            ran = [v for v in views if v.variant == variant and v.status == "ok"]
            counts = tally_claims({"kind": c.kind, "verdict": c.verdict} for v in ran for c in v.claims).get(kind)
            if counts:
                rows.append([KIND_LABELS[kind], VARIANT_LABELS[variant], str(sum(counts.values()))]
                            + [", ".join(f"{n} {w}" for w, n in counts.items())])
    return ["kind", "data", "claims", "verdicts"], rows
