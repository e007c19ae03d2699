"""Render the report as one self-contained HTML file (CSS inline, figures as relative PNGs)."""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from html import escape
from importlib import resources
from urllib.parse import quote

from .. import __version__
from ._model import STATUS_LABELS, VARIANT_LABELS, VERDICTS, ExperimentGroup, ExperimentView, claims_by_data, group

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


def _status(status: str, label: str | None = None) -> str:
    text = STATUS_LABELS.get(status, status) if label is None else label
    return f'<span class="status status-{_e(status)}">{_e(text)}</span>'


def _run(view: ExperimentView) -> str:
    out = [f'<section class="run run-{_e(view.variant)}">']
    out.append(f"<h3>On {_e(view.data_label)}</h3>")
    out.append(f'<p class="meta">status {_status(view.status, view.status_label)}' + (f" · {_e(view.elapsed)}" if view.elapsed else "") + "</p>")
    if view.data:
        out.append("<ul>" + "".join(f"<li>data set <code>{_e(n)}</code>: <code>{_e(p)}</code></li>" for n, p in view.data) + "</ul>")
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
    for table in view.tables:
        out.append(f"<h4>{_e(table['title'])}</h4>")
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
        out.append("<h4>Notes</h4><ul>" + "".join(f"<li>{_e(n)}</li>" for n in view.notes) + "</ul>")
    if view.warnings:
        out.append("<h4>Warnings during the run (skipped files, ...)</h4><ul>"
                   + "".join(f"<li>{_e(w)}</li>" for w in view.warnings) + "</ul>")
    if view.config:
        out.append("<h4>Configuration</h4>")
        out.append(_table(["parameter", "value"], [list(r) for r in view.config]))
    out.append("<h4>Run</h4>")
    out.append(_table(["", ""], [list(r) for r in view.run_info], numeric=False))
    out.append(f'<p class="note">Record: <code>{_e(view.source)}</code></p>')
    out.append("</section>")
    return "\n".join(out)


def _verdict(text: str) -> str:
    word = text.split(" (")[0]
    if word not in VERDICTS:
        return _e(text)
    return f'<span class="verdict verdict-{_e(word.replace(" ", "-"))}">{_e(text)}</span>'


def _section(group: ExperimentGroup) -> str:
    out = [f'<section id="{_e(_slug(group.id))}">']
    out.append(f"<h2>{_e(group.title)}</h2>")
    out.append(f'<p class="meta"><code>{_e(group.id)}</code> · thesis: {_e(group.thesis_ref or "—")}</p>')
    columns, rows = group.claim_rows()
    if rows:
        out.append("<h3>Claims</h3><table><thead><tr>" + "".join(f"<th>{_e(c)}</th>" for c in columns)
                   + "</tr></thead><tbody>")
        for row in rows:
            out.append(f"<tr><td>{_e(row[0])}</td><td><code>{_e(row[1])}</code></td>"
                       + "".join(f"<td>{_verdict(c)}</td>" for c in row[2:]) + "</tr>")
        out.append("</tbody></table>")
    columns, rows = group.metric_rows()
    if rows:
        out.append("<h3>Numbers: the thesis' and ours, on each data</h3>")
        out.append(_table(columns, rows, caption="95 % interval in brackets where there are folds or seeds"))
    out.extend(_run(view) for view in group.views)
    out.append("</section>")
    return "\n".join(out)


def render_html(views: list[ExperimentView], *, title: str, problems: Sequence[tuple[str, str]] = ()) -> str:
    """Return the whole HTML report for ``views`` (``problems``: records left out, as (file, reason))."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    groups = group(views)
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title>",
        f"<style>\n{_css()}\n</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        f'<p class="meta">Generated {_e(now)} by mmconcepts {_e(__version__)} · '
        f"{len(groups)} experiment(s), {len(views)} run(s)</p>",
    ]
    if problems:
        out.append('<h3 id="records-left-out">Records left out</h3><p class="note">These files look like result '
                   "records but cannot be read or shown; rerun their experiments (or delete them).</p>")
        out.append(_table(["file", "reason"], [[name, reason] for name, reason in problems], numeric=False))
    if not views:
        out.append("<p>No result records found.</p>")
    else:
        out.append("<h3>Summary</h3><table><thead><tr><th>experiment</th><th>title</th><th>data</th><th>ran</th>"
                   "<th>claims</th><th>run time</th></tr></thead><tbody>")
        for view in views:
            out.append(
                f'<tr><td><a href="#{_e(_slug(view.id))}"><code>{_e(view.id)}</code></a></td>'
                f"<td>{_e(view.title)}</td><td>{_e(view.data_label)}</td><td>{_status(view.status, view.status_label)}</td>"
                f"<td>{_e(view.claims_summary)}</td><td>{_e(view.elapsed)}</td></tr>"
            )
        out.append("</tbody></table>")
        out.append("<ul>")
        for variant in ("real", "synthetic"):
            runs = [v for v in views if v.variant == variant and v.status == "ok"]
            if runs:
                counts = ", ".join(f"{sum(v.count(x) for v in runs)} {x}" for x in VERDICTS)
                out.append(f"<li>On {_e(VARIANT_LABELS[variant])}: {len(runs)} run(s); claims: {_e(counts)}.</li>")
        out.append("</ul>")
        columns, rows = claims_by_data(views)
        if rows:
            out.append("<h3>Every claim on each data</h3><p class=\"note\">Claims whose verdict differs between real "
                       "and generated data come first; the experiment's section has the numbers and intervals behind "
                       "each verdict.</p>")
            out.append("<table><thead><tr>" + "".join(f"<th>{_e(c)}</th>" for c in columns) + "</tr></thead><tbody>")
            for row in rows:
                out.append(f'<tr><td><a href="#{_e(_slug(row[0]))}"><code>{_e(row[0])}</code></a></td>'
                           f"<td>{_e(row[1])}</td>" + "".join(f"<td>{_verdict(c)}</td>" for c in row[2:-1])
                           + f"<td>{_e(row[-1])}</td></tr>")
            out.append("</tbody></table>")
    out.extend(_section(g) for g in groups)
    out.append("</body></html>\n")
    return "\n".join(out)
