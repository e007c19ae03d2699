"""The ch4-inverse-control experiment in quick mode."""

from __future__ import annotations

import pytest

from mmconcepts.experiments import RunContext
from mmconcepts.experiments.ch4_inverse_control import Config, run


@pytest.mark.slow
def test_quick_run_metrics():
    res = run(Config.quick(), RunContext(show_progress=False))
    res.validate()
    for name in ("flat", "supervised", "unsupervised"):
        for split in ("train", "test", "new_start"):
            assert 0 <= res.metrics[f"{name}.{split}.rel_l2"] < 1
    assert res.metrics["supervised.train.rel_l2"] < 0.01
    assert set(res.figures) == {"fig4_1_dictionaries", "fig4_3_trajectories"}
