"""ch3-unseen: label sets of choreographies whose gesture combination was never seen (Thesis Table 3.3).

Thesis section 3.3.4, "Handling unknown combinations of primitives" (lines 2810-2840). Same
data, features and learners as ``ch3-choreography`` (see that module for every choice:
k = 150, MU iterations, soft-VQ joint angle-velocity histograms, threshold by CV on the
training fold), but the test sets are made only of label combinations absent from their
training set. Synthetic and Choreo1 examples (each its own recording): all examples showing
one combination are held out together; full mode leaves one combination out at a time
(the analogue of the thesis' leave-one-out), quick mode uses 5 folds of whole
combinations. MSR limb mixtures (built per part of their source recordings): each fold
tests one part, and its training set is the other parts without the mixtures whose
combination the test part shows (so it is smaller than the rest of the data; the unit
says by how much).

What the thesis states: Table 3.3 (lines 2828-2836) gives NMF (Frobenius) l_full and
l_given_number and the SVM's l_full on unseen combinations: with 47 labels NMF beats the
SVM, with 16 labels the SVM does better. Both orders are thesis claims, decided under the
four histogram x SVM settings of ``ch3-choreography`` (soft VQ or KDE, plain or
standardised SVM), in both presets. Each number of the table, and NMF's gain
l_given_number - l_full computed from it, is a magnitude claim. The thesis says the
system recognises combinations never observed in training (lines 2862-2866) without a
bar: "most unseen combinations named with the number given" (l_given_number above 0.5)
is ours.

``chance.l_full`` (the most frequent training label set) is 0 by construction here;
``chance.l_given_number`` is the expected score of a random ranking of the labels. A test
gesture can be absent from every training example of its fold (rare in the 16-label set,
possible in the 47-label set); it then can never be predicted, by any learner.
"""

from __future__ import annotations

from dataclasses import dataclass

from matplotlib.figure import Figure

from ...engine import Claim, Experiment, Result, RunContext, register
from .choreography import Config as _BaseConfig
from .choreography import SUBSETS, magnitude_claims, nmf_vs_svm, score_figure, score_table

__all__ = ["Config", "compute", "present", "run"]

LEARNERS = ("nmf_frobenius", "svm", "svm_std", "chance")
#: The learners fitted again on KDE histograms (the settings of the NMF-vs-SVM claims).
SENSITIVITY_LEARNERS = ("nmf_frobenius", "svm", "svm_std")


@dataclass(frozen=True)
class Config(_BaseConfig):
    """As ``ch3-choreography``; ``n_folds=None`` leaves one label combination out at a time.

    The quick preset is ``ch3-choreography``'s with 5 folds of whole combinations instead of
    10 (the KDE setting of its claims is computed in both presets; 5 folds pay for it)."""

    QUICK = {**_BaseConfig.QUICK, "n_folds": 5}
    # the smoke preset: ch3-choreography's with more examples of 47 labels (with 90, most test gestures are unseen
    # in training) and a larger learner
    SMOKE = {**_BaseConfig.SMOKE, "n_records_full": 200, "n_components": 50, "max_iter": 80}


TABLE_3_3 = {
    "16.nmf_frobenius.l_full": 0.568, "16.nmf_frobenius.l_given_number": 0.800, "16.svm.l_full": 0.667,
    "47.nmf_frobenius.l_full": 0.406, "47.nmf_frobenius.l_given_number": 0.653, "47.svm.l_full": 0.206,
}
#: Table 3.3's numbers, and the gain l_given_number - l_full of NMF (Frobenius) computed from them.
REFERENCE = {**TABLE_3_3, **{
    f"{nl}.nmf_frobenius.gain_given_number": round(TABLE_3_3[f"{nl}.nmf_frobenius.l_given_number"]
                                                   - TABLE_3_3[f"{nl}.nmf_frobenius.l_full"], 6)
    for nl in SUBSETS}}
#: The thesis' line of each row of Table 3.3.
LINES = {"16.nmf_frobenius": 2830, "16.svm": 2831, "47.nmf_frobenius": 2832, "47.svm": 2833}

TITLE = "Table 3.3: label sets of choreographies showing unseen combinations"

#: Why each former claim was restated or reclassified (kept in the record's notes).
NOTES = [
    "Restated: 'NMF l_full at least 0.75 x the thesis' value' -> magnitude claims (our number / the thesis', with "
    "its interval) for every number of Table 3.3: 0.75 was our bar.",
    "Reclassified as ours: 'NMF names the gestures of most unseen combinations (l_given_number above 0.5)': the "
    "thesis says the system recognises combinations never observed (lines 2862-2866) but gives no bar; 'most' "
    "(0.5) is ours.",
    "Restated: 'most errors are in the number of gestures: the gain is at least half the thesis'' -> a magnitude "
    "claim on the gain l_given_number - l_full: 'most' and 'half' were ours.",
    "The NMF-vs-SVM orders were decided with the plain SVM on soft-VQ histograms only (the quick preset skipped the "
    "KDE histograms); they are now decided under all four settings in both presets.",
]


def compute(config: Config, ctx: RunContext) -> Result:
    """Table 3.3's numbers (:func:`~mmconcepts.experiments.ch3.choreography.score_table` on unseen combinations)."""
    result = score_table(config, ctx, learners=LEARNERS, unseen=True, reference=REFERENCE, title=TITLE,
                         sensitivity_learners=SENSITIVITY_LEARNERS)
    result.notes.extend(NOTES)
    return result


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Our scores beside the thesis'."""
    return {"scores": score_figure(result, learners=LEARNERS, reference=REFERENCE, title=TITLE)}


EXPERIMENT = register(Experiment(
    id="ch3-unseen",
    title="Unseen combinations of gestures: NMF vs linear SVM",
    thesis_ref="Section 3.3.4, Table 3.3",
    config_cls=Config,
    compute=compute,
    present=present,
    reference=REFERENCE,
    claims=[
        Claim("On unseen combinations with 47 labels NMF (Frobenius) reconstructs exact label sets better than the "
              "linear SVM (l_full {thesis:47.nmf_frobenius.l_full} vs {thesis:47.svm.l_full}).",
              kind="thesis", source="Section 3.3.4, Table 3.3 (lines 2832-2833)", settings=nmf_vs_svm("47")),
        Claim("On unseen combinations with 16 labels the linear SVM reconstructs exact label sets better than NMF "
              "(Frobenius) (l_full {thesis:16.svm.l_full} vs {thesis:16.nmf_frobenius.l_full}).",
              kind="thesis", source="Section 3.3.4, Table 3.3 (lines 2830-2831)",
              settings=nmf_vs_svm("16", nmf_better=False)),
        *magnitude_claims(REFERENCE, "Table 3.3", LINES),
        Claim("Given the number of gestures, NMF (Frobenius) names the gestures of most unseen combinations "
              "(l_given_number above 0.5, our bar), on both sets.",
              "16.nmf_frobenius.l_given_number > 0.5 and 47.nmf_frobenius.l_given_number > 0.5", kind="ours"),
    ],
    datasets=("choreo1", "msr-action3d"),
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
