"""ch4-inverse-control: a dictionary of primitive cost functions from mixed demonstrations (Fig 4.1-4.3).

Thesis section 4.2.2. An agent in [0, 1]^2 descends costs on a 5 x 5 grid of Gaussian
radial basis functions (F = 25) by eq. (4.1). Six primitive costs (i.i.d. standard normal
weights on the features: the thesis does not say how its primitives were drawn) are mixed
2 or 3 at a time (weights uniform in [0.5, 1.5]); 200 training demonstrations, each from
a random start point. Learners: the flat imitator (Brillinger's regression, eq. 4.3, one
demonstration), the dictionary learnt from demonstrations and given coefficients
(supervised), and the fully unsupervised dictionary learner (eq. 4.5-4.7). Score: the
relative L2 error between demonstrator and imitator trajectories.

Data path. The demonstrator and the imitator are the same agent ("identical bodies"):
every trajectory, demonstrated or imitated, follows the discrete form of eq. (4.1) given in
section 4.2.1, ``q_{t+1} = q_t - lambda dt J(q_t)^T beta`` (``dynamics='euler'``, the
default, as the thesis and the issue specify), for ``n_steps`` steps. The learners see
the demonstrations through a noisy sensor, so their regressions are not exact; the
imitators' trajectories are compared with the noise-free demonstrator's.
``dynamics='ode'`` instead integrates the continuous-time eq. (4.1) with an adaptive
solver (LSODA, rtol 1e-8, atol 1e-10) sampled every ``dt``, for both demonstrator and
imitators, while the learners still regress on the discrete approximation: the error
then also contains that approximation's bias (about 0.03 relative error for the supervised
learner on the quick preset, 10 times the thesis' numbers).

Random streams. Each repetition spawns independent ``numpy.random.SeedSequence`` children for
the data (true dictionary, mixtures, start points), the sensor noise and the learners'
initial dictionaries (:func:`streams`): the seed that drew the data never reaches a learner.

Learners. The supervised learner minimises eq. (4.5) in D by conjugate gradient
(``d_solver='cg'``, run to convergence); the thesis says "gradient descent" without a step
count, and steepest descent from a random start needs thousands of steps on this
ill-conditioned quadratic (the sensitivity table shows it at 200 steps). The unsupervised
model is invariant to any invertible mixing of the atoms, so its dictionary is scored up to
one (:func:`mixing_error`).

Sensor noise. The thesis gives none. Its agent models kinesthetic demonstrations read on
the imitator's own body (section 4.2.1), i.e. from joint encoders; a 12-bit encoder
resolves 1/4096 of its range, a quantisation noise of standard deviation
``1 / (4096 sqrt(12)) ~ 7e-5`` of the range. We take ``sensor_noise = 1e-4`` of the
workspace side (Q = [0, 1]^2), i.i.d. Gaussian on each observed coordinate; it was fixed
from that argument, not fitted to the thesis' numbers. Finite differences amplify it by
``1 / dt``: with ``dt = 0.01`` the velocity noise is ~0.014 against speeds of order 1.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment

from ..tasks import FactorialInverseControl, RBFFeatures, brillinger_regression, control_trajectories, relative_l2_error
from .base import Claim, Experiment, Result, RunContext, Table
from .config import PresetConfig
from .registry import register

__all__ = ["Config", "compute", "present", "run", "streams", "make_data", "mixing_error"]

LEARNERS = ("flat", "supervised", "unsupervised")
#: thesis section 4.2.2: mean relative L2 error of the supervised learner on train and test tasks
THESIS_TRAIN, THESIS_TEST = 0.001127, 0.002675
#: the sensitivity table's cells: (metric label, dynamics, sensor noise, D solver)
SENSITIVITY = (("euler.noise_1e_4", "euler", 1e-4, "cg"), ("euler.noise_0", "euler", 0.0, "cg"),
               ("euler.noise_1e_3", "euler", 1e-3, "cg"), ("ode.noise_1e_4", "ode", 1e-4, "cg"),
               ("ode.noise_0", "ode", 0.0, "cg"), ("ode.noise_1e_3", "ode", 1e-3, "cg"),
               ("euler.noise_1e_4.steepest_200", "euler", 1e-4, "steepest"))
SENSITIVITY_METRICS = ("supervised.train.rel_l2", "supervised.test.rel_l2", "supervised.new_start.rel_l2",
                       "supervised.dictionary_rel_error")


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes of the factorial inverse control experiment (defaults: the thesis' settings).

    ``sensor_noise`` is the standard deviation of the Gaussian noise on observed positions,
    as a fraction of the workspace side (see the module docstring for the default).
    ``max_iter`` counts the unsupervised learner's alternations, ``supervised_max_iter``
    the supervised learner's gradient steps on D (``d_solver``: 'cg' conjugate gradient,
    'steepest' steepest descent; see :class:`~mmconcepts.tasks.FactorialInverseControl`).
    ``n_repeats`` independent repetitions (new dictionary, tasks, noise and learner
    initialisation each); metrics are means over them, per-repetition values their
    samples. ``learner_seed`` (default: spawned from ``seed``) changes the
    learners' initialisation alone; ``sensitivity`` adds the sensitivity table (on every
    repetition's dictionary and tasks).
    """

    grid_size: int = 5
    n_primitives: int = 6
    n_train: int = 200
    n_test: int = 100
    n_steps: int = 100
    dt: float = 0.01
    lam: float = 1.0
    max_iter: int = 200
    supervised_max_iter: int = 2000
    d_solver: str = "cg"
    sensor_noise: float = 1e-4
    dynamics: str = "euler"
    n_repeats: int = 5
    sensitivity: bool = True
    learner_seed: int | None = None
    seed: int = 0

    QUICK = dict(n_test=50, max_iter=60, n_repeats=3)


def _mix(rng, n, k):
    A = np.zeros((n, k))
    for i in range(n):
        idx = rng.choice(k, size=int(rng.integers(2, 4)), replace=False)
        A[i, idx] = rng.uniform(0.5, 1.5, idx.size)
    return A


def streams(config: Config) -> list[dict[str, np.random.SeedSequence]]:
    """Independent random streams per repetition: ``data`` (dictionary, mixtures, start points),
    ``sensor`` (observation noise) and ``learner`` (initial dictionaries).

    The learner streams come from ``config.learner_seed`` when it is set, else from ``config.seed``
    (a child that never drew data), so that the seed that drew the data never reaches a learner.
    """
    reps = np.random.SeedSequence(config.seed).spawn(config.n_repeats)
    out = [dict(zip(("data", "sensor", "learner"), r.spawn(3))) for r in reps]
    if config.learner_seed is not None:
        for d, ls in zip(out, np.random.SeedSequence(config.learner_seed).spawn(config.n_repeats)):
            d["learner"] = ls
    return out


def _children(seq: np.random.SeedSequence, n: int) -> list[np.random.SeedSequence]:
    """The first ``n`` children of ``seq``, the same whatever was spawned from it before (``spawn`` is stateful)."""
    return [np.random.SeedSequence(seq.entropy, spawn_key=tuple(seq.spawn_key) + (i,), pool_size=seq.pool_size)
            for i in range(n)]


def make_data(config: Config, data_ss: np.random.SeedSequence, sensor_ss: np.random.SeedSequence,
              feats: RBFFeatures) -> dict[str, np.ndarray]:
    """The true dictionary, train/test mixtures, start points, demonstrations and their noisy observations."""
    rng = np.random.default_rng(data_ss)
    K = config.n_primitives
    d: dict[str, np.ndarray] = {"D": rng.standard_normal((K, feats.n_features))}
    d["A_tr"], d["A_te"] = _mix(rng, config.n_train, K), _mix(rng, config.n_test, K)
    d["s_tr"], d["s_te"], d["s_new"] = (rng.random((config.n_train, 2)), rng.random((config.n_test, 2)),
                                        rng.random((config.n_test, 2)))
    kw = _traj_kw(config)
    d["demo_tr"] = control_trajectories(feats, d["A_tr"] @ d["D"], d["s_tr"], **kw)
    d["demo_te"] = control_trajectories(feats, d["A_te"] @ d["D"], d["s_te"], **kw)
    d["demo_new"] = control_trajectories(feats, d["A_te"] @ d["D"], d["s_new"], **kw)  # new start points
    # what the learners observe: the sampled demonstrations through a noisy sensor
    noise = np.random.default_rng(sensor_ss)
    d["obs_tr"] = d["demo_tr"] + config.sensor_noise * noise.standard_normal(d["demo_tr"].shape)
    d["obs_te"] = d["demo_te"] + config.sensor_noise * noise.standard_normal(d["demo_te"].shape)
    return d


def _traj_kw(config: Config) -> dict:
    return dict(n_steps=config.n_steps, lam=config.lam, dt=config.dt, method=config.dynamics)


def _matched_error(learnt: np.ndarray, true: np.ndarray) -> float:
    """Relative error of ``learnt`` atoms against ``true`` ones after the best one-to-one matching and scaling.

    Each true atom is paired with one learnt atom (Hungarian assignment on the residual) and
    compared with its least-squares rescaling, so that order and scale (the ambiguities of
    section 4.2.3) do not count.
    """
    L = learnt / np.linalg.norm(learnt, axis=1, keepdims=True)
    proj = true @ L.T  # scale of learnt atom j that best fits true atom i
    cost = (true**2).sum(1)[:, None] - proj**2  # residual |t_i - c L_j|^2 at the best c
    rows, cols = linear_sum_assignment(cost)
    return float(np.sqrt(np.maximum(cost[rows, cols], 0.0).sum() / (true**2).sum()))


def mixing_error(learnt: np.ndarray, true: np.ndarray) -> float:
    """Dictionary error up to an invertible mixing of the atoms: 0 iff ``learnt = M @ true``, M invertible.

    The unsupervised model ``beta_i = a_i D`` is unchanged when D becomes ``M D`` and ``a_i``
    becomes ``a_i M^{-1}``, for any invertible M (order and scale are special cases), so only
    the span of the atoms can be compared. Returns the larger of the two relative residuals of
    least-squares fits: true atoms by combinations of learnt ones, and learnt atoms by
    combinations of true ones (the first alone would accept extra directions, the second alone
    a rank-deficient dictionary).
    """
    def residual(X, Y):  # |X - C Y| / |X| at the least-squares C
        C = np.linalg.lstsq(Y.T, X.T, rcond=None)[0].T
        return float(np.linalg.norm(X - C @ Y) / np.linalg.norm(X))

    learnt, true = np.asarray(learnt, dtype=float), np.asarray(true, dtype=float)
    return max(residual(true, learnt), residual(learnt, true))


def _learner_kw(config: Config, feats: RBFFeatures, rng: np.random.Generator) -> dict:
    return dict(features=feats, lam=config.lam, dt=config.dt, d_solver=config.d_solver,
                random_state=int(rng.integers(2**63)))


def _supervised(config: Config, feats, data, learner_ss, *, noise_free=False) -> dict:
    """Fit the supervised learner; return its metrics (and the fitted model under ``'model'``)."""
    kw = _traj_kw(config)
    obs_tr = data["demo_tr"] if noise_free else data["obs_tr"]
    lkw = _learner_kw(config, feats, np.random.default_rng(learner_ss))
    sup = FactorialInverseControl(config.n_primitives, max_iter=config.supervised_max_iter,
                                  **lkw).fit(list(obs_tr), data["A_tr"])
    C, D = sup.components_, data["D"]
    m = {"train.rel_l2": relative_l2_error(data["demo_tr"], control_trajectories(feats, data["A_tr"] @ C,
                                                                                   data["s_tr"], **kw)),
         "test.rel_l2": relative_l2_error(data["demo_te"], control_trajectories(feats, data["A_te"] @ C,
                                                                                 data["s_te"], **kw)),
         "dictionary_rel_error": float(np.linalg.norm(C - D) / np.linalg.norm(D))}
    if not noise_free:
        inferred = sup.transform(list(data["obs_te"])) @ C
        m["inferred.test.rel_l2"] = relative_l2_error(data["demo_te"], control_trajectories(
            feats, inferred, data["s_te"], **kw))
        m["new_start.rel_l2"] = relative_l2_error(data["demo_new"], control_trajectories(
            feats, inferred, data["s_new"], **kw))
        m["given.new_start.rel_l2"] = relative_l2_error(data["demo_new"], control_trajectories(
            feats, data["A_te"] @ C, data["s_new"], **kw))
        m["initial_dictionary_rel_error"] = float(np.linalg.norm(sup.init_components_ - D) / np.linalg.norm(D))
        m["n_iter"] = float(sup.n_iter_)
    m["model"] = sup
    return m


def _repeat(job) -> dict:
    """One repetition: data from its own streams, the three learners, their errors."""
    config, ss = job
    feats = RBFFeatures(config.grid_size)
    kw = _traj_kw(config)
    data = make_data(config, ss["data"], ss["sensor"], feats)
    sup_ss, uns_ss, clean_ss = _children(ss["learner"], 3)
    sup = _supervised(config, feats, data, sup_ss)
    sup_clean = _supervised(config, feats, data, clean_ss, noise_free=True)  # diagnostic: no sensor noise
    uns = FactorialInverseControl(config.n_primitives, max_iter=config.max_iter,
                                  **_learner_kw(config, feats, np.random.default_rng(uns_ss))).fit(list(data["obs_tr"]))

    def flat_b(demos):
        return np.array([brillinger_regression(feats, d, lam=config.lam, dt=config.dt) for d in demos])

    per_task: dict[str, np.ndarray] = {}
    for name, b_tr, b_te in (("flat", flat_b(data["obs_tr"]), flat_b(data["obs_te"])),
                             ("unsupervised", uns.coefficients_ @ uns.components_,
                              uns.transform(list(data["obs_te"])) @ uns.components_)):
        per_task[f"{name}.train.rel_l2"] = relative_l2_error(data["demo_tr"], control_trajectories(
            feats, b_tr, data["s_tr"], **kw))
        im_te = control_trajectories(feats, b_te, data["s_te"], **kw)
        im_new = control_trajectories(feats, b_te, data["s_new"], **kw)
        per_task[f"{name}.test.rel_l2"] = relative_l2_error(data["demo_te"], im_te)
        per_task[f"{name}.new_start.rel_l2"] = relative_l2_error(data["demo_new"], im_new)
        if name == "unsupervised":
            uns_im = (im_te, im_new)
        else:
            flat_im = (im_te, im_new)
    for key in ("train.rel_l2", "test.rel_l2", "new_start.rel_l2", "inferred.test.rel_l2", "given.new_start.rel_l2"):
        per_task[f"supervised.{key}"] = sup[key]
    metrics = {k: float(np.mean(v)) for k, v in per_task.items()}
    for name in LEARNERS:
        metrics[f"{name}.new_start.median_rel_l2"] = float(np.median(per_task[f"{name}.new_start.rel_l2"]))
    metrics["supervised.dictionary_rel_error"] = sup["dictionary_rel_error"]
    metrics["supervised.initial_dictionary_rel_error"] = sup["initial_dictionary_rel_error"]
    metrics["supervised.n_iter"] = sup["n_iter"]
    metrics["unsupervised.dictionary_matched_rel_error"] = _matched_error(uns.components_, data["D"])
    metrics["unsupervised.dictionary_mixing_rel_error"] = mixing_error(uns.components_, data["D"])
    metrics["unsupervised.initial_dictionary_mixing_rel_error"] = mixing_error(uns.init_components_, data["D"])
    metrics["unsupervised.n_iter"] = float(uns.n_iter_)
    for key in ("train.rel_l2", "test.rel_l2"):
        metrics[f"supervised_noise_free.{key}"] = float(np.mean(sup_clean[key]))
    metrics["supervised_noise_free.dictionary_rel_error"] = sup_clean["dictionary_rel_error"]
    figure = {"D": data["D"], "sup": sup["model"].components_, "uns": uns.components_, "A_te": data["A_te"][:1],
              "demo_te": data["demo_te"][:1], "demo_new": data["demo_new"][:1], "s_te": data["s_te"][:1],
              "s_new": data["s_new"][:1], "flat": [x[:1] for x in flat_im], "unsupervised": [x[:1] for x in uns_im],
              "supervised": [control_trajectories(feats, sup["model"].transform(list(data["obs_te"][:1]))
                                                  @ sup["model"].components_, s, **kw) for s in
                             (data["s_te"][:1], data["s_new"][:1])]}
    return {"metrics": metrics, "figure": figure}


def _sensitivity_cell(job) -> dict[str, float]:
    """The supervised learner's errors on one repetition's tasks with another dynamics / noise / solver."""
    config, ss, (label, dynamics, noise, solver) = job
    cfg = dataclasses.replace(config, dynamics=dynamics, sensor_noise=noise, d_solver=solver,
                              supervised_max_iter=200 if solver == "steepest" else config.supervised_max_iter)
    feats = RBFFeatures(cfg.grid_size)
    data = make_data(cfg, ss["data"], ss["sensor"], feats)
    sup = _supervised(cfg, feats, data, _children(ss["learner"], 3)[0])
    return {f"sensitivity.{label}.supervised.{k}": float(np.mean(v)) for k, v in sup.items()
            if f"supervised.{k}" in SENSITIVITY_METRICS}


def compute(config: Config, ctx: RunContext) -> Result:
    """The errors of every repetition and sensitivity cell (no figures; ``figure_data["trajectories"]``: the first
    repetition's dictionaries and a test task's trajectories, for :func:`present`)."""
    if config.dynamics not in ("euler", "ode"):
        raise ValueError(f"dynamics must be 'euler' or 'ode'; got {config.dynamics!r}")
    if config.d_solver not in ("cg", "steepest"):
        raise ValueError(f"d_solver must be 'cg' or 'steepest'; got {config.d_solver!r}")
    if config.n_repeats < 1:
        raise ValueError(f"n_repeats must be at least 1; got {config.n_repeats!r}")
    feats = RBFFeatures(config.grid_size)
    ss = streams(config)
    jobs: list[tuple[str, tuple]] = [("repeat", (config, s)) for s in ss]
    if config.sensitivity:
        jobs += [("cell", (config, s, cell)) for s in ss for cell in SENSITIVITY]
    outs = ctx.parallel(_job, jobs, desc="fits")
    reps = [o["metrics"] for (kind, _), o in zip(jobs, outs) if kind == "repeat"]
    cells = [o for (kind, _), o in zip(jobs, outs) if kind == "cell"]
    samples = {name: [r[name] for r in reps] for name in reps[0]}
    for cell in cells:
        for name, value in cell.items():
            samples.setdefault(name, []).append(value)
    metrics = {name: float(np.mean(v)) for name, v in samples.items()}

    rows = []
    for name in LEARNERS:
        rows.append([name] + [metrics[f"{name}.{split}.rel_l2"] for split in ("train", "test", "new_start")]
                    + [metrics[f"{name}.new_start.median_rel_l2"]])
    tables = {"errors": Table(
        f"Relative L2 error between demonstrator and imitator trajectories (mean over tasks, then over "
        f"{config.n_repeats} repetitions)",
        ["learner", "train tasks", "test tasks (demo start)", "test tasks (new start)", "new start (median)"], rows,
        note="supervised: train and test use the given mixing coefficients (the thesis' protocol for 0.001127 / "
             "0.002675); its new-start error uses coefficients inferred from the demonstration (eq. 4.6). "
             "Per-repetition values are kept as the metrics' samples.")}
    if config.sensitivity:
        tables["sensitivity"] = Table(
            f"Sensitivity of the supervised learner's errors to our choices (mean over the {config.n_repeats} "
            "repetitions' tasks; default: Euler dynamics, sensor noise 1e-4, conjugate gradient on D)",
            ["dynamics", "sensor noise", "D solver"] + list(SENSITIVITY_METRICS),
            [[dyn, noise, "steepest descent, 200 steps" if solver == "steepest" else "conjugate gradient"]
             + [metrics[f"sensitivity.{label}.{m}"] for m in SENSITIVITY_METRICS]
             for label, dyn, noise, solver in SENSITIVITY],
            note="Metric names: sensitivity.<dynamics>.noise_<level>[.steepest_200].<metric>, noise_1e_4 = 1e-4. "
                 "'ode': demonstrator and imitators integrate the continuous-time eq. (4.1); the learner still "
                 "regresses on its discrete form. The thesis states neither a sensor noise nor a step count for "
                 "its gradient descent on D.")

    thesis_order = "below 10 x the thesis' numbers"
    notes = [
        f"RBF width sigma = {feats.sigma:g} (grid spacing), lambda = {config.lam}, dt = {config.dt}, "
        f"{config.n_steps} steps per trajectory; trajectories are not clipped to [0, 1]^2. {config.n_repeats} "
        "independent repetitions (new primitives, tasks, start points, sensor noise and learner initialisation); "
        "every metric is the mean over repetitions and keeps its per-repetition values (samples; the report's "
        "95 % interval and the claims' verdicts come from them), the sensitivity table's cells too.",
        "Random streams: per repetition, numpy SeedSequence(seed) children draw the data (dictionary, mixtures, "
        "start points), the sensor noise and the learners' initial dictionaries independently. Until this "
        "version the true dictionary and the learners' initial dictionary were the same draw (the learners "
        "started at the answer: supervised errors of 3e-5 that said nothing about learning); "
        f"supervised.initial_dictionary_rel_error = {metrics['supervised.initial_dictionary_rel_error']:.3g} "
        "shows where the learner starts now.",
        ("Every trajectory (demonstrator and imitators) follows the discrete form of eq. (4.1) of section "
         "4.2.1" if config.dynamics == "euler" else
         "Every trajectory (demonstrator and imitators) is the continuous-time agent of eq. (4.1) integrated "
         "with LSODA (rtol 1e-8) and sampled every dt") +
        "; the learners regress on the discrete form of section 4.2.1 "
        f"from demonstrations observed with Gaussian sensor noise of std "
        f"{config.sensor_noise:g} (fraction of the workspace side; see the module docstring). Reading taken: "
        "section 4.2.2 generates trajectories 'according to eq. (4.1)', which is the continuous law; section "
        "4.2.1 gives its discrete form for sampled trajectories. The sensitivity table shows both.",
        f"The supervised learner minimises eq. (4.5) in D by {'conjugate gradient' if config.d_solver == 'cg' else 'steepest descent'} "
        f"(at most {config.supervised_max_iter} steps; {metrics['supervised.n_iter']:.0f} on average here). The "
        "thesis minimises (4.5) by 'a gradient descent approach' without a step count, and its errors are those of "
        "a converged fit. With a random start, steepest descent with exact line search crawls along the "
        "ill-conditioned directions (one demonstration excites few features): after 200 steps its errors are "
        "about 0.1-0.3 (sensitivity row steepest_200), where conjugate gradient reaches the minimiser of the same "
        "objective in a few hundred steps.",
        "supervised_noise_free.* is a diagnostic beyond the thesis: the supervised learner on the same "
        "demonstrations without sensor noise. supervised.given.new_start uses the true mixing coefficients from "
        "new start points; supervised.new_start infers them from the test demonstration (eq. 4.6), as the "
        "unsupervised learner must. *.median_rel_l2 shows how much of a mean is due to a few imitations that end "
        "in another basin of the cost.",
        "The flat imitator's least-squares fit (eq. 4.3, minimum-norm) of 25 weights on one demonstration is "
        "ill-conditioned: the demonstration excites few directions, and the noise residuals put huge weights on "
        "the others, so its trajectories leave the demonstrated region (relative errors of 1e4 and more). The "
        "claims that the dictionary learners beat it were dropped: a diverging baseline is beaten by anything and "
        "is no evidence. Its errors stay in the table as a diagnostic.",
        "The unsupervised model is invariant to any invertible mixing of the atoms (D -> M D, a -> a M^-1), so "
        "'its dictionary differs from the true one' (the former claim, on the order-and-scale matched error) holds "
        "whatever the learner does. The dictionary is now judged up to an invertible mixing: "
        "unsupervised.dictionary_mixing_rel_error (0 iff the learnt atoms span the true ones; "
        f"{metrics['unsupervised.initial_dictionary_mixing_rel_error']:.3g} for its random initial dictionary). "
        "unsupervised.dictionary_matched_rel_error is kept as a diagnostic.",
        "The unsupervised learner starts from random Gaussian atoms and alternates least squares on the "
        f"coefficients (eq. 4.6) with 5 {'conjugate-gradient' if config.d_solver == 'cg' else 'exact-line-search gradient'} "
        f"steps on D (eq. 4.7), at most {config.max_iter} alternations.",
        "The thesis gives numbers only for the supervised learner (train 0.001127, test 0.002675; claims check "
        f"the magnitude: {thesis_order}); flat and unsupervised errors have no thesis reference, and the thesis "
        "states that its evaluation did not validate the unsupervised learner quantitatively (section 4.2.3).",
    ]
    if config.sensitivity:
        def sv(label, m):
            return metrics[f"sensitivity.{label}.supervised.{m}"]

        notes.append(
            "What the sensitivity table says: the verdicts of the supervised claims depend on the dynamics. With "
            "the discrete dynamics the learner's regression is exact and its errors scale with the sensor noise "
            f"(train error {sv('euler.noise_0', 'train.rel_l2'):.2g} / {sv('euler.noise_1e_4', 'train.rel_l2'):.2g}"
            f" / {sv('euler.noise_1e_3', 'train.rel_l2'):.2g} for noise 0 / 1e-4 / 1e-3, against the thesis' "
            "0.001127). With the continuous dynamics the discrete regression's bias dominates whatever the noise "
            f"(train {sv('ode.noise_1e_4', 'train.rel_l2'):.2g}, test {sv('ode.noise_1e_4', 'test.rel_l2'):.2g}, "
            f"dictionary error {sv('ode.noise_1e_4', 'dictionary_rel_error'):.2g}): claims 1 and 2 would fail. "
            "Steepest descent stopped at 200 steps leaves errors of "
            f"{sv('euler.noise_1e_4.steepest_200', 'train.rel_l2'):.2g} (the issue's 'about 0.22' is the same "
            "learner at 60 steps). Euler and the noise level were fixed before these numbers were seen (an earlier "
            "issue and section 4.2.1; the encoder argument of the module docstring); conjugate gradient replaced "
            "steepest descent after we saw that the latter had not converged: both minimise eq. (4.5), and a "
            "converged fit is what the thesis' numbers describe.")
    return Result(metrics=metrics, tables=tables, notes=notes, samples=samples,
                  figure_data={"trajectories": outs[0]["figure"]})


def _job(job):
    kind, payload = job
    return _repeat(payload) if kind == "repeat" else _sensitivity_cell(payload)


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Fig. 4.1 (primitive costs: true, supervised, unsupervised) and Fig. 4.2-4.3 (a test task imitated)."""
    return _figures(RBFFeatures(config.grid_size), config.n_primitives, result.figure_data["trajectories"])


def _figures(feats: RBFFeatures, K: int, fd: dict) -> dict[str, Figure]:
    from matplotlib.lines import Line2D

    grid = np.linspace(0, 1, 60)
    Qg = np.stack(np.meshgrid(grid, grid), -1)
    fig1 = Figure(figsize=(2 * K + 1.4, 6.4), layout="constrained")
    axes = fig1.subplots(3, K, squeeze=False)
    for r, (lab, Dm) in enumerate((("true", fd["D"]), ("supervised", fd["sup"]), ("unsupervised", fd["uns"]))):
        costs = [feats.cost(Dm[j], Qg) for j in range(K)]
        lo, hi = float(np.min(costs)), float(np.max(costs))
        for j in range(K):
            img = axes[r, j].imshow(costs[j], origin="lower", extent=(0, 1, 0, 1), cmap="gray_r", vmin=lo, vmax=hi)
            axes[r, j].set_xticks([]); axes[r, j].set_yticks([])
            axes[r, j].set_title(f"{lab} {j + 1}", fontsize=7)
        axes[r, 0].set_ylabel("position y")
        fig1.colorbar(img, ax=list(axes[r, :]), shrink=0.9, pad=0.01).set_label("cost", fontsize=8)
    for ax in axes[-1, :]:
        ax.set_xlabel("position x")
    fig1.suptitle("Fig 4.1: primitive costs: true, supervised learner, unsupervised learner (dark = high cost; "
                  "the unsupervised atoms are known up to a mixing)")

    fig3 = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig3.subplots(2, 4, squeeze=False)
    for c, (lab, src) in enumerate((("demonstrator", None), ("flat", "flat"), ("supervised (inferred)", "supervised"),
                                    ("unsupervised", "unsupervised"))):
        for r, (demo, start) in enumerate(((fd["demo_te"], fd["s_te"]), (fd["demo_new"], fd["s_new"]))):
            ax = axes[r, c]
            img = ax.imshow(feats.cost(fd["A_te"][0] @ fd["D"], Qg), origin="lower", extent=(0, 1, 0, 1),
                            cmap="gray_r")
            ax.plot(*demo[0].T, "b.-", ms=2, lw=0.8, label="demonstrator")
            if src is not None:
                ax.plot(*fd[src][r][0].T, "r.-", ms=2, lw=0.8, label="imitator")
            ax.plot(*start[0], "y*", ms=10)
            ax.set_xlim(0, 1); ax.set_ylim(0, 1); ax.set_xticks([]); ax.set_yticks([])
            ax.set_title(f"{lab}, {'demo start' if r == 0 else 'new start'}", fontsize=7)
            if c == 0:
                ax.set_ylabel("position y")
            if r == 1:
                ax.set_xlabel("position x")
    fig3.colorbar(img, ax=axes, shrink=0.7, pad=0.01).set_label("cost of the test task (dark = high)", fontsize=8)
    fig3.legend(handles=[Line2D([], [], color="b", marker=".", ms=4, lw=0.8, label="demonstrator's trajectory"),
                         Line2D([], [], color="r", marker=".", ms=4, lw=0.8, label="imitator's trajectory"),
                         Line2D([], [], color="y", marker="*", ms=10, ls="", mec="0.3", label="start")],
                loc="outside lower center", ncol=3, fontsize=8)
    fig3.suptitle("Fig 4.2-4.3: a test task imitated from one demonstration")
    return {"fig4_1_dictionaries": fig1, "fig4_3_trajectories": fig3}


EXPERIMENT = register(
    Experiment(
        id="ch4-inverse-control",
        title="Factorial inverse feedback control: a dictionary of primitive costs",
        thesis_ref="Section 4.2 (eq. 4.1-4.7, Fig 4.1-4.3)",
        config_cls=Config,
        compute=compute,
        present=present,
        reference={"supervised.train.rel_l2": 0.001127, "supervised.test.rel_l2": 0.002675},
        claims=[
            Claim("The supervised learner (dictionary from coefficients) reproduces demonstrated trajectories "
                  "accurately, on train and on new tasks: 0.001127 and 0.002675 in the thesis; checked as the same "
                  "order of magnitude or better (below 10 x the thesis' numbers).",
                  "supervised.train.rel_l2 < 0.01127 and supervised.test.rel_l2 < 0.02675"),
            Claim("The supervised learner achieves an accurate reconstruction of the original dictionary of "
                  "primitive tasks (Fig 4.1; checked as a relative error below 10%; with given coefficients the "
                  "dictionary is identifiable, not only up to a mixing).",
                  "supervised.dictionary_rel_error < 0.1"),
            Claim("The supervised dictionary lets the imitator solve a new task inferred from a single "
                  "demonstration (eq. 4.6) from new random start points (section 4.2.3); the thesis gives no number "
                  "for this protocol: checked as the accuracy of its test tasks (mean error below 10 x 0.002675).",
                  "supervised.new_start.rel_l2 < 0.02675"),
            Claim("The unsupervised factorial representation enables imitation of a new task from a single "
                  "demonstration, from new start points (same check as for the supervised learner). The thesis "
                  "states this but says its own evaluation did not validate it quantitatively (section 4.2.3).",
                  "unsupervised.new_start.rel_l2 < 0.02675"),
            Claim("The unsupervised learner acquires its own representation of the same primitive tasks (Fig 4.1, "
                  "section 4.2.3): its atoms differ from the demonstrator's by an invertible mixing, the ambiguity "
                  "of the model; checked as a dictionary error up to an invertible mixing below 10%.",
                  "unsupervised.dictionary_mixing_rel_error < 0.1"),
        ],
        description=__doc__.split("\n\n")[0],
    )
)

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
