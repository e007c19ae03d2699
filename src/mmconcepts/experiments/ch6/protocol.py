"""Shared machinery of the chapter-6 experiments: the three modalities, pairing by concept, folds.

The sound-motion pairs (speech and motion data, pairing, sources and split checks) are
:mod:`mmconcepts.experiments.protocols.pairs`, shared with chapter 7; their names are importable
from here too. This module adds the images, the folds of Tables 6.2-6.4 and the concept analysis.

Thesis sections 6.5-6.6. Each modality comes from a real set when it is in ``ctx.data``,
else from its generated stand-in:

- sound: the utterances of one speaker (the first by name; the thesis uses speaker 1),
  one keyword each. Real: ``fsdd`` (Free Spoken Digit Dataset: ten digit words said
  alone, 50 recordings per word and speaker), ``acorns`` (Caregiver) or ``audio``
  (generic layout); synthetic: the chapter 5 Caregiver-like corpus
  (:func:`mmconcepts.experiments.ch5.protocol.load_corpus`). Represented by HAC (22 MFCC,
  codebooks 150/150/100, lags 2 and 5) with codebooks fitted per training fold;
- motion: one gesture per record. Real: ten MSR Action3D actions (``msr-action3d``: Kinect
  skeletons, positions only, so the 16 joint angles of
  :func:`mmconcepts.motion.joint_angles`) or Choreo2 (``choreo2``); synthetic: the
  Choreo2-like set. Joint angle-velocity histograms
  (:class:`~mmconcepts.motion.MotionHistograms`) fitted per training fold;
- images: one object per concept, many views each. Real: ETH-80 (``eth80``: ten objects
  taken round robin over the eight categories, apple1, car1, ..., tomato1, apple2, car2) or
  a generic folder (``images``); synthetic: :func:`mmconcepts.vision.make_objects`;
- labels: the concept as a one-hot vector (the symbolic modality).

Concepts: keyword k goes with gesture ``mapping[k]`` (and object ``objects[k]``) through a
random bijection (the thesis' Table 6.1 is one such mapping). Examples are paired by
concept *within each partition* (cross-validation fold, or training / test / reference
part): the utterances, the motion records and the object views are each split by concept
first, then every utterance gets a record (a view) of its concept from the same part,
drawn without replacement while possible. So when a real set has fewer records than
there are utterances (MSR Action3D: about 27 records per action for 50 utterances per
word) a record may serve twice, but never in both training and test. Every example knows the
recordings it is made of (:func:`example_sources`: the utterance's file, the motion record's
id, the image's file), and :func:`fold_split_groups` / :func:`part_split_groups` check with
:func:`~mmconcepts.engine.splits.describe_split` that no recording behind a test (or
reference) example is behind a training example, for the record's ``split_groups``. Object
views are photos of the concept's one object (the thesis' design: one object per concept, so
every split shows the same object on both sides); a view is one recording, never on both
sides.

Random streams: :func:`streams` gives the independent streams of the configuration's seed
(:class:`~mmconcepts.engine.Streams`) for the data (bijections, pairing, stream order), the
folds (splits), the learners (HAC and histogram codebooks, NMF initialisation), the reference
draws of the matching protocol and the controls, and the composition of the test utterances
of the sliding windows.

:func:`evaluate` runs every fold of Tables 6.2-6.4 and Fig. 6.10 through ``ctx.parallel`` and
caches each fold's result on disk as the fold ends (key: the data, the setting, the fold and
:func:`code_fingerprint`), so the four experiments share one computation and an
interrupted run resumes from the folds it finished. Each fold also fits the k = 15 learner of
Fig. 6.10 on its training pairs and measures the mutual information between concepts and
coefficients there (:func:`concept_analysis`); the first fold keeps that learner's coefficients,
from which the four experiments' concept explorer is read (:func:`fold_explorer`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..._fingerprint import code_fingerprint
from ...errors import ConvergenceWarning, DataError
from ...motion import MotionHistograms
from ..._jit import single_threaded
from ...multimodal import MultimodalNMF, matching_success_rate, mutual_information_matrix, pairwise_divergence
from ...sound.hac import HAC
from ..protocols.pairs import (
    KEYWORDS_NOTE,
    MOTION_SETS,
    MSR_ACTIONS,
    SPEECH_SETS,
    THESIS_CHANCE,
    data_source_note,
    example_sources,
    fold_split_groups,
    gesture_mapping,
    load_motion,
    load_pairs,
    load_speech,
    motion_note,
    pair_within_parts,
    part_split_groups,
    speech_note,
)
from ..protocols.explorer import UTTERANCES, explorer_note, recordings_explorer
from ...engine import (
    Explorer,
    PresetConfig,
    RunContext,
    Streams,
    array_digest,
    cached_call,
    streams,
)

__all__ = ["Streams", "streams", "PairsConfig", "load_speech", "load_motion", "load_images", "load_pairs", "evaluate",
           "data_source_note", "pair_within_parts", "SPACE_NAMES", "METRIC_NAMES", "MSR_ACTIONS", "SPEECH_SETS",
           "MOTION_SETS", "IMAGE_SETS", "image_locals", "image_concepts", "image_ids", "space_pairs",
           "gesture_mapping", "speech_note", "motion_note", "eth80_objects", "KEYWORDS_NOTE", "example_sources",
           "fold_split_groups", "part_split_groups", "concept_analysis", "entropy_bits", "CONCEPT_METRICS",
           "SPECIALISED_FRACTION", "seen_columns", "TABLE_6_2", "TABLE_6_3", "TABLE_6_4", "THESIS_CHANCE",
           "fold_explorer"]

#: Metric names of the tables -> metric of :func:`mmconcepts.multimodal.pairwise_divergence`.
#: "kl" is the thesis' setting: the data are not normalised per example, so the divergence
#: is the I-divergence (generalised KL, section 6.6.1); "kl_normalised" is the KL divergence
#: after normalising both sides to sum to one, reported beside it.
METRIC_NAMES = {"kl": "idiv", "kl_normalised": "kl", "euclidean": "euclidean", "cosine": "cosine"}

IMAGE_SETS = ("images", "eth80")



def SPACE_NAMES(direction: str) -> dict[str, str]:
    """Thesis space name -> comparison space of :func:`crossmodal_distances` for a direction."""
    if direction == "sound2motion":
        return {"internal": "internal", "motion": "reference", "sound": "test"}
    return {"internal": "internal", "sound": "reference", "motion": "test"}




#: Thesis Table 6.2 (success rates; the shuffled control "generally scores around" shuffled.mean; "baseline random
#: is in that case" THESIS_CHANCE, footnote 6: the keywords are not exactly uniform).
TABLE_6_2 = {
    "sound2motion.internal.kl": 0.608, "sound2motion.internal.euclidean": 0.612, "sound2motion.internal.cosine": 0.646,
    "sound2motion.motion.kl": 0.552, "sound2motion.motion.euclidean": 0.379, "sound2motion.motion.cosine": 0.444,
    "sound2motion.sound.kl": 0.238, "sound2motion.sound.euclidean": 0.126, "sound2motion.sound.cosine": 0.208,
    "motion2sound.internal.kl": 0.610, "motion2sound.internal.euclidean": 0.704, "motion2sound.internal.cosine": 0.830,
    "motion2sound.sound.kl": 0.106, "motion2sound.sound.euclidean": 0.090, "motion2sound.sound.cosine": 0.186,
    "motion2sound.motion.kl": 0.676, "motion2sound.motion.euclidean": 0.642, "motion2sound.motion.cosine": 0.749,
    "shuffled.mean": 0.116, "chance": THESIS_CHANCE,
}
#: Thesis Table 6.3 (with symbolic labels in training).
TABLE_6_3 = {
    "sound2motion.internal.kl": 0.387, "sound2motion.internal.euclidean": 0.699, "sound2motion.internal.cosine": 0.721,
    "sound2motion.motion.kl": 0.543, "sound2motion.motion.euclidean": 0.261, "sound2motion.motion.cosine": 0.424,
    "sound2motion.sound.kl": 0.136, "sound2motion.sound.euclidean": 0.089, "sound2motion.sound.cosine": 0.131,
    "motion2sound.internal.kl": 0.573, "motion2sound.internal.euclidean": 0.620, "motion2sound.internal.cosine": 0.702,
    "motion2sound.sound.kl": 0.114, "motion2sound.sound.euclidean": 0.090, "motion2sound.sound.cosine": 0.122,
    "motion2sound.motion.kl": 0.519, "motion2sound.motion.euclidean": 0.469, "motion2sound.motion.cosine": 0.552,
    "chance": THESIS_CHANCE,
}
#: Thesis Table 6.4 (label recognition: mean over folds, and the standard deviation over folds the thesis gives).
TABLE_6_4 = {"sound_labels.s2l": 0.916, "sound_labels.s2l_std": 0.034,
             "motion_labels.m2l": 0.906, "motion_labels.m2l_std": 0.052,
             "all.s2l": 0.896, "all.s2l_std": 0.043,
             "all.m2l": 0.910, "all.m2l_std": 0.054,
             "all.sm2l": 0.917, "all.sm2l_std": 0.055}

# ---------------------------------------------------------------------------- the folds' configuration
@dataclass(frozen=True)
class PairsConfig(PresetConfig):
    """The cross-validation of sound-motion pairs behind Tables 6.2-6.4 and Fig. 6.10 (defaults: the thesis').

    ``n_per_speaker`` and ``n_motion`` select the generated data; ``k`` and ``n_iter`` are
    the learner of Tables 6.2-6.4 (k = 50, 50 iterations), ``concept_k`` and ``mi_bins`` the
    learner and the discretisation of Fig. 6.10 (k = 15, 10 bins), fitted on the same
    training folds. One config for the four experiments, so that they share the folds.
    """

    n_per_speaker: int = 1000
    n_motion: int = 1100
    n_folds: int = 10
    k: int = 50
    n_iter: int = 50
    motion_bins: int = 25
    concept_k: int = 15
    mi_bins: int = 10
    seed: int = 0

    hac_fit_frames: int = 100_000  # training frames (at most) for each HAC codebook: HAC's max_fit_frames
    QUICK = dict(n_per_speaker=250, n_motion=250, n_folds=5, hac_fit_frames=20_000)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_per_speaker=50, n_motion=60, n_folds=3, k=10, n_iter=20, concept_k=5, hac_fit_frames=5_000)








def eth80_objects(labels, categories, n_objects: int) -> list[str]:
    """``n_objects`` ETH-80 objects taken round robin over the categories (lowest instance of each, then the next)."""
    by_cat: dict[str, list[str]] = {}
    for lab, cat in set(zip(labels, categories)):
        by_cat.setdefault(cat, []).append(lab)
    for cat, objs in by_cat.items():
        n = len(cat)
        objs.sort(key=lambda o: (int(o[n:]) if o[n:].isdigit() else 0, o))
    out: list[str] = []
    for rank in range(max(len(v) for v in by_cat.values())):
        out += [objs[rank] for _, objs in sorted(by_cat.items()) if rank < len(objs)]
    return out[:n_objects]


def load_images(ctx: RunContext, n_objects: int, n_views: int):
    """The image set: generic folder, ETH-80 (``n_objects`` objects over the categories) or synthetic objects.

    The synthetic objects are rendered once per code version and kept on disk (``ch6-objects``).
    """
    from ...vision import ImageSet, load_eth80, load_image_folder
    from ...vision.data import parse_eth80_name

    if ctx.has_dataset("images"):
        return load_image_folder(ctx.dataset("images"), on_error="skip")
    if ctx.has_dataset("eth80"):
        # choose the objects from the file names, then read only their images
        found = {(f"{parsed[0]}{parsed[1]}", parsed[0])
                 for p in Path(ctx.dataset("eth80")).rglob("*.png") if (parsed := parse_eth80_name(p.name))}
        if not found:
            raise DataError(f"no ETH-80 image (<category><instance>-<tilt>-<pan>.png) in {ctx.dataset('eth80')}.")
        labs, cats = zip(*sorted(found))
        objs = eth80_objects(labs, cats, n_objects)
        ims = load_eth80(ctx.dataset("eth80"), categories=sorted({c for o, c in found if o in objs}),
                         instances=sorted({int(o.lstrip("abcdefghijklmnopqrstuvwxyz")) for o in objs}), on_error="skip")
        return ims.subset(np.isin(ims.labels, objs))
    memo = ctx.memory("ch6-objects").cache(_cached_objects)
    levels, labels, views, categories = cached_call(memo, int(n_objects), int(n_views), code_fingerprint())
    # the generator's photos are on 8-bit levels (k / 255): the cache keeps the levels, so this is bit for bit
    # make_objects(n_objects, n_views, random_state=0)
    return ImageSet([lv.astype(np.float64) / 255 for lv in levels], list(labels), list(views), list(categories), None,
                    "synthetic-objects")


def _cached_objects(n_objects: int, n_views: int, code: str) -> tuple[np.ndarray, list, list, list]:
    """``make_objects(n_objects, n_views, random_state=0)`` as 8-bit levels, labels, views and categories; cached
    on disk by :func:`load_images` (``ctx.cache_dir/ch6-objects``) under the sizes and ``code`` (the package's
    :func:`~mmconcepts._fingerprint.code_fingerprint`), so the three image experiments render them once."""
    from ...vision import make_objects

    ims = make_objects(n_objects, n_views, random_state=0)
    levels = np.stack([np.round(np.asarray(im) * 255) for im in ims.images]).astype(np.uint8)
    return levels, list(ims.labels), list(ims.views or []), list(ims.categories or [])






def image_note(ctx: RunContext, ims=None) -> str:
    size = f" ({len(ims)} views of {len(set(ims.labels))} objects)" if ims is not None else ""
    if ctx.has_dataset("images"):
        return f"Images: real photos in the generic layout from {ctx.dataset('images')}{size}."
    if ctx.has_dataset("eth80"):
        objs = ", ".join(sorted(set(ims.labels))) if ims is not None else "ten objects"
        return (f"Images: real ETH-80 photos ({ctx.dataset('eth80')}){size}: {objs} (round robin over the eight "
                "categories).")
    return f"Images: synthetic object photos (mmconcepts.vision.make_objects){size}."




















# ---------------------------------------------------------------------------- features
def seen_columns(X_train) -> np.ndarray:
    """Indices of the columns with a nonzero entry in the training examples ``X_train``.

    The multiplicative updates set a dictionary's weight on a feature absent from every
    training example to exactly zero after the first update, and a zero weight adds nothing
    to an internal representation, so dropping those columns from training and test data
    leaves the model and every internal-space comparison as they are (only the random
    initialisation, drawn for fewer columns, differs), while a HAC vector's 110 000 columns
    (mostly never seen in a few hundred utterances) no longer cost time at each update.
    Comparisons in a modality's own space would change (the observed test vector loses
    entries): the experiments that make them keep every column.
    """
    nnz = X_train.getnnz(axis=0) if hasattr(X_train, "getnnz") else np.count_nonzero(np.asarray(X_train), axis=0)
    return np.flatnonzero(nnz)




def entropy_bits(p: np.ndarray) -> np.ndarray:
    """Entropy (bits) of a binary variable that is 1 with probability ``p`` (elementwise)."""
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return -(p * np.log2(p) + (1 - p) * np.log2(1 - p))


def _align(y: np.ndarray, W: np.ndarray, n_bins: int) -> dict:
    """Mutual information, its Kuhn-Munkres alignment of concepts and coefficients, and the matched fractions."""
    mi = mutual_information_matrix(y, W, n_bins)
    rows, cols = linear_sum_assignment(-mi)
    matched = mi[rows, cols]
    frac = matched / entropy_bits(np.bincount(y)[np.unique(y)] / len(y))[rows]
    mask = np.ones_like(mi, dtype=bool)
    mask[rows, cols] = False
    order = list(cols[np.argsort(-matched)]) + [j for j in range(W.shape[1]) if j not in set(cols)]
    return {"mi": mi, "matched": matched, "fraction": frac, "others": mi[mask], "order": order,
            "rows": rows, "cols": cols}


#: The values of one Fig. 6.10 analysis (:func:`concept_analysis`), each a number.
CONCEPT_METRICS = ("matched.mean_mi", "matched.max_mi", "others.mean_mi", "matched.mean_fraction",
                   "matched.max_fraction", "n_specialised", "shuffled.matched.mean_mi", "shuffled.matched.max_mi")

#: A matched coefficient is counted as specialised when it captures more than this fraction of its concept's
#: entropy (the project's threshold: the thesis reads Fig. 6.10 by eye).
SPECIALISED_FRACTION = 0.5


def concept_analysis(y: np.ndarray, W: np.ndarray, n_bins: int, control_seed: int) -> tuple[dict, dict, dict]:
    """Fig. 6.10 on one set of internal coefficients: alignment, shuffled-concept control, values.

    The matched coefficient of a concept is its Kuhn-Munkres partner (maximum total mutual
    information); its *fraction* is ``I(X_l; Y_j) / H(X_l)``. The control repeats the
    analysis with the concepts permuted across examples (``control_seed``), which measures
    the estimator's bias. Returns the analysis, the control's, and the values of
    :data:`CONCEPT_METRICS`.
    """
    y = np.asarray(y)
    res = _align(y, W, n_bins)
    shuffled = _align(np.random.default_rng(control_seed).permutation(y), W, n_bins)
    values = {
        "matched.mean_mi": float(res["matched"].mean()),
        "matched.max_mi": float(res["matched"].max()),
        "others.mean_mi": float(res["others"].mean()) if res["others"].size else 0.0,
        "matched.mean_fraction": float(res["fraction"].mean()),
        "matched.max_fraction": float(res["fraction"].max()),
        "n_specialised": float(np.sum(res["fraction"] > SPECIALISED_FRACTION)),
        "shuffled.matched.mean_mi": float(shuffled["matched"].mean()),
        "shuffled.matched.max_mi": float(shuffled["matched"].max()),
    }
    return res, shuffled, values


# ---------------------------------------------------------------------------- folds of Tables 6.2-6.4, Fig. 6.10
def _labels(y: np.ndarray, n: int) -> np.ndarray:
    L = np.zeros((len(y), n))
    L[np.arange(len(y)), y] = 1.0
    return L


def space_pairs(model, X: dict, test_mods, ref_mods, cache: dict) -> dict[str, tuple]:
    """(test side, reference side) matrices of each comparison space, as :func:`crossmodal_distances` builds them.

    ``X`` holds the same examples in every modality (the test fold); internal
    representations are computed once per set of modalities and kept in ``cache``, so
    every metric and direction reuses them.
    """
    def h(mods):
        key = tuple(mods)
        if key not in cache:
            cache[key] = model.transform({m: X[m] for m in mods})
        return cache[key]

    def obs(mods):
        parts = [X[m].toarray() if hasattr(X[m], "toarray") else np.asarray(X[m]) for m in mods]
        return parts[0] if len(parts) == 1 else np.hstack(parts)

    return {"internal": (h(test_mods), h(ref_mods)),
            "reference": (model.reconstruct(h(test_mods), list(ref_mods)), obs(ref_mods)),
            "test": (obs(test_mods), model.reconstruct(h(ref_mods), list(test_mods)))}


def _recognise(model, X: dict, mods: list[str], y: np.ndarray) -> float:
    """Label recognition (Table 6.4): the fraction of examples whose best reconstructed label is theirs."""
    W = model.transform({m: X[m] for m in mods})  # noqa: N806
    return float(np.mean(model.reconstruct(W, "labels").argmax(1) == y))


def _fold(task: dict) -> dict:
    tr, te, y = task["train"], task["test"], task["y"]
    seed, ref_seed = task["learner_seed"], task["reference_seed"]
    n_classes = int(y.max()) + 1
    out: dict[str, Any] = {}
    with single_threaded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = HAC(random_state=seed, max_fit_frames=task["hac_fit_frames"]).fit([task["mfcc"][i] for i in tr])
        hist = MotionHistograms(**task["motion_features"], random_state=seed).fit([task["angles"][i] for i in tr])
        S = hac.transform(task["mfcc"])
        M = hist.transform(task["angles"])
        L = _labels(y, n_classes)
        Xtr = {"sound": S[tr], "motion": M[tr], "labels": L[tr]}
        Xte = {"sound": S[te], "motion": M[te]}
        kw = dict(n_components=task["k"], max_iter=task["n_iter"], random_state=seed)
        shuffled_motion = M[tr][np.random.default_rng(task["control_seed"]).permutation(len(tr))]
        # each learner is fitted when its metrics are computed and released after them (every learner has the
        # fold's seed, so the order changes nothing): one sound dictionary in memory at a time
        training = {"": {"sound": Xtr["sound"], "motion": Xtr["motion"]},
                    "shuffled.": {"sound": Xtr["sound"], "motion": shuffled_motion},
                    "symbolic.": Xtr}
        for prefix, train in training.items():
            model = MultimodalNMF(**kw).fit(train)
            cache: dict = {}
            for direction, (tmods, rmods) in (("sound2motion", (["sound"], ["motion"])),
                                              ("motion2sound", (["motion"], ["sound"]))):
                pairs = space_pairs(model, Xte, tmods, rmods, cache)
                for space_name, space in SPACE_NAMES(direction).items():
                    A, B = pairs[space]
                    for name, metric in METRIC_NAMES.items():
                        D = pairwise_divergence(A, B, metric)
                        out[f"{prefix}{direction}.{space_name}.{name}"] = matching_success_rate(
                            D, y[te], y[te], random_state=ref_seed)
                del pairs
            if prefix == "symbolic.":  # label recognition (Table 6.4) by the learner of all three modalities
                out["all.s2l"] = _recognise(model, Xte, ["sound"], y[te])
                out["all.m2l"] = _recognise(model, Xte, ["motion"], y[te])
                out["all.sm2l"] = _recognise(model, Xte, ["sound", "motion"], y[te])
            del model, cache
        out["sound_labels.s2l"] = _recognise(
            MultimodalNMF(**kw).fit({"sound": Xtr["sound"], "labels": Xtr["labels"]}), Xte, ["sound"], y[te])
        out["motion_labels.m2l"] = _recognise(
            MultimodalNMF(**kw).fit({"motion": Xtr["motion"], "labels": Xtr["labels"]}), Xte, ["motion"], y[te])

        # Fig. 6.10: the k = 15 learner on the training pairs, its coefficients of the training pairs
        W = MultimodalNMF(n_components=task["concept_k"], max_iter=task["n_iter"], random_state=seed).fit_transform(
            {"sound": Xtr["sound"], "motion": Xtr["motion"]})
        res, _, values = concept_analysis(y[tr], W, task["mi_bins"], task["concept_seed"])
        out["concepts"] = {"values": values, "mi": res["mi"], "order": [int(j) for j in res["order"]],
                           "rows": res["rows"], "cols": res["cols"], "fraction": res["fraction"]}
        if task["explorer"]:  # the coefficients of the concept explorer's learner (fold_explorer)
            out["concepts"]["coefficients"] = W
    return out


#: The reference stream's draws per fold (``st.seed_for("reference", draw, fold)``): the reference
#: examples, the shuffled pairs of the control, the concept permutation of Fig. 6.10's control.
REFERENCE, CONTROL, CONCEPTS = 0, 1, 2


def fold_tasks(data: dict, config, st: Streams) -> list[dict]:
    """One task per fold: its learner seed (``st.seed_for("learner", fold)``) and its reference draws.

    The reference stream draws the reference examples (:data:`REFERENCE`), the shuffled pairs
    of the control (:data:`CONTROL`) and the concept permutation of Fig. 6.10's control
    (:data:`CONCEPTS`), each fold its own. A config without ``concept_k`` or ``mi_bins``
    gets the thesis' k = 15 and 10 bins. The first fold keeps the coefficients of its Fig. 6.10
    learner for the concept explorer (:func:`fold_explorer`).
    """
    n = data["n_folds"]
    features = {"data": "joint", "method": "vq", "n_bins": config.motion_bins, "delay": 3}
    learner = st.seeds_for("learner", n)
    reference, control = st.seeds_for("reference", n, REFERENCE), st.seeds_for("reference", n, CONTROL)
    concept_k, mi_bins = int(getattr(config, "concept_k", 15)), int(getattr(config, "mi_bins", 10))
    return [{"train": np.flatnonzero(data["fold"] != f), "test": np.flatnonzero(data["fold"] == f), "y": data["y"],
             "mfcc": data["mfcc"], "angles": data["angles"], "motion_features": features, "k": config.k,
             "n_iter": config.n_iter, "learner_seed": learner[f], "reference_seed": reference[f],
             "control_seed": control[f], "hac_fit_frames": config.hac_fit_frames, "concept_k": concept_k,
             "mi_bins": mi_bins, "concept_seed": st.seed_for("reference", CONCEPTS, f), "explorer": f == 0}
            for f in range(n)]


def _fold_keys(data: dict, tasks: list[dict]) -> list[tuple]:
    """What each fold result of :func:`evaluate` depends on, besides the code."""
    data_key = (array_digest(data["mfcc"]), array_digest(data["angles"]), data["y"], data["fold"])
    return [(data_key, f, sorted(t["motion_features"].items()), t["k"], t["n_iter"], t["learner_seed"],
             t["reference_seed"], t["control_seed"], t["hac_fit_frames"], t["concept_k"], t["mi_bins"],
             t["concept_seed"]) for f, t in enumerate(tasks)]


def _cached_fold(task: dict, key: tuple, code: str) -> dict:
    """:func:`_fold`, cached on disk by :func:`evaluate` (``task`` is not hashed).

    ``key`` stands for everything ``task`` holds (digests of the data, the labels and
    folds, the fold's index, features, k, iterations and seeds), ``code`` is the package's
    :func:`~mmconcepts._fingerprint.code_fingerprint`.
    """
    return _fold(task)


def evaluate(ctx: RunContext, config, *, desc: str = "folds", seeds: Streams | None = None) -> tuple[dict, list[dict]]:
    """Pairs and per-fold results.

    Each fold's result is cached on disk as the fold ends (the disk cache of :meth:`RunContext.memory <mmconcepts.engine.context.RunContext.memory>` under
    ``ctx.cache_dir/ch6-folds``), so experiments sharing the folds compute them once and an
    interrupted run resumes from the folds it finished. ``seeds`` replaces the streams
    of ``config.seed`` (to vary one alone: :meth:`~mmconcepts.engine.Streams.rooted`).
    """
    st = seeds if seeds is not None else streams(config.seed)
    data = load_pairs(ctx, n_per_speaker=config.n_per_speaker, n_motion=config.n_motion, n_folds=config.n_folds,
                      streams=st)
    tasks = fold_tasks(data, config, st)
    memo = ctx.memory("ch6-folds").cache(_cached_fold, ignore=["task"])
    code = code_fingerprint()
    return data, ctx.parallel_cached(memo, [(t, key, code) for t, key in zip(tasks, _fold_keys(data, tasks))],
                                     desc=desc)


def fold_explorer(data: dict, folds: list[dict]) -> Explorer | None:
    """The concept explorer of the folds' runs: the atoms of the first fold's Fig. 6.10 learner.

    That learner (k = ``concept_k``, sound and motion) is fitted on the first fold's training
    pairs; its coefficients of those pairs (kept by the fold, so nothing is fitted again) give
    the cards: each atom's keywords, and the utterances and motion records of the pairs it
    makes up most (:func:`~mmconcepts.experiments.protocols.explorer.recordings_explorer`).
    None when the fold kept no coefficients.
    """
    W = folds[0]["concepts"].get("coefficients")
    if W is None:
        return None
    rows = np.flatnonzero(data["fold"] != 0)
    note = explorer_note(f"the k = {W.shape[1]} learner of Fig. 6.10 fitted on the {len(rows)} training pairs of fold 1 "
                         f"of {data['n_folds']} (sound and motion)", "pairs",
                         f"{UTTERANCES} and the first pair's motion record")
    return recordings_explorer(W, rows, speech=data["speech"], motion=data["motion"], motion_of=data["motion_idx"],
                               note=note)


def summarise(folds: list[dict], keys) -> dict[str, float]:
    """Mean over folds of each key, and ``<key>_std``."""
    out = {}
    for k in keys:
        v = np.array([f[k] for f in folds])
        out[k] = float(v.mean())
        out[f"{k}_std"] = float(v.std())
    return out


def fold_samples(folds: list[dict], metrics: dict, rename: Callable[[str], str | None] = lambda k: k) -> dict[str, list[float]]:
    """Per-fold (or per-repetition) values of every key that is a metric (``rename``: key -> metric name or None)."""
    out: dict[str, list[float]] = {}
    for k in folds[0]:
        name = rename(k)
        if name is not None and name in metrics:
            out[name] = [float(f[k]) for f in folds]
    return out


# ---------------------------------------------------------------------------- image features
def _locals_chunk(images: list) -> tuple[list, list]:
    from ...vision import THESIS_DESCRIPTORS, ImageFeatures

    with single_threaded():
        colors, keypoints = ImageFeatures(THESIS_DESCRIPTORS).extract_locals(images)
    assert colors is not None and keypoints is not None  # the thesis' descriptors use both
    return colors, keypoints


def image_locals(ctx: RunContext, ims, *, chunk: int = 40) -> tuple[list, list]:
    """Colour and keypoint local features of every image (cached on disk per image set).

    They do not depend on any codebook, so the experiments fit their codebooks on each
    repetition's training images from these (:meth:`ImageFeatures.fit_locals`) instead of
    extracting them again. The cache is the disk cache of :meth:`RunContext.memory <mmconcepts.engine.context.RunContext.memory>` under
    ``ctx.cache_dir/ch6-image-locals``; key: the images (shapes, types and bytes) and
    :func:`code_fingerprint`.
    """
    images = list(ims.images) if hasattr(ims, "images") else list(ims)
    memo = ctx.memory("ch6-image-locals").cache(_cached_locals, ignore=["ctx", "images", "chunk"])
    return cached_call(memo, ctx, images, chunk, array_digest(images), code_fingerprint())


def _cached_locals(ctx: RunContext, images: list, chunk: int, digest: str, code: str) -> tuple[list, list]:
    """The local features of ``images``, ``chunk`` images per task of ``ctx.parallel``; cached by
    :func:`image_locals` under the images' ``digest`` and ``code`` (the package's
    :func:`~mmconcepts._fingerprint.code_fingerprint`); ``ctx``, ``images`` and ``chunk`` are not hashed."""
    parts = ctx.parallel(_locals_chunk, [images[i:i + chunk] for i in range(0, len(images), chunk)],
                         desc="image features")
    return [c for p in parts for c in p[0]], [k for p in parts for k in p[1]]


def image_ids(ims) -> list[str]:
    """A recording id per image: its file name, else its object and view, else its index."""
    paths = getattr(ims, "paths", None)
    if paths is not None and all(p is not None for p in paths):
        return [str(p) for p in paths]
    views = getattr(ims, "views", None)
    if views is not None:
        return [f"{lab}-{v}" for lab, v in zip(ims.labels, views)]
    return [f"image {i}" for i in range(len(ims.labels))]


def image_concepts(labels, objects_of_concept) -> np.ndarray:
    """Concept of each image (index of its object in ``objects_of_concept``; -1 for unused objects)."""
    index = {o: c for c, o in enumerate(objects_of_concept)}
    return np.array([index.get(lab, -1) for lab in labels])
