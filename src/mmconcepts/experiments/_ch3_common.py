"""Shared machinery of the chapter-3 experiments: data, features, folds, fold evaluation.

Thesis section 3.3. What is shared:

- :func:`load_subset` reads a Choreo1 subset from ``--data choreo1=DIR`` (``DIR/<subset>.json``)
  or generates the synthetic one (:func:`mmconcepts.motion.synthetic.make_choreo1`) in the
  run's cache folder; :func:`motion_arrays` turns it into joint-angle trajectories (computed
  once per data set) and the label matrix.
- Splits: :func:`kfold_splits` (k-fold or leave-one-out, thesis section 3.3.1) and
  :func:`unseen_combination_splits` (test folds made only of label combinations absent from
  their training folds, thesis Table 3.3: whole combinations are held out together).
- :func:`evaluate_folds` runs one fold per task through ``ctx.parallel``: histograms
  (grids / codebooks) are fitted on the fold's training recordings only, then each learner
  is fitted on the training examples and scores the test examples. Fold results are cached
  on disk (``ctx.cache_dir/ch3-folds``) under a hash of everything they depend on (data,
  split, features, learner parameters, seed), so experiments sharing a protocol (Table 3.2,
  Fig. 3.7, Fig. 3.8) fit each fold once.
- :func:`pooled_scores` gathers the test scores of all folds (each example is tested exactly
  once) and computes l_full / l_given_number / l_single over all examples, which for
  leave-one-out is the thesis' "averaged over all possible test sets".

Learners (names used in metric keys): ``nmf_frobenius`` and ``nmf_kl``
(:class:`~mmconcepts.nmf.LabelNMF`, beta = 2 and 1, threshold by inner cross-validation on
the training fold), ``svm`` (:func:`~mmconcepts.nmf.make_svm_baseline`, one linear SVM per
label), ``chance`` (predicts the most frequent training label set; its label scores are the
training label frequencies with a random tie-break).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import time
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from ..motion import MotionHistograms, joint_angles, load_choreo1
from .. import __version__
from ..nmf import LabelNMF, l_full, l_given_number, l_single, make_svm_baseline
from .base import RunContext

__all__ = [
    "combination_ids",
    "data_source_note",
    "evaluate_folds",
    "kfold_splits",
    "load_subset",
    "motion_arrays",
    "pooled",
    "pooled_scores",
    "unseen_combination_splits",
]

_SUBSETS = ("primitive", "mixed_partial", "mixed_full")


def load_subset(ctx: RunContext, subset: str, *, seed: int = 0, n_records: int | None = None):
    """The Choreo1 subset ``subset``: real (``--data choreo1=DIR``) or synthetic (generated, cached).

    With real data ``n_records`` keeps the first ``n_records`` records (for small runs).
    """
    if subset not in _SUBSETS:
        raise ValueError(f"subset must be one of {_SUBSETS}; got {subset!r}")
    folder = ctx.data.get("choreo1")
    if folder is not None:
        ds = load_choreo1(Path(folder) / f"{subset}.json", on_error="skip")
        if n_records is not None:
            ds = ds.subset(range(min(n_records, len(ds))))
        ds.name = subset
        return ds
    from ..motion.synthetic import make_choreo1

    return make_choreo1(subset, data_home=ctx.cache_dir, random_state=seed, n_records=n_records)


def data_source_note(ctx: RunContext) -> str:
    if ctx.data.get("choreo1") is not None:
        return f"Data: real Choreo1 recordings from {ctx.data['choreo1']}."
    return ("Data: synthetic Choreo1 (mmconcepts.motion.synthetic.make_choreo1: a kinematic dancer whose noise and "
            "variability were measured on real Kinect skeletons of MSR Action3D); pass --data choreo1=DIR for the "
            "thesis' recordings.")


def motion_arrays(ds) -> tuple[list[np.ndarray], np.ndarray, list[int]]:
    """Joint-angle trajectories (16 angles per frame), the label matrix and its label ids."""
    angles = [np.ascontiguousarray(joint_angles(r), dtype=np.float64) for r in ds]
    label_ids = list(ds.label_ids)
    return angles, ds.label_matrix(label_ids).astype(np.float64), label_ids


# ---------------------------------------------------------------------------- splits
def kfold_splits(n: int, n_folds: int | None, seed: int, y: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, test) index pairs: leave-one-out when ``n_folds`` is None, else shuffled k-fold
    (stratified by ``y`` when single labels are given and every class has n_folds examples)."""
    from sklearn.model_selection import KFold, LeaveOneOut, StratifiedKFold

    idx = np.zeros((n, 1))
    if n_folds is None:
        return [(tr, te) for tr, te in LeaveOneOut().split(idx)]
    if y is not None and np.bincount(np.unique(y, return_inverse=True)[1]).min() >= n_folds:
        return [(tr, te) for tr, te in StratifiedKFold(n_folds, shuffle=True, random_state=seed).split(idx, y)]
    return [(tr, te) for tr, te in KFold(n_folds, shuffle=True, random_state=seed).split(idx)]


def combination_ids(Y: np.ndarray) -> np.ndarray:
    """An integer per example naming its label combination (the set of its labels)."""
    keys = [tuple(np.flatnonzero(row > 0)) for row in Y]
    uniq = {k: i for i, k in enumerate(sorted(set(keys)))}
    return np.array([uniq[k] for k in keys])


def unseen_combination_splits(Y: np.ndarray, n_folds: int | None, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Splits whose test examples only show label combinations absent from their training set.

    All examples of a combination go to the same fold (combinations are shuffled, then each
    is given to the currently smallest fold). ``n_folds=None``: leave one combination out.
    """
    groups = combination_ids(Y)
    n = len(groups)
    uniq, counts = np.unique(groups, return_counts=True)
    rng = np.random.default_rng(seed)
    if n_folds is None:
        fold_of = {g: i for i, g in enumerate(uniq)}
        k = len(uniq)
    else:
        k = min(int(n_folds), len(uniq))
        order = rng.permutation(len(uniq))
        sizes = np.zeros(k)
        fold_of = {}
        for j in order[np.argsort(-counts[order], kind="stable")]:  # big groups first, random among equals
            f = int(np.argmin(sizes))
            fold_of[uniq[j]] = f
            sizes[f] += counts[j]
    fold = np.array([fold_of[g] for g in groups])
    out = []
    for f in range(k):
        te = np.flatnonzero(fold == f)
        tr = np.flatnonzero(fold != f)
        if te.size and tr.size:
            out.append((tr, te))
    assert sum(len(te) for _, te in out) == n
    return out


# ---------------------------------------------------------------------------- one fold
def _learner(name: str, params: dict, seed: int):
    if name.startswith("nmf_"):
        beta = {"nmf_frobenius": 2.0, "nmf_kl": 1.0}[name]
        return LabelNMF(params["n_components"], beta_loss=beta, max_iter=params["max_iter"], cv=params["inner_cv"],
                        random_state=seed)
    if name == "svm":
        return make_svm_baseline(random_state=seed)
    raise ValueError(f"unknown learner {name!r}")


def _fold(task: dict) -> dict:
    """Fit features and learners on one training fold; score its test examples."""
    from threadpoolctl import threadpool_limits

    angles, Y, train, test = task["angles"], task["Y"], task["train"], task["test"]
    single = task["single"]
    seed = task["seed"]
    out: dict[str, Any] = {"test": test}
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ConvergenceWarning of capped NMF iterations (max_iter is the protocol)
        t0 = time.perf_counter()
        hist = MotionHistograms(**task["features"], random_state=seed).fit([angles[i] for i in train])
        X = hist.transform(angles)
        out["feature_seconds"] = time.perf_counter() - t0
        Xtr, Xte, Ytr = X[train], X[test], Y[train]
        L = Y.shape[1]
        for name in task["learners"]:
            t0 = time.perf_counter()
            res: dict[str, Any] = {}
            if name == "chance":
                freq = Ytr.mean(axis=0)
                rng = np.random.default_rng(seed)
                res["scores"] = np.tile(freq, (len(test), 1)) + 1e-9 * rng.random((len(test), L))
                common = Counter(tuple(r) for r in Ytr.astype(int)).most_common(1)[0][0]
                res["pred"] = np.tile(np.array(common), (len(test), 1))
            elif single:
                y_tr = np.argmax(Ytr, axis=1)
                model = _learner(name, task["params"], seed)
                model.fit(Xtr, y_tr)
                s = model.decision_function(Xte)
                if s.ndim == 1:
                    s = np.column_stack([-s, s])
                scores = np.full((len(test), L), -1e9)
                scores[:, model.classes_] = s
                res["scores"] = scores
            else:
                model = _learner(name, task["params"], seed)
                keep = Ytr.sum(axis=0) > 0  # labels absent from training cannot be learnt
                model.fit(Xtr, Ytr[:, keep])
                s = model.decision_function(Xte)
                scores = np.full((len(test), L), -1e9)
                scores[:, keep] = s
                pred = np.zeros((len(test), L), dtype=np.int64)
                pred[:, keep] = model.predict(Xte)
                res["scores"], res["pred"] = scores, pred
                if name.startswith("nmf_"):
                    res["threshold"] = float(model.threshold_)
            res["seconds"] = time.perf_counter() - t0
            out[name] = res
    return out


def _fingerprint(angles: list[np.ndarray], Y: np.ndarray) -> str:
    h = hashlib.sha1()
    for a in angles:
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(np.ascontiguousarray(Y).tobytes())
    return h.hexdigest()


def evaluate_folds(ctx: RunContext, angles: list[np.ndarray], Y: np.ndarray, splits, *, features: dict,
                   learners: tuple[str, ...], params: dict, seed: int, single: bool = False,
                   desc: str = "folds") -> list[dict]:
    """Evaluate every split (in parallel over ``ctx.workers``), reusing cached folds.

    Parameters
    ----------
    angles : list of (T_i, n_dof) arrays
    Y : (n, L) label matrix (one-hot for single-label data)
    splits : list of (train, test) index arrays
    features : keyword arguments of :class:`~mmconcepts.motion.MotionHistograms`, or a list of them
        (then one list of fold results per entry is returned, all folds run in one parallel batch)
    learners : names among 'nmf_frobenius', 'nmf_kl', 'svm', 'chance'
    params : ``n_components``, ``max_iter``, ``inner_cv`` of the NMF learners
    single : single-label data (1-D fit, l_single)

    Returns
    -------
    list of dict, one per split: ``test`` indices, and per learner ``scores`` (n_test, L),
    ``pred`` (multi-label only), ``threshold`` (NMF), ``seconds``.
    """
    many = isinstance(features, (list, tuple))
    feature_list = list(features) if many else [features]
    fp = _fingerprint(angles, Y)
    cache = Path(ctx.cache_dir) / "ch3-folds"
    cache.mkdir(parents=True, exist_ok=True)
    results: list[list[dict | None]] = [[None] * len(splits) for _ in feature_list]
    todo, keys = [], []
    for j, feats in enumerate(feature_list):
        for i, (tr, te) in enumerate(splits):
            fold_seed = int(np.random.SeedSequence([seed, i]).generate_state(1)[0] % (2**31 - 1))
            # Every histogram parameter, defaults included, so a changed default is a new key.
            hist_params = sorted(MotionHistograms(**feats).get_params().items())
            h = hashlib.sha1(pickle.dumps((fp, hist_params, tuple(learners), sorted(params.items()), single,
                                           np.asarray(tr).tobytes(), np.asarray(te).tobytes(), fold_seed, __version__, 2)))
            key = cache / f"{h.hexdigest()}.pkl"
            if key.exists():
                try:
                    results[j][i] = pickle.loads(key.read_bytes())
                    continue
                except (OSError, pickle.UnpicklingError, EOFError):  # a torn cache file: recompute
                    key.unlink(missing_ok=True)
            todo.append(((j, i), {"angles": angles, "Y": Y, "train": np.asarray(tr), "test": np.asarray(te), "features": feats,
                                      "learners": tuple(learners), "params": params, "seed": fold_seed, "single": single}))
            keys.append(key)
    done = ctx.parallel(_fold, [t for _, t in todo], desc=desc)
    for ((j, i), _), key, res in zip(todo, keys, done):
        results[j][i] = res
        tmp = key.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(pickle.dumps(res))
        os.replace(tmp, key)
    if not many:
        return results[0]  # type: ignore[return-value]
    return results  # type: ignore[return-value]


def pooled(folds: list[dict], name: str, field: str, n: int, L: int) -> np.ndarray:
    """One array (n, L) of a learner's ``scores`` or ``pred`` over all test examples."""
    out = np.zeros((n, L))
    seen = np.zeros(n, bool)
    for f in folds:
        out[f["test"]] = f[name][field]
        seen[f["test"]] = True
    if not seen.all():
        raise RuntimeError("some examples were never tested; the splits do not cover the data set")
    return out


def pooled_scores(folds: list[dict], Y: np.ndarray, name: str, *, single: bool = False) -> dict[str, float]:
    """l_single (single) or l_full and l_given_number of learner ``name`` over all test examples."""
    n, L = Y.shape
    S = pooled(folds, name, "scores", n, L)
    if single:
        return {"l_single": float(l_single(np.argmax(Y, axis=1), S))}
    out = {"l_given_number": float(l_given_number(Y, S))}
    out["l_full"] = float(l_full(Y, pooled(folds, name, "pred", n, L)))
    return out
