"""ch5-label-sets: TF-IDF voting with label sets (known answers), chance levels, label-set checks, the experiment
on a fake FSDD of tones, its streams, and a reduced run on the real FSDD."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from _fake_audio import fake_fsdd

from conftest import real_data_path
from mmconcepts.errors import DataError, ParameterError
from mmconcepts.experiments import RunContext, evaluate_rule
from mmconcepts.experiments.ch5 import protocol as common
from mmconcepts.experiments.ch5 import label_sets as ls
from mmconcepts.nmf.scores import l_full
from mmconcepts.sound.voting import EventVoting, relative_votes

L15, L3 = math.log(1.5), math.log(3.0)


# -- voting with label sets: hand-computed answers (eq. 5.1) -------------------------------------
def _three_tag_model() -> EventVoting:
    # events 0,1 said with {a, b}; 1,2 with b; 2,3 with c
    return EventVoting().fit([np.array([0, 1]), np.array([1, 2]), np.array([2, 3])], [("a", "b"), "b", ("c",)])


def test_voting_with_a_set_counts_the_events_for_each_tag():
    m = _three_tag_model()
    assert m.classes_ == ["a", "b", "c"]
    # n_t: a 1, b 2, c 1; n_{i,t}: e0 (1,1,0), e1 (1,2,0), e2 (0,1,1), e3 (0,0,1)
    np.testing.assert_array_equal(m.tag_counts_[:3], [1, 2, 1])
    np.testing.assert_array_equal(m.counts_[:4, :3], [[1, 1, 0], [1, 2, 0], [0, 1, 1], [0, 0, 1]])
    # w_i = log(3 / tags with i): e0..e2 in two tags, e3 in one
    np.testing.assert_allclose(m.weights()[:4], [L15, L15, L15, L3])
    # query [0, 3, 3]: a = 1 * 1 * w0; b = 1 * (1/2) * w0; c = 2 * 1 * w3
    # query [1, 2]:    a = 1 * w1;     b = (2/2) * w1 + (1/2) * w2; c = 1 * w2
    V = m.decision_function([np.array([0, 3, 3]), np.array([1, 2])])
    np.testing.assert_allclose(V, [[L15, 0.5 * L15, 2 * L3], [L15, 1.5 * L15, L15]])


def test_voting_columns_follow_the_classes_asked_for():
    m = _three_tag_model()
    V = m.decision_function([np.array([1, 2])], classes=["c", "zebra", "a"])
    np.testing.assert_allclose(V, [[L15, 0.0, L15]])  # a tag never seen gets no vote
    with pytest.raises(ParameterError, match="not one string"):
        m.decision_function([np.array([1])], classes="abc")


def test_predict_sets_thresholds_the_relative_votes():
    m = _three_tag_model()
    bags = [np.array([1, 2]), np.array([0, 3, 3]), np.array([9])]
    # relative votes: [1, 2] -> a 2/3, b 1, c 2/3; [0, 3, 3] -> a w0/(2 w3), b w0/(4 w3), c 1; [9]: no vote
    np.testing.assert_allclose(relative_votes(m.decision_function(bags)),
                               [[2 / 3, 1, 2 / 3], [L15 / (2 * L3), L15 / (4 * L3), 1], [0, 0, 0]])
    np.testing.assert_array_equal(m.predict_sets(bags, threshold=0.6), [[1, 1, 1], [0, 0, 1], [0, 0, 0]])
    np.testing.assert_array_equal(m.predict_sets(bags, threshold=0.7), [[0, 1, 0], [0, 0, 1], [0, 0, 0]])
    with pytest.raises(ParameterError, match="finite number"):
        m.predict_sets(bags, threshold=float("nan"))
    # the thesis' threshold keeps a score equal to eta: [0] votes a = w0, b = w0 / 2 exactly
    np.testing.assert_array_equal(m.predict_sets([np.array([0])], threshold=0.5), [[1, 1, 0]])


def test_a_tag_repeated_in_a_set_counts_once_and_an_empty_set_is_refused():
    a = EventVoting().fit([np.array([0, 1]), np.array([1])], [("x", "x", "y"), "y"])
    b = EventVoting().fit([np.array([0, 1]), np.array([1])], [("x", "y"), "y"])
    np.testing.assert_array_equal(a.counts_, b.counts_)
    np.testing.assert_array_equal(a.tag_counts_, b.tag_counts_)
    with pytest.raises(DataError, match=r"utterance 1 has an empty tag set.*expected at least one tag.*Fix"):
        EventVoting().fit([np.array([0]), np.array([1])], ["x", ()])


def test_single_tags_keep_their_votes():
    # one tag per utterance, the thesis' setting: e0 in a and b (w = log 1), e1 in b only (w = log 2)
    bags = [np.array([0]), np.array([0, 1])]
    plain = EventVoting().fit(bags, ["a", "b"])
    as_sets = EventVoting().fit(bags, [("a",), ["b"]])
    np.testing.assert_allclose(plain.decision_function([np.array([1, 1, 0])]), [[0.0, 2 * math.log(2)]])
    np.testing.assert_array_equal(plain.decision_function([np.array([1, 0])]),
                                  as_sets.decision_function([np.array([1, 0])]))
    assert plain.predict([np.array([1])]) == ["b"]


# -- the voting threshold, chance levels ------------------------------------------------------------
def _word_bags(rng, n, n_words=15):
    """Each word has its own events (3 of them); an utterance says 1-2 words plus 2 shared filler events.

    Few words per utterance among many: with eq. (5.1) an event seen with every tag weighs 0, and with label
    sets a word's events are also counted for the words said with it.
    """
    Y = np.zeros((n, n_words))
    bags, tags = [], []
    for i in range(n):
        said = rng.choice(n_words, int(rng.integers(1, 3)), replace=False)
        Y[i, said] = 1
        ev = [3 * w + int(rng.integers(3)) for w in said for _ in range(4)] + list(3 * n_words + rng.integers(0, 2, 2))
        bags.append(np.array(ev))
        tags.append(tuple(f"w{w}" for w in said))
    return bags, tags, Y, [f"w{w}" for w in range(n_words)]


def test_vote_threshold_picks_a_threshold_that_reconstructs_the_sets(rng):
    bags, tags, Y, keywords = _word_bags(rng, 120)
    eta, curve = ls.vote_threshold(bags[:80], tags[:80], Y[:80], keywords, cv=4, seed=0)
    assert curve.shape == ls.DEFAULT_THRESHOLD_GRID.shape and curve.max() > 0.85 and curve.min() < 0.6
    assert eta == pytest.approx(ls.DEFAULT_THRESHOLD_GRID[np.flatnonzero(curve == curve.max())][
        len(np.flatnonzero(curve == curve.max())) // 2])  # the median of the best thresholds
    m = EventVoting().fit(bags[:80], tags[:80])
    assert l_full(Y[80:], m.predict_sets(bags[80:], threshold=eta, classes=keywords)) >= 0.9
    # too high a threshold keeps the best word only: at most the one-word utterances are right
    assert l_full(Y[80:], m.predict_sets(bags[80:], threshold=0.999, classes=keywords)) <= np.mean(Y[80:].sum(1) == 1)
    assert np.mean(Y[80:].sum(1) == 1) < 0.9


def test_uniform_chance_known_answer():
    K = 10
    Y_test = np.zeros((2, K))
    Y_test[0, 0] = 1
    Y_test[1, [1, 2]] = 1
    Y_train = np.zeros((4, K))
    Y_train[0, 0] = Y_train[1, 1] = 1
    Y_train[2, [0, 1]] = 1
    Y_train[3, [0, 1, 2]] = 1  # sizes 1, 1, 2, 3: p(1) = 1/2, p(2) = p(3) = 1/4
    out = ls.uniform_chance(Y_test, Y_train)
    assert out["l_single"] == pytest.approx(0.1)
    assert out["l_given_number"] == pytest.approx((1 / 10 + 1 / 45) / 2)
    assert out["l_full"] == pytest.approx((0.5 / 10 + 0.25 / 45) / 2)


def test_chance_learner_predicts_the_most_frequent_training_set():
    Y_train = np.array([[1, 0, 0], [0, 1, 1], [0, 1, 1], [1, 1, 0]])
    S, P = ls.chance_learner(Y_train, 3, seed=0)
    np.testing.assert_array_equal(P, [[0, 1, 1]] * 3)
    assert S.shape == (3, 3) and np.all(np.argsort(-S, axis=1)[:, 0] == 1)  # b is the most frequent label


# -- label sets: bad input ----------------------------------------------------------------------
class _Corpus:
    def __init__(self, labels):
        self.labels = labels
        self.paths = [f"u{i}.wav" for i in range(len(labels))]


def test_keyword_sets_and_an_utterance_with_no_keyword():
    Y, kw = common.keyword_sets(_Corpus([("car",), ("car", "bath"), ("bath", "bath")]))
    assert kw == ["bath", "car"]
    np.testing.assert_array_equal(Y, [[0, 1], [1, 1], [1, 0]])
    with pytest.raises(DataError, match=r"utterance 1 \(u1.wav\) says no keyword: expected at least one.*got no label"
                                         r".*Fix"):
        common.keyword_sets(_Corpus([("car",), ()]))
    with pytest.raises(DataError, match=r"says no keyword.*got labels \('dog',\)"):
        common.keyword_sets(_Corpus([("dog",)]), ["car", "bath"])


def test_label_sets_of_the_wrong_shape_are_refused():
    good = np.array([[1, 0], [0, 1]])
    np.testing.assert_array_equal(common.check_label_sets(good, 2, 2), good)
    with pytest.raises(DataError, match=r"shape \(n_utterances, n_keywords\) = \(2, 3\); got shape \(2, 2\).*Fix"):
        common.check_label_sets(good, 2, 3)
    with pytest.raises(DataError, match="got shape \\(2,\\)"):
        common.check_label_sets(np.array([1, 0]), 2, 1)
    with pytest.raises(DataError, match="0/1 values"):
        common.check_label_sets(np.array([[2, 0]]), 1, 2)
    with pytest.raises(DataError, match="utterance 1 has an empty label set"):
        common.check_label_sets(np.array([[1, 0], [0, 0]]), 2, 2)


def test_more_words_per_utterance_than_the_vocabulary_is_refused():
    assert common.check_words_per_utterance((1, 3), 10) == (1, 3)
    with pytest.raises(ParameterError, match=r"up to 11 distinct keywords.*vocabulary has 10.*expected at most 10.*Fix"):
        common.check_words_per_utterance((2, 11), 10)
    with pytest.raises(ParameterError, match="1 <= fewest <= most"):
        common.check_words_per_utterance((3, 2), 10)


# -- the experiment on a fake FSDD (a tone per digit) --------------------------------------------
_fake_fsdd = fake_fsdd  # tests/_fake_audio.py


@pytest.fixture(scope="module")
def fake_fsdd(tmp_path_factory):
    return _fake_fsdd(tmp_path_factory.mktemp("fsdd") / "fsdd", np.random.default_rng(7))


def test_ch5_label_sets_smoke_on_tones(fake_fsdd, tmp_path):
    cfg = ls.Config.smoke()
    k, n = cfg.n_folds, cfg.n_folds * cfg.n_composed_per_fold
    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    res = ls.compute(cfg, ctx)
    res.validate()
    m = res.metrics
    assert m["n_utterances"] == n and m["n_folds"] == k and 1 <= m["mean_words"] <= 3
    for who in ("nmf", "voting", "chance"):
        for s in ls.SCORES:
            assert 0 <= m[f"{who}.{s}"] <= 1, (who, s)
            assert len(res.samples[f"{who}.{s}"]) == k
    assert m["voting.l_given_number"] > m["chance.l_given_number"]
    assert m["diff.l_full"] == pytest.approx(m["nmf.l_full"] - m["voting.l_full"])
    # the by-size table covers every utterance once
    assert sum(r[1] for r in res.tables["by_size"].rows) == n
    # folds of one data set (corrected resampled t), composed fold by fold: no recording on both sides
    unit = f"{k} folds"
    assert set(res.sample_units.values()) == {unit} and res.units[unit].kind == "resampled"
    assert res.units[unit].test_train_ratio == pytest.approx(1 / (k - 1))
    split = res.split_groups["label_sets"]
    assert split["shared_sources"] == 0 and split["n_folds"] == k and "composed" in split["by"]
    assert split["n_sources"] <= 80  # the 80 recordings of the fake FSDD's two speakers, at most
    assert {c.kind for c in ls.EXPERIMENT.claims} == {"ours"}  # beyond the thesis
    for claim in ls.EXPERIMENT.claims:
        assert evaluate_rule(claim.rule, m) in (True, False)
    figs = ls.present(res, cfg)
    assert set(figs) == {"label_sets"}


def test_streams_are_independent(fake_fsdd, tmp_path):
    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    s = common.streams(0)

    def data(seeds):
        d = common.label_set_corpus(ctx, seeds=seeds, n_folds=3, n_per_speaker=1, n_composed=6, n_words=(1, 3))
        return [str(p) for p in d.corpus.paths], d.Y, d.fold

    base = data(s)
    other_learner = data(s.rooted("learner", 1234).rooted("reference", 4321))
    assert base[0] == other_learner[0]
    np.testing.assert_array_equal(base[1], other_learner[1])
    np.testing.assert_array_equal(base[2], other_learner[2])
    other_data = data(s.rooted("composition", 1234))  # real recordings: the composition stream composes them
    assert base[0] != other_data[0] or not np.array_equal(base[1], other_data[1])
    np.testing.assert_array_equal(base[2], other_data[2])  # the same folds


def test_composed_label_sets_keep_each_fold_s_recordings(fake_fsdd, tmp_path):
    """A test fold's utterances are made of that fold's recordings only, and name them."""
    from mmconcepts.experiments import describe_split

    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    d = common.label_set_corpus(ctx, seeds=common.streams(0), n_folds=3, n_per_speaker=1, n_composed=6,
                                n_words=(1, 3))
    assert d.kind == "composed" and len(d.sources) == len(d.Y) == 18
    assert [len(s) for s in d.sources] == d.Y.sum(axis=1).astype(int).tolist()  # one recording per keyword said
    by_fold = [{r for s, f in zip(d.sources, d.fold) if f == i for r in s} for i in range(3)]
    assert not (by_fold[0] & by_fold[1] or by_fold[0] & by_fold[2] or by_fold[1] & by_fold[2])
    assert describe_split("t", common.fold_sources(d.sources, d.fold))["shared_sources"] == 0


def test_ch5_label_sets_refuses_more_words_than_keywords(fake_fsdd, tmp_path):
    cfg = dataclasses.replace(ls.Config.smoke(), max_words=11)
    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    with pytest.raises(ParameterError, match="vocabulary has 10 keywords"):
        ls.compute(cfg, ctx)


@pytest.mark.slow
def test_ch5_label_sets_smoke_on_real_fsdd(tmp_path):
    fsdd = real_data_path("fsdd")
    cfg = ls.Config.smoke()
    res = ls.compute(cfg, RunContext(data={"fsdd": fsdd}, cache_dir=tmp_path, show_progress=False))
    res.validate()
    m = res.metrics
    assert m["n_utterances"] == cfg.n_folds * cfg.n_composed_per_fold and m["n_folds"] == cfg.n_folds
    assert m["voting.l_given_number"] > m["chance.l_given_number"]
    assert "Free Spoken Digit" in res.notes[0]


def _tone_sentences(root, rng, n=24, *, empty_at=None):
    """Generic audio layout: utterances of 1-2 tone 'words' (labels 'w0;w3'), one speaker."""
    from mmconcepts.sound.audio import write_audio

    root.mkdir(parents=True, exist_ok=True)
    rows = ["file,speaker,labels,transcription"]
    t = np.arange(int(0.2 * 16000)) / 16000
    for i in range(n):
        said = rng.choice(6, 1 + i % 2, replace=False)
        y = np.concatenate([0.3 * np.sin(2 * np.pi * (300 + 200 * w) * t) for w in said])
        y = y + 0.02 * rng.standard_normal(y.size)
        write_audio(root / f"u{i}.wav", np.clip(y, -1, 1), 16000)
        labels = "" if i == empty_at else ";".join(f"w{w}" for w in said)
        rows.append(f"u{i}.wav,s1,{labels},")
    (root / "labels.csv").write_text("\n".join(rows) + "\n")
    return root


def test_utterances_with_several_keywords_are_used_as_recorded(tmp_path, rng):
    root = _tone_sentences(tmp_path / "audio", rng)
    ctx = RunContext(data={"audio": root}, cache_dir=tmp_path / "cache", show_progress=False)
    d = common.label_set_corpus(ctx, seeds=common.streams(0), n_folds=3, n_per_speaker=1, n_composed=5)
    assert d.kind == "as-recorded" and len(d.Y) == 24 and set(d.Y.sum(1)) == {1.0, 2.0}
    assert sorted(set(d.fold)) == [0, 1, 2]
    # each fold holds both sizes (stratified by the number of keywords)
    for f in range(3):
        assert set(d.Y[d.fold == f].sum(1)) == {1.0, 2.0}


def test_an_utterance_with_no_keyword_is_refused(tmp_path, rng):
    root = _tone_sentences(tmp_path / "audio", rng, empty_at=5)
    ctx = RunContext(data={"audio": root}, cache_dir=tmp_path / "cache", show_progress=False)
    with pytest.raises(DataError, match=r"utterance 5 \(.*u5.wav\) says no keyword: expected at least one.*Fix"):
        common.label_set_corpus(ctx, seeds=common.streams(0), n_folds=3, n_per_speaker=1, n_composed=5)


def test_the_three_scores_known_answer():
    Y = np.array([[1, 0, 0], [0, 1, 1], [1, 0, 0]])
    S = np.array([[0.9, 0.1, 0.0], [0.2, 0.5, 0.6], [0.1, 0.8, 0.0]])
    P = np.array([[1, 0, 0], [0, 1, 0], [1, 0, 0]])
    out = ls._scores(Y, S, P)
    assert out["l_single"] == pytest.approx(0.5)  # rows 0 and 2 say one keyword; row 2's best is wrong
    assert out["l_given_number"] == pytest.approx(2 / 3)  # row 1's two best are its two keywords
    assert out["l_full"] == pytest.approx(2 / 3)  # row 1 misses a keyword
    assert np.isnan(ls._scores(Y[1:2], S[1:2], P[1:2])["l_single"])  # no one-keyword utterance: not measured
