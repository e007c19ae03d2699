"""Motion primitives: skeletons, kinematics, angle/velocity histograms, choreography data.

Thesis chapter 3 (sections 3.2-3.3) and Appendix B.2-B.3.

Contents
--------
data
    :class:`MotionRecording`, :class:`MotionDataset`; loaders and writers for Choreo1
    (JSON + NPZ, text layout), Choreo2 (JSON + NPZ with orientations) and MSR Action3D.
kinematics
    :func:`joint_angles` (16 angles of a geometric limb model), :func:`orientation_angles`
    (relative rotations along the limbs as Euler angles), :func:`delayed_velocity`.
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
    MSR_JOINTS,
    MotionDataset,
    MotionRecording,
    SkippedRecord,
    load_choreo1,
    load_choreo1_text,
    load_choreo2,
    load_msr_action3d,
    normalize_marker_name,
    save_choreo1,
    save_choreo1_text,
    save_choreo2,
)
from .kinematics import (
    JOINT_ANGLE_NAMES,
    delayed_velocity,
    joint_angles,
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
    "MSR_JOINTS",
    "MotionDataset",
    "MotionRecording",
    "SkippedRecord",
    "delayed_velocity",
    "joint_angles",
    "load_choreo1",
    "load_choreo1_text",
    "load_choreo2",
    "load_msr_action3d",
    "normalize_marker_name",
    "orientation_angles",
    "save_choreo1",
    "save_choreo1_text",
    "save_choreo2",
]

from .histograms import MotionHistograms

__all__ += ["MotionHistograms"]
