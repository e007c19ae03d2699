"""The chapter 6 motion/sound/label experiments on tiny generated data."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmconcepts.experiments import RunContext


@pytest.mark.slow
def test_ch6_motion_sound_symbolic_labels_small(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments import _ch6_common as common
    from mmconcepts.experiments.ch6_motion_sound import Config, run_labels, run_motion_sound, run_symbolic

    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    cfg = dataclasses.replace(Config.quick(), n_motion=60, n_folds=2, k=12, n_iter=30)
    data = common.load_pairs(ctx, n_per_speaker=50, n_motion=60, seed=0)
    # pairing by concept: each utterance's motion has the gesture its keyword maps to
    assert len(data["mfcc"]) == len(data["angles"]) == len(data["y"]) == 50
    assert sorted(data["mapping"].values()) == sorted(set(data["mapping"].values()))  # a bijection
    res = run_motion_sound(cfg, ctx)
    res.validate()
    m = res.metrics
    keys = [k for k in m if k.count(".") == 2 and not k.endswith("_std") and not k.startswith("shuffled")]
    assert len(keys) == 18  # 2 directions x 3 spaces x 3 metrics, the keys of Table 6.2
    assert all(0.0 <= m[k] <= 1.0 for k in keys)
    assert m["sound2motion.internal.cosine"] > m["shuffled.sound2motion.internal.cosine"]
    # the other two reuse the cached folds
    sym = run_symbolic(cfg, ctx).metrics
    assert sym["without_labels.sound2motion.internal.cosine"] == m["sound2motion.internal.cosine"]
    lab = run_labels(cfg, ctx).metrics
    for k in ("sound_labels.s2l", "motion_labels.m2l", "all.s2l", "all.m2l", "all.sm2l"):
        assert 0.0 <= lab[k] <= 1.0 and np.isfinite(lab[f"{k}_std"])
    assert lab["motion_labels.m2l"] > 2 * lab["chance"]


@pytest.mark.slow
def test_ch6_image_features_small(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments.ch6_image_features import SETS, Config, run

    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    cfg = dataclasses.replace(Config.quick(), n_views=6, n_repeats=1, k=12, n_iter=30)
    res = run(cfg, ctx)
    res.validate()
    m = res.metrics
    for name in SETS:
        for key in ("i2s", "s2i"):
            assert 0.0 <= m[f"{name}.{key}"] <= 1.0
    assert m["best_single.i2s"] == max(m[f"{s}.i2s"] for s in SETS if s != "all")
    assert m["best_single.i2s"] > m["chance"]  # 10 test examples: coarse rates, only the best is robust


def test_mutual_information_matrix_by_construction(rng):
    from mmconcepts.experiments.ch6_concepts import mutual_information_matrix

    y = np.repeat(np.arange(4), 50)
    W = rng.random((200, 3)) * 0.1
    W[:, 0] += (y == 2) * 5.0  # coefficient 0 is on exactly for concept 2
    mi = mutual_information_matrix(y, W, 10)
    h = -(0.25 * np.log2(0.25) + 0.75 * np.log2(0.75))
    assert mi[2, 0] == pytest.approx(h, rel=1e-9)  # all of the concept's entropy
    assert mi[:, 1:].max() < 0.15  # noise coefficients: only estimator bias
    assert mi.shape == (4, 3) and (mi >= 0).all()


@pytest.mark.slow
def test_ch6_concepts_small(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments.ch6_concepts import Config, run

    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    res = run(dataclasses.replace(Config.quick(), n_motion=60, k=8, n_iter=30), ctx)
    res.validate()
    m = res.metrics
    assert m["n_concepts"] == 10 and 0 <= m["n_specialised"] <= 8
    assert m["matched.mean_mi"] >= m["others.mean_mi"]
    assert len(res.tables["matching"].rows) == 8  # k = 8 coefficients matched to 8 of the 10 concepts


@pytest.mark.slow
def test_ch6_modalities_small(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments.ch6_modalities import Config, _setups, run

    assert len(_setups()) == 18  # 6 one-to-one x (two, three) + 3 two-to-one + 3 one-to-two
    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    cfg = dataclasses.replace(Config.quick(), n_motion=60, n_views=6, n_repeats=1, k=10, k_sweep=(5, 10), n_iter=20)
    res = run(cfg, ctx)
    res.validate()
    m = res.metrics
    for key in ("two.S2M", "three.S2M", "three.SM2I", "three.I2SM", "k_5.two", "k_10.three"):
        assert 0.0 <= m[key] <= 1.0
    assert m["k_10.two"] == pytest.approx(m["two.mean_1to1"])  # k = 10 is the main fit: same models
    assert set(res.figures) == {"fig6_5_6_6", "fig6_7"}


def test_stream_windows_cover_the_stream():
    from mmconcepts.experiments.ch6_sliding import stream_windows

    win = stream_windows(np.array([0.0, 1.5]), np.array([1.5, 1.0]), 0.5, 0.25)
    assert win[0].tolist() == [0.0, 0.5] and win[-1, 1] <= 2.5 + 1e-9
    np.testing.assert_allclose(np.diff(win[:, 0]), 0.25)


@pytest.mark.slow
def test_ch6_sliding_small(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments.ch6_sliding import Config, run

    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    cfg = dataclasses.replace(Config.quick(), n_views=6, widths=(0.2, 0.5), k=12, n_iter=30, probe_width=0.5)
    res = run(cfg, ctx)
    res.validate()
    m = res.metrics
    for key in ("width_0_2.s2i", "width_0_5.i2s", "localisation.peak_in_keyword", "localisation.chance"):
        assert 0.0 <= m[key] <= 1.0
    assert m["width_0_2.n_windows"] > m["width_0_5.n_windows"] > 0  # narrower windows, more of them
    assert m["localisation.n_utterances"] > 0  # the corpus has keyword timings
    assert set(res.figures) == {"fig6_8", "fig6_9"}


MSR = __import__("pathlib").Path(__file__).resolve().parents[1].parent / "shared" / "data" / "msr-action3d"


@pytest.mark.slow
@pytest.mark.skipif(not MSR.is_dir(), reason="needs ../shared/data/msr-action3d (real MSR Action3D skeletons)")
def test_ch6_labels_on_real_msr_motion(tiny_speech_corpus, tmp_path):
    from mmconcepts.experiments import _ch6_common as common
    from mmconcepts.experiments.ch6_motion_sound import Config, run_labels

    ctx = RunContext(data={"audio": tiny_speech_corpus, "msr": MSR}, cache_dir=tmp_path, show_progress=False)
    data = common.load_pairs(ctx, n_per_speaker=50, n_motion=0, seed=0)
    assert set(data["mapping"].values()) <= set(common.MSR_ACTIONS)
    assert all(a.shape[1] == 16 for a in data["angles"])  # joint angles of the limb model
    res = run_labels(dataclasses.replace(Config.quick(), n_folds=2, k=12, n_iter=30), ctx)
    assert "MSR Action3D" in res.notes[0]
    assert res.metrics["motion_labels.m2l"] > 2 * res.metrics["chance"]
