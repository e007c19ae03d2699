"""Render the report as one self-contained HTML file (CSS inline, figures as relative PNGs)."""

from __future__ import annotations

import datetime as _dt
from html import escape
from importlib import resources
from urllib.parse import quote

from .. import __version__
from ._model import STATUS_LABELS, ExperimentView

__all__ = ["render_html"]

_FALLBACK_CSS = "body { font-family: sans-serif; max-width: 980px; margin: 2rem auto; }"


def _css() -> str:
    try:
        return resources.files("mmconcepts.report").joinpath("report.css").read_text(encoding="utf-8")
    except (FileNotFoundError, OSError):  # pragma: no cover - package data missing
        return _FALLBACK_CSS


def _e(text: object) -> str:
    return escape(str(text), quote=True)


def _slug(text: str) -> str:
    return "exp-" + "".join(c if c.isalnum() or c == "-" else "-" for c in text)


def _is_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text == "n/a"
    return True


def _table(columns: list[str], rows: list[list[str]], *, caption: str | None = None, numeric: bool = True) -> str:
    out = ["<table>"]
    if caption:
        out.append(f"<caption>{_e(caption)}</caption>")
    out.append("<thead><tr>" + "".join(f"<th>{_e(c)}</th>" for c in columns) + "</tr></thead><tbody>")
    for row in rows:
        cells = []
        for cell in row:
            cls = ' class="num"' if numeric and cell and _is_numeric(cell) else ""
            cells.append(f"<td{cls}>{_e(cell)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _status(status: str) -> str:
    return f'<span class="status status-{_e(status)}">{_e(STATUS_LABELS.get(status, status))}</span>'


def _section(view: ExperimentView) -> str:
    out = [f'<section id="{_e(_slug(view.id))}">']
    out.append(f"<h2>{_e(view.title)}</h2>")
    out.append(
        f'<p class="meta"><code>{_e(view.id)}</code> · thesis: {_e(view.thesis_ref or "—")} · '
        f"status {_status(view.status)}"
        + (f" · {_e(view.elapsed)}" if view.elapsed else "")
        + "</p>"
    )
    if view.status == "failed":
        message = view.message or ""
        if "\n" in message:
            out.append(f"<p><strong>Failed:</strong></p><pre>{_e(message)}</pre>")
        else:
            out.append(f"<p><strong>Failed:</strong> {_e(message)}</p>")
        if view.traceback:
            out.append(f"<details><summary>traceback</summary><pre>{_e(view.traceback)}</pre></details>")
    elif view.status == "skipped":
        out.append(f"<p><strong>Skipped:</strong> {_e(view.message or '')}</p>")

    if view.claims:
        out.append("<h3>Claims</h3><ul class=\"claims\">")
        for claim in view.claims:
            cls = "verdict-" + claim.verdict.replace(" ", "-")
            detail = f' <span class="muted">({_e(claim.error)})</span>' if claim.error else ""
            out.append(
                f'<li><span class="verdict {cls}">{_e(claim.verdict)}</span> {_e(claim.text)} '
                f"<code>{_e(claim.rule)}</code>{detail}</li>"
            )
        out.append("</ul>")

    if view.metrics:
        out.append("<h3>Metrics</h3>")
        out.append(_table(["metric", "ours", "thesis"], [list(r) for r in view.metrics]))

    for table in view.tables:
        out.append(f"<h3>{_e(table['title'])}</h3>")
        out.append(_table(table["columns"], table["rows"]))
        if table["note"]:
            out.append(f'<p class="note">{_e(table["note"])}</p>')

    for name, rel, exists in view.figures:
        src = quote(rel, safe="/")
        missing = "" if exists else ' <span class="muted">(file missing)</span>'
        out.append(
            f'<figure><img src="{_e(src)}" alt="{_e(name)}" loading="lazy">'
            f"<figcaption>{_e(name)}{missing}</figcaption></figure>"
        )

    if view.notes:
        out.append("<h3>Notes</h3><ul>" + "".join(f"<li>{_e(n)}</li>" for n in view.notes) + "</ul>")

    if view.config:
        out.append("<h3>Configuration</h3>")
        out.append(_table(["parameter", "value"], [list(r) for r in view.config]))
    out.append("<h3>Run</h3>")
    out.append(_table(["", ""], [list(r) for r in view.run_info], numeric=False))
    out.append(f'<p class="note">Record: <code>{_e(view.source)}</code></p>')
    out.append("</section>")
    return "\n".join(out)


def render_html(views: list[ExperimentView], *, title: str) -> str:
    """Return the whole HTML report for ``views``."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title>",
        f"<style>\n{_css()}\n</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        f'<p class="meta">Generated {_e(now)} by mmconcepts {_e(__version__)} · '
        f"{len(views)} experiment(s)</p>",
    ]
    if not views:
        out.append("<p>No result records found.</p>")
    else:
        out.append("<h3>Summary</h3><table><thead><tr><th>experiment</th><th>title</th><th>status</th>"
                   "<th>claims</th><th>run time</th></tr></thead><tbody>")
        for view in views:
            out.append(
                f'<tr><td><a href="#{_e(_slug(view.id))}"><code>{_e(view.id)}</code></a></td>'
                f"<td>{_e(view.title)}</td><td>{_status(view.status)}</td>"
                f"<td>{_e(view.claims_summary)}</td><td>{_e(view.elapsed)}</td></tr>"
            )
        out.append("</tbody></table>")
    out.extend(_section(view) for view in views)
    out.append("</body></html>\n")
    return "\n".join(out)
