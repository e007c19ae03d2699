"""The ch4-factorial-irl experiment on a small world (the quick preset is timed separately)."""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts.experiments import RunContext
from mmconcepts.experiments.ch4_factorial_irl import Config, run, score_rewards
from mmconcepts.tasks import grid_world


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
