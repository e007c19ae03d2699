"""ch5-tree: quality and cost of the cluster tree's two backtracking searches against exact search.

Thesis section 5.2.3. The incremental tree (Algorithm 1) is built from the MFCC windows
(80 ms, sliding by a third) of training utterances; windows of held-out utterances are
then retrieved with the greedy descent, the first backtracking search (recursing into the
b best children at each node, "best_children") and the second one (b full descents,
restarting from the most promising skipped node, "restart"), and with exact search over
all leaves. For each: recall@1 (the leaf found is the exact nearest leaf), the number of
distance evaluations per query (the thesis' measure of cost) and the time per query. The
thesis found that "the second method gave a better trade-off between the number of
explored nodes ... and the quality of the retrieved approximate nearest neighbor".

Random streams (:func:`~mmconcepts.experiments._ch5_common.streams`): the split of the
utterances into tree and query utterances and the draw of the query windows use the
``splits`` stream; the sample that sets r_max and the tree's k-means use the ``learner``
stream.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from ..sound.features import MFCCConfig
from ..sound.tree import ClusterTree
from . import _ch5_common as common
from .base import Claim, Experiment, Result, RunContext, Table
from .registry import register

__all__ = ["Config", "run"]

SEARCHES = (("greedy", 1), ("best_children", 2), ("best_children", 3),
            ("restart", 2), ("restart", 4), ("restart", 8), ("restart", 12), ("restart", 16), ("restart", 24))


@dataclass(frozen=True)
class Config:
    """Sizes; ``n_per_speaker`` selects the generated corpus (ignored with --data)."""

    n_per_speaker: int = 1000
    n_train_utterances: int = 3600
    n_queries: int = 2000
    n_mfcc: int = 13
    window_ms: float = 80.0
    metric: str = "dtw"
    seed: int = 0

    @classmethod
    def quick(cls) -> "Config":
        return cls(n_per_speaker=250, n_train_utterances=400, n_queries=400)

    @classmethod
    def full(cls) -> "Config":
        return cls()


def _key(search: str, b: int) -> str:
    return "greedy" if search == "greedy" else f"{search}_b{b}"


def _plan(windows: list[np.ndarray], config: Config, s: common.Streams) -> tuple[np.ndarray, np.ndarray]:
    """Tree utterances and query windows, from the ``splits`` stream only."""
    rng = np.random.default_rng(s.splits)
    order = rng.permutation(len(windows))
    n_train = min(config.n_train_utterances, len(windows) - max(1, len(windows) // 10))
    train, held = order[:n_train], order[n_train:]
    pool = np.concatenate([windows[i] for i in held if len(windows[i])])
    queries = pool[rng.choice(len(pool), size=min(config.n_queries, len(pool)), replace=False)]
    return train, queries


def _build_tree(ctx: RunContext, windows: list[np.ndarray], train: np.ndarray, config: Config,
                learner_seed: int) -> tuple[ClusterTree, float, float]:
    """The tree of the training windows, with r_max and the k-means seeded by the ``learner`` stream."""
    r_max = common.choose_r_max([windows[i] for i in train[:200]], metric=config.metric,
                                quantile=common.voting_params()["r_quantile"], seed=learner_seed)
    tree = ClusterTree(r_max, metric=config.metric, random_state=learner_seed)
    t0 = time.perf_counter()
    for i in ctx.progress(train, desc="building the tree"):
        if len(windows[i]):
            tree.partial_fit(windows[i])
    return tree, r_max, time.perf_counter() - t0


def run(config: Config, ctx: RunContext) -> Result:
    corpus = common.load_corpus(ctx, n_per_speaker=config.n_per_speaker)
    windows = common.corpus_windows(ctx, corpus, MFCCConfig(n_mfcc=config.n_mfcc), window_ms=config.window_ms)
    s = common.streams(config.seed)
    train, queries = _plan(windows, config, s)
    n_train = len(train)
    tree, r_max, build_s = _build_tree(ctx, windows, train, config, s.learner)

    t0 = time.perf_counter()
    exact_leaf, exact_dist, exact_cost = tree.query_batch(queries, search="exact")
    exact_ms = 1000 * (time.perf_counter() - t0) / len(queries)
    metrics: dict[str, float] = {
        "n_leaves": float(tree.n_leaves_), "n_nodes": float(tree.n_nodes_), "max_depth": float(tree.max_depth_),
        "n_queries": float(len(queries)), "build_seconds": build_s, "r_max": r_max,
        "exact.n_distances": float(exact_cost.mean()), "exact.ms_per_query": exact_ms, "exact.recall": 1.0,
    }
    rows = [["exact", "-", 1.0, float(exact_cost.mean()), exact_ms, 0.0]]
    hits: dict[str, np.ndarray] = {}
    for search, b in SEARCHES:
        t0 = time.perf_counter()
        leaf, dist, cost = tree.query_batch(queries, search=search, backtrack=b)
        ms = 1000 * (time.perf_counter() - t0) / len(queries)
        key = _key(search, b)
        hits[key] = (leaf == exact_leaf).astype(float)
        recall = float(np.mean(leaf == exact_leaf))
        excess = float(np.mean(dist / np.maximum(exact_dist, 1e-12) - 1.0))
        metrics.update({f"{key}.recall": recall, f"{key}.n_distances": float(cost.mean()),
                        f"{key}.ms_per_query": ms, f"{key}.distance_excess": excess})
        rows.append([search, b, recall, float(cost.mean()), ms, excess])

    # trade-off: restart's recall interpolated at the cost of best_children (b = 2), query by query
    # (a linear interpolation of the two restart searches around that cost, so its mean is the
    # interpolated recall and its per-query values pair with the other searches' for the bootstrap)
    restart = sorted((metrics[f"restart_b{b}.n_distances"], f"restart_b{b}") for m, b in SEARCHES if m == "restart")
    costs = np.array([c for c, _ in restart])
    bc_cost = metrics["best_children_b2.n_distances"]
    j = int(np.clip(np.searchsorted(costs, bc_cost), 1, len(costs) - 1))
    (c0, k0), (c1, k1) = restart[j - 1], restart[j]
    a = (bc_cost - c0) / (c1 - c0) if c1 > c0 else 0.0
    if 0.0 <= a <= 1.0:
        at_cost = (1 - a) * hits[k0] + a * hits[k1]
        metrics["restart.recall_at_best_children_b2_cost"] = float(at_cost.mean())
    else:  # outside the restart searches' costs: not measured (no extrapolation, no clipping)
        at_cost = None
        metrics["restart.recall_at_best_children_b2_cost"] = float("nan")
    fast = [b for m, b in SEARCHES if m == "restart" and metrics[f"restart_b{b}.recall"] >= 0.9]
    metrics["restart.cost_fraction_at_recall_0.9"] = (
        metrics[f"restart_b{min(fast)}.n_distances"] / metrics["exact.n_distances"] if fast else float("nan"))

    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    for search, marker in (("restart", "o"), ("best_children", "s"), ("greedy", "^")):
        pts = [(metrics[f"{_key(m, b)}.n_distances"], metrics[f"{_key(m, b)}.recall"]) for m, b in SEARCHES if m == search]
        xs, ys = zip(*sorted(pts))
        ax.plot(xs, ys, marker=marker, label=search)
    ax.axvline(metrics["exact.n_distances"], color="k", ls=":", label="exact search cost")
    ax.set_xscale("log")
    ax.set_xlabel("distance evaluations per query")
    ax.set_ylabel("recall@1 (exact nearest leaf found)")
    ax.set_ylim(0, 1.02)
    ax.set_title(f"Cluster tree search, {tree.n_leaves_} leaves ({config.metric.upper()})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    samples = {f"{k}.recall": v.tolist() for k, v in hits.items()}
    if at_cost is not None:
        samples["restart.recall_at_best_children_b2_cost"] = at_cost.tolist()
    return Result(
        metrics=metrics,
        samples=samples,
        tables={"searches": Table("Searches against exact search",
                                  ["search", "b", "recall@1", "distances per query", "ms per query",
                                   "mean excess distance"], rows)},
        figures={"tree_search": fig},
        notes=[common.data_source_note(ctx, corpus),
               "On FSDD each utterance is one digit word said alone; the tree is built from the windows of "
               "utterances of every speaker, and queried with windows of other utterances.",
               f"Tree built from the windows of {n_train} utterances ({tree.n_leaves_} leaves, {tree.n_nodes_} nodes, "
               f"depth {tree.max_depth_}, r_max {r_max:.3g}) in {build_s:.1f} s; {len(queries)} query windows "
               "from other utterances. Times are wall-clock on this machine and include Python overhead for DTW.",
               "The thesis gives no numbers for this comparison; the claims are its qualitative statements. Recall "
               "samples are per query window (hit or miss), so claims comparing two searches are decided by a "
               "paired bootstrap over the same queries.",
               "Claim dropped (issue 12): 'restart_b4.recall > greedy.recall' held by construction, since the "
               "restart search's first descent is the greedy one (its candidate set contains the greedy leaf), so "
               "it could only fail on ties. It is replaced by a claim on the size of the gain (backtracking with "
               "b = 4 removes at least half of the greedy descent's misses: the thesis' 'minimize the impact of "
               "the approximate nature of our structure'), which can fail when backtracking helps little."],
    )


register(Experiment(
    id="ch5-tree",
    title="Backtracking searches in the incremental cluster tree",
    thesis_ref="Section 5.2.3 (Algorithm 1, two backtracking searches)",
    config_cls=Config,
    run=run,
    reference={},
    claims=[
        Claim("Backtracking minimises the impact of the tree's approximation: with b = 4 restarts the search "
              "misses the exact nearest leaf less than half as often as the greedy descent.",
              "1 - restart_b4.recall < 0.5 * (1 - greedy.recall)"),
        Claim("The second backtracking search gives the better trade-off between explored nodes and quality: at the "
              "cost of the first search (b = 2) it finds the exact nearest leaf more often.",
              "restart.recall_at_best_children_b2_cost > best_children_b2.recall"),
        Claim("The tree retrieves the nearest leaf for a small fraction of the cost of exact search (recall 0.9 for "
              "less than a fifth of the distance evaluations).",
              "restart.cost_fraction_at_recall_0.9 < 0.2"),
    ],
    datasets=("acorns", "fsdd", "audio"),
    description=__doc__.split("\n\n")[0],
))
