"""ch3-choreography: learning gestures from ambiguous label sets by NMF (Thesis Table 3.2).

Thesis section 3.3 (data 3.3.1, algorithm 3.3.2, scores 3.3.3, results 3.3.4). Each
choreography of the mixed Choreo1 subsets (``mixed_partial``: 137 records, 16 gestures;
``mixed_full``: 277 records, 47 gestures) is described by joint angle-velocity histograms
of its 16 joint angles and by the set of its 2-3 gesture labels. NMF (Frobenius or
Kullback-Leibler) factorizes the stacked [histograms, labels] training matrix; a test
choreography's labels are reconstructed from its histograms alone, and the label set is
the reconstructed activations above a threshold chosen by cross-validation on the
training folds. The baseline is one linear SVM per label.

Data: the thesis' Choreo1 (``--data choreo1=DIR``), else real Kinect skeletons of MSR
Action3D (``--data msr-action3d=DIR``) recombined limb-wise into mixed choreographies (the
16-gesture set becomes 2-limb mixtures over 18 labels, the 47-gesture set 3-limb mixtures
over 33 labels; see :func:`mmconcepts.experiments.ch3.protocol.msr_subset`), else the
synthetic dancer. The metric names are the same on every data set ("16" = the small mixed
set, "47" = the large one).

What the thesis states (section 3.3.4) and how it is tested:

- Table 3.2 (lines 2793-2802) gives l_full and l_given_number of NMF (Frobenius, KL) and
  l_full of the SVM on both sets. Each number is the reference of a *magnitude* claim (our
  number / the thesis', with its interval), and so is the gain l_given_number - l_full of
  NMF (Frobenius), the thesis' way of showing "which part of the error is due to the
  thresholding mechanism" (lines 2768-2770); the gain's reference is computed from the
  table's two numbers.
- The orders of the table are *thesis* claims at the thesis' comparison: NMF (Frobenius)
  beats the SVM on l_full with 16 and with 47 labels; Frobenius beats KL on both sets and
  both scores; the 47-gesture set is harder ("can be considered difficult", lines
  2806-2808).
- The thesis does not say which histograms Table 3.2 used nor how its SVM was set up, and
  the NMF-vs-SVM order depends on both (on our data KDE histograms reversed it): those two
  claims are decided under each of four settings, soft-VQ or KDE histograms with the plain
  (the thesis' scikit-learn default) or the standardised SVM, and the record says under
  which they hold; the Frobenius-vs-KL claim under both histogram methods.

Choices (the thesis' where it says):

- k = 150 atoms (thesis section 3.3.2); multiplicative updates (the plain NMF of the
  thesis), ``max_iter`` iterations (the thesis does not say how many: 200 in full mode,
  100 in quick mode), the threshold chosen by ``inner_cv``-fold cross-validation on each
  training fold (5 full, 2 quick) over 0.05..0.95.
- Features: joint angle-velocity histograms by vector quantisation with soft assignment,
  16 centroids per degree of freedom, velocity delay 3 frames (0.1 s at 30 Hz); codebooks
  fitted on each training fold only. The alternative setting (``alternative_features``):
  KDE histograms, same bins and delay. Both are computed in both presets.
- Sizes: the thesis' (137 records in the 16-gesture set, 277 in the 47-gesture set); on
  MSR Action3D, where the limb mixtures give 427 of each, a random draw of that many (data
  stream). ``None`` keeps every record.
- Protocol: leave-one-out in full mode (thesis section 3.3.1), shuffled 10-fold in quick
  mode; scores pooled over all test examples. Splits are grouped by source recording:
  synthetic and Choreo1 examples are each their own recording; the MSR mixtures are built
  per part of their recordings and the folds are the parts (10 parts in both modes, since
  a spliced mixture cannot be left out alone).
- The label weight of the stacked matrix (the thesis does not say) is LabelNMF's 'l1'
  rule of thesis section 6.4.
- Baselines: ``svm`` is the thesis' plain linear SVM (one per label, C = 1, on the raw
  histograms); ``svm_std`` standardises each feature first (ours); ``chance`` predicts the
  most frequent training label set.
- Random streams: the seed's :class:`~mmconcepts.engine.Streams` give the data (synthetic
  recordings, MSR limb pairings), learner (codebooks, NMF initialisation, SVM; one draw per
  fold), splits (folds, parts of the MSR recordings) and reference streams.
- ``l_given_number >= l_full`` holds for any scores (a label set found exactly by the
  threshold is also the top-n of the activations), so it is no claim.
- Spread: every score has its per-fold values as samples (leave-one-out: per example),
  one unit per data set (``SampleUnit.folds``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from math import comb
from typing import Any, NamedTuple

import numpy as np
from matplotlib.figure import Figure

from . import protocol as common
from ...engine import Claim, Experiment, PresetConfig, Result, RunContext, Table, fill_thesis_numbers, register

__all__ = ["Config", "Mixed", "compute", "evaluate_mixed", "magnitude_claims", "nmf_vs_svm", "present", "run",
           "score_figure", "score_table"]

LEARNERS = ("nmf_frobenius", "nmf_kl", "svm", "svm_std", "chance")
#: The learners fitted again on the alternative histograms (the settings of the NMF-vs-SVM claims).
SENSITIVITY_LEARNERS = ("nmf_frobenius", "nmf_kl", "svm", "svm_std")
SUBSETS = {"16": "mixed_partial", "47": "mixed_full"}
#: The settings of the NMF-vs-SVM claims: histograms (the metric prefix) x SVM (the learner).
SETTINGS = {"soft VQ, plain SVM": ("", "svm"), "soft VQ, standardised SVM": ("", "svm_std"),
            "KDE, plain SVM": ("kde.", "svm"), "KDE, standardised SVM": ("kde.", "svm_std")}


@dataclass(frozen=True)
class Config(PresetConfig):
    """Protocol of Table 3.2 (``n_folds=None``: leave-one-out)."""

    n_folds: int | None = None
    n_components: int = 150
    max_iter: int = 200
    inner_cv: int = 5
    data: str = "joint"
    method: str = "vq"
    n_bins: int = 16
    delay: int = 3
    assignment: str = "soft"
    n_records_partial: int | None = 137
    n_records_full: int | None = 277
    sensitivity: bool = True
    seed: int = 0

    QUICK = dict(n_folds=10, max_iter=100, inner_cv=2)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_folds=5, n_components=20, max_iter=40, n_records_partial=60, n_records_full=90, sensitivity=False)

    def features(self) -> dict:
        feats = {"data": self.data, "method": self.method, "n_bins": self.n_bins, "delay": self.delay}
        if self.method == "vq":
            feats["assignment"] = self.assignment
        return feats

    def params(self) -> dict:
        return {"n_components": self.n_components, "max_iter": self.max_iter, "inner_cv": self.inner_cv}

    def alternative_features(self) -> dict:
        """The other histogram setting (KDE <-> soft VQ), all else equal."""
        if self.method == "vq":
            return {"data": self.data, "method": "kde", "n_bins": self.n_bins, "delay": self.delay}
        return {"data": self.data, "method": "vq", "assignment": self.assignment, "n_bins": self.n_bins,
                "delay": self.delay}


class Mixed(NamedTuple):
    """One mixed set evaluated on its folds."""

    Y: np.ndarray
    folds: list[dict]
    arrays: common.MotionArrays
    splits: list[tuple[np.ndarray, np.ndarray]]


def mixed_arrays(config, ctx: RunContext, n_labels: str) -> common.MotionArrays:
    """The mixed subset ``n_labels`` ("16" or "47") drawn from the data stream of ``config.seed`` (the MSR mixtures
    built per part of their recordings, dealt by the splits stream)."""
    st = common.streams(config.seed)
    n_rec = config.n_records_partial if n_labels == "16" else config.n_records_full
    return common.subset_arrays(ctx, SUBSETS[n_labels], streams=st, n_records=n_rec)


def evaluate_mixed(config, ctx: RunContext, n_labels: str, *, learners=LEARNERS, unseen: bool = False,
                   features: dict | None = None) -> Mixed:
    """Load one mixed subset and evaluate ``learners`` on its folds (grouped by source recording).

    ``features`` replaces ``config.features()`` (the alternative histograms)."""
    st = common.streams(config.seed)
    arrays = mixed_arrays(config, ctx, n_labels)
    splits = common.example_splits(arrays, config.n_folds, st.seed_for("splits"), unseen=unseen)
    folds = common.evaluate_folds(ctx, arrays.angles, arrays.Y, splits, features=features or config.features(),
                                  learners=learners, params=config.params(), streams=st,
                                  desc=f"{n_labels} labels")
    return Mixed(arrays.Y, folds, arrays, splits)


def _spread(samples: dict, key: str) -> float:
    """The standard deviation of a metric's per-fold values (NaN without at least two)."""
    v = np.asarray(samples.get(key, []), dtype=float)
    v = v[np.isfinite(v)]
    return float(np.std(v, ddof=1)) if v.size > 1 else np.nan


def _bar_figure(metrics: dict, reference: dict, rows: list[tuple[str, str]], title: str,
                samples: dict | None = None) -> Figure:
    """Our scores (± their std over folds where the record has them) beside the thesis', with chance per bar."""
    samples = samples or {}
    fig = Figure(figsize=(9, 4.6), layout="constrained")
    ax = fig.subplots()
    names = [f"{a} labels\n{b}" for a, b in rows]
    ours = [metrics.get(f"{a}.{b}", np.nan) for a, b in rows]
    ref = [reference.get(f"{a}.{b}", np.nan) for a, b in rows]
    err = np.array([_spread(samples, f"{a}.{b}") for a, b in rows])
    x = np.arange(len(rows))
    ax.bar(x - 0.2, ours, 0.4, yerr=err if np.isfinite(err).any() else None, capsize=2, error_kw={"lw": 0.8},
           label="ours (± std over folds)" if np.isfinite(err).any() else "ours")
    ax.bar(x + 0.2, ref, 0.4, label="thesis")
    # chance: the "chance" learner's score on the same set and score (the most frequent label set)
    chance = [metrics.get(f"{a}.chance.{b.rsplit('.', 1)[-1]}", np.nan) for a, b in rows]
    at = np.isfinite(chance)
    if at.any():
        ax.hlines(np.asarray(chance)[at], (x - 0.45)[at], (x + 0.45)[at], colors="k", linestyles=":", lw=1.2,
                  label="chance (the most frequent label set)")
    ax.set_xticks(x, names, fontsize=6, rotation=45, ha="right")
    ax.set_ylim(0, 1)
    ax.set_ylabel("score (fraction of test examples\nwith the right label set)")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the bars, never over them
    return fig


def plot_rows(learners) -> list[tuple[str, str]]:
    """The (set, metric) bars of the score figure: every learner but chance, the SVMs without l_given_number."""
    return [(nl, f"{n}.{s}") for nl in SUBSETS for n in learners if n != "chance"
            for s in ("l_full", "l_given_number") if not (n.startswith("svm") and s == "l_given_number")]


def score_figure(result: Result, *, learners, reference, title) -> Figure:
    """Our scores beside the thesis' (the figure of Tables 3.2 and 3.3), from the metrics of :func:`score_table`."""
    return _bar_figure(result.metrics, reference, plot_rows(learners), title, result.samples)


def _unit_name(nl: str) -> str:
    return f"folds of the {nl}-label set"


def score_table(config, ctx, *, learners, unseen, reference, title,
                sensitivity_learners=SENSITIVITY_LEARNERS) -> Result:
    """The scores of ``learners`` on both mixed sets (Table 3.2, or 3.3 with ``unseen``): numbers, no figure.

    Every metric of a set has one sample per fold of that set (the two sets are different
    data: different units); with ``config.sensitivity`` the NMF (Frobenius) and SVM scores
    also on the alternative histograms (metrics ``<set>.<method>.<learner>.*``, the same
    folds: paired with the main ones) for ``sensitivity_learners``.
    """
    metrics: dict[str, float] = {}
    samples: dict[str, list[float]] = {}
    rows = []
    seconds = {}
    used = []
    units: dict[str, Any] = {}
    groups: dict[str, Any] = {}
    train_sizes = {}
    for nl in SUBSETS:
        t0 = time.perf_counter()
        Y, folds, arrays, splits = evaluate_mixed(config, ctx, nl, learners=learners, unseen=unseen)
        used.append(arrays)
        seconds[nl] = time.perf_counter() - t0
        units[_unit_name(nl)] = common.fold_unit(splits, f"the {nl}-label set")
        groups[f"{nl} labels"] = common.split_groups(arrays, splits)
        train_sizes[nl] = (min(len(tr) for tr, _ in splits), max(len(tr) for tr, _ in splits))
        metrics[f"{nl}.n_examples"] = float(len(Y))
        n_present = int((Y.sum(axis=0) > 0).sum())  # labels that occur (a loader may list unused ones)
        metrics[f"{nl}.n_labels"] = float(n_present)
        metrics[f"{nl}.n_folds"] = float(len(folds))
        for name in learners:
            sc = common.pooled_scores(folds, Y, name)
            metrics[f"{nl}.{name}.l_full"] = sc["l_full"]
            metrics[f"{nl}.{name}.l_given_number"] = sc["l_given_number"]
            if name == "chance":  # a random ranking of the labels names the true set with probability 1/C(L, n)
                metrics[f"{nl}.chance.l_given_number"] = sc["l_given_number"] = float(np.mean(
                    [1.0 / comb(n_present, int(k)) for k in Y.sum(axis=1)]))
            metrics[f"{nl}.{name}.gain_given_number"] = sc["l_given_number"] - sc["l_full"]
            per_fold = common.fold_samples(folds, Y, name)
            if name == "chance":
                # the most frequent training label set is fitted per fold: l_full has a spread; l_given_number is
                # the analytic expectation of a random ranking (no spread), so the gain's spread is l_full's
                samples[f"{nl}.chance.l_full"] = per_fold["l_full"]
                samples[f"{nl}.chance.gain_given_number"] = [sc["l_given_number"] - f for f in per_fold["l_full"]]
            else:
                for k, v in per_fold.items():
                    samples[f"{nl}.{name}.{k}"] = v
                samples[f"{nl}.{name}.gain_given_number"] = [
                    g - f for g, f in zip(samples[f"{nl}.{name}.l_given_number"], samples[f"{nl}.{name}.l_full"])]
            if "threshold" in folds[0][name]:  # the NMF learners: the threshold each training fold chose by CV
                thr = common.fold_thresholds(folds, name)
                metrics[f"{nl}.{name}.mean_threshold"] = float(np.mean(thr))
                samples[f"{nl}.{name}.mean_threshold"] = thr
            rows.append([f"{nl} labels", name, sc["l_full"], reference.get(f"{nl}.{name}.l_full"),
                         sc["l_given_number"], reference.get(f"{nl}.{name}.l_given_number")])
    protocol = ("leave-one-out" if config.n_folds is None else f"{config.n_folds}-fold") if not unseen else \
        ("leave-one-combination-out" if config.n_folds is None else f"{config.n_folds} folds of whole label combinations")
    if used[0].parts is not None:
        protocol = (f"leave one part of the source recordings out ({metrics['16.n_folds']:.0f} and "
                    f"{metrics['47.n_folds']:.0f} parts)" + ("; each training set without the combinations of its "
                                                              "test part" if unseen else ""))
    note = (f"{protocol}; k = {config.n_components}, {config.max_iter} MU iterations, threshold by {config.inner_cv}-fold "
            f"CV on each training fold; features {config.data} {config.method} histograms, {config.n_bins} bins/dof, "
            f"delay {config.delay}. Training examples per fold: " + ", ".join(
                f"{k} labels {a}-{b}" for k, (a, b) in train_sizes.items())
            + ". Run time: " + ", ".join(f"{k} labels {v:.0f} s" for k, v in seconds.items()) + ".")
    table = Table(title, ["data", "learner", "l_full", "thesis l_full", "l_given_number", "thesis l_given_number"],
                  rows, note=note)
    tables = {"scores": table}
    sens_notes: list[str] = []
    if getattr(config, "sensitivity", False):
        alt = config.alternative_features()
        tag = alt["method"]
        srows = []
        for nl in SUBSETS:
            Y, folds, _, _ = evaluate_mixed(config, ctx, nl, learners=sensitivity_learners, unseen=unseen,
                                            features=alt)
            for name in sensitivity_learners:
                sc = common.pooled_scores(folds, Y, name)
                for k in ("l_full", "l_given_number"):
                    metrics[f"{nl}.{tag}.{name}.{k}"] = sc[k]
                for k, v in common.fold_samples(folds, Y, name).items():
                    samples[f"{nl}.{tag}.{name}.{k}"] = v
                srows.append([f"{nl} labels", name, metrics[f"{nl}.{name}.l_full"], sc["l_full"],
                              metrics[f"{nl}.{name}.l_given_number"], sc["l_given_number"]])
        main = config.features()["method"]
        for nl in SUBSETS:
            parts = []
            for label, (pre, svm) in SETTINGS.items():
                nmf, base = metrics[f"{nl}.{pre}nmf_frobenius.l_full"], metrics[f"{nl}.{pre}{svm}.l_full"]
                parts.append(f"{label}: NMF {nmf:.3f} vs SVM {base:.3f}")
            sens_notes.append(f"{nl} labels, l_full under each setting: " + "; ".join(parts) + ".")
        tables["sensitivity"] = Table(
            f"The histogram setting: {main} (main) against {tag}, same bins and delay",
            ["data", "learner", f"l_full ({main})", f"l_full ({tag})", f"l_given_number ({main})",
             f"l_given_number ({tag})"], srows,
            note="The thesis does not say how Table 3.2's histograms were built: the NMF-vs-SVM claims are decided "
                 "under both (metrics <set>.<method>.<learner>.*).")
    else:  # the claims' settings on the alternative histograms are then "not evaluated"
        tag = config.alternative_features()["method"]
        for nl in SUBSETS:
            for name in sensitivity_learners:
                for k in ("l_full", "l_given_number"):
                    metrics[f"{nl}.{tag}.{name}.{k}"] = float("nan")
    sample_units = {name: _unit_name(name.split(".", 1)[0]) for name in samples}
    return Result(metrics=metrics, tables=tables, sample_units=sample_units, units=units, split_groups=groups,
                  notes=[common.data_source_note(ctx, used), note,
                         "The SVM's l_given_number ranks its per-label decision values; the thesis gives none.",
                         "svm = the thesis' plain linear SVM on raw histograms; svm_std = the same on standardised "
                         "features (ours). The NMF-vs-SVM claims are decided under both and under both histogram "
                         "methods; the other claims use the main setting (soft VQ).",
                         "No claim 'l_given_number >= l_full': it holds for any scores (an exact label set found by the "
                         "threshold is also the top-n of the activations).",
                         "Per-fold values of every score are the result's samples; the folds of a set are its unit "
                         "(corrected resampled t), the two sets are independent."] + sens_notes,
                  samples=samples, extra={"seconds": seconds})


def nmf_vs_svm(nl: str, *, nmf_better: bool = True) -> dict[str, str]:
    """One rule per setting (:data:`SETTINGS`): NMF (Frobenius) l_full above (or below) the SVM's on set ``nl``."""
    op = ">" if nmf_better else "<"
    return {label: f"{nl}.{pre}nmf_frobenius.l_full {op} {nl}.{pre}{svm}.l_full"
            for label, (pre, svm) in SETTINGS.items()}


_NAMES = {"nmf_frobenius": "NMF (Frobenius)", "nmf_kl": "NMF (KL)", "svm": "linear SVM"}
_SCORES = {"l_full": "l_full (exact label set)", "l_given_number": "l_given_number (number of gestures given)",
           "gain_given_number": "gain l_given_number - l_full"}


def magnitude_claims(reference: Mapping[str, float], table: str, lines: Mapping[str, int | str]) -> list[Claim]:
    """A magnitude claim per number of ``reference`` (``<set>.<learner>.<score>``), our number against the thesis'.

    ``lines`` gives the thesis' line of each (set, learner) row, e.g. ``{"16.svm": 2795}``.
    """
    out = []
    for name in reference:
        nl, learner, score = name.split(".")
        extra = ""
        if score == "gain_given_number":
            extra = (f" (the thesis' {{thesis:{nl}.{learner}.l_given_number}} - {{thesis:{nl}.{learner}.l_full}})")
        line = lines[f"{nl}.{learner}"]
        where = f"lines {line}" if isinstance(line, str) else f"line {line}"
        out.append(Claim(f"{table}, {nl} labels, {_NAMES[learner]}: {_SCORES[score]} against the thesis' "
                         f"{{thesis:{name}}}{extra}.", name, kind="magnitude", source=f"{table} ({where})"))
    return out


TABLE_3_2 = {
    "16.svm.l_full": 0.818, "16.nmf_frobenius.l_full": 0.854, "16.nmf_frobenius.l_given_number": 0.971,
    "16.nmf_kl.l_full": 0.789, "16.nmf_kl.l_given_number": 0.905,
    "47.svm.l_full": 0.422, "47.nmf_frobenius.l_full": 0.625, "47.nmf_frobenius.l_given_number": 0.755,
    "47.nmf_kl.l_full": 0.574, "47.nmf_kl.l_given_number": 0.679,
}
#: Table 3.2's numbers, and the gain l_given_number - l_full of NMF (Frobenius) computed from them.
REFERENCE = {**TABLE_3_2, **{
    f"{nl}.nmf_frobenius.gain_given_number": round(TABLE_3_2[f"{nl}.nmf_frobenius.l_given_number"]
                                                   - TABLE_3_2[f"{nl}.nmf_frobenius.l_full"], 6)
    for nl in SUBSETS}}
#: The thesis' line of each row of Table 3.2.
LINES = {"16.svm": 2795, "16.nmf_frobenius": 2796, "16.nmf_kl": 2797, "47.svm": 2798, "47.nmf_frobenius": 2799,
         "47.nmf_kl": 2800}

TITLE = "Table 3.2: label sets of new choreographies"


def compute(config: Config, ctx: RunContext) -> Result:
    """Table 3.2's numbers (:func:`score_table`)."""
    result = score_table(config, ctx, learners=LEARNERS, unseen=False, reference=REFERENCE, title=TITLE)
    result.notes.extend(fill_thesis_numbers(note, REFERENCE) for note in NOTES)
    return result


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Our scores beside the thesis'."""
    return {"scores": score_figure(result, learners=LEARNERS, reference=REFERENCE, title=TITLE)}


#: Why each former claim was restated or reclassified (kept in the record's notes); ``{thesis:NAME}`` is the
#: thesis' number of that name (the reference table).
NOTES = [
    "Restated: 'With 16 labels NMF is at least as good as the SVM (>=)' -> NMF beats the SVM (>), the comparison "
    "the thesis' table makes (NMF {thesis:16.nmf_frobenius.l_full} vs SVM {thesis:16.svm.l_full}), decided under "
    "the four histogram x SVM settings.",
    "Restated: 'NMF l_full at least 0.75 x the thesis' value' -> magnitude claims (our number / the thesis', with "
    "its interval) for every number of Table 3.2: 0.75 was our bar.",
    "Restated: 'Knowing the number of gestures helps substantially: the gain is at least half the thesis'' -> a "
    "magnitude claim on the gain l_given_number - l_full: 'substantially' and 'half' were ours; the thesis reports "
    "both scores to show which part of the error is due to the threshold (lines 2768-2770).",
    "Reclassified as ours: 'All learners far above chance (5 x the most-frequent-label-set score, and above 0.3)' "
    "-> every learner above the most frequent training label set: the thesis gives no chance level; the 5 x and "
    "0.3 bars were ours and are dropped.",
]

EXPERIMENT = register(Experiment(
    id="ch3-choreography",
    title="Choreographies learnt from ambiguous label sets: NMF vs linear SVM",
    thesis_ref="Section 3.3, Table 3.2",
    config_cls=Config,
    compute=compute,
    present=present,
    reference=REFERENCE,
    claims=[
        Claim("With 47 labels NMF (Frobenius) reconstructs exact label sets better than the linear SVM (l_full "
              "{thesis:47.nmf_frobenius.l_full} vs {thesis:47.svm.l_full}).",
              kind="thesis", source="Section 3.3.4, Table 3.2 (lines 2798-2799)", settings=nmf_vs_svm("47")),
        Claim("With 16 labels NMF (Frobenius) reconstructs exact label sets better than the linear SVM (l_full "
              "{thesis:16.nmf_frobenius.l_full} vs {thesis:16.svm.l_full}).",
              kind="thesis", source="Section 3.3.4, Table 3.2 (lines 2795-2796)", settings=nmf_vs_svm("16")),
        Claim("NMF with the Frobenius loss does better than with the Kullback-Leibler divergence on both sets and "
              "both scores (Table 3.2).", kind="thesis", source="Section 3.3.4, Table 3.2 (lines 2796-2800)",
              settings={label: " and ".join(f"{nl}.{pre}nmf_frobenius.{sc} > {nl}.{pre}nmf_kl.{sc}" for nl in SUBSETS
                                            for sc in ("l_full", "l_given_number"))
                        for label, pre in (("soft VQ", ""), ("KDE", "kde."))}),
        # The 16- and 47-label samples come from two different data sets: their sample units differ, so the
        # comparison is Welch's, never pairing fold i of one with fold i of the other.
        Claim("The 47-gesture set is harder than the 16-gesture set: NMF (Frobenius) reconstructs fewer exact label "
              "sets on it ({thesis:47.nmf_frobenius.l_full} vs {thesis:16.nmf_frobenius.l_full}).",
              "47.nmf_frobenius.l_full < 16.nmf_frobenius.l_full",
              kind="thesis", source="Section 3.3.4, Table 3.2 (lines 2806-2808)"),
        *magnitude_claims(REFERENCE, "Table 3.2", LINES),
        Claim("Every learner (NMF Frobenius and KL, both SVMs) reconstructs more exact label sets than predicting the "
              "most frequent training label set, on both sets (a control of ours).",
              " and ".join(f"{nl}.{n}.l_full > {nl}.chance.l_full" for nl in SUBSETS
                           for n in ("nmf_frobenius", "nmf_kl", "svm", "svm_std")), kind="ours"),
    ],
    datasets=("choreo1", "msr-action3d"),
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
