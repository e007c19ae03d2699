"""Chapter 5's splits are grouped by source recording: no recording behind a test example feeds training.

Composed utterances (several recordings of one word said in a row) are split by splitting the
recordings into stratified folds and composing each fold's utterances from that fold's
recordings only; single-word utterances are one recording each, split per speaker (the
thesis' protocols are speaker-dependent); the cluster tree's queries come from utterances the
tree was not built from, each repetition from its own part of the corpus. These property
tests draw random corpora and check every split function of the chapter with
:func:`~mmconcepts.engine.splits.describe_split` (which raises on a shared recording).
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import RunContext, describe_split
from mmconcepts.experiments.ch5 import protocol as common
from mmconcepts.experiments.ch5 import incremental as ch5_incremental, tree as ch5_tree

_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def _recordings(draw):
    """Keywords of the recordings (2 to 8 of each), a number of folds, a seed."""
    n_keywords = draw(st.integers(2, 6))
    counts = draw(st.lists(st.integers(2, 8), min_size=n_keywords, max_size=n_keywords))
    y = np.repeat([f"k{c}" for c in range(n_keywords)], counts)
    return y, draw(st.integers(2, 6)), draw(st.integers(0, 2**31 - 1))


class _Recordings:
    """The part of a SpeechCorpus that composition uses: paths, and subsets of them."""

    def __init__(self, paths):
        self.paths = list(paths)

    def subset(self, idx):
        return _Recordings([self.paths[int(i)] for i in idx])

    def __len__(self):
        return len(self.paths)


class _Composed:
    def __init__(self, sources):
        self.sources = sources

    def __len__(self):
        return len(self.sources)


def _fake_compose(ctx, corpus, *, n_utterances, seed, n_words, pause_s):
    """As compose_utterances: each utterance is 1+ distinct recordings of the corpus it is given, nothing else."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_utterances):
        n = min(int(rng.integers(n_words[0], n_words[1] + 1)), len(corpus.paths))
        out.append([str(p) for p in rng.choice(corpus.paths, size=n, replace=False)])
    return _Composed(out)


@_SETTINGS
@given(data=_recordings(), n_composed=st.integers(1, 6), lo=st.integers(1, 2), extra=st.integers(0, 2))
def test_composing_fold_by_fold_never_puts_a_recording_on_both_sides(data, n_composed, lo, extra):
    y, n_folds, seed = data
    fold = common.recording_folds(y, n_folds, seed)
    k = int(fold.max()) + 1
    assert k == min(n_folds, int(np.unique(y, return_counts=True)[1].min()))
    assert sorted(set(fold.tolist())) == list(range(k))  # every recording in exactly one fold
    for i in range(k):  # stratified: each fold holds every keyword
        assert set(y[fold == i]) == set(y)
    paths = [f"rec{j}.wav" for j in range(len(y))]
    with mock.patch.object(common, "composed_corpus", _fake_compose), \
            mock.patch.object(common, "utterance_sources", lambda c: c.sources):
        parts = common.compose_by_fold(None, _Recordings(paths), fold, n_composed=n_composed, streams=common.streams(seed),
                                       n_words=(lo, lo + extra))
    assert len(parts) == k
    for i, part in enumerate(parts):  # fold i's utterances are made of fold i's recordings only
        assert {s for src in part.sources for s in src} <= {paths[j] for j in np.flatnonzero(fold == i)}
    fold_of = np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)])
    sources = [src for p in parts for src in p.sources]
    # the learner of fold i trains on the other folds' utterances and on the other folds' single recordings
    split = describe_split("test", common.fold_sources(sources, fold_of, extra_train=[([[p] for p in paths], fold)]))
    assert split["shared_sources"] == 0 and split["n_folds"] == k


@pytest.mark.parametrize("leak", ["a test utterance made of a training recording", "a test recording as training"])
def test_fold_sources_with_a_shared_recording_is_refused(leak):
    """The check is wired: one test example made of a training recording makes describe_split raise."""
    sources = [["a", "b"], ["c"], ["d", "e"], ["f"]]
    fold = np.array([0, 0, 1, 1])
    singles, single_fold = [["a"], ["b"], ["c"], ["d"], ["e"], ["f"]], np.array([0, 0, 0, 1, 1, 1])
    assert describe_split("t", common.fold_sources(sources, fold, extra_train=[(singles, single_fold)]))[
        "shared_sources"] == 0
    if leak.startswith("a test utterance"):
        sources[3] = ["f", "a"]  # fold 1's utterance holds a recording of fold 0
    else:
        single_fold[0] = 1  # recording a, behind a fold-0 utterance, is a training recording of fold 0
    with pytest.raises(ExperimentError, match="recording"):
        describe_split("t", common.fold_sources(sources, fold, extra_train=[(singles, single_fold)]))


def test_fold_sources_known_answer():
    out = common.fold_sources([["a"], ["b"], ["c"]], np.array([0, 1, -1]), extra_train=[([["x"], ["y"]], [1, 0])])
    assert out == [([["b"], ["c"], ["x"]], [["a"]]), ([["a"], ["c"], ["y"]], [["b"]])]


@_SETTINGS
@given(data=_recordings(), n_speakers=st.integers(1, 3), n_train=st.integers(1, 12), n_test=st.integers(1, 6),
       n_repeats=st.integers(1, 3))
def test_speaker_splits_keep_recordings_apart_and_are_speaker_dependent(data, n_speakers, n_train, n_test, n_repeats):
    y, _, seed = data
    y = np.tile(y, n_speakers)
    speakers = np.repeat([f"s{i}" for i in range(n_speakers)], len(y) // n_speakers)
    splits = ch5_incremental.speaker_splits(y, speakers, n_train=n_train, n_test=n_test, n_repeats=n_repeats,
                                            seed=seed)
    assert len(splits) == n_repeats
    for rep in splits:
        assert set(rep) == set(speakers)  # every speaker on both sides: speaker-dependent, as the thesis
        for s, (tr, te) in rep.items():
            assert (speakers[tr] == s).all() and (speakers[te] == s).all()
            assert len(te) >= 1 and len(tr) <= n_train and not set(tr) & set(te)
        split = describe_split("t", [([[f"u{i}"] for i in tr], [[f"u{i}"] for i in te]) for tr, te in rep.values()])
        assert split["shared_sources"] == 0


@_SETTINGS
@given(n=st.integers(2, 60), parts=st.integers(1, 30), seed=st.integers(0, 2**31 - 1))
def test_corpus_parts_are_disjoint_and_cover_the_corpus(n, parts, seed):
    parts = min(parts, n // 2)
    out = ch5_tree.corpus_parts(n, parts, np.random.default_rng(seed))
    assert len(out) == parts
    assert sorted(np.concatenate(out).tolist()) == list(range(n))
    assert max(map(len, out)) - min(map(len, out)) <= 1


@_SETTINGS
@given(lengths=st.lists(st.integers(1, 6), min_size=10, max_size=40), n_train=st.integers(1, 30),
       n_queries=st.integers(1, 20), n_repeats=st.integers(1, 5), seed=st.integers(0, 2**31 - 1))
def test_tree_queries_never_come_from_a_tree_utterance(lengths, n_train, n_queries, n_repeats, seed):
    windows = [np.zeros((m, 2, 1)) + i for i, m in enumerate(lengths)]  # window values name their utterance
    cfg = ch5_tree.Config(n_repeats=n_repeats, n_train_utterances=n_train, n_queries=n_queries)
    plans = ch5_tree._plan(windows, cfg, common.streams(1).rooted("splits", seed))
    assert len(plans) == n_repeats
    seen = set()
    for p in plans:
        train, owner = set(p["train"].tolist()), set(p["owner"].tolist())
        assert not (train | owner) & seen  # the repetitions use disjoint utterances
        seen |= train | owner
        assert not train & owner and 1 <= len(p["queries"]) <= n_queries
        assert 1 <= len(p["train"]) <= n_train
        for q, o in zip(p["queries"], p["owner"]):  # each query is a window of its owner utterance
            assert (q == o).all()
    split = describe_split("t", [([[i] for i in p["train"]], [[o] for o in p["owner"]]) for p in plans])
    assert split["shared_sources"] == 0


def test_composed_utterances_name_their_source_recordings(tmp_path, rng):
    """utterance_sources reads what compose_utterances wrote: the fold's recordings, by the same ids."""
    from _fake_audio import fake_fsdd

    root = fake_fsdd(tmp_path / "fsdd", rng, speakers=("amy",), per_digit=2)
    ctx = RunContext(data={"fsdd": root}, cache_dir=tmp_path / "cache", show_progress=False)
    corpus = common.load_corpus(ctx, n_per_speaker=1)
    y = common.keyword_targets(corpus)
    fold = common.recording_folds(y, 2, seed=3)
    parts = common.compose_by_fold(ctx, corpus, fold, n_composed=4, streams=common.streams(5), n_words=(2, 3))
    own = common.utterance_sources(corpus)
    assert all(len(s) == 1 for s in own)
    for i, part in enumerate(parts):
        mine = {s[0] for s, f in zip(own, fold) if f == i}
        got = common.utterance_sources(part)
        assert len(got) == 4 and all(2 <= len(s) <= 3 for s in got)
        assert {r for s in got for r in s} <= mine
