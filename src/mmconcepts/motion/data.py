"""Motion recordings, data sets and their loaders (thesis section 3.3.1, Appendix B.2-B.3).

Formats (as the thesis' data formats describe them):

Choreo1
    ``<subset>.json`` ``{"marker-names": [...], "data-file": "<subset>.npz", "records":
    [{"data-id": 0, "labels": [3, 27]}, ...]}`` (hyphenated keys) and an NPZ holding one
    ``(T, n_markers, 3)`` array per record under ``str(data-id)``. Labels are gesture ids
    of Thesis Table B.2 (1..48). The text layout holds one frame per line, ``3 *
    n_markers`` floats.
Choreo2
    ``choreo2.json`` ``{"name": ..., "marker_names": [...], "label_descriptions": [...],
    "data_file": "choreo2.npz", "records": [{"data_id": 0, "labels": [g]}, ...]}``
    (underscored keys); NPZ arrays ``(T, 15, 7)``: x, y, z, then the marker frame's unit
    quaternion in ROS tf order (qx, qy, qz, qw), relative to the camera.
MSR Action3D
    ``aAA_sSS_eEE_skeleton3D.txt``, one joint per line ``x y z confidence``, 20 lines per
    frame (Li, Zhang and Liu, CVPR workshops 2010).
Generic motion layout (your own recordings)
    One CSV file per recording, a header ``<joint>_x,<joint>_y,<joint>_z`` for every joint
    and one row per frame, plus ``labels.csv`` (``file,labels``): :func:`load_motion_folder`,
    :func:`save_motion_folder`.

Marker names are matched without regard to case, with spaces, hyphens and underscores
treated alike (:func:`normalize_marker_name`).
"""

from __future__ import annotations

import json
import logging
import numbers
import os
import re
import warnings
import zipfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .._io import LABEL_SEPARATOR, LABELS_HEADER, atomic_path
from ..errors import DataError, DataFormatError, ParameterError

__all__ = [
    "CHOREO1_GESTURES",
    "CHOREO1_LIMBS",
    "CHOREO1_MARKERS",
    "CHOREO1_SMALL_GESTURES",
    "CHOREO2_GESTURES",
    "CHOREO2_MARKERS",
    "CHOREO2_TO_CHOREO1",
    "MSR_ACTIONS",
    "MSR_JOINTS",
    "MotionDataset",
    "MotionRecording",
    "SkippedRecord",
    "load_choreo1",
    "load_choreo1_text",
    "load_choreo2",
    "load_motion_folder",
    "load_msr_action3d",
    "parse_msr_name",
    "normalize_marker_name",
    "save_choreo1",
    "save_choreo1_text",
    "save_choreo2",
    "save_motion_folder",
]

# --------------------------------------------------------------------------- constants

#: The 24 Kinect/OpenNI markers of Choreo1 (Thesis Appendix B.2.1), snake_case as the
#: generators write them. The thesis' list names "right hand" twice and omits one of
#: OpenNI's 24 skeleton joints, the torso; here the list is OpenNI's (``torso`` added).
CHOREO1_MARKERS: tuple[str, ...] = (
    "head", "neck", "waist",
    "left_hip", "left_shoulder", "left_elbow", "left_hand", "left_knee", "left_foot",
    "left_collar", "left_wrist", "left_fingertip", "left_ankle",
    "right_hip", "right_shoulder", "right_elbow", "right_hand", "right_knee", "right_foot",
    "right_collar", "right_wrist", "right_fingertip", "right_ankle",
    "torso",
)

#: The 15 OpenNI tracker frames of Choreo2 (Thesis Appendix B.3.1, formats.md).
CHOREO2_MARKERS: tuple[str, ...] = (
    "head", "neck", "torso",
    "left_shoulder", "left_elbow", "left_hand",
    "right_shoulder", "right_elbow", "right_hand",
    "left_hip", "left_knee", "left_foot",
    "right_hip", "right_knee", "right_foot",
)

_ARM_DESCRIPTIONS = (
    "hold horizontal",
    "hold vertical (down)",
    "hold vertical (up)",
    "from horizontal on side, bend over the head",
    "raise from horizontal to vertical",
    "lower from horizontal to vertical",
    "from horizontal side, bend in front of the torso",
    "from horizontal side, bent elbow to get vertical forearm toward up",
    "mimic punching",
    "hold horizontal and bring from side to front",
    "from horizontal side, bend elbow to get vertical forearm toward down",
    "from horizontal side, bring hand to shoulder (elbow moving vertically)",
    "hold horizontal and bring from {side} side to {other} side",
    "swing forearm downside with horizontal upper arm",
    "draw circles with arm extended on the {side}",
    "wave motion of the arm held, horizontal on the side",
    "wave hand (shoulder level)",
    "wave hand (over the head)",
)


def _table_b2() -> tuple[dict[int, str], dict[int, str]]:
    names: dict[int, str] = {}
    limbs: dict[int, str] = {}
    for i, d in enumerate(_ARM_DESCRIPTIONS):
        names[1 + i] = "right arm: " + d.format(side="right", other="left")
        limbs[1 + i] = "right_arm"
        names[30 + i] = "left arm: " + d.format(side="left", other="right")
        limbs[30 + i] = "left_arm"
    both = ("clap hands (at varying positions)", "mimic paddling on the left",
            "mimic paddling on the right", "mimic pushing on ski sticks")
    for i, d in enumerate(both):
        names[19 + i] = "both arms: " + d
        limbs[19 + i] = "both_arms"
    legs = ("un-squat", "mimic walking", "stay still", "step on the right", "step on the left",
            "right leg: raise and bend leg to form a flag (or 'P') shape",
            "left leg: raise and bend leg to form a flag (or 'P') shape")
    for i, d in enumerate(legs):
        names[23 + i] = ("legs: " + d) if i < 5 else d
        limbs[23 + i] = "legs"
    return dict(sorted(names.items())), dict(sorted(limbs.items()))


#: Gesture id -> description, Thesis Table B.2 (47 gestures; id 48 is unused).
#: Limb group of each gesture of Table B.2: ``legs``, ``right_arm``, ``left_arm`` or
#: ``both_arms`` (gestures 28 and 29, one leg, belong to the ``legs`` group).
CHOREO1_GESTURES, CHOREO1_LIMBS = _table_b2()

#: The 16 gestures of the small mixed set, Thesis Table 3.1.
CHOREO1_SMALL_GESTURES: tuple[int, ...] = (1, 5, 6, 10, 19, 20, 21, 22, 23, 24, 25, 28, 30, 38, 40, 43)

#: The 10 gestures of Choreo2, Thesis Table B.3 (label id 0..9).
CHOREO2_GESTURES: tuple[str, ...] = (
    "both legs: squat",
    "both legs: walk",
    "right leg: make a flag/P on right leg",
    "both arms: clap",
    "both arms: mimic paddling left",
    "right arm: mimic punching with right arm",
    "right arm: right arm horizontal goes from side to front",
    "left arm: horizontal left arm, forearm goes down to form a square angle",
    "left arm: make waves on left arm",
    "left arm: say hello with left arm",
)

#: The Table B.2 gesture each Choreo2 gesture (Table B.3) corresponds to; used by the
#: synthetic generator to reuse the same gesture model.
CHOREO2_TO_CHOREO1: tuple[int, ...] = (23, 24, 28, 19, 20, 9, 10, 40, 45, 46)

#: MSR Action3D joint order, checked on the data (the 567 skeleton files of the ``msr-action3d`` set):
#: joint 20 is the highest (head); joints 17-20 lowest (ankles/feet); the arm that moves
#: in "high arm wave" (subjects used their right arm) is 9/11/13 and the leg that moves in
#: "forward kick" is 15/17/19, which fixes which of each pair is the right one.
MSR_JOINTS: tuple[str, ...] = (
    "left_shoulder", "right_shoulder", "neck", "spine", "left_hip", "right_hip", "hip_center",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_foot", "right_foot", "head",
)

#: The 20 MSR Action3D action names (ids 1..20).
MSR_ACTIONS: dict[int, str] = dict(enumerate((
    "high arm wave", "horizontal arm wave", "hammer", "hand catch", "forward punch",
    "high throw", "draw x", "draw tick", "draw circle", "hand clap", "two hand wave",
    "side boxing", "bend", "forward kick", "side kick", "jogging", "tennis swing",
    "tennis serve", "golf swing", "pick up and throw"), start=1))


def normalize_marker_name(name: str) -> str:
    """Canonical form of a marker name: lower case, runs of spaces/hyphens/underscores -> ``_``.

    ``"Left Shoulder"``, ``"left-shoulder"`` and ``"left_shoulder"`` all give
    ``"left_shoulder"`` (formats.md).
    """
    if not isinstance(name, str):
        raise DataFormatError(f"A marker name must be a string; got {name!r}.")
    return re.sub(r"[\s\-_]+", "_", name.strip().lower())


# --------------------------------------------------------------------------- types


def _as_float_array(values: Any, what: str, where: str) -> np.ndarray:
    """``values`` as a float array, or :class:`DataError` if they are not real numbers."""
    if np.iscomplexobj(values):
        raise DataError(f"{what} must be real numbers; got complex values{where}.")
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{what} must be an array of numbers; got a {type(values).__name__} that does not convert "
                        f"to one ({exc}){where}.") from exc


#: The policies of :class:`MotionRecording` for non-finite positions or orientations.
_ON_MISSING: tuple[str, ...] = ("raise", "interpolate", "drop")


def _check_frame_rate(frame_rate: object) -> float:
    """``frame_rate`` as a float, or :class:`ParameterError` unless it is a finite number > 0."""
    if (isinstance(frame_rate, bool) or not isinstance(frame_rate, (int, float, np.integer, np.floating))
            or not (np.isfinite(frame_rate) and frame_rate > 0)):
        raise ParameterError(f"frame_rate must be a finite number of frames per second > 0 (Kinect: 30, MSR "
                             f"Action3D: 15); got {frame_rate!r}.")
    return float(frame_rate)


def _nonfinite(values: np.ndarray, names: Sequence[str], what: str) -> str | None:
    """Where ``values`` (n_frames, n_markers, k) are not finite, in words naming the first frame and
    joint; None if all are."""
    bad = ~np.isfinite(values)
    if not bad.any():
        return None
    t, j = (int(i) for i in np.argwhere(bad)[0][:2])
    return (f"{what} hold {int(bad.sum())} non-finite value(s) in {int(bad.any(axis=(1, 2)).sum())} frame(s); the "
            f"first at frame {t}, joint {names[j]!r} ({', '.join(str(v) for v in values[t, j].tolist())})")


def _interpolate_missing(values: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """``values`` (n_frames, ...) with the entries where ``missing`` (broadcast to its shape) linearly
    interpolated in time from the same column's other frames; before the first and after the last of
    those the nearest value is held (:func:`numpy.interp`). Each column needs one entry not missing.
    The one interpolation of lost motion: :class:`MotionRecording` (per coordinate) and the MSR
    Action3D loader (whole frames) both use it."""
    flat = values.reshape(len(values), -1).copy()
    miss = np.broadcast_to(missing, values.shape).reshape(len(values), -1)
    t = np.arange(len(values))
    for j in np.flatnonzero(miss.any(axis=0)):
        m = miss[:, j]
        flat[m, j] = np.interp(t[m], t[~m], flat[~m, j])
    return flat.reshape(values.shape)


def _slerp_missing(Q: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Quaternions ``Q`` (n_frames, n_markers, 4) with the frames where ``missing`` (n_frames, n_markers)
    filled per marker by spherical linear interpolation between the nearest present frames
    (:class:`scipy.spatial.transform.Slerp`), the nearest present one held at the ends. Zero
    quaternions are no rotation: they are kept, and never interpolated from."""
    out = Q.copy()
    t = np.arange(len(Q), dtype=float)
    for j in np.flatnonzero(missing.any(axis=0)):
        m = missing[:, j]
        q = Q[~m, j]
        scale = np.abs(q).max(axis=1)
        anchor = np.flatnonzero(~m)[scale > 0]
        q = q[scale > 0] / scale[scale > 0, None]  # exact rotations; no overflow in the norm
        if len(anchor) == 1:
            out[m, j] = Rotation.from_quat(q[0]).as_quat()
        else:
            slerp = Slerp(t[anchor], Rotation.from_quat(q))
            out[m, j] = slerp(np.clip(t[m], t[anchor[0]], t[anchor[-1]])).as_quat()
    return out


@dataclass(eq=False)
class MotionRecording:
    """One recorded demonstration: marker positions over time and its labels.

    Parameters
    ----------
    positions : ndarray of shape (n_frames, n_markers, 3)
        Marker positions (metres, camera frame for Kinect data), at least one frame. NaN
        or infinite values mark a joint whose tracking was lost: see ``on_missing``.
    marker_names : sequence of str, length n_markers
        Names as found in the file; look-ups use :func:`normalize_marker_name`.
    labels : tuple of int
        Label ids (gesture ids of Table B.2 for Choreo1, 0..9 for Choreo2, action id for MSR).
    orientations : ndarray of shape (n_frames, n_markers, 4), optional
        Unit quaternions (qx, qy, qz, qw) of each marker's frame (Choreo2). A quaternion
        with a NaN or infinite component is missing, as a position is.
    frame_rate : float
        Frames per second, finite and > 0.
    source : str
        File the record came from (used in error messages).
    record_id : str
        Record key inside that file.
    on_missing : {"raise", "interpolate", "drop"}, default="raise"
        What to do with non-finite positions or orientations (not stored):
        ``"raise"``: a :class:`DataError` names the first frame and joint (and the file);
        ``"interpolate"``: each missing coordinate is linearly interpolated in time between
        the nearest frames where that joint's coordinate is finite, and the nearest finite
        value is held before the first and after the last (orientations: spherical linear
        interpolation, ``scipy.spatial.transform.Slerp``); the frames and the time axis stay
        as they are, so delayed velocities keep their meaning. A joint with no finite value
        in any frame is a :class:`DataError`;
        ``"drop"``: every frame holding a non-finite value is left out (the time axis then
        has gaps); a :class:`DataError` if no frame is left.

    Raises
    ------
    DataError
        Positions or orientations that are not arrays of numbers of the right shape, labels
        that are not integers, non-finite values with ``on_missing="raise"``.
    ParameterError
        A frame rate that is not a finite number > 0, an unknown ``on_missing``.
    """

    positions: np.ndarray
    marker_names: tuple[str, ...]
    labels: tuple[int, ...] = ()
    orientations: np.ndarray | None = None
    frame_rate: float = 30.0
    source: str = ""
    record_id: str = ""
    on_missing: InitVar[str] = "raise"
    _index: dict[str, int] = field(default_factory=dict, repr=False)

    def __post_init__(self, on_missing: str) -> None:
        if not (isinstance(on_missing, str) and on_missing in _ON_MISSING):
            raise ParameterError(f"on_missing must be one of {list(_ON_MISSING)}; got {on_missing!r}.")
        self.frame_rate = _check_frame_rate(self.frame_rate)
        where = self._where()
        self.positions = _as_float_array(self.positions, "positions", where)
        if isinstance(self.marker_names, str) or not isinstance(self.marker_names, Iterable):
            raise DataError(f"marker_names must be a sequence of names, one per marker; got {self.marker_names!r}"
                            f"{where}.")
        self.marker_names = tuple(self.marker_names)
        labels = tuple(self.labels) if isinstance(self.labels, Iterable) and not isinstance(self.labels, str) else None
        if labels is None or not all(isinstance(x, numbers.Integral) and not isinstance(x, bool) for x in labels):
            raise DataError(f"labels must be a sequence of integer label ids; got {self.labels!r}{where}.")
        self.labels = tuple(int(x) for x in labels)
        if self.positions.ndim != 3 or self.positions.shape[2] != 3 or self.positions.shape[0] == 0:
            raise DataError(f"positions must have shape (n_frames, n_markers, 3) with at least one frame; got "
                            f"{self.positions.shape}{where}.")
        if self.positions.shape[1] != len(self.marker_names):
            raise DataError(
                f"{len(self.marker_names)} marker names for {self.positions.shape[1]} markers in the "
                f"positions array{where}."
            )
        if self.orientations is not None:
            self.orientations = _as_float_array(self.orientations, "orientations", where)
            if self.orientations.shape != self.positions.shape[:2] + (4,):
                raise DataError(
                    f"orientations must have shape {self.positions.shape[:2] + (4,)}; got "
                    f"{self.orientations.shape}{where}."
                )
        self._index = {}
        for i, n in enumerate(self.marker_names):
            self._index.setdefault(normalize_marker_name(n), i)
        self._handle_missing(on_missing, where)

    def _handle_missing(self, on_missing: str, where: str) -> None:
        """Apply ``on_missing`` to non-finite positions and orientations (see the class docstring)."""
        P, Q, names = self.positions, self.orientations, self.marker_names
        lost_p = ~np.isfinite(P)
        lost_q = np.zeros(P.shape[:2], dtype=bool) if Q is None else ~np.isfinite(Q).all(axis=2)
        if not lost_p.any() and not lost_q.any():
            return
        if on_missing == "raise":
            found = [_nonfinite(P, names, "positions"), None if Q is None else _nonfinite(Q, names, "orientations")]
            raise DataError(
                f"{'; '.join(m for m in found if m)}{where}. Expected finite values: pass on_missing='interpolate' "
                "(fill lost joints linearly in time) or on_missing='drop' (leave those frames out), or leave lost "
                "frames out before building the recording."
            )
        if on_missing == "drop":
            keep = ~lost_p.any(axis=(1, 2)) & ~lost_q.any(axis=1)
            if not keep.any():
                raise DataError(f"Every one of the {len(keep)} frame(s) holds a non-finite position or orientation"
                                f"{where}; on_missing='drop' would leave nothing. Expected at least one frame "
                                "where every joint is tracked.")
            self.positions = P[keep]
            self.orientations = None if Q is None else Q[keep]
            return
        never = lost_p.all(axis=0).any(axis=1)  # a coordinate of the joint is lost in every frame
        if Q is not None:  # lost somewhere, and no finite nonzero quaternion anywhere to interpolate from
            anchors = ~lost_q & (np.abs(np.nan_to_num(Q)).max(axis=2) > 0)
            never |= lost_q.any(axis=0) & ~anchors.any(axis=0)
        if never.any():
            j = int(np.flatnonzero(never)[0])
            raise DataError(
                f"Joint {names[j]!r} has no finite value in any of the {self.n_frames} frame(s) (a coordinate of "
                f"its position, or its orientation){where}: there is nothing to interpolate from. Expected each "
                "joint tracked in at least one frame: leave that joint out of the recording."
            )
        self.positions = _interpolate_missing(P, lost_p)
        if Q is not None and lost_q.any():
            self.orientations = _slerp_missing(Q, lost_q)

    def _where(self) -> str:
        parts = []
        if self.source:
            parts.append(f"file {self.source}")
        if self.record_id != "":
            parts.append(f"record {self.record_id}")
        return (" (" + ", ".join(parts) + ")") if parts else ""

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self.positions.shape[0])

    @property
    def duration(self) -> float:
        """Length in seconds: ``n_frames / frame_rate``."""
        return self.n_frames / self.frame_rate

    def has_marker(self, name: str) -> bool:
        """Whether a marker is present (names matched as in :func:`normalize_marker_name`)."""
        return normalize_marker_name(name) in self._index

    def marker_index(self, name: str) -> int:
        """Column of a marker; :class:`DataError` naming the marker and the file if absent."""
        key = normalize_marker_name(name)
        if key not in self._index:
            raise DataError(
                f"Marker {name!r} is needed but missing{self._where()}; the recording has markers "
                f"{list(self.marker_names)}."
            )
        return self._index[key]

    def marker(self, name: str) -> np.ndarray:
        """Positions of one marker, shape (n_frames, 3)."""
        return self.positions[:, self.marker_index(name), :]

    def orientation(self, name: str) -> np.ndarray:
        """Quaternions (qx, qy, qz, qw) of one marker, shape (n_frames, 4)."""
        if self.orientations is None:
            raise DataError(f"The recording has no orientations{self._where()}; only Choreo2-style data has them.")
        return self.orientations[:, self.marker_index(name), :]


@dataclass(frozen=True)
class SkippedRecord:
    """A record that ``on_error="skip"`` left out, and why."""

    source: str
    record_id: str
    reason: str

    @property
    def file(self) -> str:
        """The file at fault (the same as ``source``; the name the audio and image loaders' ``SkippedFile`` use)."""
        return self.source


@dataclass(eq=False)
class MotionDataset:
    """A list of :class:`MotionRecording` with the names of their labels.

    Parameters
    ----------
    recordings : list of MotionRecording
    label_names : mapping int -> str
        Description of every label id that may occur.
    name : str
    skipped : list of SkippedRecord
        Records that could not be read with ``on_error="skip"`` (empty otherwise).
    """

    recordings: list[MotionRecording]
    label_names: dict[int, str]
    name: str = ""
    skipped: list[SkippedRecord] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.recordings)

    def __getitem__(self, i: int) -> MotionRecording:
        return self.recordings[i]

    def __iter__(self):
        return iter(self.recordings)

    @property
    def labels(self) -> list[tuple[int, ...]]:
        """Label ids of each recording."""
        return [r.labels for r in self.recordings]

    @property
    def label_ids(self) -> list[int]:
        """Sorted label ids of ``label_names``."""
        return sorted(self.label_names)

    def label_matrix(self, label_ids: Sequence[int] | None = None) -> np.ndarray:
        """Binary label matrix, shape (n_recordings, n_labels) (Thesis section 3.3.1, y_i).

        Column j is ``label_ids[j]`` (default :attr:`label_ids`).
        """
        ids = list(self.label_ids if label_ids is None else label_ids)
        col = {l: j for j, l in enumerate(ids)}
        Y = np.zeros((len(self.recordings), len(ids)))
        for i, r in enumerate(self.recordings):
            for l in r.labels:
                if l not in col:
                    raise DataError(f"Label {l} of recording {i} is not among label_ids {ids}.")
                Y[i, col[l]] = 1.0
        return Y

    def subset(self, indices: Iterable[int]) -> MotionDataset:
        """A dataset holding the recordings at ``indices`` (same labels)."""
        return MotionDataset([self.recordings[i] for i in indices], dict(self.label_names), self.name)


# --------------------------------------------------------------------------- helpers


def _check_on_error(on_error: str) -> None:
    if on_error not in ("raise", "skip"):
        raise ParameterError(f"on_error must be 'raise' or 'skip'; got {on_error!r}.")


def _read_json(path: Path) -> dict:
    try:
        with open(path, encoding="utf-8") as f:
            meta = json.load(f)
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataFormatError(f"Cannot read {path}: not valid JSON ({exc}).") from exc
    except RecursionError as exc:  # nesting deeper than Python's recursion limit: no index is that deep
        raise DataFormatError(f"Cannot read {path}: JSON nested too deeply to be a data index.") from exc
    if not isinstance(meta, dict):
        raise DataFormatError(f"{path} must hold a JSON object; got {type(meta).__name__}.")
    return meta


def _require(meta: Mapping, key: str, path: Path, hint: str = "") -> object:
    if key not in meta:
        alt = key.replace("-", "_") if "-" in key else key.replace("_", "-")
        extra = f" (found {alt!r}: is this the other Choreo format?)" if alt in meta else ""
        raise DataFormatError(f"{path} has no {key!r} entry{extra}{hint}; keys present: {sorted(meta)}.")
    return meta[key]


def _open_npz(path: Path):
    try:
        return np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataFormatError(f"Cannot read {path}: not a valid NPZ archive ({exc}).") from exc


def _write_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)  # type: ignore[arg-type]  # savez takes arrays as keyword arguments


def write_json(path: Path, obj: object) -> None:
    """Write ``obj`` as indented JSON to ``path``, atomically (:func:`mmconcepts._io.atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(obj, f, indent=1)


def _load_records(
    json_path: Path,
    records: object,
    npz,
    npz_path: Path,
    *,
    id_key: str,
    n_values: int,
    marker_names: tuple[str, ...],
    frame_rate: float,
    on_error: str,
    skipped: list[SkippedRecord],
) -> list[MotionRecording]:
    out = []
    if not isinstance(records, list):
        raise DataFormatError(f"{json_path}: 'records' must be a list; got {type(records).__name__}.")
    for k, rec in enumerate(records):
        rid = str(rec.get(id_key, f"#{k}")) if isinstance(rec, dict) else f"#{k}"
        source = json_path  # the record's entry in the index is checked first, then its array
        try:
            if not isinstance(rec, dict) or id_key not in rec or "labels" not in rec:
                raise DataFormatError(
                    f"{json_path}: record #{k} must be an object with {id_key!r} and 'labels'; got {rec!r}."
                )
            labels = rec["labels"]
            if not isinstance(labels, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in labels):
                raise DataFormatError(f"{json_path}: record {rid} has labels {labels!r}; expected a list of ints.")
            source = npz_path
            try:
                arr = npz[rid]
            except KeyError:
                raise DataFormatError(
                    f"{npz_path}: no array for record {rid} (key {rid!r}) listed in {json_path}."
                ) from None
            except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib_error) as exc:
                raise DataFormatError(f"{npz_path}: record {rid} is corrupt ({type(exc).__name__}: {exc}).") from exc
            if arr.ndim != 3 or arr.shape[1:] != (len(marker_names), n_values):
                raise DataFormatError(
                    f"{npz_path}: record {rid} has shape {arr.shape}; expected (T, {len(marker_names)}, {n_values}) "
                    f"({len(marker_names)} marker names in {json_path.name})."
                )
            if arr.shape[0] == 0 or arr.dtype.kind not in "iuf":
                raise DataFormatError(f"{npz_path}: record {rid} is empty or not an array of real numbers "
                                      f"(dtype {arr.dtype}).")
            arr = arr.astype(float)
            lost = _nonfinite(arr[..., :3], marker_names, "positions") or _nonfinite(arr[..., 3:], marker_names,
                                                                                   "orientations")
            if lost:
                raise DataFormatError(f"{npz_path}: record {rid}: {lost}. Expected finite values: leave frames where "
                                      "tracking was lost out, or interpolate them, before saving.")
            out.append(MotionRecording(
                positions=arr[..., :3], marker_names=marker_names, labels=tuple(labels),
                orientations=arr[..., 3:7] if n_values == 7 else None, frame_rate=frame_rate,
                source=str(npz_path), record_id=rid,
            ))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedRecord(str(source), rid, str(exc)))
    return out


try:  # zlib errors from compressed NPZ members
    from zlib import error as zlib_error
except ImportError:  # pragma: no cover
    zlib_error = OSError  # type: ignore[misc, assignment]


def _warn_skipped(skipped: list[SkippedRecord], what: str) -> None:
    for k in skipped:  # each record in the log, as the audio loaders do; one warning for them all
        logging.getLogger(__name__).warning("skipped %s (record %s): %s", k.file, k.record_id, k.reason)
    if skipped:
        warnings.warn(
            f"{len(skipped)} record(s) of {what} could not be read and were skipped "
            f"(see dataset.skipped): first: {skipped[0].reason}",
            RuntimeWarning,
            stacklevel=3,
        )


# --------------------------------------------------------------------------- Choreo1


def load_choreo1(
    path: str | os.PathLike[str],
    *,
    on_error: str = "raise",
    frame_rate: float = 30.0,
) -> MotionDataset:
    """Load a Choreo1 subset (``<subset>.json`` + NPZ), Thesis Appendix B.2.

    Parameters
    ----------
    path : path-like
        The subset's JSON file (``primitive.json``, ``mixed_partial.json``, ...), or a
        folder holding exactly one such JSON file.
    on_error : {"raise", "skip"}
        ``"raise"``: a corrupt or unreadable record raises :class:`DataFormatError` naming
        the file and record. ``"skip"``: such records are left out, listed in
        ``dataset.skipped``, and a :class:`RuntimeWarning` says how many.
    frame_rate : float, default=30
        Frame rate to attach (not stored in the files; OpenNI streams at 30 Hz).

    Returns
    -------
    MotionDataset
        Positions (T, n_markers, 3); labels are Table B.2 gesture ids.
    """
    json_path, _, recs, skipped = _load_choreo(path, "Choreo1", "-", n_values=3, on_error=on_error,
                                               frame_rate=frame_rate)
    _warn_skipped(skipped, str(json_path))
    return MotionDataset(recs, dict(CHOREO1_GESTURES), name=json_path.stem, skipped=skipped)


def _load_choreo(path: str | os.PathLike[str], what: str, sep: str, *, n_values: int, on_error: str,
                 frame_rate: float, check_meta: Callable[[Mapping, Path], object] | None = None,
                 ) -> tuple[Path, dict, list[MotionRecording], list[SkippedRecord]]:
    """What :func:`load_choreo1` and :func:`load_choreo2` share: the JSON index, its NPZ, the records.

    The two formats differ in the spelling of the index's keys (``sep``: ``"-"`` in Choreo1,
    ``marker-names``, ``data-file``, ``data-id``; ``"_"`` in Choreo2) and in the values per
    marker (``n_values``: 3 positions, or 7 with an orientation quaternion).
    ``check_meta(meta, json_path)``, when given, checks the format's other entries before
    the NPZ is opened. Returns the JSON path, its content, the records read and the skipped.
    """
    _check_on_error(on_error)
    frame_rate = _check_frame_rate(frame_rate)
    json_path = _resolve_json(Path(path), what)
    meta = _read_json(json_path)
    names_key = f"marker{sep}names"
    names = _require(meta, names_key, json_path)
    data_file = _require(meta, f"data{sep}file", json_path)
    records = _require(meta, "records", json_path)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise DataFormatError(f"{json_path}: {names_key!r} must be a list of strings.")
    if check_meta is not None:
        check_meta(meta, json_path)
    if not isinstance(data_file, str) or not data_file or Path(data_file).name != data_file:
        raise DataFormatError(
            f"{json_path}: {f'data{sep}file'!r} must be the name of the NPZ file beside it; got {data_file!r}."
        )
    npz_path = json_path.parent / data_file
    if not npz_path.is_file():
        raise DataFormatError(f"{json_path} names the data file {data_file!r}, which is missing ({npz_path}).")
    npz = _open_npz(npz_path)
    skipped: list[SkippedRecord] = []
    with npz:
        recs = _load_records(json_path, records, npz, npz_path, id_key=f"data{sep}id", n_values=n_values,
                             marker_names=tuple(names), frame_rate=frame_rate, on_error=on_error,
                             skipped=skipped)
    return json_path, meta, recs, skipped


def _resolve_json(path: Path, what: str) -> Path:
    if path.is_dir():
        cands = sorted(p for p in path.glob("*.json") if not p.name.startswith("_"))
        if len(cands) != 1:
            raise DataFormatError(
                f"{path} is a folder with {len(cands)} JSON files ({[c.name for c in cands]}); give the "
                f"{what} JSON file itself."
            )
        return cands[0]
    if not path.exists():
        raise FileNotFoundError(f"{what} file not found: {path}")
    return path


def save_choreo1(dataset: MotionDataset | Sequence[MotionRecording], folder: str | os.PathLike[str],
                 subset: str) -> Path:
    """Write recordings in the Choreo1 layout: ``<folder>/<subset>.json`` + ``<subset>.npz``.

    All recordings must share the same marker names (the first one's are written).
    The NPZ is written before the JSON, each atomically. Returns the JSON path.
    """
    recs = list(dataset)
    if not recs:
        raise DataError("Nothing to write: the dataset is empty.")
    names = recs[0].marker_names
    folder = Path(folder)
    arrays = {}
    records = []
    for i, r in enumerate(recs):
        if r.marker_names != names:
            raise DataError(f"Recording {i} has markers {r.marker_names}, the first one {names}.")
        arrays[str(i)] = r.positions.astype(np.float64)
        records.append({"data-id": i, "labels": [int(x) for x in r.labels]})
    _write_npz(folder / f"{subset}.npz", arrays)
    meta = {"marker-names": list(names), "data-file": f"{subset}.npz", "records": records}
    write_json(folder / f"{subset}.json", meta)
    return folder / f"{subset}.json"


def load_choreo1_text(
    path: str | os.PathLike[str],
    *,
    marker_names: Sequence[str] = CHOREO1_MARKERS,
    labels: Sequence[int] = (),
    frame_rate: float = 30.0,
) -> MotionRecording:
    """Load one record in the Choreo1 text layout: one frame per line, ``3 * n_markers`` floats.

    Parameters
    ----------
    path : path-like
    marker_names : sequence of str, default=CHOREO1_MARKERS
        Marker order of the columns (x, y, z of marker 0, then marker 1, ...).
    labels : sequence of int
    frame_rate : float

    Raises
    ------
    DataFormatError
        If a line does not hold ``3 * len(marker_names)`` numbers (file and line named).
    """
    frame_rate = _check_frame_rate(frame_rate)
    path = Path(path)
    n = 3 * len(marker_names)
    rows = []
    try:
        with open(path, encoding="utf-8") as f:
            for lineno, line in enumerate(f, 1):
                if not line.strip():
                    continue
                try:
                    vals = [float(v) for v in line.split()]
                except ValueError as exc:
                    raise DataFormatError(f"{path}, line {lineno}: not a number ({exc}).") from exc
                if len(vals) != n:
                    raise DataFormatError(
                        f"{path}, line {lineno}: {len(vals)} values, expected {n} (= 3 x {len(marker_names)} markers)."
                    )
                rows.append(vals)
    except UnicodeDecodeError as exc:
        raise DataFormatError(f"{path}: not a text file ({exc}).") from exc
    if not rows:
        raise DataFormatError(f"{path}: no frames.")
    arr = np.asarray(rows).reshape(len(rows), len(marker_names), 3)
    lost = _nonfinite(arr, tuple(marker_names), "positions")
    if lost:
        raise DataFormatError(f"{path}: {lost} (frame k is the k-th line of numbers). Expected finite values: leave "
                              "frames where tracking was lost out, or interpolate them.")
    return MotionRecording(arr, tuple(marker_names), tuple(labels), frame_rate=frame_rate, source=str(path))


def save_choreo1_text(recording: MotionRecording, path: str | os.PathLike[str]) -> None:
    """Write one recording in the Choreo1 text layout (``%.18e``, one frame per line)."""
    flat = recording.positions.reshape(recording.n_frames, -1)
    with atomic_path(Path(path)) as tmp:
        np.savetxt(str(tmp), flat, fmt="%.18e")


# --------------------------------------------------------------------------- Choreo2


def load_choreo2(
    path: str | os.PathLike[str],
    *,
    on_error: str = "raise",
    frame_rate: float = 30.0,
) -> MotionDataset:
    """Load Choreo2 (``choreo2.json`` + NPZ of (T, 15, 7) arrays), Thesis Appendix B.3.

    Parameters
    ----------
    path : path-like
        ``choreo2.json`` or the folder holding it.
    on_error : {"raise", "skip"}
        As in :func:`load_choreo1`.
    frame_rate : float, default=30

    Returns
    -------
    MotionDataset
        Positions and orientations (qx, qy, qz, qw); label ids 0..9 named by
        ``label_descriptions``.
    """
    json_path, meta, recs, skipped = _load_choreo(path, "Choreo2", "_", n_values=7, on_error=on_error,
                                                  frame_rate=frame_rate, check_meta=_choreo2_descriptions)
    _warn_skipped(skipped, str(json_path))
    descr = _choreo2_descriptions(meta, json_path)
    return MotionDataset(recs, dict(enumerate(descr)), name=str(meta.get("name", json_path.stem)), skipped=skipped)


def _choreo2_descriptions(meta: Mapping, json_path: Path) -> list[str]:
    """The gesture names of a Choreo2 index (its ``label_descriptions``, else Table B.3's)."""
    descr = meta.get("label_descriptions")
    if descr is None:
        descr = list(CHOREO2_GESTURES)
    if not isinstance(descr, list) or not all(isinstance(d, str) for d in descr):
        raise DataFormatError(f"{json_path}: 'label_descriptions' must be a list of strings.")
    return descr


def save_choreo2(dataset: MotionDataset | Sequence[MotionRecording], folder: str | os.PathLike[str], *,
                 name: str = "choreo2", label_descriptions: Sequence[str] = CHOREO2_GESTURES,
                 dtype: type = np.float64) -> Path:
    """Write recordings with orientations in the Choreo2 layout (``choreo2.json`` + ``choreo2.npz``).

    ``dtype`` of the stored arrays (float32 halves the file; the loader returns float64).
    """
    recs = list(dataset)
    if not recs:
        raise DataError("Nothing to write: the dataset is empty.")
    names = recs[0].marker_names
    folder = Path(folder)
    arrays: dict[str, np.ndarray] = {}
    records = []
    for i, r in enumerate(recs):
        if r.orientations is None:
            raise DataError(f"Recording {i} has no orientations; Choreo2 stores 7 values per marker.")
        if r.marker_names != names:
            raise DataError(f"Recording {i} has markers {r.marker_names}, the first one {names}.")
        arrays[str(i)] = np.concatenate([r.positions, r.orientations], axis=2).astype(dtype)
        records.append({"data_id": i, "labels": [int(x) for x in r.labels]})
    _write_npz(folder / "choreo2.npz", arrays)
    meta = {"name": name, "marker_names": list(names), "label_descriptions": list(label_descriptions),
            "data_file": "choreo2.npz", "records": records}
    write_json(folder / "choreo2.json", meta)
    return folder / "choreo2.json"


# --------------------------------------------------------------------------- MSR Action3D

_MSR_RE = re.compile(r"a(\d\d)_s(\d\d)_e(\d\d)_skeleton3D\.txt$")


def parse_msr_name(name: str) -> tuple[int, int, int] | None:
    """``(action, subject, episode)`` of an MSR Action3D skeleton file ``aAA_sSS_eEE_skeleton3D.txt``, else None.

    The one definition of an MSR Action3D recording's name: :func:`load_msr_action3d` reads
    the files it matches, and the data-set registry (:mod:`mmconcepts.datasets`) recognises
    MSR Action3D folders by it.

    Examples
    --------
    >>> parse_msr_name("a03_s07_e02_skeleton3D.txt")
    (3, 7, 2)
    >>> parse_msr_name("a03_s07_e02_sdepth.bin") is None
    True
    """
    m = _MSR_RE.search(name)
    return None if m is None else (int(m.group(1)), int(m.group(2)), int(m.group(3)))


def _fill_lost_frames(P: np.ndarray, lost: np.ndarray, mode: str) -> np.ndarray:
    """Drop leading/trailing lost frames; interpolate (or drop) interior ones."""
    good = np.flatnonzero(~lost)
    P = P[good[0]: good[-1] + 1]
    lost = lost[good[0]: good[-1] + 1]
    if not lost.any():
        return P
    if mode == "drop":
        return P[~lost]
    return _interpolate_missing(P, lost[:, None, None])


def load_msr_action3d(
    folder: str | os.PathLike[str],
    *,
    actions: Iterable[int] | None = None,
    subjects: Iterable[int] | None = None,
    lost_frames: str = "interpolate",
    on_error: str = "raise",
    frame_rate: float = 15.0,
) -> MotionDataset:
    """Load MSR Action3D skeletons (real-world coordinates, 20 Kinect v1 joints).

    Parameters
    ----------
    folder : path-like
        Folder of ``aAA_sSS_eEE_skeleton3D.txt`` files.
    actions, subjects : iterable of int, optional
        Keep only these action ids (1..20) / subject ids (1..10).
    lost_frames : {"interpolate", "drop"}
        Frames where tracking was lost (every joint exactly zero; 373 frames in 19 of the
        567 files) are removed at the start and end of a sequence; inside a sequence
        they are linearly interpolated between the neighbouring tracked frames
        (``"interpolate"``, keeps the time axis regular for delayed velocities) or removed
        (``"drop"``). A file with no tracked frame at all (``a13_s09_e02``) holds no
        motion: it is left out and listed in ``dataset.skipped`` whatever ``on_error``.
    on_error : {"raise", "skip"}
        As in :func:`load_choreo1`.
    frame_rate : float, default=15
        The dataset was recorded at 15 frames per second.

    Returns
    -------
    MotionDataset
        Marker names :data:`MSR_JOINTS`; one label per recording, the action id; each
        recording's ``record_id`` is the file stem (``a01_s01_e01``).
    """
    _check_on_error(on_error)
    if lost_frames not in ("interpolate", "drop"):
        raise ParameterError(f"lost_frames must be 'interpolate' or 'drop'; got {lost_frames!r}.")
    frame_rate = _check_frame_rate(frame_rate)
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"MSR Action3D folder not found: {folder}")
    acts = None if actions is None else {int(a) for a in actions}
    subs = None if subjects is None else {int(s) for s in subjects}
    recs: list[MotionRecording] = []
    skipped: list[SkippedRecord] = []
    files = sorted(p for p in folder.iterdir() if parse_msr_name(p.name) is not None)
    if not files:
        raise DataFormatError(f"{folder} holds no aAA_sSS_eEE_skeleton3D.txt file.")
    for p in files:
        parsed = parse_msr_name(p.name)
        assert parsed is not None  # the files were selected by this name
        a, s, _e = parsed
        if (acts is not None and a not in acts) or (subs is not None and s not in subs):
            continue
        rid = p.name.split("_skeleton3D")[0]
        try:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    arr = np.loadtxt(p, ndmin=2)
            except ValueError as exc:
                raise DataFormatError(f"{p}: not a table of numbers ({exc}).") from exc
            except OSError as exc:  # a folder or a dangling link named like a data file, an unreadable file
                raise DataFormatError(f"{p}: cannot be read as a skeleton file ({exc.strerror or exc}).") from exc
            if arr.shape[1] != 4 or arr.shape[0] == 0 or arr.shape[0] % 20:
                raise DataFormatError(
                    f"{p}: {arr.shape[0]} lines of {arr.shape[1]} values; expected 20 lines of "
                    "'x y z confidence' per frame."
                )
            P = arr.reshape(-1, 20, 4)[..., :3]
            nonfinite = _nonfinite(P, MSR_JOINTS, "positions")
            if nonfinite:
                t, j = np.argwhere(~np.isfinite(P))[0][:2]
                raise DataFormatError(f"{p}, line {20 * int(t) + int(j) + 1}: {nonfinite}. Expected finite numbers (a "
                                      "frame where tracking was lost has every joint at 0 0 0).")
            lost = np.all(P == 0, axis=(1, 2))
            if lost.all():  # no motion at all (a13_s09_e02): left out, listed in skipped
                skipped.append(SkippedRecord(str(p), rid, f"{p}: tracking lost in every frame (all joints zero)."))
                continue
            P = _fill_lost_frames(P, lost, lost_frames)
            recs.append(MotionRecording(P, MSR_JOINTS, (a,), frame_rate=frame_rate, source=str(p), record_id=rid))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedRecord(str(p), rid, str(exc)))
    _warn_skipped([k for k in skipped if "tracking lost in every frame" not in k.reason], str(folder))
    return MotionDataset(recs, dict(MSR_ACTIONS), name="msr-action3d", skipped=skipped)


# --------------------------------------------------------------------------- generic CSV layout

#: Name of the label table of the generic motion layout.
MOTION_LABELS_FILE = "labels.csv"

_AXES = ("x", "y", "z")


def _csv_joints(header: list[str], path: Path) -> list[str]:
    """Joint names, in order of first appearance, from a header of ``<joint>_x,<joint>_y,<joint>_z`` columns.

    Every column must be such a column, every joint must have all three, once each.
    """
    where = f"{path}, line 1 (header)"
    if not header or header == [""]:
        raise DataFormatError(f"{where}: no header; the first line must name the columns <joint>_x,<joint>_y,"
                              "<joint>_z of every joint.")
    joints: list[str] = []
    seen: dict[str, set[str]] = {}
    for col in header:
        joint, sep, axis = col.rpartition("_")
        if not sep or not joint or axis.lower() not in _AXES:
            raise DataFormatError(f"{where}: column {col!r} is not <joint>_x, <joint>_y or <joint>_z; every column "
                                  "must be one coordinate of one joint.")
        key = normalize_marker_name(joint)
        if key not in seen:
            seen[key] = set()
            joints.append(joint)
        if axis.lower() in seen[key]:
            raise DataFormatError(f"{where}: column {col!r} appears twice.")
        seen[key].add(axis.lower())
    incomplete = [j for j in joints if seen[normalize_marker_name(j)] != set(_AXES)]
    if incomplete:
        j = incomplete[0]
        missing = [a for a in _AXES if a not in seen[normalize_marker_name(j)]]
        raise DataFormatError(f"{where}: joint {j!r} lacks column(s) {[f'{j}_{a}' for a in missing]}; every joint "
                              "needs its x, y and z.")
    return joints


def _read_motion_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """Joint names and positions (n_frames, n_joints, 3) of one recording file of the generic layout."""
    import csv

    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFormatError(f"Cannot read motion file {path}: {exc}.") from exc
    if not rows:
        raise DataFormatError(f"Motion file {path} is empty; it needs a header and one row per frame.")
    header = [h.strip() for h in rows[0]]
    joints = _csv_joints(header, path)
    index = {}
    for c, col in enumerate(header):
        joint, _, axis = col.rpartition("_")
        index[c] = (joints.index(next(j for j in joints if normalize_marker_name(j) == normalize_marker_name(joint))),
                    _AXES.index(axis.lower()))
    frames = []
    for line, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue  # a blank line (a trailing newline, a spreadsheet's empty row)
        if len(row) != len(header):
            raise DataFormatError(f"{path}, line {line}: {len(row)} values for {len(header)} columns.")
        frame = np.empty((len(joints), 3))
        for c, cell in enumerate(row):
            try:
                value = float(cell)
            except ValueError:
                raise DataFormatError(f"{path}, line {line}, column {header[c]!r}: {cell.strip()!r} is not a "
                                      "number.") from None
            if not np.isfinite(value):
                raise DataFormatError(f"{path}, line {line}, column {header[c]!r}: {cell.strip()!r}; positions "
                                      "must be finite (leave lost frames out, or interpolate them).")
            frame[index[c]] = value
        frames.append(frame)
    if not frames:
        raise DataFormatError(f"Motion file {path} has a header but no frame.")
    return joints, np.stack(frames)


def _motion_label_ids(names: Iterable[str]) -> dict[str, int]:
    """Label name -> id: the integer itself when every name is an integer, else the rank in sorted order."""
    names = sorted(set(names))
    try:
        ids = {n: int(n) for n in names}
    except ValueError:
        return {n: i for i, n in enumerate(names)}
    if len(set(ids.values())) != len(ids):  # "1" and "01": not one id per name
        return {n: i for i, n in enumerate(names)}
    return ids


def load_motion_folder(
    root: str | os.PathLike[str],
    *,
    joints: Sequence[str] | None = None,
    frame_rate: float = 30.0,
    on_error: str = "raise",
    name: str | None = None,
) -> MotionDataset:
    """Load a folder in the generic motion layout: one CSV file per recording, and ``labels.csv``.

    Each recording file has a header naming its columns ``<joint>_x,<joint>_y,<joint>_z`` for
    every joint (joint names as in :func:`normalize_marker_name`: ``left_hand_x``,
    ``Left Hand_x``...; the joint is what comes before the last ``_``) and one row per frame
    of positions (metres, any fixed frame of reference). ``labels.csv`` has the columns
    ``file`` (relative to ``root``) and ``labels`` (one label, or several separated by ``;``);
    other columns are ignored, and only the files it lists are read. A column ``label`` (the
    old spelling of ``labels``) is still read, with a :class:`FutureWarning`.

    Parameters
    ----------
    root : path-like
        The folder holding ``labels.csv``.
    joints : sequence of str, optional
        The joints every recording must have, in the order of the loaded arrays (for
        instance :data:`MSR_JOINTS`, so that the recordings feed the features of MSR
        Action3D skeletons); other joints in a file are dropped. Default: the joints of the
        first recording read, in its column order; every other recording must have the
        same joints (in any column order).
    frame_rate : float, default=30
        Frames per second of every recording.
    on_error : {"raise", "skip"}
        ``"raise"``: a bad row of ``labels.csv``, a missing file, or a recording file that
        cannot be read (missing joints, ragged rows, text or NaN among the numbers) raises
        :class:`~mmconcepts.errors.DataFormatError` naming the file and the line.
        ``"skip"``: those recordings are left out and listed in ``dataset.skipped``; a
        :class:`RuntimeWarning` says how many.
    name : str, optional
        Data set name (default: the folder's name).

    Returns
    -------
    MotionDataset
        Recordings in the order of ``labels.csv``, ``positions`` of shape
        (n_frames, n_joints, 3), ``record_id`` the file name without ``.csv``. Labels are
        integer ids: the labels themselves when every label is an integer, else their
        ranks in sorted order; ``label_names`` maps each id to the label as written.
    """
    from .._io import read_labels_csv, split_labels

    _check_on_error(on_error)
    frame_rate = _check_frame_rate(frame_rate)
    want = None if joints is None else list(joints)
    if want is not None and (not want or not all(isinstance(j, str) for j in want)
                             or len({normalize_marker_name(j) for j in want}) != len(want)):
        raise ParameterError(f"joints must be a non-empty sequence of distinct joint names; got {joints!r}.")
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Motion folder not found: {root}")
    labels_path = root / MOTION_LABELS_FILE
    if not labels_path.is_file():
        raise DataFormatError(f"{root} has no {MOTION_LABELS_FILE}; the generic motion layout needs one with columns "
                              "file,labels and one CSV file per recording.")
    _, rows = read_labels_csv(labels_path, layout="generic motion", on_error=on_error)
    read: list[tuple[str, tuple[str, ...], str, np.ndarray, str]] = []  # file, labels, record id, positions, where
    skipped: list[SkippedRecord] = []
    names: list[str] | None = want
    for line, row in rows:
        where = f"{labels_path}, line {line}"
        rel = row.get("file", "")
        try:
            if not rel:
                raise DataFormatError(f"{where}: empty 'file' cell.")
            labels = split_labels(row.get("labels", ""))
            if not labels:
                raise DataFormatError(f"{where}: no label for {rel!r}.")
            path = root / rel
            if not path.is_file():
                raise DataFormatError(f"Motion file {path} not found ({where}).")
            file_joints, P = _read_motion_csv(path)
            have = {normalize_marker_name(j): k for k, j in enumerate(file_joints)}
            if names is None:
                names = file_joints
            lacking = [j for j in names if normalize_marker_name(j) not in have]
            extra = [j for j in file_joints if want is None and normalize_marker_name(j) not in
                     {normalize_marker_name(n) for n in names}]
            if lacking or extra:
                raise DataFormatError(
                    f"{path}, line 1 (header): "
                    + (f"joint(s) {lacking} missing" if lacking else f"joint(s) {extra} not in the other recordings")
                    + f"; {'the joints asked for' if want is not None else 'the first recording has'} {list(names)}."
                )
            P = P[:, [have[normalize_marker_name(j)] for j in names], :]
            read.append((rel, labels, Path(rel).with_suffix("").as_posix(), P, where))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedRecord(str(root / rel), Path(rel).with_suffix("").as_posix() if rel else "",
                                         str(exc)))
    ids = _motion_label_ids(l for _, labels, _, _, _ in read for l in labels)
    recs = [MotionRecording(P, tuple(names or ()), tuple(ids[l] for l in labels), frame_rate=frame_rate,
                            source=str(root / rel), record_id=rid)
            for rel, labels, rid, P, _ in read]
    _warn_skipped(skipped, str(root))
    return MotionDataset(recs, {i: n for n, i in ids.items()}, name=name if name is not None else root.name,
                         skipped=skipped)


def save_motion_folder(dataset: MotionDataset | Sequence[MotionRecording], root: str | os.PathLike[str], *,
                       label_names: Mapping[int, str] | None = None) -> Path:
    """Write recordings in the generic motion layout (:func:`load_motion_folder`): CSV files and ``labels.csv``.

    Each recording goes to ``<record_id>.csv`` (``rec<i>.csv`` when it has no id, or ids
    repeat), positions written with 17 significant digits so that loading gives back the
    same floats. Labels are written by name (``label_names``, default the data set's) or
    as their integer ids, several separated by ``;``. Each file is written atomically.
    Returns the path of ``labels.csv``.

    Raises
    ------
    DataError
        If there is no recording, a recording has no label, or a label name holds ``;``.
    """
    import csv

    recs = list(dataset)
    if not recs:
        raise DataError("Nothing to write: the dataset is empty.")
    if label_names is None and isinstance(dataset, MotionDataset):
        label_names = dataset.label_names
    names = dict(label_names or {})
    root = Path(root)
    ids = [r.record_id for r in recs]
    safe = all(i and Path(i).name == i and not i.startswith(".") for i in ids) and len(set(ids)) == len(ids)
    rows = []
    for i, r in enumerate(recs):
        if not r.labels:
            raise DataError(f"Recording {i}{r._where()} has no label; the generic motion layout needs one.")
        labels = [names.get(l, str(l)) for l in r.labels]
        if any(LABEL_SEPARATOR in l for l in labels):
            raise DataError(f"Labels of recording {i} contain {LABEL_SEPARATOR!r}, the label separator: {labels}.")
        fname = f"{r.record_id if safe else f'rec{i}'}.csv"
        header = [f"{m}_{a}" for m in r.marker_names for a in _AXES]
        with atomic_path(root / fname) as tmp, open(tmp, "w", encoding="utf-8", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            w.writerows([[f"{v:.17g}" for v in frame.ravel()] for frame in r.positions])
        rows.append([fname, LABEL_SEPARATOR.join(labels)])
    with atomic_path(root / MOTION_LABELS_FILE) as tmp, open(tmp, "w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(LABELS_HEADER)
        w.writerows(rows)
    return root / MOTION_LABELS_FILE
