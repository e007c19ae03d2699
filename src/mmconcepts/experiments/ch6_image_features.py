"""ch6-image-features: image <-> sound associations with each image descriptor set (Fig 6.4).

Thesis section 6.6.1 ("Images and sound: comparison of the image representations").
Utterances of speaker 1 (one keyword each) are paired by concept with photos of objects
(one object per concept, a random keyword <-> object bijection). Each repetition splits
the pairs into training (60 %), test (20 %) and reference (20 %) examples, stratified by
concept, so that reference examples are "always taken outside the two previous sets". The
HAC codebooks and the image codebooks are fitted on the training examples; one multimodal
NMF (I-divergence, k = 50, 50 iterations) is learnt per image descriptor set, alone or all
combined, and tested both ways: Image -> Sound and Sound -> Image, comparing internal
representations with the cosine dissimilarity against one reference example per concept.

Image descriptor sets (:class:`mmconcepts.vision.ImageFeatures`, standing in for the
robot's SURF and HSV superpixel features): ``keypoints`` (dense SIFT-like words, "SURF"),
``keypoint_pairs`` ("SURF mid-couples"), ``color`` (HSV superpixel words),
``color_pairs`` and ``color_triplets`` (colour mid-couples and triplets), and ``all``.
Images: the synthetic objects of :func:`mmconcepts.vision.make_objects`, or
``--data images=DIR`` (generic layout) or ``--data eth80=DIR`` (the first objects).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from threadpoolctl import threadpool_limits

from ..errors import ConvergenceWarning, DataError
from ..multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate
from ..sound.features import MFCCConfig
from ..sound.hac import HAC
from . import _ch5_common as ch5
from .base import Claim, Experiment, Result, RunContext, Table
from .registry import register

__all__ = ["Config", "run", "SETS"]

SETS = ("keypoints", "keypoint_pairs", "color", "color_pairs", "color_triplets", "all")


@dataclass(frozen=True)
class Config:
    """Sizes; ``n_per_speaker`` and ``n_views`` select the generated data."""

    n_per_speaker: int = 1000
    n_views: int = 41
    n_repeats: int = 10
    k: int = 50
    n_iter: int = 50
    seed: int = 0

    @classmethod
    def quick(cls) -> "Config":
        return cls(n_per_speaker=250, n_views=24, n_repeats=3)

    @classmethod
    def full(cls) -> "Config":
        return cls()


def load_images(ctx: RunContext, n_objects: int, n_views: int):
    """The image set: generic folder, ETH-80 (first ``n_objects`` objects) or synthetic objects."""
    from ..vision import load_eth80, load_image_folder, make_objects

    if "images" in ctx.data:
        return load_image_folder(ctx.data["images"], on_error="skip")
    if "eth80" in ctx.data:
        ims = load_eth80(ctx.data["eth80"], on_error="skip")
        keep = np.isin(ims.labels, sorted(set(ims.labels))[:n_objects])
        return ims.subset(keep)
    return make_objects(n_objects, n_views, random_state=0)


def _data_note(ctx: RunContext) -> str:
    if "images" in ctx.data:
        img = f"images from {ctx.data['images']}"
    elif "eth80" in ctx.data:
        img = f"real ETH-80 photos from {ctx.data['eth80']} (the first 10 objects)"
    else:
        img = "synthetic object photos (mmconcepts.vision.make_objects)"
    return f"Images: {img}. " + ch5.data_source_note(ctx)


def _repeat(task: dict) -> dict:
    from ..vision import ImageFeatures, THESIS_DESCRIPTORS, stack_descriptors

    y, seed = task["y"], task["seed"]
    tr, te, ref = task["train"], task["test"], task["ref"]
    images, mfcc = task["images"], task["mfcc"]
    out = {}
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = HAC(random_state=seed).fit([mfcc[i] for i in tr])
        S = hac.transform(mfcc)
        feats = ImageFeatures(THESIS_DESCRIPTORS, random_state=seed)
        feats.fit([images[i] for i in np.unique(task["image_of"][tr])])
        F = feats.transform(images)
        F["all"] = stack_descriptors(F, list(THESIS_DESCRIPTORS))
        idx = task["image_of"]
        for name in SETS:
            I = F[name][idx]
            model = MultimodalNMF(task["k"], max_iter=task["n_iter"], random_state=seed).fit(
                {"sound": S[tr], "image": I[tr]})
            for key, (tm, rm) in (("i2s", ("image", "sound")), ("s2i", ("sound", "image"))):
                X = {"sound": S, "image": I}
                D = crossmodal_distances(model, {tm: X[tm][te]}, {rm: X[rm][ref]}, space="internal", metric="cosine")
                out[f"{name}.{key}"] = matching_success_rate(D, y[te], y[ref], random_state=seed)
    return out


def run(config: Config, ctx: RunContext) -> Result:
    from sklearn.model_selection import train_test_split

    sub, first, keywords, y = ch5.first_speaker(ctx, n_per_speaker=config.n_per_speaker)
    kw = np.asarray(keywords)[y]
    mfcc = ch5.corpus_mfcc(ctx, sub, MFCCConfig(n_mfcc=22))
    ims = load_images(ctx, len(keywords), config.n_views)
    objects = sorted(set(ims.labels))
    if len(objects) < len(keywords):
        raise DataError(f"{len(keywords)} keywords but only {len(objects)} objects: cannot map concepts one to one.")
    rng = np.random.default_rng(config.seed)
    mapping = dict(zip(keywords, rng.permutation(objects)[: len(keywords)].tolist()))
    labels = np.asarray(ims.labels)
    image_of = np.empty(len(y), dtype=np.int64)
    for k in keywords:
        want = np.flatnonzero(kw == k)
        pool = np.flatnonzero(labels == mapping[k])
        reps = int(np.ceil(want.size / pool.size))
        image_of[want] = np.concatenate([rng.permutation(pool) for _ in range(reps)])[: want.size]
    tasks = []
    for r in range(config.n_repeats):
        s = int(rng.integers(2**31 - 1))
        tr, rest = train_test_split(np.arange(len(y)), train_size=0.6, stratify=y, random_state=s)
        te, ref = train_test_split(rest, train_size=0.5, stratify=y[rest], random_state=s)
        tasks.append({"train": tr, "test": te, "ref": ref, "y": y, "mfcc": mfcc, "images": list(ims.images),
                      "image_of": image_of, "k": config.k, "n_iter": config.n_iter, "seed": config.seed * 1000 + r})
    reps = ctx.parallel(_repeat, tasks, desc="repetitions")
    metrics: dict[str, float] = {"chance": 1.0 / len(keywords)}
    for name in SETS:
        for key in ("i2s", "s2i"):
            v = np.array([r[f"{name}.{key}"] for r in reps])
            metrics[f"{name}.{key}"] = float(v.mean())
            metrics[f"{name}.{key}_std"] = float(v.std())
    singles = [s for s in SETS if s != "all"]
    metrics["best_single.i2s"] = max(metrics[f"{s}.i2s"] for s in singles)
    metrics["best_single.s2i"] = max(metrics[f"{s}.s2i"] for s in singles)
    best = max(singles, key=lambda s: metrics[f"{s}.i2s"] + metrics[f"{s}.s2i"])
    metrics["best_single_is_color"] = float(best.startswith("color"))
    rows = [[s, metrics[f"{s}.i2s"], metrics[f"{s}.i2s_std"], metrics[f"{s}.s2i"], metrics[f"{s}.s2i_std"]] for s in SETS]
    fig = Figure(figsize=(7, 3.5))
    ax = fig.subplots()
    x = np.arange(len(SETS))
    for j, key in enumerate(("i2s", "s2i")):
        ax.bar(x + (j - 0.5) * 0.4, [metrics[f"{s}.{key}"] for s in SETS], 0.4,
               yerr=[metrics[f"{s}.{key}_std"] for s in SETS], label={"i2s": "I -> S", "s2i": "S -> I"}[key])
    ax.axhline(metrics["chance"], color="k", ls=":", label="chance")
    ax.set_xticks(x, SETS, rotation=20, fontsize=8)
    ax.set_ylabel("success rate")
    ax.set_ylim(0, 1)
    ax.set_title("Fig. 6.4: image descriptor sets")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return Result(
        metrics=metrics,
        tables={"fig6_4": Table("Fig. 6.4: success rates by image descriptor set",
                                ["descriptors", "I -> S", "std", "S -> I", "std"], rows)},
        figures={"fig6_4": fig},
        notes=[_data_note(ctx),
               f"Speaker {first}: {len(y)} utterances paired with {len(ims)} images of {len(objects)} objects; "
               f"{config.n_repeats} repetitions of a stratified 60/20/20 train/test/reference split; internal space, "
               f"cosine; k = {config.k}, {config.n_iter} iterations. Best single set: {best}.",
               "Concepts: " + ", ".join(f"{k} -> {v}" for k, v in mapping.items()) + "."],
    )


register(Experiment(
    id="ch6-image-features",
    title="Image <-> sound associations by image descriptor set",
    thesis_ref="Section 6.6.1, Fig. 6.4",
    config_cls=Config,
    run=run,
    reference={},
    claims=[
        Claim("Every image descriptor set supports the association with sound, in both directions, above chance.",
              "min(keypoints.i2s, keypoint_pairs.i2s, color.i2s, color_pairs.i2s, color_triplets.i2s) > 2 * chance and "
              "min(keypoints.s2i, keypoint_pairs.s2i, color.s2i, color_pairs.s2i, color_triplets.s2i) > 2 * chance"),
        Claim("The system is robust to adding information: all descriptor sets together do nearly as well as the best "
              "set alone (within 0.1).",
              "all.i2s > best_single.i2s - 0.1 and all.s2i > best_single.s2i - 0.1"),
        Claim("The colour representations work best (on the thesis' robot images).", "best_single_is_color == 1"),
    ],
    datasets=("acorns", "audio", "images", "eth80"),
    description=__doc__.split("\n\n")[0],
))
