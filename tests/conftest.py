"""Shared pytest fixtures: a seeded ``rng`` and an isolated experiment registry."""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")  # no display needed for figures

import numpy as np
import pytest

TESTS_DIR = Path(__file__).resolve().parent


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator, the same in every test."""
    return np.random.default_rng(12345)


@pytest.fixture
def registry(monkeypatch, tmp_path):
    """A fresh, empty experiment registry whose EXPERIMENT_MODULES is the toy module.

    The real experiment modules are not imported; ``tests/_toy_experiment.py`` is
    (re)imported on the first ``get()``/``all_experiments()`` call and registers
    ``toy-mean`` and ``toy-data``. Caches go to a temporary folder. Everything is
    restored afterwards.
    """
    import mmconcepts.experiments as experiments
    from mmconcepts.experiments import registry as reg

    monkeypatch.setattr(reg, "_REGISTRY", {})
    monkeypatch.setattr(reg, "_LOADED", False)
    monkeypatch.setattr(experiments, "EXPERIMENT_MODULES", ("_toy_experiment",))
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
