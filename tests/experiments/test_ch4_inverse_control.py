"""The ch4-inverse-control experiment: demonstrations (discrete or continuous-time) observed through a noisy sensor,
every claim under every setting (dynamics x sensor noise)."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmconcepts.experiments import RunContext, get
from mmconcepts.experiments.ch4.inverse_control import (
    SENSOR,
    SETTINGS,
    SUPERVISED,
    TASKS,
    THESIS,
    UNSUPERVISED,
    Config,
    _matched_error,
    compute,
    make_data,
    mixing_error,
    observe,
    run,
    run_streams,
    setting_label,
)
from mmconcepts.engine.verdicts import decide_claim
from mmconcepts.tasks import FactorialInverseControl, RBFFeatures, control_trajectories, relative_l2_error

SMOKE = Config.smoke()
_SOURCE = re.compile(r"\((?:line \d+|lines \d+(?:-\d+|, \d+))\)\Z")


def test_quick_preset_keeps_the_thesis_setup_and_computes_every_setting():
    q = Config.quick()
    assert (q.grid_size, q.n_primitives, q.n_train) == (5, 6, 200)
    assert q.n_repeats >= 5  # five independent units behind every verdict
    computed = {setting_label(d, n) for d in q.dynamics for n in q.sensor_noises}
    assert computed == {label for label, *_ in SETTINGS} == {"euler.noise_1e_4", "euler.noise_1e_3",
                                                             "ode.noise_1e_4", "ode.noise_1e_3"}
    assert Config.full().dynamics == q.dynamics and Config.full().sensor_noises == q.sensor_noises


def test_setting_labels():
    assert setting_label("euler", 1e-4) == "euler.noise_1e_4"
    assert setting_label("ode", 0.0) == "ode.noise_0"
    assert setting_label("euler", 2.5e-3) == "euler.noise_2_5e_3"  # distinct from 3e-3: no rounding
    assert setting_label("euler", 2.5e-3) != setting_label("euler", 3e-3)


def test_claims_kinds_sources_and_settings():
    exp = get("ch4-inverse-control")
    magnitudes = [c for c in exp.claims if c.kind == "magnitude"]
    # one magnitude per thesis number and setting, each thesis number the reference's value under every setting
    assert sorted(c.rule for c in magnitudes) == sorted(f"{label}.{name}" for label, *_ in SETTINGS for name in THESIS)
    assert exp.reference == {f"{label}.{name}": value for label, *_ in SETTINGS for name, value in THESIS.items()}
    assert THESIS == {"supervised.train.rel_l2": 0.001127, "supervised.test.rel_l2": 0.002675}
    for c in magnitudes:
        assert _SOURCE.search(c.source) and "4.2.2" in c.source
        assert str(THESIS[c.rule.split(".", 2)[2]]) in c.text  # the thesis number is filled into the text
    others = [c for c in exp.claims if c.kind != "magnitude"]
    assert others and all(c.kind == "ours" for c in others)  # section 4.2 states no order: bars and controls are ours
    for c in others:
        assert set(c.settings) == {title for _, title, *_ in SETTINGS}  # every claim under every setting
        for (label, title, *_) in SETTINGS:
            assert all(name.startswith(label + ".") for name in re.findall(r"[a-z_]+\.[a-z0-9_.]+", c.settings[title]))


def test_smoke_run_declares_units_and_split():
    cfg = dataclasses.replace(SMOKE, n_repeats=2)  # deviation from the smoke preset: more than one repetition
    res = compute(cfg, RunContext(show_progress=False))
    res.validate()
    assert set(res.sample_units) == set(res.samples) and set(res.sample_units.values()) == {"repetitions"}
    assert res.units["repetitions"].kind == "independent"
    assert all(len(v) == cfg.n_repeats for v in res.samples.values())
    assert res.metrics["euler.noise_1e_4.supervised.train.rel_l2"] == pytest.approx(
        np.mean(res.samples["euler.noise_1e_4.supervised.train.rel_l2"]))
    split = res.split_groups["demonstrations"]
    assert split["shared_sources"] == 0 and split["n_folds"] == cfg.n_repeats
    assert (split["n_train_examples"], split["n_test_examples"]) == (cfg.n_train, 2 * cfg.n_test)


def test_settings_not_computed_are_not_evaluated():
    # deviation from the smoke preset: one setting computed, Euler with noise 1e-4
    cfg = dataclasses.replace(SMOKE, dynamics=("euler",), sensor_noises=(1e-4,))
    res = compute(cfg, RunContext(show_progress=False))
    exp = get("ch4-inverse-control")
    for claim in exp.claims:
        rec = decide_claim(claim, res.metrics, res.samples, reference=exp.reference, units=res.sample_units,
                           unit_kinds=res.units)
        if claim.kind == "magnitude":  # Euler with noise 1e-4 only
            assert (rec.verdict == "not evaluated") != claim.rule.startswith("euler.noise_1e_4.")
        else:
            per = {s["label"]: s["verdict"] for s in rec.settings}
            assert per.pop("Euler, noise 1e-4") != "not evaluated"
            assert set(per.values()) == {"not evaluated"}


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


def _data(cfg, rep=0, dynamics="euler"):
    st = run_streams(cfg)[rep]
    return make_data(cfg, st.sequence("data", TASKS), st.sequence("data", SENSOR), RBFFeatures(cfg.grid_size), dynamics)


def _state(seed_seq):
    return seed_seq.generate_state(4).tolist()


def test_settings_share_the_draws():
    euler, ode = _data(SMOKE, dynamics="euler"), _data(SMOKE, dynamics="ode")
    for key in ("D", "A_tr", "A_te", "s_tr", "s_te", "s_new", "z_tr", "z_te"):  # the same tasks under both dynamics
        np.testing.assert_array_equal(euler[key], ode[key])
    assert not np.allclose(euler["demo_tr"], ode["demo_tr"])  # only the agent's law differs
    low, high = observe(euler, 1e-4), observe(euler, 1e-3)  # the same demonstrations, the noise scaled
    np.testing.assert_allclose(high[0] - euler["demo_tr"], 10 * (low[0] - euler["demo_tr"]), rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(observe(euler, 0.0)[1], euler["demo_te"])


def test_control_ignores_the_learners_and_the_noise():
    cfg = SMOKE
    assert {1e-4, 1e-3} <= set(cfg.sensor_noises) and "euler" in cfg.dynamics  # the settings read below
    m = compute(cfg, RunContext(show_progress=False)).metrics
    # the average task of the true dictionary: the same under both noise levels, and the same whatever the learners
    assert m["euler.noise_1e_4.mean_task.new_start.rel_l2"] == m["euler.noise_1e_3.mean_task.new_start.rel_l2"]
    other = compute(dataclasses.replace(cfg, learner_seed=99, max_iter=1), RunContext(show_progress=False)).metrics
    assert other["euler.noise_1e_4.mean_task.new_start.rel_l2"] == m["euler.noise_1e_4.mean_task.new_start.rel_l2"]
    assert other["euler.noise_1e_4.unsupervised.new_start.rel_l2"] != m["euler.noise_1e_4.unsupervised.new_start.rel_l2"]
    # known answer: the demonstrator's own law on the average training task, from the new start points
    d, feats = _data(cfg), RBFFeatures(cfg.grid_size)
    imitated = control_trajectories(feats, np.tile(d["A_tr"].mean(0) @ d["D"], (cfg.n_test, 1)), d["s_new"],
                                    n_steps=cfg.n_steps, lam=cfg.lam, dt=cfg.dt, method="euler")
    assert m["euler.noise_1e_4.mean_task.new_start.rel_l2"] == pytest.approx(
        np.mean(relative_l2_error(d["demo_new"], imitated)), rel=1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_train=st.integers(2, 12), n_test=st.integers(1, 6))
def test_test_tasks_are_new_tasks(seed, n_train, n_test):
    """No test task is a training task: its mixture and its start points are drawn apart from every training one."""
    cfg = dataclasses.replace(SMOKE, seed=seed, n_train=n_train, n_test=n_test, n_steps=3)
    d = _data(cfg)
    for A_te, s in ((d["A_te"], d["s_te"]), (d["A_te"], d["s_new"])):
        same_task = (np.abs(A_te[:, None, :] - d["A_tr"][None, :, :]).max(-1) == 0)
        same_start = (np.abs(s[:, None, :] - d["s_tr"][None, :, :]).max(-1) == 0)
        assert not same_task.any() and not same_start.any()


def test_learner_seed_alone_leaves_the_data_unchanged():
    other = dataclasses.replace(SMOKE, learner_seed=12345)
    a, b = _data(SMOKE), _data(other)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert _state(run_streams(SMOKE)[0].sequence("learner", SUPERVISED)) != \
        _state(run_streams(other)[0].sequence("learner", SUPERVISED))


def test_data_seed_alone_leaves_the_learner_unchanged():
    one, two = dataclasses.replace(SMOKE, seed=1, learner_seed=7), dataclasses.replace(SMOKE, seed=2, learner_seed=7)
    assert not np.array_equal(_data(one)["D"], _data(two)["D"])
    assert not np.array_equal(_data(one)["z_tr"], _data(two)["z_tr"])
    assert _state(run_streams(one)[0].sequence("learner", UNSUPERVISED)) == \
        _state(run_streams(two)[0].sequence("learner", UNSUPERVISED))


def test_no_stream_is_shared_and_repetitions_differ():
    cfg = dataclasses.replace(SMOKE, n_repeats=2)  # deviation from the smoke preset: two repetitions to compare
    ss = run_streams(cfg)
    states = [_state(s.sequence(*k)) for s in ss
              for k in (("data", TASKS), ("data", SENSOR), ("learner", SUPERVISED), ("learner", UNSUPERVISED))]
    assert len({tuple(x) for x in states}) == len(states)
    assert not np.array_equal(_data(cfg, 0)["D"], _data(cfg, 1)["D"])


def test_same_config_same_numbers_with_one_or_two_workers():
    cfg = dataclasses.replace(SMOKE, n_repeats=2)  # deviation from the smoke preset: two repetitions to share out
    a = compute(cfg, RunContext(show_progress=False, workers=1)).metrics
    b = compute(cfg, RunContext(show_progress=False, workers=2)).metrics
    assert a.keys() == b.keys()
    np.testing.assert_equal(a, b)  # NaN (settings not computed) equals NaN


def test_learners_do_not_start_at_the_true_dictionary():
    # regression: the true dictionary and the learners' initial one used to be the same draw of default_rng(seed)
    # deviation from the smoke preset: one gradient step of the supervised learner, and its diagnostics
    res = compute(dataclasses.replace(SMOKE, supervised_max_iter=1, diagnostics=True), RunContext(show_progress=False))
    m = res.metrics
    assert m["supervised.initial_dictionary_rel_error"] > 0.5
    assert m["unsupervised.initial_dictionary_mixing_rel_error"] > 0.5
    assert m["euler.noise_0.supervised.dictionary_rel_error"] > 0.1  # one gradient step from a random start
    assert m["euler.noise_0.supervised.train.rel_l2"] > 1e-3
    # the same comparison at the level of the learner: its seed-derived initial dictionary is not the truth
    D = _data(SMOKE)["D"]
    learner = FactorialInverseControl(6, features=RBFFeatures(5), max_iter=1, random_state=SMOKE.seed)
    learner.fit(list(_data(SMOKE)["demo_tr"][:3]), np.ones((3, 6)))
    assert np.linalg.norm(learner.init_components_ - D) > 0.5 * np.linalg.norm(D)


def test_changing_the_learner_seed_changes_only_the_learners():
    ctx = RunContext(show_progress=False)
    a = compute(SMOKE, ctx).metrics
    b = compute(dataclasses.replace(SMOKE, learner_seed=99), ctx).metrics
    for split in ("train", "test", "new_start"):  # data only: no learner seed
        assert a[f"euler.noise_1e_4.flat.{split}.rel_l2"] == b[f"euler.noise_1e_4.flat.{split}.rel_l2"]
    assert a["supervised.initial_dictionary_rel_error"] != b["supervised.initial_dictionary_rel_error"]
    assert a["euler.noise_1e_4.unsupervised.dictionary_mixing_rel_error"] != \
        b["euler.noise_1e_4.unsupervised.dictionary_mixing_rel_error"]


@pytest.mark.slow
def test_smoke_run_under_both_dynamics():
    # deviation from the smoke preset: a noise far above the other (1e-2), and the diagnostics (noise 0, steepest
    # descent)
    cfg = dataclasses.replace(SMOKE, sensor_noises=(1e-4, 1e-2), diagnostics=True)
    res = run(cfg, RunContext(show_progress=False))
    res.validate()
    m = res.metrics
    for label in ("euler.noise_1e_4", "ode.noise_1e_4"):
        for name in ("supervised", "unsupervised"):
            for split in ("train", "test", "new_start"):
                assert np.isfinite(m[f"{label}.{name}.{split}.rel_l2"]) and m[f"{label}.{name}.{split}.rel_l2"] >= 0
    assert "ode.noise_1e_4.flat.train.rel_l2" not in m  # the flat imitator's costs are not integrable
    # without sensor noise the regression inverts the discrete agent exactly, not the continuous one
    assert m["euler.noise_0.supervised.train.rel_l2"] < 1e-5
    assert 1e-4 < m["ode.noise_0.supervised.train.rel_l2"] < 0.2
    assert 1e-6 < m["euler.noise_1e_4.supervised.train.rel_l2"] < 0.05
    # the sensor noise reaches the dictionary
    assert m["euler.noise_1e_2.supervised.dictionary_rel_error"] > m["euler.noise_1e_4.supervised.dictionary_rel_error"]
    assert np.isfinite(m["euler.noise_1e_4.steepest_200.supervised.train.rel_l2"])
    assert set(res.figures) == {"fig4_1_dictionaries", "fig4_3_trajectories"}
    rows = res.tables["supervised"].rows
    assert [r[0] for r in rows][:4] == ["Euler, noise 1e-4", "Euler, noise 1e-2", "ODE, noise 1e-4", "ODE, noise 1e-2"]


def test_unknown_dynamics_is_refused():
    with pytest.raises(ValueError, match="dynamics"):
        compute(dataclasses.replace(SMOKE, dynamics=("rk4",)), RunContext(show_progress=False))
