"""ch6-concepts: do internal coefficients specialise on concepts? Mutual information (Fig 6.10).

Thesis section 6.6.3. A multimodal NMF with k = 15 atoms learns from pairs of a motion
demonstration and an acoustic description (the pairs of ``ch6-motion-sound``: by default
real FSDD digits and MSR Action3D actions, all of them used for training; the concepts
are never shown to the learner). For each concept l and
coefficient j of the internal representations w_i of the training pairs, the mutual
information I(X_l; Y_j) between X_l (example i features concept l) and Y_j = w_ij,
discretised into 10 equal-width bins, is estimated from the samples. Coefficients are
aligned with concepts by the Kuhn-Munkres algorithm (maximum total mutual information) and
plotted matched coefficients first (by decreasing mutual information), then the others.

How specialised a matched coefficient is: the fraction ``I(X_l; Y_j) / H(X_l)`` of the
concept's entropy it captures. A control repeats the analysis with the concepts shuffled
across examples, which measures the estimator's bias.

Uncertainty (issue 12): the features are computed once and the multimodal NMF is fitted
``n_repeats`` times from independent initialisations (children of the learner stream);
each fit's shuffled control draws its own permutation (children of the reference stream).
Every metric is the mean over the repetitions and keeps the per-repetition values as its
samples, so the claims are decided by the paired bootstrap over repetitions.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment
from threadpoolctl import threadpool_limits

from ..errors import ConvergenceWarning
from ..motion import MotionHistograms
from ..multimodal import MultimodalNMF
from ..sound.hac import HAC
from . import _ch6_common as common
from .base import Claim, Experiment, Result, RunContext, Table
from .config import PresetConfig
from .registry import register

__all__ = ["Config", "compute", "present", "run", "mutual_information_matrix", "REPEATED"]


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes (``n_per_speaker``, ``n_motion`` select the generated data), the thesis' k = 15, 10 bins.

    ``n_repeats``: NMF fits from as many learner initialisations (the features are computed once).
    """

    n_per_speaker: int = 1000
    n_motion: int = 1100
    k: int = 15
    n_iter: int = 50
    n_bins: int = 10
    motion_bins: int = 25
    n_repeats: int = 10
    seed: int = 0

    # 3 initialisations: one NMF fit costs about a quarter of the single-fit quick run on real data and an
    # eighth on generated data, so 3 add about 45 % and 25 % with --workers 1 (30 % over both variants; with
    # two workers, as make reproduce runs, half that), where 5 would double the real one; the verdicts say
    # inconclusive rather than slow the run down (issue 12's time budget)
    hac_fit_frames: int = 100_000  # training frames (at most) for each HAC codebook: HAC's max_fit_frames
    QUICK = dict(n_per_speaker=250, n_motion=250, n_repeats=3, hac_fit_frames=20_000)


def mutual_information_matrix(y: np.ndarray, W: np.ndarray, n_bins: int = 10) -> np.ndarray:
    """I(X_l; Y_j) in bits for every concept l (rows) and coefficient j (columns).

    X_l is the indicator "the example features concept l" and Y_j the coefficient j
    discretised into ``n_bins`` equal-width bins over its range (thesis section 6.6.3). The
    plug-in estimate from the joint counts, as :func:`sklearn.metrics.mutual_info_score`
    gives for each pair (in nats), computed for every concept at once from one contingency
    table per coefficient (hand-written: sklearn's per-pair call cost a second per fit).

    Parameters
    ----------
    y : ndarray of int, shape (n_samples,)
        Concept of each example.
    W : ndarray of shape (n_samples, k)
        Internal coefficients.
    n_bins : int
        Equal-width bins over each coefficient's range.
    """
    concepts, yi = np.unique(np.asarray(y), return_inverse=True)
    n, n_concepts = yi.size, concepts.size
    out = np.zeros((n_concepts, W.shape[1]))
    n_c = np.bincount(yi, minlength=n_concepts)[:, None].astype(float)  # examples of each concept
    for j in range(W.shape[1]):
        col = W[:, j]
        edges = np.linspace(col.min(), col.max(), n_bins + 1)[1:-1]
        binned = np.digitize(col, edges)
        # joint[c, b]: examples of concept c in bin b; the examples of the other concepts in bin b are the rest
        joint = np.bincount(yi * n_bins + binned, minlength=n_concepts * n_bins).reshape(n_concepts, n_bins)
        n_b = joint.sum(axis=0)[None, :].astype(float)
        total = np.zeros(n_concepts)
        for counts, n_x in ((joint, n_c), (n_b - joint, n - n_c)):  # X_l = 1, then X_l = 0
            with np.errstate(divide="ignore", invalid="ignore"):
                terms = counts / n * np.log2(counts * n / (n_x * n_b))
            total += np.where(counts > 0, terms, 0.0).sum(axis=1)
        out[:, j] = np.maximum(total, 0.0)
    return out


def _entropy_bits(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return -(p * np.log2(p) + (1 - p) * np.log2(1 - p))


def _analyse(y: np.ndarray, W: np.ndarray, n_bins: int) -> dict:
    mi = mutual_information_matrix(y, W, n_bins)
    rows, cols = linear_sum_assignment(-mi)
    matched = mi[rows, cols]
    frac = matched / _entropy_bits(np.bincount(y)[np.unique(y)] / len(y))[rows]
    mask = np.ones_like(mi, dtype=bool)
    mask[rows, cols] = False
    order = list(cols[np.argsort(-matched)]) + [j for j in range(W.shape[1]) if j not in set(cols)]
    return {"mi": mi, "matched": matched, "fraction": frac, "others": mi[mask], "order": order,
            "rows": rows, "cols": cols}


#: Per-repetition metrics (each reported as the mean over the repetitions, with its samples).
REPEATED = ("matched.mean_mi", "matched.max_mi", "others.mean_mi", "matched.mean_fraction", "n_specialised",
            "shuffled.matched.mean_mi")


def _repetition(y: np.ndarray, W: np.ndarray, n_bins: int, control_seed: int) -> tuple[dict, dict, dict]:
    """One fit's analysis, its shuffled-concept control (own permutation) and its metrics."""
    res = _analyse(y, W, n_bins)
    shuffled = _analyse(np.random.default_rng(control_seed).permutation(y), W, n_bins)
    values = {
        "matched.mean_mi": float(res["matched"].mean()),
        "matched.max_mi": float(res["matched"].max()),
        "others.mean_mi": float(res["others"].mean()),
        "matched.mean_fraction": float(res["fraction"].mean()),
        "n_specialised": float(np.sum(res["fraction"] > 0.5)),
        "shuffled.matched.mean_mi": float(shuffled["matched"].mean()),
    }
    return res, shuffled, values


def _fit_repetition(task: dict) -> tuple[dict, dict, dict]:
    """One repetition (module level, so that ``ctx.parallel`` can run it in a worker): fit, analyse, control."""
    # one thread per worker process when the repetitions run side by side; all threads in a plain loop
    with threadpool_limits(1 if task["in_workers"] else None), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = MultimodalNMF(task["k"], max_iter=task["n_iter"], random_state=task["seed"])
        W = model.fit_transform({"sound": task["S"], "motion": task["M"]})
    return _repetition(task["y"], W, task["n_bins"], task["control_seed"])


def compute(config: Config, ctx: RunContext) -> Result:
    """Mutual information and specialisation over the repetitions (no figure; ``figure_data``: the first
    repetition's mutual-information matrix and matching order, and the keywords, for :func:`present`)."""
    st = common.streams(config.seed)
    data = common.load_pairs(ctx, n_per_speaker=config.n_per_speaker, n_motion=config.n_motion, seeds=st)
    y = data["y"]
    # children of the learner stream: HAC codebooks, motion codebook, then one NMF initialisation per repetition
    # (child_seeds(s, n)[:m] == child_seeds(s, m): the features are those of a single fit)
    learner = common.child_seeds(st.learner, 2 + config.n_repeats)
    controls = common.child_seeds(st.reference, config.n_repeats)  # one concept permutation per repetition
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        S = HAC(random_state=learner[0], max_fit_frames=config.hac_fit_frames).fit_transform(data["mfcc"])
        M = MotionHistograms(data="joint", method="vq", n_bins=config.motion_bins, delay=3,
                             random_state=learner[1]).fit_transform(data["angles"])
    tasks = [{"S": S, "M": M, "y": y, "k": config.k, "n_iter": config.n_iter, "n_bins": config.n_bins,
              "seed": learner[2 + r], "control_seed": controls[r], "in_workers": ctx.workers > 1}
             for r in range(config.n_repeats)]
    reps = ctx.parallel(_fit_repetition, tasks, desc="NMF initialisations")
    per_rep = [v for _, _, v in reps]
    metrics = {name: float(np.mean([v[name] for v in per_rep])) for name in REPEATED}
    metrics["n_concepts"] = float(len(np.unique(y)))
    metrics["concept_entropy_bits"] = float(_entropy_bits(np.array([1.0 / metrics["n_concepts"]]))[0])
    # every repeated metric has one value per repetition, all from the same fits (paired)
    samples = {name: [v[name] for v in per_rep] for name in REPEATED}
    res = reps[0][0]  # the figure and the matching table show the first repetition
    keywords = data["keywords"]
    rows = [[keywords[r], int(c), float(res["mi"][r, c]), float(f)]
            for r, c, f in sorted(zip(res["rows"], res["cols"], res["fraction"]), key=lambda t: -t[2])]
    rep_rows = [[r + 1] + [v[name] for name in REPEATED] for r, v in enumerate(per_rep)]
    return Result(
        metrics=metrics,
        samples=samples,
        tables={"matching": Table("Kuhn-Munkres matching of concepts and coefficients (repetition 1)",
                                  ["concept", "coefficient", "mutual information (bits)", "fraction of H(concept)"],
                                  rows),
                "repetitions": Table("Per repetition (NMF initialisation; shuffled control with its own permutation)",
                                     ["repetition"] + list(REPEATED), rep_rows)},
        figure_data={"mi": res["mi"], "order": res["order"], "keywords": keywords},
        notes=[common.data_source_note(ctx, data["speech"], data["motion"]),
               f"{len(y)} sound-motion pairs of speaker {data['speaker']} (all used for training); k = {config.k}, "
               f"{config.n_iter} iterations; coefficients discretised into {config.n_bins} equal-width bins. "
               f"{config.n_repeats} repetitions: the HAC and motion features are computed once, the multimodal NMF "
               "is fitted from a new initialisation each time (children of the learner stream), and its shuffled-"
               "concept control uses a permutation of its own (children of the reference stream). Metrics are means "
               "over the repetitions, with the per-repetition values as samples; n_specialised is the mean count.",
               f"Shuffled-concept control: matched mean {metrics['shuffled.matched.mean_mi']:.3f} bits (estimator "
               "bias).",
               common.KEYWORDS_NOTE,
               "Thesis ambiguities of Fig. 6.10 and the readings taken: (1) the 10 bins are not said to be of equal "
               "width or equal frequency: equal-width bins over each coefficient's range (equal-frequency bins would "
               "make every coefficient's marginal uniform); (2) 'pairs ... from the training set' does not say which "
               "training set: all the pairs, as no test set is used here; (3) how specialised a coefficient must be "
               "to count is not stated: more than half of the concept's entropy (the project's threshold)."],
    )


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Fig. 6.10: mutual information between concepts and coefficients (first repetition), matched ones first."""
    res = result.figure_data  # the first repetition's matrix and matching order
    keywords = res["keywords"]
    mi_sorted = res["mi"][:, res["order"]]
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.subplots()
    im = ax.imshow(mi_sorted, aspect="auto", cmap="viridis")
    ax.set_yticks(range(len(keywords)), keywords, fontsize=8)
    ax.set_xticks(range(len(res["order"])), [str(j) for j in res["order"]], fontsize=7)
    ax.set_xlabel("internal coefficient (its index; matched ones first)")
    ax.set_ylabel("concept (keyword)")
    ax.set_title(f"Fig. 6.10: mutual information, k = {config.k}, repetition 1 of {config.n_repeats}")
    fig.colorbar(im, ax=ax).set_label("mutual information with the concept (bits)")
    return {"fig6_10": fig}


EXPERIMENT = register(Experiment(
    id="ch6-concepts",
    title="Specialisation of internal coefficients on concepts (mutual information)",
    thesis_ref="Section 6.6.3, Fig. 6.10",
    config_cls=Config,
    compute=compute,
    present=present,
    reference={},
    claims=[
        Claim("Some coefficients are highly specialised: at least one captures more than half of a concept's entropy "
              "(mean count over the NMF initialisations).",
              "n_specialised >= 1"),
        Claim("The relationship is not a perfect one-to-one: not every concept has its own specialised coefficient.",
              "n_specialised < n_concepts"),
        Claim("The alignment reflects learnt structure, not estimator bias: matched coefficients carry far more "
              "information than with shuffled concepts.",
              "matched.mean_mi > 5 * shuffled.matched.mean_mi"),
    ],
    datasets=("fsdd", "msr-action3d", "acorns", "audio", "choreo2"),
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
