"""The bones of the skeletons mmconcepts reads: which markers a stick figure joins.

:data:`SKELETON_CHAINS` lists kinematic chains over the marker names of Choreo1 (OpenNI's
24 markers), Choreo2 (15 frames) and MSR Action3D (20 Kinect joints); :func:`skeleton_bones`
turns them into the bones of a given skeleton. Used by the figures of :mod:`mmconcepts.plot`
and the stick figures of the report's concept explorer.
"""

from __future__ import annotations

from collections.abc import Sequence

from .data import normalize_marker_name

__all__ = ["SKELETON_CHAINS", "skeleton_bones"]

#: Kinematic chains of the skeletons mmconcepts reads (OpenNI's 24 markers of Choreo1, the 15 frames of
#: Choreo2, the 20 joints of MSR Action3D): :func:`skeleton_bones` joins the consecutive markers of a chain
#: that a recording has. An entry that is a tuple names alternatives: the first one present is used
#: (the pelvis is ``hip_center`` in MSR Action3D, ``waist`` or else ``torso`` in OpenNI). ``{s}`` is
#: ``left`` and ``right``.
SKELETON_CHAINS: tuple[tuple[str | tuple[str, ...], ...], ...] = (
    ("head", "neck", "spine", "torso", "waist", "hip_center"),
    *(("neck", f"{s}_collar", f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist", f"{s}_hand", f"{s}_fingertip")
      for s in ("left", "right")),
    *((("hip_center", "waist", "torso"), f"{s}_hip", f"{s}_knee", f"{s}_ankle", f"{s}_foot")
      for s in ("left", "right")),
)


def skeleton_bones(marker_names: Sequence[str],
                   chains: Sequence[Sequence[str | tuple[str, ...]]] = SKELETON_CHAINS) -> list[tuple[int, int]]:
    """The bones of a skeleton: pairs of marker indices, joined along kinematic chains.

    Parameters
    ----------
    marker_names : sequence of str
        The markers of the skeleton (names matched as in
        :func:`~mmconcepts.motion.normalize_marker_name`).
    chains : sequence of sequences of str or tuple of str, default=SKELETON_CHAINS
        Each chain's markers in order; a tuple names alternatives (the first present is used).
        Markers the skeleton lacks are skipped: their neighbours are joined.

    Returns
    -------
    list of (int, int)
        Each bone once, as indices into ``marker_names``.

    Examples
    --------
    >>> skeleton_bones(["head", "neck", "left_shoulder", "left_hand"])
    [(0, 1), (1, 2), (2, 3)]
    """
    index: dict[str, int] = {}
    for i, name in enumerate(marker_names):
        index.setdefault(normalize_marker_name(name), i)
    bones: list[tuple[int, int]] = []
    for chain in chains:
        present = []
        for entry in chain:
            alternatives = (entry,) if isinstance(entry, str) else entry
            found = [index[k] for k in map(normalize_marker_name, alternatives) if k in index]
            if found:
                present.append(found[0])
        for a, b in zip(present, present[1:]):
            if a != b and (a, b) not in bones and (b, a) not in bones:
                bones.append((a, b))
    return bones
