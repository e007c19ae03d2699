"""Render the report as Markdown (GitHub-flavoured tables, figures as relative images, a concept
explorer as a list of links to its files).

The same structure as the HTML report where Markdown can: a contents list, a summary, one
section per experiment, each with a link back to the summary, and an anchor (an empty
``<a id="...">``, the ids of the HTML report) before every experiment, run, table, figure
and claim. Text from a record is escaped: no HTML from a record reaches the file.
"""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Sequence
from urllib.parse import quote

from .. import __version__
from ..engine.verdicts import TALLY_KINDS
from ._model import (KIND_SECTIONS, VARIANT_LABELS, ExperimentGroup, ExperimentView, MediaView, Plan, chance_line,
                     claims_by_data, group, kind_tally_rows, variant_summaries)

__all__ = ["render_markdown"]


def _cell(text: object) -> str:
    """Escape a table cell: pipes, backslashes, newlines and angle brackets."""
    s = str(text).replace("\\", "\\\\").replace("|", "\\|")
    s = s.replace("<", "&lt;").replace(">", "&gt;")
    return " ".join(s.splitlines()) if s else " "


def _text(text: object) -> str:
    """Escape prose so that HTML in it is shown, not interpreted."""
    return str(text).replace("<", "&lt;").replace(">", "&gt;")


def _code(text: object) -> str:
    """An inline code span that holds ``text`` verbatim (HTML in it is not interpreted).

    CommonMark: the fence is one backtick longer than the longest run of backticks inside,
    padded with a space when the text starts or ends with a backtick; a newline would end
    the table row or paragraph, so it becomes a space.
    """
    s = " ".join(str(text).splitlines())
    longest = max((len(run) for run in re.findall(r"`+", s)), default=0)
    fence = "`" * (longest + 1)
    pad = " " if s.startswith("`") or s.endswith("`") else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def _table(columns: list[str], rows: list[list[str]], *, raw: int = 0) -> list[str]:
    """A GFM table; the first ``raw`` cells of each row are table-ready Markdown already (pipes escaped)."""
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    for row in rows:
        cells = [c if i < raw else _cell(c) for i, c in enumerate(row)]
        out.append("| " + " | ".join(cells) + " |")
    return out + [""]


def _anchor(anchor: str) -> str:
    """An empty HTML anchor; ``anchor`` comes from :class:`Plan` (ASCII letters, digits, ``-``)."""
    return f'<a id="{anchor}"></a>'


def _link(text: str, anchor: str, *, cell: bool = False) -> str:
    """``[text](#anchor)`` with ``text`` as a code span (so nothing in it is markup); ``cell``: for a table cell."""
    code = _code(text)
    return f"[{code.replace('|', chr(92) + '|') if cell else code}](#{anchor})"


def _run(view: ExperimentView, plan: Plan) -> list[str]:
    meta = f"status: **{_text(view.status_label)}**"
    if view.elapsed:
        meta += f" · {view.elapsed}"
    out = [_anchor(plan.run[id(view)]), f"### On {_text(view.data_label)}", "", meta, ""]
    if view.data:
        out += [f"- data set {_code(name)}: {_code(path)}" for name, path in view.data] + [""]
    if view.omitted:
        out += [_left_out(view), ""]
    if view.status == "failed":
        out += [f"**Failed:** {_text(view.message or '')}", ""]
        if view.traceback:
            out += ["```", view.traceback.rstrip("\n").replace("```", "` ` `"), "```", ""]
    elif view.status == "skipped":
        out += [f"**Skipped:** {_text(view.message or '')}", ""]
    for j, table in enumerate(view.tables):
        out += [_anchor(plan.table[(id(view), j)]), f"#### Table: {_text(table['title'])}", ""]
        out += _table(table["columns"], table["rows"])
        if table.get("left_out"):
            out += [f"*{_text(table['left_out'])} not shown; see the record {_code(view.source)}.*", ""]
        if table["note"]:
            out += [f"*{_text(table['note'])}*", ""]
    for j, (name, rel, exists) in enumerate(view.figures):
        out += [_anchor(plan.figure[(id(view), j)])]
        if exists:
            out += [f"![figure {_text(name)}]({quote(rel, safe='/')})", "", f"*Figure {_code(name)}*", ""]
        else:
            out += [f"*Figure {_code(name)}: file missing ({_code(rel)})*", ""]
    if view.cards:
        out += _explorer(view, plan)
    if view.notes:
        out += ["#### Notes", ""] + [f"- {_text(n)}" for n in view.notes] + [""]
    if view.warnings:
        out += ["#### Warnings during the run (skipped files, ...)", ""] + [f"- {_text(w)}" for w in view.warnings] + [""]
    if view.config:
        out += ["#### Configuration", ""] + _table(["parameter", "value"], [list(r) for r in view.config])
    out += ["#### Run", ""] + _table(["", ""], [list(r) for r in view.run_info])
    out += [f"Record: {_code(view.source)}", ""]
    return out


def _left_out(view: ExperimentView, *whats: str) -> str:
    """What of ``whats`` (default: everything) the record holds past the report's limits, as a note ('' if none)."""
    left = view.left_out(*whats)
    if not left:
        return ""
    where = f"On {_text(view.data_label)}: " if whats else "Past the report's limits, "
    return f"*{where}{left} not shown; see the record {_code(view.source)}.*"


def _files(what: str, media: list[MediaView]) -> str:
    """``clips: [1](a.wav) [2](b.wav)``; a missing file named instead of linked."""
    links = [f"[{k}]({quote(m.path, safe='/')})" if m.exists else f"{k} (missing: {_code(m.path)})"
             for k, m in enumerate(media, start=1)]
    return f"{what}: " + " ".join(links) if links else ""


def _explorer(view: ExperimentView, plan: Plan) -> list[str]:
    """The concept explorer as a compact list: per card its labels and links to its files."""
    out = [_anchor(plan.explorer[id(view)]), "#### Concept explorer", ""]
    if view.explorer_note:
        out += [_text(view.explorer_note), ""]
    for j, card in enumerate(view.cards):
        labels = ", ".join(f"{_text(label)} ({share})" if share else _text(label) for label, share in card.labels)
        parts = [p for p in (f"aligned with {labels}" if labels else "", _files("clips", card.clips),
                             _files("images", card.images), _files("motion", card.motions)) if p]
        out.append(f"- {_anchor(plan.card[(id(view), j)])}**{_text(card.title)}**: " + " · ".join(parts))
    return out + [""]


def _section(g: ExperimentGroup, plan: Plan) -> list[str]:
    sec = plan.section[id(g)]
    out = [_anchor(sec), f"## {_text(g.title)}", "", f"{_code(g.id)} · thesis: {_text(g.thesis_ref or '—')}", "",
           "[↑ back to the summary](#summary)", ""]
    columns, rows = g.claim_rows()
    if rows:
        cells = [[_anchor(plan.claim[(id(g), i)])] + row for i, row in enumerate(rows)]
        out += ["### Claims", "", "Each verdict is what the interval in its test column says (95 %, two-sided; see "
                "the README, *What a verdict means*).", ""] + _table(["#", *columns], cells, raw=1)
    out += [line for view in g.views if view.omitted.get("claims") for line in (_left_out(view, "claims"), "")]
    columns, rows = g.metric_rows()
    if rows:
        out += ["### Numbers: the thesis' and ours, on each data (95 % interval where there are folds or seeds)", ""]
        out += _table(columns, rows)
    out += [line for view in g.views if view.omitted.get("metrics") for line in (_left_out(view, "metrics"), "")]
    for view in g.views:
        out += _run(view, plan)
    out += ["[↑ back to the summary](#summary)", ""]
    return out


def _contents(groups: list[ExperimentGroup], plan: Plan, *, problems: bool, claims: bool) -> list[str]:
    out = ["## Contents", "", "- [Summary](#summary)"]
    if problems:
        out.append("- [Records left out](#records-left-out)")
    if claims:
        out.append("- [Every claim on each data](#claims)")
    for g in groups:
        runs = "; ".join(f"{VARIANT_LABELS.get(v.variant, _text(v.variant))}: "
                         + (v.claims_summary if v.status == "ok" else _text(v.status_label)) for v in g.views)
        out.append(f"- {_link(g.id, plan.section[id(g)])}: {_text(g.title)} ({runs})")
    return out + [""]


def _summary(views: list[ExperimentView], plan: Plan) -> list[str]:
    out = [_anchor("summary"), "## Summary", "",
           "One row per run: whether it ran, on which data, and the verdicts of its claims, counted apart by kind "
           "(as stored in the record).", ""]
    kinds = [k for k in TALLY_KINDS if any(c.kind == k for v in views for c in v.claims)]
    rows = []
    for g in plan.groups:
        for view in g.views:
            summaries = [view.kind_summary(k) if view.status == "ok" else "" for k in kinds]
            rows.append([_link(view.id, plan.run[id(view)], cell=True), view.title, view.data_label, view.status_label]
                        + summaries + [view.elapsed])
    out += _table(["experiment", "title", "data", "ran", *kinds, "run time"], rows, raw=1)
    columns, rows = kind_tally_rows(views)
    if rows:
        out += ["### Tallies by kind of claim", ""] + _table(columns, rows)
    for label, text in variant_summaries(views):
        out.append(f"- On {label}: {text}.")
    out.append("")
    for line in chance_line(views):
        out.append(f"- {_text(line)}")
    out.append("")
    if any(claims_by_data(views)[1]):
        out += [_anchor("claims"), "### Every claim on each data", "",
                "By kind of claim; within each table, the claims whose verdict differs between real and generated data "
                "come first. Each claim links to its experiment's section, with the numbers and intervals behind the "
                "verdict.", ""]
        for kind, heading, what in KIND_SECTIONS:
            columns, rows = claims_by_data(views, kind)
            if not rows:
                continue
            out += [f"#### {heading}", "", what, ""]
            linked = []
            for row in rows:
                target = plan.claim_by_text.get((row[0], row[1])) or plan.section_of.get(row[0], "summary")
                linked.append([_link(row[0], plan.section_of.get(row[0], "summary"), cell=True),
                               f"[{_cell(row[1]).replace('[', '&#91;').replace(']', '&#93;')}](#{target})"] + row[3:])
            out += _table([columns[0], columns[1]] + columns[3:], linked, raw=2)
    return out


def render_markdown(views: list[ExperimentView], *, title: str, problems: Sequence[tuple[str, str]] = ()) -> str:
    """Return the whole Markdown report for ``views`` (``problems``: records left out, as (file, reason))."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    groups = group(views)
    plan = Plan(groups)
    out = [f"# {_text(title)}", "", f"Generated {now} by mmconcepts {__version__} · {len(groups)} experiment(s), "
           f"{len(views)} run(s)", ""]
    if views:
        out += _contents(groups, plan, problems=bool(problems), claims=bool(claims_by_data(views)[1]))
    if problems:
        out += [_anchor("records-left-out"), "### Records left out", "",
                "These files look like result records but cannot be read or shown; rerun their experiments (or "
                "delete them).", ""]
        out += _table(["file", "reason"], [[name, reason] for name, reason in problems])
    if not views:
        out += [_anchor("summary"), "No result records found.", ""]
    else:
        out += _summary(views, plan)
    for g in groups:
        out += _section(g, plan)
    return "\n".join(out).rstrip("\n") + "\n"
