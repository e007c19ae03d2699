"""ch3-msr-action3d: single-action classification and arm+leg mixtures on real Kinect motion (MSR Action3D).

Not in the thesis: a check of the chapter-3 pipeline (thesis section 3.3) on real
skeletons, tuned to MSR Action3D's frame rate. Data: MSR Action3D (Li, Zhang and Liu 2010;
567 sequences, 20 actions, up to 10 subjects, Kinect v1 at 15 fps), given as
``--data msr-action3d=DIR`` (or found as ``msr-action3d`` under ``--data-root DIR``); the
experiment is skipped without it. The five thesis experiments (``ch3-choreography``,
``ch3-unseen``, ``ch3-threshold``, ``ch3-combinations``, ``ch3-representations``) run on the
same data through the same loader (:func:`mmconcepts.experiments.ch3.protocol.msr_subset`);
this one adds what they do not: the velocity delay of 2 frames (0.13 s at 15 fps, close to
Choreo1's 3 frames at 30 fps; the thesis experiments keep the thesis' 3 frames), and the
single-action classification with four representations side by side.

1. Single actions (as Fig. 3.5/3.6): each sequence is labelled by its action; the NMF
   label learner (Frobenius, k = 150) reconstructs the label activations of test sequences
   (l_single), for four representations: KDE angle histograms, KDE joint angle-velocity
   histograms (15 bins per degree of freedom), VQ joint histograms (16 centroids, hard and
   soft). Stratified k-fold; each sequence is its own recording.
2. Mixed "choreographies" (as Tables 3.2 and 3.3): the small mixed set of ``msr_subset``
   (arm angles of an arm-action sequence + torso and leg angles of a leg-action sequence of
   the same subject; 18 labels, 45 combinations), built per part of the source recordings
   (``n_folds_mixed`` parts, dealt by the splits stream) so that no recording behind a test
   mixture feeds a training one. Learnt from label sets with NMF (Frobenius, k = 150,
   threshold by CV) and the linear SVMs (``svm`` plain, as the thesis; ``svm_std``
   standardised), scored leaving one part out, and leaving one part out with the training
   set stripped of the test part's combinations (Table 3.3's protocol: unseen
   combinations).

Features of the mixed set: joint angle-velocity histograms by soft vector quantisation,
16 centroids per degree of freedom, delay 2 frames, and, as the second setting of the
NMF-vs-SVM claims, KDE histograms with the same bins and delay (metrics ``kde.*``); fitted
on the training folds only. MU iterations: 100 quick, 200 full (not given by the thesis).
Random streams: the seed's :class:`~mmconcepts.engine.Streams` (data pairing, learners, splits
and parts, reference).

Claims, all ours (the thesis' statements of Tables 3.2 and 3.3 are tested on the same data by
``ch3-choreography`` and ``ch3-unseen``): the orders of the thesis' 16-gesture rows (the
analogue of this 18-label set) on real Kinect data at this experiment's delay, decided under
the four histogram x SVM settings: NMF beats the SVM on new mixtures (Table 3.2), the SVM
beats NMF on unseen combinations (Table 3.3); chance levels, "most mixtures named", VQ
against KDE at 15-16 bins. The thesis' 16-gesture numbers stand beside ours in the table,
with no magnitude claim.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from math import comb

import numpy as np
from matplotlib.figure import Figure

from . import protocol as common
from ...engine import (
    Claim,
    Experiment,
    ExperimentSkipped,
    PresetConfig,
    Result,
    RunContext,
    Table,
    fill_thesis_numbers,
    register,
)
from .choreography import TABLE_3_2
from .unseen import TABLE_3_3

__all__ = ["Config", "compute", "nmf_vs_svm", "present", "run"]

SINGLE_REPS = {"angles_kde": {"data": "angles", "method": "kde", "n_bins": 15, "delay": 2},
               "joint_kde": {"data": "joint", "method": "kde", "n_bins": 15, "delay": 2},
               "joint_vq_hard": {"data": "joint", "method": "vq", "assignment": "hard", "n_bins": 16, "delay": 2},
               "joint_vq_soft": {"data": "joint", "method": "vq", "assignment": "soft", "n_bins": 16, "delay": 2}}
MIXED_FEATURES = SINGLE_REPS["joint_vq_soft"]  # the representation of ch3-choreography, at 15 fps
#: The second histogram setting of the mixtures: KDE, same bins and delay (as ch3-choreography's alternative).
MIXED_ALT_FEATURES = {"data": "joint", "method": "kde", "n_bins": 16, "delay": 2}
MIXED_LEARNERS = ("nmf_frobenius", "svm", "svm_std")
PROTOCOLS = ("mixed", "unseen")
#: The settings of the NMF-vs-SVM claims: histograms (metric prefix) x SVM.
SETTINGS = {"soft VQ, plain SVM": ("", "svm"), "soft VQ, standardised SVM": ("", "svm_std"),
            "KDE, plain SVM": ("kde.", "svm"), "KDE, standardised SVM": ("kde.", "svm_std")}


@dataclass(frozen=True)
class Config(PresetConfig):
    n_folds_single: int = 10
    n_folds_mixed: int = 10
    n_components: int = 150
    max_iter: int = 200
    inner_cv: int = 5
    n_records: int | None = None
    seed: int = 0

    QUICK = dict(n_folds_single=5, max_iter=100, inner_cv=2)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_folds_mixed=5, n_components=30, max_iter=40, n_records=200)


def _folder(ctx: RunContext):
    if not ctx.has_dataset("msr-action3d"):
        raise ExperimentSkipped("needs the real MSR Action3D skeletons (the folder of aAA_sSS_eEE_skeleton3D.txt "
                                "files): pass --data-root DIR (holding msr-action3d/) or --data msr-action3d=DIR.")
    return ctx.dataset("msr-action3d")


def compute(config: Config, ctx: RunContext) -> Result:
    """Single actions and arm + leg mixtures on MSR Action3D (no figure: :func:`present` draws the metrics)."""
    folder = _folder(ctx)
    t0 = time.perf_counter()
    st = common.streams(config.seed)
    single = common.msr_subset(folder, "primitive", streams=st, n_records=config.n_records)
    Y1 = single.Y
    y = np.argmax(Y1, axis=1)
    metrics: dict[str, float] = {"single.n_examples": float(len(y))}
    samples: dict[str, list[float]] = {}
    sample_units: dict[str, str] = {}
    units = {}
    groups = {}
    params = {"n_components": config.n_components, "max_iter": config.max_iter, "inner_cv": config.inner_cv}
    splits = common.example_splits(single, config.n_folds_single, st.seed_for("splits"), y=y)
    units["single"] = common.fold_unit(splits, "the single actions")
    groups["single actions"] = common.split_groups(single, splits)
    res = common.evaluate_folds(ctx, single.angles, Y1, splits, features=list(SINGLE_REPS.values()),
                                learners=("nmf_frobenius",), params=params, streams=st, single=True,
                                desc="MSR single")
    for name, folds in zip(SINGLE_REPS, res):
        metrics[f"single.{name}.l_single"] = common.pooled_scores(folds, Y1, "nmf_frobenius", single=True)["l_single"]
        samples[f"single.{name}.l_single"] = common.fold_samples(folds, Y1, "nmf_frobenius", single=True)["l_single"]
        sample_units[f"single.{name}.l_single"] = "single"
    metrics["single.chance.l_single"] = float(np.bincount(y).max() / len(y))

    mixed = common.msr_subset(folder, "mixed_partial", streams=st, n_records=config.n_records,
                              n_parts=config.n_folds_mixed)
    Y2 = mixed.Y
    metrics["mixed.n_examples"] = float(len(Y2))
    metrics["mixed.n_combinations"] = float(len(np.unique(common.combination_ids(Y2))))
    rows = []
    train_sizes = {}
    for proto in PROTOCOLS:
        spl = common.example_splits(mixed, config.n_folds_mixed, st.seed_for("splits"), unseen=proto == "unseen")
        units[proto] = common.fold_unit(spl, "the mixtures" + (" (unseen combinations)" if proto == "unseen" else ""))
        groups["mixtures" if proto == "mixed" else "mixtures, unseen combinations"] = common.split_groups(mixed, spl)
        train_sizes[proto] = (min(len(tr) for tr, _ in spl), max(len(tr) for tr, _ in spl))
        both = common.evaluate_folds(ctx, mixed.angles, Y2, spl, features=[MIXED_FEATURES, MIXED_ALT_FEATURES],
                                     learners=MIXED_LEARNERS, params=params, streams=st, desc=f"MSR {proto}")
        for pre, folds in zip(("", "kde."), both):
            for name in MIXED_LEARNERS:
                key = f"{proto}.{pre}{name}"
                sc = common.pooled_scores(folds, Y2, name)
                metrics[f"{key}.l_full"] = sc["l_full"]
                metrics[f"{key}.l_given_number"] = sc["l_given_number"]
                metrics[f"{key}.gain_given_number"] = sc["l_given_number"] - sc["l_full"]
                for k, v in common.fold_samples(folds, Y2, name).items():
                    samples[f"{key}.{k}"] = v
                samples[f"{key}.gain_given_number"] = [
                    g - f for g, f in zip(samples[f"{key}.l_given_number"], samples[f"{key}.l_full"])]
                for k in ("l_full", "l_given_number", "gain_given_number"):
                    sample_units[f"{key}.{k}"] = proto
                rows.append([proto, f"{pre}{name}", sc["l_full"], sc["l_given_number"]])
    metrics["mixed.chance.l_given_number"] = 1.0 / comb(Y2.shape[1], 2)
    elapsed = time.perf_counter() - t0

    names = list(SINGLE_REPS)
    t1 = Table("Single actions: l_single by representation", ["representation", "l_single"],
               [[n, metrics[f"single.{n}.l_single"]] for n in names] + [["chance", metrics["single.chance.l_single"]]])
    t2 = Table("Arm + leg mixtures from label sets", ["protocol", "learner", "l_full", "l_given_number"], rows,
               note=f"{len(Y2)} mixtures, {int(metrics['mixed.n_combinations'])} combinations, {Y2.shape[1]} labels; "
                    f"{config.n_folds_mixed} parts of the source recordings, one left out at a time; training "
                    "mixtures per fold: " + ", ".join(f"{p} {a}-{b}" for p, (a, b) in train_sizes.items())
                    + " (unseen: without the test part's combinations); kde.* = KDE histograms.")
    setting_notes = []
    for proto in PROTOCOLS:
        setting_notes.append(f"{proto}, l_full under each setting: " + "; ".join(
            f"{label}: NMF {metrics[f'{proto}.{pre}nmf_frobenius.l_full']:.3f} vs SVM "
            f"{metrics[f'{proto}.{pre}{svm}.l_full']:.3f}" for label, (pre, svm) in SETTINGS.items()) + ".")
    return Result(metrics=metrics, tables={"single": t1, "mixed": t2}, samples=samples, sample_units=sample_units,
                  units=units, split_groups=groups,
                  notes=[f"Data: MSR Action3D from {folder}. {single.description}; {mixed.description}. "
                         f"Run time {elapsed:.0f} s.",
                         ("Not a thesis experiment: its claims are ours. The thesis' statements of Tables 3.2 and 3.3 "
                          "are tested on real motion by ch3-choreography and ch3-unseen (the same MSR Action3D data "
                          "through the same loader); here the orders of the thesis' 16-gesture rows (the analogue of "
                          "this 18-label set) are our checks of the pipeline at MSR Action3D's delay of 2 frames, and "
                          "the reference numbers are those rows, shown beside ours with no magnitude claim (another "
                          "protocol: counting them would count the thesis' numbers twice)."),
                         fill_thesis_numbers(
                             "Restated: 'On unseen combinations NMF beats the SVM (Table 3.3, 47 labels)' read the "
                             "wrong row: this is the small (18-label) set, whose thesis analogue (16 gestures) has the "
                             "SVM ahead ({thesis:unseen.svm.l_full} vs {thesis:unseen.nmf_frobenius.l_full}); the "
                             "claim is now that order, under the four settings.", REFERENCE),
                         ("Dropped: 'the gain l_given_number - l_full is at least half the thesis'' (our bar); "
                          "l_full and l_given_number stand beside the thesis' 16-gesture numbers in the table."),
                         ("Reclassified as ours: the chance bars (5 x the most frequent action), 'most mixtures named' "
                          "(l_given_number above 0.5) and 'VQ beats KDE' at 15-16 bins (the thesis places VQ's "
                          "advantage at small numbers of bins only)."),
                         "Per-fold values: the result's samples; the single actions, the mixtures and the mixtures "
                         "with unseen combinations are three units (their folds differ)."] + setting_notes)


def present(result: Result, config: Config) -> dict[str, Figure]:
    """l_single by representation (single actions) and the scores on the mixtures."""
    metrics, samples = result.metrics, result.samples

    def spread(keys):  # std of each metric's per-fold values, NaN where there are none
        out = []
        for k in keys:
            v = np.asarray(samples.get(k, []), dtype=float)
            out.append(float(np.std(v, ddof=1)) if v.size > 1 else np.nan)
        return np.array(out)

    fig = Figure(figsize=(9, 4.6), layout="constrained")
    names = list(SINGLE_REPS)
    ax1, ax2 = fig.subplots(1, 2, width_ratios=[1, 2.2])
    keys = [f"single.{n}.l_single" for n in names]
    err = spread(keys)
    ax1.bar(range(len(names)), [metrics[k] for k in keys], yerr=err if np.isfinite(err).any() else None, capsize=3,
            label="ours (± std over folds)")
    ax1.axhline(metrics["single.chance.l_single"], color="k", ls=":", label="chance (the most frequent action)")
    ax1.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=7)
    ax1.set_xlabel("representation")
    ax1.set_ylabel("score (fraction of test examples right)")
    ax1.set_ylim(0, 1)
    ax1.set_title("single actions (l_single)", fontsize=9)
    ax1.legend(fontsize=7)
    keys = [f"{p}.{n}.{s}" for p in PROTOCOLS for n in MIXED_LEARNERS for s in ("l_full", "l_given_number")]
    err = spread(keys)
    x = np.arange(len(keys))
    ax2.bar(x, [metrics[k] for k in keys], yerr=err if np.isfinite(err).any() else None, capsize=2,
            label="ours (± std over folds)")
    chance = [metrics.get(f"{k.split('.')[0]}.chance.{k.rsplit('.', 1)[-1]}", np.nan) for k in keys]
    at = np.isfinite(chance)
    if at.any():
        ax2.hlines(np.asarray(chance)[at], (x - 0.45)[at], (x + 0.45)[at], colors="k", linestyles=":", lw=1.2,
                   label="chance (a random pair of actions)")
    ax2.set_xticks(x, keys, rotation=60, ha="right", fontsize=6)
    ax2.set_ylim(0, 1)
    ax2.set_ylabel("score (fraction of test examples\nwith the right label set)")
    ax2.set_title("arms + legs mixtures (all, and unseen combinations)", fontsize=9)
    ax2.legend(fontsize=7)
    return {"msr": fig}


#: The thesis' 16-gesture rows of Tables 3.2 (new mixtures) and 3.3 (unseen combinations), this 18-label set's
#: analogue.
REFERENCE = {f"{p}.{name}": table[f"16.{name}"] for p, table in (("mixed", TABLE_3_2), ("unseen", TABLE_3_3))
             for name in ("nmf_frobenius.l_full", "nmf_frobenius.l_given_number", "svm.l_full")}


def nmf_vs_svm(proto: str, *, nmf_better: bool = True) -> dict[str, str]:
    """One rule per setting (:data:`SETTINGS`): NMF (Frobenius) l_full above (or below) the SVM's under ``proto``."""
    op = ">" if nmf_better else "<"
    return {label: f"{proto}.{pre}nmf_frobenius.l_full {op} {proto}.{pre}{svm}.l_full"
            for label, (pre, svm) in SETTINGS.items()}


EXPERIMENT = register(Experiment(
    id="ch3-msr-action3d",
    title="Chapter 3 on real Kinect skeletons: single actions and arm+leg mixtures (MSR Action3D)",
    thesis_ref="Section 3.3 (method), on MSR Action3D instead of Choreo1",
    config_cls=Config,
    compute=compute,
    present=present,
    reference=REFERENCE,
    claims=[
        Claim("Learnt from label sets, NMF (Frobenius) reconstructs exact label sets of new real mixtures better than "
              "the linear SVM (thesis, 16 gestures: l_full {thesis:mixed.nmf_frobenius.l_full} vs "
              "{thesis:mixed.svm.l_full}), our check of the pipeline on real motion.", kind="ours",
              settings=nmf_vs_svm("mixed")),
        Claim("On real mixtures whose combination is unseen in training the linear SVM reconstructs exact label sets "
              "better than NMF (Frobenius) (thesis, 16 gestures: l_full {thesis:unseen.svm.l_full} vs "
              "{thesis:unseen.nmf_frobenius.l_full}), our check of the pipeline on real motion.", kind="ours",
              settings=nmf_vs_svm("unseen", nmf_better=False)),
        Claim("The histogram representations classify single real actions far above chance: KDE angle and joint "
              "histograms above 5 times the rate of the most frequent action (our bar).",
              "single.joint_kde.l_single > 5 * single.chance.l_single and "
              "single.angles_kde.l_single > 5 * single.chance.l_single", kind="ours"),
        Claim("Joint histograms by vector quantisation (16 centroids) classify single real actions better than by "
              "KDE (15 bins), our comparison at the bins of Table 3.2's features.", kind="ours",
              settings={"hard VQ": "single.joint_vq_hard.l_single > single.joint_kde.l_single",
                        "soft VQ": "single.joint_vq_soft.l_single > single.joint_kde.l_single"}),
        Claim("Learnt from label sets, NMF (Frobenius) names both actions of most new real mixtures (l_given_number "
              "above 0.5, our bar; a random ranking scores 1/153).",
              "mixed.nmf_frobenius.l_given_number > 0.5", kind="ours"),
    ],
    datasets=("msr-action3d",),
    synthetic=False,
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
