"""What an experiment declares and returns: its claims (:class:`Claim`), its result (:class:`Result`)
and the tables in it (:class:`Table`); :class:`ExperimentSkipped` for a run that cannot go on here."""

from __future__ import annotations

import dataclasses
import numbers
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from ..errors import ExperimentError
from .explorer import Explorer
from .rules import is_valid_metric_name, parse_rule
from .uncertainty import SampleUnit

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["CLAIM_KINDS", "Claim", "ExperimentSkipped", "Result", "Table", "fill_thesis_numbers"]

_FIGURE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")


class ExperimentSkipped(ExperimentError):
    """Raised by an experiment's ``run`` when it cannot run here, e.g. real data is absent.

    The runner records the experiment as ``"skipped"`` with this message instead of as a
    failure. :meth:`RunContext.require_data` raises it for a missing ``--data`` set.
    """

#: The kinds of claims, in the order the report counts them (see :class:`Claim`).
CLAIM_KINDS = ("thesis", "magnitude", "ours", "check")

_THESIS_NUMBER = re.compile(r"\{thesis:([A-Za-z0-9_.]+)\}")


def _format_thesis_number(value: float) -> str:
    return f"{value:.6g}" if abs(value) >= 0.01 or value == 0 else f"{value:.4g}"


def fill_thesis_numbers(text: str, reference: Mapping[str, float]) -> str:
    """``text`` with each ``{thesis:NAME}`` replaced by the thesis' number ``reference[NAME]``.

    For claim texts (done when an experiment is made) and notes, so that each thesis number is
    written once, in the experiment's reference table.

    Raises
    ------
    ExperimentError
        If a name is not in ``reference``.

    Examples
    --------
    >>> fill_thesis_numbers("NMF {thesis:a} vs SVM {thesis:b}", {"a": 0.854, "b": 0.818})
    'NMF 0.854 vs SVM 0.818'
    """
    def fill(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in reference:
            raise ExperimentError(f"{text!r:.60} cites {{thesis:{name}}}, which is not in the reference table (known: "
                                  f"{', '.join(sorted(reference)) or 'none'}).")
        return _format_thesis_number(float(reference[name]))

    return _THESIS_NUMBER.sub(fill, text)


@dataclass(frozen=True)
class Claim:
    """A statement checked on our metrics, and what kind of statement it is.

    Parameters
    ----------
    text : str
        The claim in words, e.g. "NMF with the Frobenius loss beats the SVM". A thesis
        number is written ``{thesis:NAME}``, filled in from the experiment's reference table
        (so that each thesis number is written once, in that table).
    rule : str
        For kinds ``thesis``, ``ours`` and ``check``: a boolean expression over metric names,
        e.g. ``"nmf_frobenius.l_full > svm.l_full"`` (see
        :mod:`mmconcepts.engine.rules`), its syntax checked when the claim is made. For
        kind ``magnitude``: the name of the metric set beside the thesis' number of the same
        name in the reference table. Empty when ``settings`` is given.
    kind : {"thesis", "magnitude", "ours", "check"}, default="ours"
        ``thesis``: a statement the thesis makes (an order, a trend, "X beats Y"), tested at
        the thesis' own comparison; ``magnitude``: our number against the thesis' number, as
        a ratio with its interval (:func:`~mmconcepts.engine.evidence.magnitude_verdict`);
        ``ours``: a check we added (a control, a bar of our own); ``check``: a property of the
        code kept in the record only to show that the run is sane (never evidence).
    source : str, default=""
        Where the thesis says it: section, table or figure, and the line of the thesis' text
        (``"Section 3.3.4, Table 3.2 (line 2790)"``). Required for kinds ``thesis`` and
        ``magnitude``.
    settings : mapping of str to str, optional
        For a statement whose verdict depends on a setting we had to choose (features,
        dynamics, noise): one rule per setting, by the setting's label. The claim is decided
        under each, and its verdict says "holds under all", "holds only under X" or "fails
        under all" (:func:`~mmconcepts.engine.verdicts.combine_settings`).
    """

    text: str
    rule: str = ""
    kind: str = "ours"
    source: str = ""
    settings: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.text, str) or not self.text.strip():
            raise ExperimentError(f"Claim.text must be a non-empty string; got {self.text!r}.")
        if self.kind not in CLAIM_KINDS:
            raise ExperimentError(f"Claim.kind must be one of {', '.join(CLAIM_KINDS)}; got {self.kind!r} "
                                  f"(claim {self.text!r:.60}).")
        if self.kind in ("thesis", "magnitude") and (not isinstance(self.source, str) or not self.source.strip()):
            raise ExperimentError(f"a {self.kind} claim needs its source: where the thesis says it (section, table or "
                                  f"figure, and the line of the thesis' text); claim {self.text!r:.60}.")
        if not isinstance(self.settings, Mapping):
            raise ExperimentError(f"Claim.settings must map a setting's label to a rule; got {self.settings!r:.60}.")
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))
        if self.settings:
            if self.rule:
                raise ExperimentError(f"claim {self.text!r:.60}: give a rule or settings (a rule per setting), "
                                      "not both.")
            if self.kind == "magnitude":
                raise ExperimentError(f"claim {self.text!r:.60}: a magnitude claim has no settings.")
            for label, rule in self.settings.items():
                if not isinstance(label, str) or not label.strip():
                    raise ExperimentError(f"claim {self.text!r:.60}: a setting's label must be a non-empty string; "
                                          f"got {label!r}.")
                parse_rule(rule)
        elif self.kind == "magnitude":
            if not is_valid_metric_name(self.rule):
                raise ExperimentError(f"a magnitude claim's rule is the metric set beside the thesis' number of the "
                                      f"same name; got {self.rule!r} (claim {self.text!r:.60}).")
        else:
            parse_rule(self.rule)  # syntax and type check; metric names are checked at run time

    @property
    def rules(self) -> dict[str, str]:
        """The rule under each setting (``{"": rule}`` without settings)."""
        return dict(self.settings) if self.settings else {"": self.rule}

    def with_thesis_numbers(self, reference: Mapping[str, float], exp_id: str = "") -> "Claim":
        """This claim with each ``{thesis:NAME}`` of its text replaced by ``reference[NAME]``.

        Raises
        ------
        ExperimentError
            If a name is not in ``reference``, or a magnitude claim's metric has no thesis number.
        """
        if self.kind == "magnitude" and self.rule not in reference:
            raise ExperimentError(f"experiment {exp_id!r}: magnitude claim {self.text!r:.60} sets {self.rule!r} beside "
                                  "the thesis' number, but the reference table has none of that name.")
        try:
            text = fill_thesis_numbers(self.text, reference)
        except ExperimentError as exc:
            raise ExperimentError(f"experiment {exp_id!r}: claim {exc}") from None
        return self if text == self.text else dataclasses.replace(self, text=text)


@dataclass
class Table:
    """A result table, kept JSON-friendly.

    Parameters
    ----------
    title : str
        Caption, e.g. "Table 3.2: classification scores".
    columns : list of str
        Column headers.
    rows : list of list
        One list per row, each with ``len(columns)`` cells (numbers, strings or None).
    note : str, default=""
        A remark shown under the table.
    """

    title: str
    columns: list[str]
    rows: list[list[Any]]
    note: str = ""

    def __post_init__(self) -> None:
        self.columns = [str(c) for c in self.columns]
        self.rows = [list(row) for row in self.rows]
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ExperimentError(
                    f"table {self.title!r}: row {i} has {len(row)} cells but there are "
                    f"{len(self.columns)} columns ({', '.join(self.columns)})."
                )

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"title", "columns", "rows", "note"}`` (cells not yet JSON-cleaned)."""
        return {"title": self.title, "columns": list(self.columns), "rows": [list(r) for r in self.rows], "note": self.note}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Table":
        """Rebuild a table from :meth:`to_dict` output (as read back from JSON)."""
        return cls(title=d.get("title", ""), columns=list(d["columns"]), rows=[list(r) for r in d["rows"]], note=d.get("note", "") or "")


@dataclass
class Result:
    """What an experiment's ``run`` returns.

    Parameters
    ----------
    metrics : dict of str to float
        Named numbers; names are runs of ``[A-Za-z0-9_.]`` (``"16.nmf_kl.l_full"``), the
        ones claim rules and the reference use. NaN means "not measured".
    tables : dict of str to Table
        Result tables, by a short name.
    figures : dict of str to matplotlib.figure.Figure
        Figures, by a file-name-safe name; the runner saves each as ``<id>/<name>.png``
        and closes it. Prefer :class:`matplotlib.figure.Figure` over pyplot.
    notes : list of str
        Remarks for the report (what differs from the thesis and why, ...).
    extra : dict
        Anything else JSON-able worth keeping (per-trial scores, ...).
    samples : dict of str to list of float
        The per-fold, per-seed or per-draw values behind a metric, by the metric's name
        (each name must also be in ``metrics``). The runner turns them into a 95 %
        interval and uses them to decide claims beyond their uncertainty: metrics whose
        samples have the same length are taken to come from the same folds or seeds and
        are resampled together (a paired bootstrap), unless ``sample_units`` says
        otherwise.
    sample_units : dict of str to str
        Optional: the unit of a metric's samples (``"16-label folds"``, ``"seeds"``). Metrics
        with the same unit are paired (their samples must then have the same length and
        order); metrics with different units are resampled independently, even when their
        samples have the same length. A metric without an entry is paired with every other
        metric without one whose samples have the same length.
    units : dict of str to SampleUnit
        What each unit named in ``sample_units`` is
        (:class:`~mmconcepts.engine.uncertainty.SampleUnit`): independent seeds or
        repetitions, the folds of one cross-validation (whose intervals and verdicts use the
        corrected resampled t), or blocks of one fit (whose verdicts are marked "within one
        fit"). A unit not declared here is taken as independent.
    split_groups : dict
        For each split of the data into training and test parts, what its examples are
        grouped by so that no source recording behind a test example feeds a training
        example, e.g. ``{"mixtures": {"by": "source recordings", "n_groups": 40}}``
        (JSON-able; stored in the record).
    figure_data : dict
        What an experiment's ``present`` draws beyond the metrics and tables (loss curves,
        per-unit curves, value maps, ...), set by its ``compute``. Kept in memory only: the
        runner never writes it to the record.
    explorer : Explorer, optional
        The cards of the concepts the run's learner found (:class:`~mmconcepts.engine.explorer.Explorer`):
        the runner writes their clips, thumbnails and motions beside the figures and lists them in
        the record's ``explorer``.
    """

    metrics: dict[str, float] = field(default_factory=dict)
    tables: dict[str, Table] = field(default_factory=dict)
    figures: dict[str, "Figure"] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    samples: dict[str, list[float]] = field(default_factory=dict)
    sample_units: dict[str, str] = field(default_factory=dict)
    figure_data: dict[str, Any] = field(default_factory=dict)
    units: dict[str, SampleUnit] = field(default_factory=dict)
    split_groups: dict[str, Any] = field(default_factory=dict)
    explorer: Explorer | None = None

    def validate(self) -> None:
        """Check names and types; raise :class:`ExperimentError` naming the culprit."""
        for name, value in self.metrics.items():
            if not is_valid_metric_name(name):
                raise ExperimentError(
                    f"metric name {name!r} is not allowed: use letters, digits, '_' and '.', "
                    "not a plain number nor one of and/or/not/abs/min/max."
                )
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ExperimentError(f"metric {name!r} must be a real number; got {value!r} ({type(value).__name__}).")
        for name, table in self.tables.items():
            if not isinstance(table, Table):
                raise ExperimentError(f"table {name!r} must be a Table; got {type(table).__name__}.")
        for name, fig in self.figures.items():
            if not isinstance(name, str) or not _FIGURE_NAME.fullmatch(name):
                raise ExperimentError(f"figure name {name!r} must be a file-name-safe word ([A-Za-z0-9_.-]).")
            if not hasattr(fig, "savefig"):
                raise ExperimentError(f"figure {name!r} must be a matplotlib Figure; got {type(fig).__name__}.")
        if isinstance(self.notes, str) or not all(isinstance(n, str) for n in self.notes):
            raise ExperimentError("Result.notes must be a list of strings.")
        if not isinstance(self.figure_data, Mapping):
            raise ExperimentError(f"Result.figure_data must be a dict; got {type(self.figure_data).__name__}.")
        for name, values in self.samples.items():
            if name not in self.metrics:
                raise ExperimentError(
                    f"samples given for {name!r}, which is not a metric; add metrics[{name!r}] (their summary) "
                    "or rename the samples to the metric they belong to."
                )
            if isinstance(values, (str, bytes)) or not all(
                isinstance(v, numbers.Real) and not isinstance(v, bool) for v in values
            ):
                raise ExperimentError(f"samples[{name!r}] must be a list of real numbers; got {values!r:.80}.")
        lengths: dict[str, tuple[str, int]] = {}
        for name, unit in self.sample_units.items():
            if name not in self.samples:
                raise ExperimentError(
                    f"sample_units gives a unit for {name!r}, which has no samples; give samples[{name!r}] or drop "
                    "the entry."
                )
            if not isinstance(unit, str) or not unit:
                raise ExperimentError(f"sample_units[{name!r}] must be a non-empty string; got {unit!r}.")
            first = lengths.setdefault(unit, (name, len(self.samples[name])))
            if first[1] != len(self.samples[name]):
                raise ExperimentError(
                    f"metrics of unit {unit!r} are paired, so their samples must have the same length: "
                    f"{first[0]!r} has {first[1]}, {name!r} has {len(self.samples[name])}; give them different units "
                    "if they do not come from the same folds or seeds."
                )
        if not isinstance(self.units, Mapping):
            raise ExperimentError(f"Result.units must map a unit's name to a SampleUnit; got {type(self.units).__name__}.")
        named = set(self.sample_units.values())
        for unit, kind in self.units.items():
            if not isinstance(kind, SampleUnit):
                raise ExperimentError(f"units[{unit!r}] must be a SampleUnit (SampleUnit.folds(k), .seeds(), "
                                      f".within_fit()); got {kind!r:.60}.")
            if unit not in named:
                raise ExperimentError(f"units declares {unit!r}, which no metric's samples have (sample_units names "
                                      f"{', '.join(sorted(named)) or 'none'}).")
        if not isinstance(self.split_groups, Mapping):
            raise ExperimentError(f"Result.split_groups must be a dict; got {type(self.split_groups).__name__}.")
        if self.explorer is not None and not isinstance(self.explorer, Explorer):
            raise ExperimentError(f"Result.explorer must be an Explorer (mmconcepts.engine.Explorer) or None; got "
                                  f"{type(self.explorer).__name__}.")


