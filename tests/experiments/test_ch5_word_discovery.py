"""ch5-word-discovery: word/atom mutual information (known answers, scikit-learn), the Kuhn-Munkres alignment,
the experiment on a fake FSDD of tones, its streams and bad input, and a reduced run on the real FSDD."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _fake_audio import fake_fsdd
from sklearn.metrics import mutual_info_score

from conftest import real_data_path
from mmconcepts.errors import ParameterError
from mmconcepts.experiments import RunContext, evaluate_rule
from mmconcepts.experiments.ch5 import protocol as common
from mmconcepts.experiments.ch5 import word_discovery as wd


def _entropy(p):
    return -(p * np.log2(p) + (1 - p) * np.log2(1 - p))


def _presence(rng, n=200, n_words=4):
    Y = np.zeros((n, n_words))
    for row in Y:
        row[rng.choice(n_words, int(rng.integers(1, 3)), replace=False)] = 1
    return Y


def test_an_atom_equal_to_a_word_carries_its_whole_entropy(rng):
    Y = _presence(rng)
    W = np.column_stack([rng.random(len(Y)), Y[:, 2], rng.random(len(Y))])
    mi = wd.word_atom_mi(Y, W, n_bins=10)
    assert mi.shape == (4, 3)
    assert mi[2, 1] == pytest.approx(_entropy(Y[:, 2].mean()))
    assert mi[2, 1] == mi.max()


def test_word_atom_mi_matches_scikit_learn(rng):
    Y = _presence(rng, n=150)
    W = rng.gamma(1.0, size=(150, 5)) + 2 * Y[:, [0, 1, 2, 3, 0]]
    mi = wd.word_atom_mi(Y, W, n_bins=7)
    for l in range(4):
        for j in range(5):
            col = W[:, j]
            binned = np.digitize(col, np.linspace(col.min(), col.max(), 8)[1:-1])
            assert mi[l, j] == pytest.approx(mutual_info_score(Y[:, l], binned) / np.log(2), abs=1e-12)


def test_a_word_always_present_carries_no_information(rng):
    Y = _presence(rng, n=50)
    Y[:, 0] = 1
    assert np.all(wd.word_atom_mi(Y, rng.random((50, 3)))[0] == 0)


def test_align_recovers_a_permuted_dictionary_and_the_control_does_not(rng):
    Y = _presence(rng, n=300, n_words=5)
    perm = np.array([3, 0, 4, 1, 2, 5])  # atom j holds word perm[j]; atom 5 is noise
    W = np.column_stack([Y[:, p] if p < 5 else np.zeros(len(Y)) for p in perm]) * rng.uniform(0.5, 1.5, (300, 1))
    W += 0.05 * rng.random(W.shape)
    res = wd.align(Y, W)
    assert dict(zip(res["rows"], res["cols"])) == {int(p): j for j, p in enumerate(perm) if p < 5}
    assert np.all(res["fraction"] > 0.9) and 5 not in res["order"][:5]
    assert [int(perm[j]) for j in res["order"][:5]] == res["word_order"]  # the figure's diagonal: matched pairs
    shuffled = wd.align(Y[rng.permutation(300)], W)
    assert shuffled["matched"].mean() < 0.2 * res["matched"].mean()


# -- the experiment on a fake FSDD (a tone per digit) ---------------------------------------------
_fake_fsdd = fake_fsdd  # tests/_fake_audio.py


@pytest.fixture(scope="module")
def fake_fsdd(tmp_path_factory):
    return _fake_fsdd(tmp_path_factory.mktemp("fsdd") / "fsdd", np.random.default_rng(11))


def test_ch5_word_discovery_smoke_on_tones(fake_fsdd, tmp_path):
    cfg = wd.Config.smoke()
    res = wd.compute(cfg, RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False))
    res.validate()
    m = res.metrics
    assert m["n_utterances"] == cfg.n_utterances and m["n_words"] == 10 and m["n_atoms"] == 10
    n = cfg.n_repeats
    for name in wd.REPEATED:
        assert len(res.samples[name]) == n, name
    # disjoint parts of the data, one repetition each: independent, no recording in two
    assert m["n_parts"] == n and [r[1] for r in res.tables["repetitions"].rows] == [cfg.n_utterances // n] * n
    assert set(res.sample_units.values()) == {"parts"} and res.units["parts"].kind == "independent"
    assert res.split_groups["parts"]["shared_sources"] == 0 and res.split_groups["parts"]["n_folds"] == n
    assert {c.kind for c in wd.EXPERIMENT.claims} == {"ours"}  # beyond the thesis
    assert all("shuffled" in c.rule for c in wd.EXPERIMENT.claims)  # each decided against the control
    assert 0 <= m["matched.mean_fraction"] <= 1
    assert m["gain.mean_mi"] == pytest.approx(m["matched.mean_mi"] - m["shuffled.matched.mean_mi"])
    assert m["matched.mean_mi"] > m["shuffled.matched.mean_mi"]  # distinct tones: atoms find the words
    assert len(res.tables["matching"].rows) == 10
    for claim in wd.EXPERIMENT.claims:
        assert evaluate_rule(claim.rule, m) in (True, False)
    figs = wd.present(res, cfg)
    assert set(figs) == {"word_atoms"}
    image = figs["word_atoms"].axes[0].images[0].get_array()
    first = res.figure_data
    np.testing.assert_allclose(np.diag(image), first["mi"][first["word_order"], first["order"][:10]])


def test_learner_seed_changes_the_atoms_not_the_data(fake_fsdd, tmp_path):
    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    s = common.streams(0)
    kw = dict(n_folds=None, n_per_speaker=1, n_composed=8, n_words=(1, 3))
    a = common.label_set_corpus(ctx, seeds=s, **kw)
    b = common.label_set_corpus(ctx, seeds=s.rooted("learner", 1234).rooted("reference", 4321), **kw)
    assert [str(p) for p in a.corpus.paths] == [str(p) for p in b.corpus.paths]
    np.testing.assert_array_equal(a.Y, b.Y)
    assert np.all(a.fold == -1)
    # through the experiment: the same seed gives the same numbers
    cfg = wd.Config.smoke()
    r1 = wd.compute(cfg, ctx)
    r2 = wd.compute(cfg, ctx)
    assert r1.metrics == r2.metrics


def test_bad_input(fake_fsdd, tmp_path):
    ctx = RunContext(data={"fsdd": fake_fsdd}, cache_dir=tmp_path, show_progress=False)
    with pytest.raises(ParameterError, match="n_components must be >= 0"):
        wd.compute(dataclasses.replace(wd.Config.quick(), n_components=-1), ctx)
    with pytest.raises(ParameterError, match="n_repeats must be >= 2"):
        wd.compute(dataclasses.replace(wd.Config.quick(), n_repeats=1), ctx)
    with pytest.raises(ParameterError, match=r"up to 12 distinct keywords.*vocabulary has 10"):
        wd.compute(dataclasses.replace(wd.Config.smoke(), max_words=12), ctx)


@pytest.mark.slow
def test_ch5_word_discovery_smoke_on_real_fsdd(tmp_path):
    fsdd = real_data_path("fsdd")
    cfg = wd.Config.smoke()
    res = wd.compute(cfg, RunContext(data={"fsdd": fsdd}, cache_dir=tmp_path, show_progress=False))
    res.validate()
    assert res.metrics["n_utterances"] == cfg.n_utterances and res.metrics["n_words"] == 10
    assert "Free Spoken Digit" in res.notes[0]
