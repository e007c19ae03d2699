"""Fuzz tests of the motion constructors and what reads them.

Generated :class:`MotionRecording` inputs (shapes, NaN/inf placed in a value, a frame, a
joint or everywhere, odd dtypes, frame rates, marker names, orientations, ``on_missing``
policies) go through the constructor, :func:`joint_angles`, :class:`MotionHistograms` on
those angles and :func:`orientation_angles`. Every example ends in a typed mmconcepts error
or a finite result that passes a check of what correct means: the policy's frames and
values, the duration, the angles' ranges, histograms that sum to one.
"""

from __future__ import annotations

import numpy as np
import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from mmconcepts.motion import CHOREO2_MARKERS, MSR_JOINTS, MotionRecording, joint_angles, orientation_angles
from mmconcepts.motion.histograms import MotionHistograms

pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore")]

HS = dict(suppress_health_check=list(HealthCheck))
ABSENT = "<absent>"

MARKERS = {
    "msr": MSR_JOINTS,
    "choreo2": CHOREO2_MARKERS,
    "few": ("neck", "left_hip", "right_hip"),
    "dupes": ("neck", "Neck", "left hip"),
    "empty": (),
}


def _positions(rng, T, names, scale, special, dtype):
    """A skeleton-like (T, n_markers, 3) array with special values or an odd dtype/shape."""
    M = len(names)
    base = rng.normal(scale=0.3, size=(M, 3)) + np.array([0.0, 0.0, 2.5])
    P = scale * (base[None] + 0.05 * rng.normal(size=(T, M, 3)))
    if P.size:
        t, j, c = rng.integers(T), rng.integers(M), rng.integers(3)
        if special in ("nan", "inf", "-inf"):
            P[t, j, c] = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf}[special]
        elif special == "nan_frame":
            P[t] = np.nan
        elif special == "nan_joint":
            P[:, j] = np.nan
        elif special == "nan_ends":
            P[0, j, c] = P[-1, j, c] = np.nan
        elif special == "nan_many":
            P[rng.random(P.shape) < 0.3] = np.nan
        elif special == "all_nan":
            P[:] = np.nan
    if dtype == "float32":
        return P.astype(np.float32)
    if dtype == "int":
        return np.nan_to_num(P).astype(np.int64)
    if dtype == "object":
        P = P.astype(object)
        if P.size:
            P.flat[0] = "a"
        return P
    if dtype == "list":
        return P.tolist()
    if dtype == "2d":
        return P.reshape(T, 3 * M)
    if dtype == "4d":
        return P[..., None]
    if dtype == "xyzw":
        return np.concatenate([P, np.ones(P.shape[:2] + (1,))], axis=2)
    if dtype == "complex":
        return P.astype(complex)
    return P


def _orientations(rng, T, M, kind):
    if kind is None:
        return None
    q = rng.normal(size=(T, M, 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    if q.size:
        if kind == "nan":
            q[rng.integers(T), rng.integers(M), rng.integers(4)] = np.nan
        elif kind == "zero":
            q[rng.integers(T), rng.integers(M)] = 0.0
        elif kind == "huge":
            q *= 1e300
        elif kind == "nan_marker":
            q[:, rng.integers(M)] = np.nan
    if kind == "shape":
        return q[:, :, :3]
    return q


#: Each argument: the values a caller means (first list) and odd ones (second list).
CHOICES = {
    "names": (["msr", "msr", "choreo2", "few"], ["dupes", "empty", "one_less", "non_str", "str"]),
    "n_frames": ([2, 4, 7, 12], [0, 1]),
    "scale": ([1.0, 1.0, 1e-3, 1e3], [1e-12, 1e150, 1e200, 1e300, 1e-300]),
    "dtype": (["float", "float", "float32", "int", "list"], ["object", "2d", "4d", "xyzw", "complex"]),
    "labels": ([(), (1,), (3, 27), (np.int64(4),)], [("walk",), (1.5,), (True,), 3]),
    "frame_rate": ([ABSENT, 15, 30.0, np.float32(30)], [0, 0.0, -1, np.nan, np.inf, True, "30", None, 1e-300, 1e300]),
    "orientations": ([None, None, "ok"], ["zero", "huge", "shape"]),
    "on_missing": ([ABSENT, "raise", "interpolate", "drop"], ["bogus", None, "Drop"]),
}


@st.composite
def recordings(draw):
    """Keyword arguments of a MotionRecording, drawn, and the float array of its positions (or None).

    Every argument is one a caller means, but at most one (half of the time), which is odd;
    NaN or infinite values are placed independently (half of the time), as tracking loses joints.
    """
    odd = draw(st.sampled_from([None] * len(CHOICES) + list(CHOICES)))
    pick = {k: draw(st.sampled_from(CHOICES[k][k == odd])) for k in CHOICES}
    special = draw(st.sampled_from(["none"] * 7 + ["nan", "inf", "-inf", "nan_frame", "nan_joint", "nan_ends",
                                                   "nan_many", "all_nan", "orientation_nan", "orientation_marker"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    names = MARKERS.get(pick["names"], MSR_JOINTS)
    T = pick["n_frames"]
    kw = dict(positions=_positions(rng, T, names, pick["scale"], special, pick["dtype"]))
    kw["marker_names"] = {"one_less": names[:-1], "non_str": names[:-1] + (3,), "str": "neck"}.get(pick["names"],
                                                                                                    names)
    kw["labels"] = pick["labels"]
    orient = {"orientation_nan": "nan", "orientation_marker": "nan_marker"}.get(special, pick["orientations"])
    kw["orientations"] = _orientations(rng, T, len(names), orient if pick["orientations"] is not None
                                       or special.startswith("orientation") else None)
    for k in ("frame_rate", "on_missing"):
        if pick[k] is not ABSENT:
            kw[k] = pick[k]
    kw["source"] = draw(st.sampled_from(["", "rec.npz"]))
    try:
        P0 = np.asarray(kw["positions"], dtype=float)
    except (TypeError, ValueError):
        P0 = None
    return kw, P0


def _bad_frames(P0, Q0):
    """Frames holding a non-finite position (or orientation)."""
    bad = ~np.isfinite(P0).all(axis=(1, 2))
    if Q0 is not None:
        bad |= ~np.isfinite(Q0).all(axis=(1, 2))
    return bad


def _recording_is_right(rec, duration, kw, P0):
    """The constructor's output: finite arrays, the duration, and the policy's frames and values."""
    if P0 is None or P0.ndim != 3 or not isinstance(rec.frame_rate, float) or not rec.frame_rate > 0:
        return False
    Q0 = None if kw.get("orientations") is None else np.asarray(kw["orientations"], dtype=float)
    P = rec.positions
    if P.shape[1:] != (len(kw["marker_names"]), 3) or duration != rec.n_frames / rec.frame_rate:
        return False
    if not np.isfinite(P).all() or (rec.orientations is not None and not np.isfinite(rec.orientations).all()):
        return False
    bad = _bad_frames(P0, Q0)
    policy = kw.get("on_missing", "raise")
    if policy == "drop":
        want = ~bad
        return bool(want.any() and np.array_equal(P, P0[want])
                    and (Q0 is None or np.array_equal(rec.orientations, Q0[want])))
    if policy == "interpolate":
        finite = np.isfinite(P0)
        return bool(P.shape == P0.shape and np.array_equal(P[finite], P0[finite]))
    return bool(not bad.any() and np.array_equal(P, P0))


@fuzz_settings(200, **HS)
@given(drawn=recordings())
def test_fuzz_motion_recording(drawn):
    kw, P0 = drawn

    def run():
        rec = MotionRecording(**kw)
        return rec, rec.duration

    assert_typed_or_good("mmconcepts.motion.MotionRecording", run, check=lambda res: _recording_is_right(*res, kw, P0))


def _angles_are_right(rec_and_angles):
    rec, A = rec_and_angles
    return bool(A.shape == (rec.n_frames, 16) and (A >= -np.pi / 2 - 1e-12).all() and (A <= np.pi + 1e-12).all())


@fuzz_settings(200, **HS)
@given(drawn=recordings())
def test_fuzz_joint_angles_of_a_recording(drawn):
    kw, _ = drawn

    def run():
        rec = MotionRecording(**kw)
        return rec, joint_angles(rec)

    assert_typed_or_good("mmconcepts.motion.joint_angles(MotionRecording)", run, check=_angles_are_right)


@fuzz_settings(100, **HS)
@given(drawn=recordings(), data=st.sampled_from(["joint", "angles", "velocities"]),
       method=st.sampled_from(["kde", "vq"]))
def test_fuzz_histograms_of_joint_angles(drawn, data, method):
    kw, _ = drawn

    def run():
        A = joint_angles(MotionRecording(**kw))
        mh = MotionHistograms(data=data, method=method, n_bins=4, delay=1, random_state=0)
        return mh.fit_transform([A, A[::-1]]), mh.n_channels_

    def check(res):
        H, n_channels = res
        sums = H.reshape(2, n_channels, -1).sum(axis=2)
        return bool((H >= 0).all() and np.allclose(sums, 1.0))

    assert_typed_or_good("mmconcepts.motion.MotionHistograms(joint_angles)", run, check=check)


@fuzz_settings(150, **HS)
@given(drawn=recordings())
def test_fuzz_orientation_angles_of_a_recording(drawn):
    kw, _ = drawn

    def run():
        rec = MotionRecording(**kw)
        pairs = [(rec.marker_names[0], rec.marker_names[-1])] if rec.marker_names else []
        return rec, orientation_angles(rec, pairs=pairs)

    def check(res):
        rec, E = res
        return bool(E.shape == (rec.n_frames, 3) and (np.abs(E) <= np.pi + 1e-12).all())

    assert_typed_or_good("mmconcepts.motion.orientation_angles(MotionRecording)", run, check=check)
