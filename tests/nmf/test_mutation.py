"""Tests written from the mutation run on ``mmconcepts.nmf``.

Each test kills mutants that the rest of the suite let survive (see /work/notes/mutation13.md):
Hoyer's sparseness on known answers and on the all-zero vector (NaN, without a warning), and
the message of ``match_components`` for non-finite dictionaries, and feature indices checked
against numpy's own indexing.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.nmf import NMF, beta_nmf, hoyer_sparseness, match_components
from mmconcepts.nmf._estimator import resolve_features
from mmconcepts.nmf._init import initialize

pytestmark = pytest.mark.mutation


def test_hoyer_sparseness_known_answers_and_the_zero_vector_without_warnings():
    """Thesis eq. (2.20): (sqrt(n) - |x|_1 / |x|_2) / (sqrt(n) - 1); 0 for a constant vector,
    1 for one nonzero entry, NaN (documented, no RuntimeWarning) for the zero vector."""
    x = np.array([3.0, -4.0, 0.0, 0.0])  # |x|_1 = 7, |x|_2 = 5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert hoyer_sparseness(x) == pytest.approx((2.0 - 7.0 / 5.0) / (2.0 - 1.0), rel=1e-14)
        assert hoyer_sparseness(np.full(9, 2.5)) == pytest.approx(0.0, abs=1e-14)
        assert hoyer_sparseness(np.eye(5)[2]) == pytest.approx(1.0, rel=1e-14)
        assert np.isnan(hoyer_sparseness(np.zeros(4)))
        cols = hoyer_sparseness(np.array([[0.0, 1.0], [0.0, 1.0]]), axis=0)
    assert np.isnan(cols[0]) and cols[1] == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_match_components_names_non_finite_dictionaries(bad):
    A = np.eye(3)
    B = np.eye(3)
    B[1, 2] = bad
    with pytest.raises(DataError, match="dictionaries hold NaN or infinite values"):
        match_components(A, B)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")  # 20 iterations are enough here
def test_features_take_every_index_numpy_takes_and_refuse_the_others():
    """``features`` are numpy indices: -n_features .. n_features - 1 select what
    ``np.arange(n)[idx]`` selects (so -n_features is column 0); anything else is refused."""
    rng = np.random.default_rng(0)
    X = rng.random((12, 5)) + 0.1
    model = NMF(2, max_iter=20, random_state=0).fit(X)
    n = X.shape[1]
    for idx in ([-n, 1], [-1, -n + 2], [4, -n + 1]):
        cols = np.arange(n)[idx]
        np.testing.assert_array_equal(resolve_features(idx, n), cols)
        np.testing.assert_array_equal(model.transform(X[:, cols], features=idx),
                                      model.transform(X[:, cols], features=list(cols)))
    for idx in ([-n - 1], [n]):
        with pytest.raises(ParameterError, match="out of range"):
            resolve_features(idx, n)
    # a column given twice, also as its negative index, and far apart: refused; each once, in any order: taken
    for idx in ([1, 1], [0, -n], [4, 0, 2, 3, 4], [3, 2, 1, -2]):
        with pytest.raises(ParameterError, match="repeated indices"):
            resolve_features(idx, n)
    np.testing.assert_array_equal(resolve_features([4, -5, 2, 3, 1], n), [4, 0, 2, 3, 1])


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("init", ["nndsvd", "nndsvda", "nndsvdar"])
def test_svd_starts_ignore_what_lies_in_masked_cells(init):
    """The README's promise, for the SVD-based starts too: unobserved cells have no influence."""
    rng = np.random.default_rng(1)
    X = rng.random((15, 8)) + 0.1
    mask = rng.random(X.shape) < 0.8
    fits = [NMF(3, init=init, beta_loss=1, max_iter=15, random_state=0).fit(np.where(mask, X, g), mask=mask)
            for g in (np.nan, 0.0, 1e3)]
    for other in fits[1:]:
        np.testing.assert_allclose(other.components_, fits[0].components_, rtol=1e-12, atol=1e-14)


def test_beta_nmf_reports_a_bad_init_through_its_parameter_table():
    X = np.random.default_rng(2).random((6, 5))
    with pytest.raises(ParameterError, match=r"^beta_nmf: init must be one of 'random', 'nndsvd'"):
        beta_nmf(X, 2, init="bogus")


@pytest.mark.parametrize("bad", ["W", "H"])
def test_beta_nmf_names_the_negative_starting_factor(bad):
    X = np.random.default_rng(3).random((6, 5))
    W, H = np.ones((6, 2)), np.ones((2, 5))
    factors = {"W": W, "H": H}
    factors[bad] = -factors[bad]
    with pytest.raises(DataError, match=rf"^Negative values in data passed to {bad}:"):
        beta_nmf(X, 2, init="custom", **factors)


@pytest.mark.parametrize("init", ["nndsvd", "nndsvda", "nndsvdar"])
def test_masked_svd_start_is_the_start_of_the_mean_filled_matrix(init):
    """As documented: with a mask, unobserved cells are filled with the observed mean before
    the SVD -- so the masked start equals the unmasked start of that filled matrix."""
    rng = np.random.default_rng(5)
    X = rng.random((12, 7)) + 0.1
    mask = rng.random(X.shape) < 0.7
    filled = np.where(mask, X, X[mask].mean())
    W1, H1 = initialize(np.where(mask, X, 0.0), 3, init, np.random.default_rng(0), mask=mask)
    W2, H2 = initialize(filled, 3, init, np.random.default_rng(0))
    np.testing.assert_allclose(W1, W2, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(H1, H2, rtol=1e-10, atol=1e-12)


# ------------------------------------------------------------------ from the hold-out sample


def test_partial_fit_without_n_components_uses_the_documented_default():
    X = np.random.default_rng(6).random((9, 4)) + 0.1
    model = NMF(None, max_iter=5, random_state=0).partial_fit(X)
    assert model.components_.shape == (min(X.shape), X.shape[1])  # "Default: min(n_samples, n_features)"


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_inverse_transform_takes_sparse_coefficients():
    rng = np.random.default_rng(7)
    model = NMF(3, max_iter=10, random_state=0).fit(rng.random((10, 6)) + 0.1)
    W = rng.random((4, 3)) * (rng.random((4, 3)) < 0.5)
    np.testing.assert_allclose(model.inverse_transform(sp.csr_matrix(W)), W @ model.components_, rtol=1e-12)


def test_relative_stopping_rule_also_stops_a_fit_whose_objective_is_below_one():
    """The rule is relative (decrease / first error < tol): Frobenius MU is scale-equivariant, so
    a fit of 1e-3 X (objective ~1e-6) must stop like the fit of X, not run to max_iter. (The
    stopping iterations are compared within two loss checks: in floating point the equivariance
    is not exact, and here the two fits stop 10 iterations apart.)"""
    X = np.random.default_rng(8).random((20, 10)) + 0.1
    fits = [NMF(3, beta_loss=2, tol=1e-3, max_iter=500, random_state=0).fit(c * X) for c in (1.0, 1e-3)]
    assert fits[0].n_iter_ < 500 and fits[1].n_iter_ < 500
    assert abs(fits[1].n_iter_ - fits[0].n_iter_) <= 20


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_a_sparse_mask_gives_the_fit_of_the_dense_mask():
    rng = np.random.default_rng(9)
    X = rng.random((12, 6)) + 0.1
    mask = rng.random(X.shape) < 0.7
    dense = NMF(2, beta_loss=1, max_iter=20, random_state=0).fit(X, mask=mask)
    sparse = NMF(2, beta_loss=1, max_iter=20, random_state=0).fit(X, mask=sp.csr_matrix(mask))
    np.testing.assert_allclose(sparse.components_, dense.components_, rtol=1e-10)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
def test_itakura_saito_refuses_observed_zeros_of_sparse_x_only():
    """beta <= 0 is undefined at X = 0: implicit zeros of a sparse X count when observed, and
    do not when the mask hides them."""
    rng = np.random.default_rng(10)
    dense = (rng.random((8, 5)) + 0.1) * (rng.random((8, 5)) < 0.6)
    X = sp.csr_matrix(dense)
    with pytest.raises(DataError, match="beta_loss=0 is undefined where X is zero"):
        NMF(2, beta_loss=0, max_iter=5, random_state=0).fit(X)
    NMF(2, beta_loss=0, max_iter=5, random_state=0).fit(X, mask=dense > 0)  # zeros unobserved: fine
