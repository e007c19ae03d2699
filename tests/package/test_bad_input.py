"""Inputs that gave silently wrong output or an untyped error, one test each.

Each asserts what a user should get instead: a ParameterError/DataError naming the problem,
or a correct finite result checked against an answer computed here.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.motion import delayed_velocity
from mmconcepts.nmf import NMF
from mmconcepts.sound import cooccurrence_counts
from mmconcepts.tasks.mdp import grid_world, greedy_policy, sample_trajectories


# --------------------------------------------------------------------------- cooccurrence_counts
@given(st.lists(st.lists(st.integers(0, 4), max_size=12), min_size=1, max_size=4), st.integers(1, 3))
def test_cooccurrence_counts_equal_a_direct_count(streams, lag):
    X = cooccurrence_counts([np.array(s, dtype=np.int64) for s in streams], 5, lag).toarray()
    for i, s in enumerate(streams):
        expected = Counter((a, b) for a, b in zip(s, s[lag:]))
        assert {(c // 5, c % 5): int(v) for c, v in enumerate(X[i]) if v} == dict(expected)


def test_cooccurrence_counts_refuse_ids_outside_the_alphabet():
    # an id >= n_events used to land in another pair's column (a * n + b wraps): silent corruption
    with pytest.raises(DataError, match=r"events\[1\] holds event ids in \[0, 5\], outside \[0, n_events=5\)"):
        cooccurrence_counts([np.array([0, 1, 2]), np.array([0, 5, 1])], 5, 1)
    with pytest.raises(DataError, match="outside"):
        cooccurrence_counts([np.array([-1, 1, 2])], 5, 1)
    with pytest.raises(DataError, match="integer event ids"):
        cooccurrence_counts([np.array([0.5, 1.0])], 5, 1)
    assert cooccurrence_counts([np.array([], dtype=float)], 5, 1).nnz == 0  # an empty stream is fine


# --------------------------------------------------------------------------- NMF
def test_an_absurd_n_components_is_a_parameter_error_not_an_allocation():
    X = np.random.default_rng(0).random((100, 50))
    with pytest.raises(ParameterError, match=r"n_components=1000000 on a 100 x 50 matrix needs about .* GiB"):
        NMF(10**6).fit(X)
    assert NMF(120, max_iter=3, tol=0.5).fit(X).components_.shape == (120, 50)  # overcomplete is fine


# --------------------------------------------------------------------------- motion
@pytest.mark.parametrize("period", [0, -1.0, np.inf, np.nan, "2pi"])
def test_delayed_velocity_period_must_be_finite_and_positive(period):
    with pytest.raises(ParameterError, match="period must be a finite number > 0"):
        delayed_velocity(np.zeros((5, 2)), period=period)


def test_delayed_velocity_wraps_angles():
    x = np.array([[3.1], [-3.1]])
    assert delayed_velocity(x, period=2 * np.pi)[0, 0] == pytest.approx(-6.2 + 2 * np.pi)


# --------------------------------------------------------------------------- tasks
def test_greedy_policy_with_infinite_values():
    Q = np.array([[1.0, np.inf, 0.0, np.inf], [-np.inf, -np.inf, -np.inf, -np.inf], [0.0, 1.0, 1.0, 0.5]])
    pi = greedy_policy(Q)
    assert np.isfinite(pi).all()  # was NaN where a value was infinite (inf - inf)
    np.testing.assert_array_equal(pi, [[0, 0.5, 0, 0.5], [0.25] * 4, [0, 0.5, 0.5, 0]])
    with pytest.raises(DataError, match=r"Q holds NaN at \[0, 2\]"):
        greedy_policy(np.array([[0.0, 1.0, np.nan]]))


@pytest.mark.parametrize("start", [[-1, 0], [16, 0], [0.5, 1.0]])
def test_sample_trajectories_start_must_be_states(start):
    mdp = grid_world(4)
    pi = np.full((mdp.n_states, mdp.n_actions), 1 / mdp.n_actions)
    with pytest.raises(ParameterError, match=r"start must hold state indices \(integers in \[0, 16\)\)"):
        sample_trajectories(mdp, pi, 2, 5, start=start, random_state=0)
    trajs = sample_trajectories(mdp, pi, 2, 5, start=[3, 15], random_state=0)
    assert [int(t[0][0]) for t in trajs] == [3, 15]


# --------------------------------------------------------------------------- loaders
def _msr_folder(tmp_path):
    folder = tmp_path / "msr"
    folder.mkdir()
    frames = np.random.default_rng(0).random((3 * 20, 4)) + 0.1  # 3 frames of 20 joints: x y z confidence
    np.savetxt(folder / "a01_s01_e01_skeleton3D.txt", frames)
    (folder / "a02_s01_e01_skeleton3D.txt").mkdir()  # a stray folder named like a data file
    (folder / "a03_s01_e01_skeleton3D.txt").symlink_to(tmp_path / "gone.txt")  # a dangling link
    return folder


def test_msr_skip_passes_over_folders_and_dangling_links(tmp_path):
    from mmconcepts.errors import DataFormatError
    from mmconcepts.motion import load_msr_action3d

    folder = _msr_folder(tmp_path)
    with pytest.warns(RuntimeWarning, match="2 record"):
        ds = load_msr_action3d(folder, on_error="skip")
    assert [r.record_id for r in ds] == ["a01_s01_e01"]
    assert sorted(s.record_id for s in ds.skipped) == ["a02_s01_e01", "a03_s01_e01"]
    assert all("cannot be read as a skeleton file" in s.reason for s in ds.skipped)
    with pytest.raises(DataFormatError, match="a02_s01_e01_skeleton3D.txt: cannot be read as a skeleton file"):
        load_msr_action3d(folder)


def test_a_deeply_nested_json_index_is_a_format_error(tmp_path):
    from mmconcepts.errors import DataFormatError
    from mmconcepts.motion import load_choreo1

    path = tmp_path / "primitive.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(DataFormatError, match="nested too deeply"):
        load_choreo1(path)


def test_sparseness_one_gives_a_vertex_not_nan():
    from mmconcepts.nmf import beta_nmf
    from mmconcepts.nmf.sparseness import project_hoyer

    x = np.array([0.2, 0.9, 0.4, 0.1])
    # l1 == l2: the only nonnegative vectors are l1 times a basis vector; the closest is at x's largest entry
    np.testing.assert_array_equal(project_hoyer(x, 2.0, 2.0), [0.0, 2.0, 0.0, 0.0])
    X = np.random.default_rng(0).random((30, 20))
    res = beta_nmf(X, 5, max_iter=20, random_state=0, sparseness_H=1.0)
    assert np.isfinite(res.H).all() and np.isfinite(res.W).all()  # was NaN


# --------------------------------------------------------------------------- saved models
def test_loading_a_damaged_model_file_names_it(tmp_path):
    from mmconcepts.errors import DataFormatError
    from mmconcepts.multimodal import MultimodalNMF

    rng = np.random.default_rng(0)
    model = MultimodalNMF(3, max_iter=10).fit({"a": rng.random((20, 5)), "b": rng.random((20, 4))})
    path = tmp_path / "model.npz"
    model.save(path)
    raw = path.read_bytes()
    damaged = {"empty": b"", "truncated": raw[: len(raw) // 2], "cut-at-the-end": raw[:-30], "noise": b"x" * 500}
    for name, data in damaged.items():  # were EOFError, BadZipFile, ... naming no file
        bad = tmp_path / f"{name}.npz"
        bad.write_bytes(data)
        with pytest.raises(DataFormatError, match=str(bad).replace(".", r"\.")):
            MultimodalNMF.load(bad)
    back = MultimodalNMF.load(path)  # the intact file still loads
    np.testing.assert_array_equal(back.components_, model.components_)


# --------------------------------------------------------------------------- images
def test_image_descriptors_take_gray_and_rgba_and_name_other_shapes():
    from mmconcepts.vision import dense_sift, superpixel_colors

    rng = np.random.default_rng(0)
    rgb = rng.random((32, 32, 3))
    rgba = np.concatenate([rgb, rng.random((32, 32, 1))], axis=2)
    gray = rgb.mean(axis=2)
    gray_alpha = np.stack([gray, rng.random((32, 32))], axis=2)  # 2 channels: gray + alpha (PNG "LA")
    for fn in (superpixel_colors, dense_sift):
        a, b = fn(rgba), fn(rgb)  # the alpha channel is dropped: the same features as the RGB image
        np.testing.assert_array_equal(a.vectors, b.vectors)
        np.testing.assert_array_equal(fn(gray_alpha).vectors, fn(gray).vectors)
        with pytest.raises(DataError, match=r"must have shape \(H, W\) \(grayscale\).*got \(32, 32, 5\)"):
            fn(rng.random((32, 32, 5)))
        with pytest.raises(DataError, match="got"):
            fn(rng.random((2, 32, 32, 3)))
    # gray: superpixels of a gray image have no hue or saturation (cone coordinates (0, 0, v))
    g = superpixel_colors(gray, n_segments=9)
    np.testing.assert_allclose(g.vectors[:, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(dense_sift(gray).vectors, dense_sift(np.stack([gray] * 3, axis=2)).vectors, atol=1e-12)


def test_an_object_array_of_text_is_a_data_error():
    from mmconcepts._validation import check_nonnegative_matrix
    from mmconcepts.errors import DataError

    with pytest.raises(DataError, match="must hold numbers"):
        check_nonnegative_matrix(np.array([["a", "b"]], dtype=object), "X")
