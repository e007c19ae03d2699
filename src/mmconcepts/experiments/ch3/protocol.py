"""Shared machinery of the chapter-3 experiments: data, random streams, features, folds, scores.

Thesis section 3.3. What the experiments have in common:

- :func:`subset_arrays` gives the joint-angle trajectories (16 angles per frame), the label
  matrix and a description of one of the three Choreo1 subsets (``primitive``,
  ``mixed_partial``, ``mixed_full``) from whichever data the run was given, in this order:
  ``choreo1`` (the thesis' recordings, ``DIR/<subset>.json``), ``msr-action3d`` (real Kinect
  skeletons; the subsets are built from them, see :func:`msr_subset`), else the synthetic
  dancer (:func:`mmconcepts.motion.synthetic.make_choreo1`, generated in the run's cache).
  The experiments only see arrays, so the protocol and the metric names are the same on
  every data set.
- :func:`streams`: the independent random streams of an experiment (data, learner
  initialisation, splits, reference draws) drawn from its seed (:class:`~mmconcepts.engine.Streams`):
  the seed that drew the data never reaches a learner.
- Splits, grouped by source recording (no recording behind a test example feeds a training
  example): :func:`example_splits` gives a protocol's (train, test) folds for a data set,
  :func:`split_groups` checks and describes them for the record. Examples that are each
  their own recording (Choreo1 demonstrations, synthetic draws, MSR single sequences) use
  :func:`kfold_splits` (k-fold or leave-one-out, thesis section 3.3.1) and
  :func:`unseen_combination_splits` (test folds made only of label combinations absent from
  their training folds, thesis Table 3.3: whole combinations held out together). The MSR
  limb mixtures reuse their source recordings (a leg recording is spliced into about five
  mixtures), so they are built per *part*: the recordings are dealt into parts first
  (:func:`source_parts`, from the splits stream) and each part's mixtures are made of its
  own recordings only (:func:`msr_mixture_plan`); the folds are the parts
  (:func:`part_splits`), and for unseen combinations each fold's training set also leaves
  out the mixtures whose combination its test part shows.
- :func:`evaluate_folds` runs one fold per task through ``ctx.parallel``: histograms
  (grids / codebooks) are fitted on the fold's training recordings only, then each learner
  is fitted on the training examples and scores the test examples. Results are cached on
  disk, one entry per learner and fold written as the learner ends (the disk cache of
  :meth:`RunContext.memory <mmconcepts.engine.context.RunContext.memory>` under
  ``ctx.cache_dir/ch3-folds``), under a hash of everything they depend on (data, split,
  features, learner and its parameters, seed, :func:`~mmconcepts._fingerprint.code_fingerprint`),
  so experiments sharing a protocol (Table 3.2, Fig. 3.7, Fig. 3.8) fit each fold once, an
  interrupted run resumes from the fits it finished, and a change of code recomputes. A
  fold's seed depends on what it leaves out (:func:`fold_seeds`): leave-one-out and
  leave-one-combination-out share the folds that leave out one example alone (a
  combination shown by one example only), fitted once for both (Tables 3.2 and 3.3).
- :func:`pooled_scores` gathers the test scores of all folds (each example is tested exactly
  once) and computes l_full / l_given_number / l_single over all examples, which for
  leave-one-out is the thesis' "averaged over all possible test sets"; :func:`fold_samples`
  gives the same scores per fold (the spread), :func:`fold_thresholds` the threshold each
  fold's NMF learnt. :func:`score_units` groups the test examples for per-fold statistics that
  mean nothing on one example (a curve over thresholds, a subset's score): the folds' test
  sets, or, under leave-one-out, blocks of examples drawn from the splits stream.

Learners (names used in metric keys): ``nmf_frobenius`` and ``nmf_kl``
(:class:`~mmconcepts.nmf.LabelNMF`, beta = 2 and 1, threshold by inner cross-validation on
the training fold), ``svm`` (the thesis' baseline: one plain linear SVM per label on the raw
histograms, :func:`~mmconcepts.nmf.make_svm_baseline` with ``scale=False``), ``svm_std``
(the same on standardised features, a second baseline of ours), ``chance`` (predicts the
most frequent training label set; its label scores are the training label frequencies with
a random tie-break).
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, overload

import numpy as np

from ...errors import ConvergenceWarning, ExperimentError, ParameterError
from ..._fingerprint import code_fingerprint
from ...motion import (
    ARM_COLUMNS,
    LEFT_ARM_COLUMNS,
    RIGHT_ARM_COLUMNS,
    MotionHistograms,
    joint_angles,
    load_choreo1,
    msr_joint_angles,
)
from ...nmf import LabelNMF, l_full, l_given_number, l_single, make_svm_baseline
from ...engine import RunContext, SampleUnit, Streams, array_digest, describe_split, streams

__all__ = [
    "MotionArrays",
    "Streams",
    "combination_ids",
    "data_kind",
    "data_source_note",
    "evaluate_folds",
    "example_splits",
    "fold_samples",
    "fold_seeds",
    "fold_unit",
    "fold_thresholds",
    "kfold_splits",
    "msr_mixture_plan",
    "msr_subset",
    "part_splits",
    "pooled",
    "pooled_scores",
    "score_units",
    "source_parts",
    "split_groups",
    "split_sources",
    "streams",
    "subset_arrays",
    "unseen_combination_splits",
]

_SUBSETS = ("primitive", "mixed_partial", "mixed_full")


# ---------------------------------------------------------------------------- random streams
# ---------------------------------------------------------------------------- data
@dataclass
class MotionArrays:
    """One data set as the chapter-3 protocol sees it.

    angles : list of (T_i, 16) arrays (joint angles, :data:`~mmconcepts.motion.JOINT_ANGLE_NAMES`)
    Y : (n, L) binary label matrix; label_ids : the L label ids (columns of Y)
    source : "choreo1", "msr-action3d" or "synthetic"; description : what it is, in words
    sources : per example, the ids of the recordings it is made of (one for a demonstration
        recorded as such, two or three for an MSR limb mixture); None means each example is
        its own recording
    parts : (n,) int array or None: the part of the source recordings each example was
        built from (MSR limb mixtures, :func:`msr_mixture_plan`); its folds are these parts
        (:func:`part_splits`). None: the examples are independent recordings, split freely.
    """

    angles: list[np.ndarray]
    Y: np.ndarray
    label_ids: list[int]
    source: str
    description: str
    info: dict[str, Any] = field(default_factory=dict)
    sources: list[tuple[Any, ...]] | None = None
    parts: np.ndarray | None = None

    def example_sources(self) -> list[tuple[Any, ...]]:
        """The recordings behind each example (each example its own when ``sources`` is None)."""
        if self.sources is None:
            return [(i,) for i in range(len(self.Y))]
        return list(self.sources)


def data_kind(ctx: RunContext) -> str:
    """Which data the chapter-3 experiments use: "choreo1", else "msr-action3d", else "synthetic"."""
    for name in ("choreo1", "msr-action3d"):
        if ctx.has_dataset(name):
            return name
    return "synthetic"


def motion_arrays(ds) -> tuple[list[np.ndarray], np.ndarray, list[int]]:
    """Joint-angle trajectories (16 angles per frame), the label matrix and its label ids."""
    angles = [np.ascontiguousarray(joint_angles(r), dtype=np.float64) for r in ds]
    label_ids = list(ds.label_ids)
    return angles, ds.label_matrix(label_ids).astype(np.float64), label_ids


#: Parts of the source recordings of the MSR limb mixtures, in every preset: the folds of the protocols on
#: them. A spliced mixture cannot be left out alone (its recordings feed other mixtures), so leave-one-out
#: becomes leave-one-part-out; with fewer parts the unseen-combination protocol would leave too little training
#: data (its training sets also drop the test part's combinations).
MSR_PARTS = 10


def subset_arrays(ctx: RunContext, subset: str, *, streams: Streams, n_records: int | None = None) -> MotionArrays:
    """The Choreo1 subset ``subset`` from the run's data (choreo1 > msr-action3d > synthetic).

    Parameters
    ----------
    subset : {"primitive", "mixed_partial", "mixed_full"}
    streams : Streams
        The run's streams: the *data* stream draws the synthetic recordings, or the pairing
        of limbs of the real MSR recordings; the *splits* stream deals the recordings of the
        MSR mixed sets into :data:`MSR_PARTS` parts, within which the mixtures are built.
    n_records : int, optional
        Keep fewer records (small runs): the first ones of real Choreo1 files, a random
        draw (data stream) of the MSR sets, the first generated ones of the synthetic set.

    Returns
    -------
    MotionArrays
        Synthetic and Choreo1 examples are each their own recording (``sources`` None); the
        MSR mixed sets carry ``sources`` and ``parts``.
    """
    if subset not in _SUBSETS:
        raise ParameterError(f"subset must be one of {_SUBSETS}; got {subset!r}")
    kind = data_kind(ctx)
    if kind == "choreo1":
        folder = Path(ctx.dataset("choreo1"))
        ds = load_choreo1(folder / f"{subset}.json", on_error="skip")
        if n_records is not None:
            ds = ds.subset(range(min(n_records, len(ds))))
        angles, Y, ids = motion_arrays(ds)
        return MotionArrays(angles, Y, ids, kind, f"real Choreo1 {subset} ({len(Y)} records, {len(ids)} gestures) "
                                                   f"from {folder}")
    if kind == "msr-action3d":
        if subset == "primitive":
            return msr_subset(ctx.dataset("msr-action3d"), subset, streams=streams, n_records=n_records)
        return msr_subset(ctx.dataset("msr-action3d"), subset, streams=streams, n_records=n_records, n_parts=MSR_PARTS)
    from ...motion.synthetic import make_choreo1

    ds = make_choreo1(subset, data_home=ctx.cache_dir, random_state=streams.seed_for("data"), n_records=n_records,
                      verbose=ctx.verbose)
    angles, Y, ids = motion_arrays(ds)
    return MotionArrays(angles, Y, ids, kind, f"synthetic Choreo1 {subset} ({len(Y)} records, {len(ids)} gestures)")


# MSR Action3D: actions whose motion is in the arms (the right arm, when one arm moves) and in the legs.
MSR_ARM_ACTIONS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 17, 18, 19)
MSR_LEG_ACTIONS = (14, 15, 16)
#: Label id of an arm action performed (mirrored) on the left arm in the ``mixed_full`` MSR set.
LEFT_ARM_OFFSET = 100


def source_parts(actions: np.ndarray, subjects: np.ndarray, n_parts: int, seed: int) -> np.ndarray:
    """Deal the source recordings of the MSR limb mixtures into ``n_parts`` parts, per subject.

    Within each subject, the leg-action recordings are sorted by action (random order
    within an action) and dealt round robin from a random part, so the subject's legs are
    spread over as many parts as it has leg recordings; its arm-action recordings are dealt
    the same way over the parts that hold one of its leg recordings (a mixture needs a leg
    recording of the same subject in the same part). Recordings of other actions get -1.

    Parameters
    ----------
    actions, subjects : (n_recordings,) int arrays
    n_parts : int >= 2
    seed : int
        The *splits* stream: the parts are the folds of the protocol.

    Returns
    -------
    (n_recordings,) int array, the part of each recording (-1: not used by mixtures)
    """
    if n_parts < 2:
        raise ParameterError(f"n_parts must be >= 2; got {n_parts}")
    actions, subjects = np.asarray(actions), np.asarray(subjects)
    rng = np.random.default_rng(seed)
    part = np.full(len(actions), -1, dtype=np.int64)
    for s in np.unique(subjects):
        mine = subjects == s

        def deal(which: np.ndarray, slots: np.ndarray) -> None:
            idx = np.flatnonzero(which)
            if not idx.size or not slots.size:
                return
            order = idx[np.lexsort((rng.random(idx.size), actions[idx]))]  # by action, random within
            start = int(rng.integers(slots.size))
            part[order] = slots[(start + np.arange(order.size)) % slots.size]

        deal(mine & np.isin(actions, MSR_LEG_ACTIONS), np.arange(n_parts))
        deal(mine & np.isin(actions, MSR_ARM_ACTIONS), np.unique(part[mine & np.isin(actions, MSR_LEG_ACTIONS)]))
    return part


def msr_mixture_plan(actions: np.ndarray, subjects: np.ndarray, subset: str, *, streams: Streams,
                     n_parts: int | None = None) -> tuple[list[tuple[int, ...]], list[tuple[int, ...]], np.ndarray | None]:
    """Which recordings each MSR limb mixture is made of, its label set and its part.

    Parameters
    ----------
    actions, subjects : (n_recordings,) int arrays (the primitive set's order)
    subset : {"mixed_partial", "mixed_full"} (see :func:`msr_subset`)
    streams : Streams
        The run's streams: the *data* stream draws which leg (and left-arm) recording joins
        each arm recording; the *splits* stream deals the recordings into parts.
    n_parts : int, optional
        Deal the recordings into this many parts first (:func:`source_parts`) and build each
        mixture from recordings of its own part only, so that splits by part never put a
        recording on both sides. None: every recording of the subject can join (one pool,
        the mixtures share recordings; split them by part only).

    Returns
    -------
    sources : list of tuple of int
        Per mixture, the recordings (indices) it is made of: (arm, leg) or (right arm, left
        arm, leg).
    labels : list of tuple of int
        Per mixture, its label set.
    parts : (n_mixtures,) int array or None
        The part of each mixture's recordings (None without ``n_parts``).
    """
    if subset not in ("mixed_partial", "mixed_full"):
        raise ParameterError(f"subset must be 'mixed_partial' or 'mixed_full'; got {subset!r}")
    actions, subjects = np.asarray(actions), np.asarray(subjects)
    rng = streams.rng("data", _SUBSETS.index(subset))
    if n_parts is not None:
        rec_part = source_parts(actions, subjects, int(n_parts), streams.seed_for("splits"))
    else:
        rec_part = np.zeros(len(actions), dtype=np.int64)
    by_pool: dict[tuple[int, int], list[int]] = {}
    for i in range(len(actions)):
        by_pool.setdefault((int(subjects[i]), int(rec_part[i])), []).append(i)
    sources: list[tuple[int, ...]] = []
    labels: list[tuple[int, ...]] = []
    parts: list[int] = []
    for i in range(len(actions)):
        if actions[i] not in MSR_ARM_ACTIONS or rec_part[i] < 0:
            continue
        mine = by_pool[(int(subjects[i]), int(rec_part[i]))]
        legs = [j for j in mine if actions[j] in MSR_LEG_ACTIONS]
        if not legs:
            continue
        j = legs[int(rng.integers(len(legs)))]
        if subset == "mixed_partial":
            sources.append((i, j))
            labels.append((int(actions[i]), int(actions[j])))
            parts.append(int(rec_part[i]))
            continue
        others = [k for k in mine if actions[k] in MSR_ARM_ACTIONS and actions[k] != actions[i]]
        if not others:
            continue
        k = others[int(rng.integers(len(others)))]
        sources.append((i, k, j))
        labels.append((int(actions[i]), LEFT_ARM_OFFSET + int(actions[k]), int(actions[j])))
        parts.append(int(rec_part[i]))
    return sources, labels, (np.array(parts, dtype=np.int64) if n_parts is not None else None)


def msr_subset(folder, subset: str, *, streams: Streams, n_records: int | None = None,
               n_parts: int | None = None) -> MotionArrays:
    """A Choreo1-like subset made of real MSR Action3D skeletons (Li, Zhang and Liu 2010).

    - ``primitive``: every usable sequence, labelled by its action (20 labels), the analogue
      of the thesis' single-gesture demonstrations; each example is its own recording.
    - ``mixed_partial`` (the small mixed set, thesis 16 gestures): the arm angles (both
      arms) of each sequence of an arm action (15 actions) joined with the torso and leg
      angles of a random sequence of a leg action (forward kick, side kick, jogging) of the
      same subject, cropped to the shorter; label set {arm action, leg action}: 18 labels,
      45 possible combinations, so combinations repeat.
    - ``mixed_full`` (the large mixed set, thesis 47 gestures): the right-arm angles of each
      arm-action sequence on the right arm, the right-arm angles of a random sequence of
      *another* arm action of the same subject on the left arm (mirrored: the angles are
      defined symmetrically per side), the torso and legs of a random leg-action sequence of
      the same subject; label set {A on the right arm, B on the left arm (id 100 + B), leg
      action}: 33 labels, 630 possible combinations, most of them seen once (as Fig. 3.8).
      MSR's one-arm actions are done with the right arm (its left arm barely moves: angle
      sd 0.07-0.14 rad against 0.40-0.65 rad), hence the mirroring.

    A leg recording joins about five mixtures, so the mixtures are not independent
    examples. With ``n_parts`` the recordings are first dealt into parts (splits stream,
    :func:`source_parts`) and each mixture is made of recordings of one part
    (:func:`msr_mixture_plan`): the parts are folds that keep every recording on one side.

    Whatever subjects the folder holds are used (no subject is named here); the random
    pairings come from the data stream of ``streams``, the parts from its splits stream.
    """
    if subset not in _SUBSETS:
        raise ParameterError(f"subset must be one of {_SUBSETS}; got {subset!r}")
    folder = Path(folder)
    angles, actions, subjects, skipped = msr_joint_angles(folder)
    rng = streams.rng("data", _SUBSETS.index(subset))
    parts: np.ndarray | None = None
    labels: list[tuple[int, ...]]
    sources: list[tuple[int, ...]]
    if subset == "primitive":
        out = [a.copy() for a in angles]
        labels = [(int(a),) for a in actions]
        sources = [(i,) for i in range(len(angles))]
    else:
        sources, labels, parts = msr_mixture_plan(actions, subjects, subset, streams=streams, n_parts=n_parts)
        # the draw of n_records below: a draw of its own, apart from the pairing's
        rng = streams.rng("data", _SUBSETS.index(subset), 1)
        out = []
        for src in sources:
            T = min(len(angles[r]) for r in src)
            x = angles[src[-1]][:T].copy()  # torso and legs of the leg recording
            if len(src) == 2:
                x[:, ARM_COLUMNS] = angles[src[0]][:T, ARM_COLUMNS]
            else:
                x[:, RIGHT_ARM_COLUMNS] = angles[src[0]][:T, RIGHT_ARM_COLUMNS]
                x[:, LEFT_ARM_COLUMNS] = angles[src[1]][:T, RIGHT_ARM_COLUMNS]
            out.append(x)
    if n_records is not None and n_records < len(out):
        keep = np.sort(rng.choice(len(out), int(n_records), replace=False))
        out = [out[i] for i in keep]
        labels = [labels[i] for i in keep]
        sources = [sources[i] for i in keep]
        if parts is not None:
            parts = parts[keep]
    ids = sorted({l for ls in labels for l in ls})
    col = {l: c for c, l in enumerate(ids)}
    Y = np.zeros((len(labels), len(ids)))
    for r, ls in enumerate(labels):
        Y[r, [col[l] for l in ls]] = 1.0
    n_subj = len(np.unique(subjects))
    what = {"primitive": "whole sequences, one action each",
            "mixed_partial": "both arms of an arm action + torso/legs of a leg action, same subject",
            "mixed_full": "right arm of an arm action + another arm action mirrored on the left arm + torso/legs of "
                          "a leg action, same subject"}[subset]
    desc = (f"real MSR Action3D skeletons ({n_subj} subjects, 15 fps), {subset}: {len(Y)} examples, {len(ids)} labels, "
            f"{len(set(labels))} label combinations ({what}")
    desc += (f"; built within {len(np.unique(parts))} parts of the recordings)" if parts is not None else ")")
    if skipped:
        desc += f"; left out: {', '.join(skipped)} (unreadable, or no tracked frames, or too short)"
    return MotionArrays(out, Y, ids, "msr-action3d", desc, {"n_subjects": n_subj, "skipped": list(skipped),
                                                                  "sources": sources},
                        sources=list(sources), parts=parts)


def data_source_note(ctx: RunContext, arrays: MotionArrays | list[MotionArrays] | None = None) -> str:
    """Which data the experiment ran on, with sizes (for the result's notes)."""
    kind = data_kind(ctx)
    items = [] if arrays is None else ([arrays] if isinstance(arrays, MotionArrays) else list(arrays))
    sizes = "; ".join(a.description for a in items)
    if kind == "choreo1":
        head = f"Data: real Choreo1 recordings from {ctx.dataset('choreo1')}."
    elif kind == "msr-action3d":
        head = (f"Data: real Kinect skeletons of MSR Action3D (Li, Zhang and Liu 2010) from {ctx.dataset('msr-action3d')}, "
                "standing in for Choreo1: mixed 'choreographies' combine the limbs of different real recordings of one "
                "subject (mmconcepts.experiments.ch3.protocol.msr_subset); the 16- and 47-gesture sets of the thesis are "
                "its small (18 labels, 2 per example) and large (33 labels, 3 per example) mixed sets. A recording "
                "joins several mixtures, so the recordings are dealt into parts (the folds) first and each part's "
                "mixtures are built from its own recordings: no recording behind a test mixture feeds a training one.")
    else:
        head = ("Data: synthetic Choreo1 (mmconcepts.motion.synthetic.make_choreo1: a kinematic dancer whose noise and "
                "variability were measured on real Kinect skeletons of MSR Action3D); pass --data choreo1=DIR for the "
                "thesis' recordings or --data msr-action3d=DIR for real Kinect skeletons.")
    return head + (f" Sizes: {sizes}." if sizes else "")


# ---------------------------------------------------------------------------- splits
def kfold_splits(n: int, n_folds: int | None, seed: int, y: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, test) index pairs: leave-one-out when ``n_folds`` is None, else shuffled k-fold
    (stratified by ``y`` when single labels are given and every class has n_folds examples)."""
    from sklearn.model_selection import KFold, LeaveOneOut, StratifiedKFold

    idx = np.zeros((n, 1))
    if n_folds is None:
        return [(tr, te) for tr, te in LeaveOneOut().split(idx)]
    if y is not None and np.bincount(np.unique(y, return_inverse=True)[1]).min() >= n_folds:
        return [(tr, te) for tr, te in StratifiedKFold(n_folds, shuffle=True, random_state=seed).split(idx, y)]
    return [(tr, te) for tr, te in KFold(n_folds, shuffle=True, random_state=seed).split(idx)]


def part_splits(parts: np.ndarray, Y: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Leave one part out: the folds of examples built per part of their source recordings.

    Parameters
    ----------
    parts : (n,) int array
        The part of each example (:attr:`MotionArrays.parts`).
    Y : (n, L) label matrix, optional
        Given, each fold's training set also leaves out the examples whose label combination
        occurs in its test part (thesis Table 3.3: the test combinations are unseen in
        training); the test set is the whole part, so every example is tested once.

    Returns
    -------
    list of (train, test) index arrays, one per part (in part order), test parts non-empty
    """
    parts = np.asarray(parts)
    groups = None if Y is None else combination_ids(Y)
    out = []
    for f in np.unique(parts):
        te = np.flatnonzero(parts == f)
        tr = np.flatnonzero(parts != f)
        if groups is not None:
            tr = tr[~np.isin(groups[tr], groups[te])]
        if te.size and tr.size:
            out.append((tr, te))
    return out


def example_splits(arrays: MotionArrays, n_folds: int | None, seed: int, *, unseen: bool = False,
                   y: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """The (train, test) folds of a protocol on ``arrays``, grouped by source recording.

    Examples built per part of their recordings (MSR limb mixtures) are split by part
    (:func:`part_splits`, whatever ``n_folds``); examples that are
    each their own recording by :func:`kfold_splits` (``unseen=False``) or
    :func:`unseen_combination_splits` (``unseen=True``).

    Parameters
    ----------
    arrays : MotionArrays
    n_folds : int or None
        Folds (None: leave-one-out, or one combination out with ``unseen``).
    seed : int
        The *splits* stream.
    unseen : bool, default=False
        Test folds show only label combinations absent from their training set.
    y : (n,) int array, optional
        Single labels to stratify k-fold by.
    """
    if arrays.parts is not None:
        return part_splits(arrays.parts, arrays.Y if unseen else None)
    if unseen:
        return unseen_combination_splits(arrays.Y, n_folds, seed)
    return kfold_splits(len(arrays.Y), n_folds, seed, y=y)


def split_sources(arrays: MotionArrays, splits) -> list[tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]]:
    """Per fold, the source recordings of each training and each test example (for :func:`describe_split`)."""
    src = arrays.example_sources()
    return [([src[i] for i in tr], [src[i] for i in te]) for tr, te in splits]


def split_groups(arrays: MotionArrays, splits) -> dict[str, Any]:
    """What the folds keep apart, for the result's ``split_groups``: :func:`~mmconcepts.engine.describe_split`
    of :func:`split_sources`, which raises when a recording is behind examples on both sides of a fold."""
    if arrays.parts is None:
        own = {"synthetic": "each generated example is an independent draw of the dancer (its own recording)",
               "choreo1": "each Choreo1 demonstration is its own recording",
               "msr-action3d": "each MSR Action3D sequence is its own recording"}[arrays.source]
        by = f"source recordings: {own}"
    else:
        by = ("source recordings: the MSR Action3D sequences spliced into each mixture (arms, legs); the recordings "
              "are dealt into parts per subject and each part's mixtures are built from its own recordings")
    return describe_split(by, split_sources(arrays, splits))


def fold_unit(splits, what: str) -> SampleUnit:
    """The sample unit of per-fold values: ``SampleUnit.folds(k)`` when each training set is the rest of the data
    (k-fold; leave-one-out over n is ``folds(n)``), else resampled splits with the folds' mean n_test / n_train."""
    n = len(np.unique(np.concatenate([np.asarray(te) for _, te in splits] + [np.asarray(tr) for tr, _ in splits])))
    k = len(splits)
    if all(len(tr) + len(te) == n for tr, te in splits):
        return SampleUnit.folds(k, f"{k} folds of {what}")
    ratio = float(np.mean([len(te) / len(tr) for tr, te in splits]))
    return SampleUnit("resampled", ratio, f"{k} folds of {what} (training sets leave out more than the test fold: "
                                          f"mean n_test / n_train {ratio:.3f})")


def combination_ids(Y: np.ndarray) -> np.ndarray:
    """An integer per example naming its label combination (the set of its labels)."""
    keys = [tuple(np.flatnonzero(row > 0)) for row in Y]
    uniq = {k: i for i, k in enumerate(sorted(set(keys)))}
    return np.array([uniq[k] for k in keys])


def unseen_combination_splits(Y: np.ndarray, n_folds: int | None, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Splits whose test examples only show label combinations absent from their training set.

    All examples of a combination go to the same fold (combinations are shuffled, then each
    is given to the currently smallest fold). ``n_folds=None``: leave one combination out.
    """
    groups = combination_ids(Y)
    n = len(groups)
    uniq, counts = np.unique(groups, return_counts=True)
    rng = np.random.default_rng(seed)
    if n_folds is None:
        fold_of = {g: i for i, g in enumerate(uniq)}
        k = len(uniq)
    else:
        k = min(int(n_folds), len(uniq))
        order = rng.permutation(len(uniq))
        sizes = np.zeros(k)
        fold_of = {}
        for j in order[np.argsort(-counts[order], kind="stable")]:  # big groups first, random among equals
            f = int(np.argmin(sizes))
            fold_of[uniq[j]] = f
            sizes[f] += counts[j]
    fold = np.array([fold_of[g] for g in groups])
    out = []
    for f in range(k):
        te = np.flatnonzero(fold == f)
        tr = np.flatnonzero(fold != f)
        if te.size and tr.size:
            out.append((tr, te))
    assert sum(len(te) for _, te in out) == n
    return out


# ---------------------------------------------------------------------------- one fold
def _learner(name: str, params: dict, seed: int, features: dict | None = None):
    if name.startswith("nmf_"):
        beta = {"nmf_frobenius": 2.0, "nmf_kl": 1.0}[name]
        return LabelNMF(params["n_components"], beta_loss=beta, max_iter=params["max_iter"], cv=params["inner_cv"],
                        random_state=seed)
    if name == "svm":  # the thesis' baseline: a plain linear SVM per label on the raw histograms
        return make_svm_baseline(scale=False, random_state=seed)
    if name == "svm_std":  # ours: the same on standardised features
        # make_svm_baseline(scale=True), with the faster of LinearSVC's two solvers for the histograms (the same
        # optimum): the dual on standardised VQ histograms (dual="auto" would pick the primal when there are more
        # examples than features), the primal on standardised KDE histograms (benchmarks/README.md has the
        # measurements). Stopping tolerance 1e-3 (libsvm's and sklearn.svm.SVC's default; LinearSVC's is 1e-4):
        # decision values within ~1e-3 of the tighter solution.
        from sklearn.multiclass import OneVsRestClassifier
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import LinearSVC

        dual = (features or {}).get("method") != "kde"
        return OneVsRestClassifier(make_pipeline(StandardScaler(), LinearSVC(C=1.0, tol=1e-3, max_iter=10000,
                                                                             dual=dual, random_state=seed)))
    raise ParameterError(f"unknown learner {name!r}")


@contextlib.contextmanager
def _fold_context() -> Iterator[None]:
    """One BLAS thread (the folds run in parallel processes); capped NMF iterations are the protocol
    (``max_iter``): their ConvergenceWarning is expected, others (the SVMs' among them) are shown."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        yield


def _histograms(task: dict) -> np.ndarray:
    """The histograms (n, n_features) of every example, grids or codebooks fitted on the fold's training examples."""
    angles, train = task["angles"], task["train"]
    hist = MotionHistograms(**task["features"], random_state=task["seed"]).fit([angles[i] for i in train])
    return hist.transform(angles)


def _learner_result(name: str, X: np.ndarray, task: dict) -> dict[str, Any]:
    """Fit learner ``name`` on the fold's training rows of ``X``; its ``scores`` (and ``pred``, ``threshold``) on the
    test rows, and the ``seconds`` it took."""
    Y, train, test, seed = task["Y"], task["train"], task["test"], task["seed"]
    t0 = time.perf_counter()
    Xtr, Xte, Ytr = X[train], X[test], Y[train]
    L = Y.shape[1]
    res: dict[str, Any] = {}
    if name == "chance":
        freq = Ytr.mean(axis=0)
        rng = np.random.default_rng(seed)
        res["scores"] = np.tile(freq, (len(test), 1)) + 1e-9 * rng.random((len(test), L))
        common = Counter(tuple(r) for r in Ytr.astype(int)).most_common(1)[0][0]
        res["pred"] = np.tile(np.array(common), (len(test), 1))
    elif task["single"]:
        y_tr = np.argmax(Ytr, axis=1)
        model = _learner(name, task["params"], seed, task["features"])
        model.fit(Xtr, y_tr)
        s = model.decision_function(Xte)
        if s.ndim == 1:
            s = np.column_stack([-s, s])
        scores = np.full((len(test), L), -1e9)
        scores[:, model.classes_] = s
        res["scores"] = scores
    else:
        model = _learner(name, task["params"], seed, task["features"])
        keep = Ytr.sum(axis=0) > 0  # labels absent from training cannot be learnt
        model.fit(Xtr, Ytr[:, keep])
        s = model.label_activations(Xte) if name.startswith("nmf_") else model.decision_function(Xte)
        scores = np.full((len(test), L), -1e9)
        scores[:, keep] = s
        pred = np.zeros((len(test), L), dtype=np.int64)
        # LabelNMF.predict is its activations at the threshold: read from s, not transformed again
        pred[:, keep] = (s >= model.threshold_).astype(np.int64) if name.startswith("nmf_") else model.predict(Xte)
        res["scores"], res["pred"] = scores, pred
        if name.startswith("nmf_"):
            res["threshold"] = float(model.threshold_)
    res["seconds"] = time.perf_counter() - t0
    return res


def _fold(task: dict) -> dict:
    """Fit features and learners on one training fold; score its test examples (what :func:`evaluate_folds` gives
    per fold, with ``feature_seconds``)."""
    out: dict[str, Any] = {"test": task["test"]}
    with _fold_context():
        t0 = time.perf_counter()
        X = _histograms(task)
        out["feature_seconds"] = time.perf_counter() - t0
        for name in task["learners"]:
            out[name] = _learner_result(name, X, task)
    return out


def _cached_learner(task: dict, key: tuple, code: str) -> dict:
    """:func:`_learner_result` of ``task["learner"]`` on ``task["X"]``, cached on disk by :func:`evaluate_folds`
    (``task`` is not hashed).

    ``key`` stands for everything the result depends on (a digest of the data, the split, the
    features, the learner and its parameters, the fold's seed), ``code`` is the package's
    :func:`~mmconcepts._fingerprint.code_fingerprint`.
    """
    return _learner_result(task["learner"], task["X"], task)


def _fold_entries(item: tuple) -> dict[str, dict]:
    """The learners of one fold that the cache lacks: the histograms once, then each learner, whose entry is
    written as soon as it ends. ``item`` is ``(cached, task, {learner: key}, code)``."""
    cached, task, keys, code = item
    with _fold_context():
        X = _histograms(task)
        return {name: cached.compute(dict(task, X=X, learner=name), key, code) for name, key in keys.items()}


def fold_seeds(streams: Streams, splits, n: int) -> list[int]:
    """The *learner* seed of each fold (its histogram codebooks and learners).

    A fold that leaves one example out (its test set is example ``j``, its training set all the
    others) draws ``streams.seed_for("learner", j)``: every protocol that leaves ``j`` out
    alone (leave-one-out, and leave-one-combination-out for a combination shown by ``j`` only)
    has the same fold, fitted once (:func:`evaluate_folds` caches it). Fold ``i`` of any other
    kind draws ``streams.seed_for("learner", i)``, or ``streams.seed_for("learner", i, 1)`` when
    the splits also hold folds of one left-out example, so that no two folds share a seed.
    Under leave-one-out fold ``i`` leaves example ``i`` out: both rules give the same seeds.

    Parameters
    ----------
    streams : Streams
    splits : list of (train, test) index arrays
    n : int
        The number of examples.

    Returns
    -------
    list of int, one per fold
    """
    alone = [len(te) == 1 and len(tr) == n - 1 for tr, te in splits]
    mixed = any(alone) and not all(alone)
    return [streams.seed_for("learner", int(np.asarray(te)[0])) if one
            else streams.seed_for("learner", i, 1) if mixed else streams.seed_for("learner", i)
            for i, ((_, te), one) in enumerate(zip(splits, alone))]


@overload
def evaluate_folds(ctx: RunContext, angles: list[np.ndarray], Y: np.ndarray, splits, *, features: dict,
                   learners: tuple[str, ...], params: dict, streams: Streams, single: bool = False,
                   desc: str = "folds") -> list[dict]: ...


@overload
def evaluate_folds(ctx: RunContext, angles: list[np.ndarray], Y: np.ndarray, splits, *,
                   features: list[dict] | tuple[dict, ...], learners: tuple[str, ...], params: dict,
                   streams: Streams, single: bool = False, desc: str = "folds") -> list[list[dict]]: ...


def evaluate_folds(ctx: RunContext, angles: list[np.ndarray], Y: np.ndarray, splits, *,
                   features: dict | list[dict] | tuple[dict, ...], learners: tuple[str, ...], params: dict,
                   streams: Streams, single: bool = False, desc: str = "folds") -> list[dict] | list[list[dict]]:
    """Evaluate every split (in parallel over ``ctx.workers``), reusing cached learners.

    Each learner's result on a fold is one cache entry (the disk cache of
    :meth:`RunContext.memory <mmconcepts.engine.context.RunContext.memory>` under
    ``ctx.cache_dir/ch3-folds``), keyed on the data, the fold's training and test examples, the
    histogram parameters, the learner and its parameters, the fold's seed (:func:`fold_seeds`)
    and the code: experiments that ask for the same learner on the same fold (the same
    protocol; or leave-one-out and leave-one-combination-out leaving out the same single
    example) fit it once, whichever other learners they ask for. A fold's histograms are
    computed once for the learners it lacks.

    Parameters
    ----------
    angles : list of (T_i, n_dof) arrays
    Y : (n, L) label matrix (one-hot for single-label data)
    splits : list of (train, test) index arrays
    features : keyword arguments of :class:`~mmconcepts.motion.MotionHistograms`, or a list of them
        (then one list of fold results per entry is returned, all folds run in one parallel batch)
    learners : names among 'nmf_frobenius', 'nmf_kl', 'svm', 'svm_std', 'chance'
    params : ``n_components``, ``max_iter``, ``inner_cv`` of the NMF learners
    streams : Streams
        The run's streams: each fold's histogram codebooks and learners are seeded by its
        *learner* stream (:func:`fold_seeds`).
    single : single-label data (1-D fit, l_single)

    Returns
    -------
    list of dict, one per split: ``test`` indices, and per learner ``scores`` (n_test, L),
    ``pred`` (multi-label only), ``threshold`` (NMF), ``seconds``.
    """
    many = isinstance(features, (list, tuple))
    feature_list: list[dict] = list(features) if isinstance(features, (list, tuple)) else [features]
    fp = array_digest([*angles, Y])
    code = code_fingerprint()
    memo = ctx.memory("ch3-folds").cache(_cached_learner, ignore=["task"])
    seeds = fold_seeds(streams, splits, len(Y))
    nmf_params = sorted(params.items())
    folds: list[dict] = []
    todo: list[tuple] = []
    for feats in feature_list:
        # Every histogram parameter, defaults included, so a changed default is a new key.
        hist_params = sorted(MotionHistograms(**feats).get_params().items())
        for (tr, te), fold_seed in zip(splits, seeds):
            task = {"angles": angles, "Y": Y, "train": np.asarray(tr), "test": np.asarray(te), "features": feats,
                    "params": params, "seed": fold_seed, "single": single}
            fold: dict[str, Any] = {"test": task["test"]}
            missing = {}
            for name in learners:
                key = (fp, hist_params, name, nmf_params if name.startswith("nmf_") else [], single, task["train"],
                       task["test"], fold_seed)
                found, value = memo.lookup(task, key, code)
                if found:
                    fold[name] = value
                else:
                    missing[name] = key
            if missing:
                todo.append((len(folds), (memo, task, missing, code)))
            folds.append(fold)
    # Each learner's entry is written by the process that computed it as soon as it ends,
    # so an interrupted run resumes from the fits it finished.
    done = ctx.parallel(_fold_entries, [item for _, item in todo], desc=desc)
    for (j, _), computed in zip(todo, done):
        folds[j].update(computed)
    for fold in folds:  # the learners in the order asked
        order = {name: fold.pop(name) for name in learners}
        fold.update(order)
    results = [folds[j * len(splits):(j + 1) * len(splits)] for j in range(len(feature_list))]
    if not many:
        return results[0]
    return results


def pooled(folds: list[dict], name: str, field: str, n: int, L: int) -> np.ndarray:
    """One array (n, L) of a learner's ``scores`` or ``pred`` over all test examples."""
    out = np.zeros((n, L))
    seen = np.zeros(n, bool)
    for f in folds:
        out[f["test"]] = f[name][field]
        seen[f["test"]] = True
    if not seen.all():
        raise ExperimentError("some examples were never tested; the splits do not cover the data set")
    return out


def pooled_scores(folds: list[dict], Y: np.ndarray, name: str, *, single: bool = False) -> dict[str, float]:
    """l_single (single) or l_full and l_given_number of learner ``name`` over all test examples."""
    n, L = Y.shape
    S = pooled(folds, name, "scores", n, L)
    if single:
        return {"l_single": float(l_single(np.argmax(Y, axis=1), S))}
    out = {"l_given_number": float(l_given_number(Y, S))}
    out["l_full"] = float(l_full(Y, pooled(folds, name, "pred", n, L)))
    return out


def fold_samples(folds: list[dict], Y: np.ndarray, name: str, *, single: bool = False) -> dict[str, list[float]]:
    """The scores of :func:`pooled_scores` computed on each fold's test examples (the spread over folds)."""
    out: dict[str, list[float]] = {}
    for f in folds:
        te = f["test"]
        Yt, S = Y[te], f[name]["scores"]
        if single:
            out.setdefault("l_single", []).append(float(l_single(np.argmax(Yt, axis=1), S)))
            continue
        out.setdefault("l_full", []).append(float(l_full(Yt, f[name]["pred"])))
        out.setdefault("l_given_number", []).append(float(l_given_number(Yt, S)))
    return out


def fold_thresholds(folds: list[dict], name: str) -> list[float]:
    """The threshold learner ``name`` chose by cross-validation on each training fold (fold order).

    The samples of ``<set>.<name>.mean_threshold``: same folds, same order as :func:`fold_samples`.
    """
    return [float(f[name]["threshold"]) for f in folds]


#: Leave-one-out test examples are grouped into this many blocks by :func:`score_units`.
N_BLOCKS = 10


def score_units(folds: list[dict], seed: int, *, n_blocks: int = N_BLOCKS) -> list[np.ndarray]:
    """Groups of test examples over which a per-fold statistic is computed (its samples).

    With k folds, each fold's test examples, in fold order (the units of :func:`fold_samples`).
    With leave-one-out (every fold tests one example) a statistic of one example is 0 or 1
    and a curve over thresholds is a step: the examples are then shuffled by ``seed`` (the
    *splits* stream, which leave-one-out does not otherwise use) and cut into ``n_blocks``
    blocks of nearly equal size (``numpy.array_split``), each block one unit.

    Parameters
    ----------
    folds : fold results of :func:`evaluate_folds` (their ``test`` indices)
    seed : int
        The splits stream (``streams(config.seed).seed_for("splits")``).
    n_blocks : int, default=:data:`N_BLOCKS`

    Returns
    -------
    list of int arrays, a partition of the tested examples
    """
    tests = [np.asarray(f["test"]) for f in folds]
    if len(tests) > n_blocks and all(t.size == 1 for t in tests):
        order = np.random.default_rng(seed).permutation(np.concatenate(tests))
        return [np.sort(b) for b in np.array_split(order, n_blocks)]
    return tests
