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

Sensor noise. The thesis gives none. Its agent models kinesthetic demonstrations read on
the imitator's own body (section 4.2.1), i.e. from joint encoders; a 12-bit encoder
resolves 1/4096 of its range, a quantisation noise of standard deviation
``1 / (4096 sqrt(12)) ~ 7e-5`` of the range. We take ``sensor_noise = 1e-4`` of the
workspace side (Q = [0, 1]^2), i.i.d. Gaussian on each observed coordinate; it was fixed
from that argument, not fitted to the thesis' numbers. Finite differences amplify it by
``1 / dt``: with ``dt = 0.01`` the velocity noise is ~0.014 against speeds of order 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment

from ..tasks import FactorialInverseControl, RBFFeatures, brillinger_regression, control_trajectories, relative_l2_error
from .base import Claim, Experiment, Result, RunContext, Table
from .registry import register

__all__ = ["Config", "run"]

LEARNERS = ("flat", "supervised", "unsupervised")


@dataclass(frozen=True)
class Config:
    """Sizes of the factorial inverse control experiment (defaults: the thesis' settings).

    ``sensor_noise`` is the standard deviation of the Gaussian noise on observed positions,
    as a fraction of the workspace side (see the module docstring for the default).
    """

    grid_size: int = 5
    n_primitives: int = 6
    n_train: int = 200
    n_test: int = 100
    n_steps: int = 100
    dt: float = 0.01
    lam: float = 1.0
    max_iter: int = 200
    sensor_noise: float = 1e-4
    dynamics: str = "euler"
    seed: int = 0

    @classmethod
    def quick(cls) -> "Config":
        return cls(n_test=50, max_iter=60)

    @classmethod
    def full(cls) -> "Config":
        return cls()


def _mix(rng, n, k):
    A = np.zeros((n, k))
    for i in range(n):
        idx = rng.choice(k, size=int(rng.integers(2, 4)), replace=False)
        A[i, idx] = rng.uniform(0.5, 1.5, idx.size)
    return A


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


def run(config: Config, ctx: RunContext) -> Result:
    rng = np.random.default_rng(config.seed)
    feats = RBFFeatures(config.grid_size)
    K, F = config.n_primitives, feats.n_features
    D = rng.standard_normal((K, F))
    if config.dynamics not in ("euler", "ode"):
        raise ValueError(f"dynamics must be 'euler' or 'ode'; got {config.dynamics!r}")
    kw = dict(n_steps=config.n_steps, lam=config.lam, dt=config.dt, method=config.dynamics)
    A_tr, A_te = _mix(rng, config.n_train, K), _mix(rng, config.n_test, K)
    s_tr, s_te, s_new = rng.random((config.n_train, 2)), rng.random((config.n_test, 2)), rng.random((config.n_test, 2))
    demo_tr = control_trajectories(feats, A_tr @ D, s_tr, **kw)
    demo_te = control_trajectories(feats, A_te @ D, s_te, **kw)
    demo_new = control_trajectories(feats, A_te @ D, s_new, **kw)  # the demonstrator from new start points
    # what the learners observe: the sampled demonstrations through a noisy sensor
    obs_tr = demo_tr + config.sensor_noise * rng.standard_normal(demo_tr.shape)
    obs_te = demo_te + config.sensor_noise * rng.standard_normal(demo_te.shape)

    learner_kw = dict(features=feats, lam=config.lam, dt=config.dt, max_iter=config.max_iter,
                      random_state=config.seed)
    sup = FactorialInverseControl(K, **learner_kw).fit(list(obs_tr), A_tr)
    uns = FactorialInverseControl(K, **learner_kw).fit(list(obs_tr))
    sup_clean = FactorialInverseControl(K, **learner_kw).fit(list(demo_tr), A_tr)  # diagnostic: no sensor noise

    def flat_b(demos):
        return np.array([brillinger_regression(feats, d, lam=config.lam, dt=config.dt) for d in demos])

    betas = {
        "flat": (flat_b(obs_tr), flat_b(obs_te)),
        "supervised": (A_tr @ sup.components_, A_te @ sup.components_),  # given coefficients
        "unsupervised": (uns.coefficients_ @ uns.components_, uns.transform(list(obs_te)) @ uns.components_),
    }
    sup_inferred = sup.transform(list(obs_te)) @ sup.components_
    metrics, rows, imit = {}, [], {}
    for name, (b_tr, b_te) in betas.items():
        im_tr = control_trajectories(feats, b_tr, s_tr, **kw)
        im_te = control_trajectories(feats, b_te if name != "supervised" else sup_inferred, s_te, **kw)
        im_given = control_trajectories(feats, b_te, s_te, **kw)
        im_new = control_trajectories(feats, b_te if name != "supervised" else sup_inferred, s_new, **kw)
        imit[name] = (im_te, im_new)
        metrics[f"{name}.train.rel_l2"] = float(np.mean(relative_l2_error(demo_tr, im_tr)))
        metrics[f"{name}.test.rel_l2"] = float(np.mean(relative_l2_error(demo_te, im_given if name == "supervised" else im_te)))
        metrics[f"{name}.new_start.rel_l2"] = float(np.mean(relative_l2_error(demo_new, im_new)))
        metrics[f"{name}.new_start.median_rel_l2"] = float(np.median(relative_l2_error(demo_new, im_new)))
        if name == "supervised":
            metrics["supervised.inferred.test.rel_l2"] = float(np.mean(relative_l2_error(demo_te, im_te)))
            metrics["supervised.given.new_start.rel_l2"] = float(np.mean(relative_l2_error(
                demo_new, control_trajectories(feats, b_te, s_new, **kw))))
        rows.append([name, metrics[f"{name}.train.rel_l2"], metrics[f"{name}.test.rel_l2"],
                     metrics[f"{name}.new_start.rel_l2"]])
    metrics["supervised.dictionary_rel_error"] = float(np.linalg.norm(sup.components_ - D) / np.linalg.norm(D))
    metrics["unsupervised.dictionary_matched_rel_error"] = _matched_error(uns.components_, D)
    metrics["supervised_noise_free.train.rel_l2"] = float(np.mean(relative_l2_error(
        demo_tr, control_trajectories(feats, A_tr @ sup_clean.components_, s_tr, **kw))))
    metrics["supervised_noise_free.test.rel_l2"] = float(np.mean(relative_l2_error(
        demo_te, control_trajectories(feats, A_te @ sup_clean.components_, s_te, **kw))))
    metrics["supervised_noise_free.dictionary_rel_error"] = float(
        np.linalg.norm(sup_clean.components_ - D) / np.linalg.norm(D))

    grid = np.linspace(0, 1, 60)
    Qg = np.stack(np.meshgrid(grid, grid), -1)
    fig1 = Figure(figsize=(2 * K, 6))
    axes = fig1.subplots(3, K, squeeze=False)
    for r, (lab, Dm) in enumerate((("true", D), ("supervised", sup.components_), ("unsupervised", uns.components_))):
        for j in range(K):
            axes[r, j].imshow(feats.cost(Dm[j], Qg), origin="lower", extent=(0, 1, 0, 1), cmap="gray_r")
            axes[r, j].set_xticks([]); axes[r, j].set_yticks([])
            axes[r, j].set_title(f"{lab} {j + 1}", fontsize=7)
    fig1.suptitle("Fig 4.1: primitive costs: true, supervised learner, unsupervised learner (dark = high cost)")
    fig1.tight_layout()

    fig3 = Figure(figsize=(10, 5))
    axes = fig3.subplots(2, 4, squeeze=False)
    j = 0
    for c, (lab, src) in enumerate((("demonstrator", None), ("flat", "flat"), ("supervised (inferred)", "supervised"),
                                    ("unsupervised", "unsupervised"))):
        for r, (demo, start) in enumerate(((demo_te, s_te), (demo_new, s_new))):
            ax = axes[r, c]
            ax.imshow(feats.cost(A_te[j] @ D, Qg), origin="lower", extent=(0, 1, 0, 1), cmap="gray_r")
            ax.plot(*demo[j].T, "b.-", ms=2, lw=0.8, label="demonstrator")
            if src is not None:
                ax.plot(*imit[src][r][j].T, "r.-", ms=2, lw=0.8, label="imitator")
            ax.plot(*start[j], "y*", ms=10)
            ax.set_xlim(0, 1); ax.set_ylim(0, 1); ax.set_xticks([]); ax.set_yticks([])
            ax.set_title(f"{lab}, {'demo start' if r == 0 else 'new start'}", fontsize=7)
    fig3.suptitle("Fig 4.2-4.3: a test task imitated from one demonstration")
    fig3.tight_layout()

    return Result(
        metrics=metrics,
        tables={"errors": Table("Relative L2 error between demonstrator and imitator trajectories (mean)",
                                ["learner", "train tasks", "test tasks (demo start)", "test tasks (new start)"], rows,
                                note="supervised: train and test use the given mixing coefficients (the thesis' "
                                     "protocol for 0.001127 / 0.002675); its new-start error uses coefficients "
                                     "inferred from the demonstration (eq. 4.6).")},
        figures={"fig4_1_dictionaries": fig1, "fig4_3_trajectories": fig3},
        notes=[f"RBF width sigma = {feats.sigma:g} (grid spacing), lambda = {config.lam}, dt = {config.dt}, "
               f"{config.n_steps} steps per trajectory; trajectories are not clipped to [0, 1]^2.",
               ("Every trajectory (demonstrator and imitators) follows the discrete form of eq. (4.1) of section "
                "4.2.1" if config.dynamics == "euler" else
                "Every trajectory (demonstrator and imitators) is the continuous-time agent of eq. (4.1) integrated "
                "with LSODA (rtol 1e-8) and sampled every dt") +
               "; the learners regress on the discrete form of section 4.2.1 "
               f"from demonstrations observed with Gaussian sensor noise of std "
               f"{config.sensor_noise:g} (fraction of the workspace side; see the module docstring).",
               "supervised_noise_free.* is a diagnostic beyond the thesis: the supervised learner on the same "
               "demonstrations without sensor noise "
               f"({'exact up to the learner' if config.dynamics == 'euler' else 'only the discrete approximation of eq. (4.1) limits it'}) "
               f"(train {metrics['supervised_noise_free.train.rel_l2']:.4g} without noise vs "
               f"{metrics['supervised.train.rel_l2']:.4g} with it). supervised.given.new_start uses the true mixing "
               "coefficients from new start points; supervised.new_start infers them from the test demonstration "
               "(eq. 4.6), as the unsupervised learner must. *.median_rel_l2 shows how much of a mean is due to a "
               "few imitations that end in another basin of the cost.",
               "The flat imitator's least-squares fit (eq. 4.3, minimum-norm) of 25 weights on one demonstration "
               "is ill-conditioned: the demonstration excites few directions, and the approximation and noise "
               "residuals put huge weights on the others, so its trajectories leave the demonstrated region. With the "
               "discrete dynamics one step on such a gradient throws the imitator far outside Q = [0, 1]^2, where the "
               "RBF features vanish and it stays: hence relative errors of 1e4 and more (mean and median), which "
               "only say that the flat imitator fails.",
               "The unsupervised dictionary starts from random Gaussian atoms and alternates least squares on the "
               f"coefficients (eq. 4.6) with 5 exact-line-search gradient steps on D (eq. 4.7), {uns.n_iter_} "
               f"alternations (max_iter = {config.max_iter}).",
               "The thesis gives numbers only for the supervised learner (train 0.001127, test 0.002675); flat and "
               "unsupervised errors have no thesis reference, and the thesis states that its evaluation did not "
               "validate the unsupervised learner quantitatively (section 4.2.3)."],
    )


register(
    Experiment(
        id="ch4-inverse-control",
        title="Factorial inverse feedback control: a dictionary of primitive costs",
        thesis_ref="Section 4.2 (eq. 4.1-4.7, Fig 4.1-4.3)",
        config_cls=Config,
        run=run,
        reference={"supervised.train.rel_l2": 0.001127, "supervised.test.rel_l2": 0.002675},
        claims=[
            Claim("The supervised learner (dictionary from coefficients) reproduces demonstrated trajectories "
                  "accurately, on train and on new tasks (0.001127 and 0.002675 in the thesis; 'accurately' "
                  "checked as below 1%).",
                  "supervised.train.rel_l2 < 0.01 and supervised.test.rel_l2 < 0.01"),
            Claim("The supervised learner achieves an accurate reconstruction of the original dictionary of "
                  "primitive tasks (Fig 4.1; checked as a relative error below 10%).",
                  "supervised.dictionary_rel_error < 0.1"),
            Claim("A single demonstration shows the task only locally, so the flat imitator does worse than the "
                  "supervised dictionary (coefficients inferred from the same demonstration) from new start points "
                  "(section 4.2.1).", "flat.new_start.rel_l2 > supervised.new_start.rel_l2"),
            Claim("The unsupervised factorial representation enables imitation of a new task from a single "
                  "demonstration, better than the flat imitator from new start points. The thesis states this but "
                  "says its own evaluation did not validate it quantitatively (section 4.2.3).",
                  "unsupervised.new_start.rel_l2 < flat.new_start.rel_l2"),
            Claim("The unsupervised learner's dictionary is very different from the demonstrator's, even up to the "
                  "order and scale of the atoms (Fig 4.1, section 4.2.3; checked as a matched relative error above "
                  "50%).", "unsupervised.dictionary_matched_rel_error > 0.5"),
        ],
        description=__doc__.split("\n\n")[0],
    )
)
