"""Motion primitives: skeletons, kinematics, angle/velocity histograms, choreography data.

Thesis chapter 3 (sections 3.2-3.3) and Appendix B.2-B.3.

Contents
--------
data
    :class:`MotionRecording`, :class:`MotionDataset`; loaders and writers for Choreo1
    (JSON + NPZ, text layout), Choreo2 (JSON + NPZ with orientations), MSR Action3D and
    the generic layout (:func:`load_motion_folder`: one CSV per recording + ``labels.csv``).
kinematics
    :func:`joint_angles` (16 angles of a geometric limb model), :func:`orientation_angles`
    (relative rotations along the limbs as Euler angles), :func:`delayed_velocity`.
skeleton
    :data:`SKELETON_CHAINS`, :func:`skeleton_bones`: the bones a stick figure joins.
histograms
    :class:`MotionHistograms`, the scikit-learn transformer turning angle trajectories into
    concatenated per-degree-of-freedom histograms (KDE or vector quantisation).
synthetic
    A kinematic dancer performing the gestures of Table B.2, writing Choreo1 / Choreo2
    files: :func:`make_choreo1`, :func:`make_choreo2`.
"""

from __future__ import annotations

from .data import (
    CHOREO1_GESTURES,
    CHOREO1_LIMBS,
    CHOREO1_MARKERS,
    CHOREO1_SMALL_GESTURES,
    CHOREO2_GESTURES,
    CHOREO2_MARKERS,
    MOTION_LABELS_FILE,
    MSR_JOINTS,
    MotionDataset,
    MotionRecording,
    SkippedRecord,
    load_choreo1,
    load_choreo1_text,
    load_choreo2,
    load_motion_folder,
    load_msr_action3d,
    normalize_marker_name,
    save_choreo1,
    save_choreo1_text,
    save_choreo2,
    save_motion_folder,
)
from .kinematics import (
    ARM_COLUMNS,
    JOINT_ANGLE_NAMES,
    LEFT_ARM_COLUMNS,
    RIGHT_ARM_COLUMNS,
    delayed_velocity,
    joint_angles,
    msr_joint_angles,
    orientation_angles,
)

__all__ = [
    "CHOREO1_GESTURES",
    "CHOREO1_LIMBS",
    "CHOREO1_MARKERS",
    "CHOREO1_SMALL_GESTURES",
    "CHOREO2_GESTURES",
    "CHOREO2_MARKERS",
    "JOINT_ANGLE_NAMES",
    "MOTION_LABELS_FILE",
    "MSR_JOINTS",
    "MotionDataset",
    "MotionRecording",
    "SkippedRecord",
    "delayed_velocity",
    "joint_angles",
    "load_choreo1",
    "load_choreo1_text",
    "load_choreo2",
    "load_motion_folder",
    "load_msr_action3d",
    "normalize_marker_name",
    "orientation_angles",
    "save_choreo1",
    "save_choreo1_text",
    "save_choreo2",
    "save_motion_folder",
]

from .histograms import MotionHistograms
from .skeleton import SKELETON_CHAINS, skeleton_bones

__all__ += ["MotionHistograms", "SKELETON_CHAINS", "skeleton_bones"]
