"""ch4-inverse-control: a dictionary of primitive cost functions from mixed demonstrations (Fig 4.1-4.3).

Thesis section 4.2.2. An agent in [0, 1]^2 descends costs on a 5 x 5 grid of Gaussian
radial basis functions (F = 25) by eq. (4.1). Six primitive costs (i.i.d. standard normal
weights on the features: the thesis does not say how its primitives were drawn) are mixed
2 or 3 at a time (weights uniform in [0.5, 1.5]); 200 training demonstrations, each from
a random start point. Learners: the flat imitator (Brillinger's regression, eq. 4.3, one
demonstration), the dictionary learnt from demonstrations and given coefficients
(supervised), and the fully unsupervised dictionary learner (eq. 4.5-4.7). Score: the
relative L2 error between demonstrator and imitator trajectories.

Settings. Two choices the thesis leaves open decide some verdicts, so every claim is
evaluated under each combination (:data:`SETTINGS`; ``Claim(settings=...)``):

* the dynamics of demonstrator and imitators ("identical bodies"): ``'euler'``, the
  discrete form of eq. (4.1) given in section 4.2.1, ``q_{t+1} = q_t - lambda dt
  J(q_t)^T beta``, which the learners' regression inverts exactly; or ``'ode'``, the
  continuous-time eq. (4.1) integrated with an adaptive solver (LSODA, rtol 1e-8, atol
  1e-10) and sampled every ``dt``, while the learners still regress on the discrete form
  (section 4.2.2 generates trajectories "according to eq. (4.1)", the continuous law);
* the sensor noise through which the learners observe the demonstrations: ``1e-4`` or
  ``1e-3`` of the workspace side, i.i.d. Gaussian on each observed coordinate. The thesis
  gives none. Its agent models kinesthetic demonstrations read on the imitator's own body
  (section 4.2.1), i.e. from joint encoders; a 12-bit encoder resolves 1/4096 of its
  range, a quantisation noise of standard deviation ``1 / (4096 sqrt(12)) ~ 7e-5`` of the
  range, hence 1e-4, and 1e-3 for a coarser sensor. Finite differences amplify it by
  ``1 / dt``: with ``dt = 0.01`` the velocity noise is 0.014 (1e-4) against speeds of order 1.

The demonstrations of one repetition are the same under both noise levels (only the
observation noise is scaled: one standard normal draw, times 1e-4 or 1e-3), and its
dictionary, tasks and start points the same under both dynamics, so the settings are
compared on the same draws. The imitators' trajectories are compared with the noise-free
demonstrator's.

Random streams. Each repetition has its own streams (:func:`run_streams`): the data stream draws
the true dictionary, mixtures and start points, and apart the sensor noise; the learner stream the
learners' initial dictionaries. The seed that drew the data never reaches a learner.

Learners. The supervised learner minimises eq. (4.5) in D by conjugate gradient
(``d_solver='cg'``, run to convergence); the thesis says "gradient descent" without a step
count, and steepest descent from a random start needs thousands of steps on this
ill-conditioned quadratic (the diagnostics table shows it at 200 steps). The unsupervised
model is invariant to any invertible mixing of the atoms, so its dictionary is scored up to
one (:func:`mixing_error`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment

from ...errors import DataError, ParameterError
from ...tasks import (
    FactorialInverseControl,
    RBFFeatures,
    brillinger_regression,
    control_trajectories,
    relative_l2_error,
)
from ...engine import (Claim, Experiment, PresetConfig, Result, RunContext, SampleUnit, Streams, Table, describe_split,
                      register, streams)

__all__ = ["Config", "compute", "present", "run", "run_streams", "make_data", "observe", "mixing_error", "setting_label",
           "SETTINGS", "THESIS"]

LEARNERS = ("flat", "supervised", "unsupervised")
DYNAMICS = ("euler", "ode")
SENSOR_NOISES = (1e-4, 1e-3)
#: Thesis section 4.2.2 (lines 3378-3380): the supervised learner's mean relative L2 trajectory error on the
#: training tasks and on new tasks of the same dictionary (coefficients given). The only numbers of section 4.2.
THESIS = {"supervised.train.rel_l2": 0.001127, "supervised.test.rel_l2": 0.002675}
_THESIS_LINES = {"supervised.train.rel_l2": "line 3379", "supervised.test.rel_l2": "line 3380"}
_THESIS_WHAT = {"supervised.train.rel_l2": "on the training tasks", "supervised.test.rel_l2": "on new tasks"}


def _short(noise: float) -> str:
    """``1e-4`` for 0.0001, ``0`` for 0."""
    if noise == 0:
        return "0"
    mantissa, exponent = f"{noise:e}".split("e")
    return f"{float(mantissa):g}e{int(exponent)}"


def setting_label(dynamics: str, noise: float) -> str:
    """The metric prefix of a setting: ``setting_label('euler', 1e-4) == 'euler.noise_1e_4'``."""
    return f"{dynamics}.noise_{_short(noise).replace('-', '_').replace('.', '_')}"


def _setting_title(dynamics: str, noise: float) -> str:
    return f"{'Euler' if dynamics == 'euler' else 'ODE'}, noise {_short(noise)}"


#: The settings every claim is evaluated under: (metric prefix, label shown, dynamics, sensor noise).
SETTINGS = tuple((setting_label(d, n), _setting_title(d, n), d, n) for d in DYNAMICS for n in SENSOR_NOISES)


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes of the factorial inverse control experiment (defaults: the thesis' settings).

    ``dynamics`` and ``sensor_noises`` are the settings computed (every combination; see the
    module docstring): the sensor noise is the standard deviation of the Gaussian noise on
    observed positions, as a fraction of the workspace side. ``max_iter`` counts the
    unsupervised learner's alternations, ``supervised_max_iter`` the supervised learner's
    gradient steps on D (``d_solver``: 'cg' conjugate gradient, 'steepest' steepest descent;
    see :class:`~mmconcepts.tasks.FactorialInverseControl`). ``n_repeats`` independent
    repetitions (new dictionary, tasks, start points, noise and learner initialisation each);
    metrics are means over them, per-repetition values their samples. ``learner_seed``
    (default: spawned from ``seed``) changes the learners' initialisation alone;
    ``diagnostics`` adds the supervised learner without sensor noise and with 200 steps of
    steepest descent.
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
    dynamics: tuple[str, ...] = DYNAMICS
    sensor_noises: tuple[float, ...] = SENSOR_NOISES
    n_repeats: int = 5
    diagnostics: bool = True
    learner_seed: int | None = None
    seed: int = 0

    QUICK = dict(n_test=25, max_iter=40, diagnostics=False)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one
    SMOKE = dict(n_train=30, n_test=6, n_steps=30, max_iter=3, n_repeats=1)


def _mix(rng, n, k):
    A = np.zeros((n, k))
    for i in range(n):
        idx = rng.choice(k, size=int(rng.integers(2, 4)), replace=False)
        A[i, idx] = rng.uniform(0.5, 1.5, idx.size)
    return A


#: The data stream's two draws per repetition: the tasks (dictionary, mixtures, start points), the sensor noise.
TASKS, SENSOR = 0, 1
#: The learner stream's two draws per repetition: the supervised and the unsupervised learner's initialisation.
SUPERVISED, UNSUPERVISED = 0, 1


def run_streams(config: Config) -> list[Streams]:
    """The random streams of each repetition (:meth:`~mmconcepts.engine.Streams.sub`): ``data``
    draws the tasks (key :data:`TASKS`: dictionary, mixtures, start points) and the sensor noise
    (key :data:`SENSOR`); ``learner`` the initial dictionaries (keys :data:`SUPERVISED`,
    :data:`UNSUPERVISED`).

    The learner stream is drawn from ``config.learner_seed`` when it is set, else from
    ``config.seed``; it never draws data.
    """
    st = streams(config.seed, learner_seed=config.learner_seed)
    return [st.sub(rep) for rep in range(config.n_repeats)]


def make_data(config: Config, data_ss: np.random.SeedSequence, sensor_ss: np.random.SeedSequence,
              feats: RBFFeatures, dynamics: str = "euler") -> dict[str, np.ndarray]:
    """The true dictionary, train/test mixtures, start points, demonstrations under ``dynamics``, and the
    sensor's standard normal draws (``z_tr``, ``z_te``; see :func:`observe`).

    The dictionary, mixtures and start points depend on ``data_ss`` alone, not on ``dynamics``.
    """
    rng = np.random.default_rng(data_ss)
    K = config.n_primitives
    d: dict[str, np.ndarray] = {"D": rng.standard_normal((K, feats.n_features))}
    d["A_tr"], d["A_te"] = _mix(rng, config.n_train, K), _mix(rng, config.n_test, K)
    d["s_tr"], d["s_te"], d["s_new"] = (rng.random((config.n_train, 2)), rng.random((config.n_test, 2)),
                                        rng.random((config.n_test, 2)))
    kw = _traj_kw(config, dynamics)
    d["demo_tr"] = control_trajectories(feats, d["A_tr"] @ d["D"], d["s_tr"], **kw)
    d["demo_te"] = control_trajectories(feats, d["A_te"] @ d["D"], d["s_te"], **kw)
    d["demo_new"] = control_trajectories(feats, d["A_te"] @ d["D"], d["s_new"], **kw)  # new start points
    noise = np.random.default_rng(sensor_ss)
    d["z_tr"] = noise.standard_normal(d["demo_tr"].shape)
    d["z_te"] = noise.standard_normal(d["demo_te"].shape)
    return d


def observe(data: dict[str, np.ndarray], sensor_noise: float) -> tuple[np.ndarray, np.ndarray]:
    """What the learners observe: the training and test demonstrations through a sensor of noise ``sensor_noise``."""
    return data["demo_tr"] + sensor_noise * data["z_tr"], data["demo_te"] + sensor_noise * data["z_te"]


def _traj_kw(config: Config, dynamics: str) -> dict:
    return dict(n_steps=config.n_steps, lam=config.lam, dt=config.dt, method=dynamics)


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


def _learner_kw(config: Config, feats: RBFFeatures, rng: np.random.Generator, d_solver: str) -> dict:
    return dict(features=feats, lam=config.lam, dt=config.dt, d_solver=d_solver, random_state=int(rng.integers(2**63)))


def _errors(feats, reference, beta, start, kw) -> np.ndarray:
    """Per-task relative L2 errors of the imitators of costs ``beta`` against ``reference``; NaN when the
    continuous dynamics cannot be integrated (a cost so large that they are too stiff)."""
    try:
        return relative_l2_error(reference, control_trajectories(feats, beta, start, **kw))
    except DataError:
        return np.full(len(reference), np.nan)


def _supervised(config: Config, feats, data, obs_tr, obs_te, learner_ss, kw, *, d_solver: str | None = None,
                max_iter: int | None = None, full: bool = True) -> dict:
    """Fit the supervised learner on ``obs_tr`` with the given coefficients; return its per-task errors and its
    dictionary error (and, with ``full``, the imitation of test tasks inferred from ``obs_te``)."""
    sup = FactorialInverseControl(config.n_primitives, max_iter=max_iter or config.supervised_max_iter,
                                  **_learner_kw(config, feats, np.random.default_rng(learner_ss),
                                                d_solver or config.d_solver)).fit(list(obs_tr), data["A_tr"])
    C, D = sup.components_, data["D"]
    m = {"train.rel_l2": _errors(feats, data["demo_tr"], data["A_tr"] @ C, data["s_tr"], kw),
         "test.rel_l2": _errors(feats, data["demo_te"], data["A_te"] @ C, data["s_te"], kw),
         "dictionary_rel_error": float(np.linalg.norm(C - D) / np.linalg.norm(D))}
    if full:
        inferred = sup.transform(list(obs_te)) @ C
        m["inferred.test.rel_l2"] = _errors(feats, data["demo_te"], inferred, data["s_te"], kw)
        m["new_start.rel_l2"] = _errors(feats, data["demo_new"], inferred, data["s_new"], kw)
        m["given.new_start.rel_l2"] = _errors(feats, data["demo_new"], data["A_te"] @ C, data["s_new"], kw)
        m["initial_dictionary_rel_error"] = float(np.linalg.norm(sup.init_components_ - D) / np.linalg.norm(D))
        m["n_iter"] = float(sup.n_iter_)
    return {"metrics": m, "model": sup}


def _unsupervised(config: Config, feats, data, obs_tr, obs_te, learner_ss, kw) -> dict:
    """Fit the unsupervised learner on ``obs_tr``; return its per-task errors (training tasks: the first ``n_test``)
    and its dictionary errors."""
    uns = FactorialInverseControl(config.n_primitives, max_iter=config.max_iter,
                                  **_learner_kw(config, feats, np.random.default_rng(learner_ss),
                                                config.d_solver)).fit(list(obs_tr))
    b_te = uns.transform(list(obs_te)) @ uns.components_
    n = config.n_test  # its training-task errors, a diagnostic, on the first n_test training tasks
    m = {"train.rel_l2": _errors(feats, data["demo_tr"][:n], (uns.coefficients_ @ uns.components_)[:n],
                                 data["s_tr"][:n], kw),
         "test.rel_l2": _errors(feats, data["demo_te"], b_te, data["s_te"], kw),
         "new_start.rel_l2": _errors(feats, data["demo_new"], b_te, data["s_new"], kw),
         "dictionary_mixing_rel_error": mixing_error(uns.components_, data["D"]),
         "dictionary_matched_rel_error": _matched_error(uns.components_, data["D"]),
         "initial_dictionary_mixing_rel_error": mixing_error(uns.init_components_, data["D"]),
         "n_iter": float(uns.n_iter_)}
    return {"metrics": m, "model": uns, "b_te": b_te}


def _flat(config: Config, feats, data, obs_tr, obs_te, kw) -> dict:
    """The flat imitator's per-task errors (Brillinger's regression on each demonstration; training tasks: the first
    ``n_test``)."""
    def fit(demos):
        return np.array([brillinger_regression(feats, d, lam=config.lam, dt=config.dt) for d in demos])

    b_te = fit(obs_te)
    n = config.n_test  # its training-task errors on the first n_test training tasks
    return {"metrics": {"train.rel_l2": _errors(feats, data["demo_tr"][:n], fit(obs_tr[:n]), data["s_tr"][:n], kw),
                        "test.rel_l2": _errors(feats, data["demo_te"], b_te, data["s_te"], kw),
                        "new_start.rel_l2": _errors(feats, data["demo_new"], b_te, data["s_new"], kw)},
            "b_te": b_te}


def _summary(prefix: str, values: dict) -> dict[str, float]:
    """Per-task arrays to their mean over tasks (``new_start`` errors also to their median); scalars as they are."""
    out = {}
    for key, v in values.items():
        if np.ndim(v) == 0:
            out[f"{prefix}.{key}"] = float(v)
            continue
        v = np.asarray(v, dtype=float)
        out[f"{prefix}.{key}"] = float(np.mean(v))
        if key == "new_start.rel_l2":
            out[f"{prefix}.new_start.median_rel_l2"] = float(np.median(v))
    return out


def _dynamics_job(job) -> dict:
    """One repetition under one dynamics: its data, then every sensor noise's learners and errors."""
    config, st, dynamics, with_figure = job
    feats = RBFFeatures(config.grid_size)
    kw = _traj_kw(config, dynamics)
    data = make_data(config, st.sequence("data", TASKS), st.sequence("data", SENSOR), feats, dynamics)
    sup_ss, uns_ss = st.sequence("learner", SUPERVISED), st.sequence("learner", UNSUPERVISED)
    metrics: dict[str, float] = {}
    figure = None
    # the control: an imitator that knows the average training task exactly but ignores the demonstration
    mean_task = np.broadcast_to(data["A_tr"].mean(axis=0) @ data["D"], (config.n_test, data["D"].shape[1]))
    control = _summary("mean_task", {"new_start.rel_l2": _errors(feats, data["demo_new"], mean_task, data["s_new"],
                                                                   kw)})
    for noise in config.sensor_noises:
        label = setting_label(dynamics, noise)
        obs_tr, obs_te = observe(data, noise)
        sup = _supervised(config, feats, data, obs_tr, obs_te, sup_ss, kw)
        uns = _unsupervised(config, feats, data, obs_tr, obs_te, uns_ss, kw)
        # the learners' starting points are the same under every setting (same draws): kept once, unprefixed
        metrics["supervised.initial_dictionary_rel_error"] = sup["metrics"].pop("initial_dictionary_rel_error")
        metrics["unsupervised.initial_dictionary_mixing_rel_error"] = uns["metrics"].pop(
            "initial_dictionary_mixing_rel_error")
        metrics.update({f"{label}.{k}": v for k, v in control.items()})
        metrics.update(_summary(f"{label}.supervised", sup["metrics"]))
        metrics.update(_summary(f"{label}.unsupervised", uns["metrics"]))
        flat = None
        # a diagnostic, under the first noise level only; under the continuous dynamics its huge costs cannot be
        # integrated
        if dynamics == "euler" and noise == config.sensor_noises[0]:
            flat = _flat(config, feats, data, obs_tr, obs_te, kw)
            metrics.update(_summary(f"{label}.flat", flat["metrics"]))
        if with_figure and figure is None:
            C = sup["model"].components_
            starts = (data["s_te"][:1], data["s_new"][:1])
            figure = {"setting": _setting_title(dynamics, noise), "D": data["D"], "sup": C,
                      "uns": uns["model"].components_, "A_te": data["A_te"][:1], "demo_te": data["demo_te"][:1],
                      "demo_new": data["demo_new"][:1], "s_te": data["s_te"][:1], "s_new": data["s_new"][:1],
                      "unsupervised": [control_trajectories(feats, uns["b_te"][:1], s, **kw) for s in starts],
                      "supervised": [control_trajectories(feats, sup["model"].transform(list(obs_te[:1])) @ C, s, **kw)
                                     for s in starts],
                      "flat": None if flat is None else [control_trajectories(feats, flat["b_te"][:1], s, **kw)
                                                         for s in starts]}
    if config.diagnostics:
        # the supervised learner without sensor noise (the regression's own bias), and steepest descent stopped
        # at 200 steps (why the D step is conjugate gradient)
        clean = _supervised(config, feats, data, data["demo_tr"], data["demo_te"], sup_ss, kw, full=False)
        metrics.update(_summary(f"{setting_label(dynamics, 0.0)}.supervised", clean["metrics"]))
        if dynamics == "euler" and config.sensor_noises:
            noise = config.sensor_noises[0]
            obs_tr, obs_te = observe(data, noise)
            slow = _supervised(config, feats, data, obs_tr, obs_te, sup_ss, kw, d_solver="steepest", max_iter=200,
                               full=False)
            metrics.update(_summary(f"{setting_label(dynamics, noise)}.steepest_200.supervised", slow["metrics"]))
    return {"metrics": metrics, "figure": figure}


#: The metrics the claims read, per setting (NaN when a config does not compute the setting).
CLAIM_METRICS = ("supervised.train.rel_l2", "supervised.test.rel_l2", "supervised.dictionary_rel_error",
                 "supervised.new_start.rel_l2", "unsupervised.new_start.rel_l2", "unsupervised.dictionary_mixing_rel_error",
                 "mean_task.new_start.rel_l2")


def compute(config: Config, ctx: RunContext) -> Result:
    """The errors of every repetition under every setting (no figures; ``figure_data["trajectories"]``: the first
    repetition's dictionaries and a test task's trajectories under the first setting, for :func:`present`)."""
    for dynamics in config.dynamics:
        if dynamics not in DYNAMICS:
            raise ParameterError(f"dynamics must be among {', '.join(DYNAMICS)}; got {dynamics!r}")
    if not config.dynamics or not config.sensor_noises or min(config.sensor_noises) < 0:
        raise ParameterError(f"give at least one dynamics and one sensor noise >= 0; got {config.dynamics!r} and "
                         f"{config.sensor_noises!r}")
    if config.d_solver not in ("cg", "steepest"):
        raise ParameterError(f"d_solver must be 'cg' or 'steepest'; got {config.d_solver!r}")
    if config.n_repeats < 1:
        raise ParameterError(f"n_repeats must be at least 1; got {config.n_repeats!r}")
    ss = run_streams(config)
    index = [(rep, dyn) for rep in range(config.n_repeats) for dyn in config.dynamics]
    outs = ctx.parallel(_dynamics_job, [(config, ss[rep], dyn, rep == 0 and dyn == config.dynamics[0])
                                        for rep, dyn in index], desc="fits")
    reps: list[dict[str, float]] = [{} for _ in ss]
    for (rep, _), out in zip(index, outs):
        reps[rep].update(out["metrics"])
    figure = next(out["figure"] for out in outs if out["figure"] is not None)

    names = list(reps[0])
    samples = {name: [r.get(name, float("nan")) for r in reps] for name in names}
    with np.errstate(invalid="ignore"):
        metrics = {name: float(np.nanmean(v)) if np.isfinite(v).any() else float("nan") for name, v in samples.items()}
    for label, *_ in SETTINGS:  # a claim's metric under a setting this config does not compute: not measured
        for name in CLAIM_METRICS:
            metrics.setdefault(f"{label}.{name}", float("nan"))
    failed = {name: int(np.sum(~np.isfinite(v))) for name, v in samples.items() if not np.isfinite(v).all()}

    computed = [(setting_label(d, n), _setting_title(d, n)) for d in config.dynamics for n in config.sensor_noises]
    rows = []
    for label, title in computed:
        for name in LEARNERS:
            if f"{label}.{name}.train.rel_l2" not in metrics:
                continue
            rows.append([title, name] + [metrics[f"{label}.{name}.{split}.rel_l2"]
                                         for split in ("train", "test", "new_start")]
                        + [metrics[f"{label}.{name}.new_start.median_rel_l2"], metrics[f"{label}.mean_task.new_start.rel_l2"]])
    tables = {"errors": Table(
        f"Relative L2 error between demonstrator and imitator trajectories (mean over tasks, then over "
        f"{config.n_repeats} repetitions), under each setting",
        ["setting", "learner", "train tasks", "test tasks (demo start)", "test tasks (new start)",
         "new start (median)", "control: average task, new start"], rows,
        note="supervised: train and test use the given mixing coefficients (the thesis' protocol for its two "
             "numbers); its new-start error uses coefficients inferred from the test demonstration (eq. 4.6), as "
             "the unsupervised learner's. The control imitates the average training task (true dictionary, mean "
             f"of the true coefficients) from the new start points, ignoring the demonstration. The unsupervised "
             f"and flat learners' training-task errors (diagnostics) are over the first {config.n_test} training "
             "tasks (the supervised learner's over all). The flat imitator, a diagnostic, is run under the "
             "discrete dynamics and the first noise level only (under the continuous dynamics its costs are too "
             "large to integrate).")}
    diag_rows = []
    for label, title in computed:
        diag_rows.append([title, "conjugate gradient"] + [metrics[f"{label}.supervised.{m}"]
                                                          for m in ("train.rel_l2", "test.rel_l2",
                                                                    "dictionary_rel_error")])
    if config.diagnostics:
        for dynamics in config.dynamics:
            label = setting_label(dynamics, 0.0)
            diag_rows.append([_setting_title(dynamics, 0.0), "conjugate gradient"]
                             + [metrics[f"{label}.supervised.{m}"] for m in ("train.rel_l2", "test.rel_l2",
                                                                             "dictionary_rel_error")])
        if "euler" in config.dynamics:
            label = setting_label("euler", config.sensor_noises[0]) + ".steepest_200"
            diag_rows.append([_setting_title("euler", config.sensor_noises[0]), "steepest descent, 200 steps"]
                             + [metrics[f"{label}.supervised.{m}"] for m in ("train.rel_l2", "test.rel_l2",
                                                                             "dictionary_rel_error")])
    tables["supervised"] = Table(
        "The supervised learner under each setting, and diagnostics (mean over repetitions)",
        ["setting", "D solver", "train tasks", "test tasks", "dictionary error"], diag_rows,
        note="Metric names: <dynamics>.noise_<level>.supervised.<metric>, noise_1e_4 = 1e-4; noise_0 (no sensor "
             "noise) and steepest_200 are diagnostics, not settings: a noise-free sensor is no plausible sensor, and "
             "200 steps of steepest descent leave eq. (4.5) far from its minimum.")

    # per repetition: each training demonstration, and each test task's demonstrations (from its start and from a
    # new start), by its own id: generated apart, none is both
    sides = [([(f"r{rep}.train{i}",) for i in range(config.n_train)],
              [(f"r{rep}.test{i}",) for i in range(config.n_test)] + [(f"r{rep}.new_start{i}",)
                                                                     for i in range(config.n_test)])
             for rep in range(config.n_repeats)]
    demonstrations = describe_split("generated demonstrations (one per task mixture and start point)", sides)
    return Result(metrics=metrics, tables=tables, notes=_notes(config, metrics, failed), samples=samples,
                  sample_units={name: "repetitions" for name in samples},
                  units={"repetitions": SampleUnit.seeds(
                      "independent repetitions: new primitives, tasks, start points, sensor noise and learner "
                      "initialisation")},
                  split_groups={"demonstrations": demonstrations},
                  figure_data={"trajectories": figure})


def _notes(config: Config, metrics: dict[str, float], failed: dict[str, int]) -> list[str]:
    notes = [
        f"RBF width sigma = {RBFFeatures(config.grid_size).sigma:g} (grid spacing), lambda = {config.lam}, "
        f"dt = {config.dt}, {config.n_steps} steps per trajectory; trajectories are not clipped to [0, 1]^2. "
        f"{config.n_repeats} independent repetitions (new primitives, tasks, start points, sensor noise and learner "
        "initialisation); every metric is the mean over repetitions of a mean over tasks, and keeps its "
        "per-repetition values (samples, one unit: the repetitions, paired across settings and learners).",
        "Settings: the dynamics (Euler: the discrete form of eq. 4.1, section 4.2.1; ODE: the continuous eq. 4.1, "
        "integrated) and the sensor noise (1e-4 or 1e-3 of the workspace side; the thesis gives none) are ours to "
        "choose and change verdicts, so every claim is evaluated under each of the four combinations, and the "
        "magnitudes are given under each. The learners always regress on the discrete form: under the continuous "
        "dynamics their errors also contain that approximation's bias. One repetition's demonstrations are the "
        "same under both noise levels, its dictionary, tasks and start points the same under both dynamics.",
        "Magnitudes: the thesis' two numbers (section 4.2.2: mean relative L2 error of the supervised learner, "
        "coefficients given, on training and on new tasks) against ours, as ratios with their interval, under "
        "each setting. They replace a claim that checked both errors below ten times the thesis' numbers (a bar "
        "of ours).",
        "Reclassified (ours): 'the supervised learner achieves an accurate reconstruction of the dictionary' "
        "(Fig. 4.1) is checked as a relative error below 10 %, a bar of ours: the thesis says 'accurate' without "
        "a number.",
        "Reclassified (ours): imitation of a new task inferred from one demonstration, from new start points "
        "(section 4.2.3), was checked below ten times the thesis' test error, a bar built on a number the thesis "
        "gives for another protocol (coefficients given, demonstration's start). The thesis gives no number and no "
        "comparison for this protocol; the check is now a control of ours: the imitation beats an imitator that "
        "knows the average training task exactly and ignores the demonstration (mean_task.new_start.rel_l2), "
        "i.e. the inferred task carries what the demonstration shows. For the unsupervised learner the thesis "
        "itself says that its evaluation did not validate this capability quantitatively (section 4.2.3).",
        "Ours: the unsupervised learner's atoms span the demonstrator's primitives (error up to an invertible "
        "mixing below 10 %). The thesis says only that it 'acquires its own representation', 'very different' "
        "from the demonstrator's (Fig. 4.1, section 4.2.3); that statement is not tested: the model is "
        "invariant to any invertible mixing of the atoms (D -> M D, a -> a M^-1), so a raw or order-and-scale "
        "difference holds whatever the learner does. unsupervised.dictionary_matched_rel_error is kept as a "
        "diagnostic; unsupervised.initial_dictionary_mixing_rel_error "
        f"({metrics['unsupervised.initial_dictionary_mixing_rel_error']:.3g}) is the error of its random start.",
        f"The supervised learner minimises eq. (4.5) in D by {'conjugate gradient' if config.d_solver == 'cg' else 'steepest descent'} "
        f"(at most {config.supervised_max_iter} steps). The thesis minimises (4.5) by 'a gradient descent approach' "
        "without a step count, and its errors are those of a converged fit. With a random start, steepest descent "
        "with exact line search crawls along the ill-conditioned directions (one demonstration excites few "
        "features): see the steepest_200 row of the diagnostics (config.diagnostics, on in the full preset). "
        "supervised.initial_dictionary_rel_error = "
        f"{metrics['supervised.initial_dictionary_rel_error']:.3g} shows where the learner starts.",
        "The unsupervised learner starts from random Gaussian atoms and alternates least squares on the "
        f"coefficients (eq. 4.6) with 5 {'conjugate-gradient' if config.d_solver == 'cg' else 'exact-line-search gradient'} "
        f"steps on D (eq. 4.7), at most {config.max_iter} alternations.",
        "The flat imitator's least-squares fit (eq. 4.3, minimum-norm) of 25 weights on one demonstration is "
        "ill-conditioned: the demonstration excites few directions, and the noise residuals put huge weights on "
        "the others, so its trajectories leave the demonstrated region (relative errors of 1e4 and more) and "
        "cannot be integrated under the continuous dynamics. It is a diagnostic with no claim: a diverging "
        "baseline is beaten by anything and is no evidence.",
        "Quick preset: five repetitions (was three), each computing every setting with every learner (before: "
        f"one setting, and the supervised learner alone under the others). To keep its CPU time, it has "
        f"{Config.QUICK['n_test']} test tasks per repetition (was 50), {Config.QUICK['max_iter']} alternations of "
        f"the unsupervised learner (was 60; {Config.max_iter} in the full preset), "
        "the unsupervised and flat learners' training-task errors over the first test-task-many training tasks, "
        "and the diagnostics (noise-free and steepest-descent fits) in the full "
        "preset only. The thesis fixes none of these; the repetitions, not the tasks, are the verdicts' units.",
        "Random streams (mmconcepts.engine.Streams): per repetition, the seed's data and learner streams draw the data (dictionary, mixtures, "
        "start points), the sensor noise and the learners' initial dictionaries independently; the learners start "
        "from the same initial dictionaries under every setting.",
    ]
    if failed:
        notes.append("Not measured in some repetitions (the continuous dynamics could not be integrated for a "
                      "learnt cost; the mean is over the others): "
                      + ", ".join(f"{name} ({n})" for name, n in sorted(failed.items())) + ".")
    return notes


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
                  f"the unsupervised atoms are known up to a mixing; {fd.get('setting', '')})")

    fig3 = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig3.subplots(2, 4, squeeze=False)
    for c, (lab, src) in enumerate((("demonstrator", None), ("flat", "flat"), ("supervised (inferred)", "supervised"),
                                    ("unsupervised", "unsupervised"))):
        for r, (demo, start) in enumerate(((fd["demo_te"], fd["s_te"]), (fd["demo_new"], fd["s_new"]))):
            ax = axes[r, c]
            img = ax.imshow(feats.cost(fd["A_te"][0] @ fd["D"], Qg), origin="lower", extent=(0, 1, 0, 1),
                            cmap="gray_r")
            ax.plot(*demo[0].T, "b.-", ms=2, lw=0.8, label="demonstrator")
            if src is not None and fd[src] is not None:
                ax.plot(*fd[src][r][0].T, "r.-", ms=2, lw=0.8, label="imitator")
            elif src is not None:
                ax.text(0.5, 0.5, "not integrable", ha="center", va="center", fontsize=7, color="r")
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
    fig3.suptitle(f"Fig 4.2-4.3: a test task imitated from one demonstration ({fd.get('setting', '')})")
    return {"fig4_1_dictionaries": fig1, "fig4_3_trajectories": fig3}


def _magnitude_claims() -> list[Claim]:
    return [Claim(f"{title}: the supervised learner's mean relative L2 trajectory error {_THESIS_WHAT[name]} "
                  f"(coefficients given) against the thesis' {{thesis:{label}.{name}}}.", f"{label}.{name}",
                  kind="magnitude", source=f"Section 4.2.2 ({_THESIS_LINES[name]})")
            for label, title, _, _ in SETTINGS for name in THESIS]


def _under_every_setting(rule: str) -> dict[str, str]:
    """``rule`` (``{s}`` standing for a setting's metric prefix) under each of :data:`SETTINGS`."""
    return {title: rule.format(s=label) for label, title, _, _ in SETTINGS}


EXPERIMENT = register(
    Experiment(
        id="ch4-inverse-control",
        title="Factorial inverse feedback control: a dictionary of primitive costs",
        thesis_ref="Section 4.2 (eq. 4.1-4.7, Fig 4.1-4.3)",
        config_cls=Config,
        compute=compute,
        present=present,
        reference={f"{label}.{name}": value for label, _, _, _ in SETTINGS for name, value in THESIS.items()},
        claims=_magnitude_claims() + [
            Claim("The supervised learner (dictionary from coefficients) achieves an accurate reconstruction of the "
                  "original dictionary of primitive tasks (Fig. 4.1): a relative error below 10 %, our bar (with "
                  "given coefficients the dictionary is identifiable, not only up to a mixing).",
                  kind="ours", settings=_under_every_setting("{s}.supervised.dictionary_rel_error < 0.1")),
            Claim("With the supervised dictionary, a new task inferred from a single demonstration (eq. 4.6) is "
                  "imitated from new start points better than by an imitator that knows the average training task "
                  "and ignores the demonstration (section 4.2.3; the control is ours).",
                  kind="ours", settings=_under_every_setting(
                      "{s}.supervised.new_start.rel_l2 < {s}.mean_task.new_start.rel_l2")),
            Claim("With the unsupervised dictionary, a new task inferred from a single demonstration is imitated "
                  "from new start points better than by an imitator that knows the average training task and ignores "
                  "the demonstration (section 4.2.3, which says that its own evaluation did not validate this "
                  "quantitatively; the control is ours).",
                  kind="ours", settings=_under_every_setting(
                      "{s}.unsupervised.new_start.rel_l2 < {s}.mean_task.new_start.rel_l2")),
            Claim("The unsupervised learner's atoms span the demonstrator's primitives: a dictionary error up to an "
                  "invertible mixing (the ambiguity of the model) below 10 %, our bar (the thesis says only that it "
                  "acquires its own representation, Fig. 4.1).",
                  kind="ours", settings=_under_every_setting("{s}.unsupervised.dictionary_mixing_rel_error < 0.1")),
        ],
        description=__doc__.split("\n\n")[0],
    )
)

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
