"""The result record of one experiment run, as a dataclass that reads and writes its JSON.

:class:`ResultRecord` holds what :func:`~mmconcepts.engine.run_experiment` writes to
``<output>/<id>.json`` (the schema is in :mod:`mmconcepts.engine.runner`'s docstring and
the README, "Where things go"): :meth:`ResultRecord.to_json` writes exactly that JSON and
:meth:`ResultRecord.from_json` reads it back, also from records of schema version 1 or
without the keys added since (they get their defaults). Metrics are floats in memory, NaN
for a metric that could not be measured, and ``null`` in the JSON. The JSON ends with the
digest of its content (:mod:`mmconcepts.engine.digest`); a record read back says whether its
content still matches it (:attr:`ResultRecord.digest_ok`).

A record also reads like the JSON object it writes: ``record["metrics"]``,
``record.get("variant")`` and ``dict(record)`` give the plain values (claims and tables as
dicts), with metrics as floats, as the dict that ``run_experiment`` returned before it
returned a record.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import numbers
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any

import numpy as np

from ..errors import ExperimentError
from .digest import content_digest, digest_matches
from .spec import Table

__all__ = ["SCHEMA_VERSION", "RECORD_KEYS", "ClaimRecord", "ResultRecord", "to_jsonable"]

#: Version of the result-record schema written by :func:`run_experiment`.
SCHEMA_VERSION = 5
#: The first schema version whose records hold a digest.
FIRST_DIGESTED = 5

#: Keys present in every result record, whatever its status, in the order they are written.
RECORD_KEYS = (
    "schema_version",
    "experiment",
    "title",
    "thesis_ref",
    "status",
    "message",
    "traceback",
    "preset",
    "config",
    "seed",
    "variant",
    "version",
    "code",
    "data",
    "data_signature",
    "metrics",
    "intervals",
    "samples",
    "sample_units",
    "units",
    "split_groups",
    "reference",
    "claims",
    "tables",
    "figures",
    "explorer",
    "notes",
    "extra",
    "warnings",
    "elapsed_s",
    "started_at",
    "python",
    "platform",
    "digest",
)

#: The keys without which a JSON object is not a result record.
_REQUIRED = ("schema_version", "experiment", "status")


def to_jsonable(obj: Any, *, where: str = "value") -> Any:
    """Convert ``obj`` to plain JSON types.

    Dataclasses become dicts, tuples and sets lists, numpy scalars and arrays Python
    numbers and lists, paths strings; NaN and infinite floats become None (JSON null).
    Plain JSON values come back unchanged.

    Raises
    ------
    ExperimentError
        If something cannot be represented (the message says where).
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), where=where)
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item(), where=where)
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value, where=where)
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name), where=f"{where}.{f.name}") for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, (str, int, float, bool)) and not isinstance(key, np.generic):
                raise ExperimentError(f"{where}: dictionary key {key!r} cannot be a JSON key; use strings.")
            out[str(key)] = to_jsonable(value, where=f"{where}[{key!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, where=f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (set, frozenset)):
        return [to_jsonable(v, where=where) for v in sorted(obj, key=repr)]
    raise ExperimentError(
        f"{where}: a {type(obj).__name__} value ({obj!r:.60}) cannot be stored in a JSON result; "
        "convert it to numbers, strings, lists or dicts."
    )


def dumps(obj: Mapping[str, Any]) -> str:
    """The JSON text of a record's dict: indented, strict (no NaN), UTF-8 text, a final newline."""
    return json.dumps(obj, indent=2, allow_nan=False, ensure_ascii=False) + "\n"


def _verdict_of(holds: Any) -> str:
    """The verdict of a claim stored before verdicts (schema 1): its value on the reported numbers."""
    return {True: "holds", False: "fails"}.get(holds, "not evaluated")


@dataclass(kw_only=True)
class ClaimRecord:
    """One claim of a result record and its outcome on the run's numbers.

    Parameters
    ----------
    text, rule : str
        The claim in words and its rule (:class:`~mmconcepts.engine.Claim`); for a
        magnitude claim, the rule is the metric set beside the thesis' number.
    kind : {"thesis", "magnitude", "ours", "check", "unclassified"}, default="unclassified"
        The claim's kind (:class:`~mmconcepts.engine.Claim`); ``unclassified`` for claims
        of records written before kinds (schema 1 and 2).
    source : str, default=""
        Where the thesis says it (thesis and magnitude claims).
    holds : bool or None, default=None
        The rule on the reported numbers (None: not evaluated or a magnitude).
    verdict : str, default="not evaluated"
        ``holds``, ``fails``, ``depends``, ``inconclusive`` or ``not evaluated``; for a magnitude,
        ``matches``, ``below``, ``above``, ``inconclusive`` or ``not evaluated``
        (:mod:`~mmconcepts.engine.uncertainty`).
    basis : str, default=""
        How the verdict was decided.
    tests : list of dict, default=[]
        For a rule: each comparison with its margin and the margin's interval, the test
        behind the verdict (:class:`~mmconcepts.engine.evidence.ComparisonTest`).
    scope : str, default=""
        ``"within one fit"`` when the samples behind it come from one fit.
    ratio : float or None, default=None
        For a magnitude: ours / thesis.
    ratio_interval : [float, float] or None, default=None
        For a magnitude: the ratio's interval.
    settings : list of dict, default=[]
        For a claim decided under several settings: ``{"label", "rule", "holds", "verdict",
        "basis", "tests", "scope"}`` per setting.
    detail : str, default=""
        For a claim decided under several settings: "holds under all", "holds only under X", ...
    support : float or None, default=None
        Read from records of schema 2 (the share of bootstrap replicates on which the rule
        held); None in newer records.
    """

    text: str
    rule: str
    kind: str = "unclassified"
    source: str = ""
    holds: bool | None = None
    verdict: str = "not evaluated"
    basis: str = ""
    tests: list[dict[str, Any]] = field(default_factory=list)
    scope: str = ""
    ratio: float | None = None
    ratio_interval: list[float] | None = None
    settings: list[dict[str, Any]] = field(default_factory=list)
    detail: str = ""
    support: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The claim as in the JSON."""
        return {"text": self.text, "rule": self.rule, "kind": self.kind, "source": self.source, "holds": self.holds,
                "verdict": self.verdict, "basis": self.basis, "tests": [dict(t) for t in self.tests],
                "scope": self.scope, "ratio": self.ratio,
                "ratio_interval": None if self.ratio_interval is None else list(self.ratio_interval),
                "settings": [dict(s) for s in self.settings], "detail": self.detail, "support": self.support}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ClaimRecord:
        """Read a claim of a record; a claim without a verdict (schema 1) gets that of ``holds``.

        Raises
        ------
        ExperimentError
            If ``d`` is not a dict with ``text`` and ``rule``.
        """
        if not isinstance(d, Mapping) or "text" not in d or "rule" not in d:
            raise ExperimentError(f"a claim of a result record must be a dict with 'text' and 'rule'; got {d!r:.80}.")
        holds = d.get("holds")
        tests = d.get("tests") or []
        settings = d.get("settings") or []
        if not isinstance(tests, list) or not isinstance(settings, list):
            raise ExperimentError(f"the tests and settings of a claim must be lists; got {d!r:.80}.")
        interval = d.get("ratio_interval")
        return cls(text=d["text"], rule=d["rule"], kind=str(d.get("kind") or "unclassified"),
                   source=str(d.get("source") or ""), holds=holds,
                   verdict=d["verdict"] if "verdict" in d else _verdict_of(holds),
                   basis=d.get("basis", "") or "", tests=[dict(t) for t in tests if isinstance(t, Mapping)],
                   scope=str(d.get("scope") or ""), ratio=d.get("ratio"),
                   ratio_interval=list(interval) if isinstance(interval, (list, tuple)) else None,
                   settings=[dict(x) for x in settings if isinstance(x, Mapping)], detail=str(d.get("detail") or ""),
                   support=d.get("support"))


@dataclass(kw_only=True)
class ResultRecord(Mapping[str, Any]):
    """The record of one experiment run (schema version 5).

    Its fields are the keys of the JSON record, in the order written (:data:`RECORD_KEYS`);
    the runner's module docstring and the README describe each. Read-only mapping access
    (``record["status"]``) gives the JSON values (claims and tables as dicts), except that
    metrics are floats, NaN where the JSON has null.

    Parameters
    ----------
    experiment : str
        The experiment's id.
    status : {"ok", "failed", "skipped"}
    metrics : dict of str to float
        NaN for a metric that was not measured (null in the JSON).
    claims : list of ClaimRecord
    tables : dict of str to Table
    explorer : dict
        ``{}``, or the concept explorer's ``{"note", "cards"}`` with the relative paths of its
        files (:func:`mmconcepts.engine.media.write_explorer`).
    digest_ok : bool or None, default=True
        For a record read back: whether its content matches the digest it holds (False: it was
        changed after it was written); None for a record of a schema before digests (4 and
        older), which has none. True for a record made in memory. Not part of the JSON.
    (others)
        As in the JSON; see :data:`RECORD_KEYS`. ``digest`` is not a field: it is computed
        from the content (:attr:`digest`).
    """

    schema_version: int = SCHEMA_VERSION
    experiment: str
    title: str = ""
    thesis_ref: str = ""
    status: str
    message: str | None = None
    traceback: str | None = None
    preset: str = ""
    config: dict[str, Any] = field(default_factory=dict)
    seed: Any = None
    variant: str = "synthetic"
    version: str = ""
    code: str | None = None
    data: dict[str, str] = field(default_factory=dict)
    data_signature: dict[str, str] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    intervals: dict[str, list[float]] = field(default_factory=dict)
    samples: dict[str, list[Any]] = field(default_factory=dict)
    sample_units: dict[str, str] = field(default_factory=dict)
    units: dict[str, dict[str, Any]] = field(default_factory=dict)
    split_groups: dict[str, Any] = field(default_factory=dict)
    reference: dict[str, float] = field(default_factory=dict)
    claims: list[ClaimRecord] = field(default_factory=list)
    tables: dict[str, Table] = field(default_factory=dict)
    figures: dict[str, str] = field(default_factory=dict)
    explorer: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    elapsed_s: float | None = None
    started_at: str = ""
    python: str = ""
    platform: str = ""
    digest_ok: bool | None = field(default=True, compare=False)

    @property
    def digest(self) -> str:
        """The digest of the record's content as it is now (:func:`mmconcepts.engine.digest.content_digest`)."""
        return str(self.to_dict()["digest"])

    # ------------------------------------------------------------------ mapping view (the JSON values)

    def __getitem__(self, key: str) -> Any:
        if key not in RECORD_KEYS:
            raise KeyError(key)
        if key == "claims":
            return [c.to_dict() for c in self.claims]
        if key == "tables":
            return {name: table.to_dict() for name, table in self.tables.items()}
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(RECORD_KEYS)

    def __len__(self) -> int:
        return len(RECORD_KEYS)

    # ------------------------------------------------------------------ JSON

    def to_dict(self) -> dict[str, Any]:
        """The record as plain JSON values, keys in :data:`RECORD_KEYS` order (NaN metrics as None).

        Raises
        ------
        ExperimentError
            If a value cannot be represented in JSON (the message says where).
        """
        out = {key: to_jsonable(self[key], where=key) for key in RECORD_KEYS if key != "digest"}
        out["digest"] = content_digest(out)
        return out

    def to_json(self) -> str:
        """The JSON text written to ``<id>.json`` (strict JSON: no NaN or Infinity tokens)."""
        return dumps(self.to_dict())

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ResultRecord:
        """Read a record from its JSON dict (as :meth:`to_dict` gives it, or as older versions wrote it).

        Keys missing from older records get their defaults: no intervals, samples, sample
        units, warnings or explorer (before schema 4); the variant ``"real"`` when the record names real data, else
        ``"synthetic"``; no code fingerprint; a claim without a verdict gets that of its
        ``holds``. Unknown keys are ignored, but count in the check of the digest, which sets
        :attr:`digest_ok`.

        Raises
        ------
        ExperimentError
            If ``d`` is not a result record: a key of ``schema_version``, ``experiment``,
            ``status`` is missing, the schema version is newer than :data:`SCHEMA_VERSION`,
            or metrics, claims, tables or the explorer are malformed.
        """
        if not isinstance(d, Mapping) or not all(key in d for key in _REQUIRED):
            raise ExperimentError(f"not a result record: a result record is a JSON object with the keys "
                                  f"{', '.join(_REQUIRED)}.")
        version = d["schema_version"]
        if isinstance(version, bool) or not isinstance(version, int) or version > SCHEMA_VERSION:
            raise ExperimentError(f"result-record schema version {version!r} is not supported (this version of "
                                  f"mmconcepts reads versions up to {SCHEMA_VERSION}).")
        metrics = d.get("metrics") or {}
        if not isinstance(metrics, Mapping):
            raise ExperimentError(f"the metrics of a result record must be a dict; got {type(metrics).__name__}.")
        tables = d.get("tables") or {}
        claims = d.get("claims") or []
        if not isinstance(tables, Mapping) or not isinstance(claims, list):
            raise ExperimentError("the tables of a result record must be a dict and its claims a list.")
        if not isinstance(d.get("explorer") or {}, Mapping):
            raise ExperimentError(f"the explorer of a result record must be a dict; got {type(d['explorer']).__name__}.")
        try:
            metric_values = {str(k): math.nan if v is None else float(v) for k, v in metrics.items()}
            table_values = {str(name): Table.from_dict(t) for name, t in tables.items()}
        except (TypeError, ValueError, KeyError, OverflowError, AttributeError) as exc:
            raise ExperimentError(f"malformed metrics or tables in a result record ({type(exc).__name__}: "
                                  f"{exc}).") from exc
        fields: dict[str, Any] = {key: d[key] for key in RECORD_KEYS if key in d and key != "digest"}
        fields.update(metrics=metric_values, tables=table_values, claims=[ClaimRecord.from_dict(c) for c in claims],
                      digest_ok=digest_matches(d, version, FIRST_DIGESTED))
        if "variant" not in d:  # schema 1: before variants
            fields["variant"] = "real" if d.get("data") else "synthetic"
        for key in ("config", "data", "data_signature", "intervals", "samples", "sample_units", "units", "split_groups",
                    "reference", "figures", "explorer", "notes", "extra", "warnings"):
            if key in fields and fields[key] is None:  # null where a dict or list belongs: empty
                del fields[key]
        return cls(**fields)

    @classmethod
    def from_json(cls, text: str | bytes) -> ResultRecord:
        """Read a record from the JSON text :meth:`to_json` writes.

        Raises
        ------
        ExperimentError
            If ``text`` is not JSON, or not a result record (see :meth:`from_dict`).
        """
        try:
            obj = json.loads(text)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ExperimentError(f"not a result record: not valid JSON ({exc}).") from exc
        return cls.from_dict(obj)
