"""Every registered experiment's claims: a kind each, the thesis' source for thesis statements and magnitudes, each
thesis number written once, and no thesis statement judged against a thesis number."""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

import pytest

from mmconcepts.experiments import CLAIM_KINDS, all_experiments
from mmconcepts.engine.rules import parse_rule

THESIS = Path(__file__).resolve().parents[3] / "shared" / "reference" / "000_282ac1a69b9c20d0.txt"
_SOURCE = re.compile(r"\((?:line (\d+)|lines (\d+(?:(?:-|, )\d+)+))\)\Z")
_NUMBER = re.compile(r"(?<![A-Za-z0-9_.])(\d+\.\d+|\.\d+|\d+(?:\.\d*)?e-?\d+)(?![A-Za-z0-9_])")


def _claims():
    return [(exp, claim) for exp in all_experiments() for claim in exp.claims]


def _ids(pairs):
    return [f"{exp.id}: {claim.text[:40]}" for exp, claim in pairs]


def test_every_claim_has_a_kind():
    pairs = _claims()
    assert pairs, "no claims registered"
    assert {claim.kind for _, claim in pairs} <= set(CLAIM_KINDS)
    kinds = {claim.kind for _, claim in pairs}
    assert {"thesis", "magnitude", "ours"} <= kinds


def _lines(source: str) -> list[int]:
    m = _SOURCE.search(source)
    assert m, f"the source {source!r} must end with '(line N)' or '(lines N, M)' / '(lines N-M)'"
    return [int(x) for x in re.findall(r"\d+", m.group(0))]


@pytest.mark.parametrize("exp, claim", [p for p in _claims() if p[1].kind in ("thesis", "magnitude")],
                         ids=_ids([p for p in _claims() if p[1].kind in ("thesis", "magnitude")]))
def test_thesis_statements_and_magnitudes_cite_a_line_of_the_thesis(exp, claim):
    lines = _lines(claim.source)
    if THESIS.is_file():
        n = len(THESIS.read_text(encoding="utf-8").splitlines())
        assert all(1 <= line <= n for line in lines), (claim.source, n)
    if claim.kind == "magnitude":
        assert claim.rule in exp.reference


def _reference_numbers(exp) -> set[float]:
    return {float(v) for v in exp.reference.values()}


@pytest.mark.parametrize("exp, claim", [p for p in _claims() if p[1].kind == "thesis"],
                         ids=_ids([p for p in _claims() if p[1].kind == "thesis"]))
def test_no_thesis_statement_is_judged_against_a_thesis_number(exp, claim):
    """A thesis statement is tested at the thesis' comparison: its rule holds no thesis number (nor a fraction of
    one, which would also hold that number); the thesis' numbers are compared in magnitude claims."""
    numbers = _reference_numbers(exp)
    for rule in claim.rules.values():
        parse_rule(rule)
        used = {float(x) for x in _NUMBER.findall(rule)}
        assert not (used & numbers), f"{exp.id}: rule {rule!r} uses the thesis number(s) {sorted(used & numbers)}"


def _modules():
    by_module: dict[str, list] = {}
    for exp in all_experiments():
        by_module.setdefault(exp.compute.__module__, []).append(exp)
    return sorted(by_module.items())


@pytest.mark.parametrize("module_name, experiments", _modules(), ids=[m for m, _ in _modules()])
def test_each_thesis_number_is_written_once(module_name, experiments):
    """A module writes each thesis number of its experiments' reference tables once (as many times as the tables
    hold distinct entries of that value, e.g. two cells of Table 6.2 that are both 0.090); claim texts and notes cite
    them as {thesis:NAME}."""
    source = inspect.getsource(sys.modules[module_name])
    entries: dict[float, set[str]] = {}
    for exp in experiments:
        for name, value in exp.reference.items():
            entries.setdefault(float(value), set()).add(name)
    literals = [float(m) for m in _NUMBER.findall(source)]
    for value, names in entries.items():
        if value in (0.0, 1.0):
            continue
        assert literals.count(value) <= len(names), \
            f"{module_name}: the thesis number {value!r} ({', '.join(sorted(names))}) is written {literals.count(value)} times"
    for exp in experiments:
        for claim in exp.claims:
            assert "{thesis:" not in claim.text  # filled in when the experiment was made


def test_claim_texts_are_distinct_within_an_experiment():
    for exp in all_experiments():
        texts = [c.text for c in exp.claims]
        assert len(texts) == len(set(texts)), exp.id
