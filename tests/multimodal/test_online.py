"""MultimodalNMF.partial_fit: the online multimodal learner.

What is checked, and against what:
- one call on all the data is ``fit`` (same dictionary, scales and transform, dense and sparse,
  several betas): the batch learner is the outside answer;
- the rescaling of the dictionary and statistics when the online scales change is the exact
  image of the statistics recomputed in the new units (brute force from the NMF's own
  numerator and denominator);
- the objective on a stream stays close to the batch fit's and to scikit-learn's
  MiniBatchNMF on the same stream (beta = 1 and 2, one modality);
- the state's arrays and the memory of a call do not grow with the examples seen;
- bad input gives DataError / ParameterError saying expected, got and fix.
"""

from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from sklearn.base import clone

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.multimodal import MultimodalNMF
from mmconcepts.nmf import NMF, beta_divergence, mm_exponent
from mmconcepts.nmf._problem import Problem


def _pairs(n: int = 120, seed: int = 0, sparse: bool = False, k: int = 4):
    """Two modalities generated from shared concepts (a planted multimodal NMF plus noise)."""
    rng = np.random.default_rng(seed)
    y = rng.integers(0, k, n)
    Hs = rng.random((k, 60)) ** 4
    Hm = rng.random((k, 12)) ** 2
    S = 5.0 * (Hs[y] * rng.random((n, 1)) + 0.02 * rng.random((n, 60)))
    S[rng.random(S.shape) < 0.6] = 0.0  # sparse, as HAC counts
    M = 30.0 * (Hm[y] + 0.05 * rng.random((n, 12)))
    return {"sound": sp.csr_matrix(S) if sparse else S, "motion": M}, y


def _rows(X, sl):
    return {m: v[sl] for m, v in X.items()}


def _stream(model, X, batch):
    n = next(iter(X.values())).shape[0]
    for i in range(0, n, batch):
        model.partial_fit(_rows(X, slice(i, i + batch)))
    return model


def _objective(model, X):
    """I-divergence (the estimator's beta) of the stacked normalised data, coefficients from transform."""
    W = model.transform(X)
    total = 0.0
    for m in model.modalities_:
        Xm = X[m].toarray() if sp.issparse(X[m]) else X[m]
        total += beta_divergence(Xm / model.scales_[m], W, model.components_[:, model.component_slice(m)],
                                 model.nmf_.beta_loss)
    return total


# --------------------------------------------------------------------------- one batch of all data = fit
@pytest.mark.parametrize("beta", [0.5, 1.0, 1.5, 2.0, 3.0])
@pytest.mark.parametrize("sparse", [False, True])
def test_one_batch_of_all_data_is_fit(beta, sparse):
    X, _ = _pairs(sparse=sparse)
    kw = dict(n_components=4, beta_loss=beta, max_iter=40, random_state=7)
    batch = MultimodalNMF(**kw).fit(X)
    online = MultimodalNMF(**kw, partial_max_iter=3).partial_fit(X)
    assert online.modalities_ == batch.modalities_ and online.n_features_ == batch.n_features_
    for m in batch.modalities_:
        assert online.scales_[m] == pytest.approx(batch.scales_[m], rel=1e-14)
    np.testing.assert_allclose(online.components_, batch.components_, rtol=1e-9, atol=1e-13)
    # the coefficients are solved to 1e-7 of each row's largest (the solver's tolerance): two dictionaries 1e-9 apart
    # may stop at points of a flat minimum that far apart (same objective to rounding)
    want = batch.transform(X)
    np.testing.assert_allclose(online.transform(X), want, rtol=0, atol=1e-7 * want.max())
    assert online.n_samples_seen_ == batch.n_samples_seen_ == 120


def test_forgetting_does_not_change_the_first_call():
    X, _ = _pairs()
    a = MultimodalNMF(4, max_iter=30, random_state=1, forget_factor=0.3).partial_fit(X)
    b = MultimodalNMF(4, max_iter=30, random_state=1).fit(X)
    np.testing.assert_allclose(a.components_, b.components_, rtol=1e-9, atol=1e-13)


# --------------------------------------------------------------------------- online scales
def test_online_scales_are_the_running_average_l1_norm():
    X, _ = _pairs(n=90)
    model = MultimodalNMF(3, max_iter=5, random_state=0)
    _stream(model, X, 30)
    for m in X:  # no forgetting: the average over every example seen
        assert model.scales_[m] == pytest.approx(np.abs(X[m]).sum(axis=1).mean(), rel=1e-12)
    rho = 0.5
    model = MultimodalNMF(3, max_iter=5, random_state=0, forget_factor=rho)
    _stream(model, X, 30)
    w = np.repeat([rho ** 2, rho, 1.0], 30)  # an example seen t batches ago weighs rho ** t
    for m in X:
        want = (w * np.abs(X[m]).sum(axis=1)).sum() / w.sum()
        assert model.scales_[m] == pytest.approx(want, rel=1e-12)
    assert model.n_samples_seen_ == pytest.approx(w.sum())


@pytest.mark.parametrize("beta", [0.5, 1.0, 1.5, 2.0, 3.0])
def test_rescaling_is_the_statistics_recomputed_in_the_new_units(beta):
    """Brute force: the numerator and denominator of the dictionary update, at the same coefficients,
    computed on the data and dictionary in the new units, equal the rescaled old ones."""
    rng = np.random.default_rng(3)
    k, n_s, n_m, n = 3, 7, 5, 20
    X = rng.random((n, n_s + n_m)) + 0.1
    W = rng.random((n, k)) + 0.1
    Ht = rng.random((n_s + n_m, k)) + 0.1  # (n_features, k), as the NMF's statistics
    gamma = mm_exponent(beta)

    def stats(X, Ht):
        num, den = Problem(X, None).sides[1].numerator_denominator(Ht, W, beta)
        return Ht ** (1.0 / gamma) * num, np.array(den)

    A, B = stats(X, Ht)
    old, new = {"sound": 2.0, "motion": 5.0}, {"sound": 1.6, "motion": 6.5}
    c = np.r_[np.full(n_s, old["sound"] / new["sound"]), np.full(n_m, old["motion"] / new["motion"])]
    A2, B2 = stats(X * c, Ht * c[:, None])
    fake = NMF(k, beta_loss=beta)  # a fitted NMF's state, set by hand
    fake.components_, fake._stats = Ht.T.copy(), (A, B)
    MultimodalNMF(k, beta_loss=beta)._rescale(fake, ["sound", "motion"], {"sound": n_s, "motion": n_m}, old, new)
    np.testing.assert_allclose(fake.components_, (Ht * c[:, None]).T, rtol=1e-13)
    np.testing.assert_allclose(fake._stats[0], A2, rtol=1e-12)
    np.testing.assert_allclose(fake._stats[1], B2, rtol=1e-12)


def test_a_zero_column_is_learnt_when_its_feature_appears():
    """A feature absent from the first batch is not locked at zero by the multiplicative updates."""
    X, _ = _pairs(n=80)
    S = X["sound"].copy()
    S[:40, 0] = 0.0
    S[40:, 0] = 3.0
    model = MultimodalNMF(4, max_iter=20, random_state=0)
    model.partial_fit({"sound": S[:40], "motion": X["motion"][:40]})
    assert model.components_[:, 0].max() == 0.0
    model.partial_fit({"sound": S[40:], "motion": X["motion"][40:]})
    assert model.components_[:, 0].max() > 1e-3 * model.components_[:, :60].max()
    assert np.isfinite(model.nmf_.reconstruction_err_)


# --------------------------------------------------------------------------- the stream's objective
@pytest.mark.parametrize("sparse", [False, True])
def test_the_objective_on_a_stream_stays_near_the_batch_fit(sparse):
    X, _ = _pairs(n=240, sparse=sparse)
    kw = dict(n_components=4, max_iter=40, random_state=2)
    batch = MultimodalNMF(**kw).fit(X)
    online = MultimodalNMF(**kw, partial_max_iter=10)
    losses = []
    for i in range(0, 240, 30):
        online.partial_fit(_rows(X, slice(i, i + 30)))
        losses.append(_objective(online, X))
    assert np.all(np.isfinite(losses))
    assert max(losses[1:]) < 1.5 * losses[0]  # no blow-up along the stream
    for m in X:  # the online scales reach the batch ones (every example has the same weight)
        assert online.scales_[m] == pytest.approx(batch.scales_[m], rel=1e-12)
    assert losses[-1] < 1.15 * _objective(batch, X)


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_a_single_modality_stream_is_as_good_as_scikit_learns_minibatch_nmf(beta):
    """Outside answer: scikit-learn's MiniBatchNMF on the same stream (one modality, no normalisation,
    no forgetting, the same number of passes); our objective must not be worse by more than 5 %."""
    from sklearn.decomposition import MiniBatchNMF

    X, _ = _pairs(n=300)
    S = np.hstack([X["sound"], X["motion"]])
    ours = MultimodalNMF(4, beta_loss=beta, max_iter=50, partial_max_iter=20, normalize=None, init="nndsvda",
                         random_state=0)
    theirs = MiniBatchNMF(4, beta_loss=beta, init="nndsvda", forget_factor=1.0, batch_size=50, max_iter=1,
                          random_state=0, fresh_restarts=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(0, 300, 50):
            ours.partial_fit({"x": S[i:i + 50]})
            theirs.partial_fit(S[i:i + 50])
    d_ours = beta_divergence(S, ours.transform({"x": S}), ours.components_, beta)
    d_theirs = beta_divergence(S, theirs.transform(S), theirs.components_, beta)
    assert d_ours < 1.05 * d_theirs, (d_ours, d_theirs)


# --------------------------------------------------------------------------- memory
def test_the_state_does_not_grow_with_the_examples_seen():
    X, _ = _pairs(n=400, sparse=True)

    def arrays(model):
        out = {"components_": model.components_.shape}
        out.update({f"stats{i}": a.shape for i, a in enumerate(model.nmf_._stats)})
        return out, sum(a.nbytes for a in (model.components_, *model.nmf_._stats))

    short = _stream(MultimodalNMF(4, max_iter=5, random_state=0), _rows(X, slice(0, 40)), 20)
    long = _stream(MultimodalNMF(4, max_iter=5, random_state=0), X, 20)
    assert arrays(short) == arrays(long)
    assert arrays(long)[0] == {"components_": (4, 72), "stats0": (72, 4), "stats1": (72, 4)}
    # the memory a call allocates does not depend on how many examples came before it
    peaks = []
    for model in (short, long):
        tracemalloc.start()
        model.partial_fit(_rows(X, slice(0, 20)))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.2 * peaks[0] + 10_000


def test_save_load_mid_stream_continues_the_same_stream(tmp_path):
    X, _ = _pairs(n=90)
    model = _stream(MultimodalNMF(3, max_iter=10, random_state=0, forget_factor=0.8), _rows(X, slice(0, 60)), 30)
    loaded = MultimodalNMF.load(model.save(tmp_path / "mid"))
    assert loaded.n_samples_seen_ == model.n_samples_seen_
    nxt = _rows(X, slice(60, 90))
    np.testing.assert_array_equal(loaded.partial_fit(nxt).components_, model.partial_fit(nxt).components_)


def test_clone_forgets_the_stream_and_partial_fit_after_fit_continues():
    X, _ = _pairs()
    model = _stream(MultimodalNMF(4, max_iter=10, random_state=0), X, 40)
    fresh = clone(model)
    assert not hasattr(fresh, "components_")
    np.testing.assert_allclose(fresh.partial_fit(X).components_, clone(model).fit(X).components_, rtol=1e-9,
                               atol=1e-13)
    fitted = MultimodalNMF(4, max_iter=10, random_state=0).fit(X)
    before = fitted.components_.copy()
    fitted.partial_fit(_rows(X, slice(0, 40)))
    assert fitted.n_samples_seen_ == 160 and not np.array_equal(fitted.components_, before)


# --------------------------------------------------------------------------- bad input
def test_bad_batches_are_refused_with_expected_got_and_fix():
    X, _ = _pairs()
    model = MultimodalNMF(3, max_iter=5, random_state=0).partial_fit(_rows(X, slice(0, 40)))
    before = model.components_.copy()
    with pytest.raises(DataError, match=r"needs the modalities .*'motion', 'sound'|needs the modalities .*unknown: "
                                        r"\['image'\].*clone"):
        model.partial_fit({**_rows(X, slice(40, 60)), "image": np.ones((20, 3))})
    with pytest.raises(DataError, match=r"missing: \['motion'\].*Give every batch the same modalities"):
        model.partial_fit({"sound": X["sound"][40:60]})
    with pytest.raises(DataError, match="'motion' has 19 examples but the first modality has 20"):
        model.partial_fit({"sound": X["sound"][40:60], "motion": X["motion"][40:59]})
    with pytest.raises(DataError, match=r"'motion' has 11 features in this batch; the learner was fitted with 12\. "
                                        "Give every batch the same features"):
        model.partial_fit({"sound": X["sound"][40:60], "motion": X["motion"][40:60, :11]})
    np.testing.assert_array_equal(model.components_, before)  # a refused batch changes nothing
    assert model.n_samples_seen_ == 40
    other = MultimodalNMF(3, max_iter=5, random_state=0).fit({"sound": X["sound"], "labels": np.eye(3)[_pairs()[1] % 3]})
    with pytest.raises(DataError, match=r"fitted with, \['sound', 'labels'\].*unknown: \['motion'\].*missing: "
                                        r"\['labels'\]"):
        other.partial_fit(X)
    with pytest.raises(DataError, match="all zeros on the first batch"):
        MultimodalNMF(3).partial_fit({"sound": np.zeros((4, 3)), "motion": np.ones((4, 2))})
    with pytest.raises(DataError, match="non-empty mapping"):
        MultimodalNMF(3).partial_fit(np.ones((4, 3)))


@pytest.mark.parametrize("name, value", [("forget", 0.0), ("forget", 1.01), ("forget", "none"),
                                         ("partial_max_iter", 0), ("partial_max_iter", 2.5)])
def test_bad_online_parameters_are_refused_by_partial_fit(name, value):
    X, _ = _pairs()
    with pytest.raises(ParameterError, match=rf"^MultimodalNMF: {name} must be .*; got "):
        MultimodalNMF(3).set_params(**{name: value}).partial_fit(X)


def test_itakura_saito_refuses_zeros_in_a_batch_as_fit_does():
    X, _ = _pairs()
    with pytest.raises(DataError):
        MultimodalNMF(3, beta_loss="itakura-saito").partial_fit(X)


# --------------------------------------------------------------------------- updating only the touched columns
def _sparse_stream(seed: int, n_batches: int = 6, n: int = 30, m: int = 4000):
    """Sparse count batches whose nonzeros fall on a few hundred of m columns (as HAC vectors), one row empty."""
    rng = np.random.default_rng(seed)
    p = 1.0 / (np.arange(m) + 10.0) ** 1.2
    p = p[rng.permutation(m)] / p.sum()
    out = []
    for _ in range(n_batches):
        X = np.zeros((n, m))
        for i in range(1, n):
            np.add.at(X[i], rng.choice(m, 25, p=p), 1.0)
        out.append(sp.csr_matrix(X))
    return out


def _all_columns(monkeypatch):
    """Make NMF.partial_fit update every column (the plain form of the update)."""
    import mmconcepts.nmf._estimator as est
    monkeypatch.setattr(est, "_touched_columns", lambda *a, **k: None)


@pytest.mark.parametrize("forget", [0.7, 1.0])
def test_updating_only_the_touched_columns_is_the_full_update(forget, monkeypatch):
    """Under KL, partial_fit iterates on a sparse batch's nonzero columns plus the sum of the others:
    the dictionary and the statistics equal those of the update over every column (to rounding)."""
    from mmconcepts.nmf import NMF
    import mmconcepts.nmf._estimator as est

    batches = _sparse_stream(3)
    taken = []
    real = est._touched_columns

    def spy(*a, **k):
        out = real(*a, **k)
        taken.append(out is not None and out.size < batches[0].shape[1] // 4)
        return out

    def run():
        model = NMF(5, beta_loss="kullback-leibler", max_iter=12, forget_factor=forget, random_state=0)
        for X in batches:
            model.partial_fit(X)
        return model

    monkeypatch.setattr(est, "_touched_columns", spy)
    fast = run()
    assert taken and all(taken)  # every later call took the touched-columns path, on a small share of columns
    _all_columns(monkeypatch)
    full = run()
    np.testing.assert_allclose(fast.components_, full.components_, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(fast._stats[0], full._stats[0], rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(np.broadcast_to(fast._stats[1], full._stats[1].shape), full._stats[1], rtol=1e-12)
    assert fast.loss_history_[0] == pytest.approx(full.loss_history_[0], rel=1e-10)


def test_the_multimodal_stream_keeps_the_broadcast_denominator_and_the_full_update(monkeypatch):
    """MultimodalNMF's rescaling keeps KL's pooled denominator one broadcast row (so the touched-columns
    path applies at every batch), with the same dictionary as the update over every column."""
    batches = _sparse_stream(4, n_batches=5)
    rng = np.random.default_rng(9)
    motion = [30.0 * rng.random((b.shape[0], 12)) for b in batches]

    def run():
        model = MultimodalNMF(4, max_iter=15, partial_max_iter=6, forget_factor=0.8, random_state=0)
        for S, M in zip(batches, motion):
            model.partial_fit({"sound": S, "motion": M})
            assert model.nmf_._stats is None or model.nmf_._stats[1].strides[0] == 0
        return model

    fast = run()
    _all_columns(monkeypatch)
    full = run()
    np.testing.assert_allclose(fast.components_, full.components_, rtol=1e-9, atol=1e-300)
    assert fast.scales_ == full.scales_


def test_a_saved_stream_loads_with_its_broadcast_denominator(tmp_path):
    from mmconcepts.nmf import NMF

    batches = _sparse_stream(5, n_batches=3)
    model = NMF(4, beta_loss="kullback-leibler", max_iter=8, random_state=0)
    for X in batches[:2]:
        model.partial_fit(X)
    loaded = NMF.load(model.save(tmp_path / "m"))
    assert loaded._stats[1].strides[0] == 0
    model.partial_fit(batches[2])
    loaded.partial_fit(batches[2])
    np.testing.assert_array_equal(loaded.components_, model.components_)


def test_forget_is_the_deprecated_name_of_forget_factor():
    """One spelling across NMF and MultimodalNMF: forget_factor; the old name still works, with a FutureWarning,
    and learns the same."""
    X, _ = _pairs(n=60)
    new = MultimodalNMF(3, max_iter=5, random_state=0, forget_factor=0.7)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new.partial_fit(_rows(X, slice(0, 30))).partial_fit(_rows(X, slice(30, 60)))
    old = MultimodalNMF(3, max_iter=5, random_state=0, forget=0.7)
    with pytest.warns(FutureWarning, match="forget_factor"):
        old.partial_fit(_rows(X, slice(0, 30))).partial_fit(_rows(X, slice(30, 60)))
    np.testing.assert_array_equal(old.components_, new.components_)
    assert "forget_factor" in MultimodalNMF().get_params() and "forget_factor" in NMF().get_params()
