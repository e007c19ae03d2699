"""The incremental hierarchical cluster tree of acoustic events (Thesis section 5.2.3).

Fixed-length MFCC windows ("CAF vectors", 80 or 150 ms) are grouped on line into
*acoustic events*: the leaves of a tree whose rules are (thesis section 5.2.3, rules 1-3):

1. every leaf or node is a cluster ``C`` represented by its centroid ``v_C``;
2. a leaf is a hypersphere of radius ``r_max`` around its centroid: a vector ``v`` joins
   leaf ``C`` if and only if ``d(v, v_C) <= r_max``;
3. a node has fewer than ``N_max`` children; its centroid is the mean of all the vectors
   it contains (so it is the count-weighted mean of its children's centroids).

Insertion (thesis Algorithm 1, Fig. 5.2): descend from the root to the nearest child
until the children are leaves, take the nearest leaf; if the vector is within ``r_max``
of its centroid it joins it, else a new leaf holding only the vector is created under the
same father; if the father now has ``N_max`` children or more, its children are
partitioned into (up to) ``k`` groups by k-means on their centroids (thesis Algorithm 2)
and the father gets one new node per group, whose children are that group.

Retrieval is the same descent. The descent is an approximate nearest-leaf search; the
thesis gives two backtracking variants, both here (``search=``): ``"best_children"``
recurses into the ``b`` children closest to the query at every node, ``"restart"`` runs
``b`` full greedy descents, the first from the root and each next one from the skipped
sibling that was the least farther than the child chosen instead of it (a priority queue,
as branch-and-bound; by default the margins are summed along the path from the root, see
``restart_priority``), and keeps the best leaf seen. ``"exact"`` compares the query with
every leaf (the reference). Every search reports how many distances it evaluated.

Everything lives in flat, growable numpy arrays (parent, fixed-width children table,
sums and counts of the vectors below every node, cached centroids); with either built-in
metric, insertion and every search run in one set of numba kernels written here by hand
(no maintained library implements this tree: scikit-learn's trees are static and FLANN's
hierarchical k-means tree is not incremental). For ``metric="dtw"`` the kernels call the
compiled DTW of :mod:`mmconcepts.sound.dtw` (the lane kernel of
:func:`~mmconcepts.sound.dtw.dtw_one_to_many`, same values bit for bit). Only a user's
callable metric runs in Python (``ClusterTree._insert_generic`` and ``_search_generic``,
the same algorithm, which the tests use as the reference of the kernels).

Identifiers
-----------
*Leaf ids* ``0 .. n_leaves_ - 1`` number the acoustic events in their order of creation.
*Node ids* ``0 .. n_nodes_ - 1`` number every node, leaves included, in order of
creation; the root is node 0. Neither is ever renumbered: a split adds new internal
nodes between the father and its children and keeps every existing id.
``leaf_node_ids_[leaf]`` is the node id of a leaf and :meth:`ClusterTree.ancestors` the
node ids from the root down to it, for vocabularies where every node is an event
(thesis section 5.2.3, "Semantic tag inference").
"""

from __future__ import annotations

import heapq
import numbers
from collections.abc import Callable
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import ArrayLike
import scipy.sparse as sp
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils.validation import check_is_fitted

from .._jit import njit
from .._persist import SaveLoadMixin
from .._validation import Interval, Options, check_random_state, validate_params
from ..errors import DataError, DataFormatError, ParameterError
from .dtw import dtw_to_rows

__all__ = ["SEARCHES", "ClusterTree"]

#: Retrieval strategies of :meth:`ClusterTree.query`, with their codes in the kernels.
SEARCHES = {"greedy": 0, "best_children": 1, "restart": 2, "exact": 3}

#: ``backtrack=None`` means this value for each search (see :class:`ClusterTree`).
DEFAULT_BACKTRACK = {"greedy": 1, "best_children": 2, "restart": 12, "exact": 1}

# k-means of a split: k-means++ seeding then Lloyd iterations, best of a few seedings.
_KMEANS_N_INIT = 3
_KMEANS_MAX_ITER = 100

# Same options as nmf/_kernels.py: reassociation lets LLVM vectorise the distance loops.
_OPTS: dict[str, Any] = {"nogil": True, "cache": True, "fastmath": {"reassoc", "contract"}, "error_model": "numpy"}

# Metric codes of the kernels (user callables run in Python, see ClusterTree._search_generic).
# The kernels' numba cache (cache=True) holds the compiled DTW of dtw.py they call, and numba
# invalidates a cache only when its own source file changes: after editing the kernels of
# dtw.py, touch this file (or delete its cache files in __pycache__).
_EUCLIDEAN, _DTW = 0, 1
_METRIC_CODES = {"euclidean": _EUCLIDEAN, "dtw": _DTW}

# Leaves compared with the query per DTW call of the exhaustive search.
_EXACT_CHUNK = 256


# --------------------------------------------------------------------------- numba kernels
@njit(**_OPTS)
def _dist(center, i, q):  # pragma: no cover - compiled
    """Euclidean distance between row ``i`` of ``center`` and ``q``."""
    s = 0.0
    for t in range(q.shape[0]):
        e = center[i, t] - q[t]
        s += e * e
    return np.sqrt(s)


@njit(**_OPTS)
def _dist2(center, i, q):  # pragma: no cover - compiled
    """Squared Euclidean distance between row ``i`` of ``center`` and ``q``."""
    s = 0.0
    for t in range(q.shape[0]):
        e = center[i, t] - q[t]
        s += e * e
    return s


@njit(**_OPTS)
def _node_dists(metric, T, center, ids, q, cand, dbuf):  # pragma: no cover - compiled
    """dbuf[j] = d(q, centroid of node ids[j]) for every j: Euclidean (metric 0) or DTW on
    (T, d) windows (metric 1, :func:`mmconcepts.sound.dtw.dtw_to_rows`; ``cand`` is its
    work buffer)."""
    if metric == _EUCLIDEAN:
        for j in range(ids.shape[0]):
            dbuf[j] = _dist(center, ids[j], q)
    else:
        dtw_to_rows(q, T, center, ids, cand, dbuf)


@njit(nogil=True, cache=True, error_model="numpy")  # no fastmath: the rounding of the reference
def _margin(base, d, d_min):  # pragma: no cover - compiled
    """Priority of a skipped sibling: ``base + (d - d_min)``, rounded as written."""
    return base + (d - d_min)


@njit(**_OPTS)
def _heap_less(hp, hs, i, j):  # pragma: no cover - compiled
    """Entry i before entry j: smaller priority, then earlier push (as heapq on (priority, seq))."""
    return hp[i] < hp[j] or (hp[i] == hp[j] and hs[i] < hs[j])


@njit(**_OPTS)
def _heap_push(hp, hn, hs, size, p, n, s):  # pragma: no cover - compiled
    """Push (priority p, node n, push number s) on the binary min-heap (hp, hn, hs) of ``size`` items."""
    i = size
    hp[i] = p
    hn[i] = n
    hs[i] = s
    while i > 0:
        par = (i - 1) >> 1
        if not _heap_less(hp, hs, i, par):
            break
        hp[par], hp[i] = hp[i], hp[par]
        hn[par], hn[i] = hn[i], hn[par]
        hs[par], hs[i] = hs[i], hs[par]
        i = par
    return size + 1


@njit(**_OPTS)
def _heap_pop(hp, hn, hs, size):  # pragma: no cover - compiled
    """Drop the top of the heap (read hn[0] first); return the new size."""
    size -= 1
    hp[0] = hp[size]
    hn[0] = hn[size]
    hs[0] = hs[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and _heap_less(hp, hs, c + 1, c):
            c += 1
        if not _heap_less(hp, hs, c, i):
            break
        hp[c], hp[i] = hp[i], hp[c]
        hn[c], hn[i] = hn[i], hn[c]
        hs[c], hs[i] = hs[i], hs[c]
        i = c
    return size


@njit(**_OPTS)
def _scan_leaves(metric, T, center, child, node, m, q, best, best_key, cand, dbuf):  # pragma: no cover - compiled
    """Nearest of the ``m`` leaf children of ``node`` if nearer than ``best``: (best, its key).

    The key is the squared distance for the Euclidean metric, the distance for DTW.
    """
    if metric == _EUCLIDEAN:
        for j in range(m):
            c = child[node, j]
            d2 = _dist2(center, c, q)
            if d2 < best_key:
                best_key = d2
                best = c
        return best, best_key
    _node_dists(metric, T, center, child[node, :m], q, cand, dbuf)
    for j in range(m):
        if dbuf[j] < best_key:
            best_key = dbuf[j]
            best = child[node, j]
    return best, best_key


@njit(**_OPTS)
def _argmin(dbuf, m):  # pragma: no cover - compiled
    """(first index of the smallest of dbuf[:m], that value); (0, inf) if none is < inf."""
    jm = 0
    dm = np.inf
    for j in range(m):
        if dbuf[j] < dm:
            dm = dbuf[j]
            jm = j
    return jm, dm


@njit(**_OPTS)
def _search_one(q, metric, T, mode, b, path_priority, center, child, nchild, leaf_of, node_of_leaf, n_leaves, hp,
                hn, hs, dbuf, cand):  # pragma: no cover - compiled
    """Nearest leaf of ``q``: returns (leaf node id, distance, distance evaluations).

    ``metric`` 0 is Euclidean on the flattened items, 1 DTW on (T, d) windows. mode 0
    greedy descent, 1 best-children backtracking (b children per node), 2 restart
    backtracking (b descents; a skipped sibling's priority is its margin over the chosen
    child, plus, if ``path_priority``, the priority of the node the descent started
    from; ties go to the sibling skipped first), 3 exhaustive. hp, hn, hs (>= n_nodes + 1)
    and dbuf (>= n_max, and >= the exhaustive chunk for DTW) are work buffers, cand the
    DTW's (see :func:`_work_buffers`). The node id is -1 for an empty tree and -2 if ``q``
    holds NaN or infinite values.
    """
    for t in range(q.shape[0]):
        if not np.isfinite(q[t]):
            return -2, np.nan, 0
    euclid = metric == _EUCLIDEAN
    best = -1
    best_key = np.inf
    n_eval = 0
    if mode == 3:
        if euclid:
            for leaf in range(n_leaves):
                node = node_of_leaf[leaf]
                d2 = _dist2(center, node, q)
                if d2 < best_key:
                    best_key = d2
                    best = node
            return best, np.sqrt(best_key), n_leaves
        for l0 in range(0, n_leaves, _EXACT_CHUNK):
            ids = node_of_leaf[l0 : min(n_leaves, l0 + _EXACT_CHUNK)]
            _node_dists(metric, T, center, ids, q, cand, dbuf)
            for j in range(ids.shape[0]):
                if dbuf[j] < best_key:
                    best_key = dbuf[j]
                    best = ids[j]
        return best, best_key, n_leaves
    if nchild[0] == 0:
        return best, np.inf, n_eval
    if mode == 1:
        top = 1
        hn[0] = 0
        while top > 0:
            top -= 1
            node = hn[top]
            m = nchild[node]
            if leaf_of[child[node, 0]] >= 0:
                best, best_key = _scan_leaves(metric, T, center, child, node, m, q, best, best_key, cand, dbuf)
                n_eval += m
                continue
            _node_dists(metric, T, center, child[node, :m], q, cand, dbuf)
            n_eval += m
            for _ in range(min(b, m)):  # the b nearest, nearest pushed first (explored last)
                jm, _dm = _argmin(dbuf, m)
                hn[top] = child[node, jm]
                top += 1
                dbuf[jm] = np.inf
        return best, (np.sqrt(best_key) if euclid else best_key), n_eval
    n_desc = 1 if mode == 0 else b
    size = _heap_push(hp, hn, hs, 0, 0.0, 0, 0)
    n_push = 1
    descents = 0
    while descents < n_desc and size > 0:
        node = hn[0]
        base = hp[0] if path_priority else 0.0
        size = _heap_pop(hp, hn, hs, size)
        descents += 1
        while True:
            m = nchild[node]
            if m == 0:
                break
            if leaf_of[child[node, 0]] >= 0:
                best, best_key = _scan_leaves(metric, T, center, child, node, m, q, best, best_key, cand, dbuf)
                n_eval += m
                break
            _node_dists(metric, T, center, child[node, :m], q, cand, dbuf)
            jm, dm = _argmin(dbuf, m)
            n_eval += m
            if n_desc > 1:
                # Memorise the skipped siblings with how much farther they were than the
                # chosen child (thesis section 5.2.3, second backtracking method).
                for j in range(m):
                    if j != jm:
                        size = _heap_push(hp, hn, hs, size, _margin(base, dbuf[j], dm), child[node, j], n_push)
                        n_push += 1
            node = child[node, jm]
    return best, (np.sqrt(best_key) if euclid else best_key), n_eval


@njit(**_OPTS)
def _work_buffers(metric, n_nodes, n_max, D):  # pragma: no cover - compiled
    """The work buffers of :func:`_search_one` and :func:`_insert_batch`: hp, hn, hs, dbuf, cand."""
    rows = n_max if metric == _EUCLIDEAN else max(n_max, _EXACT_CHUNK)
    cand = np.empty(rows * D if metric != _EUCLIDEAN else 0)
    return (np.empty(n_nodes + 1), np.empty(n_nodes + 1, dtype=np.int64), np.empty(n_nodes + 1, dtype=np.int64),
            np.empty(rows), cand)


@njit(**_OPTS)
def _query_one(q, metric, T, mode, b, path_priority, center, child, nchild, leaf_of, node_of_leaf, n_nodes,
               n_leaves):  # pragma: no cover - compiled
    """:func:`_search_one` with its own work buffers (so concurrent queries are safe)."""
    hp, hn, hs, dbuf, cand = _work_buffers(metric, n_nodes, child.shape[1], q.shape[0])
    return _search_one(q, metric, T, mode, b, path_priority, center, child, nchild, leaf_of, node_of_leaf, n_leaves,
                       hp, hn, hs, dbuf, cand)


@njit(compile_apart=True, **_OPTS)
def _search_batch(Q, metric, T, mode, b, path_priority, center, child, nchild, leaf_of, node_of_leaf, n_nodes,
                  n_leaves, out_node, out_d, out_n):  # pragma: no cover - compiled
    """:func:`_search_one` for every row of ``Q``."""
    hp, hn, hs, dbuf, cand = _work_buffers(metric, n_nodes, child.shape[1], Q.shape[1])
    for i in range(Q.shape[0]):
        node, d, n = _search_one(Q[i], metric, T, mode, b, path_priority, center, child, nchild, leaf_of,
                                 node_of_leaf, n_leaves, hp, hn, hs, dbuf, cand)
        out_node[i] = node
        out_d[i] = d
        out_n[i] = n


@njit(**_OPTS)
def _add_path(node, x, parent, sums, count, center):  # pragma: no cover - compiled
    """Add vector ``x`` to ``node`` and to every ancestor of it (sums, counts, centroids)."""
    while node >= 0:
        count[node] += 1
        inv = 1.0 / count[node]
        for t in range(x.shape[0]):
            sums[node, t] += x[t]
            center[node, t] = sums[node, t] * inv
        node = parent[node]


@njit(**_OPTS)
def _new_leaf(father, x, parent, child, nchild, sums, count, center, leaf_of, node_of_leaf,
              n_nodes, n_leaves):  # pragma: no cover - compiled
    """Create a leaf holding only ``x`` under ``father``; returns its node id."""
    new = n_nodes
    parent[new] = father
    nchild[new] = 0
    leaf_of[new] = n_leaves
    node_of_leaf[n_leaves] = new
    count[new] = 0
    for t in range(x.shape[0]):
        sums[new, t] = 0.0
    child[father, nchild[father]] = new
    nchild[father] += 1
    _add_path(new, x, parent, sums, count, center)
    return new


@njit(compile_apart=True, **_OPTS)
def _insert_batch(X, start, metric, T, r_max, n_max, parent, child, nchild, sums, count, center, leaf_of,
                  node_of_leaf, n_nodes, n_leaves, out):  # pragma: no cover - compiled
    """Thesis Algorithm 1 for rows ``start, start + 1, ...`` of ``X`` (metric as :func:`_search_one`).

    Stops after a row that leaves a node with ``n_max`` children (the caller splits it)
    or before a row when the arrays are full. Returns (next row, n_nodes, n_leaves,
    node to split or -1); ``out[i]`` receives the leaf id of row ``i``.
    """
    cap = parent.shape[0]
    _hp, _hn, _hs, dbuf, cand = _work_buffers(metric, 0, child.shape[1], X.shape[1])
    for i in range(start, X.shape[0]):
        if n_nodes + 1 > cap:
            return i, n_nodes, n_leaves, -1
        x = X[i]
        node = 0
        while nchild[node] > 0 and leaf_of[child[node, 0]] < 0:
            m = nchild[node]
            _node_dists(metric, T, center, child[node, :m], x, cand, dbuf)
            jm, _dm = _argmin(dbuf, m)
            node = child[node, jm]
        best = -1
        dm = np.inf
        m = nchild[node]
        if m > 0:
            _node_dists(metric, T, center, child[node, :m], x, cand, dbuf)
            jm, dm = _argmin(dbuf, m)
            if dm < np.inf:
                best = child[node, jm]
        if best >= 0 and dm <= r_max:
            _add_path(best, x, parent, sums, count, center)
            out[i] = leaf_of[best]
            continue
        _new_leaf(node, x, parent, child, nchild, sums, count, center, leaf_of, node_of_leaf, n_nodes, n_leaves)
        out[i] = n_leaves
        n_nodes += 1
        n_leaves += 1
        if nchild[node] >= n_max:
            return i + 1, n_nodes, n_leaves, node
    return X.shape[0], n_nodes, n_leaves, -1


@njit(compile_apart=True, **_OPTS)
def _kmeans(P, k, u, max_iter):  # pragma: no cover - compiled
    """Thesis Algorithm 2 on the rows of ``P``: greedy k-means++ seeding (as scikit-learn:
    each new centre is the best of ``u.shape[2]`` candidates drawn with probability
    proportional to the squared distance, uniforms ``u[r]``), then Lloyd iterations until
    the assignments stop changing; best of ``u.shape[0]`` seedings. Returns the labels
    (clusters may be empty when points coincide)."""
    m, D = P.shape
    n_trials = u.shape[2]
    best_labels = np.zeros(m, dtype=np.int64)
    best_inertia = np.inf
    C = np.empty((k, D))
    d2 = np.empty(m)
    labels = np.empty(m, dtype=np.int64)
    cnt = np.empty(k)
    for r in range(u.shape[0]):
        # greedy k-means++ seeding
        first = min(int(u[r, 0, 0] * m), m - 1)
        for t in range(D):
            C[0, t] = P[first, t]
        for i in range(m):
            s = 0.0
            for t in range(D):
                e = P[i, t] - C[0, t]
                s += e * e
            d2[i] = s
        for j in range(1, k):
            total = d2.sum()
            pick = -1
            pick_pot = np.inf
            for tr in range(n_trials):
                c = m - 1
                if total > 0.0:
                    thr = u[r, j, tr] * total
                    acc = 0.0
                    for i in range(m):
                        acc += d2[i]
                        if acc > thr:
                            c = i
                            break
                else:
                    c = min(int(u[r, j, tr] * m), m - 1)
                pot = 0.0
                for i in range(m):
                    s = 0.0
                    for t in range(D):
                        e = P[i, t] - P[c, t]
                        s += e * e
                    pot += min(s, d2[i])
                if pot < pick_pot:
                    pick_pot = pot
                    pick = c
            for t in range(D):
                C[j, t] = P[pick, t]
            for i in range(m):
                s = 0.0
                for t in range(D):
                    e = P[i, t] - C[j, t]
                    s += e * e
                d2[i] = min(d2[i], s)
        # Lloyd
        for i in range(m):
            labels[i] = -1
        inertia = 0.0
        for it in range(max_iter + 1):
            changed = False
            inertia = 0.0
            for i in range(m):
                bj = 0
                bd = np.inf
                for j in range(k):
                    s = 0.0
                    for t in range(D):
                        e = P[i, t] - C[j, t]
                        s += e * e
                    if s < bd:
                        bd = s
                        bj = j
                inertia += bd
                if labels[i] != bj:
                    labels[i] = bj
                    changed = True
            if not changed or it == max_iter:
                break
            for j in range(k):
                cnt[j] = 0.0
            for i in range(m):
                cnt[labels[i]] += 1.0
            for j in range(k):
                if cnt[j] > 0:  # an empty cluster keeps its centre
                    for t in range(D):
                        C[j, t] = 0.0
            for i in range(m):
                j = labels[i]
                for t in range(D):
                    C[j, t] += P[i, t]
            for j in range(k):
                if cnt[j] > 0:
                    for t in range(D):
                        C[j, t] /= cnt[j]
        if inertia < best_inertia:
            best_inertia = inertia
            best_labels[:] = labels
    return best_labels


@njit(**_OPTS)
def _apply_split(father, labels, k, parent, child, nchild, sums, count, center, leaf_of,
                 n_nodes):  # pragma: no cover - compiled
    """Replace the children of ``father`` by one new node per non-empty label group, each
    holding its group (thesis Algorithm 1, "set new nodes as the children of father").
    Returns the new number of nodes."""
    m = nchild[father]
    old = child[father, :m].copy()
    nchild[father] = 0
    D = sums.shape[1]
    for j in range(k):
        new = -1
        for i in range(m):
            if labels[i] != j:
                continue
            if new < 0:
                new = n_nodes
                n_nodes += 1
                parent[new] = father
                nchild[new] = 0
                leaf_of[new] = -1
                count[new] = 0
                for t in range(D):
                    sums[new, t] = 0.0
                child[father, nchild[father]] = new
                nchild[father] += 1
            c = old[i]
            child[new, nchild[new]] = c
            nchild[new] += 1
            parent[c] = new
            count[new] += count[c]
            for t in range(D):
                sums[new, t] += sums[c, t]
        if new >= 0:
            inv = 1.0 / count[new]
            for t in range(D):
                center[new, t] = sums[new, t] * inv
    return n_nodes


# --------------------------------------------------------------------------- the estimator
class ClusterTree(SaveLoadMixin, ClusterMixin, BaseEstimator):
    """Incremental hierarchical clustering of sound windows into acoustic events (Thesis 5.2.3).

    Leaves ("primitive clusters", the acoustic events) are balls of radius ``r_max``
    around their centroid; nodes have fewer than ``n_max`` children and are split by
    k-means into ``k`` new nodes when they reach ``n_max`` (thesis Algorithm 1). The
    centroid of a leaf or node ``C`` is the mean of the vectors it contains,

    .. math:: v_C = \\frac{1}{|C|} \\sum_{v \\in C} v, \\qquad
              v \\text{ joins leaf } C \\iff d(v, v_C) \\le r_{\\max}
              \\quad \\text{(thesis section 5.2.3, rules 1-3)}

    Parameters
    ----------
    r_max : float > 0
        Radius of the leaves, in the units of ``metric``. It sets the size of the
        vocabulary and has no default: it depends on the scale of the features (choose it
        from the distribution of nearest-neighbour distances of your windows).
    n_max : int, default=24
        Maximum number of children of a node, ``N_max``: a node that reaches it is split.
        Must be at least ``k + 1`` (otherwise a split would not reduce the count).
    k : int, default=12
        Number of groups of the k-means split. The thesis gives no value for the
        experiments (its Fig. 5.2 illustrates ``N_max = 3, k = 2``). A node that was
        split keeps its ``k`` children for ever (new leaves only go to nodes whose
        children are leaves), so ``k`` is the fan-out of the internal levels and
        ``n_max`` that of the last one. On the ~20 000-leaf MFCC-like windows of
        ``benchmarks/tree.py``, the distance evaluations the "restart" search needs
        for a recall@1 of 0.9 were (two seeds each): 620-850 for (n_max, k) = (10, 2),
        305-345 for (16, 4), 310-320 for (12, 6), 195-205 for (20, 8), 170-175 for
        (24, 12) and 155-160 for (32, 16): wide, shallow trees (k = n_max / 2, depth 6
        instead of 26 for (10, 2)) misroute less; the gain levels off after (24, 12).
    metric : {"euclidean", "dtw"} or callable, default="euclidean"
        Distance between windows. "euclidean" works on the flattened windows; "dtw" is
        :func:`mmconcepts.sound.dtw.dtw_one_to_many`'s distance (Euclidean frame cost,
        no window) on (T, d) windows, as in the thesis; both run in compiled kernels. A
        callable ``metric(query, candidates) -> (n,)`` receives one item and an
        ``(n, *item_shape)`` stack of centroids, and runs in Python.
    search : {"greedy", "best_children", "restart", "exact"}, default="restart"
        Default retrieval strategy of :meth:`query` and :meth:`predict` (insertion always
        uses the greedy descent of thesis Algorithm 1). "restart" is the thesis' second
        backtracking method, which it found to give the better trade-off (so do we).
    backtrack : int >= 1, optional
        The backtracking parameter ``b``: children explored per node for
        "best_children", number of descents for "restart" (ignored by "greedy" and
        "exact"). None means 2 for "best_children" and 12 for "restart": with the
        default ``n_max`` and ``k``, 12 descents gave a recall@1 of 0.93-0.94 against
        exhaustive search on ``benchmarks/tree.py`` (~20 000 leaves) for about 255
        distance evaluations, 1/80 of the exhaustive search (8 descents: 0.91-0.92);
        raise it for more recall.
        With ``k = 2``, "best_children" with ``b >= 2`` visits the whole tree.
    restart_priority : {"path", "sibling"}, default="path"
        Which skipped node the "restart" search descends from next. The thesis memorises
        each skipped sibling "with some value representing how far [it was] from the
        chosen child": "sibling" uses that margin ``d(q, s) - d(q, c)`` alone; "path"
        adds the priority of the node the current descent started from, i.e. the sum of
        the margins by which the path to ``s`` left the greedy choices since the root.
        On ``benchmarks/tree.py`` (defaults, two seeds) both needed about 180 distance
        evaluations for a recall@1 of 0.9; "path" needed 10-20 % fewer for 0.93 and
        25-40 % fewer for 0.95.
    random_state : int, numpy.random.Generator or None
        Seeds the k-means++ seedings of the splits. Resolved once per :meth:`fit` (or
        first :meth:`partial_fit`): a given int gives the same tree for the same data in
        the same order, whatever the batching of :meth:`partial_fit` calls.

    Attributes
    ----------
    labels_ : ndarray of int64, shape (n_samples,)
        Leaf id each vector of the last :meth:`fit` / :meth:`partial_fit` call was put
        in, at the time of its insertion (the leaf it joined or the leaf it created).
    item_shape_ : tuple
        Shape of one item: ``(d,)`` for vectors, ``(T, d)`` for windows.
    n_features_in_ : int
        Number of values of one item (``prod(item_shape_)``).
    n_samples_seen_ : int
        Vectors inserted since the last :meth:`fit`.
    n_leaves_, n_nodes_ : int
        Number of leaves (acoustic events) and of nodes (leaves and root included).
    leaf_centers_ : ndarray of shape ``(n_leaves_, *item_shape_)``
        Centroid of every leaf (the mean of its vectors), by leaf id.
    leaf_sizes_ : ndarray of int64, shape ``(n_leaves_,)``
        Number of vectors in every leaf.
    leaf_node_ids_ : ndarray of int64, shape ``(n_leaves_,)``
        Node id of every leaf.
    node_centers_ : ndarray of shape ``(n_nodes_, *item_shape_)``
    node_sizes_ : ndarray of int64, shape ``(n_nodes_,)``
    node_parents_ : ndarray of int64, shape ``(n_nodes_,)``
        Parent node id (-1 for the root).
    node_leaf_ids_ : ndarray of int64, shape ``(n_nodes_,)``
        Leaf id of every node, -1 for internal nodes.
    max_depth_ : int
        Number of edges on the longest root-to-leaf path.
    last_query_n_distances_ : int
        Distances computed by the last :meth:`query` (set by :meth:`query` only).

    Notes
    -----
    *Saving.* A fitted tree saves and loads without pickle (:meth:`save`, :meth:`load`):
    its nodes are stored as arrays (parents, children, sums, counts, centroids) with the
    state of its random generator, so a loaded tree answers queries as the saved one and
    keeps growing as it would have. A tree with a callable ``metric`` cannot be saved.

    *Radius.* A vector joins a leaf when its distance to the leaf's centroid *at the time
    of insertion* (before the vector is added) is at most ``r_max`` (thesis rule 2).
    Centroids then move as vectors arrive, so an early vector may later be farther than
    ``r_max`` from its leaf's current centroid; the thesis does not re-assign vectors and
    neither does this class. (The thesis' Algorithm 1 writes "the nearest vector in
    current node" instead of the centroid; we follow rule 2, which keeps leaves bounded
    and needs no stored vectors.)

    *Centroids of windows.* Centroids are element-wise means, also for (T, d) windows
    compared with DTW. For fixed-length windows this is well defined and is what the
    thesis' rule 3 says; it is not a DTW barycentre, so with ``metric="dtw"`` an internal
    node's centroid is a blurred summary of its windows, used only to orient the search.
    The k-means of a split always uses the Euclidean distance between (flattened)
    centroids, as thesis Algorithm 2 does.

    *k-means.* Splits cluster at most ``n_max`` points, hundreds to thousands of times per
    tree. scikit-learn's ``KMeans`` spends most of such a call on input validation and
    thread pools; the compiled k-means here (scikit-learn's greedy k-means++ seeding, then
    Lloyd iterations, best of 3 seedings drawn from ``random_state``) is orders of magnitude
    faster on these small groups (``benchmarks/README.md``), with the same inertia as
    ``KMeans(n_init=3)`` on average (tested). When points coincide and a group is empty,
    the father gets fewer than ``k`` new nodes; if all points coincide, the children are
    dealt into ``k`` groups in order, so that every node keeps fewer than ``n_max``
    children.

    Examples
    --------
    >>> import numpy as np
    >>> from mmconcepts.sound.tree import ClusterTree
    >>> X = np.random.default_rng(0).normal(size=(2000, 4))
    >>> tree = ClusterTree(1.0, random_state=0).fit(X)
    >>> tree.n_leaves_, tree.n_nodes_, tree.leaf_centers_.shape
    (331, 440, (331, 4))
    >>> leaf, dist, cost = tree.query(X[0], return_stats=True)  # restart search, b = 12
    >>> leaf == tree.query(X[0], search="exact")[0], cost < tree.n_leaves_
    (True, True)
    >>> tree.ancestors(leaf)  # node ids, root first: events at every scale
    [0, 27, 1]
    """

    def __init__(
        self,
        r_max: float,
        *,
        n_max: int = 24,
        k: int = 12,
        metric: Literal["euclidean", "dtw"] | Callable[[np.ndarray, np.ndarray], ArrayLike] = "euclidean",
        search: Literal["greedy", "best_children", "restart", "exact"] = "restart",
        backtrack: int | None = None,
        restart_priority: Literal["path", "sibling"] = "path",
        random_state: Any = None,
    ) -> None:
        self.r_max = r_max
        self.n_max = n_max
        self.k = k
        self.metric = metric
        self.search = search
        self.backtrack = backtrack
        self.restart_priority = restart_priority
        self.random_state = random_state

    _parameter_constraints: dict[str, list] = {
        "r_max": [Interval("real", 0, None, closed="neither")],
        "n_max": [Interval("int", 1, None)],
        "k": [Interval("int", 2, None)],
        "metric": [Options("euclidean", "dtw"), "callable"],
        "search": [Options(*SEARCHES)],
        "backtrack": [Interval("int", 1, None), None],
        "restart_priority": [Options("path", "sibling")],
        "random_state": ["random_state"],
    }
    _HINTS = {
        "r_max": "Choose it from the distribution of nearest-neighbour distances of the windows.",
        "metric": "A callable takes (query, candidates) and returns one distance per candidate.",
        "backtrack": "Use None for the default of the search.",
    }

    # ------------------------------------------------------------------ validation
    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints, hints=self._HINTS)
        if self.n_max < self.k + 1:
            raise ParameterError(
                f"ClusterTree: n_max must be at least k + 1 = {self.k + 1} (a node with n_max children is split "
                f"into k nodes, which must be fewer than n_max); got n_max={self.n_max}, k={self.k}."
            )

    def _resolve_search(self, search: Any, backtrack: Any) -> tuple[str, int]:
        """The search and its backtracking parameter ``b`` (the search's default for None)."""
        b = DEFAULT_BACKTRACK.get(search) if isinstance(search, str) and backtrack is None else backtrack
        if not (isinstance(search, str) and search in SEARCHES and type(b) is int and b >= 1):
            # only unusual values reach the full check (query is called once per window)
            validate_params({"search": search, "backtrack": backtrack},
                            {n: self._parameter_constraints[n] for n in ("search", "backtrack")},
                            owner=type(self).__name__, hints=self._HINTS)
            b = int(cast(int, b))  # valid now: an int >= 1, or the search's default
        return search, b

    def _check_items(self, X: Any, name: str, *, single: bool) -> np.ndarray:
        """Validate items against ``item_shape_`` (or fix it); returns float64, C-contiguous.

        Messages follow scikit-learn's wording where its estimator checks look for it.
        """
        if sp.issparse(X):
            raise DataError(
                f"Sparse data was passed for {name}, but dense data is required: the tree stores dense "
                f"centroids. Use {name}.toarray() to convert to a dense numpy array."
            )
        try:
            X = np.asarray(X)
        except ValueError as exc:  # ragged nested lists
            raise DataError(f"{name} must be an array of numbers with one shape; {exc}") from exc
        if np.iscomplexobj(X):
            raise DataError(f"Complex data not supported: {name} holds complex numbers; give real numbers.")
        if X.dtype == object:
            X = X.astype(np.float64)  # a TypeError names any element that is not a number
        elif not (np.issubdtype(X.dtype, np.number) or X.dtype == bool):
            raise DataError(f"{name} must hold real numbers; got dtype {X.dtype}.")
        X = np.ascontiguousarray(X, dtype=np.float64)
        shape = getattr(self, "item_shape_", None)
        item_ndim = X.ndim if single else X.ndim - 1
        if shape is None:
            if item_ndim not in (1, 2):
                what = "one item of shape (d,) or (T, d)" if single else "an array of shape (n, d) or (n, T, d)"
                raise DataError(
                    f"{name} must be {what}; got an array of shape {X.shape}. Reshape your data, e.g. with "
                    f"{name}.reshape(-1, 1) for a single feature or {name}.reshape(1, -1) for a single sample."
                )
            if self.metric == "dtw" and item_ndim != 2:
                raise DataError(
                    f"metric='dtw' compares sequences: {name} must be windows of shape (n, T, d); got shape "
                    f"{X.shape}. Reshape flattened windows with X.reshape(n, T, d)."
                )
        else:
            got = X.shape if single else X.shape[1:]
            if got != shape:
                if not single and len(shape) == 1 and X.ndim == 2:
                    raise DataError(
                        f"{name} has {X.shape[1]} features, but {type(self).__name__} is expecting {shape[0]} "
                        "features as input."
                    )
                what = f"{shape}" if single else f"(n, {', '.join(map(str, shape))})"
                raise DataError(
                    f"{name} must have shape {what} like the items the tree was built with; got {X.shape}. "
                    "Reshape your data, e.g. with X.reshape(1, -1) if it contains a single sample."
                )
        if not single and X.shape[0] == 0:
            raise DataError(f"{name} is empty: 0 sample(s) (shape={X.shape}) while a minimum of 1 is required.")
        if min(X.shape[int(not single):], default=1) == 0:
            raise DataError(
                f"{name} is empty: 0 feature(s) (shape={X.shape}) while a minimum of 1 is required."
            )
        if not np.isfinite(X).all():
            n_bad = int(X.size - np.isfinite(X).sum())
            raise DataError(f"{name} contains {n_bad} NaN or infinite value(s); remove or impute them first.")
        return X

    def __sklearn_is_fitted__(self) -> bool:
        return getattr(self, "_parent", None) is not None and self._n_leaves > 0

    def _check_fitted(self) -> None:
        check_is_fitted(self, msg="This %(name)s instance holds no vector yet. Call 'fit', 'partial_fit' or "
                                  "'insert' first.")

    # ------------------------------------------------------------------ storage
    def _reset(self, item_shape: tuple) -> None:
        self._k = int(self.k)
        self._n_max = int(self.n_max)
        self._r_max = float(self.r_max)
        self._rng = check_random_state(self.random_state)
        self.item_shape_ = tuple(int(s) for s in item_shape)
        self.n_features_in_ = int(np.prod(self.item_shape_))
        self.n_samples_seen_ = 0
        cap = 64
        D = self.n_features_in_
        self._parent = np.full(cap, -1, dtype=np.int64)
        self._child = np.full((cap, self._n_max), -1, dtype=np.int64)
        self._nchild = np.zeros(cap, dtype=np.int64)
        self._sums = np.zeros((cap, D))
        self._count = np.zeros(cap, dtype=np.int64)
        self._center = np.zeros((cap, D))
        self._leaf_of = np.full(cap, -1, dtype=np.int64)
        self._node_of_leaf = np.full(cap, -1, dtype=np.int64)
        self._n_nodes = 1  # the root, node 0, internal, with no child yet
        self._n_leaves = 0

    # The arrays that hold the nodes (row i: node i), saved cut to the nodes in use.
    _NODE_ARRAYS = ("_parent", "_child", "_nchild", "_sums", "_count", "_center", "_leaf_of")

    def _get_state(self) -> dict[str, Any]:
        """The fitted state for :meth:`save`: the node arrays cut to the nodes in use, the
        sizes frozen at the first fit, and the random generator's state (splits to come)."""
        state = super()._get_state()
        if getattr(self, "_parent", None) is None:  # an unfitted tree (the parameter of a TreeVotingClassifier)
            return state
        n = self._n_nodes
        state["nodes"] = {name[1:]: getattr(self, name)[:n].copy() for name in self._NODE_ARRAYS}
        state["nodes"]["node_of_leaf"] = self._node_of_leaf[: self._n_leaves].copy()
        state["sizes"] = {"k": self._k, "n_max": self._n_max, "r_max": self._r_max}
        state["rng"] = self._rng.bit_generator.state
        return state

    def _set_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`_get_state` returned (arrays are given spare capacity again)."""
        state = dict(state)
        if "nodes" not in state:  # saved unfitted
            super()._set_state(state)
            return
        nodes, sizes, rng_state = state.pop("nodes"), state.pop("sizes"), state.pop("rng")
        super()._set_state(state)
        self.item_shape_ = tuple(int(s) for s in self.item_shape_)
        self._k, self._n_max, self._r_max = int(sizes["k"]), int(sizes["n_max"]), float(sizes["r_max"])
        bit_generator = getattr(np.random, str(rng_state.get("bit_generator")), None)
        if not (isinstance(bit_generator, type) and issubclass(bit_generator, np.random.BitGenerator)):
            raise DataFormatError(f"ClusterTree: unknown random bit generator {rng_state.get('bit_generator')!r}.")
        bg = bit_generator()
        bg.state = rng_state
        self._rng = np.random.Generator(bg)
        n, n_leaves = nodes["parent"].shape[0], nodes["node_of_leaf"].shape[0]
        cap = max(64, n)
        fills = {"parent": -1, "child": -1, "nchild": 0, "sums": 0.0, "count": 0, "center": 0.0, "leaf_of": -1}
        for name in self._NODE_ARRAYS:
            a = np.asarray(nodes[name[1:]])
            full = np.full((cap,) + a.shape[1:], fills[name[1:]], dtype=a.dtype)
            full[:n] = a
            setattr(self, name, full)
        self._node_of_leaf = np.full(cap, -1, dtype=np.int64)
        self._node_of_leaf[:n_leaves] = nodes["node_of_leaf"]
        self._n_nodes, self._n_leaves = n, n_leaves

    def _ensure_capacity(self, extra: int) -> None:
        cap = self._parent.shape[0]
        need = self._n_nodes + extra
        if need <= cap:
            return
        new = max(2 * cap, need)
        n = self._n_nodes

        def grow(a, fill):
            b = np.full((new,) + a.shape[1:], fill, dtype=a.dtype)
            b[:n] = a[:n]
            return b

        self._parent = grow(self._parent, -1)
        self._child = grow(self._child, -1)
        self._nchild = grow(self._nchild, 0)
        self._sums = grow(self._sums, 0.0)
        self._count = grow(self._count, 0)
        self._center = grow(self._center, 0.0)
        self._leaf_of = grow(self._leaf_of, -1)
        b = np.full(new, -1, dtype=np.int64)
        b[: self._n_leaves] = self._node_of_leaf[: self._n_leaves]
        self._node_of_leaf = b

    def _split(self, father: int) -> None:
        """k-means split of ``father``'s children (thesis Algorithm 1 and 2)."""
        k = self._k
        self._ensure_capacity(k)
        m = int(self._nchild[father])
        kids = self._child[father, :m]
        u = self._rng.random((_KMEANS_N_INIT, k, 2 + int(np.log(k))))
        labels = _kmeans(np.ascontiguousarray(self._center[kids]), k, u, _KMEANS_MAX_ITER)
        if np.unique(labels).size < 2:  # all centroids coincide: deal them out in order
            labels = np.arange(m, dtype=np.int64) % k
        self._n_nodes = int(
            _apply_split(father, labels, k, self._parent, self._child, self._nchild, self._sums, self._count,
                         self._center, self._leaf_of, self._n_nodes)
        )

    # ------------------------------------------------------------------ callable metric
    def _metric_code(self) -> int | None:
        """The kernels' code of a built-in metric; None for a callable (the Python path)."""
        return None if callable(self.metric) else _METRIC_CODES[self.metric]

    def _metric_fn(self) -> Callable[[np.ndarray, np.ndarray], ArrayLike]:
        # only called on the Python path, when _metric_code() is None: the metric is a callable
        return cast("Callable[[np.ndarray, np.ndarray], ArrayLike]", self.metric)

    def _distances(self, fn, q_item: np.ndarray, ids: np.ndarray) -> np.ndarray:
        cands = self._center[ids].reshape((ids.shape[0],) + self.item_shape_)
        d = np.asarray(fn(q_item, cands), dtype=np.float64)
        if d.shape != (ids.shape[0],):
            raise ParameterError(
                f"metric must return one distance per candidate, shape ({ids.shape[0]},); got shape {d.shape}."
            )
        if np.isnan(d).any():
            raise DataError("metric returned NaN distance(s); it must return real numbers.")
        return d

    def _insert_generic(self, X: np.ndarray, out: np.ndarray) -> None:
        """Thesis Algorithm 1, one item at a time, with a callable metric (:func:`_insert_batch` in Python)."""
        fn = self._metric_fn()
        child, nchild, leaf_of = self._child, self._nchild, self._leaf_of
        for i in range(X.shape[0]):
            self._ensure_capacity(1)
            child, nchild, leaf_of = self._child, self._nchild, self._leaf_of
            q = X[i]
            x = q.reshape(-1)
            node = 0
            while nchild[node] > 0 and leaf_of[child[node, 0]] < 0:
                ids = child[node, : nchild[node]]
                node = int(ids[int(np.argmin(self._distances(fn, q, ids)))])
            m = int(nchild[node])
            if m:
                ids = child[node, :m]
                d = self._distances(fn, q, ids)
                j = int(np.argmin(d))
                if d[j] <= self._r_max:
                    _add_path(int(ids[j]), x, self._parent, self._sums, self._count, self._center)
                    out[i] = leaf_of[ids[j]]
                    continue
            _new_leaf(node, x, self._parent, child, nchild, self._sums, self._count, self._center, leaf_of,
                      self._node_of_leaf, self._n_nodes, self._n_leaves)
            out[i] = self._n_leaves
            self._n_nodes += 1
            self._n_leaves += 1
            if nchild[node] >= self._n_max:
                self._split(node)

    def _search_generic(self, q: np.ndarray, mode: int, b: int) -> tuple[int, float, int]:
        """:func:`_search_one` in Python, for a callable metric (ties of the "restart" queue go to the
        sibling skipped first, as in the kernel)."""
        fn = self._metric_fn()
        child, nchild, leaf_of = self._child, self._nchild, self._leaf_of
        best, best_d, n_eval = -1, np.inf, 0

        def leaves_of(node):
            nonlocal best, best_d, n_eval
            ids = child[node, : nchild[node]]
            d = self._distances(fn, q, ids)
            n_eval += ids.shape[0]
            j = int(np.argmin(d))
            if d[j] < best_d:
                best, best_d = int(ids[j]), float(d[j])

        if mode == 3:
            ids = self._node_of_leaf[: self._n_leaves]
            d = self._distances(fn, q, ids)
            j = int(np.argmin(d))
            return int(ids[j]), float(d[j]), int(ids.shape[0])
        if nchild[0] == 0:
            return best, best_d, n_eval
        if mode == 1:
            stack = [0]
            while stack:
                node = stack.pop()
                if leaf_of[child[node, 0]] >= 0:
                    leaves_of(node)
                    continue
                ids = child[node, : nchild[node]]
                d = self._distances(fn, q, ids)
                n_eval += ids.shape[0]
                stack.extend(int(c) for c in ids[np.argsort(d, kind="stable")[: b]])
            return best, best_d, n_eval
        n_desc = 1 if mode == 0 else b
        path = self.restart_priority == "path"
        heap: list[tuple[float, int, int]] = [(0.0, 0, 0)]
        seq = 1
        for _ in range(n_desc):
            if not heap:
                break
            prio, _, node = heapq.heappop(heap)
            base = prio if path else 0.0
            while nchild[node] > 0:
                if leaf_of[child[node, 0]] >= 0:
                    leaves_of(node)
                    break
                ids = child[node, : nchild[node]]
                d = self._distances(fn, q, ids)
                n_eval += ids.shape[0]
                j = int(np.argmin(d))
                if n_desc > 1:
                    for jj in range(ids.shape[0]):
                        if jj != j:
                            heapq.heappush(heap, (base + float(d[jj] - d[j]), seq, int(ids[jj])))
                            seq += 1
                node = int(ids[j])
        return best, best_d, n_eval

    # ------------------------------------------------------------------ building
    def fit(self, X: Any, y: Any = None) -> ClusterTree:
        """Build a new tree from the items of ``X``, inserted in order.

        Parameters
        ----------
        X : array-like of shape (n_samples, d) or (n_samples, T, d)
            Vectors or fixed-length windows (e.g. MFCC windows of 80 or 150 ms).
        y : ignored

        Returns
        -------
        self
        """
        self._check_params()
        for name in ("_parent", "item_shape_", "labels_"):  # unfitted until _reset (no _parent: unfitted)
            self.__dict__.pop(name, None)
        X = self._check_items(X, "X", single=False)
        self._reset(X.shape[1:])
        self._insert_items(X)
        return self

    def partial_fit(self, X: Any, y: Any = None) -> ClusterTree:
        """Insert the items of ``X`` in order (thesis Algorithm 1), growing the tree.

        Every call validates the parameters; the first call on a fresh estimator fixes the
        item shape. ``labels_`` receives the leaf ids of this call's items.

        Parameters
        ----------
        X : array-like of shape ``(n_samples, *item_shape)``
        y : ignored

        Returns
        -------
        self
        """
        self._check_params()
        if getattr(self, "_parent", None) is None:
            self.__dict__.pop("item_shape_", None)
            X = self._check_items(X, "X", single=False)
            self._reset(X.shape[1:])
        else:
            X = self._check_items(X, "X", single=False)
        self._insert_items(X)
        return self

    def _insert_items(self, X: np.ndarray) -> None:
        """Insert the checked items ``X`` in order; ``labels_`` receives their leaf ids."""
        out = np.full(X.shape[0], -1, dtype=np.int64)
        metric = self._metric_code()
        if metric is not None:
            Xf = X.reshape(X.shape[0], -1)
            i = 0
            while i < Xf.shape[0]:
                self._ensure_capacity(min(Xf.shape[0] - i, 4096) + 1)
                i, n_nodes, n_leaves, split = _insert_batch(
                    Xf, i, metric, self.item_shape_[0], self._r_max, self._n_max, self._parent, self._child,
                    self._nchild, self._sums, self._count, self._center, self._leaf_of, self._node_of_leaf,
                    self._n_nodes, self._n_leaves, out,
                )
                self._n_nodes, self._n_leaves = int(n_nodes), int(n_leaves)
                if split >= 0:
                    self._split(int(split))
        else:
            self._insert_generic(X, out)
        self.n_samples_seen_ += X.shape[0]
        self.labels_ = out

    def insert(self, x: Any) -> int:
        """Insert one item (thesis Algorithm 1) and return the id of the leaf it ended in.

        Parameters
        ----------
        x : array-like of shape ``item_shape_`` ((d,) or (T, d))

        Returns
        -------
        int
            The leaf the item joined, or the new leaf created for it. ``labels_`` is not
            changed (it belongs to :meth:`fit` and :meth:`partial_fit`).
        """
        if getattr(self, "_parent", None) is None:
            self._check_params()
            x = self._check_items(x, "x", single=True)
            self._reset(x.shape)
        else:
            x = self._check_items(x, "x", single=True)
        labels = self.__dict__.get("labels_")
        self._insert_items(x[None])
        leaf = int(self.labels_[0])
        if labels is None:  # insert() leaves labels_ as it was (it is not a partial_fit call)
            del self.labels_
        else:
            self.labels_ = labels
        return leaf

    # ------------------------------------------------------------------ retrieval
    def query_batch(
        self, X: Any, *, search: str | None = None, backtrack: int | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Retrieve the nearest leaf of every item, without inserting anything.

        Parameters
        ----------
        X : array-like of shape ``(n_queries, *item_shape_)``
        search : {"greedy", "best_children", "restart", "exact"}, optional
            Default: the estimator's ``search``.
        backtrack : int >= 1, optional
            Default: the estimator's ``backtrack`` if ``search`` is not given here,
            else the default of this search (see the class docstring).

        Returns
        -------
        leaf_ids : ndarray of int64, shape (n_queries,)
        distances : ndarray of float64, shape (n_queries,)
            Distance from each item to the centroid of its leaf.
        n_distances : ndarray of int64, shape (n_queries,)
            Distance evaluations each search made (the search cost).
        """
        self._check_fitted()
        if search is None:
            search = self.search
            if backtrack is None:
                backtrack = self.backtrack
        search, b = self._resolve_search(search, backtrack)
        mode = SEARCHES[search]
        X = self._check_items(X, "X", single=False)
        n = X.shape[0]
        node = np.empty(n, dtype=np.int64)
        dist = np.empty(n)
        n_eval = np.empty(n, dtype=np.int64)
        metric = self._metric_code()
        if metric is not None:
            _search_batch(X.reshape(n, -1), metric, self.item_shape_[0], mode, b, self.restart_priority == "path",
                          self._center, self._child, self._nchild, self._leaf_of, self._node_of_leaf, self._n_nodes,
                          self._n_leaves, node, dist, n_eval)
        else:
            for i in range(n):
                node[i], dist[i], n_eval[i] = self._search_generic(X[i], mode, b)
        return self._leaf_of[node], dist, n_eval

    def query(
        self, x: Any, *, search: str | None = None, backtrack: int | None = None, return_stats: bool = False
    ) -> tuple[int, float] | tuple[int, float, int]:
        """Retrieve the acoustic event of one item (no insertion), thesis section 5.2.3.

        Parameters
        ----------
        x : array-like of shape ``item_shape_``
        search, backtrack : see :meth:`query_batch`
        return_stats : bool, default=False
            Also return the number of distance evaluations.

        Returns
        -------
        leaf_id : int
        distance : float
            Distance from ``x`` to the centroid of that leaf.
        n_distances : int
            Only with ``return_stats``; also stored in ``last_query_n_distances_``.
        """
        self._check_fitted()
        if search is None:
            search = self.search
            if backtrack is None:
                backtrack = self.backtrack
        search, b = self._resolve_search(search, backtrack)
        mode = SEARCHES[search]
        metric = self._metric_code()
        if metric is not None:
            if not (type(x) is np.ndarray and x.dtype == np.float64 and x.shape == self.item_shape_):
                x = self._check_items(x, "x", single=True)  # the fast path leaves the NaN check to the kernel
            node, d, n = _query_one(np.ascontiguousarray(x).reshape(-1), metric, self.item_shape_[0], mode, b,
                                    self.restart_priority == "path", self._center, self._child, self._nchild,
                                    self._leaf_of, self._node_of_leaf, self._n_nodes, self._n_leaves)
            if node == -2:
                self._check_items(x, "x", single=True)  # raises the DataError that names the problem
        else:
            x = self._check_items(x, "x", single=True)
            node, d, n = self._search_generic(x, mode, b)
        self.last_query_n_distances_ = int(n)
        leaf = int(self._leaf_of[node])
        return (leaf, float(d), int(n)) if return_stats else (leaf, float(d))

    def predict(self, X: Any, *, search: str | None = None, backtrack: int | None = None) -> np.ndarray:
        """Leaf id of every item, by retrieval only (the tree is not modified).

        Unlike ``labels_``, which records where each vector was inserted, this searches the
        current tree (with backtracking by default), so it may differ from ``labels_``.

        Parameters
        ----------
        X : array-like of shape ``(n_queries, *item_shape_)``
        search, backtrack : see :meth:`query_batch`

        Returns
        -------
        ndarray of int64, shape (n_queries,)
        """
        return self.query_batch(X, search=search, backtrack=backtrack)[0]

    # ------------------------------------------------------------------ structure
    def ancestors(self, leaf_id: int) -> list[int]:
        """Node ids from the root (node 0) down to the leaf ``leaf_id`` (its node id last).

        For vocabularies where every node is an acoustic event (thesis section 5.2.3).
        """
        self._check_fitted()
        if isinstance(leaf_id, bool) or not isinstance(leaf_id, (numbers.Integral, np.integer)):
            raise ParameterError(f"leaf_id must be an int; got {leaf_id!r}.")
        if not 0 <= leaf_id < self._n_leaves:
            raise ParameterError(f"leaf_id must be in [0, {self._n_leaves}); got {leaf_id}.")
        path = []
        node = int(self._node_of_leaf[leaf_id])
        while node >= 0:
            path.append(node)
            node = int(self._parent[node])
        return path[::-1]

    def children(self, node_id: int) -> np.ndarray:
        """Node ids of the children of node ``node_id`` (empty for a leaf)."""
        self._check_fitted()
        if not 0 <= node_id < self._n_nodes:
            raise ParameterError(f"node_id must be in [0, {self._n_nodes}); got {node_id}.")
        return self._child[node_id, : self._nchild[node_id]].copy()

    def _fitted_attr(self):
        self._check_fitted()
        return self._n_nodes, self._n_leaves

    @property
    def n_leaves_(self) -> int:
        return self._fitted_attr()[1]

    @property
    def n_nodes_(self) -> int:
        return self._fitted_attr()[0]

    @property
    def leaf_node_ids_(self) -> np.ndarray:
        return self._node_of_leaf[: self._fitted_attr()[1]].copy()

    @property
    def leaf_centers_(self) -> np.ndarray:
        ids = self.leaf_node_ids_
        return self._center[ids].reshape((ids.shape[0],) + self.item_shape_)

    @property
    def leaf_sizes_(self) -> np.ndarray:
        return self._count[self.leaf_node_ids_].copy()

    @property
    def node_centers_(self) -> np.ndarray:
        n = self._fitted_attr()[0]
        return self._center[:n].reshape((n,) + self.item_shape_).copy()

    @property
    def node_sizes_(self) -> np.ndarray:
        return self._count[: self._fitted_attr()[0]].copy()

    @property
    def node_parents_(self) -> np.ndarray:
        return self._parent[: self._fitted_attr()[0]].copy()

    @property
    def node_leaf_ids_(self) -> np.ndarray:
        return self._leaf_of[: self._fitted_attr()[0]].copy()

    @property
    def max_depth_(self) -> int:
        n = self._fitted_attr()[0]
        parent = self._parent[:n]
        # Walk all nodes up one level at a time (a split gives parents larger ids than children).
        anc = parent.copy()
        depth = (anc >= 0).astype(np.int64)
        while (anc >= 0).any():
            nxt = np.where(anc >= 0, parent[np.maximum(anc, 0)], -1)
            depth += nxt >= 0
            anc = nxt
        return int(depth[self._leaf_of[:n] >= 0].max())
