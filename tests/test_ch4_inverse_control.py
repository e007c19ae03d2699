"""The ch4-inverse-control experiment: demonstrations (discrete or continuous-time) observed through a noisy sensor."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmconcepts.experiments import RunContext
from mmconcepts.experiments.ch4_inverse_control import Config, _matched_error, run


def test_quick_preset_keeps_the_thesis_setup():
    q = Config.quick()
    assert (q.grid_size, q.n_primitives, q.n_train) == (5, 6, 200)
    assert 0 < q.sensor_noise <= 1e-3


def test_matched_error_ignores_order_and_scale(rng):
    D = rng.standard_normal((4, 25))
    learnt = D[[2, 0, 3, 1]] * np.array([[3.0], [-0.5], [2.0], [10.0]])
    assert _matched_error(learnt, D) < 1e-6  # sqrt of a cancellation: ~1e-8 at best
    assert _matched_error(rng.standard_normal((4, 25)), D) > 0.5


@pytest.mark.slow
@pytest.mark.parametrize("dynamics", ["euler", "ode"])
def test_small_run(dynamics):
    cfg = dataclasses.replace(Config.quick(), n_train=40, n_test=10, n_steps=50, max_iter=20, dynamics=dynamics)
    res = run(cfg, RunContext(show_progress=False))
    res.validate()
    m = res.metrics
    for name in ("flat", "supervised", "unsupervised"):
        for split in ("train", "test", "new_start"):
            assert np.isfinite(m[f"{name}.{split}.rel_l2"]) and m[f"{name}.{split}.rel_l2"] >= 0
    if dynamics == "euler":
        # the regression inverts the discrete agent exactly: only the sensor noise is left
        assert m["supervised_noise_free.train.rel_l2"] < 1e-8
        assert 1e-6 < m["supervised.train.rel_l2"] < 0.05
    else:
        # continuous-time data: the discrete regression is no longer exact
        assert 1e-6 < m["supervised_noise_free.train.rel_l2"] < 0.2
        assert 1e-6 < m["supervised.train.rel_l2"] < 0.2
    assert 1e-6 < m["supervised.dictionary_rel_error"] < 0.5
    assert set(res.figures) == {"fig4_1_dictionaries", "fig4_3_trajectories"}
    noisier = run(dataclasses.replace(cfg, sensor_noise=1e-2), RunContext(show_progress=False)).metrics
    assert noisier["supervised.dictionary_rel_error"] > m["supervised.dictionary_rel_error"]  # noise reaches the learner


def test_unknown_dynamics_is_refused():
    with pytest.raises(ValueError, match="dynamics"):
        run(dataclasses.replace(Config.quick(), dynamics="rk4"), RunContext(show_progress=False))
