"""Each chapter-3 experiment runs through run_experiment on a tiny config (slow)."""

from __future__ import annotations

import importlib

import pytest

from conftest import real_data_path
from mmconcepts.experiments import run_experiment

TINY = {"n_folds": 3, "n_components": 20, "max_iter": 40, "inner_cv": 2, "n_records_partial": 60, "n_records_full": 90,
        "sensitivity": False}


def _run(monkeypatch, tmp_path, module, exp_id, data=None, **tiny):
    mod = importlib.import_module(f"mmconcepts.experiments.{module}")
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    monkeypatch.setattr(mod.Config, "quick", classmethod(lambda cls: cls(**tiny)))
    record = run_experiment(exp_id, preset="quick", output=tmp_path / "out", workers=2, progress=False, data=data)
    assert record["status"] == "ok", record.get("message")
    return record["metrics"]


@pytest.mark.slow
def test_choreography_tiny(monkeypatch, tmp_path):
    m = _run(monkeypatch, tmp_path, "ch3_choreography", "ch3-choreography", **dict(TINY, sensitivity=True))
    for nl in ("16", "47"):
        # the sensitivity table: the same learners on KDE histograms, and the NMF-SVM gap under both methods
        for name in ("nmf_frobenius", "svm"):
            assert 0.0 <= m[f"{nl}.kde.{name}.l_full"] <= 1.0
        assert m[f"{nl}.nmf_minus_svm.l_full"] == pytest.approx(m[f"{nl}.nmf_frobenius.l_full"] - m[f"{nl}.svm.l_full"])
        for name in ("nmf_frobenius", "nmf_kl"):
            for s in ("l_full", "l_given_number"):
                assert 0.0 <= m[f"{nl}.{name}.{s}"] <= 1.0
        assert f"{nl}.svm.l_full" in m
        assert m[f"{nl}.nmf_frobenius.l_given_number"] > 3 * m[f"{nl}.chance.l_given_number"]
        assert m[f"{nl}.nmf_frobenius.l_given_number"] >= m[f"{nl}.nmf_frobenius.l_full"] - 0.05


@pytest.mark.slow
def test_unseen_tiny(monkeypatch, tmp_path):
    # 47 labels need more examples than TINY: with 90 records most test gestures are unseen in training
    m = _run(monkeypatch, tmp_path, "ch3_unseen", "ch3-unseen", **dict(TINY, n_records_full=200, n_components=50,
                                                                       max_iter=80))
    for nl in ("16", "47"):
        assert {f"{nl}.nmf_frobenius.l_full", f"{nl}.nmf_frobenius.l_given_number", f"{nl}.svm.l_full"} <= set(m)
        assert m[f"{nl}.chance.l_full"] == 0.0  # the most frequent training set is never a test set's
        assert m[f"{nl}.nmf_frobenius.l_given_number"] > 3 * m[f"{nl}.chance.l_given_number"]


@pytest.mark.slow
def test_representations_tiny(monkeypatch, tmp_path):
    m = _run(monkeypatch, tmp_path, "ch3_representations", "ch3-representations", bins=(4, 9), delays=(1, 5),
             n_folds=2, n_components=30, max_iter=40, n_records=100)
    for name in ("kde", "vq_hard", "vq_soft"):
        for b in (4, 9):
            assert m[f"{name}.bins_{b}.l_single"] > 2 * m["chance.l_single"]
    for name in ("angles", "velocities", "separate", "joint"):
        for d in (1, 5):
            assert f"{name}.delay_{d}.l_single" in m
    assert m["joint.best.l_single"] > 2 * m["chance.l_single"]


@pytest.mark.slow
def test_threshold_and_combinations_tiny(monkeypatch, tmp_path):
    m = _run(monkeypatch, tmp_path, "ch3_threshold", "ch3-threshold", **TINY)
    assert 0.05 <= m["nmf_frobenius.cv_threshold"] <= 0.95
    curve_ends = max(m["nmf_frobenius.lowest.l_full"], m["nmf_frobenius.highest.l_full"])
    assert m["nmf_frobenius.best.l_full"] >= curve_ends  # the maximum of the curve
    assert m["nmf_frobenius.best.l_full"] > 0.0
    m = _run(monkeypatch, tmp_path, "ch3_combinations", "ch3-combinations", **TINY)
    assert 0.0 < m["fraction_seen_once"] <= 1.0
    assert m["n_combinations"] <= m["n_examples"]


@pytest.mark.slow
def test_msr_action3d_tiny(monkeypatch, tmp_path):
    folder = real_data_path("msr-action3d")
    m = _run(monkeypatch, tmp_path, "ch3_msr_action3d", "ch3-msr-action3d", data={"msr-action3d": folder},
             n_folds_single=2, n_folds_mixed=3, n_components=30, max_iter=40, inner_cv=2, n_records=200)
    for rep in ("angles_kde", "joint_kde", "joint_vq_hard", "joint_vq_soft"):
        assert m[f"single.{rep}.l_single"] > 2 * m["single.chance.l_single"]
    for proto in ("mixed", "unseen"):
        assert {f"{proto}.nmf_frobenius.l_full", f"{proto}.svm.l_full", f"{proto}.svm_std.l_full"} <= set(m)
    assert m["mixed.nmf_frobenius.l_given_number"] > 3 * m["mixed.chance.l_given_number"]


@pytest.mark.slow
def test_choreography_tiny_on_msr_has_the_synthetic_metric_names(monkeypatch, tmp_path):
    """The real variant (MSR limb mixtures) reports the same metric names as the synthetic one."""
    folder = real_data_path("msr-action3d")
    real = _run(monkeypatch, tmp_path / "real", "ch3_choreography", "ch3-choreography",
                data={"msr-action3d": folder}, **TINY)
    synthetic = _run(monkeypatch, tmp_path / "synthetic", "ch3_choreography", "ch3-choreography", **TINY)
    assert set(real) == set(synthetic)
    assert real["16.n_labels"] == 18 and real["47.n_labels"] == 33  # 2-limb and 3-limb mixtures
    for nl in ("16", "47"):
        assert real[f"{nl}.nmf_frobenius.l_given_number"] > 3 * real[f"{nl}.chance.l_given_number"]


def test_msr_skips_without_data(tmp_path):
    from mmconcepts.experiments import ExperimentSkipped, RunContext
    from mmconcepts.experiments import ch3_msr_action3d as mod

    with pytest.raises(ExperimentSkipped, match=r"--data-root DIR.*--data msr-action3d=DIR"):
        mod.run(mod.Config.quick(), RunContext(cache_dir=tmp_path))


def test_no_machine_paths_in_chapter3_code():
    """Data only through ctx.data: no chapter-3 module looks for ../shared or any path of its own."""
    import inspect

    for module in ("_ch3_common", "ch3_choreography", "ch3_unseen", "ch3_threshold", "ch3_combinations",
                   "ch3_representations", "ch3_msr_action3d"):
        src = inspect.getsource(importlib.import_module(f"mmconcepts.experiments.{module}"))
        assert "shared" not in src and "parents[" not in src, module
