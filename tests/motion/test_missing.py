"""MotionRecording refuses non-finite motion, or repairs it by an explicit ``on_missing`` policy.

NaN or infinite positions (a joint whose tracking was lost) raise a DataError naming the
first bad frame and joint; ``on_missing="interpolate"`` fills them linearly in time per
coordinate (ends held), ``"drop"`` leaves their frames out. The frame rate must be a finite
number > 0. Joint angles of an accepted recording are finite.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.motion import MSR_JOINTS, MotionRecording, joint_angles, orientation_angles
from mmconcepts.motion.histograms import MotionHistograms

NAN, INF = np.nan, np.inf


def _two_joints():
    """6 frames, joints 'neck' and 'head'; neck x goes 0, 1, nan, nan, 4, 5; head z is lost at both ends."""
    P = np.zeros((6, 2, 3))
    P[:, 0, 0] = [0, 1, NAN, NAN, 4, 5]
    P[:, 0, 1] = 10.0
    P[:, 1, 2] = [NAN, 2, 3, 3, 7, INF]
    P[:, 1, 0] = np.arange(6) * 0.5
    return P


def test_nan_position_raises_naming_the_frame_and_the_joint():
    P = _two_joints()
    with pytest.raises(DataError, match=r"frame 0, joint 'head'.*file rec\.npz, record 7.*on_missing"):
        MotionRecording(P, ("neck", "head"), source="rec.npz", record_id="7")
    P[0, 1, 2] = 0.0
    with pytest.raises(DataError, match=r"3 non-finite.* in 3 frame\(s\).*frame 2, joint 'neck'"):
        MotionRecording(P, ("neck", "head"))


@pytest.mark.parametrize("bad", [INF, -INF, NAN])
def test_any_non_finite_position_is_refused_by_default(bad):
    P = np.ones((3, 2, 3))
    P[1, 1, 0] = bad
    with pytest.raises(DataError, match=r"frame 1, joint 'b'"):
        MotionRecording(P, ("a", "b"))


def test_interpolate_fills_each_coordinate_linearly_in_time_and_holds_the_ends():
    P = _two_joints()
    rec = MotionRecording(P, ("neck", "head"), (3,), frame_rate=15.0, on_missing="interpolate")
    assert rec.n_frames == 6 and rec.labels == (3,) and rec.frame_rate == 15.0
    np.testing.assert_array_equal(rec.positions[:, 0, 0], [0, 1, 2, 3, 4, 5])  # between 1 (t=1) and 4 (t=4)
    np.testing.assert_array_equal(rec.positions[:, 1, 2], [2, 2, 3, 3, 7, 7])  # ends held
    finite = np.isfinite(P)
    np.testing.assert_array_equal(rec.positions[finite], P[finite])  # tracked values untouched


def test_interpolate_of_uneven_gaps_matches_np_interp():
    rng = np.random.default_rng(3)
    P = rng.normal(size=(9, 3, 3))
    lost = rng.random(P.shape) < 0.3
    lost[4] = False  # every coordinate has a tracked frame
    P[lost] = NAN
    rec = MotionRecording(P, ("a", "b", "c"), on_missing="interpolate")
    t = np.arange(9)
    for j in range(3):
        for c in range(3):
            ok = ~lost[:, j, c]
            np.testing.assert_allclose(rec.positions[:, j, c], np.interp(t, t[ok], P[ok, j, c]), rtol=0, atol=1e-15)


def test_drop_leaves_out_every_frame_with_a_non_finite_value():
    P = _two_joints()
    q = np.tile([0.0, 0.0, 0.0, 1.0], (6, 2, 1))
    q[:, 0, 2] = np.arange(6) * 0.01
    rec = MotionRecording(P, ("neck", "head"), orientations=q, on_missing="drop")
    np.testing.assert_array_equal(rec.positions, P[[1, 4]])
    np.testing.assert_array_equal(rec.orientations, q[[1, 4]])


def test_a_joint_never_tracked_cannot_be_interpolated_and_nothing_left_cannot_be_dropped():
    P = np.ones((4, 2, 3))
    P[:, 1, 1] = NAN
    with pytest.raises(DataError, match=r"Joint 'b' has no finite value"):
        MotionRecording(P, ("a", "b"), on_missing="interpolate")
    with pytest.raises(DataError, match=r"Every one of the 4 frame"):
        MotionRecording(P, ("a", "b"), on_missing="drop")


@pytest.mark.parametrize("policy", ["skip", "", None, 1, "Raise"])
def test_unknown_policy_is_a_parameter_error(policy):
    with pytest.raises(ParameterError, match="on_missing"):
        MotionRecording(np.ones((2, 1, 3)), ("a",), on_missing=policy)


@pytest.mark.parametrize("rate", [0, 0.0, -1, -30.0, NAN, INF, True, "30", None])
def test_frame_rate_must_be_a_finite_positive_number(rate):
    with pytest.raises(ParameterError, match="frame_rate"):
        MotionRecording(np.ones((2, 1, 3)), ("a",), frame_rate=rate)


def test_duration_and_an_integer_frame_rate():
    rec = MotionRecording(np.ones((45, 1, 3)), ("a",), frame_rate=15)
    assert rec.duration == 3.0 and isinstance(rec.frame_rate, float)


def test_non_finite_orientation_is_refused_and_slerped_by_interpolate():
    q = np.tile([0.0, 0.0, 0.0, 1.0], (3, 1, 1))
    q[2, 0] = Rotation.from_euler("z", 90, degrees=True).as_quat()
    q[1, 0] = NAN
    with pytest.raises(DataError, match=r"orientations.*frame 1, joint 'torso'"):
        MotionRecording(np.zeros((3, 1, 3)), ("torso",), orientations=q)
    rec = MotionRecording(np.zeros((3, 1, 3)), ("torso",), orientations=q, on_missing="interpolate")
    half = Rotation.from_quat(rec.orientations[1, 0]).as_euler("xyz", degrees=True)
    np.testing.assert_allclose(half, [0, 0, 45], atol=1e-10)  # half way between 0 and 90 degrees about z


def test_positions_that_are_not_numbers_are_a_data_error():
    with pytest.raises(DataError, match="positions"):
        MotionRecording([[["a", "b", "c"]]], ("a",))
    with pytest.raises(DataError, match="labels"):
        MotionRecording(np.ones((1, 1, 3)), ("a",), labels=("walk",))


def _skeleton(rng, n_frames, scale=1.0):
    base = rng.normal(scale=0.3, size=(20, 3)) + np.array([0.0, 0.0, 2.5])
    return scale * (base[None] + 0.05 * rng.normal(size=(n_frames, 20, 3)))


def test_joint_angles_do_not_depend_on_the_unit_even_where_squares_overflow():
    rng = np.random.default_rng(0)
    P = _skeleton(rng, 5)
    ref = joint_angles(MotionRecording(P, MSR_JOINTS))
    np.testing.assert_allclose(joint_angles(MotionRecording(P * 1e200, MSR_JOINTS)), ref, atol=1e-12)


def test_joint_angles_of_positions_whose_differences_overflow_are_a_data_error():
    rng = np.random.default_rng(0)
    P = _skeleton(rng, 2)
    P[:, MSR_JOINTS.index("neck")] = 1.7e308
    P[:, MSR_JOINTS.index("hip_center")] = -1.7e308
    with pytest.raises(DataError, match="spine"):
        joint_angles(MotionRecording(P, MSR_JOINTS))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), scale=st.sampled_from([1.0, 1e-3, 1e3, 1e150, 1e200, 1e300, 1e-300]),
       n_lost=st.integers(0, 5), policy=st.sampled_from(["interpolate", "drop"]))
def test_an_accepted_recording_gives_finite_angles_and_histograms(seed, scale, n_lost, policy):
    rng = np.random.default_rng(seed)
    P = _skeleton(rng, 8, scale)
    P.reshape(-1)[rng.choice(P.size, n_lost, replace=False)] = NAN
    try:
        rec = MotionRecording(P, MSR_JOINTS, on_missing=policy)
        A = joint_angles(rec)
    except DataError:
        return  # a typed refusal (every frame dropped, degenerate or overflowing geometry)
    assert A.shape == (rec.n_frames, 16) and np.isfinite(A).all()
    assert np.isfinite(rec.positions).all() and rec.duration == rec.n_frames / rec.frame_rate
    if rec.n_frames > 3:
        H = MotionHistograms().fit_transform([A])
        assert np.isfinite(H).all()


def test_nan_trajectories_given_to_the_histograms_directly_are_refused():
    A = np.zeros((10, 2))
    A[6, 1] = NAN
    with pytest.raises(DataError, match=r"Recording 1 .*frame 6, degree of freedom 1"):
        MotionHistograms().fit([np.zeros((10, 2)), A])
    mh = MotionHistograms().fit([np.random.default_rng(0).normal(size=(10, 2))])
    with pytest.raises(DataError, match=r"Recording 0 .*frame 6, degree of freedom 1"):
        mh.transform([A])


def test_orientation_angles_of_an_accepted_recording_are_finite():
    q = Rotation.random(4, random_state=0).as_quat().reshape(2, 2, 4)
    q[1, 1] = NAN
    rec = MotionRecording(np.zeros((2, 2, 3)), ("torso", "neck"), orientations=q, on_missing="interpolate")
    assert np.isfinite(orientation_angles(rec, pairs=[("torso", "neck")])).all()


def test_loaders_skip_a_record_with_nan_naming_the_frame_and_the_marker(tmp_path):
    from mmconcepts.motion import load_choreo1, load_msr_action3d, save_choreo1

    rng = np.random.default_rng(0)
    recs = [MotionRecording(rng.normal(size=(4, 2, 3)), ("neck", "head"), (1,)) for _ in range(2)]
    path = save_choreo1(recs, tmp_path, "primitive")
    with np.load(tmp_path / "primitive.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["1"][2, 1, 0] = NAN
    np.savez(tmp_path / "primitive.npz", **arrays)
    with pytest.raises(Exception, match=r"record 1.*frame 2, joint 'head'"):
        load_choreo1(path)
    with pytest.warns(RuntimeWarning, match="1 record"):
        ds = load_choreo1(path, on_error="skip")
    assert [r.record_id for r in ds] == ["0"]
    assert "frame 2, joint 'head'" in ds.skipped[0].reason
    with pytest.raises(ParameterError, match="frame_rate"):
        load_choreo1(path, frame_rate=0)

    msr = tmp_path / "msr"
    msr.mkdir()
    rows = np.concatenate([rng.normal(size=(3 * 20, 3)), np.ones((60, 1))], axis=1)
    rows[20 + 5, 1] = NAN  # frame 1, joint 5
    np.savetxt(msr / "a01_s01_e01_skeleton3D.txt", rows, fmt="%.6f")
    with pytest.warns(RuntimeWarning, match="1 record"):
        ds = load_msr_action3d(msr, on_error="skip")
    assert len(ds) == 0 and f"frame 1, joint '{MSR_JOINTS[5]}'" in ds.skipped[0].reason
    with pytest.raises(ParameterError, match="frame_rate"):
        load_msr_action3d(msr, frame_rate=-1)


def test_a_recording_without_frames_is_refused():
    with pytest.raises(DataError, match="at least one frame"):
        MotionRecording(np.zeros((0, 2, 3)), ("a", "b"))
