"""ch7-online: the online multimodal learner along a stream.

Small configs on generated data (the tiny synthetic corpus) and on a small real subset (skips
without the real sets); the building blocks against outside answers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import mutual_info_score

from conftest import real_data_path

import mmconcepts.experiments.ch7.online as ch7  # importing registers ch7-online
from mmconcepts.experiments import RunContext
from mmconcepts.engine.splits import concept_parts

def _check_result(res, n_folds):
    from mmconcepts.engine.rules import parse_rule
    from mmconcepts.engine.evidence import claim_verdict

    res.validate()
    m = res.metrics
    assert m["chance"] == pytest.approx(0.1)
    for learner in ("online", "batch"):
        for name in ("success", "sound2motion", "motion2sound"):
            assert 0.0 <= m[f"{learner}.{name}.last"] <= 1.0
        assert m[f"{learner}.success.last"] == pytest.approx(
            (m[f"{learner}.sound2motion.last"] + m[f"{learner}.motion2sound.last"]) / 2)
    # the online learner's state is the same size at every point; the batch learner's kept data grows
    assert m["online.memory_mb.first"] == pytest.approx(m["online.memory_mb.last"])
    assert m["batch.memory_mb.last"] > m["batch.memory_mb.first"]
    assert m["online.time.last"] >= m["online.time.first"] > 0
    # the matched information never exceeds its ceiling (the concept indicators' entropy)
    for learner in ("online", "batch"):
        assert all(a <= c + 1e-12 for a, c in zip(res.samples[f"{learner}.mi.last"],
                                                   res.samples[f"{learner}.mi_ceiling.last"]))
    # every sampled metric is a fold of one cross-validation; the split is grouped by recording
    assert set(res.sample_units) == set(res.samples) and set(res.sample_units.values()) == {"folds"}
    unit = res.units["folds"]
    assert unit.kind == "resampled" and unit.test_train_ratio == pytest.approx(1 / (n_folds - 1))
    assert res.split_groups["folds"]["shared_sources"] == 0 and res.split_groups["folds"]["n_folds"] == n_folds
    for claim in ch7.EXPERIMENT.claims:  # decided on the folds (corrected resampled t): too few folds here
        for name in set(parse_rule(claim.rule).metrics) - {"chance"}:
            assert len(res.samples[name]) == n_folds
        v = claim_verdict(claim.rule, m, res.samples, units=res.sample_units, unit_kinds=res.units)
        assert v.verdict == "inconclusive"
        assert "corrected resampled t" in v.basis


@pytest.mark.slow
def test_ch7_online_smoke_generated(tiny_speech_corpus, tmp_path):
    ctx = RunContext(data={"audio": tiny_speech_corpus}, cache_dir=tmp_path, show_progress=False)
    cfg = ch7.Config.smoke()
    res = ch7.compute(cfg, ctx)
    _check_result(res, cfg.n_folds)
    assert "stream" in ch7.present(res, cfg)
    assert len(res.tables["stream"].rows) == len(cfg.points)


@pytest.mark.slow
def test_ch7_online_smoke_real(tmp_path):
    ctx = RunContext(data={"fsdd": real_data_path("fsdd"), "msr-action3d": real_data_path("msr-action3d")},
                     cache_dir=tmp_path, show_progress=False)
    cfg = ch7.Config.smoke()
    res = ch7.compute(cfg, ctx)
    _check_result(res, cfg.n_folds)
    assert any("FSDD" in n for n in res.notes)


def test_stream_segments_end_at_every_point():
    segs = ch7._segments(23, [3, 10, 23], 4)
    assert [(s.start, s.stop) for s in segs] == [(0, 3), (3, 7), (7, 10), (10, 14), (14, 18), (18, 22), (22, 23)]


def test_matched_information_is_the_kuhn_munkres_mean_of_sklearns_mutual_information():
    """Outside answer: scikit-learn's mutual_info_score per (concept indicator, binned coefficient), brute-force
    best assignment over all permutations (3 concepts, 4 coefficients)."""
    import itertools

    rng = np.random.default_rng(0)
    y = rng.integers(0, 3, 90)
    W = rng.random((90, 4))
    W[:, 2] += 2.0 * (y == 1)
    W[:, 0] += 1.0 * (y == 2)
    mi = np.zeros((3, 4))
    for c in range(3):
        for j in range(4):
            edges = np.linspace(W[:, j].min(), W[:, j].max(), 11)[1:-1]
            mi[c, j] = mutual_info_score(y == c, np.digitize(W[:, j], edges)) / np.log(2)
    best = max(np.mean([mi[c, p[c]] for c in range(3)]) for p in itertools.permutations(range(4), 3))
    assert ch7.matched_information(y, W, 10) == pytest.approx(best, rel=1e-9)


def test_crossmodal_success_is_one_on_separable_representations_and_near_chance_on_noise():
    from mmconcepts.multimodal import MultimodalNMF

    rng = np.random.default_rng(1)
    y = np.repeat(np.arange(5), 20)
    P = rng.random((5, 30)) ** 6
    Q = rng.random((5, 8)) ** 6
    X = {"sound": P[y] + 1e-3, "motion": Q[y] + 1e-3}
    model = MultimodalNMF(5, max_iter=100, random_state=0).fit(X)
    assert ch7.crossmodal_success(model, X, y, random_state=0)["mean"] > 0.95
    noise = {"sound": rng.random((100, 30)), "motion": rng.random((100, 8))}
    low = MultimodalNMF(5, max_iter=30, random_state=0).fit(noise)
    assert ch7.crossmodal_success(low, noise, y, random_state=0)["mean"] < 0.45


def test_information_ceiling_is_the_mean_indicator_entropy_and_bounds_the_matched_information():
    from scipy.stats import entropy

    rng = np.random.default_rng(2)
    y = rng.integers(0, 4, 80)
    expected = np.mean([entropy([np.mean(y == c), 1 - np.mean(y == c)], base=2) for c in np.unique(y)])
    assert ch7.information_ceiling(y) == pytest.approx(expected, rel=1e-12)
    W = np.zeros((80, 6))
    W[np.arange(80), y] = 1.0  # coefficient c is concept c's indicator: the matched information is the ceiling
    assert ch7.matched_information(y, W, 10) == pytest.approx(ch7.information_ceiling(y), rel=1e-9)
    assert ch7.matched_information(y, rng.random((80, 6)), 10) < ch7.information_ceiling(y)


def test_claims_are_ours_and_ask_for_the_fair_bar():
    from mmconcepts.experiments.ch7 import protocol as common

    claims = ch7.EXPERIMENT.claims
    assert {c.kind for c in claims} == {"ours"} and len(claims) == 5
    assert all(c.source.endswith("(lines 6082-6085)") for c in claims if c.source)
    rules = [c.rule for c in claims]
    assert "online.success.last > chance + 0.2 * (1 - chance)" in rules
    assert ("online.mi.last > online.mi_shuffled.last + 0.2 * (online.mi_ceiling.last - online.mi_shuffled.last)"
            in rules)
    assert f"abs(online.success.last - batch.success.last) < {ch7.EQUIVALENCE_MARGIN}" in rules
    assert common.FAIR_AGREEMENT == 0.2


@settings(max_examples=50, deadline=None)
@given(n_folds=st.integers(2, 5), per_concept=st.integers(5, 12), n_records=st.integers(5, 12),
       seed=st.integers(0, 2**31 - 1))
def test_property_streams_and_test_folds_share_no_recording(n_folds, per_concept, n_records, seed):
    """Pairs made as load_pairs makes them (utterances and records split by concept, paired within their fold):
    the stream of every fold (its training pairs) and its test pairs share no utterance and no motion record."""
    from mmconcepts.experiments.ch6 import protocol as c6

    rng = np.random.default_rng(seed)
    y = rng.permutation(np.repeat(np.arange(4), per_concept))
    item = rng.permutation(np.repeat(np.arange(4), n_records))
    fold_y, fold_m = concept_parts(y, n_folds, rng), concept_parts(item, n_folds, rng)
    motion_idx = c6.pair_within_parts(y, fold_y, item, fold_m, rng, "motion record")
    sources = c6.example_sources(sound=[f"u{i}" for i in range(len(y))], motion=[f"m{j}" for j in motion_idx])
    data = {"fold": fold_y, "n_folds": n_folds, "y": y, "mfcc": [None] * len(y), "angles": [None] * len(y)}
    tasks = ch7._tasks(data, ch7.Config.quick(), c6.streams(seed))
    assert len(tasks) == n_folds
    for f, t in enumerate(tasks):
        train, test = [sources[i] for i in t["train"]], [sources[i] for i in t["test"]]
        assert len(t["train"]) + len(t["test"]) == len(y) and (fold_y[t["test"]] == f).all()
        assert not set().union(*train) & set().union(*test)
