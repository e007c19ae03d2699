"""Shared machinery of the chapter-6 experiments: paired multimodal examples and fold evaluation.

Thesis sections 6.5-6.6. Data:

- sound: the utterances of one speaker (speaker 1, as in the thesis) of the chapter 5
  corpus (:func:`mmconcepts.experiments._ch5_common.load_corpus`: ``--data acorns=DIR``,
  ``--data audio=DIR`` or the synthetic corpus), each with one keyword; represented by HAC
  (22 MFCC, codebooks 150/150/100, lags 2 and 5) with codebooks fitted per training fold;
- motion: Choreo2 records (``--data choreo2=DIR`` or the synthetic Choreo2-like set), one
  gesture each; the relative rotations along the limbs as Euler angles
  (:func:`mmconcepts.motion.orientation_angles`) turned into joint angle-velocity
  histograms (:class:`~mmconcepts.motion.MotionHistograms`) fitted per training fold; or
  real Kinect skeletons of ten MSR Action3D actions (``--data msr=DIR``, positions only, so
  the 16 joint angles of :func:`mmconcepts.motion.joint_angles`);
- labels: the concept of each example as a one-hot vector (the symbolic modality).

Concepts: keyword k is associated with gesture ``mapping[k]`` by a random bijection drawn
from the seed (the thesis' Table 6.1 is one such mapping). Examples are paired by
concept: each utterance gets a motion record of its concept's gesture, drawn without
replacement while possible.

:func:`evaluate` runs every fold (stratified k-fold over the paired examples) through
``ctx.parallel`` and caches the fold results on disk, so the experiments of Tables 6.2,
6.3 and 6.4 share one computation.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from .. import __version__
from ..errors import ConvergenceWarning, DataError
from ..motion import MotionHistograms, joint_angles, load_choreo2, load_msr_action3d, orientation_angles
from ..multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate
from ..sound.features import MFCCConfig
from ..sound.hac import HAC
from . import _ch5_common as ch5
from .base import RunContext

__all__ = ["load_pairs", "evaluate", "data_source_note", "SPACE_NAMES", "METRIC_NAMES"]

#: Metric names of the thesis' tables and the metric used for each.
METRIC_NAMES = {"kl": "kl", "euclidean": "euclidean", "cosine": "cosine"}


def SPACE_NAMES(direction: str) -> dict[str, str]:
    """Thesis space name -> comparison space of :func:`crossmodal_distances` for a direction."""
    if direction == "sound2motion":
        return {"internal": "internal", "motion": "reference", "sound": "test"}
    return {"internal": "internal", "sound": "reference", "motion": "test"}


#: The ten MSR Action3D actions used as gestures with ``--data msr=DIR`` (arms, both arms,
#: legs, whole body: 1 high arm wave, 2 horizontal arm wave, 5 forward punch, 6 high throw,
#: 10 hand clap, 12 side boxing, 13 bend, 14 forward kick, 15 side kick, 16 jogging).
MSR_ACTIONS = (1, 2, 5, 6, 10, 12, 13, 14, 15, 16)


def data_source_note(ctx: RunContext) -> str:
    if "choreo2" in ctx.data:
        motion = f"real Choreo2 records from {ctx.data['choreo2']}"
    elif "msr" in ctx.data:
        motion = (f"real Kinect skeletons of MSR Action3D from {ctx.data['msr']} (actions {MSR_ACTIONS}, joint "
                  "angles of the limb model)")
    else:
        motion = "the synthetic Choreo2-like set (mmconcepts.motion.synthetic.make_choreo2)"
    return f"Motion: {motion}. " + ch5.data_source_note(ctx)


def _motion_dataset(ctx: RunContext, n_records: int):
    """The motion records and the function giving their angle trajectories."""
    if "choreo2" in ctx.data:
        path = Path(ctx.data["choreo2"])
        return load_choreo2(path if path.suffix == ".json" else path / "choreo2.json", on_error="skip"), orientation_angles
    if "msr" in ctx.data:
        return load_msr_action3d(ctx.data["msr"], actions=MSR_ACTIONS, on_error="skip"), joint_angles
    from ..motion.synthetic import make_choreo2

    return make_choreo2(data_home=ctx.cache_dir, random_state=0, n_records=n_records), orientation_angles


def load_pairs(ctx: RunContext, *, n_per_speaker: int, n_motion: int, seed: int) -> dict:
    """Paired examples: HAC-ready MFCC sequences, joint-angle trajectories and concept ids."""
    sub, first, keywords, concept = ch5.first_speaker(ctx, n_per_speaker=n_per_speaker)
    kw = np.asarray(keywords)[concept]
    mfccs = ch5.corpus_mfcc(ctx, sub, MFCCConfig(n_mfcc=22))
    ds, angle_fn = _motion_dataset(ctx, n_motion)
    gestures, angles = [], []
    for rec in ds:
        if len(rec.labels) != 1:
            raise DataError(f"motion record {rec.record_id} has {len(rec.labels)} gestures; chapter 6 needs one each.")
        gestures.append(int(rec.labels[0]))
        angles.append(np.ascontiguousarray(angle_fn(rec), dtype=np.float64))
    gestures = np.asarray(gestures)
    gesture_ids = sorted(set(gestures.tolist()))
    if len(gesture_ids) < len(keywords):
        raise DataError(f"{len(keywords)} keywords but only {len(gesture_ids)} gestures: cannot map concepts one to one.")
    rng = np.random.default_rng(seed)
    mapping = dict(zip(keywords, rng.permutation(gesture_ids)[: len(keywords)].tolist()))
    motion_idx = np.empty(len(kw), dtype=np.int64)
    for k in keywords:
        want = np.flatnonzero(kw == k)
        pool = rng.permutation(np.flatnonzero(gestures == mapping[k]))
        if pool.size == 0:
            raise DataError(f"no motion record of gesture {mapping[k]} for keyword {k!r}.")
        reps = int(np.ceil(want.size / pool.size))
        motion_idx[want] = np.concatenate([rng.permutation(pool) for _ in range(reps)])[: want.size]
    return {"mfcc": mfccs, "angles": [angles[i] for i in motion_idx], "y": concept, "keywords": keywords,
            "mapping": {k: int(v) for k, v in mapping.items()}, "speaker": first,
            "n_motion_records": len(ds)}


def _labels(y: np.ndarray, n: int) -> np.ndarray:
    L = np.zeros((len(y), n))
    L[np.arange(len(y)), y] = 1.0
    return L


def _match(model, Xte: dict, y: np.ndarray, test_mods, ref_mods, space: str, metric: str, seed: int) -> float:
    D = crossmodal_distances(model, {m: Xte[m] for m in test_mods}, {m: Xte[m] for m in ref_mods},
                             space=space, metric=metric)
    return matching_success_rate(D, y, y, random_state=seed)


def _fold(task: dict) -> dict:
    tr, te, y, seed = task["train"], task["test"], task["y"], task["seed"]
    n_classes = int(y.max()) + 1
    out: dict[str, float] = {}
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = HAC(random_state=seed).fit([task["mfcc"][i] for i in tr])
        hist = MotionHistograms(**task["motion_features"], random_state=seed).fit([task["angles"][i] for i in tr])
        S = hac.transform(task["mfcc"])
        M = hist.transform(task["angles"])
        L = _labels(y, n_classes)
        Xtr = {"sound": S[tr], "motion": M[tr], "labels": L[tr]}
        Xte = {"sound": S[te], "motion": M[te]}
        kw = dict(n_components=task["k"], max_iter=task["n_iter"], random_state=seed)
        rng = np.random.default_rng(seed)
        shuffled_motion = M[tr][rng.permutation(len(tr))]
        fits = {
            "plain": MultimodalNMF(**kw).fit({"sound": Xtr["sound"], "motion": Xtr["motion"]}),
            "shuffled": MultimodalNMF(**kw).fit({"sound": Xtr["sound"], "motion": shuffled_motion}),
            "symbolic": MultimodalNMF(**kw).fit(Xtr),
            "sound_labels": MultimodalNMF(**kw).fit({"sound": Xtr["sound"], "labels": Xtr["labels"]}),
            "motion_labels": MultimodalNMF(**kw).fit({"motion": Xtr["motion"], "labels": Xtr["labels"]}),
        }
        for prefix, model in (("", fits["plain"]), ("shuffled.", fits["shuffled"]), ("symbolic.", fits["symbolic"])):
            for direction, (tmods, rmods) in (("sound2motion", (["sound"], ["motion"])),
                                              ("motion2sound", (["motion"], ["sound"]))):
                for space_name, space in SPACE_NAMES(direction).items():
                    for metric in METRIC_NAMES:
                        out[f"{prefix}{direction}.{space_name}.{metric}"] = _match(
                            model, Xte, y[te], tmods, rmods, space, metric, seed)
        # label recognition (Table 6.4): the best reconstructed label
        def recognise(model, mods):
            W = model.transform({m: Xte[m] for m in mods})
            return float(np.mean(model.reconstruct(W, "labels").argmax(1) == y[te]))

        out["sound_labels.s2l"] = recognise(fits["sound_labels"], ["sound"])
        out["motion_labels.m2l"] = recognise(fits["motion_labels"], ["motion"])
        out["all.s2l"] = recognise(fits["symbolic"], ["sound"])
        out["all.m2l"] = recognise(fits["symbolic"], ["motion"])
        out["all.sm2l"] = recognise(fits["symbolic"], ["sound", "motion"])
    return out


def evaluate(ctx: RunContext, config, *, desc: str = "folds") -> tuple[dict, list[dict]]:
    """Pairs and per-fold results (cached on disk under ``ctx.cache_dir/ch6-folds``)."""
    from sklearn.model_selection import StratifiedKFold

    data = load_pairs(ctx, n_per_speaker=config.n_per_speaker, n_motion=config.n_motion, seed=config.seed)
    y = data["y"]
    n_folds = min(config.n_folds, int(np.bincount(y).min()))
    splits = list(StratifiedKFold(n_folds, shuffle=True, random_state=config.seed).split(np.zeros(len(y)), y))
    features = {"data": "joint", "method": "vq", "n_bins": config.motion_bins, "delay": 3}
    h = hashlib.sha1()
    for a in data["mfcc"]:
        h.update(np.ascontiguousarray(a).tobytes())
    for a in data["angles"]:
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(pickle.dumps((y.tobytes(), sorted(features.items()), config.k, config.n_iter, n_folds, config.seed,
                           __version__, 2)))  # 2: MultimodalNMF random init
    cache = Path(ctx.cache_dir) / "ch6-folds"
    cache.mkdir(parents=True, exist_ok=True)
    key = cache / f"{h.hexdigest()}.pkl"
    if key.exists():
        try:
            return data, pickle.loads(key.read_bytes())
        except (OSError, pickle.UnpicklingError, EOFError):
            key.unlink(missing_ok=True)
    tasks = [{"train": tr, "test": te, "y": y, "mfcc": data["mfcc"], "angles": data["angles"],
              "motion_features": features, "k": config.k, "n_iter": config.n_iter,
              "seed": config.seed * 1000 + i} for i, (tr, te) in enumerate(splits)]
    folds = ctx.parallel(_fold, tasks, desc=desc)
    tmp = key.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_bytes(pickle.dumps(folds))
    os.replace(tmp, key)
    return data, folds


def summarise(folds: list[dict], keys) -> dict[str, float]:
    """Mean over folds of each key, and ``<key>_std``."""
    out = {}
    for k in keys:
        v = np.array([f[k] for f in folds])
        out[k] = float(v.mean())
        out[f"{k}_std"] = float(v.std())
    return out
