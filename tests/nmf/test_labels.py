"""LabelNMF (thesis sections 3.3.2, 5.4) and the label scores (section 3.3.3)."""

from __future__ import annotations

import warnings
from math import comb
from typing import ClassVar

import numpy as np
import pytest
import scipy.sparse as sp
from sklearn.model_selection import KFold
from threadpoolctl import threadpool_limits

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.nmf import labels as labels_module
from mmconcepts.nmf._estimator import NMF
from mmconcepts.nmf.labels import DEFAULT_THRESHOLD_GRID, LabelNMF, make_svm_baseline
from mmconcepts.nmf.scores import (
    l_full,
    l_full_curve,
    l_given_number,
    l_single,
    threshold_scores,
)

N_LABELS, N_FEATURES, N_EVENTS = 12, 60, 100


@pytest.fixture(autouse=True)
def _quiet_single_thread():
    # Small matrices: BLAS threads only add contention (and erratic timings) here.
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", category=Warning)  # ConvergenceWarning of short fits
        yield


def label_mixtures(rng, n, *, patterns=None, label_sets=None):
    """Histograms of ``N_EVENTS`` events drawn from a mixture of 2-3 label patterns.

    Each label owns a nonnegative pattern over ``N_FEATURES`` bins (gamma(0.3) weights,
    so patterns are peaked but overlap); an example mixes 2 or 3 labels with activations
    in [0.5, 1.5] and its features are the counts of N_EVENTS draws from the mixture, so
    the noise is the sampling noise of a histogram (like the thesis' motion histograms
    and HAC features).
    """
    if patterns is None:
        patterns = rng.gamma(0.3, 1.0, size=(N_LABELS, N_FEATURES))
        patterns /= patterns.sum(axis=1, keepdims=True)
    Y = np.zeros((n, N_LABELS), dtype=int)
    for i in range(n):
        if label_sets is None:
            Y[i, rng.choice(N_LABELS, rng.integers(2, 4), replace=False)] = 1
        else:
            Y[i, list(label_sets[rng.integers(len(label_sets))])] = 1
    mix = (Y * rng.uniform(0.5, 1.5, size=Y.shape)) @ patterns
    X = np.array([rng.multinomial(N_EVENTS, p / p.sum()) for p in mix], dtype=float)
    return X, Y, patterns


# --------------------------------------------------------------------------- scores on hand-made matrices
def test_l_single_exact_values():
    scores = np.array([[0.9, 0.1, 0.0], [0.5, 0.5, 0.0], [0.0, 0.2, 0.3], [0.1, 0.0, 0.9]])
    y = np.array([0, 1, 2, 1])
    # correct, tie for the maximum (counted wrong), correct, wrong
    assert l_single(y, scores) == 0.5
    assert l_single(np.eye(3, dtype=int)[y], scores) == 0.5
    assert l_single(np.array([1]), np.array([[0.2, 0.3, -1.0]])) == 1.0
    with pytest.raises(DataError, match="exactly one true label"):
        l_single(np.array([[1, 1, 0]]), np.array([[0.2, 0.3, 0.1]]))
    with pytest.raises(DataError, match="label indices"):
        l_single(np.array([3]), np.array([[0.2, 0.3, 0.1]]))


def test_l_given_number_exact_values():
    Y = np.array([[1, 1, 0, 0], [0, 1, 0, 1], [1, 0, 0, 0], [0, 1, 1, 1]])
    scores = np.array(
        [
            [0.9, 0.8, 0.1, 0.0],  # best 2 = {0, 1} = true set
            [0.9, 0.8, 0.1, 0.7],  # best 2 = {0, 1} != {1, 3}
            [0.3, 0.3, 0.0, 0.0],  # tie at the boundary: ambiguous, counted wrong
            [0.0, 0.2, 0.5, 0.3],  # best 3 = {1, 2, 3}, whatever their order
        ]
    )
    assert l_given_number(Y, scores) == 0.5
    # Only the ranking matters: a monotone transform does not change it.
    assert l_given_number(Y, np.exp(3 * scores)) == 0.5
    with pytest.raises(DataError, match="shape"):
        l_given_number(Y, scores[:, :3])


def test_l_full_exact_values_and_threshold():
    Y = np.array([[1, 0, 1], [0, 1, 0], [1, 1, 0]])
    P = np.array([[1, 0, 1], [0, 1, 1], [1, 1, 0]])
    assert l_full(Y, P) == pytest.approx(2 / 3)
    assert l_full(sp.csr_matrix(Y), sp.csr_matrix(P)) == pytest.approx(2 / 3)
    S = np.array([[0.5, 0.2, 0.7], [0.1, 0.9, 0.3], [0.6, 0.4, 0.39]])
    # threshold(y_hat, eta)_j = [y_hat_j >= eta]; at eta = 0.4 the three rows match.
    assert threshold_scores(S, 0.4).tolist() == [[1, 0, 1], [0, 1, 0], [1, 1, 0]]
    assert l_full(Y, S, threshold=0.4) == 1.0
    assert l_full(Y, S, threshold=0.45) == pytest.approx(2 / 3)  # row 3 loses label 1
    with pytest.raises(DataError, match="binary"):
        l_full(Y, S)  # scores without a threshold


def test_l_full_curve_matches_thresholding_and_is_below_l_given_number(rng):
    Y = (rng.random((200, 7)) < 0.3).astype(int)
    S = np.clip(Y + rng.normal(0, 0.35, Y.shape), 0, None)
    grid = np.linspace(0.0, 1.2, 25)
    curve = l_full_curve(Y, S, grid)
    assert curve == pytest.approx([l_full(Y, S, threshold=t) for t in grid])
    assert curve.max() <= l_given_number(Y, S) + 1e-12
    assert 0.05 < curve.max() < 1.0  # the data are neither trivial nor hopeless


# --------------------------------------------------------------------------- learning label sets
@pytest.mark.parametrize(("beta_loss", "n_components"), [(2.0, 12), ("kullback-leibler", 24)])
def test_label_nmf_recovers_label_sets(rng, beta_loss, n_components):
    X, Y, _ = label_mixtures(rng, 300)
    Xtr, Ytr, Xte, Yte = X[:200], Y[:200], X[200:], Y[200:]
    model = LabelNMF(n_components, beta_loss=beta_loss, random_state=0).fit(Xtr, Ytr)
    scores = model.label_activations(Xte)
    full, given = l_full(Yte, model.predict(Xte)), l_given_number(Yte, scores)

    # Chance: ranking labels at random finds the true 2 or 3 of 12 with probability
    # <= 1/comb(12, 2) = 0.015; a predictor ignoring X cannot beat the most frequent
    # training set on l_full (a few percent at most).
    chance_given = 1 / comb(N_LABELS, 2)
    sets, counts = np.unique(Ytr, axis=0, return_counts=True)
    chance_full = max(counts.max() / len(Ytr), l_full(Yte, np.repeat(sets[[counts.argmax()]], len(Yte), 0)))
    assert chance_given < 0.02 and chance_full < 0.05
    # Bounds: the thesis reports 0.854 / 0.971 (Frobenius) and 0.789 / 0.905 (KL) on
    # 16 labels (Table 3.2); over 5 seeds of these data we measured l_full 0.78-0.92
    # (Frobenius, k=12) and 0.64-0.9 (KL, k=24). 0.6 / 0.8 leave room for the seed and
    # are >10x chance, but a learner that ignores the label part or mis-aligns columns
    # falls to chance (see the shuffled-label control below).
    assert full >= 0.6, full
    assert given >= 0.8, given
    assert full <= given + 1e-12  # thresholding can only lose examples (l_full <= l_given_number)

    # predict_given_number is the decision of l_given_number (no ties in continuous scores).
    top = model.predict_given_number(Xte, Yte.sum(axis=1))
    assert (top.sum(axis=1) == Yte.sum(axis=1)).all()
    assert l_full(Yte, top) == pytest.approx(given)

    # Control: the same learner trained on labels shuffled across examples is at chance.
    perm = rng.permutation(len(Ytr))
    shuffled = LabelNMF(n_components, beta_loss=beta_loss, threshold=0.5, random_state=0).fit(Xtr, Ytr[perm])
    assert l_given_number(Yte, shuffled.label_activations(Xte)) < 0.15


def test_label_nmf_generalises_to_unseen_combinations(rng):
    # Thesis Table 3.3: test label sets never seen together in training.
    all_pairs = [(a, b) for a in range(N_LABELS) for b in range(a + 1, N_LABELS)]
    order = rng.permutation(len(all_pairs))
    held_out = [all_pairs[i] for i in order[:15]]
    seen = [all_pairs[i] for i in order[15:]]
    Xtr, Ytr, patterns = label_mixtures(rng, 200, label_sets=seen)
    Xte, Yte, _ = label_mixtures(rng, 100, patterns=patterns, label_sets=held_out)
    train_sets = {tuple(np.flatnonzero(r)) for r in Ytr}
    assert not train_sets & {tuple(np.flatnonzero(r)) for r in Yte}
    model = LabelNMF(12, random_state=0).fit(Xtr, Ytr)
    # A learner that memorised whole label sets would score 0 here; chance is 1/66.
    assert l_given_number(Yte, model.label_activations(Xte)) >= 0.7
    assert l_full(Yte, model.predict(Xte)) >= 0.5


def test_single_label_data_gives_l_single(rng):
    names = np.array(["clap", "paddle", "punch", "squat", "walk", "wave"])
    patterns = rng.gamma(0.3, 1.0, size=(6, 40))
    patterns /= patterns.sum(axis=1, keepdims=True)
    y = rng.integers(0, 6, size=240)
    X = np.array([rng.multinomial(N_EVENTS, patterns[c]) for c in y], dtype=float)
    model = LabelNMF(6, random_state=0).fit(X[:160], names[y[:160]])
    assert model.classes_.tolist() == sorted(names.tolist())
    scores = model.decision_function(X[160:])
    assert scores.shape == (80, 6)
    score = l_single(y[160:], scores)  # classes_ are sorted names = indices of `names`
    assert score >= 0.9, score  # chance 1/6
    assert (model.predict(X[160:]) == names[np.argmax(scores, axis=1)]).all()
    assert model.score(X[160:], names[y[160:]]) == pytest.approx(score)
    assert model.threshold_ is None  # no threshold needed for one label per example


# --------------------------------------------------------------------------- the threshold
class _SpyNMF(NMF):
    """NMF that records every matrix it fits or transforms."""

    fitted: ClassVar[list] = []
    transformed: ClassVar[list] = []

    def fit(self, X, y=None, **kwargs):
        _SpyNMF.fitted.append(np.asarray(X))
        return super().fit(X, y, **kwargs)

    def transform(self, X, **kwargs):
        _SpyNMF.transformed.append(np.asarray(X))
        return super().transform(X, **kwargs)


def test_cv_threshold_in_grid_and_from_training_data_only(rng, monkeypatch):
    X, Y, _ = label_mixtures(rng, 150)
    Xtr, Ytr, Xte = X[:100], Y[:100], X[100:]
    monkeypatch.setattr(labels_module, "NMF", _SpyNMF)
    _SpyNMF.fitted, _SpyNMF.transformed = [], []
    model = LabelNMF(12, cv=4, random_state=0).fit(Xtr, Ytr)

    assert model.threshold_ in model.threshold_grid_
    assert np.array_equal(model.threshold_grid_, DEFAULT_THRESHOLD_GRID)
    assert model.cv_scores_.shape == (4, DEFAULT_THRESHOLD_GRID.size)
    best = model.cv_mean_scores_.max()
    assert model.cv_mean_scores_[model.threshold_grid_ == model.threshold_][0] == best
    assert best > 0.3  # the validation folds were learned from, not at chance

    # Each inner fold fitted once, plus the final fit: no refit per threshold.
    assert len(_SpyNMF.fitted) == 4 + 1
    # Everything fitted or transformed during fit comes from the training rows, and the
    # validation rows of the folds cover each training example exactly once.
    train_rows = {r.tobytes() for r in Xtr}
    test_rows = {r.tobytes() for r in Xte}
    assert not train_rows & test_rows
    for V in _SpyNMF.fitted:
        feats = V[:, : Xtr.shape[1]]
        assert {r.tobytes() for r in feats} <= train_rows
    seen_val = [r.tobytes() for T in _SpyNMF.transformed for r in T]
    assert sorted(seen_val) == sorted(train_rows)
    assert len(seen_val) == len(Xtr)


def test_cv_threshold_is_the_pooled_best_of_the_folds(rng):
    X, Y, _ = label_mixtures(rng, 90)
    splitter = KFold(3, shuffle=True, random_state=1)
    grid = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    model = LabelNMF(12, cv=splitter, threshold_grid=grid, random_state=0).fit(X, Y)
    sizes = np.array([len(v) for _, v in splitter.split(X)])
    assert model.cv_mean_scores_ == pytest.approx(sizes @ model.cv_scores_ / sizes.sum())
    assert model.threshold_ in grid
    assert model.cv_mean_scores_[grid.index(model.threshold_)] == model.cv_mean_scores_.max()
    # A fixed threshold skips cross-validation and is used as given.
    fixed = LabelNMF(12, threshold=0.3, random_state=0).fit(X, Y)
    assert fixed.threshold_ == 0.3 and fixed.cv_scores_ is None
    assert np.array_equal(fixed.predict(X), (fixed.label_activations(X) >= 0.3).astype(int))


def test_decision_function_is_positive_where_predicted(rng):
    # scikit-learn's convention (a label is predicted where its decision value is >= 0),
    # on top of the thesis' activations y_hat: decision = y_hat - eta.
    X, Y, _ = label_mixtures(rng, 120)
    model = LabelNMF(12, cv=3, random_state=0).fit(X[:80], Y[:80])
    y_hat, decision = model.label_activations(X[80:]), model.decision_function(X[80:])
    np.testing.assert_array_equal(decision, y_hat - model.threshold_)
    assert np.array_equal(model.predict(X[80:]), (decision >= 0).astype(int))
    assert 0 < model.predict(X[80:]).mean() < 1  # both signs occur
    # Two classes, one label per example: the second class's activation minus the first's.
    y = Y[:, 0]
    two = LabelNMF(6, random_state=0).fit(X, y)
    s = two.label_activations(X)
    np.testing.assert_array_equal(two.decision_function(X), s[:, 1] - s[:, 0])
    assert np.array_equal(two.predict(X), two.classes_[(two.decision_function(X) > 0).astype(int)])


# --------------------------------------------------------------------------- inputs
def test_sparse_X_equals_dense_X(rng):
    X, Y, _ = label_mixtures(rng, 80)
    X[:, :20] = 0.0  # a sparse matrix worth the name
    dense = LabelNMF(12, cv=3, random_state=0).fit(X, Y)
    sparse = LabelNMF(12, cv=3, random_state=0).fit(sp.csr_matrix(X), sp.csr_matrix(Y))
    assert sparse.label_weight_ == pytest.approx(dense.label_weight_)
    assert sparse.threshold_ == dense.threshold_
    np.testing.assert_allclose(sparse.nmf_.components_, dense.nmf_.components_, rtol=1e-6, atol=1e-10)
    np.testing.assert_allclose(sparse.decision_function(sp.csr_matrix(X)), dense.decision_function(X), rtol=1e-6, atol=1e-10)


def test_label_weight_balances_the_l1_norms_and_scores_are_in_label_units(rng):
    X, Y, _ = label_mixtures(rng, 60)
    model = LabelNMF(12, threshold=0.5, random_state=0).fit(X, Y)
    assert model.label_weight_ == pytest.approx(X.sum(1).mean() / Y.sum(1).mean())
    # Scores come back in label units: on training data present labels score near 1.
    s = model.label_activations(X)
    assert 0.6 < np.median(s[Y == 1]) < 1.4 and np.median(s[Y == 0]) < 0.2
    heavy = LabelNMF(12, label_weight=3.0, threshold=0.5, random_state=0).fit(X, Y)
    assert heavy.label_weight_ == 3.0
    assert heavy.nmf_.components_.shape == (12, N_FEATURES + N_LABELS)


@pytest.mark.parametrize("threshold", [-0.5, 0.0, 1.5])
def test_a_threshold_outside_0_1_is_refused(rng, threshold):
    """Label activations are >= 0 and a perfectly reconstructed present label scores 1: a threshold <= 0
    predicts every label of every example, one above 1 hardly any. Refused, as thresholds of a grid."""
    X, Y, _ = label_mixtures(rng, 30)
    with pytest.raises(ParameterError, match=r"threshold must be a real number in \(0, 1\] or one of 'cv'"):
        LabelNMF(4, threshold=threshold).fit(X, Y)
    with pytest.raises(ParameterError, match=r"threshold_grid must hold thresholds in \(0, 1\]"):
        LabelNMF(4, threshold_grid=[0.2, threshold]).fit(X, Y)
    assert LabelNMF(4, threshold=1.0, max_iter=5, random_state=0).fit(X, Y).threshold_ == 1.0


def test_bad_input_raises(rng):
    X, Y, _ = label_mixtures(rng, 30)
    with pytest.raises(DataError, match="binary"):
        LabelNMF(4, threshold=0.5).fit(X, np.where(Y == 1, 2, 0))
    with pytest.raises(DataError, match="30 samples but Y has 29 rows"):
        LabelNMF(4, threshold=0.5).fit(X, Y[:-1])
    with pytest.raises(DataError, match="Negative"):
        LabelNMF(4, threshold=0.5).fit(-X, Y)
    with pytest.raises(DataError, match="no positive label"):
        LabelNMF(4, threshold=0.5).fit(X, np.zeros_like(Y))
    with pytest.raises(DataError, match="MultiLabelBinarizer"):
        LabelNMF(4, threshold=0.5).fit(X, Y[:, :, None])
    with pytest.raises(DataError, match="continuous"):
        LabelNMF(4, threshold=0.5).fit(X, rng.random(30))
    with pytest.raises(ParameterError, match="label_weight"):
        LabelNMF(4, label_weight=-1.0).fit(X, Y)
    with pytest.raises(ParameterError, match="threshold"):
        LabelNMF(4, threshold="best").fit(X, Y)
    with pytest.raises(ParameterError, match="cv=40"):
        LabelNMF(4, cv=40).fit(X, Y)
    with pytest.raises(ParameterError, match="beta_loss"):
        LabelNMF(4, beta_loss="itakura-saito").fit(X, Y)
    model = LabelNMF(4, threshold=0.5, random_state=0).fit(X, Y)
    with pytest.raises(DataError, match="expecting 60 features"):
        model.predict(X[:, :50])
    with pytest.raises(DataError, match="Negative"):
        model.decision_function(-X)
    with pytest.raises(DataError, match="n_labels_per_sample"):
        model.predict_given_number(X, N_LABELS + 1)
    with pytest.raises(DataError, match="n_labels_per_sample"):
        model.predict_given_number(X, [2, 3])
    for err in (DataError, ParameterError):
        assert issubclass(err, ValueError)


# --------------------------------------------------------------------------- the SVM baseline
def test_svm_baseline_predicts_label_sets(rng):
    X, Y, _ = label_mixtures(rng, 300)
    svm = make_svm_baseline(random_state=0).fit(X[:200], Y[:200])
    P = svm.predict(X[200:])
    assert P.shape == (100, N_LABELS) and set(np.unique(P)) <= {0, 1}
    # Label sets come from each SVM's own decision (> 0), no threshold to learn.
    assert np.array_equal(P, (svm.decision_function(X[200:]) > 0).astype(int))
    assert l_full(Y[200:], P) > 0.4  # chance < 0.05 (see the LabelNMF test)
    with pytest.raises(ParameterError, match="C must be"):
        make_svm_baseline(C=0.0)


# --------------------------------------------------------------------------- scikit-learn contract
@pytest.mark.slow
def test_sklearn_estimator_checks():
    from sklearn.utils.estimator_checks import check_estimator

    expected = {
        # Nonnegative reconstruction from 2 shifted blob coordinates is not a general
        # classifier: accuracy 0.47-0.75 on the 3-blob problem (0.945 on 2 blobs).
        "check_classifiers_train": "method limit on 2-feature blobs",
    }
    results = check_estimator(LabelNMF(4, cv=3, random_state=0), expected_failed_checks=expected, on_fail=None)
    failed = [(r["check_name"], repr(r["exception"])[:200]) for r in results if r["status"] == "failed"]
    assert failed == []
    assert sum(r["status"] == "passed" for r in results) > 50
