"""top_examples and atom_label_association against brute-force definitions and known answers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mmconcepts.errors import DataError
from mmconcepts.multimodal import atom_label_association, top_examples

pytestmark = pytest.mark.property


def _brute_top(W, n):
    out = []
    for j in range(W.shape[1]):
        def key(i):
            total = W[i].sum()
            share = W[i, j] / total if total > 0 else -1.0
            return (-share, -W[i, j], i)
        out.append(sorted(range(W.shape[0]), key=key)[:n])
    return np.array(out)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 12), st.integers(1, 5)),
              elements=st.sampled_from([0.0, 0.5, 1.0, 2.0, 3.0])), st.integers(1, 12))
def test_top_examples_is_the_brute_force_ranking(W, n):
    n = min(n, W.shape[0])
    np.testing.assert_array_equal(top_examples(W, n), _brute_top(W, n))


def test_top_examples_ranks_by_share_not_loudness():
    W = np.array([[10.0, 10.0], [0.1, 0.0], [0.0, 1.0]])
    assert top_examples(W, 1)[0, 0] == 1  # all of example 1 is atom 0, half of the louder example 0


def test_top_examples_refuses_more_than_there_are():
    with pytest.raises(DataError, match="n <= n_samples"):
        top_examples(np.ones((2, 2)), 3)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 12), st.integers(1, 4)), elements=st.floats(0, 5)),
       st.data())
def test_association_is_the_per_label_share(W, data):
    y = np.array(data.draw(st.lists(st.sampled_from("abc"), min_size=W.shape[0], max_size=W.shape[0])))
    A, labels = atom_label_association(W, y)
    for j in range(W.shape[1]):
        total = W[:, j].sum()
        for c, lab in enumerate(labels):
            expected = W[y == lab, j].sum() / total if total > 0 else 0.0
            assert A[j, c] == pytest.approx(expected, abs=1e-12)


def test_association_with_given_labels_leaves_others_out():
    W = np.array([[1.0], [1.0], [2.0]])
    A, labels = atom_label_association(W, ["a", "b", "z"], labels=["b", "a"])
    np.testing.assert_allclose(A, [[0.25, 0.25]])
    assert labels.tolist() == ["b", "a"]


def test_association_checks_lengths():
    with pytest.raises(DataError, match="one label per row"):
        atom_label_association(np.ones((3, 2)), [1, 2])
