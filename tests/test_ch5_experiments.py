"""The chapter 5 recogniser and experiments, on a tiny generated corpus in the generic layout."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.experiments import RunContext
from mmconcepts.experiments import _ch5_common as common
from mmconcepts.sound.voting import TreeVotingClassifier


# -- the recogniser on synthetic windows -----------------------------------------------------
def window_utterances(rng, n, n_tags=4, T=5, d=3):
    """Each tag has its own 'word' (3 window prototypes); utterances mix it with shared filler windows."""
    words = rng.normal(scale=4, size=(n_tags, 3, T, d))
    filler = rng.normal(scale=4, size=(6, T, d))
    utts, tags = [], []
    for _ in range(n):
        t = int(rng.integers(n_tags))
        w = np.concatenate([words[t], filler[rng.choice(6, 4)]]) + 0.2 * rng.normal(size=(7, T, d))
        utts.append(w)
        tags.append(f"tag{t}")
    return utts, tags


@pytest.mark.parametrize("metric", ["euclidean", "dtw"])
@pytest.mark.parametrize("events", ["leaves", "nodes"])
def test_tree_voting_learns_tags(rng, metric, events):
    utts, tags = window_utterances(rng, 120)
    model = TreeVotingClassifier(3.0, metric=metric, events=events, random_state=0).fit(utts[:80], tags[:80])
    assert model.score(utts[80:], tags[80:]) > 0.9  # chance 0.25
    assert model.tree_.n_leaves_ < 80 * 7  # windows were grouped into events


def test_tree_voting_incremental_equals_batch(rng):
    utts, tags = window_utterances(rng, 60)
    a = TreeVotingClassifier(3.0, metric="euclidean", random_state=0).fit(utts, tags)
    b = TreeVotingClassifier(3.0, metric="euclidean", random_state=0)
    for i in range(0, 60, 25):
        b.partial_fit(utts[i : i + 25], tags[i : i + 25])
    np.testing.assert_array_equal(a.decision_function(utts), b.decision_function(utts))


def test_tree_voting_bad_input(rng):
    utts, tags = window_utterances(rng, 5)
    with pytest.raises(DataError, match="5 utterances but 4 tags"):
        TreeVotingClassifier(1.0).fit(utts, tags[:4])
    with pytest.raises(ParameterError):
        TreeVotingClassifier(1.0, events="phonemes").fit(utts, tags)
    with pytest.raises(DataError, match="not fitted"):
        TreeVotingClassifier(1.0).predict(utts)


def test_choose_r_max_ignores_windows_of_the_same_utterance(rng):
    # two utterances of near-identical windows, far from each other
    a = rng.normal(size=(1, 4, 2)) + 0.01 * rng.normal(size=(30, 4, 2))
    b = a + 10.0
    r = common.choose_r_max([a, b], metric="euclidean", quantile=0.5, seed=0)
    assert r > 15  # the distance across utterances, not the ~0.03 within one


# -- the experiments ---------------------------------------------------------------------
@pytest.fixture
def tiny_corpus(tiny_speech_corpus):
    return tiny_speech_corpus


def ctx_for(root, tmp_path):
    return RunContext(data={"audio": root}, cache_dir=tmp_path, show_progress=False)


@pytest.mark.slow
def test_ch5_incremental_small(tiny_corpus, tmp_path):
    from mmconcepts.experiments.ch5_incremental import Config, run

    cfg = dataclasses.replace(Config.quick(), n_train=30, n_test=10, session=10, multi_session=20)
    res = run(cfg, ctx_for(tiny_corpus, tmp_path))
    res.validate()
    m = res.metrics
    assert 0 <= m["single_speaker.final_accuracy"] <= 1
    assert m["single_speaker.final_accuracy"] > 2 * m["chance.accuracy"]
    assert len(res.tables["single_speaker"].rows) == 3  # after 10, 20, 30 utterances
    assert [r[0] for r in res.tables["multi_speaker"].rows] == [20, 40, 60]
    assert set(res.figures) == {"fig5_3", "fig5_4"}


@pytest.mark.slow
def test_ch5_nmf_keywords_small(tiny_corpus, tmp_path):
    from mmconcepts.experiments.ch5_nmf_keywords import Config, run

    cfg = dataclasses.replace(Config.quick(), n_folds=3, n_components=12, max_iter=40)
    res = run(cfg, ctx_for(tiny_corpus, tmp_path))
    res.validate()
    m = res.metrics
    assert m["n_utterances"] == 50 and m["n_folds"] == 3
    assert m["nmf.accuracy"] > 2 * m["chance.accuracy"]
    assert m["voting.accuracy"] > 2 * m["chance.accuracy"]


@pytest.mark.slow
def test_ch5_tree_small(tiny_corpus, tmp_path):
    from mmconcepts.experiments.ch5_tree import Config, run

    cfg = dataclasses.replace(Config.quick(), n_train_utterances=40, n_queries=150)
    res = run(cfg, ctx_for(tiny_corpus, tmp_path))
    res.validate()
    m = res.metrics
    assert m["exact.n_distances"] == m["n_leaves"]
    assert m["restart_b24.recall"] >= m["restart_b2.recall"] >= m["greedy.recall"] - 1e-12
    costs = [m[f"restart_b{b}.n_distances"] for b in (2, 4, 8, 12, 16, 24)]
    assert costs == sorted(costs)


def test_corpus_loading_rejects_multi_keyword_utterances(tmp_path):
    class Fake:
        labels = [("car",), ("car", "bath")]
        paths = ["a.wav", "b.wav"]

    with pytest.raises(DataError, match="utterance 1"):
        common.keyword_targets(Fake())
