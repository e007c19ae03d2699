"""ch2-nmf-recovery: beta-NMF recovers a known dictionary when the problem is identifiable.

Thesis section 2.1 (multiplicative updates, eq. 2.15-2.19, Table 2.2; projected gradient,
eq. 2.9-2.13; comparison up to scaling and permutation, section 2.1.1) and Appendix A.2
(the factorization is unique, up to scaling and permutation, only when the data fill a
simplicial cone that cannot be widened).

Data are drawn from a known nonnegative dictionary H (n_components x n_features) and
coefficients W, then corrupted by multiplicative Gamma noise (E = 1, a relative spread set by
``noise``; it keeps every cell positive, so that beta <= 0 is defined). Two generators:

* *identifiable*: every atom owns a block of features that no other atom uses (a separable
  dictionary), and coefficients are sparse (Dirichlet with alpha < 1), so some examples lie
  near each extreme ray of the cone: the sufficient conditions of Donoho & Stodden;
* *non-identifiable*: dense atoms and dense coefficients (Dirichlet alpha = 5), whose data
  fill only the middle of the cone, which a wider cone also explains.

Each beta in ``betas`` is fit with multiplicative updates (MM exponent), the heuristic
update (eq. 2.17) where it differs, and projected gradient for beta in ``pg_betas``; the
recovered dictionary is compared with the truth by the Hungarian matching distance
(mean cosine distance between matched atoms).

The thesis has no experiment in chapter 2; its statements are qualitative. What it says,
and how it is checked here:

* the multiplicative updates with the exponent of Table 2.2 never increase the objective
  (section 2.1.2, lines 1164-1169): a property of the code, tested in the test-suite and
  kept in the record as a sanity check of the run (kind ``check``);
* the factorization is unique, up to scaling and permutation, when the simplicial cone of
  the data cannot be widened (sufficient conditions of Donoho and Stodden), and in general
  it is not (Appendix A.2.3, lines 6479-6483): the dictionary recovered from identifiable
  data is closer to the true one than the dictionary recovered without those conditions
  (kind ``thesis``);
* every beta and solver recovering the identifiable dictionary to a matching distance
  below 0.02 is our bar (kind ``ours``): the thesis states uniqueness of the solution, not
  that a given solver reaches it (it converges to a local minimum, line 1060).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from ...nmf import beta_nmf, match_components
from ...errors import ParameterError
from ...engine import Claim, Experiment, PresetConfig, Result, RunContext, SampleUnit, Streams, Table, register, streams

__all__ = ["Config", "compute", "present", "run", "make_data", "run_streams"]

KINDS = ("identifiable", "nonidentifiable")


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes, betas and solvers of the recovery experiment.

    ``learner_seed`` (default: spawned from ``seed``) changes the solvers' initialisation
    alone, leaving the data unchanged (see :func:`run_streams`).
    """

    n_samples: int = 600
    n_features: int = 120
    n_components: int = 8
    noise: float = 0.05
    betas: tuple[float, ...] = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)
    pg_betas: tuple[float, ...] = (1.0, 2.0)
    max_iter: int = 1000
    pg_max_iter: int = 500
    n_repeats: int = 3
    learner_seed: int | None = None
    seed: int = 0

    QUICK = dict(n_samples=200, n_features=50, n_components=5, max_iter=300, pg_max_iter=300, n_repeats=5)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_samples=40, n_features=12, n_components=3, max_iter=30, pg_max_iter=30, n_repeats=2)
    FULL = dict(n_samples=1000, n_features=200, n_components=10, max_iter=2000, pg_max_iter=1000, n_repeats=5)


def make_data(kind: str, n_samples: int, n_features: int, n_components: int, noise: float,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Return (X, H_true): noisy data (n_samples, n_features) and its true dictionary.

    ``kind`` is 'identifiable' (separable atoms, sparse coefficients) or
    'nonidentifiable' (dense atoms, dense coefficients).
    """
    k, m = n_components, n_features
    if kind == "identifiable":
        H = np.zeros((k, m))
        blocks = np.array_split(rng.permutation(m), k)
        for i, cols in enumerate(blocks):
            H[i, cols] = rng.uniform(0.5, 1.5, cols.size)
        W = rng.dirichlet(np.full(k, 0.3), n_samples)
    elif kind == "nonidentifiable":
        H = rng.uniform(0.2, 1.0, (k, m))
        W = rng.dirichlet(np.full(k, 5.0), n_samples)
    else:
        raise ParameterError(f"kind must be 'identifiable' or 'nonidentifiable'; got {kind!r}")
    H /= H.sum(axis=1, keepdims=True) / m  # atoms of mean 1
    W *= rng.uniform(5.0, 15.0, (n_samples, 1))
    clean = W @ H
    shape = 1.0 / noise**2  # Gamma(shape, 1/shape): mean 1, relative std = noise
    X = clean * rng.gamma(shape, 1.0 / shape, clean.shape) + 1e-3 * clean.mean()
    return X, H


def run_streams(config: Config) -> Streams:
    """The run's random streams: ``data`` (kind index, repeat) draws the dictionary, coefficients
    and noise; ``learner`` (kind index, repeat) the solvers' initialisation, shared by all methods
    of a repeat so that they are compared from the same start; ``reference`` (repeat) the random
    dictionary that gives the chance level.

    The learner stream is drawn from ``config.learner_seed`` when it is set
    (:meth:`~mmconcepts.engine.Streams.rooted`), else from ``config.seed``; it never draws data.
    """
    return streams(config.seed, learner_seed=config.learner_seed)


def _methods(config: Config) -> list[tuple[str, float, str, str]]:
    out = []
    for beta in config.betas:
        out.append((f"beta_{beta:g}.mu", beta, "mu", "mm"))
        if beta < 1.0 or beta > 2.0:
            out.append((f"beta_{beta:g}.mu_heuristic", beta, "mu", "heuristic"))
    for beta in config.pg_betas:
        out.append((f"beta_{beta:g}.pg", beta, "pg", "mm"))
    return out


def max_relative_increase(history: np.ndarray) -> float:
    """Largest increase of the objective from one recorded iteration to the next, relative to its start.

    ``max(0, max_t (L[t+1] - L[t])) / |L[0]|``: 0 when the objective never increases (a decrease is
    not an increase). NaN when fewer than two values were recorded: a run that recorded no step
    cannot show that the objective does not increase.
    """
    history = np.asarray(history, dtype=float)
    if history.size < 2:
        return float("nan")
    return float(max(0.0, np.max(np.diff(history))) / abs(history[0]))


def _one_run(task):
    config, kind, repeat, name, beta, solver, rule, data_ss, learner_ss = task
    X, H_true = make_data(kind, config.n_samples, config.n_features, config.n_components, config.noise,
                          np.random.default_rng(data_ss))
    t0 = time.perf_counter()
    loss_every = 1 if solver == "mu" else 10
    max_iter = config.max_iter if solver == "mu" else config.pg_max_iter
    res = beta_nmf(X, config.n_components, beta_loss=beta, solver=solver, update_rule=rule, init="nndsvda",
                   random_state=np.random.default_rng(learner_ss), max_iter=max_iter, tol=0, loss_every=loss_every)
    elapsed = time.perf_counter() - t0
    match = match_components(res.H, H_true)
    hist = res.loss_history
    increase = max_relative_increase(hist)
    return dict(kind=kind, repeat=repeat, name=name, beta=beta, solver=solver, rule=rule,
                distance=match.distance, max_rel_increase=increase, final_loss=float(hist[-1]),
                history=(res.loss_iterations.tolist(), (hist / hist[0]).tolist()), seconds=elapsed,
                n_iter=res.n_iter)


def compute(config: Config, ctx: RunContext) -> Result:
    """The fits, distances and property check (no figures; ``figure_data["loss_curves"]``: the
    first identifiable repeat's normalised loss histories, for :func:`present`)."""
    st = run_streams(config)
    tasks = []
    for k, kind in enumerate(KINDS):
        for repeat in range(config.n_repeats):
            for name, beta, solver, rule in _methods(config):
                tasks.append((config, kind, repeat, name, beta, solver, rule, st.sequence("data", k, repeat),
                              st.sequence("learner", k, repeat)))
    runs = ctx.parallel(_one_run, tasks, desc="NMF fits")

    metrics: dict[str, float] = {}
    samples: dict[str, list[float]] = {}
    rows = []
    for name, beta, solver, rule in _methods(config):
        for kind in ("identifiable", "nonidentifiable"):
            sel = sorted((r for r in runs if r["name"] == name and r["kind"] == kind), key=lambda r: r["repeat"])
            dist = float(np.median([r["distance"] for r in sel]))
            metrics[f"{kind}.{name}.distance"] = dist
            samples[f"{kind}.{name}.distance"] = [r["distance"] for r in sel]
            if kind == "identifiable":
                rows.append([f"{beta:g}", solver, rule, dist,
                             float(np.median([next(s for s in runs if s["name"] == name and s["kind"] == "nonidentifiable"
                                                   and s["repeat"] == r["repeat"])["distance"] for r in sel])),
                             max(r["max_rel_increase"] for r in sel),
                             float(np.median([r["seconds"] for r in sel]))])
    # the sanity check keeps its maximum over every MM run (the updates never increase the objective): a fact of
    # this run, not an estimate, so it has no samples (its claim is decided on the reported number)
    mm = [r for r in runs if r["solver"] == "mu" and r["rule"] == "mm"]
    metrics["mu_mm.max_relative_increase"] = float(np.max([r["max_rel_increase"] for r in mm]))
    ident = [r["distance"] for r in runs if r["kind"] == "identifiable"]
    nonident = [r["distance"] for r in runs if r["kind"] == "nonidentifiable"]
    metrics["identifiable.max_distance"] = float(np.max(ident))
    worst = max(_methods(config), key=lambda m: metrics[f"identifiable.{m[0]}.distance"])[0]
    metrics["identifiable.worst_method_median_distance"] = metrics[f"identifiable.{worst}.distance"]
    # per repeat (paired by repeat with the per-method distances and the random dictionary): the worst
    # run of the repeat (max over methods) for the worst case over all runs, and the distance of the
    # method with the worst median for the worst method's median
    per_repeat_max = [float(max(r["distance"] for r in runs if r["kind"] == "identifiable" and r["repeat"] == rep))
                      for rep in range(config.n_repeats)]
    samples["identifiable.max_distance"] = per_repeat_max
    samples["identifiable.worst_method_median_distance"] = list(samples[f"identifiable.{worst}.distance"])
    metrics["identifiable.median_distance"] = float(np.median(ident))
    metrics["nonidentifiable.median_distance"] = float(np.median(nonident))
    for kind in KINDS:  # per repeat: the median over methods (paired by repeat across kinds)
        samples[f"{kind}.median_distance"] = [
            float(np.median([r["distance"] for r in runs if r["kind"] == kind and r["repeat"] == rep]))
            for rep in range(config.n_repeats)]
    rand = []
    for rep in range(config.n_repeats):  # chance level: a random dictionary against each repeat's true one
        _, H_true = make_data("identifiable", config.n_samples, config.n_features, config.n_components, config.noise,
                              st.rng("data", KINDS.index("identifiable"), rep))
        rand.append(match_components(st.rng("reference", rep).random(H_true.shape), H_true).distance)
    metrics["random_dictionary.distance"] = float(np.median(rand))
    samples["random_dictionary.distance"] = rand

    table = Table(
        "Dictionary recovery (median over repeats; matching distance = mean cosine distance of matched atoms)",
        ["beta", "solver", "update", "distance (identifiable)", "distance (non-identifiable)",
         "max relative loss increase", "seconds"],
        rows,
        note=f"{config.n_samples} samples, {config.n_features} features, k = {config.n_components}, "
             f"Gamma noise {config.noise:.0%}, {config.max_iter} MU and {config.pg_max_iter} projected-gradient iterations.",
    )

    first = [r for r in runs if r["kind"] == "identifiable" and r["repeat"] == 0]
    return Result(metrics=metrics, tables={"recovery": table},
                  figure_data={"loss_curves": [{k: r[k] for k in ("kind", "repeat", "name", "solver", "history")}
                                               for r in first]},
                  samples=samples,
                  sample_units={name: "repeats" for name in samples},
                  units={"repeats": SampleUnit.seeds(
                      "independent repetitions: a new dictionary, coefficients and noise for each data kind, and a "
                      "new initialisation of the solvers")},
                  notes=_notes(config, worst, len(mm)))


def _notes(config: Config, worst: str, n_mm: int) -> list[str]:
    return [
        "The thesis has no experiment in chapter 2 and gives no numbers: its statements are qualitative (section "
        "2.1.2, Appendix A.2), so the reference table is empty and there is no magnitude claim.",
        f"{config.n_repeats} independent repetitions per data kind (a new dictionary, coefficients and noise, and a "
        "new initialisation of the solvers each); distances are medians over repetitions, with the per-repetition "
        "values as samples (identifiable/nonidentifiable.median_distance: per repetition, the median over methods; "
        "random_dictionary.distance: one random dictionary per repetition; "
        "identifiable.worst_method_median_distance: the per-repetition distances of the method with the worst "
        f"median, {worst}; identifiable.max_distance: per repetition, the worst run of that repetition). All "
        "samples are of one unit, the repetitions, paired by repetition index (the two data kinds of a repetition "
        "are independent draws; pairing them changes no expected variance).",
        "Claim kinds. 'The objective never increases' is a property of the code (the auxiliary-function argument "
        "of section 2.1.2), tested in the test-suite for every beta; it stays in the record only as a sanity check "
        "of this run (kind check, never evidence): the largest increase between two iterations over every "
        f"multiplicative-update run with the MM exponent ({n_mm} runs), relative to the run's initial objective, "
        "a fact of the run decided without samples. The heuristic update (eq. 2.17) carries no such guarantee "
        "for every beta: its runs are in the table, not in the check.",
        "Reclassified: 'the recovered dictionary is further from the truth without the identifiability "
        "conditions' was checked at twice the distance, a bar of ours; it is now the plain comparison, "
        "non-identifiable distance > identifiable distance, and ours: Appendix A.2.3 (lines 6479-6483) states that "
        "the factorization is unique under the sufficient conditions, not unique in general, and says nothing of "
        "how close a solver comes (our two generators also differ in sparsity, not in identifiability alone). "
        "The matching distance is a cosine distance, smaller "
        "between dense positive vectors than between sparse ones: on this scale the dense, non-identifiable "
        "atoms look closer to anything, which works against the claim.",
        "Reclassified: 'every beta and solver recovers the identifiable dictionary' (median distance below 0.02) "
        "is ours: the thesis states that the solution is unique under these conditions, not that a given solver "
        "reaches it (the updates converge to a local minimum, line 1060); 0.02 is our bar, against about 0.5 for "
        "a random dictionary (random_dictionary.distance). Its former second part (a random dictionary is ten "
        "times further) followed from the first and was dropped.",
        f"Quick preset: five independent repetitions of {Config.QUICK['n_samples']} samples x "
        f"{Config.QUICK['n_features']} features and {Config.QUICK['max_iter']} iterations of every solver; the "
        "thesis fixes no size for this experiment.",
        "Random streams (mmconcepts.engine.Streams): the seed's data, learner and reference streams draw the data, the solvers' initialisation "
        "(nndsvda's randomized SVD; one stream per repetition, shared by all methods) and the random reference "
        "dictionary independently.",
    ]


def present(result: Result, config: Config) -> dict[str, Figure]:
    """The loss curves of the first identifiable repeat and the distances by method."""
    metrics = result.metrics
    fig_loss = Figure(figsize=(7, 4.5))
    ax = fig_loss.subplots()
    for r in result.figure_data["loss_curves"]:
        its, h = r["history"]
        ax.plot(np.asarray(its) + 1, h, label=r["name"], lw=1.2, ls="-" if r["solver"] == "mu" else "--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("iteration + 1 (1 = initialisation)")
    ax.set_ylabel("objective / initial objective")
    ax.set_title("Loss curves on identifiable data (first repeat)")
    ax.legend(fontsize=7, ncol=2)
    fig_loss.tight_layout()

    fig_dist = Figure(figsize=(7.5, 4.6), layout="constrained")
    ax = fig_dist.subplots()
    names = [m[0] for m in _methods(config)]
    x = np.arange(len(names))

    def bars(offset, kind, label):  # the median over repeats, the repeats' range as error bars
        keys = [f"{kind}.{n}.distance" for n in names]
        med = np.array([metrics[k] for k in keys], dtype=float)
        runs = [np.asarray(result.samples.get(k, []), dtype=float) for k in keys]
        err = None
        if all(r.size > 1 for r in runs):
            err = np.array([[m - r.min() for m, r in zip(med, runs)], [r.max() - m for m, r in zip(med, runs)]])
            err = np.clip(err, 0, None)
        ax.bar(x + offset, med, 0.4, yerr=err, capsize=2, error_kw={"lw": 0.8}, label=label)

    bars(-0.2, "identifiable", "identifiable data")
    bars(0.2, "nonidentifiable", "non-identifiable data")
    ax.axhline(metrics["random_dictionary.distance"], color="k", ls=":",
               label="a random dictionary (the chance level)")
    ax.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax.set_yscale("log")
    ax.set_xlabel("beta and solver")
    ax.set_ylabel("matching distance to the true dictionary\n(mean cosine distance of matched atoms)")
    ax.set_title("Dictionary recovery: median over repeats (error bars: their range)")
    ax.legend(fontsize=8)

    return {"loss_curves": fig_loss, "distances": fig_dist}


EXPERIMENT = register(
    Experiment(
        id="ch2-nmf-recovery",
        title="Beta-NMF: monotone multiplicative updates and dictionary recovery",
        thesis_ref="Section 2.1 (eq. 2.2-2.19, Table 2.2), Appendix A.2",
        config_cls=Config,
        compute=compute,
        present=present,
        reference={},
        claims=[
            Claim("Sanity check of this run: the objective never increased under the multiplicative updates with "
                  "the MM exponent of Table 2.2 (every beta, every iteration, every run).",
                  "mu_mm.max_relative_increase <= 0.000000001", kind="check"),
            Claim("Under the identifiability conditions of Appendix A.2 the factorization is unique up to scaling and "
                  "permutation, and without them it is not: the dictionary recovered from identifiable data is "
                  "closer to the true one than the dictionary recovered from data without those conditions (median "
                  "over betas and solvers).",
                  "identifiable.median_distance < nonidentifiable.median_distance", kind="ours"),
            Claim("On identifiable data every beta and solver recovers the dictionary up to scaling and "
                  "permutation in the median run: the method with the worst median stays below a matching "
                  "distance of 0.02, our bar (a random dictionary: about 0.5; single runs can stop in a local "
                  "minimum, see identifiable.max_distance).",
                  "identifiable.worst_method_median_distance < 0.02", kind="ours"),
        ],
        description=__doc__.split("\n\n")[0],
    )
)

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
