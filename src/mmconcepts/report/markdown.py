"""Render the report as Markdown (GitHub-flavoured tables, figures as relative images)."""

from __future__ import annotations

import datetime as _dt
from urllib.parse import quote

from .. import __version__
from ._model import STATUS_LABELS, ExperimentView

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
    s = str(text)
    fence = "``" if "`" in s else "`"
    pad = " " if s.startswith("`") or s.endswith("`") else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def _table(columns: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return out + [""]


def _section(view: ExperimentView) -> list[str]:
    out = [f"## {_text(view.title)}", ""]
    meta = f"`{view.id}` · thesis: {_text(view.thesis_ref or '—')} · status: **{STATUS_LABELS.get(view.status, view.status)}**"
    if view.elapsed:
        meta += f" · {view.elapsed}"
    out += [meta, ""]
    if view.status == "failed":
        out += [f"**Failed:** {_text(view.message or '')}", ""]
        if view.traceback:
            out += ["```", view.traceback.rstrip("\n").replace("```", "` ` `"), "```", ""]
    elif view.status == "skipped":
        out += [f"**Skipped:** {_text(view.message or '')}", ""]
    if view.claims:
        out += ["### Claims", ""]
        for claim in view.claims:
            detail = f" ({_text(claim.error)})" if claim.error else ""
            out.append(f"- **{claim.verdict}**: {_text(claim.text)} {_code(claim.rule)}{detail}")
        out.append("")
    if view.metrics:
        out += ["### Metrics", ""] + _table(["metric", "ours", "thesis"], [list(r) for r in view.metrics])
    for table in view.tables:
        out += [f"### {_text(table['title'])}", ""] + _table(table["columns"], table["rows"])
        if table["note"]:
            out += [f"*{_text(table['note'])}*", ""]
    for name, rel, exists in view.figures:
        missing = " (file missing)" if not exists else ""
        out += [f"![{_text(name)}]({quote(rel, safe='/')}){missing}", ""]
    if view.notes:
        out += ["### Notes", ""] + [f"- {_text(n)}" for n in view.notes] + [""]
    if view.config:
        out += ["### Configuration", ""] + _table(["parameter", "value"], [list(r) for r in view.config])
    out += ["### Run", ""] + _table(["", ""], [list(r) for r in view.run_info])
    out += [f"Record: `{view.source}`", ""]
    return out


def render_markdown(views: list[ExperimentView], *, title: str) -> str:
    """Return the whole Markdown report for ``views``."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out = [f"# {_text(title)}", "", f"Generated {now} by mmconcepts {__version__} · {len(views)} experiment(s)", ""]
    if not views:
        out += ["No result records found.", ""]
    else:
        out += ["## Summary", ""]
        out += _table(
            ["experiment", "title", "status", "claims", "run time"],
            [[v.id, v.title, STATUS_LABELS.get(v.status, v.status), v.claims_summary, v.elapsed] for v in views],
        )
    for view in views:
        out += _section(view)
    return "\n".join(out).rstrip("\n") + "\n"
