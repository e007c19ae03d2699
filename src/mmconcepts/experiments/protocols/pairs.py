"""The sound-motion pairs of chapters 6 and 7: one speaker's utterances and gestures paired by concept.

Thesis sections 6.5-6.6. Each modality comes from a real set when it is in ``ctx.data``,
else from its generated stand-in:

- sound: the utterances of one speaker (the first by name; the thesis uses speaker 1; every
  utterance of every speaker of the user's own ``audio`` recordings), one keyword each (:mod:`mmconcepts.experiments.protocols.speech`): ``fsdd``, ``acorns`` or
  ``audio``, else the generated Caregiver-like corpus;
- motion: one gesture per record: ten MSR Action3D actions (``msr-action3d``, positions
  only, turned into joint angles by :func:`mmconcepts.motion.joint_angles`) or
  Choreo2 (``choreo2``); else generated choreographies.

:func:`load_pairs` pairs each utterance with a gesture of the same concept (a random
keyword-gesture bijection, :func:`gesture_mapping`), within the parts of its fold when the
recordings are split into parts (:func:`pair_within_parts`), and records the source
recordings behind every example (:func:`example_sources`) so that
:func:`fold_split_groups` / :func:`part_split_groups` can check with
:func:`~mmconcepts.engine.describe_split` that no recording behind a test example is
behind a training example. The notes (:func:`data_source_note`, :data:`KEYWORDS_NOTE`)
say in the record which data a run used and how the thesis' ambiguities were read.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Sequence
from pathlib import Path

import numpy as np

from ...engine import RunContext, Streams, concept_parts, describe_split, fill_thesis_numbers
from ...errors import DataError
from ...motion import MotionRecording, joint_angles, load_choreo2, load_msr_action3d, orientation_angles
from ...sound.features import MFCCConfig
from .speech import chapter6_utterances, corpus_mfcc

__all__ = ["SPEECH_SETS", "MOTION_SETS", "MSR_ACTIONS", "THESIS_CHANCE", "KEYWORDS_NOTE", "load_speech",
           "load_motion", "speech_note", "motion_note", "data_source_note", "example_sources", "part_split_groups",
           "fold_split_groups", "gesture_mapping", "load_pairs", "pair_within_parts"]

SPEECH_SETS = ("acorns", "fsdd", "audio")


MOTION_SETS = ("choreo2", "msr-action3d")


#: The ten MSR Action3D actions used as gestures (arms, both arms, legs, whole body:
#: 1 high arm wave, 2 horizontal arm wave, 5 forward punch, 6 high throw, 10 hand clap,
#: 12 side boxing, 13 bend, 14 forward kick, 15 side kick, 16 jogging).
MSR_ACTIONS = (1, 2, 5, 6, 10, 12, 13, 14, 15, 16)


# ---------------------------------------------------------------------------- the thesis' Tables 6.2-6.4
#: "baseline random is in that case 0.11" (Tables 6.2 and 6.3; footnote 6: the keywords are not exactly uniform).
THESIS_CHANCE = 0.11


#: The thesis' "13 or 10 keywords" ambiguity and the reading taken (in every chapter-6 experiment's notes).
KEYWORDS_NOTE = fill_thesis_numbers(
    "Thesis ambiguity, 13 or 10 keywords: the Caregiver corpus is described with 13 keywords (sections 5.2 and "
    "B.1), chapter 6 with 10 (section 6.5.2: '1000 utterances containing 10 keywords'; Table 6.1 lists ten; "
    "'we consider 10 semantic classes'). Reading taken: 10 concepts, so chance is 0.1 (the thesis' baseline "
    "{thesis:chance} comes from its non-uniform keyword counts, footnote 6); the generated corpus uses the ten "
    "keywords of Table 6.1, FSDD its ten digit words, and a real corpus the keywords of its first speaker's "
    "utterances.", {"chance": THESIS_CHANCE})


# ---------------------------------------------------------------------------- data
def _speech_name(ctx: RunContext) -> str | None:
    return next((n for n in SPEECH_SETS if ctx.has_dataset(n)), None)


#: The data stream's draw that subsamples a real speaker's utterances (:func:`load_speech`).
SPEECH_SUBSAMPLE = 1
#: The splits stream's draws in :func:`load_pairs`: the utterances' folds, the motion records' folds.
SOUND_FOLDS, MOTION_FOLDS = 0, 1


def load_speech(ctx: RunContext, *, n_per_speaker: int, streams: Streams) -> dict:
    """Utterances of the first speaker (every utterance of ``audio``): MFCC sequences, concepts, keyword spans,
    recording ids (their files).

    A real corpus' speaker (``fsdd``, ``acorns``) with more than ``n_per_speaker`` utterances is subsampled to that
    many, stratified by keyword (draw :data:`SPEECH_SUBSAMPLE` of the data stream); the generated corpus has
    exactly ``n_per_speaker`` per speaker; the user's own recordings (``audio``) are used whole, every speaker
    (:func:`~mmconcepts.experiments.protocols.speech.chapter6_utterances`).
    """
    sub, first, keywords, y = chapter6_utterances(ctx, n_per_speaker=n_per_speaker)
    n_all = len(y)
    if _speech_name(ctx) not in (None, "audio") and len(y) > n_per_speaker:
        rng = streams.rng("data", SPEECH_SUBSAMPLE)  # apart from the pairing's draws
        per = max(1, n_per_speaker // len(keywords))
        keep = np.sort(np.concatenate([rng.permutation(np.flatnonzero(y == c))[:per] for c in range(len(keywords))]))
        sub, y = sub.subset(keep), y[keep]
    mfccs = corpus_mfcc(ctx, sub, MFCCConfig(n_mfcc=22))
    return {"corpus": sub, "speaker": first, "keywords": keywords, "y": y, "mfcc": mfccs,
            "spans": sub.keyword_spans(), "n_available": n_all, "ids": [str(u.path) for u in sub],
            "durations": np.array([len(m) * MFCCConfig(n_mfcc=22).hop_ms / 1000 for m in mfccs])}


def load_motion(ctx: RunContext, *, n_motion: int) -> dict:
    """Motion records (one gesture each): angle trajectories, gesture ids, record ids, and the skeletons (marker
    positions as float32, marker names, frame rates) the concept explorer draws."""
    if ctx.has_dataset("choreo2"):
        path = Path(ctx.dataset("choreo2"))
        ds = load_choreo2(path if path.suffix == ".json" else path / "choreo2.json", on_error="skip")
        fn: Callable[[MotionRecording], np.ndarray] = orientation_angles
    elif ctx.has_dataset("msr-action3d"):
        ds, fn = load_msr_action3d(ctx.dataset("msr-action3d"), actions=MSR_ACTIONS, on_error="skip"), joint_angles
    else:
        from ...motion.synthetic import make_choreo2

        ds = make_choreo2(data_home=ctx.cache_dir, random_state=0, n_records=n_motion, verbose=ctx.verbose)
        fn = orientation_angles
    gestures, angles, ids, positions = [], [], [], []
    for rec in ds:
        if len(rec.labels) != 1:
            raise DataError(f"motion record {rec.record_id} has {len(rec.labels)} gestures; chapter 6 needs one each.")
        gestures.append(int(rec.labels[0]))
        angles.append(np.ascontiguousarray(fn(rec), dtype=np.float64))
        ids.append(str(rec.record_id))
        positions.append(rec.positions.astype(np.float32))
    return {"angles": angles, "gesture": np.asarray(gestures), "ids": ids,
            "skipped": [str(s) for s in getattr(ds, "skipped", [])], "positions": positions,
            "markers": [rec.marker_names for rec in ds], "frame_rates": [float(rec.frame_rate) for rec in ds]}


def speech_note(ctx: RunContext, speech: dict | None = None) -> str:
    name = _speech_name(ctx)
    size = ""
    if speech is not None:
        size = (f" ({len(speech['y'])} of the {speech['n_available']} utterances of speaker {speech['speaker']}, "
                f"{len(speech['keywords'])} words)")
    if name == "fsdd":
        return (f"Sound: real spoken digits of the Free Spoken Digit Dataset (FSDD, {ctx.dataset('fsdd')}){size}, one "
                "word said alone per recording, 8 kHz resampled to 16 kHz.")
    if name is not None:
        return f"Sound: real recordings ({name}, {ctx.dataset(name)}){size}."
    return f"Sound: the synthetic Caregiver-like corpus (offline text-to-speech, keyword sentences){size}."


def motion_note(ctx: RunContext, motion: dict | None = None) -> str:
    size = ""
    if motion is not None:
        size = f" ({len(motion['angles'])} records of {len(set(motion['gesture'].tolist()))} gestures)"
    if ctx.has_dataset("choreo2"):
        return f"Motion: real Choreo2 records from {ctx.dataset('choreo2')}{size}."
    if ctx.has_dataset("msr-action3d"):
        return (f"Motion: real Kinect skeletons of MSR Action3D ({ctx.dataset('msr-action3d')}), actions "
                f"{MSR_ACTIONS}{size}, 16 joint angles of the limb model.")
    return f"Motion: the synthetic Choreo2-like set (mmconcepts.motion.synthetic.make_choreo2){size}."


def data_source_note(ctx: RunContext, speech: dict | None = None, motion: dict | None = None) -> str:
    return speech_note(ctx, speech) + " " + motion_note(ctx, motion)


def pair_within_parts(y: np.ndarray, part_y: np.ndarray, item_concept: np.ndarray, part_item: np.ndarray,
                      rng: np.random.Generator, what: str = "item") -> np.ndarray:
    """For each example (concept ``y``, part ``part_y``), an item of the same concept and part.

    Items are drawn without replacement while possible (then the pool is dealt again).
    """
    y, part_y = np.asarray(y), np.asarray(part_y)
    out = np.empty(len(y), dtype=np.int64)
    for c in np.unique(y):
        for p in np.unique(part_y[y == c]):
            want = np.flatnonzero((y == c) & (part_y == p))
            pool = np.flatnonzero((item_concept == c) & (part_item == p))
            if pool.size == 0:
                raise DataError(f"no {what} of concept {c} in part {p}: too few {what}s for this split.")
            reps = int(np.ceil(want.size / pool.size))
            out[want] = np.concatenate([rng.permutation(pool) for _ in range(reps)])[: want.size]
    return out


def example_sources(**ids_of: Sequence[Hashable]) -> list[frozenset]:
    """The recordings behind each example: one id per modality, prefixed with the modality's name.

    ``example_sources(sound=["a.wav", "b.wav"], motion=["m1", "m1"])`` is
    ``[{"sound:a.wav", "motion:m1"}, {"sound:b.wav", "motion:m1"}]``: the sources
    :func:`~mmconcepts.engine.splits.describe_split` compares across a split's sides.
    """
    lengths = {name: len(ids) for name, ids in ids_of.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"every modality needs one recording id per example; got {lengths}.")
    columns = [[f"{name}:{i}" for i in ids] for name, ids in ids_of.items()]
    return [frozenset(parts) for parts in zip(*columns)]


def part_split_groups(by: str, repetitions: Sequence[tuple[Sequence[Iterable[Hashable]], np.ndarray]],
                      train_part: int = 0) -> dict:
    """``describe_split`` of repetitions that split examples into parts: the training part against the others.

    ``repetitions`` holds, per repetition, the sources of every example (:func:`example_sources`)
    and its part (``train_part``: training; any other part, test or reference, is held out;
    -1: unused). Raises when a held-out example shares a recording with a training example.
    """
    folds = []
    for sources, part in repetitions:
        part = np.asarray(part)
        folds.append(([sources[int(i)] for i in np.flatnonzero(part == train_part)],
                      [sources[int(i)] for i in np.flatnonzero((part != train_part) & (part >= 0))]))
    return describe_split(by, folds)


def fold_split_groups(data: dict) -> dict:
    """``describe_split`` of the folds of :func:`load_pairs` (test fold against the training folds)."""
    sources = data["sources"]
    return describe_split("sound recordings and motion records (each example: one utterance and one motion record)",
                          [([sources[i] for i in np.flatnonzero(data["fold"] != f)],
                            [sources[i] for i in np.flatnonzero(data["fold"] == f)]) for f in range(data["n_folds"])])


def gesture_mapping(keywords, gestures: np.ndarray, rng: np.random.Generator) -> tuple[dict, np.ndarray]:
    """Random keyword -> gesture bijection and the concept of each motion record (-1: unused gesture)."""
    gesture_ids = sorted(set(np.asarray(gestures).tolist()))
    if len(gesture_ids) < len(keywords):
        raise DataError(f"{len(keywords)} keywords but only {len(gesture_ids)} gestures: cannot map concepts one to one.")
    chosen = rng.permutation(gesture_ids)[: len(keywords)].tolist()
    mapping = {k: int(g) for k, g in zip(keywords, chosen)}
    concept_of_gesture = {g: c for c, g in enumerate(chosen)}
    return mapping, np.array([concept_of_gesture.get(int(g), -1) for g in gestures])


def load_pairs(ctx: RunContext, *, n_per_speaker: int, n_motion: int, streams: Streams, n_folds: int = 1) -> dict:
    """Paired examples: MFCC sequences, joint-angle trajectories, concepts, folds and sources.

    The data stream of ``streams`` draws the bijection and the pairing, its splits
    stream the folds (``n_folds`` = 1: a single part, every example used together). The
    utterances and the motion records are split into folds separately, by concept, and
    paired within their fold, so no recording is behind examples of two folds; ``sources``
    holds each example's recordings (:func:`example_sources`) for :func:`fold_split_groups`.
    """
    from sklearn.model_selection import StratifiedKFold

    rng = streams.rng("data")
    speech = load_speech(ctx, n_per_speaker=n_per_speaker, streams=streams)
    motion = load_motion(ctx, n_motion=n_motion)
    y, keywords = speech["y"], speech["keywords"]
    mapping, item_concept = gesture_mapping(keywords, motion["gesture"], rng)
    if n_folds > 1:
        n_folds = min(n_folds, int(np.bincount(y).min()), int(np.bincount(item_concept[item_concept >= 0]).min()))
        if n_folds < 2:
            raise DataError("a concept has a single utterance or motion record: a cross-validation needs at least "
                            "two of each concept.")
        fold_y = np.empty(len(y), dtype=np.int64)
        skf = StratifiedKFold(n_folds, shuffle=True, random_state=streams.seed_for("splits", SOUND_FOLDS))
        for f, (_, te) in enumerate(skf.split(np.zeros(len(y)), y)):
            fold_y[te] = f
        fold_m = concept_parts(item_concept, n_folds, streams.rng("splits", MOTION_FOLDS))
    else:
        fold_y, fold_m = np.zeros(len(y), dtype=np.int64), np.where(item_concept >= 0, 0, -1)
    motion_idx = pair_within_parts(y, fold_y, item_concept, fold_m, rng, "motion record")
    sound_ids = speech.get("ids") or [f"utterance {i}" for i in range(len(y))]
    sources = example_sources(sound=sound_ids, motion=[motion["ids"][i] for i in motion_idx])
    return {"mfcc": speech["mfcc"], "angles": [motion["angles"][i] for i in motion_idx], "y": y,
            "keywords": keywords, "mapping": mapping, "speaker": speech["speaker"], "fold": fold_y,
            "n_folds": int(fold_y.max()) + 1, "motion_idx": motion_idx, "motion_ids": motion["ids"],
            "n_motion_records": len(motion["angles"]), "speech": speech, "motion": motion, "streams": streams,
            "sources": sources}
