"""The ch4-factorial-irl experiment on its smoke preset's small world (the quick preset is timed separately)."""

from __future__ import annotations

import numpy as np
import pytest

import dataclasses
import re

from hypothesis import given, settings
from hypothesis import strategies as st

from mmconcepts.experiments import RunContext, get
from mmconcepts.experiments.ch4.factorial_irl import Config, _world, compute, run, score_rewards, world_streams
from mmconcepts.engine.rules import parse_rule
from mmconcepts.engine.verdicts import decide_claim
from mmconcepts.tasks import FactorialIRL, GradIRL, grid_world

#: The smoke preset: a world small enough to fit every learner in a few seconds, with points below the default on
#: both curves.
SMOKE = Config.smoke()
_SOURCE = re.compile(r"\((?:line \d+|lines \d+(?:-\d+|, \d+))\)\Z")


def _same_tasks(a, b):
    (Ha, Ra, da), (Hb, Rb, db) = a, b
    np.testing.assert_array_equal(Ha, Hb)
    np.testing.assert_array_equal(Ra, Rb)
    for x, y in zip(da, db):
        for t, u in zip(x, y):
            np.testing.assert_array_equal(t, u)


def test_data_streams_are_independent():
    # the test tasks, the training tasks and the examples draw from separate streams: resizing one leaves the others
    base = _world(SMOKE)
    more_test = _world(dataclasses.replace(SMOKE, n_test_tasks=SMOKE.n_test_tasks + 2))
    np.testing.assert_array_equal(base[1], more_test[1])
    _same_tasks(base[2], more_test[2])
    more_train = _world(dataclasses.replace(SMOKE, n_tasks=SMOKE.n_tasks + 2))
    _same_tasks(base[3], more_train[3])
    assert base[4].integers(2**62) == more_train[4].integers(2**62)  # the example draw does not follow the data
    other = _world(dataclasses.replace(SMOKE, seed=1))
    assert not np.array_equal(base[1], other[1])


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_learners_draw_nothing():
    # no seed reaches the learners because they have no randomness: two fits on the same data are identical
    mdp, _, (H, R, demos), _, _ = _world(SMOKE)
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
    assert q.n_worlds == 1  # within one fit: five worlds would cost five quick runs
    f = Config.full()
    assert (f.n_tasks, f.n_demos, f.demo_length, f.n_test_tasks) == (100, 10, 10, 100)
    assert f.n_worlds >= 5  # independent units behind the full preset's verdicts


def test_worlds_are_independent_and_do_not_depend_on_their_number():
    a, b = _world(SMOKE, 0), _world(SMOKE, 1)
    assert not np.array_equal(a[1], b[1])  # other primitives
    more = dataclasses.replace(SMOKE, n_worlds=4)
    np.testing.assert_array_equal(_world(more, 1)[1], b[1])  # world 1 is world 1 whatever n_worlds
    states = [world_streams(SMOKE, w).sequence(*key).generate_state(2).tolist() for w in range(3)
              for key in (("data", 0), ("data", 1), ("data", 2), ("reference",))]
    assert len({tuple(x) for x in states}) == len(states)  # no stream shared within or across worlds


def test_claims_are_the_thesis_statements_with_their_sources():
    exp = get("ch4-factorial-irl")
    assert exp.reference == {}  # curves, no numbers: no magnitude claim
    assert len(exp.claims) == 6 and {c.kind for c in exp.claims} == {"thesis"}
    for c in exp.claims:
        assert _SOURCE.search(c.source) and ("4.3.2" in c.source or "4.3.1" in c.source), c.source
        assert not re.search(r"\d", c.rule.replace("4.3", ""))  # orders, no bars


def test_one_world_gives_per_task_samples_within_one_fit():
    few_demos, few_tasks = min(SMOKE.demos_curve), min(SMOKE.tasks_curve)
    assert SMOKE.n_worlds == 1 and few_demos < SMOKE.n_demos and few_tasks < SMOKE.n_tasks  # points below the default
    res = compute(SMOKE, RunContext(show_progress=False))
    res.validate()
    s, u = res.samples, res.sample_units
    assert set(u) == set(s)
    assert {k.kind for k in res.units.values()} == {"within-fit"}
    assert len(s["train.flat.deviation"]) == len(s["train.factorial.deviation"]) == SMOKE.n_tasks
    assert u["train.flat.deviation"] == u["few_demos.flat.deviation"] == "training tasks"  # the same tasks, paired
    few = res.figure_data["points"][(few_demos, SMOKE.n_tasks)]["train"]  # the curve's point with fewer demonstrations
    assert s["few_demos.flat.deviation"] == few["flat"]["deviation"]
    assert s["few_demos.factorial.deviation"] == few["factorial"]["deviation"]
    assert len(s["transfer.factorial.deviation"]) == SMOKE.n_test_tasks
    # the tasks curve compares the same first tasks: learnt from the fewest tasks, and from all (the default point)
    first = s["tasks_curve.max_tasks.factorial.deviation"]
    assert len(first) == len(s["tasks_curve.min_tasks.factorial.deviation"]) == few_tasks
    assert first == s["train.factorial.deviation"][:few_tasks]
    assert res.split_groups["tasks"]["shared_sources"] == 0
    exp = get("ch4-factorial-irl")
    for claim in exp.claims:
        assert parse_rule(claim.rule).metrics <= set(s)  # every claim has samples
        rec = decide_claim(claim, res.metrics, s, reference=exp.reference, units=u, unit_kinds=res.units)
        assert rec.verdict in ("holds", "fails", "inconclusive")
        if rec.verdict != "inconclusive":
            assert rec.scope == "within one fit"


def test_several_worlds_give_per_world_samples():
    # deviation from the smoke preset: two worlds, and no point below the default on either curve
    cfg = dataclasses.replace(SMOKE, n_worlds=2, demos_curve=(10,), tasks_curve=(8,))
    res = compute(cfg, RunContext(show_progress=False))
    res.validate()
    assert set(res.sample_units.values()) == {"worlds"} and res.units["worlds"].kind == "independent"
    assert all(len(v) == 2 for v in res.samples.values())
    first = res.figure_data["points"][(10, 8)]["train"]["flat"]["deviation"]  # world 0's default point, per task
    assert res.samples["train.flat.deviation"][0] == pytest.approx(np.mean(first))
    assert res.samples["train.flat.deviation"][1] != res.samples["train.flat.deviation"][0]  # another world
    assert res.metrics["train.flat.deviation"] == pytest.approx(np.mean(res.samples["train.flat.deviation"]))
    # no point below the default on either curve: those claims are not measured
    assert np.isnan(res.metrics["few_demos.flat.deviation"])
    assert np.isnan(res.metrics["tasks_curve.min_tasks.factorial.deviation"])
    assert res.split_groups["tasks"]["n_folds"] == 2 and res.split_groups["tasks"]["shared_sources"] == 0


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_tasks=st.integers(1, 6), n_test=st.integers(1, 4))
def test_test_tasks_are_new_tasks(seed, n_tasks, n_test):
    """No test task is a training task: its mixture is drawn apart from every training task's."""
    cfg = dataclasses.replace(SMOKE, grid_size=3, seed=seed, n_tasks=n_tasks, n_test_tasks=n_test, n_demos=1,
                              demos_curve=(1,))
    _, _, (H, _, _), (H_te, _, _), _ = _world(cfg)
    assert not (np.abs(H_te[:, None, :] - H[None, :, :]).max(-1) == 0).any()


@pytest.mark.slow
def test_smoke_run_produces_every_metric_and_figure():
    cfg = dataclasses.replace(SMOKE, maxent=True)  # deviation from the smoke preset: the maximum-entropy baseline too
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
    assert len(res.samples["train.flat.deviation"]) == len(res.samples["train.factorial.deviation"]) == cfg.n_tasks
    assert len(res.samples["transfer.factorial.deviation"]) == cfg.n_test_tasks
    assert res.metrics["train.flat.deviation"] == pytest.approx(np.mean(res.samples["train.flat.deviation"]))
    assert len(res.samples["tasks_curve.min_tasks.factorial.deviation"]) == min(cfg.tasks_curve)
