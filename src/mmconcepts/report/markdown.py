"""Render the report as Markdown (GitHub-flavoured tables, figures as relative images)."""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Sequence
from urllib.parse import quote

from .. import __version__
from ._model import STATUS_LABELS, VARIANT_LABELS, VERDICTS, ExperimentGroup, ExperimentView, claims_by_data, group

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


def _table(columns: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return out + [""]


def _run(view: ExperimentView) -> list[str]:
    meta = f"status: **{_text(view.status_label)}**"
    if view.elapsed:
        meta += f" · {view.elapsed}"
    out = [f"### On {_text(view.data_label)}", "", meta, ""]
    if view.data:
        out += [f"- data set {_code(name)}: {_code(path)}" for name, path in view.data] + [""]
    if view.status == "failed":
        out += [f"**Failed:** {_text(view.message or '')}", ""]
        if view.traceback:
            out += ["```", view.traceback.rstrip("\n").replace("```", "` ` `"), "```", ""]
    elif view.status == "skipped":
        out += [f"**Skipped:** {_text(view.message or '')}", ""]
    for table in view.tables:
        out += [f"#### {_text(table['title'])}", ""] + _table(table["columns"], table["rows"])
        if table["note"]:
            out += [f"*{_text(table['note'])}*", ""]
    for name, rel, exists in view.figures:
        missing = " (file missing)" if not exists else ""
        out += [f"![{_text(name)}]({quote(rel, safe='/')}){missing}", ""]
    if view.notes:
        out += ["#### Notes", ""] + [f"- {_text(n)}" for n in view.notes] + [""]
    if view.warnings:
        out += ["#### Warnings during the run (skipped files, ...)", ""] + [f"- {_text(w)}" for w in view.warnings] + [""]
    if view.config:
        out += ["#### Configuration", ""] + _table(["parameter", "value"], [list(r) for r in view.config])
    out += ["#### Run", ""] + _table(["", ""], [list(r) for r in view.run_info])
    out += [f"Record: {_code(view.source)}", ""]
    return out


def _section(group: ExperimentGroup) -> list[str]:
    out = [f"## {_text(group.title)}", "", f"{_code(group.id)} · thesis: {_text(group.thesis_ref or '—')}", ""]
    columns, rows = group.claim_rows()
    if rows:
        out += ["### Claims", ""] + _table(columns, rows)
    columns, rows = group.metric_rows()
    if rows:
        out += ["### Numbers: the thesis' and ours, on each data (95 % interval where there are folds or seeds)", ""]
        out += _table(columns, rows)
    for view in group.views:
        out += _run(view)
    return out


def _summary(views: list[ExperimentView]) -> list[str]:
    rows = [[v.id, v.title, v.data_label, v.status_label, v.claims_summary, v.elapsed]
            for v in views]
    out = ["## Summary", ""] + _table(["experiment", "title", "data", "ran", "claims", "run time"], rows)
    totals = {verdict: sum(v.count(verdict) for v in views if v.status == "ok") for verdict in VERDICTS}
    for variant in ("real", "synthetic"):
        runs = [v for v in views if v.variant == variant and v.status == "ok"]
        if runs:
            counts = ", ".join(f"{sum(v.count(x) for v in runs)} {x}" for x in VERDICTS)
            out += [f"- On {VARIANT_LABELS[variant]}: {len(runs)} run(s); claims: {counts}."]
    if any(totals.values()):
        out.append("")
    columns, rows = claims_by_data(views)
    if rows:
        out += ["### Every claim on each data", "",
                "Claims whose verdict differs between real and generated data come first; the experiment's "
                "section has the numbers and intervals behind each verdict.", ""]
        out += _table(columns, rows)
    return out


def render_markdown(views: list[ExperimentView], *, title: str, problems: Sequence[tuple[str, str]] = ()) -> str:
    """Return the whole Markdown report for ``views`` (``problems``: records left out, as (file, reason))."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    groups = group(views)
    out = [f"# {_text(title)}", "", f"Generated {now} by mmconcepts {__version__} · {len(groups)} experiment(s), "
           f"{len(views)} run(s)", ""]
    if problems:
        out += ["### Records left out", "", "These files look like result records but cannot be read or shown; "
                "rerun their experiments (or delete them).", ""]
        out += _table(["file", "reason"], [[name, reason] for name, reason in problems])
    if not views:
        out += ["No result records found.", ""]
    else:
        out += _summary(views)
    for g in groups:
        out += _section(g)
    return "\n".join(out).rstrip("\n") + "\n"
