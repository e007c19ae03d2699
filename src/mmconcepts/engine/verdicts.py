"""Decide a claim of an experiment on a run's numbers: the claim as the record stores it.

The one place where a verdict is decided: the runner calls :func:`decide_claim` when it
makes the record, and the report shows what the record stores. The tests behind each
verdict are in :mod:`mmconcepts.engine.evidence`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import ExperimentError
from .spec import Claim
from .record import ClaimRecord
from .evidence import claim_verdict, magnitude_verdict
from .uncertainty import MAGNITUDE_VERDICTS, VERDICTS, SampleUnit

__all__ = ["decide_claim", "pending_claim", "redecide", "tally_claims", "format_tally", "verdict_words", "TALLY_KINDS",
           "SettingsVerdict", "combine_settings"]


@dataclass(frozen=True)
class SettingsVerdict:
    """A claim evaluated under several settings: its overall verdict and how each setting went."""

    verdict: str
    detail: str
    per_setting: dict[str, str] = field(default_factory=dict)


def combine_settings(verdicts: Mapping[str, str]) -> SettingsVerdict:
    """The overall verdict of a claim evaluated under several settings (label -> verdict).

    ``holds`` when it holds under every setting, ``fails`` when it fails under every one,
    ``inconclusive`` when it is inconclusive under every one, ``not evaluated`` when no
    setting was evaluated, and ``depends`` otherwise; ``detail`` says which: "holds under
    all", "holds only under X", "fails under all", ...

    Examples
    --------
    >>> combine_settings({"KDE": "holds", "VQ": "fails"}).detail
    'holds only under KDE; fails under VQ'

    A label that holds a comma is put in parentheses, to keep the labels of a list apart:

    >>> combine_settings({"KDE, plain SVM": "holds", "VQ, plain SVM": "fails", "VQ, scaled SVM": "fails"}).detail
    'holds only under (KDE, plain SVM); fails under (VQ, plain SVM), (VQ, scaled SVM)'
    """
    if not verdicts:
        raise ExperimentError("combine_settings needs at least one setting.")
    by_word: dict[str, list[str]] = {}
    for label, verdict in verdicts.items():
        by_word.setdefault(verdict, []).append(label)
    evaluated = {w: labels for w, labels in by_word.items() if w != "not evaluated"}
    if not evaluated:
        return SettingsVerdict("not evaluated", "not evaluated under any setting", dict(verdicts))
    if len(evaluated) == 1 and len(by_word) == 1:
        word = next(iter(evaluated))
        return SettingsVerdict(word, f"{word} under all", dict(verdicts))
    parts = []
    for word in ("holds", "fails", "inconclusive", "not evaluated"):
        labels = by_word.get(word)
        if labels:
            only = "only " if word == "holds" and len(labels) < len(verdicts) else ""
            parts.append(f"{word} {only}under {', '.join(f'({x})' if ',' in x else x for x in labels)}")
    overall = "depends"
    if set(evaluated) == {"inconclusive"}:
        overall = "inconclusive"
    return SettingsVerdict(overall, "; ".join(parts), dict(verdicts))


def pending_claim(claim: Claim) -> ClaimRecord:
    """The record of ``claim`` before the run: who it is, no verdict yet."""
    rule = claim.rule if not claim.settings else " | ".join(f"{label}: {rule}" for label, rule in claim.settings.items())
    return ClaimRecord(text=claim.text, rule=rule, kind=claim.kind, source=claim.source,
                       settings=[{"label": label, "rule": r} for label, r in claim.settings.items()])


def decide_claim(
    claim: Claim,
    metrics: Mapping[str, float],
    samples: Mapping[str, Sequence[float]],
    *,
    reference: Mapping[str, float],
    units: Mapping[str, str] | None = None,
    unit_kinds: Mapping[str, SampleUnit] | None = None,
) -> ClaimRecord:
    """Decide ``claim`` on a run's numbers.

    Parameters
    ----------
    claim : Claim
        The claim (its kind says how it is decided).
    metrics : mapping of str to float
        The run's metrics (NaN: not measured).
    samples : mapping of str to sequence of float
        Their per-unit values.
    reference : mapping of str to float
        The thesis' numbers (a magnitude claim's is ``reference[claim.rule]``).
    units, unit_kinds
        The unit of each metric's samples and what each unit is (see
        :func:`~mmconcepts.engine.evidence.claim_verdict`).

    Returns
    -------
    ClaimRecord

    Raises
    ------
    ExperimentError
        If a rule does not parse or names an unknown metric.
    """
    record = pending_claim(claim)
    if claim.kind == "magnitude":
        m = magnitude_verdict(claim.rule, reference[claim.rule], metrics, samples, units=units, unit_kinds=unit_kinds)
        record.verdict, record.basis, record.scope = m.verdict, m.basis, m.scope
        record.ratio = m.ratio
        record.ratio_interval = None if m.ratio_interval is None else list(m.ratio_interval)
        return record
    if not claim.settings:
        v = claim_verdict(claim.rule, metrics, samples, units=units, unit_kinds=unit_kinds)
        record.holds, record.verdict, record.basis, record.scope = v.holds, v.verdict, v.basis, v.scope
        record.tests = [t.to_dict() for t in v.tests]
        return record
    decided = {label: claim_verdict(rule, metrics, samples, units=units, unit_kinds=unit_kinds)
               for label, rule in claim.settings.items()}
    combined = combine_settings({label: v.verdict for label, v in decided.items()})
    record.settings = [{"label": label, "rule": claim.settings[label], "holds": v.holds, "verdict": v.verdict,
                        "basis": v.basis, "tests": [t.to_dict() for t in v.tests], "scope": v.scope}
                       for label, v in decided.items()]
    record.verdict, record.detail = combined.verdict, combined.detail
    holds = {v.holds for v in decided.values()}
    record.holds = holds.pop() if len(holds) == 1 else None
    record.scope = "within one fit" if any(v.scope for v in decided.values()) else ""
    record.basis = "; ".join(f"{label}: {v.basis}" for label, v in decided.items())
    return record


#: The kinds a tally counts, in order; "unclassified": claims of records written before kinds.
TALLY_KINDS = ("thesis", "magnitude", "ours", "check", "unclassified")


def verdict_words(kind: str) -> tuple[str, ...]:
    """The verdicts a claim of ``kind`` can get, in the order tallies count them."""
    return MAGNITUDE_VERDICTS if kind == "magnitude" else VERDICTS


def tally_claims(claims: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, int]]:
    """Count claims (as stored in records: dicts with ``kind`` and ``verdict``) by kind, then by verdict.

    Returns
    -------
    dict
        ``{kind: {verdict: count}}`` for each kind of :data:`TALLY_KINDS` present, every verdict
        word of that kind listed (zeros included).

    Examples
    --------
    >>> tally_claims([{"kind": "thesis", "verdict": "holds"}, {"kind": "magnitude", "verdict": "below"}])["thesis"]
    {'holds': 1, 'fails': 0, 'depends': 0, 'inconclusive': 0, 'not evaluated': 0}
    """
    out: dict[str, dict[str, int]] = {}
    for claim in claims:
        kind = str(claim.get("kind") or "unclassified")
        kind = kind if kind in TALLY_KINDS else "unclassified"
        counts = out.setdefault(kind, dict.fromkeys(verdict_words(kind), 0))
        verdict = str(claim.get("verdict") or "not evaluated")
        counts[verdict] = counts.get(verdict, 0) + 1
    return {kind: out[kind] for kind in TALLY_KINDS if kind in out}


def format_tally(tally: Mapping[str, Mapping[str, int]]) -> str:
    """One line: ``thesis: 3 holds, 1 fails; magnitude: 1 below; ours: 2 holds`` (zeros left out)."""
    parts = []
    for kind, counts in tally.items():
        words = ", ".join(f"{n} {verdict}" for verdict, n in counts.items() if n)
        parts.append(f"{kind}: {words or 'none'}")
    return "; ".join(parts) or "no claims"


def redecide(claim: ClaimRecord, *, metrics: Mapping[str, float], samples: Mapping[str, Sequence[float]],
             reference: Mapping[str, float], units: Mapping[str, str] | None = None,
             unit_kinds: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """The verdict a stored claim's own numbers give (for a reader that checks a record against its numbers).

    Parameters
    ----------
    claim : ClaimRecord
        A claim as a record stores it.
    metrics, samples, reference, units
        The record's.
    unit_kinds : mapping of str to dict
        The record's ``units`` (as stored: dicts).

    Returns
    -------
    str
        The verdict word.

    Raises
    ------
    ExperimentError
        If the stored rule does not parse or names a metric the record does not have.
    """
    kinds = {name: SampleUnit.from_dict(d) for name, d in (unit_kinds or {}).items()}
    kind = claim.kind if claim.kind in ("thesis", "magnitude", "ours", "check") else "ours"
    if kind == "magnitude":
        if claim.rule not in reference:
            raise ExperimentError(f"magnitude claim {claim.text!r:.60}: the record has no thesis number for "
                                  f"{claim.rule!r}.")
        settings: dict[str, str] = {}
    else:
        settings = {str(s.get("label", "")): str(s.get("rule", "")) for s in claim.settings}
    rebuilt = Claim(claim.text, "" if settings else claim.rule, kind=kind, source=claim.source or "(record)",
                    settings=settings)
    return decide_claim(rebuilt, metrics, samples, reference=reference, units=units, unit_kinds=kinds).verdict
