"""The concept explorer of a run: one card per learnt concept, with what a person can listen to and look at.

An experiment may return with its numbers an :class:`Explorer`: a few :class:`ConceptCard`, one
per concept its learner found, each with the labels the concept aligns with (and their shares)
and the examples that express it most, as audio clips (:class:`AudioClip`), thumbnails
(:class:`Thumbnail`) and motions (:class:`MotionClip`). The engine knows nothing of what the
concepts are: it checks the bounds below, writes the media beside the record's figures
(:func:`mmconcepts.engine.media.write_explorer`) and lists them, with relative paths, in the
record's ``explorer`` entry; the report plays and shows them. Bounds, so that a results folder
stays small: :data:`MAX_CARDS` cards, :data:`MAX_MEDIA` clips, thumbnails and motions per card,
clips of :data:`MAX_CLIP_SECONDS`, thumbnails of :data:`MAX_THUMBNAIL` pixels a side, motions
of :data:`MAX_MOTION_FRAMES` frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ExperimentError

__all__ = ["MAX_CARDS", "MAX_MEDIA", "MAX_CLIP_SECONDS", "MAX_THUMBNAIL", "MAX_MOTION_FRAMES", "AudioClip",
           "Thumbnail", "MotionClip", "ConceptCard", "Explorer"]

#: At most this many cards per run.
MAX_CARDS = 6
#: At most this many clips, thumbnails and motions per card (each).
MAX_MEDIA = 3
#: The longest clip (seconds).
MAX_CLIP_SECONDS = 2.0
#: The longest side of a thumbnail (pixels).
MAX_THUMBNAIL = 96
#: The most frames of a motion.
MAX_MOTION_FRAMES = 40


def _fail(what: str, expected: str, got: str, fix: str) -> ExperimentError:
    return ExperimentError(f"{what}: expected {expected}; got {got}. Fix: {fix}.")


def _caption(value: object, what: str) -> str:
    if not isinstance(value, str):
        raise _fail(what, "a caption string", repr(value)[:60], "give the caption as text")
    return value


@dataclass(frozen=True)
class AudioClip:
    """A short mono sound: what an example of a concept sounds like.

    Parameters
    ----------
    samples : ndarray of shape (n_samples,)
        Float samples in [-1, 1] (clipped there when written), at most
        :data:`MAX_CLIP_SECONDS` long.
    sample_rate : int
        Samples per second.
    caption : str, default=""
    """

    samples: np.ndarray
    sample_rate: int
    caption: str = ""

    def __post_init__(self) -> None:
        x = np.asarray(self.samples, dtype=np.float64)
        sr = self.sample_rate
        if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or not 1000 <= sr <= 192_000:
            raise _fail("AudioClip.sample_rate", "an int between 1000 and 192000 (Hz)", repr(sr), "give the rate in Hz")
        if x.ndim != 1 or x.size == 0 or not np.isfinite(x).all():
            raise _fail("AudioClip.samples", "a non-empty 1-D array of finite floats",
                        f"shape {x.shape}" + ("" if np.isfinite(x).all() else " with NaN or infinite values"),
                        "give one channel of finite samples")
        if x.size > MAX_CLIP_SECONDS * sr:
            raise _fail("AudioClip.samples", f"at most {MAX_CLIP_SECONDS:g} s", f"{x.size / sr:.2f} s",
                        "cut the clip around what it should let a person hear")
        object.__setattr__(self, "samples", x)
        object.__setattr__(self, "sample_rate", int(sr))
        object.__setattr__(self, "caption", _caption(self.caption, "AudioClip.caption"))

    @property
    def seconds(self) -> float:
        """The clip's duration (s)."""
        return self.samples.size / self.sample_rate


@dataclass(frozen=True)
class Thumbnail:
    """A small image: what an example of a concept looks like.

    Parameters
    ----------
    pixels : ndarray of uint8, shape (height, width) or (height, width, 3 or 4)
        Grey levels, RGB or RGBA, at most :data:`MAX_THUMBNAIL` pixels a side
        (:meth:`from_image` makes one of any image).
    caption : str, default=""
    """

    pixels: np.ndarray
    caption: str = ""

    def __post_init__(self) -> None:
        p = np.asarray(self.pixels)
        if p.dtype != np.uint8 or p.ndim not in (2, 3) or (p.ndim == 3 and p.shape[2] not in (3, 4)) or 0 in p.shape:
            raise _fail("Thumbnail.pixels", "a uint8 array of shape (h, w), (h, w, 3) or (h, w, 4)",
                        f"{p.dtype} of shape {p.shape}", "build it with Thumbnail.from_image(image)")
        if max(p.shape[:2]) > MAX_THUMBNAIL:
            raise _fail("Thumbnail.pixels", f"at most {MAX_THUMBNAIL} pixels a side", f"{p.shape[1]} x {p.shape[0]}",
                        "build it with Thumbnail.from_image(image), which shrinks it")
        object.__setattr__(self, "pixels", p)
        object.__setattr__(self, "caption", _caption(self.caption, "Thumbnail.caption"))

    @classmethod
    def from_image(cls, image: Any, caption: str = "", *, size: int = MAX_THUMBNAIL) -> Thumbnail:
        """A thumbnail of ``image`` (uint8, or floats in [0, 1]; grey, RGB or RGBA), shrunk to ``size`` a side.

        The aspect ratio is kept; Pillow's Lanczos filter shrinks it (an image already small
        enough is kept as it is).
        """
        from PIL import Image

        p = np.asarray(image)
        if p.dtype != np.uint8:
            p = np.asarray(p, dtype=np.float64)
            if p.size and not (np.isfinite(p).all() and p.min() >= 0.0 and p.max() <= 1.0):
                raise _fail("Thumbnail.from_image", "uint8 levels or floats in [0, 1]", f"{p.dtype} values",
                            "scale the image to [0, 1]")
            p = np.round(p * 255).astype(np.uint8)
        if p.ndim == 3 and p.shape[2] == 1:
            p = p[:, :, 0]
        size = min(int(size), MAX_THUMBNAIL)
        if p.ndim in (2, 3) and max(p.shape[:2], default=0) > size:
            im = Image.fromarray(p)
            im.thumbnail((size, size), Image.Resampling.LANCZOS)
            p = np.asarray(im)
        return cls(p, caption)


@dataclass(frozen=True)
class MotionClip:
    """A short motion: a stick figure moving, or angle curves under a moving cursor.

    Give ``positions`` (with ``bones``) or ``curves``.

    Parameters
    ----------
    positions : ndarray of shape (n_frames, n_joints, 2 or 3), optional
        Joint positions; drawn in their first two coordinates, the second pointing up (a
        front view of a skeleton whose y axis is vertical). NaN hides a joint in a frame.
    bones : sequence of (int, int), default=()
        The joints each bone links (indices into the joints).
    curves : ndarray of shape (n_frames, n_curves), optional
        Values over time (joint angles): drawn as curves, a cursor moving along them.
    frame_rate : float, default=15.0
        Frames per second.
    caption : str, default=""

    At most :data:`MAX_MOTION_FRAMES` frames (keep every n-th frame and divide the frame
    rate by n to shorten one).
    """

    positions: np.ndarray | None = None
    bones: tuple[tuple[int, int], ...] = ()
    curves: np.ndarray | None = None
    frame_rate: float = 15.0
    caption: str = ""

    def __post_init__(self) -> None:
        if (self.positions is None) == (self.curves is None):
            raise _fail("MotionClip", "positions or curves (one of them)", "both" if self.positions is not None
                        else "neither", "give joint positions (with bones) or curves")
        if self.positions is not None:
            x = np.asarray(self.positions, dtype=np.float64)
            if x.ndim != 3 or x.shape[2] not in (2, 3) or x.shape[1] < 2 or not np.isfinite(x).any(axis=(1, 2)).all():
                raise _fail("MotionClip.positions", "shape (n_frames, n_joints >= 2, 2 or 3), a finite joint in "
                            "every frame", f"shape {x.shape}", "give the positions of a skeleton's joints")
            bones = tuple((int(a), int(b)) for a, b in self.bones)
            if not bones or any(not (0 <= a < x.shape[1] and 0 <= b < x.shape[1]) for a, b in bones):
                raise _fail("MotionClip.bones", f"pairs of joint indices in [0, {x.shape[1]})", repr(self.bones)[:80],
                            "link the joints the positions hold")
            object.__setattr__(self, "positions", x)
            object.__setattr__(self, "bones", bones)
        else:
            x = np.asarray(self.curves, dtype=np.float64)
            if x.ndim != 2 or x.shape[0] < 2 or x.shape[1] < 1 or not np.isfinite(x).all():
                raise _fail("MotionClip.curves", "shape (n_frames >= 2, n_curves) of finite values",
                            f"shape {x.shape}", "give one column per curve")
            object.__setattr__(self, "curves", x)
        if x.shape[0] > MAX_MOTION_FRAMES:
            raise _fail("MotionClip", f"at most {MAX_MOTION_FRAMES} frames", f"{x.shape[0]}",
                        "keep every n-th frame and divide the frame rate by n")
        rate = self.frame_rate
        if isinstance(rate, bool) or not isinstance(rate, (int, float, np.number)) or not 0 < float(rate) <= 1000:
            raise _fail("MotionClip.frame_rate", "a positive number of frames per second", repr(rate), "give it")
        object.__setattr__(self, "frame_rate", float(rate))
        object.__setattr__(self, "caption", _caption(self.caption, "MotionClip.caption"))

    @property
    def n_frames(self) -> int:
        data = self.positions if self.positions is not None else self.curves
        assert data is not None
        return int(data.shape[0])

    @property
    def seconds(self) -> float:
        """How long one loop of the animation lasts (s)."""
        return self.n_frames / self.frame_rate


def _media(values: Sequence[Any], kind: type, what: str) -> tuple[Any, ...]:
    values = tuple(values)
    if len(values) > MAX_MEDIA or not all(isinstance(v, kind) for v in values):
        raise _fail(f"ConceptCard.{what}", f"at most {MAX_MEDIA} {kind.__name__} objects",
                    f"{len(values)} of types {sorted({type(v).__name__ for v in values})}",
                    f"give the {MAX_MEDIA} examples that express the concept most")
    return values


@dataclass(frozen=True)
class ConceptCard:
    """One learnt concept: the labels it aligns with and the examples that express it most.

    Parameters
    ----------
    title : str
        E.g. ``"atom 7"``.
    labels : sequence of (str, float)
        The labels the concept aligns with and the share of its activation on each, largest
        first (:func:`mmconcepts.multimodal.atom_label_association`).
    clips, images, motions : sequences of AudioClip, Thumbnail, MotionClip
        At most :data:`MAX_MEDIA` of each.
    note : str, default=""
    """

    title: str
    labels: tuple[tuple[str, float], ...] = ()
    clips: tuple[AudioClip, ...] = ()
    images: tuple[Thumbnail, ...] = ()
    motions: tuple[MotionClip, ...] = ()
    note: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.title, str) or not self.title.strip():
            raise _fail("ConceptCard.title", "a non-empty string", repr(self.title)[:60], "name the concept")
        try:
            labels = tuple((str(lab), float(share)) for lab, share in self.labels)
        except (TypeError, ValueError):
            raise _fail("ConceptCard.labels", "(label, share) pairs", repr(self.labels)[:80],
                        "give each label with its share of the concept's activation") from None
        if any(not 0.0 <= s <= 1.0 for _, s in labels):
            raise _fail("ConceptCard.labels", "shares in [0, 1]", repr(labels)[:80], "give shares of the activation")
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "clips", _media(self.clips, AudioClip, "clips"))
        object.__setattr__(self, "images", _media(self.images, Thumbnail, "images"))
        object.__setattr__(self, "motions", _media(self.motions, MotionClip, "motions"))
        object.__setattr__(self, "note", _caption(self.note, "ConceptCard.note"))


@dataclass(frozen=True)
class Explorer:
    """The cards of a run's learnt concepts, and what they were read from.

    Parameters
    ----------
    cards : sequence of ConceptCard
        At most :data:`MAX_CARDS`.
    note : str, default=""
        Which learner, trained on which examples (shown above the cards).
    """

    cards: tuple[ConceptCard, ...] = field(default_factory=tuple)
    note: str = ""

    def __post_init__(self) -> None:
        cards = tuple(self.cards)
        if len(cards) > MAX_CARDS or not all(isinstance(c, ConceptCard) for c in cards):
            raise _fail("Explorer.cards", f"at most {MAX_CARDS} ConceptCard objects",
                        f"{len(cards)} of types {sorted({type(c).__name__ for c in cards})}",
                        "show the concepts that carry most of the data")
        object.__setattr__(self, "cards", cards)
        object.__setattr__(self, "note", _caption(self.note, "Explorer.note"))
