"""Render the report as one self-contained HTML file (CSS and a few lines of script inline,
figures as relative PNGs, a concept explorer's clips, thumbnails and motions as the relative
files its run wrote).

The page has a table of contents that stays in view beside the text (a sticky sidebar; on
a narrow screen it sits above), a summary, and one collapsible section per experiment
(``<details open>``: open by default, every section opens before printing). Every
experiment, run, table, figure and claim has an anchor (an ``id``) and every section a link
back to the summary. Nothing a result record holds reaches the page unescaped.

A run with a concept explorer shows one card per learnt concept: the labels it aligns with and
their shares, its clips as ``<audio controls>``, its thumbnails and its motion (an animated SVG)
as ``<img>``. The media are the files beside the record, linked by relative paths as the
figures are, rather than ``data:`` URIs: the page stays small (the bytes are on disk once), it
works offline from ``file://`` and from any static server, and the Markdown report links the
same files. A file that is missing is named in a muted note instead of a broken element.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from html import escape
from importlib import resources
from urllib.parse import quote

from .. import __version__
from ..engine.uncertainty import MAGNITUDE_VERDICTS, VERDICTS
from ..engine.verdicts import TALLY_KINDS
from ._model import (KIND_SECTIONS, STATUS_LABELS, VARIANT_LABELS, CardView, ExperimentGroup, ExperimentView, MediaView,
                     Plan, chance_line, claims_by_data, group, kind_tally_rows, slug_part, variant_summaries)

__all__ = ["render_html"]

_FALLBACK_CSS = "body { font-family: sans-serif; max-width: 980px; margin: 2rem auto; }"

#: Opens every section before printing, opens the section an anchor points into, and
#: wires the "open all / close all" buttons of the contents (hidden without script).
_SCRIPT = """
(function () {
  var sections = function () { return document.querySelectorAll("details.experiment"); };
  var setAll = function (open) { sections().forEach(function (d) { d.open = open; }); };
  document.querySelectorAll("button[data-open]").forEach(function (b) {
    b.hidden = false;
    b.addEventListener("click", function () { setAll(b.getAttribute("data-open") === "1"); });
  });
  window.addEventListener("beforeprint", function () { setAll(true); });
  var reveal = function () {
    var id = decodeURIComponent(location.hash.slice(1));
    var target = id && document.getElementById(id);
    var closed = target && target.closest("details:not([open])");
    if (closed) { closed.open = true; target.scrollIntoView(); }
  };
  window.addEventListener("hashchange", reveal);
  reveal();
})();
"""


def _css() -> str:
    try:
        return resources.files("mmconcepts.report").joinpath("report.css").read_text(encoding="utf-8")
    except (FileNotFoundError, OSError):  # pragma: no cover - package data missing
        return _FALLBACK_CSS


def _e(text: object) -> str:
    return escape(str(text), quote=True)


def _is_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text == "n/a"
    return True


def _table(columns: list[str], rows: list[list[str]], *, caption: str | None = None, numeric: bool = True,
           anchor: str | None = None) -> str:
    out = ['<div class="scroll">', f'<table id="{_e(anchor)}">' if anchor else "<table>"]
    if caption:
        out.append(f"<caption>{_e(caption)}</caption>")
    out.append("<thead><tr>" + "".join(f"<th>{_e(c)}</th>" for c in columns) + "</tr></thead><tbody>")
    for row in rows:
        cells = []
        for cell in row:
            cls = ' class="num"' if numeric and cell and _is_numeric(cell) else ""
            cells.append(f"<td{cls}>{_e(cell)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table></div>")
    return "".join(out)


def _status(status: str, label: str | None = None) -> str:
    text = STATUS_LABELS.get(status, status) if label is None else label
    return f'<span class="status status-{_e(slug_part(status))}">{_e(text)}</span>'


_WORDS = tuple(dict.fromkeys(VERDICTS + MAGNITUDE_VERDICTS))


def _verdict(text: str) -> str:
    word = text.split(" (")[0]
    if word not in _WORDS:
        return _e(text)
    return f'<span class="verdict verdict-{_e(word.replace(" ", "-"))}">{_e(text)}</span>'


_SYMBOLS = {"holds": "✓", "fails": "✗", "depends": "±", "inconclusive": "?", "not evaluated": "–", "matches": "≈",
            "below": "↓", "above": "↑"}


def _counts(view: ExperimentView, *, compact: bool = False, kind: str | None = "thesis") -> str:
    """Small coloured verdict counts of the claims of ``kind`` (``2 holds 1 fails``, compact ``2✓ 1✗``), or the status
    when it did not run."""
    if view.status != "ok":
        return _status(view.status, view.status_label)
    words = MAGNITUDE_VERDICTS if kind == "magnitude" else VERDICTS
    parts = [f'<span class="count count-{_e(v.replace(" ", "-"))}" title="{view.count(v, kind)} {_e(v)}">'
             f'{view.count(v, kind)}{_SYMBOLS[v] if compact else " " + _e(v)}</span>' for v in words
             if view.count(v, kind)]
    return " ".join(parts) if parts else '<span class="muted">none</span>'


def _heading(level: int, text: str, anchor: str, *, raw: bool = False) -> str:
    body = text if raw else _e(text)
    return (f'<h{level} id="{_e(anchor)}">{body} <a class="anchor" href="#{_e(anchor)}" '
            f'aria-label="link to this part">#</a></h{level}>')


def _run(view: ExperimentView, plan: Plan) -> str:
    run_id = plan.run[id(view)]
    out = [f'<section class="run run-{_e(slug_part(view.variant))}">']
    out.append(_heading(3, f"On {view.data_label}", run_id))
    out.append(f'<p class="meta">status {_status(view.status, view.status_label)}'
               + (f" · {_e(view.elapsed)}" if view.elapsed else "") + "</p>")
    if view.data:
        out.append("<ul>" + "".join(f"<li>data set <code>{_e(n)}</code>: <code>{_e(p)}</code></li>"
                                    for n, p in view.data) + "</ul>")
    if view.omitted:
        out.append(_left_out(view))
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
    for j, table in enumerate(view.tables):
        anchor = plan.table[(id(view), j)]
        out.append(_heading(4, f"Table: {table['title']}", anchor))
        out.append(_table(table["columns"], table["rows"]))
        if table.get("left_out"):
            out.append(f'<p class="note">{_e(table["left_out"])} not shown; see the record '
                       f"<code>{_e(view.source)}</code>.</p>")
        if table["note"]:
            out.append(f'<p class="note">{_e(table["note"])}</p>')
    for j, (name, rel, exists) in enumerate(view.figures):
        anchor = plan.figure[(id(view), j)]
        caption = (f'<figcaption><a class="anchor" href="#{_e(anchor)}">Figure</a> <code>{_e(name)}</code> '
                   f"({_e(view.data_label)})</figcaption>")
        if exists:
            src = _e(quote(rel, safe="/"))
            out.append(f'<figure id="{_e(anchor)}"><a href="{src}"><img src="{src}" alt="figure {_e(name)}" '
                       f'loading="lazy"></a>{caption}</figure>')
        else:  # no <img> that cannot load: say which file is missing
            out.append(f'<figure id="{_e(anchor)}" class="missing"><p class="muted">figure file missing: '
                       f"<code>{_e(rel)}</code></p>{caption}</figure>")
    if view.cards:
        out.append(_explorer(view, plan))
    if view.notes:
        out.append("<h4>Notes</h4><ul>" + "".join(f"<li>{_e(n)}</li>" for n in view.notes) + "</ul>")
    if view.warnings:
        out.append("<h4>Warnings during the run (skipped files, ...)</h4><ul>"
                   + "".join(f"<li>{_e(w)}</li>" for w in view.warnings) + "</ul>")
    if view.config:
        out.append("<details><summary>Configuration</summary>")
        out.append(_table(["parameter", "value"], [list(r) for r in view.config]))
        out.append("</details>")
    out.append("<details><summary>Run details</summary>")
    out.append(_table(["", ""], [list(r) for r in view.run_info], numeric=False))
    out.append(f'<p class="note">Record: <code>{_e(view.source)}</code></p></details>')
    out.append("</section>")
    return "\n".join(out)


def _left_out(view: ExperimentView, *whats: str) -> str:
    """What of ``whats`` (default: everything) the record holds past the report's limits, as a note ('' if none)."""
    left = view.left_out(*whats)
    if not left:
        return ""
    where = f"On {_e(view.data_label)}: " if whats else "Past the report's limits, "
    return f'<p class="note">{where}{_e(left)} not shown; see the record <code>{_e(view.source)}</code>.</p>'


def _missing(what: str, media: MediaView) -> str:
    """What stands where a file is missing: its name, muted (no element that cannot load)."""
    return f'<p class="muted missing">{_e(what)} file missing: <code>{_e(media.path)}</code></p>'


def _card(card: CardView, anchor: str) -> str:
    out = [f'<article class="card" id="{_e(anchor)}"><h5>{_e(card.title)} <a class="anchor" href="#{_e(anchor)}" '
           f'aria-label="link to this concept">#</a></h5>']
    if card.note:
        out.append(f'<p class="note">{_e(card.note)}</p>')
    if card.labels:
        out.append('<p class="labels">aligned with ' + ", ".join(
            f'<span class="label">{_e(label)}{f" <b>{_e(share)}</b>" if share else ""}</span>'
            for label, share in card.labels) + "</p>")
    for clip in card.clips:
        caption = " · ".join(x for x in (clip.caption, clip.seconds) if x)
        if clip.exists:
            src = _e(quote(clip.path, safe="/"))
            out.append(f'<figure class="clip"><audio controls preload="metadata" src="{src}"></audio>'
                       f"<figcaption>{_e(caption)}</figcaption></figure>")
        else:
            out.append(_missing("audio", clip))
    thumbs = []
    for image in card.images:
        if image.exists:
            size = f' width="{image.width}" height="{image.height}"' if image.width and image.height else ""
            thumbs.append(f'<figure><img src="{_e(quote(image.path, safe="/"))}"{size} alt="{_e(image.caption or "view")}" '
                          f'loading="lazy"><figcaption>{_e(image.caption)}</figcaption></figure>')
        else:
            thumbs.append(_missing("image", image))
    if thumbs:
        out.append('<div class="thumbs">' + "".join(thumbs) + "</div>")
    motions = []
    for motion in card.motions:
        if motion.exists:
            motions.append(f'<figure class="motion"><img src="{_e(quote(motion.path, safe="/"))}" '
                          f'alt="motion: {_e(motion.caption)}" loading="lazy"><figcaption>{_e(motion.caption)}'
                          "</figcaption></figure>")
        else:
            motions.append(_missing("motion", motion))
    if motions:
        out.append('<div class="thumbs motions">' + "".join(motions) + "</div>")
    out.append("</article>")
    return "".join(out)


def _explorer(view: ExperimentView, plan: Plan) -> str:
    """The run's concept explorer: one card per learnt concept, its clips playable, its images and motion shown."""
    out = [_heading(4, "Concept explorer", plan.explorer[id(view)])]
    if view.explorer_note:
        out.append(f'<p class="note">{_e(view.explorer_note)}</p>')
    out.append('<div class="cards">' + "".join(_card(card, plan.card[(id(view), j)])
                                              for j, card in enumerate(view.cards)) + "</div>")
    return "\n".join(out)


def _section(g: ExperimentGroup, plan: Plan) -> str:
    sec = plan.section[id(g)]
    out = [f'<section class="experiment-section" id="{_e(sec)}">', '<details class="experiment" open>']
    badges = " ".join(f'<span class="run-badge">{_e(VARIANT_LABELS.get(v.variant, v.variant))}: thesis '
                      f'{_counts(v)}</span>' for v in g.views)
    out.append(f'<summary><h2>{_e(g.title)}</h2><span class="meta"><code>{_e(g.id)}</code> · thesis: '
               f'{_e(g.thesis_ref or "—")}</span><span class="badges">{badges}</span></summary>')
    out.append('<div class="section-body">')
    out.append(f'<p class="back"><a href="#summary">↑ summary</a> · <a href="#{_e(sec)}">link to this experiment</a></p>')
    columns, rows = g.claim_rows()
    if rows:
        out.append(f'<h3>Claims</h3><div class="scroll"><table class="claims"><thead><tr><th></th>'
                   + "".join(f"<th>{_e(c)}</th>" for c in columns) + "</tr></thead><tbody>")
        n = len(g.views)
        for i, row in enumerate(rows):
            anchor = plan.claim[(id(g), i)]
            out.append(f'<tr id="{_e(anchor)}"><td><a class="anchor" href="#{_e(anchor)}" aria-label="link to this '
                       f'claim">#</a></td><td>{_e(row[0])}</td><td>{_e(row[1])}</td><td>{_e(row[2])}</td>'
                       f'<td><code>{_e(row[3])}</code></td>'
                       + "".join(f"<td>{_verdict(c)}</td>" for c in row[4:4 + n])
                       + "".join(f'<td class="test">{_e(c)}</td>' for c in row[4 + n:]) + "</tr>")
        out.append("</tbody></table></div>")
        out.append('<p class="note">Each verdict is what the interval in its test column says (95 %, two-sided).</p>')
    out.extend(filter(None, (_left_out(view, "claims") for view in g.views)))
    columns, rows = g.metric_rows()
    if rows:
        out.append("<h3>Numbers: the thesis' and ours, on each data</h3>")
        out.append(_table(columns, rows, caption="95 % interval in brackets where there are folds or seeds"))
    out.extend(filter(None, (_left_out(view, "metrics") for view in g.views)))
    out.extend(_run(view, plan) for view in g.views)
    out.append('<p class="back"><a href="#summary">↑ back to the summary</a></p>')
    out.append("</div></details></section>")
    return "\n".join(out)


def _toc(groups: list[ExperimentGroup], plan: Plan, *, has_problems: bool, has_claims: bool) -> str:
    out = ['<nav id="toc" class="toc" aria-label="contents">', '<p class="toc-title">Contents</p><ul>',
           '<li><a href="#summary">Summary</a></li>']
    if has_problems:
        out.append('<li><a href="#records-left-out">Records left out</a></li>')
    if has_claims:
        out.append('<li><a href="#claims">Every claim on each data</a></li>')
    out.append("</ul>")
    if groups:
        out.append(f'<p class="toc-title">Experiments ({len(groups)})</p><ol class="toc-experiments">')
        for g in groups:
            runs = "".join(f'<li><a href="#{_e(plan.run[id(v)])}">{_e(VARIANT_LABELS.get(v.variant, v.variant))}</a> '
                           f"{_counts(v, compact=True)}</li>" for v in g.views)
            out.append(f'<li><a href="#{_e(plan.section[id(g)])}" title="{_e(g.title)}"><code>{_e(g.id)}</code></a>'
                       f'<ul class="toc-runs">{runs}</ul></li>')
        out.append("</ol>")
        out.append('<p class="toc-legend">thesis statements: ' + " ".join(
            f'<span class="count count-{_e(v.replace(" ", "-"))}">{_SYMBOLS[v]}</span> {_e(v)}' for v in VERDICTS) + "</p>")
        out.append('<p class="toc-buttons"><button type="button" data-open="1" hidden>open all</button> '
                   '<button type="button" data-open="0" hidden>close all</button></p>')
    out.append("</nav>")
    return "\n".join(out)


def _summary(views: list[ExperimentView], plan: Plan) -> str:
    kinds = [k for k in TALLY_KINDS if any(c.kind == k for v in views for c in v.claims)]
    out = ['<h2 id="summary">Summary</h2>',
           '<p class="note">One row per run: whether it ran, on which data, and the verdicts of its claims, counted '
           "apart by kind (as stored in the record). The experiment's section has the numbers behind them.</p>",
           '<div class="scroll"><table class="summary"><thead><tr><th>experiment</th><th>title</th><th>data</th>'
           "<th>ran</th>" + "".join(f"<th>{_e(k)}</th>" for k in kinds) + "<th>run time</th></tr></thead><tbody>"]
    for g in plan.groups:  # one row per run, the experiment's cells spanning its runs
        for k, view in enumerate(g.views):
            cells = "".join(f"<td>{_counts(view, kind=kind) if view.status == 'ok' else ''}</td>" for kind in kinds)
            span = f' rowspan="{len(g.views)}"' if len(g.views) > 1 else ""
            head = (f'<td{span}><a href="#{_e(plan.section[id(g)])}"><code>{_e(g.id)}</code></a></td>'
                    f"<td{span}>{_e(g.title)}</td>") if k == 0 else ""
            out.append(
                f'<tr>{head}<td><a href="#{_e(plan.run[id(view)])}">{_e(view.data_label)}</a></td>'
                f'<td class="nowrap">{_status(view.status, view.status_label)}</td>{cells}'
                f'<td class="nowrap">{_e(view.elapsed)}</td></tr>'
            )
    out.append("</tbody></table></div>")
    columns, rows = kind_tally_rows(views)
    if rows:
        out.append("<h3>Tallies by kind of claim</h3>")
        out.append(_table(columns, rows, numeric=False))
    out.append("<ul>")
    for label, text in variant_summaries(views):
        out.append(f"<li>On {_e(label)}: {_e(text)}.</li>")
    for line in chance_line(views):
        out.append(f"<li>{_e(line)}</li>")
    out.append("</ul>")
    return "\n".join(out)


def _claims(views: list[ExperimentView], plan: Plan) -> str:
    if not claims_by_data(views)[1]:
        return ""
    out = ['<h2 id="claims">Every claim on each data</h2><p class="note">By kind of claim; within each table, the '
           "claims whose verdict differs between real and generated data come first; each claim links to its "
           "experiment's section, with the numbers and intervals behind the verdict.</p>"]
    sections = plan.section_of
    for kind, heading, what in KIND_SECTIONS:
        columns, rows = claims_by_data(views, kind)
        if not rows:
            continue
        shown = [columns[0], columns[1]] + columns[3:]
        out.append(f"<h3>{_e(heading)}</h3><p class=\"note\">{_e(what)}</p>")
        out.append('<div class="scroll"><table><thead><tr>' + "".join(f"<th>{_e(c)}</th>" for c in shown)
                   + "</tr></thead><tbody>")
        for row in rows:
            target = plan.claim_by_text.get((row[0], row[1])) or sections.get(row[0], "summary")
            out.append(f'<tr><td><a href="#{_e(sections.get(row[0], "summary"))}"><code>{_e(row[0])}</code></a></td>'
                       f'<td><a href="#{_e(target)}">{_e(row[1])}</a></td><td>{_e(row[3])}</td>'
                       + "".join(f"<td>{_verdict(c)}</td>" for c in row[4:-1]) + f"<td>{_e(row[-1])}</td></tr>")
        out.append("</tbody></table></div>")
    return "\n".join(out)


def render_html(views: list[ExperimentView], *, title: str, problems: Sequence[tuple[str, str]] = ()) -> str:
    """Return the whole HTML report for ``views`` (``problems``: records left out, as (file, reason))."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    groups = group(views)
    plan = Plan(groups)
    claims = _claims(views, plan) if views else ""
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title>",
        f"<style>\n{_css()}\n</style></head><body>",
        '<div class="layout">',
        _toc(groups, plan, has_problems=bool(problems), has_claims=bool(claims)),
        '<main id="main">',
        f'<h1 id="top">{_e(title)}</h1>',
        f'<p class="meta">Generated {_e(now)} by mmconcepts {_e(__version__)} · '
        f"{len(groups)} experiment(s), {len(views)} run(s)</p>",
    ]
    if problems:
        out.append('<h2 id="records-left-out">Records left out</h2><p class="note">These files look like result '
                   "records but cannot be read or shown; rerun their experiments (or delete them).</p>")
        out.append(_table(["file", "reason"], [[name, reason] for name, reason in problems], numeric=False))
    if not views:
        out.append('<h2 id="summary">Summary</h2><p>No result records found.</p>')
    else:
        out.append(_summary(views, plan))
        out.append(claims)
    out.extend(_section(g, plan) for g in groups)
    out.append("</main></div>")
    out.append(f"<script>{_SCRIPT}</script>")
    out.append("</body></html>\n")
    return "\n".join(out)
