"""Known poses give known angles; delayed velocities; relative rotations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.motion import (
    JOINT_ANGLE_NAMES,
    MotionRecording,
    delayed_velocity,
    joint_angles,
    orientation_angles,
)

J = {n: i for i, n in enumerate(JOINT_ANGLE_NAMES)}


def _pose(**over):
    """A T-pose-ish skeleton facing -z (camera), right side at +x, y up."""
    p = {
        "neck": (0, 0.5, 0), "left_hip": (-0.15, 0, 0), "right_hip": (0.15, 0, 0),
        "left_shoulder": (-0.2, 0.45, 0), "right_shoulder": (0.2, 0.45, 0),
        "left_elbow": (-0.2, 0.15, 0), "right_elbow": (0.2, 0.15, 0),  # arms hanging
        "left_hand": (-0.2, -0.15, 0), "right_hand": (0.2, -0.15, 0),
        "left_knee": (-0.15, -0.5, 0), "right_knee": (0.15, -0.5, 0),
        "left_ankle": (-0.15, -1.0, 0), "right_ankle": (0.15, -1.0, 0),
    }
    p.update(over)
    names = tuple(p)
    return MotionRecording(np.array([[p[n] for n in names]], dtype=float), names)


def test_standing_pose_angles():
    a = joint_angles(_pose())[0]
    assert a.shape == (16,)
    np.testing.assert_allclose(a, [0, 0] + [0, np.pi / 2, 0, 0, 0, 0, 0] * 2, atol=1e-12)


def test_arm_angles_known_poses():
    # right arm horizontal to the side, forearm bent upwards (gesture 8's end pose)
    a = joint_angles(_pose(right_elbow=(0.5, 0.45, 0), right_hand=(0.5, 0.75, 0)))[0]
    np.testing.assert_allclose(a[J["right_shoulder_elev"]], np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(a[J["right_shoulder_out"]], 0.0, atol=1e-12)
    np.testing.assert_allclose(a[J["right_elbow_flex"]], np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(a[J["right_forearm_elev"]], np.pi, atol=1e-12)
    # left arm pointing forward (toward the camera, -z), straight
    a = joint_angles(_pose(left_elbow=(-0.2, 0.45, -0.3), left_hand=(-0.2, 0.45, -0.6)))[0]
    np.testing.assert_allclose(a[J["left_shoulder_out"]], np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(a[J["left_shoulder_elev"]], np.pi / 2, atol=1e-12)
    # across the body: 180 deg from "out"
    a = joint_angles(_pose(right_elbow=(-0.1, 0.45, 0), right_hand=(-0.4, 0.45, 0)))[0]
    np.testing.assert_allclose(a[J["right_shoulder_out"]], np.pi, atol=1e-12)


def test_leg_and_torso_angles():
    # left thigh 45 deg forward, knee bent 45 deg back to vertical shin
    s = np.sqrt(0.5) * 0.5
    a = joint_angles(_pose(left_knee=(-0.15, -s, -s), left_ankle=(-0.15, -s - 0.5, -s)))[0]
    np.testing.assert_allclose(a[J["left_hip_front"]], np.pi / 4, atol=1e-12)
    np.testing.assert_allclose(a[J["left_knee_flex"]], np.pi / 4, atol=1e-12)
    np.testing.assert_allclose(a[J["left_hip_out"]], 0.0, atol=1e-12)
    # torso leaning 30 deg to the front (neck moves toward the camera)
    lean = np.radians(30)
    a = joint_angles(_pose(neck=(0, 0.5 * np.cos(lean), -0.5 * np.sin(lean))))[0]
    np.testing.assert_allclose(a[J["torso_lean_forward"]], lean, atol=1e-12)
    np.testing.assert_allclose(a[J["torso_lean_side"]], 0.0, atol=1e-12)


def test_angles_invariant_to_rigid_motion(rng):
    rec = _pose(right_elbow=(0.4, 0.3, -0.1), right_hand=(0.5, 0.6, -0.3), left_knee=(-0.2, -0.4, -0.2))
    R = Rotation.from_euler("y", 0.7).as_matrix()  # turn about the vertical + shift
    moved = MotionRecording(rec.positions @ R.T + rng.normal(size=3), rec.marker_names)
    np.testing.assert_allclose(joint_angles(moved), joint_angles(rec), atol=1e-10)


def test_missing_marker_named():
    rec = _pose()
    names = [n for n in rec.marker_names if n != "left_knee"]
    sub = MotionRecording(rec.positions[:, [rec.marker_index(n) for n in names]], names, source="x.npz")
    with pytest.raises(DataError, match="left_knee.*x.npz"):
        joint_angles(sub)


def test_delayed_velocity():
    x = np.arange(10.0)[:, None] ** 2
    v = delayed_velocity(x, 3)
    assert v.shape == (7, 1)
    np.testing.assert_array_equal(v[:, 0], x[3:, 0] - x[:-3, 0])
    np.testing.assert_array_equal(delayed_velocity(x, 1)[:, 0], np.diff(x[:, 0]))
    wrapped = delayed_velocity(np.array([3.1, -3.1]), 1, period=2 * np.pi)
    np.testing.assert_allclose(wrapped, [2 * np.pi - 6.2])
    with pytest.raises(ParameterError):
        delayed_velocity(x, 0)
    with pytest.raises(DataError):
        delayed_velocity(x[:3], 3)


def test_orientation_angles_relative_rotation(rng):
    T = 4
    parent = Rotation.random(T, random_state=1)
    rel = Rotation.from_euler("xyz", np.tile([0.3, -0.2, 1.1], (T, 1)))
    child = parent * rel
    q = np.stack([parent.as_quat(), child.as_quat()], axis=1)
    rec = MotionRecording(rng.normal(size=(T, 2, 3)), ("torso", "neck"), orientations=q)
    ang = orientation_angles(rec, pairs=[("torso", "neck")])
    np.testing.assert_allclose(ang, np.tile([0.3, -0.2, 1.1], (T, 1)), atol=1e-10)
    with pytest.raises(DataError):
        orientation_angles(MotionRecording(rng.normal(size=(T, 2, 3)), ("torso", "neck")))


def test_the_arm_columns_name_the_arms_and_pair_right_with_left():
    from mmconcepts.motion import ARM_COLUMNS, JOINT_ANGLE_NAMES, LEFT_ARM_COLUMNS, RIGHT_ARM_COLUMNS

    arms = [n for n in JOINT_ANGLE_NAMES if n.split("_", 1)[1].startswith(("shoulder", "elbow", "forearm"))]
    assert [JOINT_ANGLE_NAMES[i] for i in ARM_COLUMNS] == arms and len(arms) == 8
    for r, l in zip(RIGHT_ARM_COLUMNS, LEFT_ARM_COLUMNS):
        assert JOINT_ANGLE_NAMES[r].replace("right_", "left_") == JOINT_ANGLE_NAMES[l]
    assert sorted([*RIGHT_ARM_COLUMNS, *LEFT_ARM_COLUMNS]) == sorted(ARM_COLUMNS)


def test_msr_joint_angles_reads_a_folder_once_per_state(tmp_path):
    from mmconcepts.motion import msr_joint_angles
    from mmconcepts.motion.kinematics import _msr_joint_angles

    rng = np.random.default_rng(0)
    for name in ("a01_s02_e01_skeleton3D.txt", "a14_s03_e02_skeleton3D.txt"):
        frames = rng.normal(size=(20 * 20, 4)) + [0, 0, 2, 1]  # 20 frames x 20 joints: x y z confidence
        np.savetxt(tmp_path / name, frames, fmt="%.6f")
    _msr_joint_angles.cache_clear()
    angles, actions, subjects, skipped = msr_joint_angles(tmp_path)
    assert [a.shape for a in angles] == [(20, 16), (20, 16)] and skipped == ()
    assert list(actions) == [1, 14] and list(subjects) == [2, 3]
    assert msr_joint_angles(tmp_path)[0] is angles  # cached
    (tmp_path / "a01_s02_e01_skeleton3D.txt").unlink()
    assert len(msr_joint_angles(tmp_path)[0]) == 1  # a new folder state is read again
