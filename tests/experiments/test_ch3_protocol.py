"""Shared evaluation code of the chapter-3 experiments: splits never leak test examples."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import real_data_path
from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import RunContext, SampleUnit, describe_split
from mmconcepts.experiments.ch3 import protocol as common
from mmconcepts.motion import ARM_COLUMNS, LEFT_ARM_COLUMNS, RIGHT_ARM_COLUMNS


def _label_sets(rng, n=80, L=10):
    Y = np.zeros((n, L))
    for row in Y:
        row[rng.choice(L, rng.integers(2, 4), replace=False)] = 1
    # repeat a few combinations so that some occur several times
    Y[n // 2:n // 2 + 10] = Y[:10]
    return Y


@pytest.mark.parametrize("n_folds", [None, 3, 10])
def test_kfold_splits_partition_without_leak(n_folds):
    n = 37
    splits = common.kfold_splits(n, n_folds, seed=0)
    tested = np.concatenate([te for _, te in splits])
    assert np.array_equal(np.sort(tested), np.arange(n))  # every example tested exactly once
    for tr, te in splits:
        assert not set(tr) & set(te)
        assert len(tr) + len(te) == n
    if n_folds is None:
        assert len(splits) == n


def test_stratified_single_label_splits(rng):
    y = np.repeat(np.arange(6), 5)
    for _tr, te in common.kfold_splits(len(y), 5, seed=1, y=y):
        assert np.array_equal(np.bincount(y[te], minlength=6), np.ones(6))


@pytest.mark.parametrize("n_folds", [None, 4])
def test_unseen_combination_splits_hold_only_unseen_combinations(rng, n_folds):
    Y = _label_sets(rng)
    groups = common.combination_ids(Y)
    assert len(np.unique(groups)) < len(Y)  # some combinations repeat: the test is not vacuous
    splits = common.unseen_combination_splits(Y, n_folds, seed=0)
    tested = np.concatenate([te for _, te in splits])
    assert np.array_equal(np.sort(tested), np.arange(len(Y)))
    for tr, te in splits:
        train_sets = {tuple(np.flatnonzero(r)) for r in Y[tr]}
        assert all(tuple(np.flatnonzero(r)) not in train_sets for r in Y[te])
        assert not set(tr) & set(te)


def test_combination_ids_ignore_label_order():
    Y = np.array([[1, 1, 0], [1, 1, 0], [0, 1, 1]])
    g = common.combination_ids(Y)
    assert g[0] == g[1] != g[2]


def test_fold_fits_features_on_training_only(rng, tmp_path):
    """Outlying test recordings must not change the fitted grid: their features are the same
    whether the test part holds sane or wild values."""
    angles = [rng.normal(size=(40, 4)) for _ in range(12)]
    Y = np.eye(3)[np.arange(12) % 3]
    train, test = np.arange(9), np.arange(9, 12)
    wild = [a.copy() for a in angles]
    for i in test:
        wild[i] = wild[i] * 50.0
    task = {"Y": Y, "train": train, "test": test, "features": {"data": "angles", "method": "kde", "n_bins": 5},
                "learners": ("chance",), "params": {}, "seed": 0, "single": True}
    a = common._fold(dict(task, angles=angles))
    b = common._fold(dict(task, angles=wild))
    np.testing.assert_array_equal(a["test"], test)
    np.testing.assert_allclose(a["chance"]["scores"], b["chance"]["scores"])


def test_evaluate_folds_caches_and_pools(rng, tmp_path):
    angles = [rng.normal(size=(30, 3)) + (i % 2) for i in range(16)]
    Y = np.eye(2)[np.arange(16) % 2]
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    splits = common.kfold_splits(16, 4, seed=0)
    params = {"n_components": 4, "max_iter": 30, "inner_cv": 2}
    feats = {"data": "joint", "method": "kde", "n_bins": 9, "delay": 1}
    f1 = common.evaluate_folds(ctx, angles, Y, splits, features=feats, learners=("nmf_frobenius",), params=params,
                               streams=common.streams(0), single=True)
    assert len(list((tmp_path / "ch3-folds").rglob("*.npz"))) == 4
    f2 = common.evaluate_folds(ctx, angles, Y, splits, features=feats, learners=("nmf_frobenius",), params=params,
                               streams=common.streams(0), single=True)
    np.testing.assert_array_equal(f1[0]["nmf_frobenius"]["scores"], f2[0]["nmf_frobenius"]["scores"])
    score = common.pooled_scores(f1, Y, "nmf_frobenius", single=True)["l_single"]
    assert score > 0.75  # two well separated classes


def test_an_interrupted_evaluation_keeps_the_folds_it_finished(rng, tmp_path, monkeypatch):
    """Each fold is cached as it ends: a run stopped at the third fold resumes from there."""
    angles = [rng.normal(size=(20, 3)) + (i % 2) for i in range(12)]
    Y = np.eye(2)[np.arange(12) % 2]
    splits = common.kfold_splits(12, 4, seed=0)
    args = dict(features={"data": "joint", "method": "kde", "n_bins": 5, "delay": 1}, learners=("chance",),
                params={}, streams=common.streams(0), single=True)
    real_hist, calls = common._histograms, []

    def stop_at_third(task):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real_hist(task)

    monkeypatch.setattr(common, "_histograms", stop_at_third)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    with pytest.raises(KeyboardInterrupt):
        common.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(list((tmp_path / "ch3-folds").rglob("*.npz"))) == 2
    calls.clear()
    monkeypatch.setattr(common, "_histograms", lambda task: (calls.append(1), real_hist(task))[1])
    resumed = common.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 2 and len(resumed) == 4
    fresh = common.evaluate_folds(RunContext(workers=1, cache_dir=tmp_path / "b", show_progress=False), angles, Y,
                                  splits, **args)
    for a, b in zip(resumed, fresh):
        np.testing.assert_array_equal(a["chance"]["scores"], b["chance"]["scores"])


# --------------------------------------------------------------------------- real data: MSR Action3D subsets
def test_data_priority_choreo1_then_msr_then_synthetic(tmp_path):
    assert common.data_kind(RunContext(cache_dir=tmp_path)) == "synthetic"
    assert common.data_kind(RunContext(cache_dir=tmp_path, data={"msr-action3d": tmp_path})) == "msr-action3d"
    both = {"msr-action3d": tmp_path, "choreo1": tmp_path}
    assert common.data_kind(RunContext(cache_dir=tmp_path, data=both)) == "choreo1"


def test_msr_mixtures_join_the_limbs_of_their_sources():
    folder = real_data_path("msr-action3d")
    prim = common.msr_subset(folder, "primitive", streams=common.streams(0))
    actions = np.array(prim.label_ids)[np.argmax(prim.Y, axis=1)]
    part = common.msr_subset(folder, "mixed_partial", streams=common.streams(0))
    full = common.msr_subset(folder, "mixed_full", streams=common.streams(0))
    assert part.Y.shape[1] == 18 and full.Y.shape[1] == 33
    assert np.all(part.Y.sum(axis=1) == 2) and np.all(full.Y.sum(axis=1) == 3)
    legs = [c for c in range(16) if c not in ARM_COLUMNS]
    for r in range(0, len(part.Y), 37):
        i, j = part.info["sources"][r]
        assert actions[i] in common.MSR_ARM_ACTIONS and actions[j] in common.MSR_LEG_ACTIONS
        x = part.angles[r]
        np.testing.assert_array_equal(x[:, ARM_COLUMNS], prim.angles[i][:len(x), ARM_COLUMNS])
        np.testing.assert_array_equal(x[:, legs], prim.angles[j][:len(x), legs])
        assert set(np.array(part.label_ids)[part.Y[r] > 0]) == {actions[i], actions[j]}
    for r in range(0, len(full.Y), 37):
        i, k, j = full.info["sources"][r]
        assert actions[i] != actions[k]
        x = full.angles[r]
        np.testing.assert_array_equal(x[:, RIGHT_ARM_COLUMNS], prim.angles[i][:len(x), RIGHT_ARM_COLUMNS])
        np.testing.assert_array_equal(x[:, LEFT_ARM_COLUMNS], prim.angles[k][:len(x), RIGHT_ARM_COLUMNS])
        assert set(np.array(full.label_ids)[full.Y[r] > 0]) == {actions[i], 100 + actions[k], actions[j]}
    # most large-set combinations are unique (as the thesis' Fig. 3.8), the small set's repeat
    assert len(np.unique(common.combination_ids(full.Y))) > len(full.Y) / 2
    assert len(np.unique(common.combination_ids(part.Y))) <= 45


def test_msr_subsets_use_whatever_subjects_are_given(tmp_path):
    """No subject id is built in: a folder holding two subjects renamed to s41 and s77 works."""
    folder = real_data_path("msr-action3d")
    subjects = sorted({p.name.split("_")[1] for p in folder.glob("a*_s*_e*_skeleton3D.txt")})[:2]
    for new, old in zip(("s41", "s77"), subjects):
        for p in folder.glob(f"a*_{old}_e*_skeleton3D.txt"):
            (tmp_path / p.name.replace(f"_{old}_", f"_{new}_")).symlink_to(p)
    for subset in ("primitive", "mixed_partial", "mixed_full"):
        a = common.msr_subset(tmp_path, subset, streams=common.streams(0))
        assert a.info["n_subjects"] == 2 and len(a.Y) > 20
    again = common.msr_subset(tmp_path, "mixed_full", streams=common.streams(0))
    other = common.msr_subset(tmp_path, "mixed_full", streams=common.streams(1))
    assert again.info["sources"] == \
        common.msr_subset(tmp_path, "mixed_full", streams=common.streams(0)).info["sources"]
    assert again.info["sources"] != other.info["sources"]  # the pairing is drawn from the data stream


def test_fold_cache_key_follows_the_code_fingerprint(rng, tmp_path, monkeypatch):
    """A change of code (another fingerprint) recomputes the folds instead of reusing them."""
    angles = [rng.normal(size=(20, 3)) for _ in range(8)]
    Y = np.eye(2)[np.arange(8) % 2]
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    args = dict(features={"data": "angles", "method": "kde", "n_bins": 4}, learners=("chance",), params={}, streams=common.streams(0),
                single=True)
    common.evaluate_folds(ctx, angles, Y, common.kfold_splits(8, 2, 0), **args)
    assert len(list((tmp_path / "ch3-folds").rglob("*.npz"))) == 2
    monkeypatch.setattr(common, "code_fingerprint", lambda: "0123456789abcdef")
    common.evaluate_folds(ctx, angles, Y, common.kfold_splits(8, 2, 0), **args)
    assert len(list((tmp_path / "ch3-folds").rglob("*.npz"))) == 4


def test_msr_corrupt_file_is_skipped_and_named(tmp_path):
    """A corrupt skeleton file among good ones: the rest loads and the data note names the file left out."""
    folder = real_data_path("msr-action3d")
    for p in sorted(folder.glob("a*_s0[12]_e01_skeleton3D.txt")):
        (tmp_path / p.name).symlink_to(p)
    (tmp_path / "a01_s01_e03_skeleton3D.txt").write_text("1 2 3\nnot numbers\n")
    a = common.msr_subset(tmp_path, "primitive", streams=common.streams(0))
    assert len(a.Y) == len(list(folder.glob("a*_s0[12]_e01_skeleton3D.txt")))
    assert "a01_s01_e03" in a.description and "a01_s01_e03" in a.info["skipped"]
    ctx = RunContext(cache_dir=tmp_path, data={"msr-action3d": tmp_path})
    assert "a01_s01_e03" in common.data_source_note(ctx, a)


# --------------------------------------------------------------------------- units of per-fold statistics
def _fake_folds(splits):
    return [{"test": np.asarray(te)} for _, te in splits]


def test_score_units_are_the_fold_test_sets_with_k_folds():
    folds = _fake_folds(common.kfold_splits(37, 4, seed=0))
    units = common.score_units(folds, seed=5)
    assert len(units) == 4
    for u, f in zip(units, folds):
        np.testing.assert_array_equal(u, f["test"])


def test_score_units_cut_leave_one_out_into_blocks_from_the_seed():
    folds = _fake_folds(common.kfold_splits(37, None, seed=0))
    units = common.score_units(folds, seed=5)
    assert len(units) == common.N_BLOCKS == 10
    assert sorted(len(u) for u in units) == [3] * 3 + [4] * 7  # numpy.array_split of 37 into 10
    np.testing.assert_array_equal(np.sort(np.concatenate(units)), np.arange(37))  # a partition
    expected = np.random.default_rng(5).permutation(37)  # the splits stream draws the blocks
    for u, block in zip(units, np.array_split(expected, 10)):
        np.testing.assert_array_equal(u, np.sort(block))
    other = common.score_units(folds, seed=6)
    assert any(not np.array_equal(a, b) for a, b in zip(units, other))


def test_fold_thresholds_in_fold_order():
    folds = [{"test": np.array([i]), "nmf_frobenius": {"threshold": t}} for i, t in enumerate((0.3, 0.45, 0.2))]
    assert common.fold_thresholds(folds, "nmf_frobenius") == [0.3, 0.45, 0.2]


# --------------------------------------------------------------------------- splits grouped by source recording
_ACTIONS = common.MSR_ARM_ACTIONS + common.MSR_LEG_ACTIONS + (13, 20)  # 13, 20: used by no mixture


@st.composite
def _recordings(draw):
    """A table of recordings (action, subject) as MSR Action3D's, of any size and with any gaps."""
    n_subjects = draw(st.integers(1, 4))
    actions, subjects = [], []
    for s in range(n_subjects):
        for a in draw(st.lists(st.sampled_from(_ACTIONS), min_size=0, max_size=30)):
            actions.append(a)
            subjects.append(s + 1)
    return np.array(actions, dtype=np.int64), np.array(subjects, dtype=np.int64)


def _check_plan(actions, subjects, subset, sources, labels, parts, n_parts, split_seed):
    rec_part = common.source_parts(actions, subjects, n_parts, split_seed)
    assert len(sources) == len(labels) == len(parts)
    for src, lab, p in zip(sources, labels, parts):
        assert {int(rec_part[r]) for r in src} == {int(p)}  # every recording of a mixture is in the mixture's part
        assert len({int(subjects[r]) for r in src}) == 1  # one subject per mixture
        assert actions[src[0]] in common.MSR_ARM_ACTIONS and actions[src[-1]] in common.MSR_LEG_ACTIONS
        want = [int(actions[src[0]])] + ([common.LEFT_ARM_OFFSET + int(actions[src[1]])] if len(src) == 3 else []) \
            + [int(actions[src[-1]])]
        assert list(lab) == want
        if subset == "mixed_full":
            assert len(src) == 3 and actions[src[1]] in common.MSR_ARM_ACTIONS and actions[src[1]] != actions[src[0]]
        else:
            assert len(src) == 2


@settings(max_examples=80, deadline=None)
@given(_recordings(), st.sampled_from(["mixed_partial", "mixed_full"]), st.integers(2, 8), st.integers(0, 2**31 - 2),
       st.booleans())
def test_msr_mixture_folds_never_put_a_recording_on_both_sides(recs, subset, n_parts, seed, unseen):
    """Mixtures built per part of their recordings, split by part (and without the test part's combinations for
    unseen ones): no recording behind a test mixture is behind a training mixture."""
    actions, subjects = recs
    streams = common.streams(seed)
    sources, labels, parts = common.msr_mixture_plan(actions, subjects, subset, n_parts=n_parts, streams=streams)
    _check_plan(actions, subjects, subset, sources, labels, parts, n_parts, streams.seed_for("splits"))
    if len(sources) < 2:
        return
    ids = sorted({l for ls in labels for l in ls})
    Y = np.zeros((len(labels), len(ids)))
    for r, ls in enumerate(labels):
        Y[r, [ids.index(l) for l in ls]] = 1
    arrays = common.MotionArrays([np.zeros((2, 16))] * len(Y), Y, ids, "msr-action3d", "", sources=sources,
                                 parts=parts)
    splits = common.example_splits(arrays, 3, seed=0, unseen=unseen)
    if not splits:
        return
    folds = common.split_sources(arrays, splits)
    for tr, te in folds:
        assert not {r for s in tr for r in s} & {r for s in te for r in s}
    assert describe_split("recordings", folds)["shared_sources"] == 0
    combos = common.combination_ids(Y)
    tested = np.concatenate([te for _, te in splits])
    assert len(tested) == len(set(tested.tolist()))  # each mixture tested at most once
    for tr, te in splits:
        assert len(set(parts[te].tolist())) == 1
        if unseen:
            assert not set(combos[te].tolist()) & set(combos[tr].tolist())


def test_source_parts_spread_each_subject_over_the_parts():
    rng = np.random.default_rng(0)
    actions = np.array([a for s in range(3) for a in rng.permutation(
        np.repeat(common.MSR_ARM_ACTIONS + common.MSR_LEG_ACTIONS, 3))])
    subjects = np.repeat([1, 2, 3], 3 * 18)
    part = common.source_parts(actions, subjects, 5, seed=3)
    assert (part >= 0).all()
    for s in (1, 2, 3):
        legs = part[(subjects == s) & np.isin(actions, common.MSR_LEG_ACTIONS)]
        assert sorted(np.bincount(legs, minlength=5)) == [1, 2, 2, 2, 2]  # 9 legs dealt round robin
        arms = part[(subjects == s) & np.isin(actions, common.MSR_ARM_ACTIONS)]
        assert np.bincount(arms, minlength=5).min() == 9  # 45 arm recordings, 9 per part
        for a in common.MSR_ARM_ACTIONS:  # one action's recordings of a subject in different parts
            assert len(set(part[(subjects == s) & (actions == a)].tolist())) == 3
    assert not np.array_equal(part, common.source_parts(actions, subjects, 5, seed=4))  # drawn from the seed
    # a subject with fewer leg recordings than parts deals its arms only over the parts that have its legs
    few = common.source_parts(np.array([14, 15, 1, 1, 2, 2, 3]), np.ones(7, int), 6, seed=0)
    assert set(few[2:].tolist()) <= set(few[:2].tolist())


@settings(max_examples=60, deadline=None)
@given(st.integers(4, 60), st.integers(2, 12), st.integers(0, 1000), st.booleans(), st.booleans())
def test_independent_recordings_folds_keep_every_example_on_one_side(n, n_folds, seed, unseen, loo):
    """Synthetic / Choreo1 / MSR single sequences are each their own recording: k-fold, leave-one-out and the
    unseen-combination splits never put an example (its recording) on both sides, and unseen test combinations
    are absent from training."""
    rng = np.random.default_rng(seed)
    Y = np.zeros((n, 6))
    for row in Y:
        row[rng.choice(6, rng.integers(1, 3), replace=False)] = 1
    arrays = common.MotionArrays([np.zeros((2, 16))] * n, Y, list(range(6)), "synthetic", "")
    splits = common.example_splits(arrays, None if loo else min(n_folds, n), seed, unseen=unseen)
    if not splits:  # a single label combination: no unseen-combination split exists
        assert unseen and len(set(common.combination_ids(Y).tolist())) == 1
        return
    groups = common.split_groups(arrays, splits)
    assert groups["shared_sources"] == 0 and "independent draw" in groups["by"]
    tested = np.sort(np.concatenate([te for _, te in splits]))
    np.testing.assert_array_equal(tested, np.arange(n))  # every example tested once
    combos = common.combination_ids(Y)
    for tr, te in splits:
        assert not set(tr.tolist()) & set(te.tolist())
        if unseen:
            assert not set(combos[te].tolist()) & set(combos[tr].tolist())


def test_split_groups_raise_on_a_shared_recording():
    Y = np.eye(2)[[0, 1, 0, 1]]
    arrays = common.MotionArrays([np.zeros((2, 16))] * 4, Y, [0, 1], "msr-action3d", "",
                                 sources=[(0, 9), (1, 8), (2, 9), (3, 7)], parts=np.array([0, 0, 1, 1]))
    with pytest.raises(ExperimentError, match="recording"):  # recording 9 is behind a mixture of each part
        common.split_groups(arrays, common.part_splits(arrays.parts))


def test_part_splits_leave_out_the_test_combinations_only_when_asked():
    parts = np.array([0, 0, 1, 1, 2, 2])
    Y = np.eye(3)[[0, 1, 0, 2, 2, 1]]
    plain = common.part_splits(parts)
    assert [te.tolist() for _, te in plain] == [[0, 1], [2, 3], [4, 5]]
    assert [tr.tolist() for tr, _ in plain] == [[2, 3, 4, 5], [0, 1, 4, 5], [0, 1, 2, 3]]
    unseen = common.part_splits(parts, Y)
    assert [tr.tolist() for tr, _ in unseen] == [[3, 4], [1, 5], [0, 2]]


def test_fold_unit_is_k_fold_or_the_measured_ratio():
    unit = common.fold_unit(common.kfold_splits(20, 4, 0), "x")
    assert unit == SampleUnit.folds(4, "4 folds of x")
    loo = common.fold_unit(common.kfold_splits(7, None, 0), "x")
    assert loo.test_train_ratio == pytest.approx(1 / 6)  # leave-one-out over n is folds(n)
    pruned = common.fold_unit(common.part_splits(np.array([0, 0, 1, 1, 2, 2]), np.eye(3)[[0, 1, 0, 2, 2, 1]]), "x")
    assert pruned.kind == "resampled" and pruned.test_train_ratio == pytest.approx(1.0)  # 2 tested, 2 trained


def test_msr_mixtures_in_parts_share_no_recording_across_parts():
    folder = real_data_path("msr-action3d")
    for subset in ("mixed_partial", "mixed_full"):
        a = common.msr_subset(folder, subset, streams=common.streams(0), n_records=150, n_parts=common.MSR_PARTS)
        assert len(np.unique(a.parts)) == common.MSR_PARTS and len(a.Y) == 150
        for unseen in (False, True):
            splits = common.example_splits(a, 10, seed=0, unseen=unseen)
            assert common.split_groups(a, splits)["shared_sources"] == 0
        # the splits stream deals the recordings: another split seed, other parts and other mixtures
        b = common.msr_subset(folder, subset, streams=common.streams(0).rooted("splits", 2), n_records=150,
                              n_parts=common.MSR_PARTS)
        assert a.sources != b.sources
    # without parts the mixtures share recordings across any split by example (why they are built per part)
    c = common.msr_subset(folder, "mixed_partial", streams=common.streams(0))
    assert c.parts is None
    legs = [s[-1] for s in c.sources]
    assert len(set(legs)) < len(legs) / 3  # a leg recording joins several mixtures


@pytest.mark.parametrize(("show_progress", "terminal", "bar"), [(True, True, True), (False, True, False),
                                                                 (True, False, False)])
def test_generated_choreographies_show_progress_in_an_interactive_run(tmp_path, monkeypatch, capsys,
                                                                      show_progress, terminal, bar):
    """The run's ctx.verbose (progress asked for, stderr a terminal) reaches the generator; the data is the same."""
    import sys

    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    ctx = RunContext(cache_dir=tmp_path, show_progress=show_progress)
    assert ctx.verbose is bar
    arrays = common.subset_arrays(ctx, "primitive", streams=common.streams(3), n_records=4)
    assert ("generated primitive" in capsys.readouterr().err) is bar
    again = common.subset_arrays(RunContext(cache_dir=tmp_path / "other", show_progress=False), "primitive",
                                 streams=common.streams(3), n_records=4)
    assert all(np.array_equal(a, b) for a, b in zip(arrays.angles, again.angles))


# ---------------------------------------------------------------------------- fold seeds and shared fits
def test_fold_seeds_leave_one_out_by_example_others_by_index():
    streams = common.streams(0)
    n = 9
    loo = common.kfold_splits(n, None, seed=0)
    assert common.fold_seeds(streams, loo, n) == [streams.seed_for("learner", i) for i in range(n)]
    kfold = common.kfold_splits(n, 3, seed=0)
    assert common.fold_seeds(streams, kfold, n) == [streams.seed_for("learner", i) for i in range(3)]
    # a list mixing folds of one left-out example with others: the former by their example, the latter apart
    mixed = [(np.arange(1, n), np.array([0])), (np.r_[0, 4:n], np.arange(1, 4)), (np.arange(n - 1), np.array([n - 1]))]
    seeds = common.fold_seeds(streams, mixed, n)
    assert seeds == [streams.seed_for("learner", 0), streams.seed_for("learner", 1, 1),
                     streams.seed_for("learner", n - 1)]
    assert len(set(seeds)) == 3
    # a test set of one example that does not train on all the others is not a leave-one-out fold
    partial = [(np.arange(2, n), np.array([0])), (np.arange(3, n), np.array([1]))]
    assert common.fold_seeds(streams, partial, n) == [streams.seed_for("learner", i) for i in range(2)]


def _fold_data(rng, n=14, L=5):
    Y = np.zeros((n, L))
    for row in Y:
        row[rng.choice(L, 2, replace=False)] = 1
    Y[:4] = Y[4:8]  # these combinations shown at least twice
    angles = [rng.normal(size=(25, 3)) + Y[i, :3] for i in range(n)]
    return angles, Y


def test_leave_one_out_and_unseen_combinations_share_the_folds_of_one_example(rng, tmp_path, monkeypatch):
    """Leave-one-combination-out reads the leave-one-out fits of the examples whose combination is theirs
    alone, and computes only its other folds; a learner asked for again is read back, whatever the others."""
    from mmconcepts.experiments import RunContext

    angles, Y = _fold_data(rng)
    n = len(Y)
    ctx = RunContext(cache_dir=tmp_path, show_progress=False)
    args = dict(features={"data": "joint", "method": "kde", "n_bins": 4, "delay": 1},
                params={"n_components": 4, "max_iter": 10, "inner_cv": 2}, streams=common.streams(0))
    fits: list[str] = []
    real = common._learner_result
    monkeypatch.setattr(common, "_learner_result", lambda name, X, task: (fits.append(name), real(name, X, task))[1])
    loo = common.evaluate_folds(ctx, angles, Y, common.kfold_splits(n, None, 0), learners=("nmf_frobenius", "chance"),
                                **args)
    assert len(fits) == 2 * n
    unseen = common.unseen_combination_splits(Y, None, seed=0)
    alone = [int(te[0]) for tr, te in unseen if len(te) == 1]
    assert 0 < len(alone) < len(unseen)  # the test is not vacuous
    fits.clear()
    folds = common.evaluate_folds(ctx, angles, Y, unseen, learners=("nmf_frobenius", "svm"), **args)
    # svm on every fold; NMF only on the folds of several examples
    assert sorted(fits) == sorted(["svm"] * len(unseen) + ["nmf_frobenius"] * (len(unseen) - len(alone)))
    for f in folds:
        if len(f["test"]) == 1:
            j = int(f["test"][0])
            np.testing.assert_array_equal(f["nmf_frobenius"]["scores"], loo[j]["nmf_frobenius"]["scores"])
        assert list(f) == ["test", "nmf_frobenius", "svm"]
    # the same fold computed directly, without the cache: the same numbers
    tr, te = common.kfold_splits(n, None, 0)[alone[0]]
    direct = common._fold({"angles": angles, "Y": Y, "train": tr, "test": te, "features": args["features"],
                           "learners": ("nmf_frobenius",), "params": args["params"], "single": False,
                           "seed": common.streams(0).seed_for("learner", alone[0])})
    np.testing.assert_array_equal(direct["nmf_frobenius"]["scores"], loo[alone[0]]["nmf_frobenius"]["scores"])


def test_nmf_label_sets_are_the_learners_predictions(rng):
    """A fold's NMF label sets are LabelNMF.predict of its test examples (read from the activations)."""
    from mmconcepts.motion import MotionHistograms
    from mmconcepts.nmf import LabelNMF

    angles, Y = _fold_data(rng, n=20)
    train, test = np.arange(14), np.arange(14, 20)
    task = {"angles": angles, "Y": Y, "train": train, "test": test, "learners": ("nmf_kl",),
            "features": {"data": "joint", "method": "kde", "n_bins": 4, "delay": 1},
            "params": {"n_components": 4, "max_iter": 15, "inner_cv": 2}, "seed": 3, "single": False}
    out = common._fold(task)["nmf_kl"]
    X = MotionHistograms(**task["features"], random_state=3).fit([angles[i] for i in train]).transform(angles)
    keep = Y[train].sum(axis=0) > 0
    model = LabelNMF(4, beta_loss=1.0, max_iter=15, cv=2, random_state=3).fit(X[train], Y[train][:, keep])
    pred = model.predict(X[test])
    assert 0 < pred.sum() < pred.size  # some labels above the threshold, some below: not vacuous
    np.testing.assert_array_equal(out["pred"][:, keep], pred)
    assert not out["pred"][:, ~keep].any()
    np.testing.assert_array_equal(out["scores"][:, keep], model.label_activations(X[test]))
