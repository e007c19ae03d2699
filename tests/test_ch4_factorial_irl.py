"""The ch4-factorial-irl experiment on a small world (the quick preset is timed separately)."""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts.experiments import RunContext
import dataclasses

from mmconcepts.experiments.ch4_factorial_irl import Config, _world, run, score_rewards
from mmconcepts.tasks import FactorialIRL, GradIRL, grid_world

SMALL = Config(grid_size=4, n_tasks=6, n_test_tasks=3, demos_curve=(2,), tasks_curve=(6,))


def _same_tasks(a, b):
    (Ha, Ra, da), (Hb, Rb, db) = a, b
    np.testing.assert_array_equal(Ha, Hb)
    np.testing.assert_array_equal(Ra, Rb)
    for x, y in zip(da, db):
        for t, u in zip(x, y):
            np.testing.assert_array_equal(t, u)


def test_data_streams_are_independent():
    # the test tasks, the training tasks and the examples draw from separate streams: resizing one leaves the others
    base = _world(SMALL)
    more_test = _world(dataclasses.replace(SMALL, n_test_tasks=5))
    np.testing.assert_array_equal(base[1], more_test[1])
    _same_tasks(base[2], more_test[2])
    more_train = _world(dataclasses.replace(SMALL, n_tasks=8))
    _same_tasks(base[3], more_train[3])
    assert base[4].integers(2**62) == more_train[4].integers(2**62)  # the example draw does not follow the data
    other = _world(dataclasses.replace(SMALL, seed=1))
    assert not np.array_equal(base[1], other[1])


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_learners_draw_nothing():
    # no seed reaches the learners because they have no randomness: two fits on the same data are identical
    mdp, _, (H, R, demos), _, _ = _world(SMALL)
    demos = [d[:2] for d in demos]
    a = GradIRL(max_iter=5).fit(mdp, demos)
    b = GradIRL(max_iter=5).fit(mdp, demos)
    np.testing.assert_array_equal(a.theta_, b.theta_)
    fa = FactorialIRL(3, max_iter=2, inner_steps=2).fit(mdp, demos, flat_theta=a.theta_)
    fb = FactorialIRL(3, max_iter=2, inner_steps=2).fit(mdp, demos, flat_theta=a.theta_)
    np.testing.assert_array_equal(fa.components_, fb.components_)


def test_score_is_zero_for_the_true_reward(rng):
    mdp = grid_world(5)
    R = rng.standard_normal((3, 25, 4))
    s = score_rewards(mdp, R, R)
    np.testing.assert_allclose(s["deviation"], 0.0, atol=1e-8)
    s0 = score_rewards(mdp, np.zeros_like(R), R)  # constant reward -> uniform policy -> normalised 1
    np.testing.assert_allclose(s0["normalised"], 1.0, atol=1e-8)


def test_quick_preset_is_the_documented_one():
    q = Config.quick()
    assert q.grid_size == 10 and q.discount == 0.9 and q.n_primitives == 5
    f = Config.full()
    assert (f.n_tasks, f.n_demos, f.demo_length, f.n_test_tasks) == (100, 10, 10, 100)


@pytest.mark.slow
def test_small_run_produces_every_metric_and_figure():
    cfg = Config(grid_size=6, n_tasks=12, n_test_tasks=6, flat_max_iter=15, factorial_max_iter=3, inner_steps=2,
                 demos_curve=(2, 10), tasks_curve=(6, 12))
    res = run(cfg, RunContext(show_progress=False))
    res.validate()
    for split in ("train", "transfer"):
        for name in ("flat", "factorial", "flat_pca", "flat_gt", "maxent"):
            v = res.metrics[f"{split}.{name}.deviation"]
            assert np.isfinite(v) and v >= -1e-8
    assert res.metrics["transfer.flat_examples.deviation"] >= -1e-8
    assert res.metrics["train.flat_gt.deviation"] < res.metrics["train.flat.deviation"]
    assert set(res.figures) == {"fig4_4_dictionaries", "fig4_5_train_curves", "fig4_6_transfer_curves",
                                "fig4_7_value_functions"}
    assert len(res.tables["train_vs_tasks"].rows) == 2 and len(res.tables["train_vs_demos"].rows) == 2
    # per-task samples behind every mean, paired across learners
    assert len(res.samples["train.flat.deviation"]) == len(res.samples["train.factorial.deviation"]) == 12
    assert len(res.samples["transfer.factorial.deviation"]) == 6
    assert res.metrics["train.flat.deviation"] == pytest.approx(np.mean(res.samples["train.flat.deviation"]))
    assert len(res.samples["tasks_curve.min_tasks.advantage"]) == 6
