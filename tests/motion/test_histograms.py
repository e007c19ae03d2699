"""Histogram invariants (Thesis 3.2): nonnegative, each dof sums to one, fit on train only."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.motion import MotionHistograms

CONFIGS = [
    dict(data="angles"), dict(data="velocities"), dict(data="separate"), dict(data="joint"),
    dict(data="joint", n_bins=(4, 5)), dict(data="joint", smoothing=0.0),
    dict(data="joint", method="vq", n_bins=8), dict(data="angles", method="vq", n_bins=6, assignment="soft"),
    dict(data="separate", method="vq", n_bins=5),
]


def _data(rng, n=6, d=3):
    return [np.cumsum(rng.normal(size=(rng.integers(20, 40), d)), axis=0) for _ in range(n)]


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: "-".join(map(str, c.values())))
def test_nonnegative_and_each_dof_sums_to_one(rng, cfg):
    X = _data(rng)
    m = MotionHistograms(random_state=0, delay=2, **cfg).fit(X)
    H = m.transform(_data(rng, 4))  # new data, possibly outside the training range
    n_ch = 6 if cfg["data"] == "separate" else 3
    assert H.shape == (4, n_ch * m.bins_per_channel_) == (4, m.n_features_out_)
    assert (H >= 0).all()
    np.testing.assert_allclose(H.reshape(4, n_ch, -1).sum(axis=2), 1.0, atol=1e-12)
    assert len(m.get_feature_names_out()) == H.shape[1]


def test_kde_counts_are_proportions(rng):
    X = [np.array([[0.0], [0.0], [1.0], [3.0]]), np.array([[3.0], [3.0]])]
    m = MotionHistograms(data="angles", n_bins=3, smoothing=0.0).fit(X)
    # grid [0, 1), [1, 2), [2, 3]: 0, 0 -> bin 0; 1 -> bin 1; 3 -> bin 2
    np.testing.assert_allclose(m.transform(X), [[0.5, 0.25, 0.25], [0, 0, 1.0]])


def test_kde_grid_ignores_rare_outliers(rng):
    # One glitch in 2000 samples: the default grid spans the 0.5-99.5 % quantiles, so the
    # ordinary values still spread over the bins; the min-max grid puts them all in one.
    x = rng.uniform(0.0, 1.0, size=(2000, 1))
    x[100] = 1000.0
    robust = MotionHistograms(data="angles", n_bins=10, smoothing=0.0).fit([x])
    plain = MotionHistograms(data="angles", n_bins=10, smoothing=0.0, range_quantile=0.0).fit([x])
    assert robust.edges_[0][0][-1] < 1.0 and plain.edges_[0][0][-1] >= 1000.0
    h_robust, h_plain = robust.transform([x])[0], plain.transform([x])[0]
    assert h_robust.max() < 0.15 and h_plain.max() > 0.99
    assert h_robust[-1] > 0  # the glitch falls in the edge bin, not lost
    np.testing.assert_allclose(h_robust.sum(), 1.0)
    with pytest.raises(ParameterError, match="range_quantile"):
        MotionHistograms(range_quantile=0.5).fit([x])


def test_transform_uses_train_grid_and_codebook(rng):
    train = _data(rng)
    for cfg in (dict(method="kde"), dict(method="vq", n_bins=6)):
        m = MotionHistograms(random_state=0, **cfg).fit(train)
        edges = [tuple(e.copy() for e in t) for t in m.edges_]
        cbs = [c.copy() for c in m.codebooks_]
        new = [10 * x + 100 for x in _data(rng, 3)]  # far from the training range
        h1 = m.transform(new)
        for a, b in zip(edges, m.edges_):
            for ea, eb in zip(a, b):
                np.testing.assert_array_equal(ea, eb)
        for a, b in zip(cbs, m.codebooks_):
            np.testing.assert_array_equal(a, b)
        # transform of a batch does not depend on the other recordings in it
        np.testing.assert_allclose(m.transform(new[:1]), h1[:1])
        # and differs from a model fitted on the new data
        assert not np.allclose(MotionHistograms(random_state=0, **cfg).fit(new).transform(new), h1)


def test_velocity_delay_matters(rng):
    X = _data(rng)
    a = MotionHistograms(data="velocities", delay=1, smoothing=0).fit_transform(X)
    b = MotionHistograms(data="velocities", delay=5, smoothing=0).fit_transform(X)
    assert not np.allclose(a, b)
    # a constant-velocity ramp: all velocity samples in one bin whatever the delay
    ramp = [np.arange(30.0)[:, None], 2 * np.arange(30.0)[:, None]]
    h = MotionHistograms(data="velocities", delay=4, smoothing=0, n_bins=4).fit_transform(ramp)
    assert np.allclose(np.sort(h, axis=1)[:, -1], 1.0)


def test_soft_assignment_is_smoother_than_hard(rng):
    X = _data(rng, 8)
    hard = MotionHistograms(method="vq", n_bins=8, random_state=0).fit_transform(X)
    soft = MotionHistograms(method="vq", n_bins=8, assignment="soft", random_state=0).fit_transform(X)
    assert (soft > 0).mean() > (hard > 0).mean()


def test_deterministic_for_seed(rng):
    X = _data(rng)
    a = MotionHistograms(method="vq", n_bins=6, random_state=3).fit_transform(X)
    b = MotionHistograms(method="vq", n_bins=6, random_state=3).fit_transform(X)
    np.testing.assert_array_equal(a, b)


def test_errors(rng):
    X = _data(rng)
    with pytest.raises(ParameterError):
        MotionHistograms(data="both").fit(X)
    with pytest.raises(ParameterError):
        MotionHistograms(n_bins=1).fit(X)
    with pytest.raises(DataError, match="list of"):
        MotionHistograms().fit(X[0])
    with pytest.raises(DataError, match="frame"):
        MotionHistograms(delay=5).fit([np.zeros((3, 2))])
    m = MotionHistograms().fit(X)
    with pytest.raises(DataError, match="degrees of freedom"):
        m.transform([np.zeros((10, 5))])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 2), n=st.integers(5, 120), k=st.integers(1, 12), d=st.integers(1, 6),
       levels=st.integers(2, 6), noise=st.sampled_from([0.0, 0.01]))
def test_lloyd_stops_where_kmeans2_is_at_its_fixed_point(seed, n, k, d, levels, noise):
    """_lloyd equals scipy's kmeans2 run for all its iterations, bit for bit (empty clusters and, on a grid of
    integers, equidistant centroids included; from five features, scipy's matrix-product distances)."""
    from scipy.cluster.vq import kmeans2

    from mmconcepts.motion.histograms import _lloyd

    rng = np.random.default_rng(seed)
    z = rng.integers(0, levels, size=(n, d)).astype(float) + noise * rng.standard_normal((n, d))
    k = min(k, n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # empty clusters
        want_cb, want_lab = kmeans2(z, k, iter=50, minit="++", seed=seed)
        cb, lab = _lloyd(z, k, seed=seed, n_iter=50)
    np.testing.assert_array_equal(lab, want_lab)
    np.testing.assert_array_equal(cb, want_cb)


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_a_lloyd_step_is_kmeans2s_iteration_with_equidistant_centroids(d):
    """One compiled Lloyd step equals ``kmeans2(z, cb, iter=1, minit="matrix")`` to the bit where samples lie at
    the same distance from several centroids (the first of them wins) and where a centroid gets no sample."""
    from scipy.cluster.vq import kmeans2

    from mmconcepts.motion.histograms import _lloyd_step

    grid = np.stack(np.meshgrid(*[np.arange(-2.0, 3.0)] * min(d, 3), indexing="ij"), axis=-1).reshape(-1, min(d, 3))
    z = np.hstack([grid, np.zeros((len(grid), d - grid.shape[1]))])
    cb = np.zeros((2 * d + 1, d))
    for f in range(d):  # one centroid on each side of the origin on every axis: the origin's 2d neighbours tie
        cb[2 * f, f], cb[2 * f + 1, f] = 1.0, -1.0
    cb[-1] = 50.0  # far from every sample: empty, keeps its place
    labels, best = np.empty(len(z), dtype=np.int64), np.empty(len(z))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the empty cluster
        want_cb, want_lab = kmeans2(z, cb, iter=1, minit="matrix")
    got = _lloyd_step(np.ascontiguousarray(z.T), cb, labels, best)
    np.testing.assert_array_equal(labels, want_lab)
    np.testing.assert_array_equal(got, want_cb)
    assert labels[np.flatnonzero((z == 0).all(axis=1))[0]] == 0  # the origin: every centroid but the last at 1


@pytest.mark.parametrize("d", [3, 4])
def test_a_lloyd_step_sums_the_features_in_scipys_order(d):
    """A sample at the origin and two centroids with the same coordinates in reverse order: equidistant in exact
    arithmetic, so the nearest one depends on the order in which the squares are summed (for about one centroid in
    eight). The compiled step picks kmeans2's centroid every time."""
    from scipy.cluster.vq import kmeans2

    from mmconcepts.motion.histograms import _lloyd_step

    rng = np.random.default_rng(0)
    for _ in range(60):
        c0 = rng.random(d)
        cb = np.vstack([c0, c0[::-1]])
        z = np.vstack([np.zeros(d), rng.random((5, d)) + 2.0])
        labels, best = np.empty(len(z), dtype=np.int64), np.empty(len(z))
        got = _lloyd_step(np.ascontiguousarray(z.T), cb, labels, best)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a centroid without samples
            want_cb, want_lab = kmeans2(z, cb, iter=1, minit="matrix")
        np.testing.assert_array_equal(labels, want_lab)
        np.testing.assert_array_equal(got, want_cb)


def test_lloyd_with_few_iterations_stops_with_kmeans2():
    from scipy.cluster.vq import kmeans2

    from mmconcepts.motion.histograms import _lloyd

    z = np.random.default_rng(3).standard_normal((400, 2))
    for n_iter in (1, 2, 3):
        want_cb, want_lab = kmeans2(z, 9, iter=n_iter, minit="++", seed=7)
        cb, lab = _lloyd(z, 9, seed=7, n_iter=n_iter)
        np.testing.assert_array_equal(cb, want_cb)
        np.testing.assert_array_equal(lab, want_lab)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 40), d=st.integers(1, 4), levels=st.sampled_from([(0.0,), (0.0, -0.0), (0.0, -0.0, 1.0, -2.5),
                                                                         (1e-300, 1e300, -1.0)]),
       seed=st.integers(0, 2**32 - 1))
def test_distinct_rows_counts_what_numpy_unique_counts(n, d, levels, seed):
    """Rows drawn from a few values (repeats, -0.0 beside 0.0, rows equal up to one column) are counted as
    ``np.unique(z, axis=0)`` counts them."""
    from mmconcepts.motion.histograms import _distinct_rows

    z = np.random.default_rng(seed).choice(np.asarray(levels), size=(n, d))
    assert _distinct_rows(z) == len(np.unique(z, axis=0))
