"""Synthetic choreographies written in the Choreo1 / Choreo2 formats (Thesis 3.3.1, App. B.2-B.3).

The thesis' data sets (a single dancer recorded with a Kinect and OpenNI) cannot be
reached from here. This module simulates them: a kinematic dancer carries the 24 OpenNI
markers of Appendix B.2 (15 with orientations for Choreo2) and performs the 47 primitive
gestures of Table B.2 on their limbs (legs, left arm, right arm, both arms), discrete
(move between two poses, hold, move back) or rhythmic (oscillations, circles, waves).
Choreographies combine 2 or 3 compatible primitives (legs + both arms, or legs + left
arm + right arm). The files it writes are read by :func:`~mmconcepts.motion.load_choreo1`
and :func:`~mmconcepts.motion.load_choreo2`, the same path as real data.

Data sets (sizes of Thesis section 3.3.1 / Appendix B):

- ``primitive``: 326 records, one gesture each, every one of the 47 gestures 6-7 times;
- ``mixed_partial``: 137 records over the 16 gestures of Table 3.1;
- ``mixed_full``: 277 records over the 47 gestures; 60 % of the records show a
  combination that occurs only once in the set (Thesis Fig. 3.8): 166 distinct
  legs + left arm + right arm combinations seen once, and 111 records spread over
  combinations repeated 2-4 times (a third of them legs + both arms: there are only 28
  such combinations, so they necessarily repeat);
- Choreo2: 1100 records, 110 of each of the 10 gestures of Table B.3, positions and
  orientations, marker names from the observer's point of view (:ref:`format-choreo2`), i.e. the
  marker written ``right_hand`` is the dancer's left hand.

How the parameters were chosen (measured on the 566 usable real Kinect v1 skeletons of
MSR Action3D (the ``msr-action3d`` data set), with :func:`joint_angles`; the script's
numbers are repeated here):

============================  ======================================  ==================
quantity                      MSR Action3D (median, [IQR or 5-95 %])  generator
============================  ======================================  ==================
upper arm / forearm / hand    0.276 / 0.290 / 0.069 m                 same, +-3 % per
thigh / shin / foot           0.543 / 0.427 / 0.167 m                 dancer-session
shoulder / hip width          0.358 / 0.345 m                         same
pelvis-spine-neck-head        0.217 / 0.278 / 0.238 m                 same
neck to shoulder              0.218 m (0.124 m drop)                  same
marker jitter, trunk/legs     robust sd 3.2-4.3 mm per axis           Student t(4), 4 mm
marker jitter, hands/feet     robust sd 7.6-11.7 mm per axis          Student t(4), 9 mm
tracking glitches             0.83 % of frame steps of idle leg       0.4 % per marker-
                              markers jump > 10 cm in 1/15 s          frame at 30 Hz,
                                                                      8-25 cm, 1-3 frames
tracking lost (all zeros)     373 / 22738 frames, 19 / 567 files      not simulated
                              (the loaders of MSR handle them)        (OpenNI repeats)
duration CV, repetitions      0.095                                   tempo lognormal 0.12
amplitude CV, repetitions     0.05-0.15 (median 0.12)                 N(1, 0.12)
posture offset, repetitions   0.5-1.5 deg idle, 3-5 deg active dofs   N(0, 2.5) deg idle,
                                                                      N(0, 4) deg active
idle-limb angle sd in a rec.  2.3-3.0 deg (incl. jitter 0.5-1.8 deg)  sway 2 x 1.5 deg
                                                                      sines, 0.1-0.5 Hz
active arm angular speed      95 %: 250-450 deg/s, 99 %: 500-750      gesture tempi
                                                                      0.6-2 Hz, moves
                                                                      0.5-1 s
torso lean forward            25 deg (Kinect spine quirk)             N(6, 2) deg
============================  ======================================  ==================

Not measurable on MSR and chosen by hand (stated as assumptions): 30 frames per second
(OpenNI's rate), demonstrations of 3-6 s (Choreo1) and 2.5-4.5 s (Choreo2), the dancer
2-3 m from the camera at +-10 cm laterally and +-7 deg of yaw, the gesture
key poses (read from the descriptions of Table B.2), and that idle arms swing a little
with walking and rise a little in squats. Nothing here was tuned on an experiment's
result.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .._paths import data_home as _data_home
from .._progress import progress
from .._store import generated_folder, versioned
from .._validation import check_random_state, validate_params
from ..errors import ParameterError
from .data import (
    CHOREO1_LIMBS,
    CHOREO1_MARKERS,
    CHOREO1_SMALL_GESTURES,
    CHOREO2_GESTURES,
    CHOREO2_MARKERS,
    CHOREO2_TO_CHOREO1,
    MotionDataset,
    MotionRecording,
    load_choreo1,
    load_choreo2,
    save_choreo1,
    save_choreo2,
)

__all__ = [
    "GENERATOR_VERSION",
    "SUBSET_SIZES",
    "DancerParams",
    "choreo1_label_sets",
    "make_choreo1",
    "make_choreo2",
    "simulate_choreography",
    "write_choreo1",
    "write_choreo2",
]

#: Bumped whenever the generator's output changes; cached data of another version is rebuilt.
GENERATOR_VERSION = 1

#: Records per subset (Thesis 3.3.1, App. B).
SUBSET_SIZES = {"primitive": 326, "mixed_partial": 137, "mixed_full": 277, "choreo2": 1100}

FRAME_RATE = 30.0
_PI = np.pi
_DEG = _PI / 180


@dataclass(frozen=True)
class DancerParams:
    """Variation and sensor parameters of the simulated dancer (values: module docstring)."""

    frame_rate: float = FRAME_RATE
    duration: tuple[float, float] = (3.0, 6.0)
    tempo_sd: float = 0.12  # log-normal sd of the tempo factor
    amplitude_sd: float = 0.12
    posture_sd_active_deg: float = 4.0
    posture_sd_idle_deg: float = 2.5
    sway_deg: float = 1.5
    noise_trunk_m: float = 0.004
    noise_extremity_m: float = 0.009
    glitch_rate: float = 0.004  # per marker and frame
    glitch_size_m: tuple[float, float] = (0.08, 0.25)
    segment_sd: float = 0.03


# --------------------------------------------------------------------------- body
_SEG = dict(upper_arm=0.276, forearm=0.290, hand=0.069, fingertip=0.06, thigh=0.543, shin=0.427, foot=0.167,
            pelvis_spine=0.217, spine_neck=0.278, neck_head=0.238, shoulder_half=0.179, shoulder_drop=0.124,
            hip_half=0.1725, ankle_height=0.08)

_EXTREMITIES = ("hand", "wrist", "fingertip", "foot", "ankle", "elbow")

IDLE_ARM = np.array([0.15, 0.35, 1.3, 0.25])  # elev, az, twist, flex
IDLE_LEG = np.array([0.03, 0.05, 0.08, 0.0])  # hip flex, hip abd, knee, knee-in


def _n(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _perp(a: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Component of a orthogonal to unit u (row-wise)."""
    return a - np.sum(a * u, axis=-1, keepdims=True) * u


def _arm_dirs(c: np.ndarray, side: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Upper-arm and forearm unit vectors and bend direction in torso coordinates (r, u, f).

    c: (T, 4) elev, az, twist, flex. side: +1 right, -1 left.
    """
    elev, az, tw, fl = c.T
    out = np.array([side, 0.0, 0.0])
    down = np.array([0.0, -1.0, 0.0])
    fwd = np.array([0.0, 0.0, 1.0])
    u = (np.cos(elev)[:, None] * down
         + np.sin(elev)[:, None] * (np.cos(az)[:, None] * out + np.sin(az)[:, None] * fwd))
    up = np.broadcast_to(-down, u.shape)
    p1 = _n(_perp(up, u) + 0.25 * _perp(np.broadcast_to(fwd, u.shape), u))
    p2 = side * np.cross(u, p1)
    b = np.cos(tw)[:, None] * p1 + np.sin(tw)[:, None] * p2
    f = np.cos(fl)[:, None] * u + np.sin(fl)[:, None] * b
    return u, _n(f), b


def _leg_dirs(c: np.ndarray, side: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thigh, shin and foot unit vectors in body coordinates. c: (T, 4)."""
    hf, ha, kn, ki = c.T
    out = np.array([side, 0.0, 0.0])
    down = np.array([0.0, -1.0, 0.0])
    fwd = np.array([0.0, 0.0, 1.0])
    t = _n(np.sin(ha)[:, None] * out + np.cos(ha)[:, None] * (np.cos(hf)[:, None] * down + np.sin(hf)[:, None] * fwd))
    back = _n(_perp(np.broadcast_to(-fwd, t.shape), t))
    inward = _n(_perp(np.broadcast_to(-out, t.shape), t) + 1e-6)
    bend = _n(np.cos(ki)[:, None] * back + np.sin(ki)[:, None] * inward)
    s = _n(np.cos(kn)[:, None] * t + np.sin(kn)[:, None] * bend)
    foot = _n(_perp(np.broadcast_to(fwd, s.shape), s) + 0.05 * s)
    return t, s, foot


def _rot_y(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 2], R[..., 1, 1], R[..., 2, 0], R[..., 2, 2] = c, s, 1.0, -s, c
    return R


def _rot_x(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 1, 1], R[..., 1, 2], R[..., 2, 1], R[..., 2, 2] = 1.0, c, -s, s, c
    return R


def _rot_z(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def _frame(axis: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Rotation matrices (T, 3, 3) with y along ``axis`` and x towards ``ref``."""
    y = _n(axis)
    x = _n(_perp(ref, y) + 1e-9)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1)


def _forward_kinematics(ctrl: dict[str, np.ndarray], seg: dict[str, float], place: dict[str, float]
                        ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Marker positions (T, 3) and frames (T, 3, 3), camera coordinates.

    Camera frame: right-handed, y up, z away from the camera, x to the observer's left;
    the dancer faces the camera, so its right is +x and its forward -z (as in MSR Action3D).
    Body coordinates (right, up, forward) map to camera ones by a 180 deg turn about y.
    """
    T = len(ctrl["yaw"])
    to_cam = np.diag([1.0, 1.0, -1.0])  # body (r, u, f) -> camera (x, y, z)
    yaw = _rot_y(ctrl["yaw"])  # about the vertical, body coordinates
    lean = _rot_z(-ctrl["lean_s"]) @ _rot_x(ctrl["lean_f"])  # lean_f > 0 tips up toward +f, lean_s > 0 toward +r
    M_p = to_cam @ yaw  # pelvis frame (T, 3, 3)
    M_t = M_p @ lean  # torso frame

    def tp(M, v):  # apply (T,3,3) to (T,3) or (3,)
        v = np.broadcast_to(v, (T, 3))
        return np.einsum("tij,tj->ti", M, v)

    legs = {}
    lowest = np.full(T, np.inf)
    for sd, sgn in (("right", 1.0), ("left", -1.0)):
        th, sh, ft = _leg_dirs(np.stack([ctrl[f"{sd}_leg{i}"] for i in range(4)], 1), sgn)
        hip = np.array([sgn * seg["hip_half"], 0.0, 0.0])
        knee = hip + seg["thigh"] * th
        ankle = knee + seg["shin"] * sh
        foot = ankle + seg["foot"] * ft
        legs[sd] = (hip, knee, ankle, foot, th, sh)
        lowest = np.minimum(lowest, np.minimum(ankle[:, 1] - seg["ankle_height"], foot[:, 1]))
    floor = place["floor"]
    # pelvis: lateral/forward offsets in the body frame, height such that the lowest foot
    # touches the floor (yaw does not change heights)
    pelvis = np.stack([ctrl["pelvis_x"], floor - lowest, ctrl["pelvis_z"]], 1)
    P = np.array([place["x"], 0.0, place["z"]]) + tp(M_p, pelvis * np.array([1.0, 0.0, 1.0]))
    P[:, 1] = pelvis[:, 1]

    pos: dict[str, np.ndarray] = {}
    frames: dict[str, np.ndarray] = {}
    up_t = np.array([0.0, 1.0, 0.0])
    pos["waist"] = P + tp(M_t, 0.08 * up_t)
    pos["torso"] = P + tp(M_t, seg["pelvis_spine"] * up_t)
    neck_b = (seg["pelvis_spine"] + seg["spine_neck"]) * up_t
    pos["neck"] = P + tp(M_t, neck_b)
    M_head = M_t @ _rot_x(ctrl["nod"])
    pos["head"] = pos["neck"] + tp(M_head, seg["neck_head"] * up_t)
    frames["torso"] = M_t
    frames["neck"] = M_head
    frames["head"] = M_head
    frames["waist"] = M_p
    for sd, sgn in (("right", 1.0), ("left", -1.0)):
        u, f, b = _arm_dirs(np.stack([ctrl[f"{sd}_arm{i}"] for i in range(4)], 1), sgn)
        sh = neck_b + np.array([sgn * seg["shoulder_half"], -seg["shoulder_drop"], 0.0])
        el = sh + seg["upper_arm"] * u
        wr = el + seg["forearm"] * f
        ha = wr + seg["hand"] * f
        fi = ha + seg["fingertip"] * f
        co = neck_b + np.array([sgn * 0.5 * seg["shoulder_half"], -0.4 * seg["shoulder_drop"], 0.0])
        for name, v in (("shoulder", sh), ("elbow", el), ("wrist", wr), ("hand", ha), ("fingertip", fi),
                        ("collar", co)):
            pos[f"{sd}_{name}"] = P + tp(M_t, v)
        frames[f"{sd}_shoulder"] = M_t @ _frame(u, b)
        frames[f"{sd}_elbow"] = M_t @ _frame(f, b)
        frames[f"{sd}_hand"] = frames[f"{sd}_elbow"]
        frames[f"{sd}_collar"] = M_t
        frames[f"{sd}_wrist"] = frames[f"{sd}_elbow"]
        frames[f"{sd}_fingertip"] = frames[f"{sd}_elbow"]
        hip, knee, ankle, foot, th, shn = legs[sd]
        fwd = np.broadcast_to(np.array([0.0, 0.0, 1.0]), th.shape)
        for name, v in (("hip", hip), ("knee", knee), ("ankle", ankle), ("foot", foot)):
            pos[f"{sd}_{name}"] = P + tp(M_p, v)
        frames[f"{sd}_hip"] = M_p @ _frame(th, fwd)
        frames[f"{sd}_knee"] = M_p @ _frame(shn, fwd)
        frames[f"{sd}_ankle"] = frames[f"{sd}_knee"]
        frames[f"{sd}_foot"] = frames[f"{sd}_knee"]
    # Body coordinates (right, up, forward) are left-handed and to_cam is a reflection: the
    # frames' third axis is flipped so that every frame is a proper rotation (det +1).
    D = np.diag([1.0, 1.0, -1.0])
    frames = {k: v @ D for k, v in frames.items()}
    return pos, frames


# --------------------------------------------------------------------------- time profiles


def _minjerk(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10 - 15 * x + 6 * x * x)


def _schedule(t: np.ndarray, rng: np.random.Generator, tempo: float, move: float = 0.8,
              hold: tuple[float, float] = (0.3, 0.9), start_at_b: bool = False) -> np.ndarray:
    """0 -> 1 -> 0 ... with min-jerk moves and irregular holds (discrete gestures)."""
    segs = []  # (t0, t1, from, to)
    level = 1.0 if start_at_b else 0.0
    now = -rng.uniform(0.0, 1.5) / tempo  # random phase: the recording starts mid-cycle
    while now < t[-1] + 1e-9:
        h = rng.uniform(*hold) / tempo
        segs.append((now, now + h, level, level))
        now += h
        m = move * rng.lognormal(0.0, 0.12) / tempo
        segs.append((now, now + m, level, 1.0 - level))
        now += m
        level = 1.0 - level
    s = np.zeros_like(t)
    for t0, t1, a, b in segs:
        sel = (t >= t0) & (t < t1)
        s[sel] = a + (b - a) * _minjerk((t[sel] - t0) / (t1 - t0))
    return s


def _phase(t: np.ndarray, rng: np.random.Generator, freq: float) -> np.ndarray:
    """2 pi f t + random phase + slow phase wander (a dancer is not a metronome)."""
    dt = t[1] - t[0] if len(t) > 1 else 1.0
    wander = np.cumsum(rng.normal(0.0, 0.6 * np.sqrt(dt), len(t)))
    return 2 * _PI * freq * t + rng.uniform(0, 2 * _PI) + wander


def _slow(t: np.ndarray, rng: np.random.Generator, amp: float, fmin: float = 0.1, fmax: float = 0.5) -> np.ndarray:
    """Sum of two slow random sines (sway)."""
    out = np.zeros_like(t)
    for _ in range(2):
        out += amp * np.sin(2 * _PI * rng.uniform(fmin, fmax) * t + rng.uniform(0, 2 * _PI))
    return out


# --------------------------------------------------------------------------- gestures
# Arm poses (elev, az, twist, flex): elev from hanging (0) to up (pi); az 0 sideways out,
# pi/2 front, > pi/2 across the body; twist 0 bends the elbow upwards, pi downwards,
# pi/2 forwards/inwards; flex 0 straight.
H = np.array([_PI / 2, 0.0, 0.0, 0.05])

_Spec = Callable[[np.ndarray, np.random.Generator, float, float], np.ndarray]


def _discrete(A, B, move=0.8, hold=(0.3, 0.9), start_at_b=False) -> _Spec:
    A, B = np.asarray(A, float), np.asarray(B, float)

    def f(t, rng, tempo, amp):
        s = _schedule(t, rng, tempo, move, hold, start_at_b)
        return A + amp * s[:, None] * (B - A)
    return f


def _hold(A) -> _Spec:
    A = np.asarray(A, float)

    def f(t, rng, tempo, amp):
        return A + 0.0 * t[:, None] + np.stack([_slow(t, rng, 2.5 * _DEG) for _ in A], 1)
    return f


def _rhythm(base, waves, freq) -> _Spec:
    """base + sum_k amp_k * sin(phase + shift_k) on control k; waves: {control: (amp, shift)}."""
    base = np.asarray(base, float)

    def f(t, rng, tempo, amp):
        ph = _phase(t, rng, freq * tempo)
        out = np.tile(base, (len(t), 1))
        for k, (a, sh) in waves.items():
            out[:, k] += amp * a * np.sin(ph + sh)
        return out
    return f


def _punch() -> _Spec:
    A = np.array([0.5, 1.35, 1.9, 2.3])
    B = np.array([_PI / 2 - 0.1, _PI / 2, 0.0, 0.05])
    return _discrete(A, B, move=0.35, hold=(0.1, 0.4))


# Right-arm gestures 1..18 (left arm 30..47 mirror them).
_ARM: dict[int, _Spec] = {
    1: _hold(H),
    2: _hold([0.05, 0.3, 1.5, 0.05]),
    3: _hold([_PI - 0.12, 0.1, 0.0, 0.05]),
    4: _discrete(H, [2.3, 0.1, 0.0, 2.0]),
    5: _discrete(H, [_PI - 0.12, 0.0, 0.0, 0.05]),
    6: _discrete(H, [0.08, 0.0, 0.0, 0.05]),
    7: _discrete(H, [_PI / 2, 0.15, _PI / 2, 2.2]),
    8: _discrete(H, [_PI / 2, 0.0, 0.0, _PI / 2]),
    9: _punch(),
    10: _discrete(H, [_PI / 2, _PI / 2, 0.0, 0.05]),
    11: _discrete(H, [_PI / 2, 0.0, _PI, _PI / 2]),
    12: _discrete(H, [0.45, 0.25, 0.0, 2.6]),
    13: _discrete(H, [_PI / 2, 2.7, 0.0, 0.05], move=1.0),
    14: _rhythm([_PI / 2, 0.0, _PI, 0.85], {3: (0.65, 0.0)}, 1.2),
    15: _rhythm([_PI / 2, 0.0, 0.0, 0.05], {0: (0.35, 0.0), 1: (0.35, _PI / 2)}, 0.7),
    16: _rhythm([_PI / 2, 0.0, 0.0, 0.35], {0: (0.25, 0.0), 3: (0.3, -1.2)}, 1.0),
    17: _rhythm([1.35, 0.35, 0.0, 1.45], {2: (0.45, 0.0), 3: (0.15, _PI / 2)}, 2.0),
    18: _rhythm([2.75, 0.15, 0.0, 0.35], {1: (0.3, 0.0), 3: (0.15, _PI / 2)}, 1.6),
}


def _both_arms(gid: int) -> Callable[[np.ndarray, np.random.Generator, float, float], dict[str, np.ndarray]]:
    def f(t, rng, tempo, amp):
        T = len(t)
        out = {}
        if gid == 19:  # clap at varying positions
            ph = _phase(t, rng, 1.8 * tempo)
            pos = 1.1 + 0.5 * np.sin(2 * _PI * rng.uniform(0.1, 0.25) * t + rng.uniform(0, 2 * _PI))
            for sd in ("right", "left"):
                az = 1.2 + amp * 0.35 * np.sin(ph)
                out[sd] = np.stack([pos, az, np.full(T, _PI / 2), np.full(T, 0.8)], 1)
        elif gid in (20, 21):  # paddling on the left (20) / right (21)
            ph = _phase(t, rng, 0.6 * tempo)
            near, far = ("left", "right") if gid == 20 else ("right", "left")
            out[near] = np.stack([0.7 + amp * 0.35 * np.sin(ph), 0.6 + amp * 0.4 * np.cos(ph),
                                  np.full(T, 1.2), 0.7 + 0.3 * np.sin(ph)], 1)
            out[far] = np.stack([1.1 + amp * 0.35 * np.sin(ph), 1.9 + amp * 0.35 * np.cos(ph),
                                 np.full(T, 1.2), np.full(T, 0.6)], 1)
            sgn = -1.0 if gid == 20 else 1.0  # lean towards the paddling side
            out["lean_s"] = sgn * (0.06 + 0.04 * np.sin(ph))
            out["yaw"] = sgn * 0.12 * np.cos(ph)
        elif gid == 22:  # pushing on ski sticks
            ph = _phase(t, rng, 0.8 * tempo)
            s = 0.5 + 0.5 * np.sin(ph)
            for sd in ("right", "left"):
                out[sd] = np.stack([0.35 + amp * 1.0 * s, np.full(T, 1.35), np.full(T, 1.3), 0.9 - 0.6 * s], 1)
            out["lean_f"] = 0.05 + 0.25 * amp * (1 - s)
        return out
    return f


def _legs(gid: int) -> Callable[[np.ndarray, np.random.Generator, float, float], dict[str, np.ndarray]]:
    def f(t, rng, tempo, amp):
        T = len(t)
        idle = np.tile(IDLE_LEG, (T, 1))
        out = {"right": idle.copy(), "left": idle.copy()}
        if gid == 23:  # un-squat: from squat, stand up, squat again ...
            s = _schedule(t, rng, tempo, move=1.0, hold=(0.3, 0.8), start_at_b=True)
            sq = np.array([1.25, 0.15, 2.0, 0.0])
            for sd in out:
                out[sd] = IDLE_LEG + amp * s[:, None] * (sq - IDLE_LEG)
            out["lean_f"] = 0.35 * amp * s
            out["idle_arm_elev"] = 0.3 * s
        elif gid == 24:  # walking in place
            ph = _phase(t, rng, 0.9 * tempo)
            for sd, sh in (("right", 0.0), ("left", _PI)):
                lift = np.maximum(0.0, np.sin(ph + sh))
                out[sd] = np.stack([0.03 + amp * 0.55 * lift, np.full(T, 0.05), 0.08 + amp * 1.0 * lift, np.zeros(T)], 1)
            out["idle_arm_swing"] = 0.12 * np.sin(ph)
        elif gid == 25:  # stay still
            pass
        elif gid in (26, 27):  # step on the right / left
            lead, trail = ("right", "left") if gid == 26 else ("left", "right")
            s = _schedule(t, rng, tempo, move=0.9, hold=(0.4, 1.0))
            ds = np.abs(np.gradient(s)) / max(np.abs(np.gradient(s)).max(), 1e-9)
            rising = np.gradient(s) >= 0
            first = np.where(rising, ds, 0.0)
            second = np.where(rising, 0.0, ds)
            out[lead][:, 1] += amp * 0.35 * first
            out[lead][:, 2] += amp * 0.4 * first
            out[trail][:, 1] -= amp * 0.15 * second
            out[trail][:, 2] += amp * 0.4 * second
            out["pelvis_x"] = (1.0 if gid == 26 else -1.0) * amp * 0.3 * s
        elif gid in (28, 29):  # flag / P shape on one leg
            sd = "right" if gid == 28 else "left"
            s = _schedule(t, rng, tempo, move=1.0, hold=(0.6, 1.4))
            flag = np.array([0.9, 0.6, 2.0, 1.0])
            out[sd] = IDLE_LEG + amp * s[:, None] * (flag - IDLE_LEG)
            out["lean_s"] = (-1.0 if gid == 28 else 1.0) * 0.05 * s
        return out
    return f


def _mirror_arm(gid: int) -> int:
    return gid - 29 if 30 <= gid <= 47 else gid


def simulate_choreography(
    gestures: tuple[int, ...] | list[int],
    *,
    random_state=None,
    params: DancerParams = DancerParams(),
    body: dict[str, float] | None = None,
    duration: float | None = None,
    markers: tuple[str, ...] = CHOREO1_MARKERS,
    with_orientations: bool = False,
) -> MotionRecording:
    """Simulate one demonstration of a choreography made of Table B.2 gestures.

    Parameters
    ----------
    gestures : sequence of int
        Gesture ids of Table B.2, at most one per limb group, compatible: legs + both
        arms, or legs + left arm + right arm (or a single gesture). Limbs without a
        gesture are idle (they still sway a little).
    random_state : int, Generator or None
    params : DancerParams
    body : dict, optional
        Segment lengths (default: the MSR Action3D medians, module docstring).
    duration : float, optional
        Seconds (default: uniform in ``params.duration``).
    markers : tuple of str
        Markers to output, a subset of the 24 OpenNI ones.
    with_orientations : bool
        Also output the markers' frames as quaternions (qx, qy, qz, qw).

    Returns
    -------
    MotionRecording
        Labels = ``gestures`` (sorted).
    """
    rng = check_random_state(random_state)
    gestures = tuple(sorted(int(g) for g in gestures))
    found = [CHOREO1_LIMBS.get(g) for g in gestures]
    limbs = [limb for limb in found if limb is not None]
    if len(limbs) < len(found):
        raise ParameterError(f"Unknown gesture id in {gestures}; ids are 1..47 (Table B.2).")
    if len(set(limbs)) != len(limbs) or ("both_arms" in limbs and ({"left_arm", "right_arm"} & set(limbs))):
        raise ParameterError(
            f"Gestures {gestures} use limbs {limbs}: a choreography takes at most one gesture per limb group, "
            "and 'both_arms' excludes the single-arm groups."
        )
    seg = dict(_SEG if body is None else body)
    fs = params.frame_rate
    dur = rng.uniform(*params.duration) if duration is None else float(duration)
    T = max(int(round(dur * fs)), 8)
    t = np.arange(T) / fs
    tempo = float(rng.lognormal(0.0, params.tempo_sd))
    amp = float(np.clip(rng.normal(1.0, params.amplitude_sd), 0.7, 1.3))
    act_sd, idle_sd = params.posture_sd_active_deg * _DEG, params.posture_sd_idle_deg * _DEG
    sway = params.sway_deg * _DEG

    ctrl: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    active = set()
    for g, limb in zip(gestures, limbs):
        if limb == "legs":
            res = _legs(g)(t, rng, tempo, amp)
            ctrl["right_leg"], ctrl["left_leg"] = res.pop("right"), res.pop("left")
            extra.update(res)
            active.add("legs")
        elif limb == "both_arms":
            res = _both_arms(g)(t, rng, tempo, amp)
            ctrl["right_arm"], ctrl["left_arm"] = res.pop("right"), res.pop("left")
            extra.update(res)
            active.update(("right_arm", "left_arm"))
        else:
            c = _ARM[_mirror_arm(g)](t, rng, tempo, amp)
            ctrl[limb] = c
            active.add(limb)
    for limb, idle in (("right_arm", IDLE_ARM), ("left_arm", IDLE_ARM), ("right_leg", IDLE_LEG),
                       ("left_leg", IDLE_LEG)):
        group = "legs" if limb.endswith("leg") else limb
        if limb not in ctrl:
            c = np.tile(idle, (T, 1))
            if limb.endswith("arm"):
                c[:, 0] += extra.get("idle_arm_elev", 0.0)
                sgn = 1.0 if limb.startswith("right") else -1.0
                c[:, 0] += sgn * extra.get("idle_arm_swing", 0.0)
            ctrl[limb] = c
        sd = act_sd if group in active else idle_sd
        ctrl[limb] = ctrl[limb] + rng.normal(0.0, sd, 4)[None, :]
        ctrl[limb] = ctrl[limb] + np.stack([_slow(t, rng, sway) for _ in range(4)], 1)
    # keep angles in their meaningful ranges
    for limb in ("right_arm", "left_arm"):
        ctrl[limb][:, 0] = np.clip(ctrl[limb][:, 0], 0.0, _PI - 0.02)
        ctrl[limb][:, 3] = np.clip(ctrl[limb][:, 3], 0.0, 2.7)
    for limb in ("right_leg", "left_leg"):
        ctrl[limb][:, 2] = np.clip(ctrl[limb][:, 2], 0.0, 2.4)

    C: dict[str, np.ndarray] = {}
    for limb in ("right_arm", "left_arm", "right_leg", "left_leg"):
        side, part = limb.split("_")
        for i in range(4):
            C[f"{side}_{part}{i}"] = ctrl[limb][:, i]
    C["yaw"] = rng.normal(0.0, 0.12) + extra.get("yaw", 0.0) + _slow(t, rng, 0.01)
    C["lean_f"] = rng.normal(6 * _DEG, 2 * _DEG) + extra.get("lean_f", 0.0) + _slow(t, rng, sway)
    C["lean_s"] = rng.normal(0.0, 1.5 * _DEG) + extra.get("lean_s", 0.0) + _slow(t, rng, sway)
    C["pelvis_x"] = np.zeros(T) + extra.get("pelvis_x", 0.0) + _slow(t, rng, 0.01)
    C["pelvis_z"] = np.zeros(T) + _slow(t, rng, 0.01)
    C["nod"] = rng.normal(0.1, 0.05) + _slow(t, rng, 2 * _DEG)
    for k, v in C.items():
        C[k] = np.broadcast_to(np.asarray(v, float), (T,)).copy()
    place = {"x": rng.normal(0.0, 0.1), "z": rng.uniform(2.0, 3.0), "floor": -1.05}
    pos, frames = _forward_kinematics(C, seg, place)

    P = np.stack([pos[m] for m in markers], 1)
    # sensor noise: Student t(4) scaled to the measured robust sd
    scale = np.array([params.noise_extremity_m if any(e in m for e in _EXTREMITIES) else params.noise_trunk_m
                      for m in markers])
    P = P + rng.standard_t(4, size=P.shape) * scale[None, :, None]
    # tracking glitches: a marker jumps away for 1-3 frames
    n_ev = rng.poisson(params.glitch_rate * T * len(markers))
    for _ in range(n_ev):
        j, t0 = rng.integers(len(markers)), rng.integers(T)
        L = min(int(rng.geometric(0.5)), 3)
        d = _n(rng.normal(size=3)) * rng.uniform(*params.glitch_size_m)
        P[t0: t0 + L, j] += d
    Q = None
    if with_orientations:
        R = np.stack([frames[m] for m in markers], 1).reshape(-1, 3, 3)
        rot = Rotation.from_matrix(R) * Rotation.from_rotvec(rng.normal(0.0, 2 * _DEG, (len(R), 3)))
        Q = rot.as_quat().reshape(T, len(markers), 4)
    return MotionRecording(P, markers, gestures, orientations=Q, frame_rate=fs)


# --------------------------------------------------------------------------- data sets

_LIMB_GROUPS = {g: [k for k, v in CHOREO1_LIMBS.items() if v == g] for g in ("legs", "both_arms", "right_arm", "left_arm")}


def _pick(group: list[int], usage: dict[int, int], rng: np.random.Generator) -> int:
    """A gesture of the group, the least used ones first (balanced coverage), ties at random."""
    m = min(usage[g] for g in group)
    cands = [g for g in group if usage[g] == m]
    g = int(cands[rng.integers(len(cands))])
    usage[g] += 1
    return g


def choreo1_label_sets(subset: str, *, n_records: int | None = None, random_state=None) -> list[tuple[int, ...]]:
    """The gesture combination of each record of a Choreo1 subset (see the module docstring)."""
    if subset not in ("primitive", "mixed_partial", "mixed_full"):
        raise ParameterError(f"subset must be 'primitive', 'mixed_partial' or 'mixed_full'; got {subset!r}.")
    rng = check_random_state(random_state)
    n = SUBSET_SIZES[subset] if n_records is None else int(n_records)
    if n < 1:
        raise ParameterError(f"n_records must be >= 1; got {n_records}.")
    if subset == "primitive":
        ids = sorted(CHOREO1_LIMBS)
        labels = [(ids[i % len(ids)],) for i in range(n)]
        return [labels[i] for i in rng.permutation(n)]
    allowed = set(CHOREO1_SMALL_GESTURES) if subset == "mixed_partial" else set(CHOREO1_LIMBS)
    groups = {k: [g for g in v if g in allowed] for k, v in _LIMB_GROUPS.items()}
    usage = {g: 0 for g in allowed}

    def combo(structure: str) -> tuple[int, ...]:
        if structure == "both":
            return tuple(sorted((_pick(groups["legs"], usage, rng), _pick(groups["both_arms"], usage, rng))))
        return tuple(sorted((_pick(groups["legs"], usage, rng), _pick(groups["right_arm"], usage, rng),
                             _pick(groups["left_arm"], usage, rng))))

    if subset == "mixed_partial":
        # 16 both-arms combinations vs 64 three-gesture ones: a third of the records use both arms.
        return [combo("both" if rng.random() < 1 / 3 else "three") for _ in range(n)]
    # mixed_full: 60 % of the records show a combination seen only once (Thesis Fig 3.8).
    n_single = int(round(0.6 * n))
    n_rep = n - n_single
    counts: list[int] = []
    while sum(counts) < n_rep:
        counts.append(int(rng.choice([2, 3, 4], p=[0.5, 0.3, 0.2])))
    while sum(counts) > n_rep:
        counts[-1] -= 1
        if counts[-1] < 2:
            extra = counts.pop()
            if counts:
                counts[-1] += extra
    seen: set[tuple[int, ...]] = set()
    out: list[tuple[int, ...]] = []
    for i, c in enumerate(counts):
        structure = "both" if i % 3 == 0 else "three"
        for _ in range(100):
            k = combo(structure)
            if k not in seen:
                break
        seen.add(k)
        out += [k] * c
    for _ in range(n_single):
        for _ in range(1000):
            k = combo("three")
            if k not in seen:
                break
        seen.add(k)
        out.append(k)
    return [out[i] for i in rng.permutation(len(out))]


def _record_rng(seed: int, subset: str, i: int) -> np.random.Generator:
    code = sum(ord(ch) * 31 ** k for k, ch in enumerate(subset)) % (2**31)
    return np.random.default_rng(np.random.SeedSequence([int(seed), code, int(i)]))


def _dancer_body(seed: int, params: DancerParams) -> dict[str, float]:
    """One demonstrator: segment lengths drawn once per seed around the MSR medians."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    return {k: v * float(np.clip(rng.normal(1.0, params.segment_sd), 0.9, 1.1)) for k, v in _SEG.items()}


def _check_seed(random_state) -> int:
    if isinstance(random_state, bool) or not isinstance(random_state, (int, np.integer)) or random_state < 0:
        raise ParameterError(
            f"random_state must be a non-negative int here (it names the cached data set); got {random_state!r}."
        )
    return int(random_state)


_GENERATOR_CONSTRAINTS: dict[str, list] = {"verbose": ["verbose"]}


def write_choreo1(folder: str | os.PathLike[str], subset: str, *, random_state: int = 0,
                  n_records: int | None = None, params: DancerParams = DancerParams(),
                  verbose: bool | int = False) -> Path:
    """Generate a Choreo1 subset and write ``<folder>/<subset>.json`` + NPZ. Returns the JSON path.

    Deterministic for a given ``random_state``: record i depends only on (seed, subset, i).
    ``verbose`` shows a progress bar over the records (see :func:`make_choreo1`).
    """
    seed = _check_seed(random_state)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="write_choreo1")
    labels = choreo1_label_sets(subset, n_records=n_records, random_state=_record_rng(seed, subset + ":labels", 0))
    body = _dancer_body(seed, params)
    recs = [simulate_choreography(l, random_state=_record_rng(seed, subset, i), params=params, body=body)
            for i, l in enumerate(progress(labels, verbose=verbose, desc=f"generated {subset}", unit="record"))]
    return save_choreo1(recs, folder, subset)


def write_choreo2(folder: str | os.PathLike[str], *, random_state: int = 0, n_records: int | None = None,
                  params: DancerParams = DancerParams(duration=(2.5, 4.5)), verbose: bool | int = False) -> Path:
    """Generate the Choreo2-like set (10 gestures of Table B.3) and write ``choreo2.json`` + NPZ.

    Marker names are written from the observer's point of view, as in the real Choreo2
    (:ref:`format-choreo2`): the dancer's left hand is written ``right_hand``. ``verbose``
    shows a progress bar over the records (see :func:`make_choreo1`).
    """
    seed = _check_seed(random_state)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="write_choreo2")
    n = SUBSET_SIZES["choreo2"] if n_records is None else int(n_records)
    if n < 1:
        raise ParameterError(f"n_records must be >= 1; got {n_records}.")
    order = np.random.default_rng(np.random.SeedSequence([seed, 2, 2])).permutation(n)
    labels = [int(i % 10) for i in order]
    body = _dancer_body(seed, params)
    swap = {m: (m.replace("left", "RIGHT").replace("right", "left").replace("RIGHT", "right")) for m in CHOREO2_MARKERS}
    recs = []
    for i, lab in enumerate(progress(labels, verbose=verbose, desc="generated choreo2", unit="record")):
        r = simulate_choreography((CHOREO2_TO_CHOREO1[lab],), random_state=_record_rng(seed, "choreo2", i),
                                  params=params, body=body, markers=CHOREO2_MARKERS, with_orientations=True)
        recs.append(MotionRecording(r.positions, tuple(swap[m] for m in CHOREO2_MARKERS), (lab,),
                                    orientations=r.orientations, frame_rate=r.frame_rate))
    return save_choreo2(recs, folder, name="synthetic choreo2 (mmconcepts)", label_descriptions=CHOREO2_GESTURES,
                        dtype=np.float32)


def _generate(home: Path, root: Path, manifest: dict, build: Callable[[Path], object], force: bool) -> Path:
    """``root`` made once by ``build`` (:func:`mmconcepts._store.generated_folder`), keyed on the version."""
    return generated_folder(root, manifest, build, code=versioned("mmconcepts.motion.synthetic", GENERATOR_VERSION),
                            home=home, force=force)


def make_choreo1(subset: str, *, data_home: str | os.PathLike[str] | None = None, random_state: int = 0,
                 n_records: int | None = None, force: bool = False, verbose: bool | int = False) -> MotionDataset:
    """The synthetic Choreo1 subset, generated once into a cache folder and loaded from it.

    Made by the package's cache facility (:func:`mmconcepts._store.generated_folder`): nothing
    is regenerated when the folder holds a complete set of the same parameters and
    :data:`GENERATOR_VERSION`, and processes sharing ``data_home`` generate it once.

    Parameters
    ----------
    subset : {"primitive", "mixed_partial", "mixed_full"}
    data_home : path-like, optional
        Cache root (default :func:`mmconcepts._paths.data_home`); files go to
        ``<data_home>/choreo1-synthetic/seed<random_state>/<subset>[-n<n_records>]/``
        (``<subset>.json`` and ``<subset>.npz``, the Choreo1 layout).
    random_state : int
        Seed; the same seed gives the same files.
    n_records : int, optional
        Fewer (or more) records than the thesis' size, e.g. for quick runs.
    force : bool
        Regenerate even if a complete copy exists.
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the records while they are generated; an
        int above 0 counts as True. The records are the same.
    """
    seed = _check_seed(random_state)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="make_choreo1")
    if subset not in ("primitive", "mixed_partial", "mixed_full"):
        raise ParameterError(f"subset must be 'primitive', 'mixed_partial' or 'mixed_full'; got {subset!r}.")
    home = _data_home(data_home)
    n = SUBSET_SIZES[subset] if n_records is None else int(n_records)
    stem = subset if n_records is None else f"{subset}-n{n}"
    root = home / "choreo1-synthetic" / f"seed{seed}" / stem
    _generate(home, root, {"seed": seed, "subset": subset, "n_records": n},
              lambda tmp: write_choreo1(tmp, subset, random_state=seed, n_records=n_records, verbose=verbose), force)
    ds = load_choreo1(root / f"{subset}.json", frame_rate=FRAME_RATE)
    ds.name = subset
    return ds


def make_choreo2(*, data_home: str | os.PathLike[str] | None = None, random_state: int = 0,
                 n_records: int | None = None, force: bool = False, verbose: bool | int = False) -> MotionDataset:
    """The synthetic Choreo2-like set (1100 records, Table B.3), cached as :func:`make_choreo1`.

    Files go to ``<data_home>/choreo2-synthetic/seed<random_state>/{full,n<n_records>}/``.
    ``verbose`` shows a progress bar over the records while they are generated.
    """
    seed = _check_seed(random_state)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="make_choreo2")
    home = _data_home(data_home)
    n = SUBSET_SIZES["choreo2"] if n_records is None else int(n_records)
    root = home / "choreo2-synthetic" / f"seed{seed}" / (f"n{n}" if n_records is not None else "full")
    _generate(home, root, {"seed": seed, "subset": "choreo2", "n_records": n},
              lambda tmp: write_choreo2(tmp, random_state=seed, n_records=n_records, verbose=verbose), force)
    return load_choreo2(root / "choreo2.json", frame_rate=FRAME_RATE)
