"""The estimator contract for the sound learners: ClusterTree, HAC, EventVoting,
TreeVotingClassifier, and the parameter checks of the public functions of ``mmconcepts.sound``.

scikit-learn's estimator checks feed 2-D arrays. ``ClusterTree`` takes them and runs all the
checks. ``HAC``, ``EventVoting`` and ``TreeVotingClassifier`` take a list of variable-length
sequences (MFCC sequences, bags of event ids, utterances of windows); their ``two_d_array``
input tag is False, so ``check_estimator`` skips every check but cloning and says why. The
checks that need no data are run here one by one; those that need data are rewritten below
on sequences (fit returns self, parameters untouched, idempotence, order and subset
invariance, NaN, read-only input, clone, save/load).
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from typing import Any, Callable

import joblib
import numpy as np
import pytest
import scipy.sparse as sp
from sklearn.base import clone
from sklearn.exceptions import NotFittedError, SkipTestWarning
from sklearn.utils import estimator_checks as ec

from mmconcepts.errors import DataError, DataFormatError, ParameterError, VersionMismatchError
from mmconcepts.sound import dtw as dtw_module
from mmconcepts.sound.features import MFCCConfig, mfcc_windows, sliding_windows, window_frames
from mmconcepts.sound.hac import HAC, cooccurrence_counts
from mmconcepts.sound.tree import ClusterTree
from mmconcepts.sound.voting import EventVoting, TreeVotingClassifier


# --------------------------------------------------------------------------- data
def mfcc_sequences(rng, n=12, d=4):
    """MFCC-like sequences of different lengths made of 3 'phones'."""
    phones = rng.normal(scale=3, size=(3, d))
    return [np.concatenate([phones[p] + 0.2 * rng.normal(size=(int(rng.integers(4, 9)), d))
                            for p in rng.integers(0, 3, size=int(rng.integers(3, 6)))]) for _ in range(n)]


def window_utterances(rng, n=16, T=4, d=2):
    """Utterances of (T, d) windows; each of 3 tags has its own 'word' among shared filler windows."""
    words = rng.normal(scale=3, size=(3, 2, T, d))
    filler = rng.normal(scale=3, size=(4, T, d))
    utts, tags = [], []
    for i in range(n):
        t = i % 3
        w = np.concatenate([words[t], filler[rng.choice(4, int(rng.integers(1, 4)))]])
        utts.append(w + 0.1 * rng.normal(size=w.shape))
        tags.append(f"tag{t}")
    return utts, tags


def event_bags(rng, n=20):
    bags = [rng.integers(0, 12, size=int(rng.integers(1, 8))) + 12 * (i % 2) for i in range(n)]
    return bags, ["a" if i % 2 else "b" for i in range(n)]


@dataclass
class Case:
    """A sequence learner, small valid parameters, training data and the output to compare."""

    name: str
    make: Callable[[], Any]
    data: Callable[[Any], tuple[list, list | None]]  # rng -> (X, y)
    output: str  # the method whose result must be reproduced
    nan_input: Callable[[list], list] | None = None  # a copy of X holding a NaN, when X holds floats

    def fit(self, est, X, y):
        return est.fit(X) if y is None else est.fit(X, y)

    def out(self, est, X):
        res = getattr(est, self.output)(X)
        return res.toarray() if sp.issparse(res) else np.asarray(res)


def _with_nan(X):
    X = [x.copy() for x in X]
    X[1][0, 0] = np.nan
    return X


CASES = [
    # HAC's defaults need 150 frames per codebook; 3-word codebooks keep the data small.
    Case("HAC", lambda: HAC(n_clusters=(3, 3, 2), lags=(1, 3), max_iter=20, random_state=0),
         lambda rng: (mfcc_sequences(rng), None), "transform", _with_nan),
    Case("EventVoting", lambda: EventVoting(), event_bags, "decision_function"),
    Case("TreeVotingClassifier",
         lambda: TreeVotingClassifier(ClusterTree(1.5, n_max=4, k=2, metric="dtw", random_state=0)),
         window_utterances, "decision_function", _with_nan),
    Case("TreeVotingClassifier-euclidean",
         lambda: TreeVotingClassifier(ClusterTree(1.5, n_max=4, k=2, random_state=0), events="nodes"),
         window_utterances, "decision_function", _with_nan),
]
CASE_IDS = [c.name for c in CASES]

# scikit-learn checks that need no training data (they build, clone, set parameters or call
# an unfitted estimator), run on the sequence learners with their defaults.
DATA_FREE_CHECKS = [
    "check_estimator_cloneable", "check_estimator_repr", "check_no_attributes_set_in_init",
    "check_do_not_raise_errors_in_init_or_set_params", "check_parameters_default_constructible",
    "check_get_params_invariance", "check_set_params", "check_mixin_order", "check_valid_tag_types",
    "check_estimator_tags_renamed", "check_estimators_unfitted",
]
SEQUENCE_LEARNERS = [HAC(), EventVoting(), TreeVotingClassifier(ClusterTree(1.0))]


# --------------------------------------------------------------------------- scikit-learn's checks
@pytest.mark.slow
def test_cluster_tree_passes_every_estimator_check():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = ec.check_estimator(ClusterTree(0.5, random_state=0), on_fail=None)
    failed = [(r["check_name"], repr(r["exception"])[:200]) for r in results if r["status"] == "failed"]
    assert failed == []
    assert sum(r["status"] == "passed" for r in results) > 30


@pytest.mark.parametrize("est", SEQUENCE_LEARNERS, ids=lambda e: type(e).__name__)
def test_check_estimator_skips_sequence_learners_and_says_why(est):
    with pytest.warns(SkipTestWarning, match=rf"Can't test estimator {type(est).__name__} .*two_d_array=False"):
        results = ec.check_estimator(est, on_fail=None)
    assert [(r["check_name"], r["status"]) for r in results] == [("check_estimator_cloneable", "passed")]


@pytest.mark.parametrize("check", DATA_FREE_CHECKS)
@pytest.mark.parametrize("est", SEQUENCE_LEARNERS, ids=lambda e: type(e).__name__)
def test_sklearn_checks_that_need_no_2d_data(est, check):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        getattr(ec, check)(type(est).__name__, est)


def test_hac_passes_the_unfitted_transformer_check():
    ec.check_transformers_unfitted("HAC", HAC())


# --------------------------------------------------------------------------- the data checks, on sequences
@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_fit_returns_self_and_changes_no_parameter(case, rng):
    X, y = case.data(rng)
    est = case.make()
    before = joblib.hash(est.get_params())
    public_before = {k for k in vars(est) if not k.startswith("_")}
    assert case.fit(est, X, y) is est
    assert joblib.hash(est.get_params()) == before
    added = {k for k in vars(est) if not k.startswith("_")} - public_before
    assert added and all(k.endswith("_") for k in added), added  # only fitted attributes are added


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_fit_is_idempotent_and_forgets_earlier_data(case, rng):
    X, y = case.data(rng)
    X2, y2 = case.data(np.random.default_rng(99))
    est = case.fit(case.make(), X, y)
    first = case.out(est, X)
    case.fit(est, X2, y2)
    assert not np.array_equal(case.out(est, X), first)  # the other data did change the model...
    case.fit(est, X, y)
    np.testing.assert_array_equal(case.out(est, X), first)  # ...and refitting forgets it


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_outputs_do_not_depend_on_the_order_or_batch_of_queries(case, rng):
    X, y = case.data(rng)
    est = case.fit(case.make(), X, y)
    full = case.out(est, X)
    perm = rng.permutation(len(X))
    np.testing.assert_array_equal(case.out(est, [X[i] for i in perm]), full[perm])
    for i in (0, len(X) - 1):
        np.testing.assert_array_equal(case.out(est, X[i : i + 1]), full[i : i + 1])


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_read_only_input_is_accepted_and_left_unchanged(case, rng):
    X, y = case.data(rng)
    expected = case.out(case.fit(case.make(), X, y), X)
    ro = [x.copy() for x in X]
    for x in ro:
        x.flags.writeable = False
    est = case.fit(case.make(), ro, y)
    np.testing.assert_array_equal(case.out(est, ro), expected)
    for a, b in zip(ro, X):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("case", [c for c in CASES if c.nan_input], ids=lambda c: c.name)
def test_nan_in_fit_or_output_input_raises_data_error(case, rng):
    X, y = case.data(rng)
    with pytest.raises(DataError, match="NaN"):
        case.fit(case.make(), case.nan_input(X), y)
    est = case.fit(case.make(), X, y)
    with pytest.raises(DataError, match="NaN"):
        case.out(est, case.nan_input(X))


@pytest.mark.parametrize("make, query", [(EventVoting, np.array([0, 1])),
                                         (lambda: TreeVotingClassifier(ClusterTree(1.0)), np.ones((2, 3, 1)))],
                         ids=["EventVoting", "TreeVotingClassifier"])
def test_a_learner_that_has_seen_no_utterance_is_not_fitted(make, query):
    est = make().partial_fit([], [])
    with pytest.raises(NotFittedError, match="fit"):
        est.predict([query])


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_clone_gives_an_unfitted_copy_with_the_same_parameters(case, rng):
    X, y = case.data(rng)
    est = case.fit(case.make(), X, y)
    copy = clone(est)
    assert _params(copy) == _params(est)
    with pytest.raises(NotFittedError, match="fit"):
        case.out(copy, X)
    np.testing.assert_array_equal(case.out(case.fit(copy, X, y), X), case.out(est, X))


def _params(est):
    """get_params(deep=False) with nested estimators replaced by (their class, their parameters)."""
    return {k: (type(v), _params(v)) if hasattr(v, "get_params") else v for k, v in est.get_params(deep=False).items()}


# --------------------------------------------------------------------------- parameters
ESTIMATORS = {
    "ClusterTree": lambda **kw: ClusterTree(**{"r_max": 1.0, **kw}),
    "HAC": lambda **kw: HAC(**{"n_clusters": (2, 2, 2), **kw}),
    "EventVoting": lambda **kw: EventVoting(**kw),
    "TreeVotingClassifier": lambda **kw: TreeVotingClassifier(**{"tree": ClusterTree(1.0, metric="dtw"), **kw}),
}
BAD_PARAMETERS = [
    ("ClusterTree", "r_max", 0.0), ("ClusterTree", "r_max", np.inf), ("ClusterTree", "n_max", 2.5),
    ("ClusterTree", "k", 1), ("ClusterTree", "metric", "cosine"), ("ClusterTree", "search", "beam"),
    ("ClusterTree", "backtrack", 0), ("ClusterTree", "backtrack", True), ("ClusterTree", "restart_priority", "depth"),
    ("ClusterTree", "random_state", -1),
    ("HAC", "n_clusters", (3, 3)), ("HAC", "n_clusters", (3, 0, 3)), ("HAC", "n_clusters", (3, 2.0, 3)),
    ("HAC", "lags", ()), ("HAC", "lags", (2, 0)), ("HAC", "lags", 2), ("HAC", "standardize", "yes"),
    ("HAC", "max_fit_frames", 0), ("HAC", "max_iter", 0), ("HAC", "random_state", "seed"),
    ("EventVoting", "weighting", "bm25"),
    ("TreeVotingClassifier", "tree", "a tree"), ("TreeVotingClassifier", "tree", -1.0),
    ("TreeVotingClassifier", "events", "phonemes"), ("TreeVotingClassifier", "weighting", "bm25"),
    # the deprecated tree parameters are still checked
    ("TreeVotingClassifier", "r_max", -1.0), ("TreeVotingClassifier", "n_max", 0), ("TreeVotingClassifier", "k", 1),
    ("TreeVotingClassifier", "metric", "cosine"), ("TreeVotingClassifier", "search", "beam"),
    ("TreeVotingClassifier", "backtrack", 0), ("TreeVotingClassifier", "random_state", 1.5),
]


def _fit_data(name, rng):
    if name == "ClusterTree":
        return rng.normal(size=(10, 3)), None
    if name == "HAC":
        return mfcc_sequences(rng, n=3), None
    if name == "EventVoting":
        return event_bags(rng, n=4)
    return window_utterances(rng, n=4)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_every_constructor_parameter_has_a_constraint(name):
    est = ESTIMATORS[name]()
    assert set(est._parameter_constraints) == set(est.get_params(deep=False))


@pytest.mark.parametrize("name, param, value", BAD_PARAMETERS)
def test_a_bad_parameter_is_refused_by_fit_and_partial_fit_with_its_name(name, param, value, rng):
    X, y = _fit_data(name, rng)
    est = ESTIMATORS[name](**{param: value})
    with pytest.raises(ParameterError, match=rf"^{name}: {param} must be .*; got "):
        est.fit(X) if y is None else est.fit(X, y)
    if hasattr(est, "partial_fit"):
        with pytest.raises(ParameterError, match=rf"^{name}: {param} must be"):
            est.partial_fit(X) if y is None else est.partial_fit(X, y)


@pytest.mark.parametrize("name", ["ClusterTree", "TreeVotingClassifier"])
def test_n_max_must_exceed_k_before_anything_is_learnt(name, rng):
    X, y = _fit_data(name, rng)
    est = ESTIMATORS[name](n_max=3, k=3) if name == "ClusterTree" else ESTIMATORS[name](tree=ClusterTree(1.0, n_max=3, k=3))
    with pytest.raises(ParameterError, match=r"n_max must be at least k \+ 1 = 4"):
        est.fit(X) if y is None else est.fit(X, y)
    assert not any(k.endswith("_") for k in vars(est))


def test_a_parameter_set_after_fit_is_checked_by_the_next_partial_fit(rng):
    X = rng.normal(size=(30, 3))
    tree = ClusterTree(1.0, random_state=0).fit(X)
    tree.set_params(metric="cosine")
    with pytest.raises(ParameterError, match="metric must be one of 'euclidean', 'dtw' or a callable"):
        tree.partial_fit(X)
    voting = EventVoting().fit(*event_bags(rng))
    voting.set_params(weighting="idf")
    with pytest.raises(ParameterError, match="weighting must be one of 'tfidf', 'uniform'"):
        voting.partial_fit(*event_bags(rng))


def test_query_time_search_arguments_are_checked(rng):
    X = rng.normal(size=(50, 3))
    tree = ClusterTree(0.5, random_state=0).fit(X)
    for kwargs, match in [({"search": "beam"}, "search must be one of"), ({"backtrack": 0}, "backtrack must be"),
                          ({"search": "restart", "backtrack": 1.5}, "backtrack must be")]:
        with pytest.raises(ParameterError, match=rf"^ClusterTree: {match}"):
            tree.query(X[0], **kwargs)
        with pytest.raises(ParameterError, match=rf"^ClusterTree: {match}"):
            tree.predict(X[:2], **kwargs)
    # a numpy int is a valid backtrack, and means what the same Python int means
    np.testing.assert_array_equal(tree.predict(X, search="restart", backtrack=np.int64(2)),
                                  tree.predict(X, search="restart", backtrack=2))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: dtw_module.dtw([1.0], [2.0], window=-1), r"^dtw: window must be None or an int >= 0"),
        (lambda: dtw_module.dtw_one_to_many(np.ones((2, 1)), np.ones((3, 2, 1)), local="l1"),
         r"^dtw_one_to_many: local must be one of 'euclidean', 'sqeuclidean'"),
        (lambda: dtw_module.dtw_distance_matrix([np.ones(2)], n_jobs=0),
         r"^dtw_distance_matrix: n_jobs must be None, an int >= 1 or an int <= -1"),
        (lambda: dtw_module.dtw_one_to_many(np.ones((2, 1)), np.ones((3, 2, 1)), n_jobs=0),
         r"^dtw_one_to_many: n_jobs must be"),
        (lambda: dtw_module.dtw_one_to_many(np.ones((2, 1)), np.ones((3, 2, 1)), window=1.5),
         r"^dtw_one_to_many: window must be"),
        (lambda: cooccurrence_counts([np.array([0, 1, 1])], 2, 0), r"^cooccurrence_counts: lag must be an int >= 1"),
        (lambda: cooccurrence_counts([np.array([0, 1, 1])], 0, 1), r"^cooccurrence_counts: n_events must be"),
        (lambda: window_frames(0.0), r"^window_frames: duration_ms must be a real number > 0"),
        (lambda: window_frames(80.0, hop_ms=-1), r"^window_frames: hop_ms must be"),
        (lambda: sliding_windows(np.ones((5, 2)), 0), r"^sliding_windows: width must be an int >= 1"),
        (lambda: sliding_windows(np.ones((5, 2)), 2, 1.5), r"^sliding_windows: shift must be an int >= 1 or None"),
        (lambda: mfcc_windows(np.zeros(16000), shift=1.5), r"^mfcc_windows: shift must be a real number in \(0, 1\]"),
        (lambda: mfcc_windows(np.zeros(16000), window_ms=0), r"^mfcc_windows: window_ms must be"),
        (lambda: MFCCConfig(n_mfcc=0), r"^MFCCConfig: n_mfcc must be an int >= 1"),
        (lambda: MFCCConfig(sr=16000.0), r"^MFCCConfig: sr must be an int >= 1"),
        (lambda: MFCCConfig(hop_ms=0), r"^MFCCConfig: hop_ms must be a real number > 0"),
        (lambda: MFCCConfig(lifter=-1), r"^MFCCConfig: lifter must be"),
        (lambda: MFCCConfig(top_db=-5.0), r"^MFCCConfig: top_db must be a real number >= 0 or None"),
        (lambda: MFCCConfig(window=3), r"^MFCCConfig: window must be a scipy.signal.get_window name"),
        (lambda: MFCCConfig(n_mfcc=41), r"^MFCCConfig: n_mfcc \(41\) cannot exceed n_mels \(40\)"),
    ],
)
def test_public_functions_check_their_parameters(call, match):
    with pytest.raises(ParameterError, match=match):
        call()


def test_public_functions_accept_their_valid_edge_values():
    assert dtw_module.dtw([1.0, 2.0], [2.0], window=0) == dtw_module.dtw([1.0, 2.0], [2.0])
    assert dtw_module.dtw_one_to_many(np.ones((2, 1)), np.ones((3, 2, 1)), n_jobs=-1).shape == (3,)
    assert window_frames(5.0) == 1
    assert sliding_windows(np.ones((5, 2)), 5).shape == (1, 5, 2)
    assert MFCCConfig(top_db=None, fmax=8000, window=("kaiser", 4.0)).top_db is None


# --------------------------------------------------------------------------- save and load
SAVED = [
    ("ClusterTree", lambda: ClusterTree(0.8, n_max=5, k=2, random_state=0),
     lambda rng: (rng.normal(size=(400, 3)), None), "predict"),
    ("ClusterTree-dtw", lambda: ClusterTree(1.0, n_max=5, k=2, metric="dtw", search="best_children",
                                            random_state=np.random.default_rng(3)),
     lambda rng: (rng.normal(size=(120, 4, 2)), None), "predict"),
    *[(c.name, c.make, c.data, c.output) for c in CASES],
]


def _saved_then_loaded(est, tmp_path):
    path = est.save(tmp_path / "model")
    return type(est).load(path), path


@pytest.mark.parametrize("name, make, data, output", SAVED, ids=[s[0] for s in SAVED])
def test_a_loaded_model_answers_and_keeps_learning_as_the_saved_one(name, make, data, output, tmp_path, rng):
    X, y = data(rng)
    half = len(X) // 2
    case = Case(name, make, data, output)
    est = make()
    est.fit(X[:half]) if y is None else est.fit(X[:half], y[:half])
    back, _ = _saved_then_loaded(est, tmp_path)
    assert type(back) is type(est)
    assert joblib.hash({k: v for k, v in back.get_params().items() if k != "random_state"}) == joblib.hash(
        {k: v for k, v in est.get_params().items() if k != "random_state"})
    np.testing.assert_array_equal(case.out(back, X), case.out(est, X))
    if hasattr(est, "partial_fit"):  # the rest of the data: same tree growth, same splits, same counts
        for m in (est, back):
            m.partial_fit(X[half:]) if y is None else m.partial_fit(X[half:], y[half:])
        np.testing.assert_array_equal(case.out(back, X), case.out(est, X))
        if isinstance(est, ClusterTree):
            np.testing.assert_array_equal(back.node_centers_, est.node_centers_)
            np.testing.assert_array_equal(back.labels_, est.labels_)
            np.testing.assert_array_equal(back.leaf_node_ids_, est.leaf_node_ids_)
            np.testing.assert_array_equal(back.predict(X, search="exact"), est.predict(X, search="exact"))


def test_loaded_models_keep_their_fitted_attributes(tmp_path, rng):
    utts, tags = window_utterances(rng)
    model = TreeVotingClassifier(ClusterTree(1.5, n_max=4, k=2, metric="dtw", random_state=0), events="nodes")
    model.fit(utts, tags)
    back, _ = _saved_then_loaded(model, tmp_path)
    assert back.classes_ == model.classes_
    assert back.tree_.n_nodes_ == model.tree_.n_nodes_ and back.tree_.max_depth_ == model.tree_.max_depth_
    np.testing.assert_array_equal(back.voting_.counts_, model.voting_.counts_)
    np.testing.assert_array_equal(back.voting_.weights(), model.voting_.weights())
    assert back.predict(utts) == model.predict(utts)
    hac = HAC(n_clusters=(3, 3, 2), random_state=0).fit(mfcc_sequences(rng))
    back = HAC.load(hac.save(tmp_path / "hac"))
    for a, b, km in zip(back.codebooks_, hac.codebooks_, back._kmeans):
        np.testing.assert_array_equal(a, b)
        # the frames are assigned to the saved centres themselves, not to a refit's rounded copy
        np.testing.assert_array_equal(km.cluster_centers_, b)
    assert back.get_feature_names_out().tolist() == hac.get_feature_names_out().tolist()


def _bump_format_version(path):
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays.pop("header")))
    header["format_version"] += 1
    np.savez(path, header=np.array(json.dumps(header)), **arrays)


@pytest.mark.parametrize("name, make, data, output", SAVED[:1] + SAVED[2:], ids=[s[0] for s in SAVED[:1] + SAVED[2:]])
def test_load_refuses_another_class_a_newer_format_and_an_unfitted_save(name, make, data, output, tmp_path, rng):
    X, y = data(rng)
    est = make()
    with pytest.raises(NotFittedError):
        est.save(tmp_path / "unfitted")
    est.fit(X) if y is None else est.fit(X, y)
    path = est.save(tmp_path / "model")
    other = EventVoting if not isinstance(est, EventVoting) else HAC
    with pytest.raises(DataFormatError, match=f"its format is 'mmconcepts.{type(est).__name__}'"):
        other.load(path)
    _bump_format_version(path)
    with pytest.raises(VersionMismatchError, match=f"reads version 1 of {type(est).__name__}"):
        type(est).load(path)


def test_a_tree_with_a_callable_metric_is_not_saved(tmp_path, rng):
    tree = ClusterTree(1.0, metric=lambda q, C: np.abs(C - q).sum(axis=1)).fit(rng.normal(size=(20, 2)))
    with pytest.raises(ParameterError, match="metric: a function cannot be saved without pickle"):
        tree.save(tmp_path / "t")
    assert not (tmp_path / "t.npz").exists()


# --------------------------------------------------------------------------- TreeVotingClassifier takes a ClusterTree
def test_tree_voting_is_a_meta_estimator_over_its_tree(rng):
    utts, tags = window_utterances(rng)
    tree = ClusterTree(1.5, n_max=4, k=2, metric="dtw", random_state=0)
    model = TreeVotingClassifier(tree, events="nodes")
    params = model.get_params(deep=True)
    assert params["tree"] is tree and params["tree__r_max"] == 1.5 and params["tree__metric"] == "dtw"
    model.fit(utts, tags)
    assert model.tree_ is not tree and not hasattr(tree, "labels_")  # the parameter is cloned, never fitted
    assert model.tree_.get_params() == tree.get_params()
    # set_params reaches the tree; clone copies it
    other = clone(model).set_params(tree__r_max=1e6, tree__search="greedy")
    assert other.tree is not tree and other.tree.r_max == 1e6 and tree.r_max == 1.5
    other.fit(utts, tags)
    assert other.tree_.n_leaves_ == 1 < model.tree_.n_leaves_  # every window joins the first leaf
    # retrieval uses the tree's own search (greedy here): the same events as the tree's predict
    bags = other.bags(utts[:3])
    for u, bag in zip(utts[:3], bags):
        leaves = other.tree_.predict(u)
        np.testing.assert_array_equal(bag, np.concatenate([other.tree_.ancestors(int(l)) for l in leaves]))


def test_deprecated_tree_parameters_warn_and_build_the_same_model(rng):
    utts, tags = window_utterances(rng)
    new = TreeVotingClassifier(ClusterTree(1.5, n_max=4, k=2, metric="dtw", backtrack=3, random_state=0))
    expected = new.fit(utts, tags).decision_function(utts)
    # the old defaults: metric "dtw", search "restart"; r_max could be the first argument
    for old in (TreeVotingClassifier(1.5, n_max=4, k=2, backtrack=3, random_state=0),
                TreeVotingClassifier(r_max=1.5, n_max=4, k=2, backtrack=3, random_state=0)):
        with pytest.warns(FutureWarning, match=r"deprecated since 0\.1\.0 .* write TreeVotingClassifier\("
                                               r"tree=ClusterTree\(r_max=1\.5, n_max=4, k=2, metric='dtw', "
                                               r"search='restart', backtrack=3, random_state=0\), \.\.\.\) instead"):
            old.fit(utts, tags)
        np.testing.assert_array_equal(old.decision_function(utts), expected)
        assert old.tree_.get_params() == new.tree_.get_params()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new form does not warn
        TreeVotingClassifier(ClusterTree(1.5, metric="dtw")).fit(utts, tags)


@pytest.mark.parametrize("kwargs, match", [
    ({}, r"tree must be a ClusterTree; got None\. Write TreeVotingClassifier\(tree=ClusterTree"),
    ({"tree": ClusterTree(1.0), "metric": "dtw"}, r"only; got tree= and the deprecated metric"),
    ({"tree": 1.0, "r_max": 2.0}, "r_max is given twice"),
    ({"metric": "dtw"}, r"the deprecated metric need r_max"),
])
def test_tree_voting_needs_one_tree(kwargs, match, rng):
    utts, tags = window_utterances(rng, n=4)
    with pytest.raises(ParameterError, match=match):
        TreeVotingClassifier(**kwargs).fit(utts, tags)


def test_a_bad_tree_parameter_is_named_by_the_tree(rng):
    utts, tags = window_utterances(rng, n=4)
    with pytest.raises(ParameterError, match=r"^ClusterTree: r_max must be a real number > 0; got -1\.0"):
        TreeVotingClassifier(ClusterTree(-1.0)).fit(utts, tags)
    model = TreeVotingClassifier(ClusterTree(1.0)).set_params(tree__search="beam")
    with pytest.raises(ParameterError, match=r"^ClusterTree: search must be one of"):
        model.partial_fit(utts, tags)


def test_a_model_saved_with_the_deprecated_parameters_loads(tmp_path, rng):
    utts, tags = window_utterances(rng)
    with pytest.warns(FutureWarning):
        old = TreeVotingClassifier(1.5, n_max=4, k=2, random_state=0).fit(utts, tags)
    back = TreeVotingClassifier.load(old.save(tmp_path / "old"))
    assert back.get_params(deep=False) == old.get_params(deep=False)
    np.testing.assert_array_equal(back.decision_function(utts), old.decision_function(utts))
