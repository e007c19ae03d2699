"""From marker positions or orientations to angles and delayed velocities (thesis 3.2-3.3.1).

The thesis converts the Kinect skeleton "into 16 angle values representing the dancer
position at a specific time ... through a simple geometrical model of human limbs"
(Thesis section 3.3.1), without listing them. :func:`joint_angles` is our geometric
model; it gives 16 angles:

====================  ============================================================
torso_lean_forward    arcsin(spine . forward_h): spine = unit(neck - pelvis); forward_h
                      is the hips' horizontal forward direction (``vertical`` given)
torso_lean_side       arcsin(spine . right_h), right_h = hips' horizontal right
<side>_shoulder_elev  arccos(-upper_arm . up_t): 0 arm hanging, pi/2 horizontal, pi up
<side>_shoulder_out   arccos(upper_arm . out_t): 0 pointing sideways out, pi/2 to the
                      front (or straight up/down), pi across the body
<side>_elbow_flex     arccos(upper_arm . forearm): 0 straight
<side>_forearm_elev   arccos(-forearm . up_t): forearm down 0, up pi
<side>_hip_front      arcsin(thigh . fwd_t): thigh forward > 0, backward < 0
<side>_hip_out        arcsin(thigh . out_t): abduction > 0
<side>_knee_flex      arccos(thigh . shin): 0 straight
====================  ============================================================

``up_t`` = unit(neck - pelvis), ``right_t`` = the shoulder line orthogonalised against
``up_t``, ``fwd_t = up_t x right_t`` (right-handed: forward) and ``out_t`` = ``right_t`` for the right limbs,
``-right_t`` for the left ones: angles are measured in the dancer's own torso frame, so
they do not depend on where the dancer stands or faces, and a gesture of the left side
gives the same values as its mirror on the right. Every angle is an arccos or arcsin
of a dot product of unit vectors: no singular pose (hanging arm, arm straight) makes an
angle jump, which matters because idle limbs hang down most of the time. With markers
named from the observer's point of view (Choreo2), ``right_t`` is the dancer's left and
``fwd_t`` points backwards: the "front" angles change sign, consistently within a data
set.

The same function reads OpenNI (Choreo1, Choreo2) and MSR Action3D (Kinect v1)
skeletons: the pelvis is ``hip_center`` (MSR) or else the mean of the two hips; the hand end is ``hand`` (else ``wrist``), the shin end is
``ankle`` (else ``foot``).

For Choreo2 orientations, :func:`orientation_angles` computes the relative rotation
between pairs of frames along the limbs, as Euler angles on static x-y-z axes
(``scipy.spatial.transform.Rotation``), as the Choreo2 format says (:ref:`format-choreo2`).
"""

from __future__ import annotations

import functools
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import DataError, ParameterError
from .data import MotionRecording, load_msr_action3d

__all__ = [
    "ARM_COLUMNS",
    "CHOREO2_FRAME_PAIRS",
    "JOINT_ANGLE_NAMES",
    "LEFT_ARM_COLUMNS",
    "RIGHT_ARM_COLUMNS",
    "delayed_velocity",
    "joint_angles",
    "msr_joint_angles",
    "orientation_angle_names",
    "orientation_angles",
]

_SIDES = ("left", "right")

#: Names of the 16 angles returned by :func:`joint_angles`, in column order.
JOINT_ANGLE_NAMES: tuple[str, ...] = ("torso_lean_forward", "torso_lean_side") + tuple(
    f"{s}_{a}"
    for s in _SIDES
    for a in ("shoulder_elev", "shoulder_out", "elbow_flex", "forearm_elev", "hip_front", "hip_out", "knee_flex")
)

_ARM_PARTS = ("shoulder", "elbow", "forearm")
#: Columns of :data:`JOINT_ANGLE_NAMES` that move with the arms (shoulders, elbows, forearms).
ARM_COLUMNS = np.array([i for i, n in enumerate(JOINT_ANGLE_NAMES) if any(k in n for k in _ARM_PARTS)])
#: The right arm's columns of :data:`ARM_COLUMNS`.
RIGHT_ARM_COLUMNS = np.array([i for i in ARM_COLUMNS if JOINT_ANGLE_NAMES[i].startswith("right_")])
#: The left arm's columns, in the order of their right-arm counterparts in :data:`RIGHT_ARM_COLUMNS`.
LEFT_ARM_COLUMNS = np.array([JOINT_ANGLE_NAMES.index("left_" + JOINT_ANGLE_NAMES[i][len("right_"):])
                             for i in RIGHT_ARM_COLUMNS])

#: Parent/child frame pairs along the limbs used by :func:`orientation_angles` (OpenNI
#: frames: a joint's frame is the orientation of the segment starting at that joint; the
#: hand and foot frames repeat the forearm and shin, so they are not paired).
CHOREO2_FRAME_PAIRS: tuple[tuple[str, str], ...] = (
    ("torso", "neck"),
    ("torso", "left_shoulder"), ("left_shoulder", "left_elbow"),
    ("torso", "right_shoulder"), ("right_shoulder", "right_elbow"),
    ("torso", "left_hip"), ("left_hip", "left_knee"),
    ("torso", "right_hip"), ("right_hip", "right_knee"),
)


def _unit(v: np.ndarray, what: str, rec: MotionRecording) -> np.ndarray:
    if not np.isfinite(v).all():
        raise DataError(
            f"Cannot compute joint angles: {what} is not finite in {int((~np.isfinite(v)).any(axis=-1).sum())} "
            f"frame(s){rec._where()}. Expected finite positions whose differences do not overflow (metres)."
        )
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    over = ~np.isfinite(n)  # the squares overflow: the norm of v / max|v|, scaled back
    if over.any():
        s = np.abs(v).max(axis=-1, keepdims=True)
        n[over] = (s * np.linalg.norm(v / s, axis=-1, keepdims=True))[over]
    if np.any(n < 1e-9):
        raise DataError(
            f"Degenerate skeleton: {what} has zero length in {int(np.sum(n < 1e-9))} frame(s){rec._where()} "
            "(two markers at the same place; lost tracking?)."
        )
    return v / n


def _first(rec: MotionRecording, *names: str) -> np.ndarray:
    for n in names:
        if rec.has_marker(n):
            return rec.marker(n)
    return rec.marker(names[0])  # raises, naming the preferred marker and the file


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _acos(x: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(x, -1.0, 1.0))


def _asin(x: np.ndarray) -> np.ndarray:
    return np.arcsin(np.clip(x, -1.0, 1.0))


def joint_angles(recording: MotionRecording, *, vertical: Sequence[float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    """The 16 joint angles of the geometric limb model (Thesis section 3.3.1).

    Parameters
    ----------
    recording : MotionRecording
        Needs markers neck, left/right shoulder, elbow, hand (or wrist), hip, knee,
        ankle (or foot); ``hip_center`` is used for the pelvis when present.
    vertical : sequence of 3 floats, default=(0, 1, 0)
        The camera's upward direction (Kinect: +y); used only by the two torso angles.

    Returns
    -------
    angles : ndarray of shape (n_frames, 16)
        Radians, columns named by :data:`JOINT_ANGLE_NAMES` (see the module docstring).

    Raises
    ------
    DataError
        If a needed marker is missing (the marker and the file are named), a segment has
        zero length, or positions differ by more than floating point holds. The angles of
        a recording that gives none of these are finite.
    """
    try:
        v = np.asarray(vertical, dtype=float)
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.shape != (3,) or not np.isfinite(v).all() or not np.abs(v).max() > 0:
        raise ParameterError(f"vertical must be a nonzero 3-vector of finite numbers; got {vertical!r}.")
    v = v / np.abs(v).max()
    v = v / np.linalg.norm(v)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflowing segment is a DataError of _unit
        return _joint_angles(recording, v)


def _joint_angles(rec: MotionRecording, v: np.ndarray) -> np.ndarray:
    """:func:`joint_angles` with ``v`` the unit vertical."""
    neck = rec.marker("neck")
    lhip, rhip = rec.marker("left_hip"), rec.marker("right_hip")
    pelvis = rec.marker("hip_center") if rec.has_marker("hip_center") else 0.5 * (lhip + rhip)
    up = _unit(neck - pelvis, "the spine (pelvis to neck)", rec)
    r = rec.marker("right_shoulder") - rec.marker("left_shoulder")
    right = _unit(r - _dot(r, up)[:, None] * up, "the shoulder line", rec)
    fwd = np.cross(up, right)  # right-handed: right x up points backwards
    # Hip frame with the world vertical, for the torso lean.
    rh = rhip - lhip
    rh = _unit(rh - (rh @ v)[:, None] * v[None, :], "the horizontal hip line", rec)
    fwd_h = np.cross(np.broadcast_to(v, rh.shape), rh)
    cols = [_asin(_dot(up, fwd_h)), _asin(_dot(up, rh))]
    for side, sign in (("left", -1.0), ("right", 1.0)):
        out = sign * right
        sh = rec.marker(f"{side}_shoulder")
        el = rec.marker(f"{side}_elbow")
        ha = _first(rec, f"{side}_hand", f"{side}_wrist")
        hip = rec.marker(f"{side}_hip")
        kn = rec.marker(f"{side}_knee")
        an = _first(rec, f"{side}_ankle", f"{side}_foot")
        ua = _unit(el - sh, f"the {side} upper arm", rec)
        fa = _unit(ha - el, f"the {side} forearm", rec)
        th = _unit(kn - hip, f"the {side} thigh", rec)
        sn = _unit(an - kn, f"the {side} shin", rec)
        cols += [
            _acos(-_dot(ua, up)),
            _acos(_dot(ua, out)),
            _acos(_dot(ua, fa)),
            _acos(-_dot(fa, up)),
            _asin(_dot(th, fwd)),
            _asin(_dot(th, out)),
            _acos(_dot(th, sn)),
        ]
    return np.stack(cols, axis=1)


def orientation_angle_names(pairs: Sequence[tuple[str, str]] = CHOREO2_FRAME_PAIRS) -> tuple[str, ...]:
    """Column names of :func:`orientation_angles` for ``pairs``."""
    return tuple(f"{a}->{b}:{ax}" for a, b in pairs for ax in "xyz")


def orientation_angles(
    recording: MotionRecording,
    *,
    pairs: Sequence[tuple[str, str]] = CHOREO2_FRAME_PAIRS,
) -> np.ndarray:
    """Relative rotations between marker frames along the limbs, as static x-y-z Euler angles.

    For each pair (parent, child), ``R_rel = R_parent^{-1} R_child`` (both frames given
    relative to the camera as unit quaternions (qx, qy, qz, qw)), converted with
    ``Rotation.as_euler("xyz")`` (lower case: extrinsic, static axes), as the authors' Choreo2
    features do (:ref:`format-choreo2`; Thesis section 6.5).

    Parameters
    ----------
    recording : MotionRecording
        Must carry ``orientations``.
    pairs : sequence of (str, str), default=CHOREO2_FRAME_PAIRS

    Returns
    -------
    angles : ndarray of shape (n_frames, 3 * len(pairs))
        Radians in (-pi, pi] (the middle angle of each triple in [-pi/2, pi/2]); columns
        named by :func:`orientation_angle_names`.
    """
    if recording.orientations is None:
        raise DataError(f"orientation_angles needs orientations (Choreo2 data){recording._where()}.")
    if len(pairs) == 0:
        raise ParameterError("pairs must hold at least one (parent, child) pair of marker names.")
    out = []
    for a, b in pairs:
        rot = []
        for n in (a, b):
            q = recording.orientation(n)
            if not np.isfinite(q).all():
                raise DataError(f"Marker {n!r} has a non-finite quaternion in some frame{recording._where()}; "
                                "expected finite orientations (MotionRecording's on_missing repairs them).")
            scale = np.abs(q).max(axis=1, keepdims=True)
            if np.any(scale < 1e-6):
                raise DataError(f"Marker {n!r} has a zero quaternion in some frame{recording._where()}.")
            big = ~np.isfinite(np.linalg.norm(q, axis=1))  # the squares overflow: q / max|q|, the same rotation
            rot.append(Rotation.from_quat(np.where(big[:, None], q / scale, q)))
        rel = rot[0].inv() * rot[1]
        out.append(rel.as_euler("xyz"))
    return np.concatenate(out, axis=1)


def delayed_velocity(x: np.ndarray, delay: int = 1, *, period: float | None = None) -> np.ndarray:
    """Delayed velocity ``x_t - x_{t-d}`` (Thesis section 3.2).

    Not divided by the time step: the histograms are invariant to a common scaling.

    Parameters
    ----------
    x : ndarray of shape (n_frames, ...)
    delay : int >= 1
    period : float, optional
        For periodic angles (Euler angles: ``2 * pi``), differences are wrapped into
        ``[-period / 2, period / 2)``.

    Returns
    -------
    v : ndarray of shape (n_frames - delay, ...)
        ``v[i] = x[i + delay] - x[i]``, i.e. the velocity at frame ``t = i + delay``.
    """
    if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)) or delay < 1:
        raise ParameterError(f"delay must be an int >= 1; got {delay!r}.")
    if period is not None and not (isinstance(period, (int, float, np.number)) and 0 < float(period) < np.inf):
        raise ParameterError(f"period must be a finite number > 0 (2 * pi for angles) or None; got {period!r}.")
    try:
        x = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"delayed_velocity needs an array of numbers; {exc}") from exc
    if not np.isfinite(x).all():
        raise DataError("delayed_velocity needs finite values; x holds NaN or infinite entries (missing frames?).")
    if x.ndim == 0 or x.shape[0] <= delay:
        raise DataError(
            f"A delayed velocity with delay={delay} needs more than {delay} frames; got shape {x.shape}."
        )
    v = x[delay:] - x[:-delay]
    if period is not None:
        v = (v + period / 2) % period - period / 2
    return v


def msr_joint_angles(folder: str | os.PathLike[str]) -> tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray,
                                                             tuple[str, ...]]:
    """Joint angles, action and subject of every usable MSR Action3D sequence of ``folder``.

    A sequence is usable when :func:`joint_angles` gives more than 8 finite frames. The
    result is cached per folder state (its files' names, sizes and modification times), so
    several experiments of one process read a folder once.

    Parameters
    ----------
    folder : path-like
        An MSR Action3D folder (see :func:`~mmconcepts.motion.load_msr_action3d`).

    Returns
    -------
    angles : tuple of ndarray of shape (T_i, 16)
        The joint angles (:data:`JOINT_ANGLE_NAMES`) of each usable sequence, float64.
    actions, subjects : ndarray of int, shape (n_usable,)
        Each sequence's action (1-20) and subject (from its ``_sNN`` record id).
    skipped : tuple of str
        Record ids of the files that could not be read or gave no usable angles.

    Raises
    ------
    DataError
        If a record id names no subject.
    """
    folder = Path(folder)
    stamp = tuple(sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in folder.iterdir()))
    return _msr_joint_angles(str(folder.resolve()), stamp)


@functools.lru_cache(maxsize=4)
def _msr_joint_angles(folder: str, stamp: tuple) -> tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray,
                                                            tuple[str, ...]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # skipped files are listed in ds.skipped
        ds = load_msr_action3d(folder, on_error="skip")
    angles, actions, subjects, skipped = [], [], [], [s.record_id for s in ds.skipped]
    for r in ds:
        a = np.ascontiguousarray(joint_angles(r), dtype=np.float64)
        if len(a) <= 8 or not np.isfinite(a).all():
            skipped.append(r.record_id)
            continue
        angles.append(a)
        actions.append(r.labels[0])
        subject = re.search(r"_s(\d+)", r.record_id)
        if subject is None:
            raise DataError(f"MSR Action3D record id {r.record_id!r} names no subject (_sNN); expected aAA_sSS_eEE.")
        subjects.append(int(subject.group(1)))
    return tuple(angles), np.array(actions), np.array(subjects), tuple(skipped)
