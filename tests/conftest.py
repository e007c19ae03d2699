"""Shared pytest fixtures: a seeded ``rng`` and an isolated experiment registry."""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")  # no display needed for figures

import numpy as np
import pytest

TESTS_DIR = Path(__file__).resolve().parent


def experiment_module(name: str):
    """The experiment module ``name``: ``"ch3_unseen"`` (a chapter and a module) or ``"ch3.unseen"``."""
    import importlib

    return importlib.import_module("mmconcepts.experiments." + (name if "." in name else name.replace("_", ".", 1)))


def fsdd_like(root: Path) -> Path:
    """A one-recording folder in FSDD's generic layout under ``root`` (``root/fsdd``): a data set the registry finds."""
    folder = root / "fsdd"
    folder.mkdir(parents=True)
    (folder / "labels.csv").write_text("file,speaker,labels,transcription\n0_alice_0.wav,alice,zero,zero\n")
    (folder / "0_alice_0.wav").write_bytes(b"RIFF")
    return folder


def _data_root() -> Path | None:
    """The data root of the real-data tests: $MMCONCEPTS_DATA_ROOT, else ../shared/data beside the checkout."""
    env = os.environ.get("MMCONCEPTS_DATA_ROOT")
    if env:
        return Path(env).expanduser()
    shared = TESTS_DIR.parents[1] / "shared" / "data"
    return shared if shared.is_dir() else None


#: Where the real data sets are for the tests (None when there is none; real-data tests skip).
DATA_ROOT = _data_root()

#: Folder names a real set may have under the data root (the first that exists is used).
_SET_FOLDERS = {
    "fsdd": ("fsdd",),
    "msr-action3d": ("msr-action3d",),
    "eth80": ("eth80", "eth80-96px"),
    "coil20": ("coil20",),
}


def real_data_path(name: str) -> Path:
    """Path of the real data set ``name`` under :data:`DATA_ROOT`, or skip the test with a reason."""
    if DATA_ROOT is None:
        pytest.skip(f"real data set {name!r} absent: no data root (set MMCONCEPTS_DATA_ROOT or put ../shared/data beside the checkout)")
    for folder in _SET_FOLDERS.get(name, (name,)):
        if (DATA_ROOT / folder).exists():
            return DATA_ROOT / folder
    pytest.skip(f"real data set {name!r} absent from the data root {DATA_ROOT}")


@pytest.fixture(autouse=True)
def _no_data_root_from_the_environment(monkeypatch):
    """A user's $MMCONCEPTS_DATA_ROOT must not turn a synthetic test into a real-data one."""
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)


@pytest.fixture(autouse=True)
def _no_background_warm_up(monkeypatch):
    """``reproduce --concurrent`` in a test starts no kernel warm-up (tests/package/test_warmup.py starts it)."""
    monkeypatch.setenv("MMCONCEPTS_WARMUP", "0")


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The data root holding the real sets (skips the test when there is none)."""
    if DATA_ROOT is None:
        pytest.skip("no data root (set MMCONCEPTS_DATA_ROOT or put ../shared/data beside the checkout)")
    return DATA_ROOT


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator, the same in every test."""
    return np.random.default_rng(12345)


@pytest.fixture
def registry(monkeypatch, tmp_path):
    """A fresh, empty experiment registry whose EXPERIMENT_PACKAGES is the toy module.

    The real experiment modules are not imported; ``tests/_toy_experiment.py`` is
    (re)imported on the first ``get()``/``all_experiments()`` call and registers
    ``toy-mean`` and ``toy-data``. Caches go to a temporary folder. Everything is
    restored afterwards.
    """
    from mmconcepts.engine import registry as reg

    monkeypatch.setattr(reg, "_REGISTRY", {})
    monkeypatch.setattr(reg, "_LOADED", False)
    monkeypatch.setattr(reg, "EXPERIMENT_PACKAGES", ("_toy_experiment",))
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    monkeypatch.syspath_prepend(str(TESTS_DIR))
    sys.modules.pop("_toy_experiment", None)
    yield reg
    sys.modules.pop("_toy_experiment", None)


@pytest.fixture
def toy(registry):
    """The freshly imported toy module (its experiments registered, CALLS empty)."""
    registry.load_experiments()
    return sys.modules["_toy_experiment"]


@pytest.fixture(scope="session")
def tiny_speech_corpus(tmp_path_factory):
    """A tiny synthetic caregiver corpus (2 speakers x 50 utterances) in the generic audio layout."""
    pytest.importorskip("piper")
    pytest.importorskip("espeakng_loader")
    from mmconcepts.sound.synthetic import make_caregiver_corpus

    root = tmp_path_factory.mktemp("speech") / "caregiver"
    make_caregiver_corpus(root, n_utterances_per_speaker=50, n_speakers=2, random_state=0)
    return root


def pytest_sessionfinish(session, exitstatus):
    """With MMCONCEPTS_FUZZ_CENSUS set, write the fuzz tests' outcome counts there (tests/_fuzz.py)."""
    fuzz = sys.modules.get("_fuzz")
    path = os.environ.get("MMCONCEPTS_FUZZ_CENSUS")
    if fuzz is not None and path:
        fuzz.write_census(path)
