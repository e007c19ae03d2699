"""The chapter 6 experiments: on tiny generated data, on small real subsets, and their building blocks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import real_data_path

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
    assert len(keys) == 24  # 2 directions x 3 spaces x 4 metrics (KL = I-divergence, KL normalised, Eucl., cos.)
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
def test_ch6_modalities_small(tiny_speech_corpus, tmp_path, monkeypatch):
    from mmconcepts.experiments import ch6_modalities
    from mmconcepts.experiments.ch6_modalities import Config, _setups, run

    # every model gets the same id, as a freed model's id can be reused by the next one: the cache
    # of internal representations must still never serve one model's to another (regression)
    monkeypatch.setattr(ch6_modalities, "id", lambda obj: 0, raising=False)

    assert len(_setups()) == 18  # 6 one-to-one x (two, three) + 3 two-to-one + 3 one-to-two
    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    # several k besides the main one: the sweep's models are freed one after the other (regression: a
    # cache keyed on id(model) then served a freed model's representations to a later model)
    cfg = dataclasses.replace(Config.quick(), n_motion=60, n_views=6, n_repeats=1, k=10, k_sweep=(3, 4, 5, 10),
                              n_iter=20)
    res = run(cfg, ctx)
    res.validate()
    m = res.metrics
    for key in ("two.S2M", "three.S2M", "three.SM2I", "three.I2SM", "k_5.two", "k_10.three"):
        assert 0.0 <= m[key] <= 1.0
    assert m["k_10.two"] == pytest.approx(m["two.mean_1to1"])  # k = 10 is the main fit: same models
    # each k is scored with its own models (a shared cache entry made every k score the same)
    assert len({round(m[f"k_{k}.{w}"], 12) for k in (3, 4, 5, 10) for w in ("two", "three")}) > 2
    assert set(res.figures) == {"fig6_5_6_7", "fig6_6"}  # Fig. 6.6 is the k sweep


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


def test_streams_are_independent_and_reproducible():
    from mmconcepts.experiments._ch6_common import child_seeds, streams

    a, b = streams(0), streams(1)
    assert a == streams(0) and len(set(a)) == len(a)  # five different seeds from one
    assert all(x != y for x, y in zip(a, b))
    assert child_seeds(a.learner, 3)[:2] == child_seeds(a.learner, 2)


def test_pairing_stays_within_concept_and_part(rng):
    from mmconcepts.experiments._ch6_common import concept_parts, pair_within_parts

    y = np.repeat(np.arange(4), 30)  # 30 utterances per concept
    item_concept = np.r_[np.repeat(np.arange(4), 11), -np.ones(5, int)]  # 11 records per concept, 5 unused
    part_y = concept_parts(y, (0.6, 0.2, 0.2), rng)
    part_i = concept_parts(item_concept, (0.6, 0.2, 0.2), rng)
    assert (part_i[item_concept < 0] == -1).all()
    for c in range(4):
        assert np.bincount(part_y[y == c]).tolist() == [18, 6, 6]
        assert np.bincount(part_i[item_concept == c]).tolist() == [7, 2, 2]
    idx = pair_within_parts(y, part_y, item_concept, part_i, rng)
    assert (item_concept[idx] == y).all() and (part_i[idx] == part_y).all()
    # without replacement while possible: the 7 training records of a concept serve 18 utterances 2-3 times each
    counts = np.bincount(idx[(y == 0) & (part_y == 0)], minlength=len(item_concept))
    assert set(counts[counts > 0].tolist()) <= {2, 3}
    folds = concept_parts(y, 5, rng)
    assert all(np.bincount(folds[y == c]).tolist() == [6] * 5 for c in range(4))


def test_composed_test_utterances_place_the_target_exactly(rng):
    from mmconcepts.experiments.ch6_sliding import compose_test_utterances

    lengths = rng.integers(20, 60, size=40)
    mfccs = [np.full((n, 3), float(i)) for i, n in enumerate(lengths)]  # each frame names its recording
    y = np.arange(40) % 10
    pool = np.arange(0, 40, 2)
    seqs, labels, spans, parts = compose_test_utterances(mfccs, y, pool, rng, hop=0.01)
    assert len(seqs) == len(pool) and (labels == y[pool]).all()
    for seq, (t0, t1), (p, pos), target in zip(seqs, spans, parts, pool):
        assert 2 <= len(p) <= 4 and p[pos] == target and set(p) <= set(pool.tolist())
        assert all(y[j] != y[target] for k, j in enumerate(p) if k != pos)  # flanking words: other concepts
        inside = seq[int(round(t0 / 0.01)): int(round(t1 / 0.01)), 0]
        assert (inside == target).all() and inside.size == lengths[target]
    assert {len(p) for p, _ in parts} == {2, 3, 4}


def test_eth80_objects_round_robin_over_categories():
    from mmconcepts.experiments._ch6_common import eth80_objects

    objs = ["car11", "car2", "car1", "apple2", "apple1", "cow1"]
    assert eth80_objects(objs, ["car", "car", "car", "apple", "apple", "cow"], 5) == \
        ["apple1", "car1", "cow1", "apple2", "car2"]


def _real_ctx(tmp_path, *names):
    return RunContext(data={n: real_data_path(n) for n in names}, cache_dir=tmp_path, show_progress=False)


def test_real_pairs_follow_the_bijection_and_keep_streams_apart(tmp_path):
    from mmconcepts.experiments import _ch6_common as common
    from mmconcepts.experiments.ch6_motion_sound import Config

    ctx = _real_ctx(tmp_path, "fsdd", "msr-action3d")
    st = common.streams(0)
    kw = dict(n_per_speaker=50, n_motion=0, n_folds=3)
    data = common.load_pairs(ctx, seeds=st, **kw)
    assert len(data["y"]) == 50 and np.bincount(data["y"]).tolist() == [5] * 10  # 5 recordings per digit
    assert sorted(data["keywords"])[:3] == ["eight", "five", "four"]
    assert sorted(data["mapping"].values()) == sorted(common.MSR_ACTIONS)  # a bijection onto the ten actions
    gestures = data["motion"]["gesture"][data["motion_idx"]]
    assert all(gestures[i] == data["mapping"][data["keywords"][c]] for i, c in enumerate(data["y"]))
    assert all(a.shape[1] == 16 for a in data["angles"])  # joint angles of the limb model
    for rec in set(data["motion_idx"].tolist()):  # a motion record serves in one fold only
        assert len(set(data["fold"][data["motion_idx"] == rec].tolist())) == 1
    cfg = dataclasses.replace(Config.quick(), n_folds=3)
    # a new learner seed leaves the data (bijection, pairing, folds) unchanged ...
    other_learner = common.load_pairs(ctx, seeds=st._replace(learner=st.learner + 1), **kw)
    for key in ("y", "fold", "motion_idx"):
        np.testing.assert_array_equal(other_learner[key], data[key])
    assert other_learner["mapping"] == data["mapping"]
    t0, t1 = common.fold_tasks(data, cfg, st), common.fold_tasks(data, cfg, st._replace(learner=st.learner + 1))
    assert [t["learner_seed"] for t in t0] != [t["learner_seed"] for t in t1]
    assert [t["reference_seed"] for t in t0] == [t["reference_seed"] for t in t1]
    # ... and new data leave the learner's initialisation unchanged
    other_data = common.load_pairs(ctx, seeds=st._replace(data=st.data + 1), **kw)
    assert other_data["mapping"] != data["mapping"]
    np.testing.assert_array_equal(other_data["fold"], data["fold"])  # same fold stream
    t2 = common.fold_tasks(other_data, cfg, st._replace(data=st.data + 1))
    assert [t["learner_seed"] for t in t2] == [t["learner_seed"] for t in t0]
    other_folds = common.load_pairs(ctx, seeds=st._replace(splits=st.splits + 1), **kw)
    assert other_folds["mapping"] == data["mapping"] and not np.array_equal(other_folds["fold"], data["fold"])


@pytest.mark.slow
def test_ch6_labels_on_real_voices_and_motion(tmp_path):
    from mmconcepts.experiments.ch6_motion_sound import Config, run_labels

    ctx = _real_ctx(tmp_path, "fsdd", "msr-action3d")
    res = run_labels(dataclasses.replace(Config.quick(), n_per_speaker=100, n_folds=2, k=12, n_iter=30), ctx)
    assert "Free Spoken Digit" in res.notes[0] and "MSR Action3D" in res.notes[0]
    assert res.metrics["motion_labels.m2l"] > 2 * res.metrics["chance"]
    assert res.metrics["sound_labels.s2l"] > 2 * res.metrics["chance"]


@pytest.mark.slow
def test_ch6_sliding_on_real_words_and_objects(tmp_path):
    from mmconcepts.experiments.ch6_sliding import Config, run

    ctx = _real_ctx(tmp_path, "fsdd", "eth80")
    cfg = dataclasses.replace(Config.quick(), n_per_speaker=100, widths=(0.2, 0.5), k=12, n_iter=30, probe_width=0.2)
    res = run(cfg, ctx)
    res.validate()
    m = res.metrics
    assert m["localisation.n_utterances"] == 20  # every test recording, flanked by 1-3 others
    assert "flanked by 1-3 other test recordings" in res.notes[2] and "ETH-80" in res.notes[0]
    assert 0.0 < m["localisation.chance"] < 1.0 and 0.0 <= m["best.s2i"] <= 1.0


def test_learner_seed_alone_leaves_the_data_unchanged_and_vice_versa(monkeypatch, tmp_path):
    """Without any data set: fake loaders, then the streams of load_pairs and fold_tasks."""
    from mmconcepts.experiments import _ch6_common as common
    from mmconcepts.experiments.ch6_motion_sound import Config

    y = np.repeat(np.arange(4), 12)
    speech = {"y": y, "keywords": ["a", "b", "c", "d"], "mfcc": [np.zeros((5, 2))] * len(y), "speaker": "s"}
    motion = {"angles": [np.full((4, 3), float(i)) for i in range(30)], "gesture": np.arange(30) % 6,
              "ids": [str(i) for i in range(30)]}
    monkeypatch.setattr(common, "load_speech", lambda ctx, **kw: speech)
    monkeypatch.setattr(common, "load_motion", lambda ctx, **kw: motion)
    ctx = RunContext(data={}, cache_dir=tmp_path, show_progress=False)
    cfg = dataclasses.replace(Config.quick(), n_folds=3)
    st = common.streams(7)

    def draw(seeds):
        data = common.load_pairs(ctx, n_per_speaker=48, n_motion=30, n_folds=3, seeds=seeds)
        return data, common.fold_tasks(data, cfg, seeds)

    base, t_base = draw(st)
    assert (motion["gesture"][base["motion_idx"]] == np.array([base["mapping"][k] for k in "abcd"])[y]).all()
    new_learner, t_learner = draw(st._replace(learner=st.learner + 1))
    for key in ("fold", "motion_idx"):
        np.testing.assert_array_equal(new_learner[key], base[key])
    assert new_learner["mapping"] == base["mapping"]
    assert [t["learner_seed"] for t in t_learner] != [t["learner_seed"] for t in t_base]
    new_data, t_data = draw(st._replace(data=st.data + 1))
    assert new_data["mapping"] != base["mapping"] or not np.array_equal(new_data["motion_idx"], base["motion_idx"])
    np.testing.assert_array_equal(new_data["fold"], base["fold"])
    assert [t["learner_seed"] for t in t_data] == [t["learner_seed"] for t in t_base]
    assert [t["reference_seed"] for t in t_data] == [t["reference_seed"] for t in t_base]
    new_folds, _ = draw(st._replace(splits=st.splits + 1))
    assert new_folds["mapping"] == base["mapping"] and not np.array_equal(new_folds["fold"], base["fold"])
