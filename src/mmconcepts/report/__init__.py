"""The HTML and Markdown report of experiment results.

:func:`write_report` reads every result record (``*.json``) of a results folder written by
:func:`mmconcepts.engine.run_experiment` and writes ``report.html`` (one
self-contained file; figures are linked as the relative PNGs next to it) and
``report.md``. A table of contents (a sidebar that stays in view in the HTML) and a summary
(per run: whether it ran, on which data, and how many of its claims hold, fail or are
inconclusive) come first; then one section per experiment (collapsible in the HTML, open by
default) with our metrics beside the thesis' values, each claim with its verdict
(re-evaluated from the stored metrics), the result tables and figures, the config, run
details and notes. Every experiment, run, claim, table and figure has an anchor, and every
section links back to the summary.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from ..errors import ExperimentError
from .._io import atomic_write
from ._model import collect
from .html import render_html
from .markdown import render_markdown

__all__ = ["write_report"]

logger = logging.getLogger("mmconcepts.report")


def write_report(
    results_dir: str | os.PathLike[str], *, title: str = "mmconcepts: reproduced results"
) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.md`` for the result records in ``results_dir``.

    Parameters
    ----------
    results_dir : str or path-like
        A folder of ``<id>.json`` result records (and their ``<id>/*.png`` figures).
        JSON files that are not result records are ignored (and logged); a damaged
        record (truncated, or edited so that it cannot be shown) is listed in the report
        under "Records left out", with the reason, and the others are shown.
    title : str, optional
        The report's title.

    Returns
    -------
    html_path, md_path : Path
        The two files written (atomically) in ``results_dir``.

    Raises
    ------
    ExperimentError
        If ``results_dir`` is not an existing folder.

    Notes
    -----
    The work is bounded whatever a record holds (a record edited by hand can hold 100 000
    claims or a 10 MB string): a string is shown up to 8 000 characters (a note, message or
    traceback up to 20 000; a traceback keeps its end), a list up to 1 000 items (claims,
    metrics, tables, rows, notes, cards...; a table up to 100 columns) and a record up to about
    1 000 000 characters in all, each cut saying how much it left out (``… (N more
    characters)``, ``9000 more claims not shown``); a file larger than 32 MB is listed under
    "Records left out" unread. No record an experiment writes comes near these limits.
    """
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise ExperimentError(
            f"results folder {str(results_dir)!r} does not exist; run `mmconcepts run ID` or "
            "`mmconcepts reproduce` first, or pass the folder they wrote to."
        )
    problems: list[tuple[str, str]] = []
    views = collect(results_dir, problems)
    html_path = results_dir / "report.html"
    md_path = results_dir / "report.md"
    # "replace": a lone surrogate (a "\\ud800" escape in a record's JSON) becomes "?" instead of failing the report
    atomic_write(html_path, render_html(views, title=title, problems=problems).encode("utf-8", "replace"))
    atomic_write(md_path, render_markdown(views, title=title, problems=problems).encode("utf-8", "replace"))
    logger.info("wrote %s and %s (%d experiment(s))", html_path, md_path, len(views))
    return html_path, md_path
