"""What a split keeps apart: the source recordings behind training and test examples.

An example can be made of several recordings (a spliced motion mixture: the arms of one
recording, the legs of another; a composed utterance: several spoken words; a multimodal
pair: a sound and a motion). A split is *grouped by source* when no recording behind a test
example is behind a training example. :func:`describe_split` checks that for every fold of
a protocol and returns what the record keeps under ``split_groups``
(:attr:`~mmconcepts.engine.Result.split_groups`).
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Sequence
from typing import Any

import numpy as np

from ..errors import ExperimentError

__all__ = ["concept_parts", "describe_split", "shared_sources"]


def _sources(examples: Iterable[Iterable[Hashable]]) -> set[Hashable]:
    out: set[Hashable] = set()
    for sources in examples:
        if isinstance(sources, (str, bytes)):
            raise ExperimentError("each example's sources must be a collection of recording ids (a list or set), "
                                  f"not a string; got {sources!r:.60}. Wrap a single id: [{sources!r:.40}].")
        out.update(sources)
    return out


def shared_sources(train: Iterable[Iterable[Hashable]], test: Iterable[Iterable[Hashable]]) -> set[Hashable]:
    """The recordings behind both a training and a test example.

    Parameters
    ----------
    train, test : iterable of iterable of hashable
        For each training (test) example, the ids of the recordings it is made of.

    Returns
    -------
    set
        Empty for a split grouped by source.

    Examples
    --------
    >>> shared_sources([{"a1", "l1"}, {"a2", "l2"}], [{"a3", "l1"}])
    {'l1'}
    """
    return _sources(train) & _sources(test)


def describe_split(by: str, folds: Sequence[tuple[Sequence[Iterable[Hashable]], Sequence[Iterable[Hashable]]]],
                   *, strict: bool = True) -> dict[str, Any]:
    """Check that each fold keeps source recordings apart, and describe the split for the record.

    Parameters
    ----------
    by : str
        What the examples are grouped by, for the reader ("MSR Action3D recordings (arms and
        legs)", "FSDD recordings").
    folds : sequence of (train, test)
        Per fold, the sources of each training example and of each test example.
    strict : bool, default=True
        Raise when a fold shares a recording; with False, the count is only reported.

    Returns
    -------
    dict
        ``{"by", "n_folds", "n_sources", "n_train_examples", "n_test_examples",
        "shared_sources"}``: the recordings seen over all folds, the examples per fold
        (smallest), and the largest number of recordings shared by a fold's two sides (0
        for a grouped split).

    Raises
    ------
    ExperimentError
        With ``strict``, when a fold's test example shares a recording with a training
        example (the message names some).
    """
    if not folds:
        raise ExperimentError("describe_split needs at least one fold.")
    shared_max, seen = 0, set()
    n_train, n_test = [], []
    for i, (train, test) in enumerate(folds):
        train, test = list(train), list(test)
        shared = shared_sources(train, test)
        if shared and strict:
            some = ", ".join(sorted(map(str, shared))[:5])
            raise ExperimentError(f"split by {by}: fold {i} has {len(shared)} recording(s) behind both a training and "
                                  f"a test example ({some}); build each side from its own recordings.")
        shared_max = max(shared_max, len(shared))
        seen |= _sources(train) | _sources(test)
        n_train.append(len(train))
        n_test.append(len(test))
    return {"by": str(by), "n_folds": len(folds), "n_sources": len(seen), "n_train_examples": min(n_train),
            "n_test_examples": min(n_test), "shared_sources": shared_max}


def concept_parts(concept: np.ndarray, parts, rng: np.random.Generator) -> np.ndarray:
    """Part of each item, split within each concept (items of concept -1 get part -1).

    ``parts`` is a number of folds (items dealt round robin after a random permutation)
    or a sequence of fractions (e.g. ``(0.6, 0.2, 0.2)``; each part gets at least one item
    of each concept that has enough).
    """
    concept = np.asarray(concept)
    out = np.full(concept.shape, -1, dtype=np.int64)
    for c in np.unique(concept[concept >= 0]):
        idx = rng.permutation(np.flatnonzero(concept == c))
        if isinstance(parts, (int, np.integer)):
            out[idx] = np.arange(idx.size) % int(parts)
        else:
            frac = np.asarray(parts, dtype=float)
            counts = np.maximum(1, np.floor(frac / frac.sum() * idx.size).astype(int)) if idx.size >= len(frac) \
                else np.r_[idx.size, np.zeros(len(frac) - 1, int)]
            counts[0] = idx.size - counts[1:].sum()
            out[idx] = np.repeat(np.arange(len(frac)), counts)
    return out
