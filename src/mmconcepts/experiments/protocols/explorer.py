"""The concept explorer of the chapter 6 and 7 runs: one card per atom of one learner the run fitted.

A multimodal learner (:class:`~mmconcepts.multimodal.MultimodalNMF`) learns atoms without being
told the concepts; :func:`concept_cards` shows what each atom stands for, from the internal
coefficients ``W`` of the learner's own training examples (no other fit): the labels the atom's
activation falls on (:func:`~mmconcepts.multimodal.atom_label_association`) and the examples it
makes up most (:func:`~mmconcepts.multimodal.top_examples`), as the engine's
:class:`~mmconcepts.engine.Explorer` (clips, thumbnails, a motion), which the runner writes
beside the figures and the report plays.

The experiment says where an example's media come from (callables); the helpers here make them
from recordings: :func:`recording_clip` (an utterance cut to :data:`CLIP_SECONDS` around its
keyword, at :data:`CLIP_RATE`), :func:`stick_figure` (a skeleton's positions, :func:`~mmconcepts.motion.skeleton_bones`),
:func:`angle_curves` (joint angles, where no skeleton is kept), :func:`recordings_explorer` (the
chapter 6 pairs: utterances, and the motion record and object view paired with each).
Building cards draws no random number and changes no number of the run.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...engine import AudioClip, ConceptCard, Explorer, MotionClip, Thumbnail
from ...engine.explorer import MAX_CARDS, MAX_MEDIA, MAX_MOTION_FRAMES
from ...motion import skeleton_bones
from ...multimodal import atom_label_association, top_examples

__all__ = ["CLIP_RATE", "CLIP_SECONDS", "THUMBNAIL", "LABEL_SHARE", "UTTERANCES", "explorer_note", "concept_cards", "card_labels", "cut_clip",
           "recording_clip", "stick_figure", "angle_curves", "recordings_explorer"]

#: The clips' sample rate (Hz): FSDD's own, at which speech stays clear and a clip stays small.
CLIP_RATE = 8000
#: The longest clip (s): a keyword and a little around it (the engine allows up to MAX_CLIP_SECONDS).
CLIP_SECONDS = 1.0
#: The longest side of a thumbnail (pixels).
THUMBNAIL = 64
#: A label is listed beside the one an atom aligns with most when it holds at least this share of the atom.
LABEL_SHARE = 0.05

#: How the clips of utterances are cut, for the explorer's note (:func:`explorer_note`).
UTTERANCES = f"their utterances (at most {CLIP_SECONDS:g} s, around the keyword)"


def explorer_note(learner: str, examples: str, media: str, *, counts: str = "") -> str:
    """What an explorer shows, in words: ``learner`` (which, fitted on what), the kind of ``examples``, their
    ``media``, and how an example ``counts`` for the keywords (when not plainly)."""
    return (f"The atoms of {learner}, read from its coefficients of its training {examples} (it never saw the "
            f"keywords): each card is one atom, the keywords its activation falls on{counts} (share of the atom's "
            f"activation), and the {examples} it makes up most: {media}.")


def card_labels(W: np.ndarray, labels: Sequence[Any]) -> tuple[np.ndarray, list[str]]:
    """The share of each atom's activation on each label, and the labels (as text).

    ``labels[i]`` is example i's label, or a sequence of labels (an example of several
    concepts): such an example counts for each of its labels with an equal part of its
    coefficients (:func:`~mmconcepts.multimodal.atom_label_association` on the examples
    repeated once per label), so that each atom's shares still sum to one.
    """
    W = np.asarray(W, dtype=np.float64)
    sets = [tuple(lab) if isinstance(lab, (list, tuple)) else (lab,) for lab in labels]
    rows = np.repeat(np.arange(len(sets)), [len(s) for s in sets])
    parts = np.repeat([1.0 / len(s) for s in sets], [len(s) for s in sets])
    assoc, names = atom_label_association(W[rows] * parts[:, None], np.array([str(x) for s in sets for x in s]))
    return assoc, [str(n) for n in names]


def concept_cards(W: Any, labels: Sequence[Any], *, note: str,
                  clip: Callable[[int, str], AudioClip | None] | None = None,
                  image: Callable[[int], Thumbnail | None] | None = None,
                  motion: Callable[[int], MotionClip | None] | None = None,
                  n_cards: int = MAX_CARDS, n_examples: int = MAX_MEDIA) -> Explorer:
    """One card per atom: the labels it aligns with and the examples that express it most.

    The atoms that carry most of the activation of the training examples come first (the sum
    of their coefficients), at most ``n_cards`` of them; an atom never active gets no card.

    Parameters
    ----------
    W : array-like of shape (n_examples, n_components)
        The internal coefficients of the learner's training examples (its ``fit_transform``).
    labels : sequence of length n_examples
        Each example's label, or its labels (see :func:`card_labels`).
    note : str
        Which learner, trained on what (shown above the cards).
    clip : callable (example, label) -> AudioClip or None, optional
        The sound of example ``i`` (a row of W), given the label the card's atom aligns with most.
    image : callable (example) -> Thumbnail or None, optional
    motion : callable (example) -> MotionClip or None, optional
        Called for the example the atom expresses most only.
    n_cards, n_examples : int
        How many atoms, and how many examples per atom.

    Returns
    -------
    Explorer
        Card ``atom j``: its labels, largest share first (the first is the argmax of row j of
        the association; the others while their share is at least :data:`LABEL_SHARE`, at most
        three), the clips and thumbnails of its ``n_examples`` top examples, the motion of the
        first.
    """
    W = np.asarray(W, dtype=np.float64)
    assoc, names = card_labels(W, labels)
    top = top_examples(W, min(int(n_examples), W.shape[0]))
    mass = W.sum(axis=0)
    order = [int(j) for j in np.argsort(-mass, kind="stable") if mass[j] > 0][: int(n_cards)]
    cards = []
    for j in order:
        ranked = np.argsort(-assoc[j], kind="stable")
        shown = [int(ranked[0])] + [int(c) for c in ranked[1:3] if assoc[j, c] >= LABEL_SHARE]
        first = names[shown[0]]
        examples = [int(i) for i in top[j]]
        clips = [c for i in examples if clip is not None and (c := clip(i, first)) is not None]
        images = [t for i in examples if image is not None and (t := image(i)) is not None]
        motions = [m for m in ([motion(examples[0])] if motion is not None else []) if m is not None]
        cards.append(ConceptCard(f"atom {j}", tuple((names[c], float(assoc[j, c])) for c in shown), tuple(clips),
                                 tuple(images), tuple(motions),
                                 note=f"{mass[j] / mass.sum():.0%} of the training examples' activation"))
    return Explorer(tuple(cards), note)


def cut_clip(samples: np.ndarray, sample_rate: int, span: Any = None, *, caption: str = "") -> AudioClip:
    """At most :data:`CLIP_SECONDS` of ``samples``, centred on ``span``.

    ``span`` is (start, end) in seconds (NaN or None: from the start); a span longer than the
    clip keeps its beginning.
    """
    x = np.asarray(samples, dtype=np.float64).ravel()
    n = int(CLIP_SECONDS * sample_rate)
    start = 0
    if span is not None and np.isfinite(np.asarray(span, dtype=float)).all() and x.size > n:
        a, b = (float(v) * sample_rate for v in span)
        start = int(np.clip(round((a + b) / 2 - n / 2), 0, x.size - n)) if b - a < n else int(np.clip(a, 0, x.size - n))
    return AudioClip(x[start:start + n], int(sample_rate), caption)


def recording_clip(path: str | Path, *, span: Any = None, caption: str = "") -> AudioClip:
    """A recording at :data:`CLIP_RATE`, cut to :data:`CLIP_SECONDS` around ``span`` (:func:`cut_clip`)."""
    from ...sound.audio import load_audio

    return cut_clip(load_audio(path, sr=CLIP_RATE, min_duration=0.0), CLIP_RATE, span, caption=caption)


def _every(n_frames: int) -> int:
    return -(-n_frames // MAX_MOTION_FRAMES)


def stick_figure(positions: np.ndarray, marker_names: Sequence[str], frame_rate: float, *,
                 caption: str = "") -> MotionClip:
    """A skeleton's motion seen from the front (x right, y up), every n-th frame so that it fits the bound."""
    x = np.asarray(positions, dtype=np.float64)
    step = _every(x.shape[0])
    return MotionClip(positions=x[::step], bones=tuple(skeleton_bones(marker_names)), frame_rate=frame_rate / step,
                      caption=caption)


def angle_curves(angles: np.ndarray, frame_rate: float, *, caption: str = "") -> MotionClip:
    """Joint angles over time as curves (a motion without a skeleton: a collage of limbs), every n-th frame."""
    x = np.asarray(angles, dtype=np.float64)
    step = _every(x.shape[0])
    return MotionClip(curves=x[::step], frame_rate=frame_rate / step, caption=caption)


def recordings_explorer(W: Any, rows: np.ndarray, *, speech: dict, note: str, motion: dict | None = None,
                        motion_of: np.ndarray | None = None, images: Any = None,
                        image_of: np.ndarray | None = None, image_ids: Sequence[str] | None = None) -> Explorer:
    """The cards of a learner trained on utterances (each paired with a motion record, an object view or both).

    Parameters
    ----------
    W : array-like of shape (len(rows), n_components)
        The coefficients of the training examples, in the order of ``rows``.
    rows : ndarray of int
        The utterance behind each training example (an index into ``speech``).
    speech : dict
        :func:`~mmconcepts.experiments.protocols.pairs.load_speech`'s: ``y`` and ``keywords``
        label the examples, ``ids`` (files) and ``spans`` (the keyword's time) give the clips.
    motion, motion_of : dict, ndarray of int, optional
        :func:`~mmconcepts.experiments.protocols.pairs.load_motion`'s (with ``positions``,
        ``markers``, ``frame_rates``) and the record paired with each utterance.
    images, image_of, image_ids : ImageSet, ndarray of int, sequence of str, optional
        The object views, the view paired with each utterance, a name per view.
    note : str
    """
    rows = np.asarray(rows, dtype=np.int64)
    keywords, y = speech["keywords"], np.asarray(speech["y"])
    spans = speech.get("spans")

    def clip(i: int, label: str) -> AudioClip:
        u = int(rows[i])
        path = Path(speech["ids"][u])
        return recording_clip(path, span=None if spans is None else spans[u],
                              caption=f"{keywords[y[u]]}: {path.name}")

    def image(i: int) -> Thumbnail | None:
        if images is None or image_of is None:
            return None
        v = int(image_of[rows[i]])
        return Thumbnail.from_image(images.images[v], "" if image_ids is None else Path(image_ids[v]).name,
                                    size=THUMBNAIL)

    def moving(i: int) -> MotionClip | None:
        if motion is None or motion_of is None or "positions" not in motion:
            return None
        r = int(motion_of[rows[i]])
        return stick_figure(motion["positions"][r], motion["markers"][r], motion["frame_rates"][r],
                            caption=f"gesture {motion['gesture'][r]}: record {motion['ids'][r]}")

    return concept_cards(W, [keywords[c] for c in y[rows]], note=note, clip=clip, image=image, motion=moving)
