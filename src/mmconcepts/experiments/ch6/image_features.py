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
Data: real FSDD spoken digits (one speaker) and real ETH-80 objects (ten objects round robin
over the eight categories) when present; else the synthetic Caregiver-like corpus and the
synthetic objects of :func:`mmconcepts.vision.make_objects`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from ...errors import ConvergenceWarning, DataError
from ...multimodal import MultimodalNMF, matching_success_rate, pairwise_divergence
from ...sound.hac import HAC
from . import protocol as common
from ..protocols.explorer import UTTERANCES, explorer_note, recordings_explorer
from ...engine import (
    Claim,
    Experiment,
    PresetConfig,
    Result,
    RunContext,
    SampleUnit,
    Table,
    above_chance_rule,
    concept_parts,
    register,
)
from ..._jit import single_threaded

__all__ = ["Config", "compute", "present", "run", "SETS", "split_repetition"]

SETS = ("keypoints", "keypoint_pairs", "color", "color_pairs", "color_triplets", "all")
SINGLES = tuple(s for s in SETS if s != "all")
SPLIT = (0.6, 0.2, 0.2)  # training, test, reference
#: The sample unit of every per-repetition metric.
REPETITIONS = "repetitions"
#: Our margin for "nearly as well as the best of the representations" (the thesis gives none).
NEARLY = 0.1


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes; ``n_per_speaker`` and ``n_views`` select the generated data."""

    n_per_speaker: int = 1000
    n_views: int = 41
    n_repeats: int = 10
    k: int = 50
    n_iter: int = 50
    seed: int = 0

    hac_fit_frames: int = 100_000  # training frames (at most) for each HAC codebook: HAC's max_fit_frames
    # five repetitions, the fewest units behind a decided claim (the thesis: "several times")
    QUICK = dict(n_per_speaker=250, n_views=24, n_repeats=5, hac_fit_frames=20_000)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_per_speaker=50, n_views=6, n_repeats=2, k=12, n_iter=30, hac_fit_frames=5_000)


def load_images(ctx: RunContext, n_objects: int, n_views: int):
    """The image set (see :func:`mmconcepts.experiments.ch6.protocol.load_images`)."""
    return common.load_images(ctx, n_objects, n_views)


def _data_note(ctx: RunContext, speech: dict | None = None, ims=None) -> str:
    return common.image_note(ctx, ims) + " " + common.speech_note(ctx, speech)


def _repeat(task: dict) -> dict:
    from ...vision import THESIS_DESCRIPTORS, ImageFeatures, stack_descriptors

    y, ref_seed = task["y"], task["reference_seed"]
    tr, te, ref = task["train"], task["test"], task["ref"]
    c_loc, k_loc, mfcc = task["c_loc"], task["k_loc"], task["mfcc"]
    out: dict = {}
    with single_threaded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        learner = task["learner_seeds"]  # the HAC codebook, the image codebooks, the NMF
        hac = HAC(random_state=learner[0], max_fit_frames=task["hac_fit_frames"]).fit([mfcc[i] for i in tr])
        S = hac.transform(mfcc)
        S = S[:, common.seen_columns(S[tr])]  # internal-space comparisons only: unseen features change nothing
        feats = ImageFeatures(THESIS_DESCRIPTORS, random_state=learner[1])
        used = np.unique(task["image_of"][tr])
        feats.fit_locals([c_loc[i] for i in used], [k_loc[i] for i in used])
        F = feats.transform_locals(c_loc, k_loc)
        F["all"] = stack_descriptors(F, list(THESIS_DESCRIPTORS))
        idx = task["image_of"]
        for name in SETS:
            I = F[name][idx]
            I = I[:, common.seen_columns(I[tr])]
            model = MultimodalNMF(task["k"], max_iter=task["n_iter"], random_state=learner[2])
            data = {"sound": S[tr], "image": I[tr]}
            if task["explorer"] and name == "all":  # the concept explorer's learner
                out["coefficients"] = model.fit_transform(data)
            else:  # only the dictionary is used: no coefficients of the training examples
                model.fit(data)
            X = {"sound": S, "image": I}
            H = {(m, part): model.transform({m: X[m][rows]}) for m in X for part, rows in (("test", te), ("ref", ref))}
            for key, (tm, rm) in (("i2s", ("image", "sound")), ("s2i", ("sound", "image"))):
                # internal space, cosine; references from the reference part (outside training and test)
                D = pairwise_divergence(H[tm, "test"], H[rm, "ref"], "cosine")
                out[f"{name}.{key}"] = matching_success_rate(D, y[te], y[ref], random_state=ref_seed)
    return out


def split_repetition(y: np.ndarray, image_concept: np.ndarray, frng: np.random.Generator,
                     drng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One repetition's split and pairing: the part of every utterance (0 training, 1 test, 2 reference) and its view.

    The utterances and each object's views are split 60/20/20 by concept (``frng``) and every
    utterance gets a view of its concept from its own part (``drng``), so a view serves in one
    part only.
    """
    part_y = concept_parts(y, SPLIT, frng)
    part_i = concept_parts(image_concept, SPLIT, frng)
    return part_y, common.pair_within_parts(y, part_y, image_concept, part_i, drng, "image")


def compute(config: Config, ctx: RunContext) -> Result:
    """Success rates by descriptor set over the repetitions (no figure: :func:`present` draws the metrics)."""
    st = common.streams(config.seed)
    speech = common.load_speech(ctx, n_per_speaker=config.n_per_speaker, streams=st)
    keywords, y, mfcc = speech["keywords"], speech["y"], speech["mfcc"]
    ims = load_images(ctx, len(keywords), config.n_views)
    objects = sorted(set(ims.labels))
    if len(objects) < len(keywords):
        raise DataError(f"{len(keywords)} keywords but only {len(objects)} objects: cannot map concepts one to one.")
    drng, frng = st.rng("data"), st.rng("splits")
    object_of = drng.permutation(objects)[: len(keywords)].tolist()
    mapping = dict(zip(keywords, object_of))
    image_concept = common.image_concepts(ims.labels, object_of)
    c_loc, k_loc = common.image_locals(ctx, ims)
    view_ids = common.image_ids(ims)
    tasks, grouping = [], []
    for r in range(config.n_repeats):
        part_y, image_of = split_repetition(y, image_concept, frng, drng)
        grouping.append((common.example_sources(sound=speech["ids"], image=[view_ids[i] for i in image_of]), part_y))
        tasks.append({"train": np.flatnonzero(part_y == 0), "test": np.flatnonzero(part_y == 1),
                      "ref": np.flatnonzero(part_y == 2), "y": y, "mfcc": mfcc, "c_loc": c_loc, "k_loc": k_loc,
                      "image_of": image_of, "k": config.k, "n_iter": config.n_iter,
                      "learner_seeds": st.seeds_for("learner", 3, r), "hac_fit_frames": config.hac_fit_frames,
                      "reference_seed": st.seed_for("reference", r), "explorer": r == 0})
    split_groups = {"repetitions": common.part_split_groups(
        "sound recordings and object views (each example: one utterance and one view of its concept's object)",
        grouping)}
    reps = ctx.parallel(_repeat, tasks, desc="repetitions")
    W = reps[0].pop("coefficients")
    explorer = recordings_explorer(
        W, tasks[0]["train"], speech=speech, images=ims, image_of=tasks[0]["image_of"], image_ids=view_ids,
        note=explorer_note(f"the k = {W.shape[1]} learner of the first repetition on all the descriptor sets, fitted "
                           f"on its {len(tasks[0]['train'])} training examples (sound and image)", "examples",
                           f"{UTTERANCES} and their object views"))
    metrics: dict[str, float] = {"chance": 1.0 / len(keywords)}
    for name in SETS:
        for key in ("i2s", "s2i"):
            v = np.array([r[f"{name}.{key}"] for r in reps])
            metrics[f"{name}.{key}"] = float(v.mean())
            metrics[f"{name}.{key}_std"] = float(v.std())
    for name in SETS:  # both directions together, per repetition (a linear summary: its samples are exact)
        metrics[f"{name}.both"] = float(np.mean([metrics[f"{name}.i2s"], metrics[f"{name}.s2i"]]))
    samples = common.fold_samples(reps, metrics)
    for name in SETS:
        samples[f"{name}.both"] = [float((r[f"{name}.i2s"] + r[f"{name}.s2i"]) / 2) for r in reps]
    # descriptive oracle only (a maximum over sets chosen on the test results; no claim uses it): the set best on
    # average, with that set's per-repetition values as samples
    for key in ("i2s", "s2i"):
        top = max(SINGLES, key=lambda s: metrics[f"{s}.{key}"])
        metrics[f"best_single.{key}"] = metrics[f"{top}.{key}"]
        samples[f"best_single.{key}"] = list(samples[f"{top}.{key}"])
    best = max(SINGLES, key=lambda s: metrics[f"{s}.both"])
    rows = [[s, metrics[f"{s}.i2s"], metrics[f"{s}.i2s_std"], metrics[f"{s}.s2i"], metrics[f"{s}.s2i_std"]] for s in SETS]
    held_out = SPLIT[1] + SPLIT[2]
    return Result(
        metrics=metrics,
        samples=samples,
        sample_units={name: REPETITIONS for name in samples},
        units={REPETITIONS: SampleUnit.splits(held_out, f"{config.n_repeats} random 60/20/20 training / test / "
                                                         f"reference splits of one data set ({held_out:.0%} held out)")},
        split_groups=split_groups,
        explorer=explorer,
        tables={"fig6_4": Table("Fig. 6.4: success rates by image descriptor set",
                                ["descriptors", "I -> S", "std", "S -> I", "std"], rows)},
        notes=[_data_note(ctx, speech, ims),
               f"Speaker {speech['speaker']}: {len(y)} utterances paired with views of {len(keywords)} objects; "
               f"{config.n_repeats} repetitions; in each, the utterances and each object's views are split 60/20/20 "
               "into training / test / reference parts by concept and paired within their part (a view never "
               "serves in two parts: split_groups counts the recordings behind both a training and a held-out "
               "example, 0); internal space, cosine, one reference example per concept; "
               f"k = {config.k}, {config.n_iter} iterations. Best single set (descriptive): {best}.",
               "Concepts (random bijection): " + ", ".join(f"{k} -> {v}" for k, v in mapping.items()) + ".",
               "Uncertainty: each success rate is the mean over the repetitions, with the per-repetition values as "
               "samples (all sets scored on the same repetitions, so compared pairwise), declared as repeated random "
               f"splits of one data set with {held_out:.0%} held out (test and reference: corrected resampled t). "
               "'<set>.both' is the mean of I -> S and S -> I. best_single.* (the single set with the best mean) "
               "is a descriptive oracle chosen on the test results: no claim uses it.",
               "Features never seen in training (most of a HAC vector's 110 000 columns) are dropped before learning: the "
               "multiplicative updates give them exactly zero weight in the dictionary, so the internal representations, "
               "the only space compared here, are unchanged.",
               "Object views: the thesis' concepts are objects, one per concept (its images are frames of a robot's "
               "interaction), so training and held-out examples show the same object, as there; each view (photo) "
               "is one recording, on one side only.",
               "Claims reclassified: 'robust to adding information' ('nearly as well as the best of the "
               f"representations') is ours, with our margin {NEARLY:g} (the thesis gives none); 'every set above "
               "twice chance' is ours (a bar of ours; the thesis states no such claim).",
               "Thesis ambiguities of Fig. 6.4 and the readings taken: (1) the caption speaks of 'cross-validation', "
               "the text of runs 'for various combinations of train, test, and reference examples, the latter always "
               "taken outside the two previous sets': repeated random 60/20/20 training / test / reference splits "
               "(the proportions are ours; the thesis gives none); (2) 'the color and color-pairs representations "
               "work best': each of the two beats every other single set, in each direction (the figure shows the "
               "two directions side by side); (3) 'nearly as well as the best of the representations': the "
               "combination does not fall more than 0.1 below any single set, in each direction (the same as below "
               "the best, without choosing the best on the test results).",
               common.KEYWORDS_NOTE],
    )


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Fig. 6.4: success rates by image descriptor set, in both directions."""
    metrics = result.metrics
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    x = np.arange(len(SETS))
    for j, key in enumerate(("i2s", "s2i")):
        ax.bar(x + (j - 0.5) * 0.4, [metrics[f"{s}.{key}"] for s in SETS], 0.4, capsize=3,
               yerr=[metrics[f"{s}.{key}_std"] for s in SETS],
               label={"i2s": "image -> sound (I -> S)", "s2i": "sound -> image (S -> I)"}[key])
    ax.axhline(metrics["chance"], color="k", ls=":", label=f"chance ({metrics['chance']:.2g}: one concept at random)")
    ax.set_xticks(x, SETS, rotation=20, fontsize=8)
    ax.set_xlabel("image descriptor set")
    ax.set_ylabel("success rate (fraction of test examples)")
    ax.set_ylim(0, 1)
    ax.set_title("Fig. 6.4: image descriptor sets (mean ± std over repetitions)")
    ax.legend(fontsize=7)
    return {"fig6_4": fig}


EXPERIMENT = register(Experiment(
    id="ch6-image-features",
    title="Image <-> sound associations by image descriptor set",
    thesis_ref="Section 6.6.1, Fig. 6.4",
    config_cls=Config,
    compute=compute,
    present=present,
    reference={},
    claims=[
        Claim("On the dataset, the colour and colour-pair representations work best: in each direction (I -> S and "
              "S -> I), each of them beats each other single descriptor set (keypoints, keypoint pairs, colour "
              "triplets), paired over the repetitions.",
              " and ".join(f"{good}.{key} > {other}.{key}" for key in ("i2s", "s2i") for good in ("color", "color_pairs")
                           for other in ("keypoints", "keypoint_pairs", "color_triplets")),
              kind="thesis", source="Section 6.6.1, Fig. 6.4 (lines 5491-5493)"),
        Claim(f"The system is robust to adding information: all descriptor sets together do nearly as well as the "
              f"best set alone, i.e. in each direction no more than {NEARLY:g} (our margin) below any single set.",
              " and ".join(f"all.{key} > {single}.{key} - {NEARLY!r}" for key in ("i2s", "s2i") for single in SINGLES),
              kind="ours"),
        Claim("Every image descriptor set, and all of them together, supports the association with sound well above "
              "chance (our bar: a chance-corrected score above 0.2), in both directions.",
              " and ".join(above_chance_rule(f"{name}.{key}", "chance") for key in ("i2s", "s2i") for name in SETS),
              kind="ours"),
    ],
    datasets=("fsdd", "eth80", "acorns", "audio", "images"),
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
