"""The incremental hierarchical cluster tree (Thesis section 5.2.3, Algorithms 1-2).

The structural rules after random insertions and the agreement of the compiled kernels
(Euclidean and DTW) with the Python path of a callable metric are property tests in
``tests/sound/test_properties.py``.
"""

from __future__ import annotations

import itertools
import pickle
import warnings

import numpy as np
import pytest
from sklearn.cluster import KMeans
from sklearn.exceptions import NotFittedError

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.sound.tree import ClusterTree, _kmeans


def clustered(rng, n, d=6, n_centers=40, spread=0.3):
    """Points around random centres, so leaves, splits and searches all happen."""
    centers = rng.normal(size=(n_centers, d)) * 2.0
    return centers[rng.integers(n_centers, size=n)] + spread * rng.normal(size=(n, d))


def cityblock(q, C):
    return np.abs(C - q).reshape(C.shape[0], -1).sum(axis=1)


@pytest.fixture
def built(rng):
    X = clustered(rng, 3000)
    tree = ClusterTree(0.6, n_max=6, k=2, random_state=0).fit(X)
    return tree, X


# --------------------------------------------------------------------------- structure
def test_radius_rule_against_centroid_at_insertion(rng):
    """A vector joins the greedy-nearest leaf iff within r_max of its centroid *before* it is added;
    otherwise it creates a new leaf under that leaf's father."""
    X = clustered(rng, 1500)
    r_max = 0.6
    tree = ClusterTree(r_max, n_max=6, k=2, random_state=0)
    tree.insert(X[0])
    joined = created = 0
    for x in X[1:]:
        leaf, d = tree.query(x, search="greedy")
        father = tree.ancestors(leaf)[-2]
        n_before = tree.n_leaves_
        center_before = tree.leaf_centers_[leaf].copy()
        size_before = tree.leaf_sizes_[leaf]
        got = tree.insert(x)
        np.testing.assert_allclose(d, np.linalg.norm(x - center_before), rtol=1e-12)
        if d <= r_max:
            joined += 1
            assert got == leaf and tree.n_leaves_ == n_before
            assert tree.leaf_sizes_[leaf] == size_before + 1
            np.testing.assert_allclose(tree.leaf_centers_[leaf], (center_before * size_before + x) / (size_before + 1))
        else:
            created += 1
            assert got == n_before and tree.n_leaves_ == n_before + 1
            assert father in tree.ancestors(got)  # under the same father (or a node a split put below it)
            np.testing.assert_array_equal(tree.leaf_centers_[got], x)
    assert joined > 200 and created > 200


def test_leaf_and_node_ids_are_stable(rng):
    X = clustered(rng, 1200)
    tree = ClusterTree(0.6, n_max=5, k=2, random_state=0)
    tree.insert(X[0])
    splits = 0
    for x in X[1:]:
        nodes_before = tree.n_nodes_
        leaf_nodes = tree.leaf_node_ids_
        node_leaf = tree.node_leaf_ids_
        centers = tree.leaf_centers_.copy()
        sizes = tree.node_sizes_
        leaf = tree.insert(x)
        np.testing.assert_array_equal(tree.leaf_node_ids_[: len(leaf_nodes)], leaf_nodes)
        np.testing.assert_array_equal(tree.node_leaf_ids_[:nodes_before], node_leaf)
        assert (tree.node_sizes_[:nodes_before] >= sizes).all()
        other = np.arange(len(centers)) != leaf
        np.testing.assert_array_equal(tree.leaf_centers_[: len(centers)][other], centers[other])
        splits += tree.n_nodes_ > nodes_before + 1
    assert splits > 50


def test_ancestors_path(built):
    tree, _ = built
    parents = tree.node_parents_
    for leaf in range(0, tree.n_leaves_, 37):
        path = tree.ancestors(leaf)
        assert path[0] == 0 and path[-1] == tree.leaf_node_ids_[leaf]
        assert all(parents[c] == p for p, c in itertools.pairwise(path))
        assert len(path) - 1 <= tree.max_depth_


def test_batching_and_insert_give_the_same_tree(rng):
    X = clustered(rng, 1500)
    a = ClusterTree(0.6, n_max=6, k=3, random_state=5).fit(X)
    b = ClusterTree(0.6, n_max=6, k=3, random_state=5)
    for chunk in np.array_split(X, 7):
        b.partial_fit(chunk)
    c = ClusterTree(0.6, n_max=6, k=3, random_state=5)
    labels = [c.insert(x) for x in X]
    for t in (b, c):
        np.testing.assert_array_equal(t.node_parents_, a.node_parents_)
        np.testing.assert_allclose(t.node_centers_, a.node_centers_, rtol=1e-12)
    np.testing.assert_array_equal(labels, a.labels_)
    np.testing.assert_array_equal(b.labels_, a.labels_[-len(b.labels_):])
    assert b.n_samples_seen_ == len(X)


def test_determinism_and_refit(rng):
    X = clustered(rng, 2000)
    a = ClusterTree(0.6, n_max=6, k=2, random_state=3).fit(X)
    b = ClusterTree(0.6, n_max=6, k=2, random_state=3).fit(X)
    np.testing.assert_array_equal(a.node_parents_, b.node_parents_)
    np.testing.assert_array_equal(a.node_centers_, b.node_centers_)
    np.testing.assert_array_equal(a.predict(X[:200]), b.predict(X[:200]))
    a.fit(X)  # fit resets: same tree again
    np.testing.assert_array_equal(a.node_parents_, b.node_parents_)


# --------------------------------------------------------------------------- searches
def test_exact_search_is_brute_force(built, rng):
    tree, X = built
    Q = np.vstack([X[:100], clustered(rng, 200)])
    leaf, dist, n_eval = tree.query_batch(Q, search="exact")
    D = np.linalg.norm(Q[:, None, :] - tree.leaf_centers_[None], axis=2)
    np.testing.assert_array_equal(leaf, D.argmin(axis=1))
    np.testing.assert_allclose(dist, D.min(axis=1), rtol=1e-12)
    assert (n_eval == tree.n_leaves_).all()


def test_greedy_returns_a_leaf_at_the_reported_distance(built, rng):
    tree, _X = built
    Q = clustered(rng, 300)
    leaf, dist, n_eval = tree.query_batch(Q, search="greedy")
    assert ((leaf >= 0) & (leaf < tree.n_leaves_)).all()
    np.testing.assert_allclose(dist, np.linalg.norm(Q - tree.leaf_centers_[leaf], axis=1), rtol=1e-12)
    # a hand-written greedy descent (thesis: follow the nearest child) finds the same leaf
    centers, leaf_of = tree.node_centers_, tree.node_leaf_ids_
    for q, lf, ne in zip(Q[:50], leaf[:50], n_eval[:50]):
        node, count = 0, 0
        while len(tree.children(node)):
            kids = tree.children(node)
            node = kids[np.argmin(np.linalg.norm(centers[kids] - q, axis=1))]
            count += len(kids)
        assert leaf_of[node] == lf and count == ne
    # query() agrees with query_batch() and counts its distances
    lf, d, ne = tree.query(Q[0], search="greedy", return_stats=True)
    assert (lf, ne) == (leaf[0], n_eval[0]) and tree.last_query_n_distances_ == ne
    assert d == pytest.approx(dist[0], rel=1e-12)


@pytest.mark.parametrize("search", ["restart", "best_children"])
def test_backtracking_is_monotone_and_exhaustive_at_the_limit(built, rng, search):
    tree, _ = built
    Q = clustered(rng, 400)
    exact, exact_d, _ = tree.query_batch(Q, search="exact")
    prev_d, prev_n, recalls = None, None, []
    for b in (1, 2, 4, 8, 32):
        leaf, d, n = tree.query_batch(Q, search=search, backtrack=b)
        recalls.append(np.mean(leaf == exact))
        if prev_d is not None:  # more backtracking explores a superset: never a worse leaf
            assert (d <= prev_d + 1e-12).all() and (n >= prev_n).all()
        prev_d, prev_n = d, n
    assert recalls[0] < 0.9 and recalls[-1] > recalls[0] + 0.1
    big = tree.n_nodes_ if search == "restart" else 2  # best_children: b >= k explores every node
    leaf, d, n = tree.query_batch(Q, search=search, backtrack=big)
    np.testing.assert_array_equal(leaf, exact)
    np.testing.assert_allclose(d, exact_d, rtol=1e-12)


def test_restart_priorities_and_defaults(built, rng):
    tree, _ = built
    Q = clustered(rng, 200)
    default = tree.predict(Q)  # search="restart", backtrack=None -> 12
    np.testing.assert_array_equal(default, tree.predict(Q, search="restart", backtrack=12))
    exact, exact_d, _ = tree.query_batch(Q, search="exact")
    greedy = tree.predict(Q, search="greedy")
    for priority in ("sibling", "path"):
        tree.set_params(restart_priority=priority)  # a search-time parameter: no refit needed
        leaf, d, _ = tree.query_batch(Q, search="restart", backtrack=8)
        assert (d >= exact_d - 1e-12).all() and np.mean(leaf == exact) > np.mean(greedy == exact)
        np.testing.assert_array_equal(tree.predict(Q, search="restart", backtrack=1), greedy)
        np.testing.assert_array_equal(tree.predict(Q, search="restart", backtrack=tree.n_nodes_), exact)


def test_predict_does_not_insert(built):
    tree, X = built
    before = (tree.n_nodes_, tree.node_sizes_.copy(), tree.labels_.copy())
    tree.predict(X[:100] + 10.0)
    tree.query(X[0] + 10.0)
    assert tree.n_nodes_ == before[0]
    np.testing.assert_array_equal(tree.node_sizes_, before[1])
    np.testing.assert_array_equal(tree.labels_, before[2])


# --------------------------------------------------------------------------- metrics and items
def test_other_callable_metric(rng):
    X = clustered(rng, 800)
    tree = ClusterTree(1.0, n_max=6, k=2, metric=cityblock, random_state=0).fit(X)
    Q = clustered(rng, 50)
    leaf, dist, _ = tree.query_batch(Q, search="exact")
    D = np.abs(Q[:, None, :] - tree.leaf_centers_[None]).sum(axis=2)
    np.testing.assert_array_equal(leaf, D.argmin(axis=1))
    np.testing.assert_allclose(dist, D.min(axis=1))
    assert tree.query(Q[0], search="restart", backtrack=4)[1] >= dist[0]


def test_windows_keep_their_shape(rng):
    W = clustered(rng, 600, d=12).reshape(600, 4, 3)
    tree = ClusterTree(0.8, n_max=6, k=2, random_state=0).fit(W)
    assert tree.item_shape_ == (4, 3) and tree.n_features_in_ == 12
    assert tree.leaf_centers_.shape == (tree.n_leaves_, 4, 3)
    flat = ClusterTree(0.8, n_max=6, k=2, random_state=0).fit(W.reshape(600, 12))
    np.testing.assert_array_equal(tree.labels_, flat.labels_)  # Euclidean on windows = on flattened windows
    assert tree.query(W[0])[0] == flat.query(W[0].ravel())[0]


def test_dtw_metric(rng):
    dtw = pytest.importorskip("mmconcepts.sound.dtw")
    W = clustered(rng, 300, d=16).reshape(300, 8, 2)
    tree = ClusterTree(5.0, n_max=6, k=2, metric="dtw", random_state=0).fit(W)
    assert 20 < tree.n_leaves_ < 200
    Q = clustered(rng, 20, d=16).reshape(20, 8, 2)
    leaf, dist, _n = tree.query_batch(Q, search="exact")
    for q, lf, d in zip(Q, leaf, dist):
        ref = dtw.dtw_one_to_many(q, tree.leaf_centers_)
        assert lf == np.argmin(ref) and d == pytest.approx(ref.min())
    greedy = tree.query_batch(Q, search="greedy")[1]
    assert (greedy >= dist - 1e-12).all()
    with pytest.raises(DataError, match="windows of shape"):
        ClusterTree(3.0, metric="dtw").fit(W.reshape(300, 16))


# --------------------------------------------------------------------------- k-means of a split
def inertia(P, labels):
    return sum(((P[labels == j] - P[labels == j].mean(axis=0)) ** 2).sum() for j in np.unique(labels))


def test_split_kmeans_matches_scikit_learn_quality(rng):
    """The compiled k-means++/Lloyd (thesis Algorithm 2) is as good as scikit-learn's on split-sized inputs."""
    ours, theirs = [], []
    for _ in range(60):
        m, k = int(rng.integers(5, 25)), int(rng.integers(2, 5))
        P = clustered(rng, m, d=8, n_centers=4, spread=0.5)
        labels = _kmeans(P, k, rng.random((3, k, 2 + int(np.log(k)))), 100)

        ours.append(inertia(P, labels))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            theirs.append(KMeans(k, n_init=3, random_state=0).fit(P).inertia_)
    ratio = np.array(ours) / np.array(theirs)
    assert np.median(ratio) <= 1.0 + 1e-9 and np.mean(ratio) < 1.03


def test_coinciding_children_are_still_split(rng):
    """Identical centroids make k-means degenerate; the node must still end with < n_max children."""
    x = rng.normal(size=4)
    X = np.repeat(x[None], 60, axis=0)
    tree = ClusterTree(1.0, n_max=4, k=2, metric=lambda q, C: np.full(len(C), 10.0), random_state=0).fit(X)
    assert tree.n_leaves_ == 60
    assert max(len(tree.children(v)) for v in range(tree.n_nodes_)) < 4
    np.testing.assert_allclose(tree.node_centers_, np.broadcast_to(x, tree.node_centers_.shape))


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "params, match",
    [
        ({"r_max": 0.0}, "r_max"),
        ({"r_max": -1.0}, "r_max"),
        ({"r_max": np.nan}, "r_max"),
        ({"r_max": 1.0, "n_max": 3, "k": 3}, "n_max must be at least k \\+ 1"),
        ({"r_max": 1.0, "k": 1}, "k must be"),
        ({"r_max": 1.0, "metric": "cosine"}, "metric"),
        ({"r_max": 1.0, "search": "beam"}, "search"),
        ({"r_max": 1.0, "backtrack": 0}, "backtrack"),
        ({"r_max": 1.0, "restart_priority": "depth"}, "restart_priority"),
    ],
)
def test_bad_parameters(params, match, rng):
    with pytest.raises(ParameterError, match=match):
        ClusterTree(**params).fit(rng.normal(size=(10, 3)))


def test_bad_input(built, rng):
    tree, X = built
    with pytest.raises(NotFittedError):
        ClusterTree(1.0).query(X[0])
    with pytest.raises(NotFittedError):
        _ = ClusterTree(1.0).n_leaves_
    bad = X[:5].copy()
    bad[2, 1] = np.nan
    with pytest.raises(DataError, match="NaN"):
        ClusterTree(1.0).fit(bad)
    with pytest.raises(DataError, match="NaN"):
        tree.partial_fit(bad)
    with pytest.raises(DataError, match="NaN"):
        tree.query(bad[2])  # the compiled fast path checks too
    with pytest.raises(DataError, match="NaN"):
        tree.predict(bad)
    with pytest.raises(DataError, match="shape"):
        tree.query(X[0, :3])
    with pytest.raises(DataError, match="X has 3 features, but ClusterTree is expecting 6"):
        tree.predict(X[:5, :3])
    with pytest.raises(DataError, match="shape"):
        tree.insert(np.ones((2, 3)))
    with pytest.raises(DataError, match="shape"):
        ClusterTree(1.0).fit(np.ones(5))
    with pytest.raises(DataError, match="shape"):
        ClusterTree(1.0).fit(np.ones((2, 3, 4, 5)))
    with pytest.raises(DataError, match="empty"):
        ClusterTree(1.0).fit(np.ones((0, 3)))
    with pytest.raises(DataError, match="real numbers"):
        ClusterTree(1.0).fit(np.array([["a", "b"]]))
    with pytest.raises(DataError, match="Complex data not supported"):
        ClusterTree(1.0).fit(np.ones((3, 2), dtype=complex))
    with pytest.raises(DataError, match="Sparse data"):
        import scipy.sparse as sp

        ClusterTree(1.0).fit(sp.csr_matrix(np.ones((3, 2))))
    with pytest.raises(ParameterError, match="search"):
        tree.query(X[0], search="beam")
    with pytest.raises(ParameterError, match="leaf_id"):
        tree.ancestors(tree.n_leaves_)
    with pytest.raises(ParameterError, match="one distance per candidate"):
        ClusterTree(1.0, metric=lambda q, C: np.zeros(3)).fit(X[:20])
    # state is untouched by the failed calls
    assert tree.n_samples_seen_ == len(X)


def test_accepts_lists_float32_and_pickles(built):
    tree, X = built
    t32 = ClusterTree(0.6, n_max=6, k=2, random_state=0).fit(X.astype(np.float32))
    assert t32.leaf_centers_.dtype == np.float64
    assert tree.query(list(X[0]))[0] == tree.query(X[0])[0]
    assert t32.query(X[0].astype(np.float32))[0] == t32.query(X[0].astype(np.float32).astype(np.float64))[0]
    clone = pickle.loads(pickle.dumps(tree))
    np.testing.assert_array_equal(clone.predict(X[:100]), tree.predict(X[:100]))
    clone.partial_fit(X[:50])  # a restored tree keeps growing
    assert clone.n_samples_seen_ == len(X) + 50
