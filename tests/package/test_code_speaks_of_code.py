"""Code and docstrings speak of the code: no issue numbers or measured timings in the package's source (they
belong in CHANGELOG.md and benchmarks/README.md), and no absolute path of a machine in the tests."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCES = sorted((ROOT / "src" / "mmconcepts").rglob("*.py"))
TESTS = sorted(p for p in (ROOT / "tests").rglob("*.py"))

#: An issue of the tracker cited in the code: "issue 12", "issues 11 and 12", "(#12)".
ISSUE = re.compile(r"\b[Ii]ssues? ?#?\d+|\(#\d+\)")
#: A measured time or speed-up: "took 8.5 s", "measured ... 3 ms", "~3.5x faster", "about 5 s".
TIMING = re.compile(
    r"\b(?:took|takes|measured)\b[^.\n]{0,60}?\b\d+(?:\.\d+)? ?(?:ms|us|µs|s|min|seconds|minutes)\b"
    r"|~?\b\d+(?:\.\d+)?x (?:faster|slower)\b"
    r"|\babout \d+(?:\.\d+)? ?(?:ms|us|µs|s|min)\b",
    re.IGNORECASE,
)
#: An absolute path of some machine (a test finds its files from its own location or a fixture).
MACHINE_PATH = re.compile(r"""["'](?:/work|/root|/home|/check|/Users|/tmp)/""")


def _hits(paths, pattern):
    found = []
    for path in paths:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    return found


def test_the_patterns_find_what_they_forbid():
    for text in ("(issue 12)", "issues 11 and 12", "fixed in (#31)"):
        assert ISSUE.search(text), text
    for text in ("took 8.5 s with threads", "the dual is ~3.5x faster", "about 5 s for 900 rows", "measured: 7 us"):
        assert TIMING.search(text), text
    for text in ("windows of 80 or 150 ms", "25 ms Hamming windows every 10 ms", "the tissue 3 layers",
                 "at most 10 s of silence"):
        assert not TIMING.search(text) and not ISSUE.search(text), text
    assert MACHINE_PATH.search('Path("/work/shared/data")') and not MACHINE_PATH.search('tmp_path / "x"')


@pytest.mark.parametrize("what, pattern", [("issue numbers", ISSUE), ("measured timings", TIMING)])
def test_the_source_has_no(what, pattern):
    found = _hits(SOURCES, pattern)
    assert not found, f"{what} in the source (move them to CHANGELOG.md or benchmarks/README.md):\n" + "\n".join(found)


def test_the_tests_name_no_path_of_a_machine():
    found = _hits([p for p in TESTS if p.name != Path(__file__).name], MACHINE_PATH)
    assert not found, "absolute paths in the tests (use tmp_path or paths relative to the test):\n" + "\n".join(found)


def test_the_tests_cite_no_issue_of_the_tracker():
    found = _hits([p for p in TESTS if p.name != Path(__file__).name], ISSUE)
    assert not found, "issue numbers in the tests (say what the test checks instead):\n" + "\n".join(found)
