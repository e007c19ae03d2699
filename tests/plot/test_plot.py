"""mmconcepts.plot: each figure shows what it says (pinned to top_examples, librosa, sklearn, the input) and
refuses bad input with a typed error."""

from __future__ import annotations

import sys

import matplotlib
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from scipy.sparse import csgraph, coo_matrix

from mmconcepts.errors import DataError, MissingExtraError, ParameterError
from mmconcepts.motion import CHOREO1_MARKERS, CHOREO2_MARKERS, MSR_JOINTS, MotionDataset, MotionRecording
from mmconcepts.multimodal import atom_label_association, top_examples
from mmconcepts.motion import skeleton_bones
from mmconcepts.plot import (
    plot_activation_timeline,
    plot_atom_labels,
    plot_confusion,
    plot_dictionary_images,
    plot_dictionary_motion,
    plot_dictionary_skeletons,
    plot_dictionary_sounds,
)
from mmconcepts.sound import MFCCConfig
from mmconcepts.vision import ImageSet, as_rgb_image

matplotlib.use("Agg")


@pytest.fixture
def W(rng):
    return rng.gamma(0.5, 1.0, (12, 3))


def grid(fig, n):
    """The panels of a dictionary figure as rows of ``n``."""
    axes = fig.axes
    return [axes[r * n:(r + 1) * n] for r in range(len(axes) // n)]


# --------------------------------------------------------------------------- images
def test_each_panel_shows_the_image_of_the_atoms_top_example(W, rng):
    images = [rng.integers(0, 256, (6, 5, 3), dtype=np.uint8) if i % 2 else rng.random((6, 5)) for i in range(12)]
    fig = plot_dictionary_images(W, images, n=3)
    assert isinstance(fig, Figure)
    rows = grid(fig, 3)
    assert len(fig.axes) == 9 and len(rows) == 3
    top = top_examples(W, 3)
    for j, row in enumerate(rows):
        assert row[0].get_ylabel() == f"atom {j}"
        for k, ax in enumerate(row):
            assert len(ax.images) == 1
            np.testing.assert_array_equal(ax.images[0].get_array(), as_rgb_image(images[top[j, k]]))
            assert ax.get_title().startswith(f"#{top[j, k]} ")


def test_titles_say_the_share_and_the_label_the_atom_aligns_with():
    W = np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 1.0]])
    images = [np.full((4, 4), v) for v in (0.0, 0.5, 1.0)]
    fig = plot_dictionary_images(W, ImageSet(images, ["a", "b", "a"]), n=2, y=["a", "b", "a"], atoms=[1, 0])
    rows = grid(fig, 2)
    # atom 1: example 1 holds only it (100 %), then example 2 (1 of 4); 3/4 of atom 1's activation is on "b"
    assert [ax.get_title() for ax in rows[0]] == ["#1 b (100%)", "#2 a (25%)"]
    assert rows[0][0].get_ylabel() == "atom 1\nb (67%)"
    assert rows[1][0].get_ylabel() == "atom 0\na (100%)"
    np.testing.assert_array_equal(rows[1][0].images[0].get_array(), as_rgb_image(images[0]))


# --------------------------------------------------------------------------- sounds
def test_a_waveform_is_shown_as_its_log_mel_spectrogram(W, rng):
    librosa = pytest.importorskip("librosa")
    t = np.arange(4000) / 8000
    sounds = [(0.3 * np.sin(2 * np.pi * (200 + 150 * i) * t) + 0.01 * rng.normal(size=t.size)).astype(np.float32)
              for i in range(12)]
    fig = plot_dictionary_sounds(W, sounds, sr=8000, n=2)
    top = top_examples(W, 2)
    cfg = MFCCConfig(sr=8000)
    for j, row in enumerate(grid(fig, 2)):
        for k, ax in enumerate(row):
            y = sounds[top[j, k]]
            mel = librosa.feature.melspectrogram(y=y, sr=8000, n_fft=cfg.n_fft, hop_length=cfg.hop_length,
                                                 win_length=cfg.win_length, window="hamming", center=False,
                                                 n_mels=cfg.n_mels, htk=True)
            expected = librosa.power_to_db(mel, ref=1.0, amin=1e-10, top_db=cfg.top_db)
            image = ax.images[0]
            np.testing.assert_allclose(image.get_array(), expected, rtol=1e-5, atol=1e-3)
            assert image.get_extent()[1] == pytest.approx(expected.shape[1] * cfg.hop_length / 8000)


def test_frame_features_are_shown_as_they_are(W, rng):
    feats = [rng.normal(size=(20 + i, 13)) for i in range(12)]
    fig = plot_dictionary_sounds(W, feats, n=1, atoms=[2])
    i = top_examples(W, 1)[2, 0]
    np.testing.assert_array_equal(fig.axes[0].images[0].get_array(), feats[i].T)
    assert fig.axes[0].images[0].get_extent()[1] == pytest.approx((20 + i) * 0.01)  # 10 ms hop at 16 kHz


@pytest.mark.fuzz
def test_sound_options_are_checked(W, rng, monkeypatch):
    sounds = [rng.normal(size=4000).astype(np.float32) for _ in range(12)]
    with pytest.raises(ParameterError, match="disagree"):
        plot_dictionary_sounds(W, sounds, sr=8000, config=MFCCConfig(sr=16000))
    with pytest.raises(DataError, match="1-D"):
        plot_dictionary_sounds(W, [np.zeros((2, 2, 2))] * 12)
    with pytest.raises(DataError, match="finite frame features"):
        plot_dictionary_sounds(W, [np.full((5, 3), np.nan)] * 12)
    monkeypatch.setitem(sys.modules, "librosa", None)  # librosa absent
    with pytest.raises(MissingExtraError, match=r"mmconcepts\[audio\]"):
        plot_dictionary_sounds(W, sounds, sr=8000)


# --------------------------------------------------------------------------- motion
def test_each_panel_draws_the_chosen_angle_curves(W, rng):
    trajectories = [rng.normal(size=(30 + i, 5)) for i in range(12)]
    names = [f"angle {d}" for d in range(5)]
    fig = plot_dictionary_motion(W, trajectories, dofs=[4, 1], names=names, frame_rate=10.0, n=2)
    top = top_examples(W, 2)
    for j, row in enumerate(grid(fig, 2)):
        for k, ax in enumerate(row):
            x = trajectories[top[j, k]]
            assert len(ax.lines) == 2
            for line, d in zip(ax.lines, (4, 1)):
                np.testing.assert_array_equal(line.get_ydata(), x[:, d])
                np.testing.assert_allclose(line.get_xdata(), np.arange(len(x)) / 10.0)
    first, last = fig.axes[0], fig.axes[-1]
    assert [line.get_color() for line in first.lines] == [line.get_color() for line in last.lines]
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["angle 4", "angle 1"]


@pytest.mark.fuzz
def test_motion_options_are_checked(W, rng):
    trajectories = [rng.normal(size=(10, 4)) for _ in range(12)]
    with pytest.raises(ParameterError, match=r"dofs must be in \[0, 4\)"):
        plot_dictionary_motion(W, trajectories, dofs=[4])
    with pytest.raises(ParameterError, match="name the 4 columns"):
        plot_dictionary_motion(W, trajectories, names=["a"])
    with pytest.raises(DataError, match="2-D array"):
        plot_dictionary_motion(W, [np.zeros(5)] * 12)
    with pytest.raises(ParameterError, match="frame_rate"):
        plot_dictionary_motion(W, trajectories, frame_rate=0)


# --------------------------------------------------------------------------- skeletons
@pytest.mark.parametrize("markers", [MSR_JOINTS, CHOREO1_MARKERS, CHOREO2_MARKERS], ids=["msr", "choreo1", "choreo2"])
def test_the_bones_of_the_known_skeletons_join_every_marker_once(markers):
    bones = skeleton_bones(markers)
    n = len(markers)
    assert len(bones) == n - 1  # a tree: as many bones as markers but one ...
    a, b = np.array(bones).T
    n_parts, _ = csgraph.connected_components(coo_matrix((np.ones(n - 1), (a, b)), shape=(n, n)), directed=False)
    assert n_parts == 1  # ... and connected
    names = [markers[i] for i in np.array(bones).ravel()]
    assert ("left_elbow" in names) and ("right_knee" in names)


def test_skeleton_bones_skip_missing_markers_and_take_the_first_alternative():
    assert skeleton_bones(["Head", "left shoulder", "neck", "left-hand"]) == [(0, 2), (2, 1), (1, 3)]
    assert skeleton_bones(["waist", "torso", "left_hip"]) == [(1, 0), (0, 2)]


def _recording(rng, frames=9):
    return MotionRecording(rng.normal(size=(frames, len(MSR_JOINTS), 3)), MSR_JOINTS, (1,))


def test_each_panel_draws_the_poses_of_the_atoms_top_motion(W, rng):
    recordings = [_recording(rng, 9 + i) for i in range(12)]
    bones = skeleton_bones(MSR_JOINTS)
    fig = plot_dictionary_skeletons(W, MotionDataset(recordings, {1: "a"}), plane=(0, 2), n_poses=3, n=2)
    top = top_examples(W, 2)
    for j, row in enumerate(grid(fig, 2)):
        for k, ax in enumerate(row):
            P = recordings[top[j, k]].positions
            assert len(ax.collections) == 3
            frames = [0, (len(P) - 1) / 2, len(P) - 1]
            for pose, f in zip(ax.collections, np.round(frames).astype(int)):
                segments = pose.get_segments()
                assert len(segments) == len(bones)
                for segment, (p, q) in zip(segments, bones):
                    np.testing.assert_array_equal(segment, P[f][[p, q]][:, [0, 2]])


@pytest.mark.fuzz
def test_skeleton_options_are_checked(W, rng):
    recordings = [_recording(rng) for _ in range(12)]
    with pytest.raises(DataError, match="'tail' is needed but missing"):
        plot_dictionary_skeletons(W, recordings, bones=[("head", "tail")])
    fig = plot_dictionary_skeletons(W, recordings, bones=[("head", "neck")], n=1, n_poses=2)
    assert all([len(c.get_segments()) for c in ax.collections] == [1, 1] for ax in fig.axes)
    with pytest.raises(ParameterError, match="plane"):
        plot_dictionary_skeletons(W, recordings, plane=(1, 1))
    with pytest.raises(DataError, match="must be a MotionRecording"):
        plot_dictionary_skeletons(W, [np.zeros((3, 20, 3))] * 12)
    with pytest.raises(DataError, match="none of the markers"):
        plot_dictionary_skeletons(W, [MotionRecording(np.zeros((2, 1, 3)), ("tail",))] * 12)


# --------------------------------------------------------------------------- what the grids share
@pytest.mark.fuzz
@pytest.mark.parametrize("plot, items", [
    (plot_dictionary_images, [np.zeros((4, 4))] * 12),
    (plot_dictionary_sounds, [np.zeros((4, 3))] * 12),
    (plot_dictionary_motion, [np.zeros((4, 3))] * 12),
], ids=["images", "sounds", "motion"])
def test_the_dictionary_grids_check_their_input(plot, items, W):
    with pytest.raises(DataError, match="one item of the examples per row of W"):
        plot(W, items[:-1])
    with pytest.raises(DataError, match="Negative"):
        plot(-W, items)
    with pytest.raises(DataError, match="n <= n_samples"):
        plot(W, items, n=13)
    with pytest.raises(ParameterError, match="n must be an int >= 1"):
        plot(W, items, n=0)
    with pytest.raises(ParameterError, match=r"atoms must be in \[0, 3\)"):
        plot(W, items, atoms=[3])
    with pytest.raises(ParameterError, match="atoms must be a non-empty sequence"):
        plot(W, items, atoms=[0.5])
    with pytest.raises(DataError, match="one item of y per row"):
        plot(W, items, y=[0, 1])
    with pytest.raises(ParameterError, match="figsize"):
        plot(W, items, figsize=(0, 3))
    with pytest.raises(ParameterError, match="a matplotlib Figure or SubFigure"):
        plot(W, items, fig="figure")
    outer = Figure()
    left, right = outer.subfigures(1, 2)
    assert plot(W, items, n=2, fig=right) is outer
    assert len(right.axes) == 6 and not left.axes
    assert len(plot(W, items, n=1, atoms=[2, 0]).axes) == 2


# --------------------------------------------------------------------------- atom labels
def test_atom_labels_shows_the_association_in_label_order():
    W = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, 3.0]])
    fig = plot_atom_labels(W, ["a", "b", "a"], annotate=True)
    ax = fig.axes[0]
    np.testing.assert_array_equal(ax.images[0].get_array(), [[1.0, 0.0], [0.0, 1.0]])  # atom 1 (a), atom 0 (b)
    assert [t.get_text() for t in ax.get_yticklabels()] == ["atom 1", "atom 0"]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b"]
    assert sorted(t.get_text() for t in ax.texts) == ["0.00", "0.00", "1.00", "1.00"]


def test_atom_labels_rows_are_the_library_association(W, rng):
    y = rng.integers(0, 4, 12)
    A, _ = atom_label_association(W, y)
    fig = plot_atom_labels(W, y, order="atom")
    np.testing.assert_array_equal(fig.axes[0].images[0].get_array(), A)
    shown = plot_atom_labels(W, y).axes[0].images[0].get_array()
    best = A.argmax(axis=1)
    order = sorted(range(3), key=lambda j: (best[j], -A[j].max(), j))
    np.testing.assert_array_equal(shown, A[order])
    with pytest.raises(ParameterError, match="order"):
        plot_atom_labels(W, y, order="share")
    with pytest.raises(DataError, match="one label per row of W"):
        plot_atom_labels(W, y[:-1])


# --------------------------------------------------------------------------- confusion
@pytest.mark.parametrize("normalize", [None, "true", "all"])
def test_confusion_is_sklearns(normalize, rng):
    from sklearn.metrics import confusion_matrix

    y_true = rng.choice(["ball", "cup", "dog"], 40)
    y_pred = np.where(rng.random(40) < 0.7, y_true, rng.choice(["ball", "cup", "dog"], 40))
    fig = plot_confusion(y_true, y_pred, normalize=normalize)
    ax = fig.axes[0]
    np.testing.assert_allclose(ax.images[0].get_array(), confusion_matrix(y_true, y_pred, normalize=normalize))
    assert len(ax.texts) == 9
    assert ax.get_title() == f"accuracy {np.mean(y_true == y_pred):.2f} (n = 40)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["ball", "cup", "dog"]


@pytest.mark.fuzz
def test_confusion_keeps_the_given_label_order_and_checks_its_input():
    fig = plot_confusion([0, 1, 1, 2], [0, 2, 1, 2], labels=[2, 1, 0], colorbar=False, title="S -> I")
    np.testing.assert_array_equal(fig.axes[0].images[0].get_array(), [[1, 0, 0], [1, 1, 0], [0, 0, 1]])
    assert len(fig.axes) == 1 and fig.axes[0].get_title() == "S -> I"
    with pytest.raises(DataError, match="one shape"):
        plot_confusion([0, 1], [0])
    with pytest.raises(DataError, match="labels that occur in y_true"):
        plot_confusion([0, 1], [0, 1], labels=[5])
    with pytest.raises(ParameterError, match="normalize"):
        plot_confusion([0, 1], [0, 1], normalize="rows")


# --------------------------------------------------------------------------- timeline
def test_timeline_lines_are_the_activations_and_bands_the_segments(rng):
    A = rng.random((25, 3))
    t = np.arange(25) * 0.05
    fig = plot_activation_timeline(A, times=t, labels=["ball", "cup", "dog"],
                                   segments=[(0.2, 0.5, "cup"), (0.7, 0.9, "cat")], ylabel="similarity")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "similarity" and ax.get_xlabel() == "time (s)"
    assert len(ax.lines) == 3
    for j, line in enumerate(ax.lines):
        np.testing.assert_array_equal(line.get_xdata(), t)
        np.testing.assert_array_equal(line.get_ydata(), A[:, j])
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["ball", "cup", "dog"]
    assert len(ax.patches) == 2
    cup, cat = ax.patches
    assert to_rgb(cup.get_facecolor()) == to_rgb(ax.lines[1].get_color())  # the band of "cup" has its colour
    assert to_rgb(cat.get_facecolor()) == to_rgb("0.6")  # no column is "cat"
    x = cup.get_patch_transform().transform(cup.get_path().vertices)[:, 0]  # a Rectangle or a Polygon
    np.testing.assert_allclose([x.min(), x.max()], [0.2, 0.5])


@pytest.mark.fuzz
def test_timeline_checks_its_input(rng):
    A = rng.random((5, 2))
    fig = plot_activation_timeline(A)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_xdata(), np.arange(5))
    with pytest.raises(DataError, match="NaN"):
        plot_activation_timeline(np.full((3, 2), np.nan))
    with pytest.raises(DataError, match=r"\(n_windows, n_concepts\)"):
        plot_activation_timeline(np.ones(4))
    with pytest.raises(DataError, match="one item of times per row"):
        plot_activation_timeline(A, times=np.arange(4))
    with pytest.raises(ParameterError, match="name the 2 columns"):
        plot_activation_timeline(A, labels=["a"])
    with pytest.raises(DataError, match=r"\(start, end, label\)"):
        plot_activation_timeline(A, segments=[(1, 2)])
    with pytest.raises(DataError, match="start <= end"):
        plot_activation_timeline(A, segments=[(2, 1, "a")])
    with pytest.raises(ParameterError, match="ylabel"):
        plot_activation_timeline(A, ylabel=None)


# --------------------------------------------------------------------------- drawing where asked, no pyplot state
def test_single_panel_figures_draw_on_the_given_axes_and_leave_pyplot_alone(W, rng):
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    outer = Figure()
    a, b, c = outer.subplots(1, 3)
    assert plot_atom_labels(W, rng.integers(0, 2, 12), ax=a) is outer
    assert plot_confusion([0, 1], [1, 1], ax=b) is outer
    assert plot_activation_timeline(W, ax=c) is outer
    assert len(c.lines) == 3 and len(a.images) == 1 and len(b.images) == 1
    plot_dictionary_images(W, [np.zeros((3, 3))] * 12)
    assert plt.get_fignums() == before
    with pytest.raises(ParameterError, match="a matplotlib Axes"):
        plot_confusion([0], [0], ax=outer)
