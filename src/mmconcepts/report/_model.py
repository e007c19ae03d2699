"""Read result records and turn them into what both report formats show (internal)."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ExperimentError
from ..experiments.runner import load_record
from ..experiments.rules import evaluate_rule

logger = logging.getLogger("mmconcepts.report")

VERDICTS = {True: "holds", False: "does not hold", None: "not evaluated"}
STATUS_LABELS = {"ok": "ok", "failed": "FAILED", "skipped": "skipped"}


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


@dataclass
class ClaimView:
    text: str
    rule: str
    holds: bool | None
    error: str | None = None

    @property
    def verdict(self) -> str:
        return VERDICTS[self.holds]


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

    @property
    def n_claims(self) -> int:
        return len(self.claims)

    @property
    def n_hold(self) -> int:
        return sum(c.holds is True for c in self.claims)

    @property
    def n_not_evaluated(self) -> int:
        return sum(c.holds is None for c in self.claims)

    @property
    def claims_summary(self) -> str:
        if not self.claims:
            return "no claims"
        text = f"{self.n_hold}/{self.n_claims} claims hold"
        if self.status == "ok" and self.n_not_evaluated:
            text += f" ({self.n_not_evaluated} not evaluated)"
        return text


def _claims(record: dict[str, Any]) -> list[ClaimView]:
    metrics = record.get("metrics") or {}
    views = []
    for claim in record.get("claims") or []:
        text, rule = str(claim.get("text", "")), str(claim.get("rule", ""))
        if record.get("status") != "ok":
            views.append(ClaimView(text, rule, None))
            continue
        try:
            holds = evaluate_rule(rule, metrics)
            error = None
        except ExperimentError as exc:
            holds, error = None, str(exc).splitlines()[0]
        stored = claim.get("holds")
        if error is None and stored is not holds:
            logger.warning(
                "%s: claim %r was stored as %s but its rule gives %s on the stored metrics; reporting %s",
                record.get("experiment"), rule, stored, holds, holds,
            )
        views.append(ClaimView(text, rule, holds, error))
    return views


def build_view(record: dict[str, Any], results_dir: Path, source: Path) -> ExperimentView:
    """Turn one result record into an :class:`ExperimentView`."""
    metrics = record.get("metrics") or {}
    reference = record.get("reference") or {}
    rows = [(name, format_number(value), format_number(reference.get(name))) for name, value in metrics.items()]
    rows += [(name, "", format_number(value)) for name, value in reference.items() if name not in metrics]
    figures = []
    for name, rel in (record.get("figures") or {}).items():
        figures.append((str(name), str(rel), (results_dir / str(rel)).is_file()))
    config = [(str(k), format_cell(v)) for k, v in (record.get("config") or {}).items()]
    data = record.get("data") or {}
    run_info = [
        ("preset", str(record.get("preset", ""))),
        ("seed", format_cell(record.get("seed"))),
        ("run time", format_duration(record.get("elapsed_s"))),
        ("started at", str(record.get("started_at", ""))),
        ("mmconcepts version", str(record.get("version", ""))),
        ("python", str(record.get("python", ""))),
        ("platform", str(record.get("platform", ""))),
    ]
    run_info += [(f"data: {name}", str(path)) for name, path in data.items()]
    tables = []
    for name, table in (record.get("tables") or {}).items():
        if isinstance(table, dict) and "columns" in table and "rows" in table:
            tables.append(
                {
                    "name": str(name),
                    "title": str(table.get("title") or name),
                    "columns": [str(c) for c in table["columns"]],
                    "rows": [[format_cell(c) for c in row] for row in table["rows"]],
                    "note": str(table.get("note") or ""),
                }
            )
    return ExperimentView(
        id=str(record.get("experiment")),
        title=str(record.get("title") or record.get("experiment")),
        thesis_ref=str(record.get("thesis_ref") or ""),
        status=str(record.get("status")),
        message=record.get("message"),
        traceback=record.get("traceback"),
        metrics=rows,
        tables=tables,
        figures=figures,
        claims=_claims(record),
        config=config,
        run_info=run_info,
        notes=[str(n) for n in record.get("notes") or []],
        source=source.name,
        elapsed=format_duration(record.get("elapsed_s")),
        extra_keys=sorted(str(k) for k in (record.get("extra") or {})),
    )


def collect(results_dir: Path) -> list[ExperimentView]:
    """Read every result record of ``results_dir``, sorted by experiment id."""
    views = []
    for path in sorted(results_dir.glob("*.json")):
        record = load_record(path)
        if record is None:
            logger.info("ignoring %s: not a result record", path)
            continue
        views.append(build_view(record, results_dir, path))
    views.sort(key=lambda v: v.id)
    return views
