"""The ch4-inverse-control experiment: demonstrations (discrete or continuous-time) observed through a noisy sensor."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmconcepts.experiments import RunContext
from mmconcepts.experiments.ch4_inverse_control import (Config, _matched_error, compute, make_data, mixing_error, run,
                                                         streams)
from mmconcepts.tasks import FactorialInverseControl, RBFFeatures

TINY = dataclasses.replace(Config.quick(), n_train=30, n_test=6, n_steps=30, max_iter=3,
                           n_repeats=1, sensitivity=False)


def test_quick_preset_keeps_the_thesis_setup():
    q = Config.quick()
    assert (q.grid_size, q.n_primitives, q.n_train) == (5, 6, 200)
    assert 0 < q.sensor_noise <= 1e-3
    assert q.dynamics == Config.full().dynamics == "euler" and q.n_repeats >= 3


def test_matched_error_ignores_order_and_scale(rng):
    D = rng.standard_normal((4, 25))
    learnt = D[[2, 0, 3, 1]] * np.array([[3.0], [-0.5], [2.0], [10.0]])
    assert _matched_error(learnt, D) < 1e-6  # sqrt of a cancellation: ~1e-8 at best
    assert _matched_error(rng.standard_normal((4, 25)), D) > 0.5


def test_mixing_error_is_zero_exactly_for_an_invertible_mixing(rng):
    D = rng.standard_normal((6, 25))
    M = rng.standard_normal((6, 6))  # invertible with probability one
    assert np.linalg.cond(M) < 1e4
    assert mixing_error(M @ D, D) < 1e-10
    assert mixing_error(D, M @ D) < 1e-10
    assert _matched_error(M @ D, D) > 0.3  # a mixing is not a reordering: the matched error cannot see this
    assert mixing_error(rng.standard_normal((6, 25)), D) > 0.5  # a random span
    deficient = D.copy()
    deficient[5] = deficient[:5].sum(0)  # in the true span, but rank 5: one primitive is lost
    assert mixing_error(deficient, D) > 0.1
    extra = D.copy()
    extra[5] = rng.standard_normal(25)  # one atom outside the true span
    assert mixing_error(extra, D) > 0.1


def _data(cfg, rep=0):
    ss = streams(cfg)[rep]
    return make_data(cfg, ss["data"], ss["sensor"], RBFFeatures(cfg.grid_size))


def _state(seed_seq):
    return seed_seq.generate_state(4).tolist()


def test_learner_seed_alone_leaves_the_data_unchanged():
    other = dataclasses.replace(TINY, learner_seed=12345)
    a, b = _data(TINY), _data(other)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert _state(streams(TINY)[0]["learner"]) != _state(streams(other)[0]["learner"])


def test_data_seed_alone_leaves_the_learner_unchanged():
    one, two = dataclasses.replace(TINY, seed=1, learner_seed=7), dataclasses.replace(TINY, seed=2, learner_seed=7)
    assert not np.array_equal(_data(one)["D"], _data(two)["D"])
    assert not np.array_equal(_data(one)["obs_tr"], _data(two)["obs_tr"])
    assert _state(streams(one)[0]["learner"]) == _state(streams(two)[0]["learner"])


def test_no_stream_is_shared_and_repetitions_differ():
    cfg = dataclasses.replace(TINY, n_repeats=2)
    ss = streams(cfg)
    states = [_state(s[k]) for s in ss for k in ("data", "sensor", "learner")]
    assert len({tuple(x) for x in states}) == len(states)
    assert not np.array_equal(_data(cfg, 0)["D"], _data(cfg, 1)["D"])


def test_learner_children_do_not_depend_on_what_was_spawned_before():
    from mmconcepts.experiments.ch4_inverse_control import _children

    seq = streams(TINY)[0]["learner"]
    first = [_state(c) for c in _children(seq, 3)]
    seq.spawn(5)  # spawn is stateful; a job run after another in the same process must not see other streams
    assert [_state(c) for c in _children(seq, 3)] == first


def test_same_config_same_numbers_with_one_or_two_workers():
    cfg = dataclasses.replace(TINY, n_repeats=2)
    a = compute(cfg, RunContext(show_progress=False, workers=1)).metrics
    b = compute(cfg, RunContext(show_progress=False, workers=2)).metrics
    assert a == b


def test_learners_do_not_start_at_the_true_dictionary():
    # regression: the true dictionary and the learners' initial one used to be the same draw of default_rng(seed)
    res = compute(dataclasses.replace(TINY, supervised_max_iter=1, sensor_noise=0.0), RunContext(show_progress=False))
    m = res.metrics
    assert m["supervised.initial_dictionary_rel_error"] > 0.5
    assert m["unsupervised.initial_dictionary_mixing_rel_error"] > 0.5
    assert m["supervised_noise_free.dictionary_rel_error"] > 0.1  # one gradient step from a random start
    assert m["supervised_noise_free.train.rel_l2"] > 1e-3
    # the same comparison at the level of the learner: its seed-derived initial dictionary is not the truth
    D = _data(TINY)["D"]
    learner = FactorialInverseControl(6, features=RBFFeatures(5), max_iter=1, random_state=TINY.seed)
    learner.fit(list(_data(TINY)["obs_tr"][:3]), np.ones((3, 6)))
    assert np.linalg.norm(learner.init_components_ - D) > 0.5 * np.linalg.norm(D)


def test_changing_the_learner_seed_changes_only_the_learners():
    ctx = RunContext(show_progress=False)
    a = compute(TINY, ctx).metrics
    b = compute(dataclasses.replace(TINY, learner_seed=99), ctx).metrics
    for name in ("flat.train.rel_l2", "flat.test.rel_l2", "flat.new_start.rel_l2"):  # data only: no learner seed
        assert a[name] == b[name]
    assert a["supervised.initial_dictionary_rel_error"] != b["supervised.initial_dictionary_rel_error"]
    assert a["unsupervised.dictionary_mixing_rel_error"] != b["unsupervised.dictionary_mixing_rel_error"]


def test_repetitions_give_samples():
    res = compute(dataclasses.replace(TINY, n_repeats=2), RunContext(show_progress=False))
    res.validate()
    assert len(res.samples["supervised.train.rel_l2"]) == 2
    assert res.metrics["supervised.train.rel_l2"] == pytest.approx(np.mean(res.samples["supervised.train.rel_l2"]))


@pytest.mark.slow
@pytest.mark.parametrize("dynamics", ["euler", "ode"])
def test_small_run(dynamics):
    cfg = dataclasses.replace(Config.quick(), n_train=40, n_test=10, n_steps=50, max_iter=20, n_repeats=1,
                              sensitivity=False, dynamics=dynamics)
    res = run(cfg, RunContext(show_progress=False))
    res.validate()
    m = res.metrics
    for name in ("flat", "supervised", "unsupervised"):
        for split in ("train", "test", "new_start"):
            assert np.isfinite(m[f"{name}.{split}.rel_l2"]) and m[f"{name}.{split}.rel_l2"] >= 0
    if dynamics == "euler":
        # the regression inverts the discrete agent exactly: only the sensor noise is left
        assert m["supervised_noise_free.train.rel_l2"] < 1e-5
        assert 1e-6 < m["supervised.train.rel_l2"] < 0.05
    else:
        # continuous-time data: the discrete regression is no longer exact
        assert 1e-4 < m["supervised_noise_free.train.rel_l2"] < 0.2
        assert 1e-6 < m["supervised.train.rel_l2"] < 0.2
    assert set(res.figures) == {"fig4_1_dictionaries", "fig4_3_trajectories"}
    if dynamics == "euler":
        assert 1e-6 < m["supervised.dictionary_rel_error"] < 0.5
        noisier = compute(dataclasses.replace(cfg, sensor_noise=1e-2), RunContext(show_progress=False)).metrics
        assert noisier["supervised.dictionary_rel_error"] > m["supervised.dictionary_rel_error"]  # noise reaches it


@pytest.mark.slow
def test_sensitivity_table_has_stable_names():
    cfg = dataclasses.replace(TINY, sensitivity=True)
    res = compute(cfg, RunContext(show_progress=False))
    rows = res.tables["sensitivity"].rows
    assert len(rows) == 7 and rows[0][:2] == ["euler", 1e-4]  # the default first
    for label in ("euler.noise_1e_4", "euler.noise_0", "ode.noise_1e_3", "euler.noise_1e_4.steepest_200"):
        assert np.isfinite(res.metrics[f"sensitivity.{label}.supervised.train.rel_l2"])
    # without sensor noise the discrete regression inverts the Euler agent exactly, not the continuous one
    euler, ode = (res.metrics[f"sensitivity.{d}.noise_0.supervised.train.rel_l2"] for d in ("euler", "ode"))
    assert euler < 1e-4 and ode > 30 * euler


def test_unknown_dynamics_is_refused():
    with pytest.raises(ValueError, match="dynamics"):
        compute(dataclasses.replace(Config.quick(), dynamics="rk4"), RunContext(show_progress=False))
