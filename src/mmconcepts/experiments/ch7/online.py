"""ch7-online: concepts emerging along a stream, learnt online (beyond the thesis).

The thesis ends ("Discussion and perspectives") on "an important shortcoming of our
approach": the multimodal learner of chapter 6 is not incremental. Here the same learner
(I-divergence NMF of stacked, L1-normalised modalities, k = 50, 50 iterations) learns from a
stream of sound-motion pairs with :meth:`~mmconcepts.multimodal.MultimodalNMF.partial_fit`
(mini-batches, accumulated statistics, no forgetting, scales estimated online), and at a few
points of the stream it is compared with the batch learner refitted from scratch on every
pair seen so far:

- cross-modal success as in Table 6.2 (``ch6-motion-sound``): a held-out pair's sound is
  matched against one motion per concept (and back), in the internal space with the cosine
  dissimilarity (the thesis' best comparison in both directions), chance 0.1;
- concept specialisation as in Fig. 6.10 (``ch6-concepts``): the mean mutual information of
  the Kuhn-Munkres-matched (concept, coefficient) pairs, on the held-out pairs' internal
  coefficients (from both modalities), beside a shuffled-concept control;
- the learning time of each learner and its memory: the online learner's state (dictionary
  and statistics, independent of the examples seen) against what the batch learner must
  keep to refit (the examples seen);
- the concept explorer: the atoms of the first fold's online learner at the end of its stream,
  read from its coefficients of the training pairs.

Data: the pairs of ``ch6-motion-sound`` (real FSDD digits of one speaker with ten MSR
Action3D actions when the data root has them, else the generated Caregiver-like corpus and
Choreo2-like motions), in a stratified cross-validation: per fold, the training pairs arrive
in a random order (the stream), the test fold is held out. The HAC and motion-histogram
codebooks are fitted on the training fold, as in ``ch6-motion-sound`` (the features are not
learnt online: both learners see the same features, so the comparison is of the learners).
Each utterance and each motion record serves in one fold only (``split_groups``). Every
value is measured within one fold, the points of its stream included, so the unit of the
samples is the fold (:meth:`SampleUnit.folds`, corrected resampled t), paired across points
and learners.

Every claim is ours (the thesis names online NMF as the way to an incremental learner but
does not run it). A claim "above chance" asks for a chance-corrected score above
:data:`~mmconcepts.experiments.ch7.protocol.FAIR_AGREEMENT` (0.2): for the success rate
against a random ranking, for the matched information from the shuffled-concept control
to its ceiling (:func:`information_ceiling`).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment

from ...errors import ConvergenceWarning
from ...motion import MotionHistograms
from ...multimodal import MultimodalNMF, matching_success_rate, pairwise_divergence
from ...sound.hac import HAC
from ..protocols import pairs as common
from ..protocols.explorer import UTTERANCES, explorer_note, recordings_explorer
from ...engine import (
    Claim,
    Experiment,
    PresetConfig,
    Result,
    RunContext,
    SampleUnit,
    Streams,
    Table,
    register,
    streams,
)
from ..._jit import single_threaded
from ...multimodal import mutual_information_matrix
from . import protocol as ch7

__all__ = ["Config", "compute", "present", "run", "crossmodal_success", "matched_information", "information_ceiling",
           "EQUIVALENCE_MARGIN"]

#: The equivalence margin of the online-versus-batch claim (absolute success rate), fixed before any run: the
#: binomial standard error of one fold's success rate at p = 0.5 with 100 held-out pairs (the real FSDD speaker's
#: 500 utterances in 5 folds), and half the chance level.
EQUIVALENCE_MARGIN = 0.05

DIRECTIONS = ("sound2motion", "motion2sound")


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes (``n_per_speaker``, ``n_motion`` select the generated data), learner and stream settings.

    ``points``: fractions of the training stream at which both learners are evaluated (the
    batch learner refitted there); ``batch_size``: pairs per ``partial_fit`` call;
    ``partial_max_iter``: iterations of each call after the first (the first runs ``n_iter``,
    as a batch fit); ``forget``: the forgetting factor (1: none, the stream is stationary).
    """

    n_per_speaker: int = 500
    n_motion: int = 1100
    n_folds: int = 5
    k: int = 50
    n_iter: int = 50
    batch_size: int = 20
    partial_max_iter: int = 10
    forget: float = 1.0
    points: tuple = (0.1, 0.25, 0.5, 0.75, 1.0)
    n_bins: int = 10
    motion_bins: int = 25
    seed: int = 0

    hac_fit_frames: int = 100_000  # training frames (at most) for each HAC codebook: HAC's max_fit_frames
    QUICK = dict(n_per_speaker=250, n_motion=250, batch_size=40, points=(0.1, 0.4, 1.0), hac_fit_frames=20_000)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_per_speaker=50, n_motion=60, n_folds=2, k=10, n_iter=20, batch_size=10, partial_max_iter=5,
                 points=(0.3, 1.0), hac_fit_frames=5_000)


def crossmodal_success(model: MultimodalNMF, X_test: dict, y_test: np.ndarray, *, random_state: Any = None,
                       W: dict | None = None) -> dict[str, float]:
    """Table 6.2's success rates in the internal space with the cosine (both directions and their mean).

    Each held-out example observed in one modality is compared with one reference example per
    concept observed in the other (drawn among the held-out examples, 10 draws,
    :func:`~mmconcepts.multimodal.matching_success_rate`). ``W`` may hold the internal
    representations from ``"sound"`` and from ``"motion"`` already computed.
    """
    W = W if W is not None else {m: model.transform({m: X_test[m]}) for m in ("sound", "motion")}
    D = pairwise_divergence(W["sound"], W["motion"], "cosine")
    s2m = matching_success_rate(D, y_test, y_test, random_state=random_state)
    m2s = matching_success_rate(D.T, y_test, y_test, random_state=random_state)
    return {"sound2motion": float(s2m), "motion2sound": float(m2s), "mean": float((s2m + m2s) / 2)}


def matched_information(y: np.ndarray, W: np.ndarray, n_bins: int) -> float:
    """Fig. 6.10's specialisation: mean mutual information (bits) of the Kuhn-Munkres-matched pairs.

    ``mutual_information_matrix`` of ``ch6-concepts`` (equal-width bins), then the assignment of
    concepts to coefficients of maximum total information, as that experiment computes it.
    """
    mi = mutual_information_matrix(y, W, n_bins)
    rows, cols = linear_sum_assignment(-mi)
    return float(mi[rows, cols].mean())


def information_ceiling(y: np.ndarray) -> float:
    """The most :func:`matched_information` can be: the mean entropy (bits) of the concept indicators.

    The information a coefficient carries about "the example features concept l" is at most
    that indicator's entropy (for the plug-in estimates too, which are the exact quantities
    of the empirical distribution); the matched mean is over every concept of ``y``.

    Examples
    --------
    >>> round(information_ceiling(np.repeat(np.arange(10), 5)), 3)   # ten equal concepts: H(0.1)
    0.469
    """
    _, counts = np.unique(np.asarray(y), return_counts=True)
    p = counts / counts.sum()
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(p * np.log2(p) + (1 - p) * np.log2(1 - p))
    return float(np.nan_to_num(h).mean())


def _evaluate(model: MultimodalNMF, S, M, y, ref_seed: int, control_seed: int, n_bins: int) -> dict[str, float]:
    X = {"sound": S, "motion": M}
    W = {m: model.transform({m: X[m]}) for m in ("sound", "motion")}
    out = crossmodal_success(model, X, y, random_state=ref_seed, W=W)
    W_both = model.transform(X)
    return {**{f"success.{k}": v for k, v in out.items()},
            "mi": matched_information(y, W_both, n_bins), "mi_ceiling": information_ceiling(y),
            "mi_shuffled": matched_information(np.random.default_rng(control_seed).permutation(y), W_both, n_bins)}


def _nbytes(X) -> int:
    if sp.issparse(X):
        return int(X.data.nbytes + X.indices.nbytes + X.indptr.nbytes)
    return int(np.asarray(X).nbytes)


def _segments(n: int, points: list[int], batch: int) -> list[slice]:
    """Batches of at most ``batch`` pairs that end exactly at every evaluation point."""
    out, start = [], 0
    for p in points:
        while start < p:
            out.append(slice(start, min(start + batch, p)))
            start = out[-1].stop
    return out


def _fold(task: dict) -> dict:
    """One fold: features, the online stream and the batch refits at the same points."""
    tr, te, y = task["train"], task["test"], task["y"]
    cfg = task["config"]
    with single_threaded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = HAC(random_state=task["feature_seed"], max_fit_frames=cfg["hac_fit_frames"]).fit([task["mfcc"][i] for i in tr])
        hist = MotionHistograms(data="joint", method="vq", n_bins=cfg["motion_bins"], delay=3,
                                random_state=task["feature_seed"]).fit([task["angles"][i] for i in tr])
        S, M = hac.transform(task["mfcc"]), hist.transform(task["angles"])
        order = tr[np.random.default_rng(task["order_seed"]).permutation(len(tr))]
        points = sorted({max(1, int(round(f * len(order)))) for f in cfg["points"]})
        kw = dict(n_components=cfg["k"], max_iter=cfg["n_iter"], random_state=task["learner_seed"])
        online = MultimodalNMF(**kw, forget_factor=cfg["forget"], partial_max_iter=cfg["partial_max_iter"])
        out: dict[str, Any] = {"points": points, "online": [], "batch": []}
        t_online = 0.0
        todo = list(points)
        for sl in _segments(len(order), points, cfg["batch_size"]):
            idx = order[sl]
            t0 = time.process_time()
            online.partial_fit({"sound": S[idx], "motion": M[idx]})
            t_online += time.process_time() - t0
            if sl.stop == todo[0]:
                todo.pop(0)
                state = online.components_.nbytes + sum(a.nbytes for a in online.nmf_._stats or ())
                ev = _evaluate(online, S[te], M[te], y[te], task["reference_seed"], task["control_seed"],
                               cfg["n_bins"])
                out["online"].append({**ev, "time": t_online, "memory_mb": state / 2**20})
        if task["explorer"]:  # the concept explorer: the online learner's coefficients of the training pairs
            out["coefficients"] = online.transform({"sound": S[tr], "motion": M[tr]})
        del online  # one learner in memory at a time (the batch refits' dictionaries are as large)
        for p in points:
            idx = order[:p]
            t0 = time.process_time()
            batch = MultimodalNMF(**kw).fit({"sound": S[idx], "motion": M[idx]})
            dt = time.process_time() - t0
            ev = _evaluate(batch, S[te], M[te], y[te], task["reference_seed"], task["control_seed"], cfg["n_bins"])
            kept = _nbytes(S[idx]) + _nbytes(M[idx]) + batch.components_.nbytes
            out["batch"].append({**ev, "time": dt, "memory_mb": kept / 2**20})
            del batch
    return out


#: Each fold's draws (``st.seed_for(stream, draw, fold)``): the codebooks and the NMF initialisations (learner
#: stream), the stream's order (splits), the reference draws and the shuffled-concept control (reference).
FEATURES, NMF_INIT = 0, 1
ORDER = 0
REFERENCE, CONTROL = 0, 1


def _tasks(data: dict, config: Config, st: Streams) -> list[dict]:
    n = data["n_folds"]
    cfg = {"k": config.k, "n_iter": config.n_iter, "batch_size": config.batch_size, "forget": config.forget,
           "partial_max_iter": config.partial_max_iter, "points": tuple(config.points), "n_bins": config.n_bins,
           "motion_bins": config.motion_bins, "hac_fit_frames": config.hac_fit_frames}
    return [{"train": np.flatnonzero(data["fold"] != f), "test": np.flatnonzero(data["fold"] == f), "y": data["y"],
             "mfcc": data["mfcc"], "angles": data["angles"], "config": cfg,
             "feature_seed": st.seed_for("learner", FEATURES, f), "learner_seed": st.seed_for("learner", NMF_INIT, f),
             "order_seed": st.seed_for("splits", ORDER, f), "reference_seed": st.seed_for("reference", REFERENCE, f),
             "control_seed": st.seed_for("reference", CONTROL, f), "explorer": f == 0} for f in range(n)]


#: Per-point values of each learner: the metric name part and the field of the fold result.
_FIELDS = {"success": "success.mean", "sound2motion": "success.sound2motion", "motion2sound": "success.motion2sound",
           "mi": "mi", "mi_shuffled": "mi_shuffled", "mi_ceiling": "mi_ceiling", "time": "time",
           "memory_mb": "memory_mb"}


def compute(config: Config, ctx: RunContext) -> Result:
    """Success, specialisation, time and memory along the stream, per fold (figures: :func:`present`)."""
    st = streams(config.seed)
    data = common.load_pairs(ctx, n_per_speaker=config.n_per_speaker, n_motion=config.n_motion,
                             n_folds=config.n_folds, streams=st)
    folds = ctx.parallel(_fold, _tasks(data, config, st), desc="folds (stream and refits)")
    W = folds[0].pop("coefficients")
    trained = np.flatnonzero(data["fold"] != 0)
    explorer = recordings_explorer(
        W, trained, speech=data["speech"], motion=data["motion"], motion_of=data["motion_idx"],
        note=explorer_note(f"the online learner of fold 1 at the end of its stream (k = {W.shape[1]}, each of its "
                           f"{len(trained)} training pairs seen once; sound and motion)", "pairs",
                           f"{UTTERANCES} and the first pair's motion record"))
    n_points = min(len(f["points"]) for f in folds)
    metrics: dict[str, float] = {"chance": 1.0 / len(data["keywords"])}
    samples: dict[str, list[float]] = {}
    for learner in ("online", "batch"):
        for name, field in _FIELDS.items():
            for i in range(n_points):
                vals = [float(f[learner][i][field]) for f in folds]
                key = f"{learner}.{name}.p{i + 1}"
                metrics[key], samples[key] = float(np.mean(vals)), vals
            for alias, i in (("first", 0), ("last", n_points - 1)):
                key = f"{learner}.{name}.{alias}"
                metrics[key] = metrics[f"{learner}.{name}.p{i + 1}"]
                samples[key] = list(samples[f"{learner}.{name}.p{i + 1}"])
        vals = [float(sum(p["time"] for p in f[learner])) if learner == "batch" else float(f[learner][-1]["time"])
                for f in folds]
        metrics[f"{learner}.time_total"], samples[f"{learner}.time_total"] = float(np.mean(vals)), vals
    ratio = [b / o for b, o in zip(samples["batch.time_total"], samples["online.time_total"])]
    metrics["time_ratio"], samples["time_ratio"] = float(np.mean(ratio)), ratio
    n_seen = [float(np.mean([f["points"][i] for f in folds])) for i in range(n_points)]
    rows = []
    for i in range(n_points):
        row = [round(n_seen[i], 1)]
        for learner in ("online", "batch"):
            row += [metrics[f"{learner}.{name}.p{i + 1}"] for name in ("success", "sound2motion", "motion2sound", "mi")]
        row += [metrics[f"online.mi_shuffled.p{i + 1}"], metrics[f"online.time.p{i + 1}"],
                metrics[f"batch.time.p{i + 1}"], metrics[f"online.memory_mb.p{i + 1}"],
                metrics[f"batch.memory_mb.p{i + 1}"]]
        rows.append(row)
    columns = ["pairs seen"] + [f"{lr} {name}" for lr in ("online", "batch")
                                for name in ("success", "S->M", "M->S", "matched MI (bits)")] + \
              ["shuffled MI (online)", "online cumulative CPU s", "batch refit CPU s", "online state MB",
               "batch kept MB"]
    stds = {k: float(np.std(v)) for k, v in samples.items()}
    n_test = int(np.mean([np.sum(data["fold"] == f) for f in range(data["n_folds"])]))
    # every value is measured in one fold (its codebooks, stream order and learners); the points of a stream are
    # within that fold, so the unit is the fold and values of one fold are paired
    unit = SampleUnit.folds(len(folds), f"{len(folds)} folds of the sound-motion pairs (one stream per fold)")
    return Result(
        metrics=metrics,
        samples=samples,
        sample_units={name: "folds" for name in samples},
        units={"folds": unit},
        split_groups={"folds": common.fold_split_groups(data)},
        explorer=explorer,
        tables={"stream": Table("Along the stream (means over folds)", columns, rows,
                                note="success: mean of sound -> motion and motion -> sound (internal space, cosine); "
                                     "CPU seconds of learning only (process time of the fold's worker).")},
        figure_data={"n_seen": n_seen, "std": stds, "n_points": n_points},
        notes=[common.data_source_note(ctx, data["speech"], data["motion"]),
               f"Speaker {data['speaker']}: {len(data['y'])} sound-motion pairs, stratified {data['n_folds']}-fold "
               f"cross-validation (about {n_test} held-out pairs per fold). Per fold, the training pairs arrive in a "
               "random order (children of the splits stream); the HAC and motion-histogram codebooks are fitted on the "
               "training fold, as in ch6-motion-sound (the features are not learnt online; both learners share them).",
               f"Online learner: MultimodalNMF.partial_fit, k = {config.k}, batches of {config.batch_size} pairs; the "
               f"first batch runs {config.n_iter} iterations (a batch fit), later ones {config.partial_max_iter} "
               f"(chosen for the time budget, not tuned on the results); forgetting factor {config.forget:g} (1: "
               "none, the stream is stationary); scales estimated online. Batch learner: MultimodalNMF.fit "
               f"({config.n_iter} iterations) from scratch on the pairs seen so far, at the same points "
               f"({', '.join(f'{p:g}' for p in config.points)} of the stream), from the same initialisation seed.",
               "Success: Table 6.2's protocol in the internal space with the cosine (the thesis' best comparison in "
               "both directions): one reference per concept drawn among the held-out pairs, 10 draws; chance "
               f"{metrics['chance']:.2f}. Specialisation: Fig. 6.10's mutual information (ch6-concepts' function, "
               f"{config.n_bins} equal-width bins), on the held-out pairs' coefficients from both modalities, mean "
               "over the Kuhn-Munkres-matched (concept, coefficient) pairs; control: the same with the concepts "
               "shuffled (its own permutation per fold), which measures the estimator's bias.",
               "Time: CPU (process) time of learning only, per fold; batch.time_total sums the refits at every point "
               "(what a learner without partial_fit pays to have a model at each point), online.time_total is the "
               "whole stream. Memory: the online learner's state (dictionary and accumulated statistics: k x "
               "n_features x 3 floats, whatever the number of pairs seen) against what the batch learner keeps to "
               "refit (the pairs seen, sparse sound and dense motion, plus its dictionary).",
               f"Equivalence claim (ours: the thesis only says online NMF exists): the margin {EQUIVALENCE_MARGIN} "
               "(absolute success rate) was fixed before any run: the binomial standard error of one fold's rate at "
               "p = 0.5 with 100 held-out pairs, and half the chance level. It holds only when the whole interval of "
               "|online - batch| lies inside the margin.",
               f"Bars: 'above chance' asks for a chance-corrected score (p - p0) / (1 - p0) above "
               f"{ch7.FAIR_AGREEMENT} (the lower end of 'fair' agreement on Landis and Koch's kappa scale), fixed "
               f"from the chance values before any result was seen. Success: one reference per concept, so a random "
               f"ranking succeeds {metrics['chance']:.2f} of the time; bar {ch7.fair_bar(metrics['chance']):.2f}. "
               "Specialisation: the useless learner's value is the shuffled-concept control (the estimator's bias, "
               f"{metrics['online.mi_shuffled.last']:.3f} bits at the end of the stream), the ceiling the mean "
               f"entropy of the concept indicators ({metrics['online.mi_ceiling.last']:.3f} bits); bar: the "
               f"control plus {ch7.FAIR_AGREEMENT} of the way to the ceiling, fold by fold.",
               "Every claim is ours (the thesis does not run this experiment; it names online NMF as the way to make "
               "its learner incremental, lines 6082-6085). Reclassified: 'success above chance' now asks for the bar "
               "above (a learner barely above chance passed it); 'more than twice the shuffled information' is "
               "replaced by the same bar between the control and the ceiling (the factor 2 was derived from nothing, "
               f"and with about {n_test} held-out pairs and {config.n_bins} bins the control's bias is a large share "
               "of the ceiling, which a factor of the control ignores).",
               f"Uncertainty: every metric is the mean over the {len(folds)} folds, with the per-fold values as "
               "samples, declared as the folds of one cross-validation (corrected resampled t): the points of a "
               "stream are measured within one fold, so the fold is the unit, and values of one fold are paired "
               "across learners and points. The split is grouped by recording (split_groups: each utterance and "
               "motion record serves in one fold only).",
               common.KEYWORDS_NOTE],
    )


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Success and specialisation against the pairs seen (online and batch), and the learning cost."""
    m, fd = result.metrics, result.figure_data
    n_seen, std, n_points = fd["n_seen"], fd["std"], fd["n_points"]
    fig = Figure(figsize=(11, 3.8), layout="constrained")
    axes = fig.subplots(1, 3)
    styles = {"online": dict(color="C0", marker="o"), "batch": dict(color="C1", marker="s", ls="--")}
    for ax, name, label in ((axes[0], "success", "cross-modal success (mean of S->M, M->S)"),
                            (axes[1], "mi", "matched mutual information (bits)")):
        for learner, style in styles.items():
            keys = [f"{learner}.{name}.p{i + 1}" for i in range(n_points)]
            ax.errorbar(n_seen, [m[k] for k in keys], yerr=[std[k] for k in keys], capsize=3,
                        label=f"{learner} learner", **style)
        if name == "success":
            ax.axhline(m["chance"], color="k", ls=":", lw=1, label=f"chance ({m['chance']:.2g})")
            ax.set_ylim(0, 1)
        else:
            keys = [f"online.mi_shuffled.p{i + 1}" for i in range(n_points)]
            ax.plot(n_seen, [m[k] for k in keys], color="gray", ls=":", label="shuffled concepts (online)")
        ax.set_xlabel("training pairs seen")
        ax.set_ylabel(label)
        ax.legend(fontsize=7)
    ax = axes[2]
    online = [m[f"online.time.p{i + 1}"] for i in range(n_points)]
    batch = np.cumsum([m[f"batch.time.p{i + 1}"] for i in range(n_points)])
    ax.plot(n_seen, online, label="online: cumulative partial_fit", **styles["online"])
    ax.plot(n_seen, batch, label="batch: cumulative refits", **styles["batch"])
    ax.set_xlabel("training pairs seen")
    ax.set_ylabel("learning CPU time (s, mean over folds)")
    ax.legend(fontsize=7)
    fig.suptitle(f"Learning online from a stream: k = {config.k}, batches of {config.batch_size}; bars: std over "
                 "folds", fontsize=9)
    return {"stream": fig}


#: Where the thesis names online NMF as the way to an incremental learner (its perspectives); the claims stay ours.
PERSPECTIVE = "Discussion and perspectives (lines 6082-6085)"

EXPERIMENT = register(Experiment(
    id="ch7-online",
    title="Multimodal concepts learnt online from a stream",
    thesis_ref="Discussion and perspectives (the learner 'is not incremental'); protocols of Table 6.2 and Fig. 6.10",
    config_cls=Config,
    compute=compute,
    present=present,
    reference={},
    claims=[
        Claim("Concepts emerge as the stream goes on: the online learner's cross-modal success at the end of the "
              "stream is higher than at its first evaluation point.",
              "online.success.last > online.success.first", source=PERSPECTIVE),
        Claim("At the end of the stream, the online learner matches sounds and motions well above chance: a "
              "chance-corrected success above 0.2 (a random ranking succeeds 0.10 of the time; the bar is 0.28).",
              ch7.bar_rule("online.success.last", "chance"), source=PERSPECTIVE),
        Claim(f"The online learner's final success is within {EQUIVALENCE_MARGIN} of the batch learner refitted on "
              "the same pairs.",
              f"abs(online.success.last - batch.success.last) < {EQUIVALENCE_MARGIN}", source=PERSPECTIVE),
        Claim("Coefficients specialise on concepts along the stream: the matched mutual information of the online "
              "learner is higher at the end than at the first point.",
              "online.mi.last > online.mi.first"),
        Claim("The specialisation is learnt structure: at the end, the matched coefficients' information is above "
              "the shuffled-concept control by more than 0.2 of the way from the control to its ceiling (the "
              "concept indicators' entropy).",
              ch7.bar_rule("online.mi.last", "online.mi_shuffled.last", "online.mi_ceiling.last")),
    ],
    datasets=("fsdd", "msr-action3d", "acorns", "audio", "choreo2"),
    description="The multimodal learner made incremental: success and specialisation along a stream.",
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
