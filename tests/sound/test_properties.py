"""Property tests (hypothesis) of the DTW distance and of the incremental cluster tree.

They replace hand-written loops over a few random draws: the invariants of DTW (symmetry
bit for bit, zero self-distance, lower and upper bounds, the window's monotonicity), the
structural rules of the cluster tree (thesis section 5.2.3, rules 1-3), and the agreement
of the compiled tree (both built-in metrics, numba) with the Python path a callable metric
takes, which serves as the reference: same tree, same searches, for DTW bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mmconcepts.sound.dtw import dtw, dtw_one_to_many
from mmconcepts.sound.tree import ClusterTree

pytestmark = pytest.mark.property

SETTINGS = settings(deadline=None, max_examples=40, suppress_health_check=[HealthCheck.too_slow])
LOCALS = ("euclidean", "sqeuclidean")

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False, width=64)


@st.composite
def sequence_pairs(draw, d=None):
    """Two sequences with the same number of features and lengths 1..12."""
    d = draw(st.integers(1, 4)) if d is None else d
    a = draw(arrays(np.float64, (draw(st.integers(1, 12)), d), elements=finite))
    b = draw(arrays(np.float64, (draw(st.integers(1, 12)), d), elements=finite))
    return a, b


def local_costs(a, b, local):
    C = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2))
    return C if local == "euclidean" else C**2


# --------------------------------------------------------------------------- DTW
@SETTINGS
@given(pair=sequence_pairs(), local=st.sampled_from(LOCALS), window=st.none() | st.integers(0, 4))
def test_dtw_is_symmetric_bit_for_bit_and_nonnegative(pair, local, window):
    a, b = pair
    ab = dtw(a, b, local=local, window=window)
    assert ab >= 0.0
    assert ab == dtw(b, a, local=local, window=window)


@SETTINGS
@given(pair=sequence_pairs(), local=st.sampled_from(LOCALS), window=st.none() | st.integers(0, 4))
def test_dtw_self_distance_is_zero(pair, local, window):
    a, _ = pair
    assert dtw(a, a.copy(), local=local, window=window) == 0.0
    # a copy with every frame repeated is also at distance zero (without window)
    assert dtw(a, np.repeat(a, 2, axis=0), local=local) == 0.0


@SETTINGS
@given(pair=sequence_pairs(), local=st.sampled_from(LOCALS))
def test_dtw_lower_and_upper_bounds(pair, local):
    """Every warping path joins (1, 1) to (n, m) and visits each row and each column: the
    summed cost is at least the end-point costs and the sum of the row (column) minima;
    on equal lengths it is at most the diagonal path."""
    a, b = pair
    value = dtw(a, b, local=local)
    C = local_costs(a, b, local)
    total = (lambda s: s) if local == "euclidean" else np.sqrt  # sqeuclidean reports sqrt(summed cost)
    tol = 1e-9 * (1.0 + C.sum())
    ends = C[0, 0] + (C[-1, -1] if (len(a), len(b)) != (1, 1) else 0.0)
    assert value >= total(max(ends, C.min(axis=1).sum(), C.min(axis=0).sum())) - tol
    if len(a) == len(b):
        assert value <= total(np.trace(C)) + tol
        assert dtw(a, b, local=local, window=0) == pytest.approx(total(np.trace(C)), rel=1e-12, abs=1e-9)


@SETTINGS
@given(pair=sequence_pairs(), local=st.sampled_from(LOCALS), w=st.integers(0, 12))
def test_a_wider_window_never_increases_dtw(pair, local, w):
    a, b = pair
    assert dtw(a, b, local=local, window=w + 1) <= dtw(a, b, local=local, window=w)
    assert dtw(a, b, local=local, window=w) >= dtw(a, b, local=local)


# --------------------------------------------------------------------------- the cluster tree
def _dtw_callable(q, C):
    """DTW through the Python path of the tree (a callable metric): the reference."""
    return dtw_one_to_many(q, C)


def _euclid_callable(q, C):
    return np.sqrt(((C - q) ** 2).reshape(C.shape[0], -1).sum(axis=1))


@st.composite
def tree_problems(draw):
    """Data with clusters (so leaves are joined, nodes split and searches backtrack), the
    tree's sizes, and a radius around the typical distance between neighbours."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(20, 300))
    T, d = draw(st.integers(1, 5)), draw(st.integers(1, 3))
    centers = rng.normal(size=(draw(st.integers(1, 12)), T, d)) * 2.0
    X = centers[rng.integers(len(centers), size=n)] + draw(st.sampled_from([0.0, 0.1, 0.5])) * rng.normal(
        size=(n, T, d))
    if draw(st.booleans()):
        X = np.round(X * 2.0) / 2.0  # a coarse grid: many equal distances (ties)
    k = draw(st.integers(2, 4))
    n_max = draw(st.integers(k + 1, k + 5))
    r_max = draw(st.sampled_from([0.3, 1.0, 3.0])) * T
    return X, dict(r_max=r_max, n_max=n_max, k=k, random_state=seed % 1000,
                   restart_priority=draw(st.sampled_from(["path", "sibling"])))


def _members(tree, labels):
    below = [[] for _ in range(tree.n_nodes_)]
    for leaf in range(tree.n_leaves_):
        idx = np.flatnonzero(labels == leaf)
        for node in tree.ancestors(leaf):
            below[node].append(idx)
    return [np.concatenate(b) if b else np.empty(0, dtype=int) for b in below]


@SETTINGS
@given(problem=tree_problems(), metric=st.sampled_from(["euclidean", "dtw"]))
def test_tree_rules_hold_after_any_insertions(problem, metric):
    X, params = problem
    tree = ClusterTree(metric=metric, **params).fit(X)
    n, n_max, k = tree.n_nodes_, params["n_max"], params["k"]
    parents, leaf_of = tree.node_parents_, tree.node_leaf_ids_
    assert parents[0] == -1 and (parents[1:] >= 0).all()
    for node in range(n):
        kids = tree.children(node)
        assert len(kids) < n_max  # rule 3, after every insertion
        assert (parents[kids] == node).all()
        if leaf_of[node] >= 0:
            assert len(kids) == 0
        elif len(kids):
            assert len(set(leaf_of[kids] >= 0)) == 1  # all leaves or all internal nodes
            if leaf_of[kids[0]] < 0:
                assert len(kids) <= k  # a split node keeps its (at most) k new children
        else:
            assert node == 0
    # leaf ids number the leaves; every node's centroid is the mean of the vectors below it
    np.testing.assert_array_equal(np.sort(np.unique(tree.labels_)), np.arange(tree.n_leaves_))
    below = _members(tree, tree.labels_)
    for node in range(n):
        assert tree.node_sizes_[node] == len(below[node]) > 0
        np.testing.assert_allclose(tree.node_centers_[node], X[below[node]].mean(axis=0), rtol=1e-9, atol=1e-9)
    # exhaustive search is the nearest leaf centroid under the metric
    leaf, dist, n_eval = tree.query_batch(X[:10], search="exact")
    for q, lf, dq in zip(X[:10], leaf, dist):
        ref = (_dtw_callable if metric == "dtw" else _euclid_callable)(q, tree.leaf_centers_)
        assert ref[lf] == pytest.approx(ref.min(), rel=1e-12, abs=1e-12) and dq == pytest.approx(ref.min(), abs=1e-9)
    assert (n_eval == tree.n_leaves_).all()


SEARCHES = [("greedy", 1), ("best_children", 2), ("best_children", 3), ("restart", 1), ("restart", 3),
            ("restart", 12), ("exact", 1)]


@SETTINGS
@given(problem=tree_problems())
def test_compiled_dtw_tree_equals_the_python_reference_bit_for_bit(problem):
    """metric="dtw" (numba kernels calling the compiled DTW) and a callable DTW (the Python
    path) build the same tree and answer every search the same, to the last bit, ties included."""
    X, params = problem
    compiled = ClusterTree(metric="dtw", **params).fit(X)
    python = ClusterTree(metric=_dtw_callable, **params).fit(X)
    np.testing.assert_array_equal(compiled.labels_, python.labels_)
    np.testing.assert_array_equal(compiled.node_parents_, python.node_parents_)
    np.testing.assert_array_equal(compiled.node_centers_, python.node_centers_)
    Q = np.concatenate([X[:15], X[-15:] + 0.25])
    for search, b in SEARCHES:
        got, ref = compiled.query_batch(Q, search=search, backtrack=b), python.query_batch(Q, search=search, backtrack=b)
        for g, r in zip(got, ref):
            np.testing.assert_array_equal(g, r)
        assert compiled.query(Q[0], search=search, backtrack=b, return_stats=True) == tuple(x[0] for x in ref)


@SETTINGS
@given(problem=tree_problems())
def test_compiled_euclidean_tree_equals_the_python_reference(problem):
    """The Euclidean kernels against a callable Euclidean metric: the same tree and the same
    leaves (distances to rounding: the kernels compare squared distances, summed in another order)."""
    X, params = problem
    X = X + 1e-6 * np.random.default_rng(params["random_state"]).normal(size=X.shape)  # no exact ties
    compiled = ClusterTree(**params).fit(X)
    python = ClusterTree(metric=_euclid_callable, **params).fit(X)
    np.testing.assert_array_equal(compiled.labels_, python.labels_)
    np.testing.assert_array_equal(compiled.node_parents_, python.node_parents_)
    Q = np.concatenate([X[:15], X[-15:] + 0.25])
    for search, b in SEARCHES:
        got, ref = compiled.query_batch(Q, search=search, backtrack=b), python.query_batch(Q, search=search, backtrack=b)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_allclose(got[1], ref[1], rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(got[2], ref[2])


@SETTINGS
@given(problem=tree_problems(), metric=st.sampled_from(["euclidean", "dtw"]), n_chunks=st.integers(1, 5))
def test_tree_does_not_depend_on_the_batching_of_insertions(problem, metric, n_chunks):
    X, params = problem
    whole = ClusterTree(metric=metric, **params).fit(X)
    parts = ClusterTree(metric=metric, **params)
    for chunk in np.array_split(X, n_chunks):
        if len(chunk):
            parts.partial_fit(chunk)
    np.testing.assert_array_equal(parts.node_parents_, whole.node_parents_)
    np.testing.assert_array_equal(parts.node_centers_, whole.node_centers_)
    np.testing.assert_array_equal(parts.predict(X), whole.predict(X))


def test_ties_in_the_restart_queue_go_to_the_sibling_skipped_first():
    """Windows on an integer grid give many equal margins in the "restart" queue; the kernels
    break them as the Python reference does (heapq on (priority, push number)). Random data
    almost never has such ties: this grid does (reversing the kernels' tie-break changes an answer)."""
    import itertools

    grid = np.array(list(itertools.product(range(5), repeat=2)), dtype=float)
    X = grid[np.random.default_rng(0).integers(len(grid), size=300)][:, :, None]
    Q = np.concatenate([grid, grid + 0.5])[:, :, None]
    for seed in range(5):
        for priority in ("path", "sibling"):
            params = dict(r_max=0.5, n_max=5, k=3, random_state=seed, restart_priority=priority)
            compiled = ClusterTree(metric="dtw", **params).fit(X)
            python = ClusterTree(metric=_dtw_callable, **params).fit(X)
            for b in (2, 3, 4, 6):
                got = compiled.query_batch(Q, search="restart", backtrack=b)
                ref = python.query_batch(Q, search="restart", backtrack=b)
                for g, r in zip(got, ref):
                    np.testing.assert_array_equal(g, r)
