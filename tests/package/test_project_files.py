"""The project files a user reads before depending on mmconcepts agree with each other."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import mmconcepts

ROOT = Path(__file__).resolve().parents[2]
tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")


@pytest.fixture(scope="module")
def project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_one_version_everywhere(project):
    version = project["version"]
    assert mmconcepts.__version__ == version
    cff = re.search(r'^version:\s*"?([^"\n]+)"?\s*$', (ROOT / "CITATION.cff").read_text(), re.M)
    assert cff and cff.group(1) == version
    assert re.search(rf"^## \[(Unreleased\] — )?{re.escape(version)}", (ROOT / "CHANGELOG.md").read_text(), re.M)


def test_licence_file_matches_the_metadata(project):
    assert project["license"] == "BSD-3-Clause"
    assert project["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "Neither the name of the copyright holder" in text  # the third clause
    assert re.search(r"^license:\s*BSD-3-Clause\s*$", (ROOT / "CITATION.cff").read_text(), re.M)


def test_all_is_what_a_user_needs_and_developer_tools_stay_apart(project):
    extras = project["optional-dependencies"]
    assert extras["all"] == ["mmconcepts[audio,speech,vision,dask]"]
    user = " ".join(d for name in ("audio", "speech", "vision", "dask") for d in extras[name])
    for tool in ("pytest", "hypothesis", "dtaidistance", "pymdptoolbox"):
        assert tool not in user
    assert [name for name, deps in extras.items() if any("pymdptoolbox" in d for d in deps)] == ["bench"]
    assert extras["dev"] == ["mmconcepts[all,test,bench,docs]"]
