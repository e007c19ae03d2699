"""The concept explorer of the chapter 6 and 7 runs (experiments/protocols/explorer.py): cards of a learner's atoms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import real_data_path

from mmconcepts.engine import AudioClip, MotionClip, RunContext
from mmconcepts.engine.explorer import MAX_CARDS, MAX_MEDIA
from mmconcepts.experiments.protocols import explorer as cards
from mmconcepts.multimodal import atom_label_association, top_examples


def test_card_labels_are_the_association_and_split_an_example_of_several_concepts(rng):
    W = rng.random((30, 4))
    y = rng.choice(["a", "b", "c"], size=30)
    A, names = cards.card_labels(W, list(y))
    expected, labels = atom_label_association(W, y)
    np.testing.assert_allclose(A, expected)
    assert names == list(labels)
    # an example of two concepts counts half for each (known answer); shares still sum to one
    W = np.array([[1.0, 0.0], [3.0, 1.0], [0.0, 1.0]])
    A, names = cards.card_labels(W, [("a",), ("a", "b"), "b"])
    assert names == ["a", "b"]
    np.testing.assert_allclose(A, [[2.5 / 4, 1.5 / 4], [0.5 / 2, 1.5 / 2]])


def test_concept_cards_order_skip_and_align(rng):
    W = rng.random((40, 9)) * np.array([1, 5, 0, 3, 2, 8, 4, 6, 7])  # atom 2 is never active
    y = rng.choice(["x", "y", "z"], size=40)
    seen: list[tuple[int, str]] = []

    def clip(i: int, label: str) -> AudioClip:
        seen.append((i, label))
        return AudioClip(np.zeros(10), 8000, f"example {i}")

    explorer = cards.concept_cards(W, y, note="n", clip=clip,
                                   motion=lambda i: MotionClip(curves=np.zeros((3, 1)), caption=f"example {i}"))
    atoms = [int(c.title.split()[-1]) for c in explorer.cards]
    assert len(atoms) == MAX_CARDS and 2 not in atoms
    assert atoms == list(np.argsort(-W.sum(axis=0)))[:MAX_CARDS]  # the most active first
    A, names = atom_label_association(W, y)
    top = top_examples(W, MAX_MEDIA)
    for j, card in zip(atoms, explorer.cards):
        assert card.labels[0] == (names[np.argmax(A[j])], pytest.approx(A[j].max()))
        assert [s for _, s in card.labels] == sorted((s for _, s in card.labels), reverse=True)
        assert all(s >= cards.LABEL_SHARE for _, s in card.labels[1:]) and len(card.labels) <= 3
        assert [c.caption for c in card.clips] == [f"example {i}" for i in top[j]]
        assert [m.caption for m in card.motions] == [f"example {top[j][0]}"]
    assert {label for _, label in seen} <= set(names) and len(seen) == MAX_CARDS * MAX_MEDIA
    assert explorer.note == "n"


def test_cut_clip_centres_on_the_keyword():
    sr = 1000
    x = np.arange(5000.0)  # 5 s
    assert cards.cut_clip(x, sr).samples.tolist() == x[:1000].tolist()  # no span: from the start
    assert cards.cut_clip(x, sr, (np.nan, np.nan)).samples[0] == 0
    assert cards.cut_clip(x, sr, (2.0, 2.4)).samples[[0, -1]].tolist() == [1700, 2699]  # centred on 2.2 s
    assert cards.cut_clip(x, sr, (4.8, 5.0)).samples[[0, -1]].tolist() == [4000, 4999]  # inside the recording
    assert cards.cut_clip(x, sr, (1.0, 3.5)).samples[0] == 1000  # longer than a clip: its beginning
    assert cards.cut_clip(x[:400], sr, (0.1, 0.2)).samples.size == 400  # shorter: whole


def test_skeleton_bones_link_anatomical_neighbours():
    from mmconcepts.motion import CHOREO1_MARKERS, CHOREO2_MARKERS, MSR_JOINTS, skeleton_bones

    for markers, n_bones in ((MSR_JOINTS, 19), (CHOREO2_MARKERS, 14), (CHOREO1_MARKERS, 23)):
        bones = {frozenset((markers[a], markers[b])) for a, b in skeleton_bones(markers)}
        assert len(bones) == n_bones, markers
        for side in ("left", "right"):
            assert frozenset((f"{side}_shoulder", f"{side}_elbow")) in bones
            assert frozenset((f"{side}_hip", f"{side}_knee")) in bones
        assert frozenset(("head", "neck")) in bones
        linked = {m for bone in bones for m in bone}
        assert linked == set(markers)  # one connected figure: every marker is on a bone
    # a skeleton's motion fits the frame bound: every n-th frame, the frame rate divided by n
    motion = cards.stick_figure(np.zeros((95, len(MSR_JOINTS), 3)) + np.arange(95)[:, None, None], MSR_JOINTS, 15.0)
    assert motion.n_frames == 32 and motion.frame_rate == 5.0 and motion.seconds == pytest.approx(95 / 15, abs=0.3)


@pytest.mark.slow
def test_the_fold_runs_cards_are_the_first_folds_concept_learner(tmp_path):
    """ch6-concepts, -labels, -motion-sound, -symbolic: one card per atom of the first fold's Fig. 6.10 learner (real
    FSDD words and MSR Action3D records), aligned with the keyword its association gives most, its clips the
    recordings of its top pairs."""
    from mmconcepts.experiments.ch6 import protocol as common
    from mmconcepts.experiments.ch6.motion_sound import Config
    from mmconcepts.sound.audio import load_audio

    ctx = RunContext(data={n: real_data_path(n) for n in ("fsdd", "msr-action3d")}, cache_dir=tmp_path,
                     show_progress=False)
    cfg = Config.smoke()
    data, folds = common.evaluate(ctx, cfg)
    W = folds[0]["concepts"]["coefficients"]
    assert all("coefficients" not in f["concepts"] for f in folds[1:])  # one fold keeps its coefficients
    rows = np.flatnonzero(data["fold"] != 0)
    assert W.shape == (len(rows), cfg.concept_k)
    explorer = common.fold_explorer(data, folds)
    assert explorer is not None and f"k = {cfg.concept_k}" in explorer.note
    assert len(explorer.cards) == min(int(np.sum(W.sum(axis=0) > 0)), MAX_CARDS) == cfg.concept_k
    A, names = atom_label_association(W, np.asarray(data["keywords"])[data["y"][rows]])
    top = top_examples(W, MAX_MEDIA)
    files = [Path(data["speech"]["ids"][u]) for u in rows]
    for card in explorer.cards:
        j = int(card.title.split()[-1])
        assert card.labels[0] == (names[np.argmax(A[j])], pytest.approx(A[j].max()))
        assert [c.caption.split(": ")[1] for c in card.clips] == [files[i].name for i in top[j]]
        assert all(c.sample_rate == cards.CLIP_RATE and c.seconds <= cards.CLIP_SECONDS for c in card.clips)
        (motion,) = card.motions
        record = data["motion_idx"][rows[top[j][0]]]
        assert motion.caption.endswith(data["motion"]["ids"][record]) and motion.positions is not None
    # a clip is its recording, at the clips' rate (an FSDD word is shorter than a clip: whole)
    j = int(explorer.cards[0].title.split()[-1])
    whole = load_audio(files[top[j][0]], sr=cards.CLIP_RATE, min_duration=0.0)
    np.testing.assert_array_equal(explorer.cards[0].clips[0].samples, whole[: int(cards.CLIP_SECONDS * 8000)])
