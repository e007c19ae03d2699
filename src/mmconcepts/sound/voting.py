"""Bags of acoustic events and TF-IDF voting (Thesis section 5.2.3, eq. 5.1).

Training counts ``n_{i,t}``, the number of training utterances tagged ``t`` whose bag
contains the acoustic event ``i``, and ``n_t``, the number of utterances tagged ``t``.
With ``f_i^t = n_{i,t} / n_t`` and the weights

.. math:: w_i = \\log \\frac{N_{tags}}{N^{(i)}_{tags}}                    \\qquad (5.1)

(``N^{(i)}_{tags}``: the number of tags whose examples contain ``i`` at least once), an
event appearing ``q_i`` times in a query utterance votes ``V_i = q_i f_i^t w_i`` for tag
``t``; the utterance gets the tag with the largest summed vote.

Label sets (thesis section 5.4: "simple sentences containing one or several keywords"):
a training utterance tagged with a set of tags counts its events for each tag of the set
(``n_{i,t}`` and ``n_t`` grow for every ``t`` in the set; a tag repeated in a set counts
once). The thesis defines the vote for one keyword per utterance; for a set, the tags are
ranked by their votes (the n best for the chapter 3 score l_given_number) or thresholded
relative to the best vote of the utterance (:meth:`EventVoting.predict_sets`, for l_full).
"""

from __future__ import annotations

import warnings
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import InstanceOf, Interval, Options, validate_params
from ..errors import DataError, ParameterError
from .tree import SEARCHES, ClusterTree

__all__ = ["EventVoting", "TreeVotingClassifier", "relative_votes"]

_WEIGHTINGS = ("tfidf", "uniform")


def _sequence_input_tags(tags: Any) -> Any:
    """Tags of a learner whose X is a list of variable-length arrays, not one 2-D array.

    scikit-learn's estimator checks feed 2-D arrays of numbers; with ``two_d_array`` False
    they skip every check but cloning, with a ``SkipTestWarning`` that names the input tags.
    The checks that still apply are run on sequences in ``tests/sound/test_contract.py``.
    """
    tags.input_tags.two_d_array = False
    return tags


def _tag_set(tag: Any, j: int) -> tuple:
    """The tags of training utterance ``j``: a tuple of distinct tags (first occurrence kept).

    A tuple, list, set or frozenset is a set of tags; anything else is one tag.

    Raises
    ------
    DataError
        If the set is empty: an utterance must say at least one tag to be counted.
    """
    if isinstance(tag, (tuple, list, set, frozenset)):
        items = sorted(tag, key=repr) if isinstance(tag, (set, frozenset)) else list(tag)
        out = tuple(dict.fromkeys(items))
        if not out:
            raise DataError(
                f"utterance {j} has an empty tag set; expected at least one tag per training utterance (its "
                "keyword(s)); got (). Fix: leave out the utterances without keyword, or give each its keyword(s)."
            )
        return out
    return (tag,)


def relative_votes(scores: Any) -> np.ndarray:
    """Votes divided by the largest vote of their row, shape (n_utterances, n_tags).

    A row with no positive vote is all zeros. Votes are nonnegative (eq. 5.1 with the
    weights of :meth:`EventVoting.weights`), so the result is in [0, 1] with a 1 at the
    best-voted tag(s).

    Parameters
    ----------
    scores : array-like of shape (n_utterances, n_tags)
        Summed votes (:meth:`EventVoting.decision_function`).
    """
    S = np.asarray(scores, dtype=np.float64)
    if S.ndim != 2:
        raise DataError(f"scores must be 2-D (n_utterances, n_tags); got shape {S.shape}.")
    if S.size and not np.isfinite(S).all():
        raise DataError("scores must be finite votes; got NaN or infinite values.")
    top = S.max(axis=1, keepdims=True) if S.shape[1] else np.zeros((S.shape[0], 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(top > 0, S / np.where(top > 0, top, 1.0), 0.0)


class EventVoting(SaveLoadMixin, ClassifierMixin, BaseEstimator):
    """Incremental tag voting over bags of discrete acoustic events (Thesis 5.2.3).

    Parameters
    ----------
    weighting : {"tfidf", "uniform"}, default="tfidf"
        ``"tfidf"``: the weights of eq. (5.1); ``"uniform"``: ``w_i = 1``.

    Attributes
    ----------
    classes_ : list
        Tags in order of first appearance.
    counts_ : ndarray of shape (n_events, n_tags)
        ``n_{i,t}`` (events seen in training, indexed by their id).
    tag_counts_ : ndarray of shape (n_tags,)
        ``n_t``.

    Notes
    -----
    The input is a list of bags (1-D integer arrays of different lengths), not a 2-D
    array, so scikit-learn's estimator checks, which feed 2-D arrays, are skipped (the
    ``two_d_array`` input tag is False); ``tests/sound/test_contract.py`` runs the ones
    that apply on bags. A fitted model saves and loads without pickle (:meth:`save`,
    :meth:`load`) when its tags are strings, numbers or tuples of them.
    """

    _parameter_constraints = {"weighting": [Options(*_WEIGHTINGS)]}

    def __init__(self, *, weighting: str = "tfidf") -> None:
        self.weighting = weighting

    def __sklearn_tags__(self):
        return _sequence_input_tags(super().__sklearn_tags__())

    def __sklearn_is_fitted__(self) -> bool:
        # fitted once a training utterance has been seen (partial_fit on no utterance is not enough)
        return bool(getattr(self, "classes_", None))

    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints,
                        hints={"weighting": "'tfidf' weighs events by eq. (5.1); 'uniform' gives every event 1."})

    def _init(self) -> None:
        self.classes_: list[Hashable] = []
        self._index: dict[Hashable, int] = {}
        self.counts_ = np.zeros((0, 0), dtype=np.int64)
        self.tag_counts_ = np.zeros(0, dtype=np.int64)

    @staticmethod
    def _check_bag(bag, i: int) -> np.ndarray:
        b = np.asarray(bag)
        if b.ndim != 1 or (b.size and not np.issubdtype(b.dtype, np.integer)):
            raise DataError(f"bag {i} must be a 1-D array of integer event ids; got {b.dtype} shape {b.shape}.")
        b = b.astype(np.int64, copy=False)
        if b.size and b.min() < 0:
            raise DataError(f"bag {i} contains a negative event id ({b.min()}).")
        return b

    def _grow(self, n_events: int, n_tags: int) -> None:
        r, c = self.counts_.shape
        if n_events > r or n_tags > c:
            new = np.zeros((max(n_events, 2 * r if n_events > r else r), max(n_tags, c)), dtype=np.int64)
            new[:r, :c] = self.counts_
            self.counts_ = new
            t = np.zeros(new.shape[1], dtype=np.int64)
            t[: self.tag_counts_.size] = self.tag_counts_
            self.tag_counts_ = t

    def partial_fit(self, bags: Sequence[np.ndarray], tags: Sequence[Any] | np.ndarray) -> EventVoting:
        """Add training utterances: ``bags[j]`` (event ids, repeats allowed) with ``tags[j]``.

        A tag is any hashable; a tuple, list or set of tags marks an utterance with several
        (each tag of the set counts the utterance's events; a tag repeated in the set counts
        once).

        Raises
        ------
        DataError
            Different numbers of bags and tags, a bag that is not 1-D integer ids, or an
            empty tag set (an utterance must say at least one tag to be counted).
        """
        self._check_params()
        if not hasattr(self, "classes_"):
            self._init()
        return self._count(bags, tags)

    def _count(self, bags: Sequence[np.ndarray], tags: Sequence[Any] | np.ndarray) -> EventVoting:
        if len(bags) != len(tags):
            raise DataError(f"got {len(bags)} bags but {len(tags)} tag entries.")
        for j, (bag, tag) in enumerate(zip(bags, tags)):
            b = self._check_bag(bag, j)
            tag_set = _tag_set(tag, j)
            cols = []
            for t in tag_set:
                if t not in self._index:
                    self._index[t] = len(self.classes_)
                    self.classes_.append(t)
                cols.append(self._index[t])
            present = np.unique(b)
            self._grow(int(present.max()) + 1 if present.size else 0, len(self.classes_))
            for c in cols:
                self.counts_[present, c] += 1
                self.tag_counts_[c] += 1
        return self

    def fit(self, bags: Sequence[np.ndarray], tags: Sequence[Any] | np.ndarray) -> EventVoting:
        """Forget everything, then :meth:`partial_fit`."""
        self._check_params()
        if len(bags) == 0:
            raise DataError("EventVoting.fit got no training utterance; it needs at least one bag with its tag(s).")
        self._init()
        return self._count(bags, tags)

    def weights(self) -> np.ndarray:
        """The event weights ``w_i`` (eq. 5.1), shape (n_events,)."""
        self._check_fitted()
        n_tags = len(self.classes_)
        counts = self.counts_[:, :n_tags]
        if self.weighting == "uniform":
            return np.ones(counts.shape[0])
        n_tags_with = (counts > 0).sum(axis=1)
        with np.errstate(divide="ignore"):
            return np.where(n_tags_with > 0, np.log(n_tags / np.maximum(n_tags_with, 1)), 0.0)

    def _check_fitted(self) -> None:
        check_is_fitted(self, msg="EventVoting has not seen any training utterance yet; call fit or partial_fit "
                                  "first.")

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        self._index = {t: i for i, t in enumerate(self.classes_)}

    def decision_function(self, bags: Sequence[np.ndarray], *, classes: Sequence[Any] | None = None) -> np.ndarray:
        """Summed votes ``sum_i q_i f_i^t w_i``, shape (n_utterances, n_tags).

        Parameters
        ----------
        bags : sequence of 1-D int arrays
        classes : sequence of tags, optional
            The columns to return, in this order (default :attr:`classes_`); a tag never
            seen in training gets no vote (0).
        """
        self._check_fitted()
        if classes is not None:
            return self._align(self.decision_function(bags), classes)
        n_tags = len(self.classes_)
        freq = self.counts_[:, :n_tags] / np.maximum(self.tag_counts_[:n_tags], 1)
        table = freq * self.weights()[:, None]
        n_events = table.shape[0]
        out = np.zeros((len(bags), n_tags))
        for j, bag in enumerate(bags):
            b = self._check_bag(bag, j)
            b = b[b < n_events]  # events never seen in training have no votes
            if b.size:
                q = np.bincount(b, minlength=n_events)
                nz = np.flatnonzero(q)
                out[j] = q[nz] @ table[nz]
        return out

    def _align(self, scores: np.ndarray, classes: Sequence[Any]) -> np.ndarray:
        """The columns of ``scores`` (order of :attr:`classes_`) for ``classes``; unseen tags score 0."""
        if isinstance(classes, (str, bytes)):
            raise ParameterError(f"classes must be a sequence of tags, not one string; got {classes!r}. "
                                 "Write classes=[tag, ...].")
        wanted = list(classes)
        if len(set(wanted)) != len(wanted):
            raise ParameterError(f"classes must not repeat a tag; got {wanted!r}.")
        out = np.zeros((scores.shape[0], len(wanted)))
        for c, t in enumerate(wanted):
            k = self._index.get(t)
            if k is not None:
                out[:, c] = scores[:, k]
        return out

    def predict(self, bags: Sequence[np.ndarray]) -> list:
        """The tag with the largest vote for each utterance (ties: first-seen tag)."""
        scores = self.decision_function(bags)
        return [self.classes_[k] for k in scores.argmax(axis=1)]

    def predict_sets(self, bags: Sequence[np.ndarray], *, threshold: float,
                     classes: Sequence[Any] | None = None) -> np.ndarray:
        """Label sets: the tags whose vote is at least ``threshold`` times the utterance's best vote.

        The thesis' ``threshold(y_hat, eta)`` (section 3.3.3) applied to the relative votes
        :func:`relative_votes` (votes divided by the utterance's largest vote), so that
        one threshold serves utterances of every length. The best-voted tag is always in
        the set (for ``threshold <= 1``); an utterance with no vote gets the empty set.

        Parameters
        ----------
        bags : sequence of 1-D int arrays
        threshold : float
            eta, in (0, 1] in practice (a fraction of the best vote).
        classes : sequence of tags, optional
            The columns, in this order (default :attr:`classes_`).

        Returns
        -------
        ndarray of int of shape (n_utterances, n_tags)
            1 where the tag is predicted.
        """
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.integer, np.floating)) \
                or not np.isfinite(threshold):
            raise ParameterError(f"threshold must be a finite number (a fraction of the best vote, e.g. 0.5); "
                                 f"got {threshold!r}.")
        rel = relative_votes(self.decision_function(bags, classes=classes))
        return (rel >= float(threshold)).astype(np.int64)

    def score(self, bags: Sequence[np.ndarray], tags: Sequence[Any] | np.ndarray) -> float:
        """Accuracy: the predicted tag is (one of) the utterance's tag(s)."""
        pred = self.predict(bags)
        ok = [
            p in t if isinstance(t, (tuple, list, set, frozenset)) else p == t
            for p, t in zip(pred, tags)
        ]
        return float(np.mean(ok)) if ok else float("nan")


class _NotSet:
    """The default of a deprecated parameter: the string "deprecated" (not given)."""

    def is_satisfied_by(self, value: Any) -> bool:
        return isinstance(value, str) and value == _DEPRECATED

    def __str__(self) -> str:
        return "'deprecated' (not given)"


_DEPRECATED = "deprecated"

# The tree parameters TreeVotingClassifier mirrored before it took a ClusterTree (deprecated
# in 0.1.0, removed in the next release), with the defaults they had then.
_TREE_PARAMS = ("r_max", "n_max", "k", "metric", "search", "backtrack", "random_state")
_OLD_DEFAULTS = {"n_max": None, "k": None, "metric": "dtw", "search": "restart", "backtrack": None,
                 "random_state": None}


class TreeVotingClassifier(SaveLoadMixin, ClassifierMixin, BaseEstimator):
    """The keyword recogniser of Thesis section 5.2.3: cluster tree + TF-IDF voting.

    Each utterance is a set of fixed-length MFCC windows (the local descriptors,
    :func:`~mmconcepts.sound.features.mfcc_windows`). Training inserts every window into
    a clone of ``tree``, an incremental :class:`~mmconcepts.sound.tree.ClusterTree`
    (Algorithm 1: unsupervised, the tags are not used), and counts, for the utterance's
    tag(s), the acoustic events its windows fall in (:class:`EventVoting`). A new
    utterance's windows are retrieved in the tree (no insertion, with the tree's ``search``
    and ``backtrack``) and the events vote (eq. 5.1). Training is incremental
    (:meth:`partial_fit`), as in the protocol of Fig. 5.3 and 5.4.

    Parameters
    ----------
    tree : ClusterTree
        The unfitted tree to grow (it is cloned; ``tree_`` is the fitted clone), e.g.
        ``ClusterTree(r_max, metric="dtw", search="restart", backtrack=4, random_state=0)``
        for the thesis' DTW and second backtracking search. Its parameters are reached as
        ``tree__<name>`` by :meth:`get_params` and :meth:`set_params`.
    events : {"leaves", "nodes"}, default="leaves"
        Acoustic events: the leaves only, or every node on the path from the root to the
        leaf (hierarchical, multi-scale events).
    weighting : {"tfidf", "uniform"}, default="tfidf"
        Weights of eq. (5.1) or uniform weights.
    r_max, n_max, k, metric, search, backtrack, random_state : deprecated
        The tree's parameters, given here before 0.1.0 (with ``metric="dtw"`` by default;
        ``r_max`` could be the first positional argument). They still build the tree, with
        a ``FutureWarning`` that says which ``tree=ClusterTree(...)`` to write instead, and
        will be removed in the next release. They cannot be mixed with ``tree``.

    Attributes
    ----------
    tree_ : ClusterTree
    voting_ : EventVoting
    classes_ : list
        The tags, in order of first appearance (those of ``voting_``).

    Notes
    -----
    The input is a list of utterances, each an array of windows, whose numbers of windows
    differ, so scikit-learn's estimator checks, which feed one 2-D array, are skipped (the
    ``two_d_array`` input tag is False); ``tests/sound/test_contract.py`` runs the ones
    that apply on utterances. A fitted model saves and loads without pickle (:meth:`save`,
    :meth:`load`; not with a callable ``metric``).

    Examples
    --------
    >>> from mmconcepts.sound import ClusterTree, TreeVotingClassifier
    >>> model = TreeVotingClassifier(ClusterTree(2.0, metric="dtw", random_state=0), events="nodes")
    >>> model.set_params(tree__r_max=1.5).get_params()["tree__r_max"]
    1.5
    """

    _parameter_constraints: dict[str, list] = {
        # a real number is the deprecated positional r_max
        "tree": [InstanceOf(ClusterTree, description="a ClusterTree"), None, Interval("real", 0, None, closed="neither")],
        "events": [Options("leaves", "nodes")],
        "weighting": [Options(*_WEIGHTINGS)],
        "r_max": [_NotSet(), Interval("real", 0, None, closed="neither")],
        "n_max": [_NotSet(), Interval("int", 1, None), None],
        "k": [_NotSet(), Interval("int", 2, None), None],
        "metric": [_NotSet(), Options("dtw", "euclidean"), "callable"],
        "search": [_NotSet(), Options(*SEARCHES)],
        "backtrack": [_NotSet(), Interval("int", 1, None), None],
        "random_state": [_NotSet(), "random_state"],
    }

    def __init__(self, tree: ClusterTree | None = None, *, events: str = "leaves", weighting: str = "tfidf",
                 r_max: Any = _DEPRECATED, n_max: Any = _DEPRECATED, k: Any = _DEPRECATED, metric: Any = _DEPRECATED,
                 search: Any = _DEPRECATED, backtrack: Any = _DEPRECATED, random_state: Any = _DEPRECATED) -> None:
        self.tree = tree
        self.events = events
        self.weighting = weighting
        self.r_max = r_max
        self.n_max = n_max
        self.k = k
        self.metric = metric
        self.search = search
        self.backtrack = backtrack
        self.random_state = random_state

    def __sklearn_tags__(self):
        return _sequence_input_tags(super().__sklearn_tags__())

    def __sklearn_is_fitted__(self) -> bool:
        # fitted once a training utterance has been counted
        return hasattr(self, "tree_") and hasattr(self, "voting_") and self.voting_.__sklearn_is_fitted__()

    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints, hints={
            "tree": "Write TreeVotingClassifier(tree=ClusterTree(r_max, metric='dtw', ...)).",
            "r_max": "Choose it from the nearest-neighbour distances between windows of different utterances.",
            "events": "'leaves' votes with the leaves only, 'nodes' with every node from the root to the leaf.",
        })

    def _new_tree(self) -> ClusterTree:
        """An unfitted clone of ``tree``, or the tree the deprecated parameters describe (with a warning)."""
        old = {name: getattr(self, name) for name in _TREE_PARAMS if not _NotSet().is_satisfied_by(getattr(self, name))}
        positional = self.tree is not None and not isinstance(self.tree, ClusterTree)
        if positional:
            if "r_max" in old:
                raise ParameterError("TreeVotingClassifier: r_max is given twice (first argument and r_max=); "
                                     "write TreeVotingClassifier(tree=ClusterTree(r_max, ...)).")
            old["r_max"] = self.tree
        if not old:
            if self.tree is None:
                raise ParameterError("TreeVotingClassifier: tree must be a ClusterTree; got None. Write "
                                     "TreeVotingClassifier(tree=ClusterTree(r_max, metric='dtw', ...)).")
            return clone(self.tree)
        if isinstance(self.tree, ClusterTree):
            raise ParameterError(
                f"TreeVotingClassifier: give the tree's parameters in tree=ClusterTree(...) only; got tree= and the "
                f"deprecated {', '.join(sorted(old))}.")
        if "r_max" not in old:
            raise ParameterError(
                f"TreeVotingClassifier: the deprecated {', '.join(sorted(old))} need r_max; write "
                "TreeVotingClassifier(tree=ClusterTree(r_max, metric='dtw', ...)).")
        kw = {"r_max": old["r_max"], **_OLD_DEFAULTS, **old}
        kw = {name: v for name, v in kw.items() if not (name in ("n_max", "k", "backtrack") and v is None)}
        tree = ClusterTree(**kw)
        shown = ", ".join(f"{name}={v!r}" if not callable(v) else f"{name}=<function>" for name, v in kw.items())
        warnings.warn(
            f"TreeVotingClassifier's tree parameters ({', '.join(n for n in _TREE_PARAMS if n in old)}) are "
            f"deprecated since 0.1.0 and will be removed in the next release; write "
            f"TreeVotingClassifier(tree=ClusterTree({shown}), ...) instead.",
            FutureWarning, stacklevel=4)
        return tree

    def _init(self) -> None:
        tree = self._new_tree()
        tree._check_params()  # what the table cannot say (n_max >= k + 1), before anything is learnt
        self.tree_ = tree
        self.voting_ = EventVoting(weighting=self.weighting)

    def _bag(self, leaves: np.ndarray) -> np.ndarray:
        leaves = np.asarray(leaves, dtype=np.int64)
        if self.events == "leaves":
            return leaves
        # all nodes: the node ids on the path from the root to each leaf (leaf's node included)
        if leaves.size == 0:
            return leaves
        return np.concatenate([np.asarray(self.tree_.ancestors(int(l)), dtype=np.int64) for l in leaves])

    @staticmethod
    def _check(utterances, tags=None) -> list[np.ndarray]:
        utts = [np.asarray(u, dtype=np.float64) for u in utterances]
        for i, u in enumerate(utts):
            if u.ndim < 2:
                raise DataError(f"utterance {i}: expected an array of windows (n_windows, ...); got shape {u.shape}.")
        if tags is not None and len(tags) != len(utts):
            raise DataError(f"got {len(utts)} utterances but {len(tags)} tags.")
        return utts

    def partial_fit(self, utterances, tags) -> TreeVotingClassifier:
        """Insert the windows of each utterance into the tree, then count its events for its tag(s)."""
        self._check_params()
        if not hasattr(self, "tree_"):
            self._init()
        return self._learn(utterances, tags)

    def _learn(self, utterances, tags) -> TreeVotingClassifier:
        utts = self._check(utterances, tags)
        bags = []
        for u in utts:
            if len(u):
                self.tree_.partial_fit(u)
                bags.append(self._bag(self.tree_.labels_.copy()))
            else:
                bags.append(np.zeros(0, np.int64))
        self.voting_.partial_fit(bags, list(tags))
        return self

    def fit(self, utterances, tags) -> TreeVotingClassifier:
        """Forget everything, then :meth:`partial_fit`."""
        self._check_params()
        if len(utterances) == 0:
            raise DataError(
                "TreeVotingClassifier.fit got no training utterance; it needs at least one utterance with its tag(s)."
            )
        self._init()
        return self._learn(utterances, tags)

    def bags(self, utterances) -> list[np.ndarray]:
        """The bag of acoustic events of each utterance (retrieval only)."""
        check_is_fitted(self, msg="TreeVotingClassifier is not fitted yet; call fit or partial_fit first.")
        utts = self._check(utterances)
        return [self._bag(self.tree_.predict(u)) if len(u) else np.zeros(0, np.int64) for u in utts]

    def decision_function(self, utterances, *, classes=None) -> np.ndarray:
        """Summed votes per tag, shape (n_utterances, n_tags) (order of ``classes_``, or of ``classes``)."""
        bags = self.bags(utterances)
        return self.voting_.decision_function(bags, classes=classes)

    def predict_sets(self, utterances, *, threshold: float, classes=None) -> np.ndarray:
        """Label sets by relative votes (:meth:`EventVoting.predict_sets`), shape (n_utterances, n_tags)."""
        bags = self.bags(utterances)
        return self.voting_.predict_sets(bags, threshold=threshold, classes=classes)

    @property
    def classes_(self) -> list:
        check_is_fitted(self, msg="TreeVotingClassifier is not fitted yet; call fit or partial_fit first.")
        return self.voting_.classes_

    def predict(self, utterances) -> list:
        """The best-voted tag of each utterance."""
        bags = self.bags(utterances)
        return self.voting_.predict(bags)

    def score(self, utterances, tags) -> float:
        """Accuracy of :meth:`predict`."""
        bags = self.bags(utterances)
        return self.voting_.score(bags, tags)
