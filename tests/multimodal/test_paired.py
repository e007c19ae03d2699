"""paired_dataset: every recording used or counted, no recording on two sides, pairs that respect the concepts."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from mmconcepts.errors import DataError, DataFormatError, DataWarning, ParameterError
from mmconcepts.motion import MotionDataset, MotionRecording
from mmconcepts.multimodal import (MultimodalNMF, PairedDataset, crossmodal_distances, matching_success_rate,
                                  paired_dataset)
from mmconcepts.vision import ImageSet


def _images(counts: dict[str, int], rng=None) -> ImageSet:
    rng = rng or np.random.default_rng(0)
    labels = [lab for lab, n in counts.items() for _ in range(n)]
    return ImageSet([rng.random((6, 6, 3)) for _ in labels], labels, paths=[f"/im/{i}.png" for i in range(len(labels))])


def _motion(counts: dict[str, int]) -> MotionDataset:
    names = {i: lab for i, lab in enumerate(counts)}
    recs = [MotionRecording(np.zeros((3, 2, 3)), ("a", "b"), labels=(i,), source=f"/m/{i}_{k}.csv")
            for i, lab in names.items() for k in range(counts[lab])]
    return MotionDataset(recs, names)


def _label(data: PairedDataset, m: str, i: int) -> str:
    coll = data.collections[m]
    if data.kinds[m] == "image":
        return coll.labels[i]
    return coll.label_names[coll[i].labels[0]]


def _check_invariants(data: PairedDataset) -> None:
    assert not data.shared_recordings()
    for m in data.modalities:
        for e in range(len(data)):  # each example's recordings are of its concept, in each modality's words
            assert _label(data, m, int(data.items[m][e])) == data.labels[m][data.y[e]]


@settings(max_examples=40, deadline=None)
@given(st.dictionaries(st.sampled_from("abcde"), st.integers(0, 9), min_size=1),
       st.dictionaries(st.sampled_from("abcdef"), st.integers(0, 9), min_size=1), st.integers(0, 2**16))
def test_shared_labels_every_recording_used_or_counted(im_counts, mo_counts, seed):
    shared = {k for k in im_counts if im_counts[k] and mo_counts.get(k)}
    images, motion = _images(im_counts), _motion(mo_counts)
    assume(shared)  # disjoint vocabularies are paired by a bijection: tested below
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = paired_dataset({"image": images, "motion": motion}, random_state=seed)
    _check_invariants(data)
    assert data.concepts == tuple(sorted(shared))
    for m, coll, counts in (("image", images, im_counts), ("motion", motion, mo_counts)):
        used = set(data.items[m].tolist())
        eligible = {i for i in range(len(coll)) if _label(data, m, i) in shared}
        # a concept with fewer recordings than parts in another modality cannot fill every part: those
        # recordings are the only ones allowed to go unused
        thin = {k for k in shared if min(im_counts[k], mo_counts[k]) < 3}
        assert {i for i in eligible if _label(data, m, i) not in thin} <= used
        assert used <= eligible
        n_out = sum(v for k, v in counts.items() if k not in shared)
        if n_out:
            assert any(f"{m}: {n_out} recording" in str(w.message) for w in caught if w.category is DataWarning)


def test_different_vocabularies_pair_by_a_random_bijection_and_warn():
    images = _images({"apple": 5, "car": 5, "cup": 5})
    motion = _motion({"wave": 5, "kick": 5})
    with pytest.warns(DataWarning, match=r"image: 5 recordings with a label left without a counterpart"):
        data = paired_dataset({"image": images, "motion": motion}, random_state=0)
    _check_invariants(data)
    assert len(data.concepts) == 2 and set(data.labels["motion"]) == {"wave", "kick"}
    pairs = {(data.labels["image"][c], data.labels["motion"][c]) for c in range(2)}
    assert len({a for a, _ in pairs}) == 2  # one-to-one
    bijections = {tuple(paired_dataset({"image": images, "motion": motion}, random_state=s).labels["motion"])
                  for s in range(12) for _ in [warnings.simplefilter("ignore", DataWarning)]}
    assert len(bijections) > 1  # the correspondence is drawn, not fixed


def test_parts_follow_the_shares_per_concept():
    data = paired_dataset({"image": _images({"a": 10, "b": 20}), "motion": _motion({"a": 10, "b": 20})},
                          random_state=3)
    for c, n in ((0, 10), (1, 20)):
        got = [int(((data.y == c) & (data.part == p)).sum()) for p in ("train", "test", "reference")]
        assert got == [round(0.6 * n), round(0.2 * n), round(0.2 * n)]
    assert data.parts == ("train", "test", "reference")


def test_pairing_csv_groups_examples_that_share_a_recording(tmp_path):
    images = _images({"a": 6, "b": 6})
    motion = _motion({"a": 6, "b": 6})
    path = tmp_path / "pairs.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["image_file", "motion_file", "concept"])
        for i in range(12):
            w.writerow([f"{i}.png", f"/m/{i // 6}_{i % 6}.csv#" if False else f"{i // 6}_{i % 6}.csv", "ab"[i // 6]])
            w.writerow([f"{i}.png", f"{i // 6}_{(i + 1) % 6}.csv", "ab"[i // 6]])  # each image in two examples
        w.writerow(["missing.png", "0_0.csv", "a"])
    with pytest.warns(DataWarning, match="1 recording rows of the pairing CSV naming an unknown file"):
        data = paired_dataset({"image": images, "motion": motion}, pairing=path, random_state=0)
    assert len(data) == 24 and data.concepts == ("a", "b")
    assert not data.shared_recordings()
    assert set(data.parts) == {"train"}  # within a concept every example shares a recording with its neighbours


def test_pairing_csv_needs_the_columns(tmp_path):
    path = tmp_path / "pairs.csv"
    path.write_text("sound_file,concept\nx.wav,a\n")
    with pytest.raises(DataFormatError, match="image_file"):
        paired_dataset({"image": _images({"a": 2}), "motion": _motion({"a": 2})}, pairing=path)


def test_bad_arguments_say_what_was_expected(tmp_path):
    with pytest.raises(DataError, match="at least two modalities"):
        paired_dataset({"image": _images({"a": 2})})
    with pytest.raises(ParameterError, match="cannot tell what modality"):
        paired_dataset({"colours": object(), "image": _images({"a": 2})})
    with pytest.raises(DataError, match="not one"):
        paired_dataset({"image": tmp_path / "nope", "motion": _motion({"a": 2})})
    with pytest.raises(ParameterError, match="positive shares"):
        paired_dataset({"image": _images({"a": 2}), "motion": _motion({"a": 2})}, parts={"train": 1.0})


class _Spy:
    """A transformer that records what it is fitted on; its features are the image means."""

    fits: list = []

    def __init__(self, random_state=None):
        self.random_state = random_state

    def get_params(self, deep=True):
        return {"random_state": self.random_state}

    def set_params(self, **p):
        self.random_state = p["random_state"]
        return self

    def fit(self, X):
        _Spy.fits.append({id(x) for x in X})
        return self

    def transform(self, X):
        return np.array([[x.mean(), 1 - x.mean()] for x in X])


def test_features_are_fitted_on_training_recordings_only():
    photos, drawings = _images({"a": 10, "b": 10}), _images({"a": 7, "b": 12}, np.random.default_rng(1))
    data = paired_dataset({"photos": photos, "drawings": drawings}, random_state=0)
    _Spy.fits = []
    X = data.features(image=_Spy(), random_state=1)
    for fitted, (m, coll) in zip(_Spy.fits, (("photos", photos), ("drawings", drawings))):
        assert fitted == {id(coll[int(i)]) for i in data.items[m][data.indices("train")]}
        for p in data.parts:
            rows = data.items[m][data.indices(p)]
            np.testing.assert_allclose(X[p][m][:, 0], [coll[int(i)].mean() for i in rows])


def test_folders_in_the_generic_layouts_end_to_end(tmp_path):
    """From two folders (WAVs and PNGs with labels.csv) to cross-modal features and a fitted learner."""
    sf = pytest.importorskip("soundfile")
    pytest.importorskip("skimage")
    from matplotlib.image import imsave

    from mmconcepts.sound.hac import HAC

    rng = np.random.default_rng(0)
    sounds, images = tmp_path / "words", tmp_path / "objects"
    sounds.mkdir()
    images.mkdir()
    words = {"ball": 300.0, "dog": 900.0}
    with open(sounds / "labels.csv", "w") as f:
        f.write("file,labels,speaker\n")
        for w, hz in words.items():
            for k in range(6):
                t = np.arange(8000) / 16000
                sf.write(sounds / f"{w}{k}.wav", 0.3 * np.sin(2 * np.pi * hz * t) + 0.01 * rng.standard_normal(t.size),
                         16000)
                f.write(f"{w}{k}.wav,{w},s{k % 2}\n")
    with open(images / "labels.csv", "w") as f:
        f.write("file,labels\n")
        for j, w in enumerate(("ball", "dog", "cat")):
            for k in range(5):
                im = np.zeros((24, 24, 3))
                im[..., j] = 0.8
                imsave(images / f"{w}{k}.png", np.clip(im + 0.05 * rng.random(im.shape), 0, 1))
                f.write(f"{w}{k}.png,{w}\n")
    with pytest.warns(DataWarning, match="image: 5 recordings with a label not shared"):
        data = paired_dataset({"sound": sounds, "image": images}, random_state=0)
    assert data.concepts == ("ball", "dog")
    assert set(data.items["sound"].tolist()) == set(range(12))  # every recording of a shared concept
    X = data.features(random_state=1, sound=HAC((4, 4, 4), lags=(2,)))
    assert X["train"]["sound"].shape[0] == X["train"]["image"].shape[0] == data.indices("train").size
    model = MultimodalNMF(4, max_iter=20, random_state=2).fit(X["train"])
    D = crossmodal_distances(model, {"sound": X["test"]["sound"]}, {"image": X["reference"]["image"]},
                             space="internal", metric="cosine")
    # two clean concepts (a low and a high tone; a red and a green object): every word names its object
    assert matching_success_rate(D, data.y[data.indices("test")], data.y[data.indices("reference")],
                                 random_state=3) == 1.0
