"""docs/migration.rst cannot drift: its tables name scikit-learn's NMF parameters and mmconcepts' own, as they are."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
from sklearn.decomposition import NMF as SkNMF
from sklearn.decomposition import MiniBatchNMF

import mmconcepts.nmf
from mmconcepts.nmf import NMF

PAGE = Path(__file__).resolve().parents[2] / "docs" / "migration.rst"
SKLEARN = {"NMF": SkNMF, "MiniBatchNMF": MiniBatchNMF}


def _params(cls) -> set[str]:
    return set(inspect.signature(cls).parameters)


def _rows(section: str) -> list[list[str]]:
    """The rows of the list-table under ``section``: each row's cells, the header row left out."""
    text = PAGE.read_text(encoding="utf-8")
    start = text.index("\n" + section + "\n")
    end = text.find("\n.. list-table::", text.index(".. list-table::", start) + 1)
    body = text[start:] if end < 0 else text[start:end]
    rows: list[list[str]] = []
    for line in body.splitlines():
        if line.startswith("   * - "):
            rows.append([line[len("   * - "):]])
        elif line.startswith("     - "):
            rows[-1].append(line[len("     - "):])
        elif line.startswith("       ") and rows:
            rows[-1][-1] += " " + line.strip()
    return rows[1:]


def _names(cell: str) -> list[str]:
    return re.findall(r"``([^`]+)``", cell)


def test_every_scikit_learn_parameter_is_listed_once_with_its_class():
    rows = _rows("Parameters")
    listed = [_names(row[0])[0] for row in rows]
    assert len(listed) == len(set(listed))
    assert set(listed) == _params(SkNMF) | _params(MiniBatchNMF)
    for row in rows:
        name, where = _names(row[0])[0], row[1].strip()
        classes = {c for c, cls in SKLEARN.items() if name in _params(cls)}
        assert classes == ({"NMF", "MiniBatchNMF"} if where == "both" else {where}), name


def test_every_mmconcepts_equivalent_is_a_parameter_of_nmf():
    rows = _rows("Parameters")
    ours = _params(NMF)
    for row in rows:
        equivalent = _names(row[2])
        assert equivalent == [] and row[2].strip() == "—" or (len(equivalent) == 1 and equivalent[0] in ours), row


def _exists(name: str) -> bool:
    """``param``, ``NMF.method``, ``NMF.method(keyword=...)``, ``NMF.fit(X=dask.array)`` or a name of mmconcepts.nmf."""
    m = re.fullmatch(r"NMF\.(\w+)(?:\((\w+)=[^)]*\))?", name)
    if m:
        method = getattr(NMF, m.group(1), None)
        return callable(method) and (m.group(2) is None or m.group(2) in inspect.signature(method).parameters)
    return name in _params(NMF) or name in mmconcepts.nmf.__all__


def test_every_addition_exists():
    rows = _rows("What mmconcepts adds")
    names = [n for row in rows for n in _names(row[0])]
    assert len(names) >= 10
    missing = [n for n in names if not _exists(n)]
    assert missing == []


def test_every_parameter_of_nmf_is_on_the_page():
    text = PAGE.read_text(encoding="utf-8")
    assert [p for p in sorted(_params(NMF)) if f"``{p}``" not in text] == []


@pytest.mark.parametrize("name, ok", [("NMF.fit(mask=...)", True), ("NMF.fit(masks=...)", False),
                                      ("NMF.fitt", False), ("n_components", True), ("ncomponents", False),
                                      ("select_rank", True)])
def test_the_checker_itself(name, ok):
    assert _exists(name) is ok
