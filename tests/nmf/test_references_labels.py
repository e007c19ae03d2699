"""The threshold rule of LabelNMF on constructed cross-validation curves.

The rule (thesis Fig. 3.7): keep the threshold with the best pooled l_full; among ties,
the median one, the middle of the plateau. The validation curves are replaced by
constructed ones, so the rule is tested alone.
"""

from __future__ import annotations

import numpy as np
import pytest

import mmconcepts.nmf.labels as labels_module
from mmconcepts.nmf import LabelNMF

pytestmark = pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning")  # 5 iterations suffice here

GRID = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]


def _data(rng):
    X = rng.random((20, 6))
    Y = (rng.random((20, 3)) < 0.4).astype(int)
    Y[:, 0] |= Y.sum(axis=1) == 0  # every example has a label
    return X, Y


@pytest.mark.parametrize(
    "curve, expected",
    [
        # one plateau of five points (indices 2..6): its middle is index 4
        ([0.1, 0.5, 0.8, 0.8, 0.8, 0.8, 0.8, 0.3, 0.2], 0.5),
        # a plateau at the start: the middle of 0..2
        ([0.9, 0.9, 0.9, 0.5, 0.4, 0.3, 0.2, 0.1, 0.0], 0.2),
        # a plateau of four (3..6): len // 2 = 2 -> index 5, the upper of the two middle points
        ([0.1, 0.2, 0.3, 0.7, 0.7, 0.7, 0.7, 0.2, 0.1], 0.6),
        # a lower plateau elsewhere is not the best one
        ([0.6, 0.6, 0.6, 0.6, 0.6, 0.1, 0.7, 0.7, 0.7], 0.8),
        # a single best point
        ([0.1, 0.2, 0.3, 0.4, 0.9, 0.4, 0.3, 0.2, 0.1], 0.5),
    ],
)
def test_cv_threshold_is_the_middle_of_the_best_plateau(rng, monkeypatch, curve, expected):
    def constructed(inner, X, Y, train, val, seed, grid):
        assert list(grid) == GRID
        return np.asarray(curve, dtype=np.float64)

    monkeypatch.setattr(labels_module, "_fold_curve", constructed)
    X, Y = _data(rng)
    model = LabelNMF(3, max_iter=5, threshold_grid=GRID, cv=3, random_state=0).fit(X, Y)
    assert model.threshold_ == pytest.approx(expected)
    np.testing.assert_allclose(model.cv_mean_scores_, curve)


def test_pooled_curve_is_weighted_by_fold_size(rng, monkeypatch):
    """Folds of sizes 7, 7, 6: the fold curves are averaged with those weights before the rule."""
    curves = iter([np.array([0.0, 1.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])])

    def constructed(inner, X, Y, train, val, seed, grid):
        return next(curves)

    monkeypatch.setattr(labels_module, "_fold_curve", constructed)
    X, Y = _data(rng)
    model = LabelNMF(3, max_iter=5, threshold_grid=[0.2, 0.5, 0.8], cv=3, random_state=0).fit(X, Y)
    np.testing.assert_allclose(model.cv_mean_scores_, [6 / 20, 14 / 20, 0.0])
    assert model.threshold_ == 0.5
