"""Chapter 6's splits are grouped by source recording: no recording behind a held-out example feeds training.

Paired multimodal examples (an utterance with a motion record, with an object view, or with
both; a window of the training stream with the views shown while it plays) are split by
splitting each modality's recordings by concept and pairing within each part. These
property tests draw random set sizes (concepts with few or many recordings, more examples
than records, unused gestures or objects) and check every split function of the chapter
with :func:`~mmconcepts.engine.splits.describe_split` (which raises on a shared
recording), and that each example's recordings are of its concept.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mmconcepts.errors import DataError, ExperimentError
from mmconcepts.experiments import RunContext, describe_split
from mmconcepts.experiments.protocols import pairs as pairs_protocol
from mmconcepts.experiments.ch6 import protocol as common
from mmconcepts.engine.splits import concept_parts

_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def _sets(draw, min_items: int = 3):
    """Concepts of the examples (utterances) and of the items (motion records or views; -1: unused)."""
    n_concepts = draw(st.integers(2, 5))
    per_example = draw(st.lists(st.integers(min_items, 12), min_size=n_concepts, max_size=n_concepts))
    per_item = draw(st.lists(st.integers(min_items, 8), min_size=n_concepts, max_size=n_concepts))
    n_unused = draw(st.integers(0, 4))
    y = np.repeat(np.arange(n_concepts), per_example)
    items = np.r_[np.repeat(np.arange(n_concepts), per_item), -np.ones(n_unused, int)]
    return y, items, draw(st.integers(0, 2**31 - 1))


def _ids(prefix: str, n: int) -> list[str]:
    return [f"{prefix}{i}" for i in range(n)]


@_SETTINGS
@given(data=_sets(), parts=st.one_of(st.integers(2, 3), st.just((0.6, 0.2, 0.2)), st.just((0.5, 0.5))))
def test_pairing_within_parts_never_shares_a_recording_across_parts(data, parts):
    y, items, seed = data
    rng = np.random.default_rng(seed)
    part_y, part_i = concept_parts(y, parts, rng), concept_parts(items, parts, rng)
    assert (part_i[items < 0] == -1).all()
    paired = common.pair_within_parts(y, part_y, items, part_i, rng, "record")
    assert (items[paired] == y).all() and (part_i[paired] == part_y).all()  # same concept, same part
    sources = common.example_sources(sound=_ids("u", len(y)), motion=[f"m{i}" for i in paired])
    for held_out in np.unique(part_y):  # every part against all the others
        split = describe_split("test", [([sources[i] for i in np.flatnonzero(part_y != held_out)],
                                         [sources[i] for i in np.flatnonzero(part_y == held_out)])])
        assert split["shared_sources"] == 0
    assert common.part_split_groups("test", [(sources, part_y)])["shared_sources"] == 0


@pytest.mark.parametrize("leak", ["a training record", "a training utterance"])
def test_part_split_groups_raises_on_a_shared_recording(leak):
    """The check is wired: one held-out example made of a training recording makes it raise."""
    part = np.array([0, 0, 0, 1, 2])
    sound, motion = _ids("u", 5), ["m0", "m1", "m2", "m3", "m4"]
    if leak == "a training record":
        motion[3] = "m1"
    else:
        sound[4] = "u0"
    with pytest.raises(ExperimentError, match="recording"):
        common.part_split_groups("test", [(common.example_sources(sound=sound, motion=motion), part)])


def _fake_loaders(monkeypatch, y, gestures, n_keywords):
    keywords = [f"k{c}" for c in range(n_keywords)]
    speech = {"y": y, "keywords": keywords, "mfcc": [np.full((4, 2), float(i)) for i in range(len(y))],
              "speaker": "s", "ids": _ids("utt", len(y))}
    motion = {"angles": [np.full((3, 2), float(i)) for i in range(len(gestures))], "gesture": gestures,
              "ids": _ids("rec", len(gestures))}
    monkeypatch.setattr(pairs_protocol, "load_speech", lambda ctx, **kw: speech)
    monkeypatch.setattr(pairs_protocol, "load_motion", lambda ctx, **kw: motion)
    return keywords, motion


@_SETTINGS
@given(data=_sets(), extra_gestures=st.lists(st.integers(2, 6), max_size=2), n_folds=st.integers(2, 5),
       seed=st.integers(0, 1000))
def test_load_pairs_folds_are_grouped_by_recording(data, extra_gestures, n_folds, seed, tmp_path_factory):
    y, items, _ = data
    n_concepts = int(y.max()) + 1
    # the records of n_concepts gestures and of a few more (the bijection leaves some gestures unused)
    gestures = np.r_[items[items >= 0], np.repeat(n_concepts + np.arange(len(extra_gestures)), extra_gestures)]
    gestures = np.random.default_rng(seed).permutation(gestures)
    with pytest.MonkeyPatch.context() as mp:
        keywords, motion = _fake_loaders(mp, y, gestures, n_concepts)
        ctx = RunContext(data={}, cache_dir=tmp_path_factory.mktemp("c"), show_progress=False)
        pairs = common.load_pairs(ctx, n_per_speaker=len(y), n_motion=len(gestures), n_folds=n_folds,
                                  streams=common.streams(seed))
    record_gesture = gestures[pairs["motion_idx"]]
    assert all(record_gesture[i] == pairs["mapping"][keywords[c]] for i, c in enumerate(y))  # the concept's gesture
    split = common.fold_split_groups(pairs)
    assert split["shared_sources"] == 0 and split["n_folds"] == pairs["n_folds"] >= 2
    assert split["n_sources"] == len(y) + len(set(pairs["motion_idx"].tolist()))
    for rec in set(pairs["motion_idx"].tolist()):  # a record serves in one fold only
        assert len(set(pairs["fold"][pairs["motion_idx"] == rec].tolist())) == 1


class _Images:
    """An image set's labels, views and (no) paths, as ``ImageSet`` has them."""

    def __init__(self, labels, views):
        self.labels, self.views, self.paths = list(labels), list(views), None


def _views(n_objects: int, n_views: int) -> _Images:
    return _Images([f"obj{o}" for o in range(n_objects) for _ in range(n_views)],
                   [f"{v:02d}" for _ in range(n_objects) for v in range(n_views)])


@_SETTINGS
@given(data=_sets(), n_views=st.integers(3, 9), extra_objects=st.integers(0, 2))
def test_image_features_repetitions_are_grouped_by_recording(data, n_views, extra_objects):
    from mmconcepts.experiments.ch6.image_features import split_repetition

    y, _, seed = data
    n_concepts = int(y.max()) + 1
    ims = _views(n_concepts + extra_objects, n_views)
    drng, frng = np.random.default_rng(seed), np.random.default_rng(seed + 1)
    objects = sorted(set(ims.labels))
    image_concept = common.image_concepts(ims.labels, drng.permutation(objects)[:n_concepts].tolist())
    reps = []
    for _ in range(3):
        part_y, image_of = split_repetition(y, image_concept, frng, drng)
        assert (image_concept[image_of] == y).all()
        reps.append((common.example_sources(sound=_ids("u", len(y)), image=[common.image_ids(ims)[i]
                                                                             for i in image_of]), part_y))
    split = common.part_split_groups("test", reps)
    assert split["shared_sources"] == 0 and split["n_folds"] == 3


@_SETTINGS
@given(data=_sets(), n_views=st.integers(3, 9), extra=st.integers(0, 2))
def test_modalities_repetitions_are_grouped_by_recording(data, n_views, extra):
    from mmconcepts.experiments.ch6.modalities import split_repetition

    y, items, seed = data
    n_concepts = int(y.max()) + 1
    keywords = [f"k{c}" for c in range(n_concepts)]
    # an extra gesture (left out of some bijections) with as many records as the first concept's
    gestures = np.r_[items[items >= 0], np.full(extra and int(np.sum(items == 0)), n_concepts)]
    ims = _views(n_concepts + extra, n_views)
    drng, frng = np.random.default_rng(seed), np.random.default_rng(seed + 1)
    reps = []
    for _ in range(3):
        part_y, motion_of, image_of = split_repetition(keywords, y, gestures, ims.labels, sorted(set(ims.labels)),
                                                       drng, frng)
        assert len(set(gestures[motion_of[y == 0]].tolist())) == 1  # one gesture per concept
        reps.append((common.example_sources(sound=_ids("u", len(y)), motion=[f"m{i}" for i in motion_of],
                                            image=[common.image_ids(ims)[i] for i in image_of]), part_y))
    assert common.part_split_groups("test", reps)["shared_sources"] == 0


def _sliding_inputs(y: np.ndarray, n_views: int, rng: np.random.Generator):
    n_concepts = int(y.max()) + 1
    mfcc = [np.zeros((int(rng.integers(20, 60)), 2)) for _ in y]
    speech = {"keywords": [f"k{c}" for c in range(n_concepts)], "y": y, "mfcc": mfcc, "corpus": None,
              "spans": np.full((len(y), 2), np.nan), "ids": _ids("u", len(y))}
    return speech, _views(n_concepts, n_views)


@_SETTINGS
@given(data=_sets(min_items=5), n_views=st.integers(3, 8), seed=st.integers(0, 1000),
       n_repeats=st.sampled_from([1, 3]))
def test_sliding_repetitions_are_grouped_by_recording(data, n_views, seed, n_repeats):
    from mmconcepts.experiments.ch6.sliding import Config, _prepare, repetition_streams

    y, _, _ = data
    speech, ims = _sliding_inputs(y, n_views, np.random.default_rng(seed))
    config = dataclasses.replace(Config.quick(), n_repeats=n_repeats, n_test_folds=2)
    st_ = common.streams(seed)
    reps = [_prepare(config, speech, ims, [None] * len(ims.labels), repetition_streams(st_, r))
            for r in range(n_repeats)]
    split = describe_split("test", [rep["sources"] for rep in reps])
    assert split["shared_sources"] == 0
    for rep in reps:
        task = rep["task"]
        assert set(task["tr"].tolist()).isdisjoint(task["te"].tolist())
        assert set(task["img_train"].tolist()).isdisjoint(task["ref_imgs"].tolist())
        assert set(task["frame_img"].tolist()) | set(task["whole_img"].tolist()) <= set(task["img_train"].tolist())
        assert sorted(task["order"].tolist()) == sorted(task["tr"].tolist())


def test_example_sources_need_one_id_per_example():
    assert common.example_sources(sound=["a", "b"], motion=["m", "m"]) == [frozenset({"sound:a", "motion:m"}),
                                                                          frozenset({"sound:b", "motion:m"})]
    with pytest.raises(DataError, match="one recording id per example"):
        common.example_sources(sound=["a", "b"], motion=["m"])
