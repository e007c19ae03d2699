"""Dynamic time warping (mmconcepts.sound.dtw, Thesis section 5.2.3).

Symmetry, zero self-distance, the bounds and the window's monotonicity are property tests
in ``tests/sound/test_properties.py``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.sound.dtw import dtw, dtw_distance_matrix, dtw_one_to_many

LOCALS = ("euclidean", "sqeuclidean")


def reference_dtw(a, b, window=None, local="euclidean"):
    """Plain full-matrix DP, written from the definition (no buffers, no lanes)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a = a[:, None] if a.ndim == 1 else a
    b = b[:, None] if b.ndim == 1 else b
    n, m = len(a), len(b)
    D = np.full((n + 1, m + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            if window is not None and not (-window - max(0, n - m) <= j - i <= window + max(0, m - n)):
                continue
            c = float(np.sum((a[i - 1] - b[j - 1]) ** 2))
            if local == "euclidean":
                c = np.sqrt(c)
            D[i, j] = c + min(D[i - 1, j - 1], D[i - 1, j], D[i, j - 1])
    return float(np.sqrt(D[n, m])) if local == "sqeuclidean" else float(D[n, m])


def random_sequences(rng, count, lengths=(1, 12), d=3):
    return [rng.standard_normal((int(rng.integers(lengths[0], lengths[1] + 1)), d)) for _ in range(count)]


# ---------------------------------------------------------------------------- definition


@pytest.mark.parametrize("local", LOCALS)
@pytest.mark.parametrize("window", [None, 0, 1, 3])
def test_matches_reference_dp(rng, local, window):
    for _ in range(25):
        n, m, d = rng.integers(1, 10, size=3)
        a = rng.standard_normal((n, d))
        b = rng.standard_normal((m, d))
        expected = reference_dtw(a, b, window, local)
        assert dtw(a, b, window=window, local=local) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("window", [None, 0, 7])
def test_long_sequences_match_reference_dp(rng, window):
    """Sequences longer than the kernel's row chunk (32 frames), in both orders."""
    a = rng.standard_normal((71, 3))
    b = rng.standard_normal((45, 3))
    for local in LOCALS:
        expected = reference_dtw(a, b, window, local)
        assert dtw(a, b, window=window, local=local) == pytest.approx(expected, rel=1e-12)
        assert dtw(b, a, window=window, local=local) == pytest.approx(expected, rel=1e-12)
    D = dtw_distance_matrix([a, b, a[:33]], window=window)
    assert D[0, 1] == pytest.approx(reference_dtw(a, b, window), rel=1e-12)
    assert D[1, 2] == pytest.approx(reference_dtw(b, a[:33], window), rel=1e-12)


def test_one_dimensional_input_is_d_equal_one(rng):
    a = rng.standard_normal(7)
    b = rng.standard_normal(5)
    assert dtw(a, b) == dtw(a[:, None], b[:, None]) == pytest.approx(reference_dtw(a, b))
    # in 1-D the euclidean frame distance is |a_i - b_j|
    assert dtw([0.0, 1.0, 2.0, 2.0, 3.0], [0.0, 1.0, 2.0, 3.0]) == 0.0
    assert dtw([0.0, 0.0], [1.0, 3.0]) == 4.0


@pytest.mark.parametrize("window", [None, 0, 2])
def test_sqeuclidean_equals_dtaidistance(rng, window):
    dtw_ndim = pytest.importorskip("dtaidistance.dtw_ndim")
    for _ in range(20):
        n, m = rng.integers(1, 15, size=2)
        a = rng.standard_normal((n, 4))
        b = rng.standard_normal((m, 4))
        # dtaidistance counts the diagonal in its window: its window=w is our window=w - 1
        theirs = dtw_ndim.distance(a, b, window=None if window is None else window + 1)
        assert dtw(a, b, window=window, local="sqeuclidean") == pytest.approx(theirs, rel=1e-12, abs=1e-12)


def test_time_stretched_copy_is_closer_than_euclidean_alignment():
    """The same trajectory at a varying speed: DTW warps it back, the frame-by-frame
    (Euclidean-aligned, i.e. diagonal path) distance does not."""
    t = np.linspace(0, 1, 40)

    def curve(s):
        return np.stack([np.sin(2 * np.pi * 2 * s), np.cos(2 * np.pi * 3 * s), s], axis=1)

    a, b = curve(t), curve(t**1.6)
    euclid_aligned = float(np.sum(np.linalg.norm(a - b, axis=1)))
    assert euclid_aligned == pytest.approx(dtw(a, b, window=0))
    assert dtw(a, b) < 0.25 * euclid_aligned
    assert dtw(a, b, local="sqeuclidean") < 0.25 * np.sqrt(np.sum((a - b) ** 2))
    # a copy with every frame said twice is at distance exactly zero
    assert dtw(a, np.repeat(a, 2, axis=0)) == 0.0


def test_window_zero_on_equal_lengths_is_the_diagonal(rng):
    a = rng.standard_normal((9, 3))
    b = rng.standard_normal((9, 3))
    diag = float(np.sum(np.linalg.norm(a - b, axis=1)))
    assert dtw(a, b, window=0) == pytest.approx(diag, rel=1e-13)
    assert dtw(a, b, window=0, local="sqeuclidean") == pytest.approx(np.sqrt(np.sum((a - b) ** 2)), rel=1e-13)


def test_window_narrower_than_length_difference_is_finite(rng):
    a = rng.standard_normal((20, 2))
    b = rng.standard_normal((5, 2))
    for window in (0, 1, 2):
        value = dtw(a, b, window=window)
        assert np.isfinite(value)
        assert value == pytest.approx(reference_dtw(a, b, window), rel=1e-12)
    # a wider window can only lower the distance; a window >= max length is no window
    values = [dtw(a, b, window=w) for w in range(25)]
    assert all(x >= y for x, y in itertools.pairwise(values))
    assert values[-1] == dtw(a, b)


# ---------------------------------------------------------------------------- matrix


@pytest.mark.parametrize("local", LOCALS)
@pytest.mark.parametrize("window", [None, 2])
def test_matrix_symmetric_zero_diagonal_and_pairwise(rng, local, window):
    X = random_sequences(rng, 11, lengths=(1, 14), d=3)
    D = dtw_distance_matrix(X, window=window, local=local)
    assert D.shape == (11, 11) and D.dtype == np.float64
    assert np.array_equal(D, D.T)
    assert np.all(np.diag(D) == 0.0)
    pairwise = np.array([[dtw(a, b, window=window, local=local) for b in X] for a in X])
    np.fill_diagonal(pairwise, 0.0)
    assert np.array_equal(D, pairwise)  # bit for bit, whatever the lanes and blocks


def test_matrix_rectangular_and_threads(rng):
    X = random_sequences(rng, 7, lengths=(3, 20), d=2)
    Y = random_sequences(rng, 150, lengths=(3, 20), d=2)
    D = dtw_distance_matrix(X, Y, local="sqeuclidean", n_jobs=1)
    assert D.shape == (7, 150)
    expected = np.array([[reference_dtw(a, b, local="sqeuclidean") for b in Y[:20]] for a in X])
    np.testing.assert_allclose(D[:, :20], expected, rtol=1e-12)
    # the threaded kernel is used above 200 000 DP cells: make a problem that big
    Z = random_sequences(rng, 120, lengths=(20, 40), d=2)
    serial = dtw_distance_matrix(Z, n_jobs=1)
    assert np.array_equal(dtw_distance_matrix(Z, n_jobs=-1), serial)
    assert np.array_equal(dtw_distance_matrix(Z, Z[:30], n_jobs=2), serial[:, :30])


def test_large_matrices_run_on_the_threads_asked_for(rng, monkeypatch):
    """n_jobs threads (clipped to NUMBA_NUM_THREADS) for a large matrix, none for a small one."""
    import numba

    from mmconcepts.sound import dtw as module

    sizes = []
    real = module.ThreadPoolExecutor

    def spy(n, **kwargs):
        sizes.append(n)
        return real(n, **kwargs)

    monkeypatch.setattr(module, "ThreadPoolExecutor", spy)
    Z = random_sequences(rng, 120, lengths=(20, 40), d=2)
    dtw_distance_matrix(Z, n_jobs=2)
    dtw_distance_matrix(Z[:5], n_jobs=2)
    assert sizes == [min(2, numba.config.NUMBA_NUM_THREADS)]


def test_matrix_equals_dtaidistance(rng):
    dtw_ndim = pytest.importorskip("dtaidistance.dtw_ndim")
    X = random_sequences(rng, 30, lengths=(5, 25), d=13)
    for local, inner in (("sqeuclidean", "squared euclidean"), ("euclidean", "euclidean")):
        theirs = dtw_ndim.distance_matrix_fast(X, inner_dist=inner, parallel=False)
        np.testing.assert_allclose(dtw_distance_matrix(X, local=local), theirs, rtol=1e-12, atol=0)


def test_three_d_input_equals_list_input(rng):
    X3 = rng.standard_normal((9, 8, 4))
    Y3 = rng.standard_normal((5, 8, 4))
    for window in (None, 1):
        assert np.array_equal(dtw_distance_matrix(X3, window=window), dtw_distance_matrix(list(X3), window=window))
        assert np.array_equal(dtw_distance_matrix(X3, Y3, window=window),
                              dtw_distance_matrix(list(X3), list(Y3), window=window))
    # float32 and non-contiguous arrays are accepted (converted to float64)
    assert np.array_equal(dtw_distance_matrix(X3.astype(np.float32)),
                          dtw_distance_matrix(X3.astype(np.float32).astype(np.float64)))
    Xf = np.asfortranarray(X3)
    assert np.array_equal(dtw_distance_matrix(Xf), dtw_distance_matrix(X3))


def test_single_sequence_matrix_is_zero(rng):
    assert np.array_equal(dtw_distance_matrix([rng.standard_normal((4, 2))]), np.zeros((1, 1)))


# ---------------------------------------------------------------------------- one to many


@pytest.mark.parametrize("window", [None, 2])
def test_one_to_many_equals_matrix_row(rng, window):
    X = random_sequences(rng, 13, lengths=(2, 16), d=3)
    D = dtw_distance_matrix(X, window=window, local="sqeuclidean")
    row = dtw_one_to_many(X[4], X, window=window, local="sqeuclidean")
    assert row.shape == (13,)
    assert np.array_equal(row, D[4])
    # fixed-length windows as a 3-D array, the incremental cluster tree's call
    W = rng.standard_normal((37, 15, 13))
    q = rng.standard_normal((15, 13))
    out = dtw_one_to_many(q, W, window=window)
    assert np.array_equal(out, np.array([dtw(q, w, window=window) for w in W]))
    assert np.array_equal(out, dtw_one_to_many(q, list(W), window=window))
    assert np.array_equal(out[:1], dtw_one_to_many(q, W[:1], window=window))
    # a query of another length than the windows
    q11 = rng.standard_normal((11, 13))
    assert np.array_equal(dtw_one_to_many(q11, W, window=window), np.array([dtw(q11, w, window=window) for w in W]))
    assert dtw_one_to_many(q11, W[:3], window=window)[2] == pytest.approx(reference_dtw(q11, W[2], window), rel=1e-12)


def test_one_to_many_large_call_runs_threaded_and_agrees(rng):
    W = rng.standard_normal((1200, 15, 3))  # 1200 * 15 * 15 > 200 000 DP cells
    q = rng.standard_normal((15, 3))
    assert np.array_equal(dtw_one_to_many(q, W, n_jobs=2), dtw_one_to_many(q, W, n_jobs=1))


# ---------------------------------------------------------------------------- bad input


def test_nan_or_inf_names_the_sequence(rng):
    X = random_sequences(rng, 5, lengths=(3, 6))
    X[3] = X[3].copy()
    X[3][1, 0] = np.nan
    with pytest.raises(DataError, match=r"X\[3\].*NaN or infinite"):
        dtw_distance_matrix(X)
    with pytest.raises(DataError, match=r"Y\[3\]"):
        dtw_distance_matrix(X[:2], X)
    X3 = rng.standard_normal((6, 4, 2))
    X3[2, 3, 1] = np.inf
    with pytest.raises(DataError, match=r"candidates\[2\]"):
        dtw_one_to_many(X3[0], X3)
    with pytest.raises(DataError, match=r"X\[2\]"):
        dtw_distance_matrix(X3)
    with pytest.raises(DataError, match="query"):
        dtw_one_to_many(X3[2], X3[:2])
    with pytest.raises(DataError, match=r"\bb\b"):
        dtw(X3[0], X3[2])


def test_empty_sequences_name_the_index(rng):
    X = random_sequences(rng, 4, lengths=(3, 6))
    X[2] = np.empty((0, 3))
    with pytest.raises(DataError, match=r"X\[2\] is empty"):
        dtw_distance_matrix(X)
    with pytest.raises(DataError, match="a is empty"):
        dtw([], [1.0, 2.0])
    with pytest.raises(DataError, match="no sequence"):
        dtw_distance_matrix([])
    with pytest.raises(DataError, match="no sequence"):
        dtw_one_to_many(np.ones((3, 2)), np.empty((0, 3, 2)))


def test_mismatched_dimensions_name_the_index(rng):
    X = random_sequences(rng, 4, d=3)
    X[1] = rng.standard_normal((5, 2))
    with pytest.raises(DataError, match=r"X\[1\] has d = 2.*X\[0\] has d = 3"):
        dtw_distance_matrix(X)
    with pytest.raises(DataError, match="same number of values per frame"):
        dtw(np.ones((3, 2)), np.ones((3, 3)))
    with pytest.raises(DataError, match="d = 3.*query has d = 2"):
        dtw_one_to_many(np.ones((3, 2)), np.ones((4, 3, 3)))
    with pytest.raises(DataError, match="X and Y must have the same d"):
        dtw_distance_matrix(np.ones((2, 3, 2)), np.ones((2, 3, 3)))


def test_ambiguous_or_wrong_shapes_are_refused():
    with pytest.raises(DataError, match=r"X\[:, :, None\]"):
        dtw_distance_matrix(np.ones((4, 6)))
    with pytest.raises(DataError, match="(n_frames, d)"):
        dtw(np.ones((2, 3, 4)), np.ones((2, 3)))
    with pytest.raises(DataError, match="numbers"):
        dtw(np.array(["a", "b"]), np.ones(2))
    with pytest.raises(DataError, match="list of"):
        dtw_distance_matrix("abc")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(window=-1), "window"),
        (dict(window=1.5), "window"),
        (dict(window=True), "window"),
        (dict(window="3"), "window"),
        (dict(local="cityblock"), "local"),
        (dict(n_jobs=0), "n_jobs"),
        (dict(n_jobs=1.0), "n_jobs"),
    ],
)
def test_bad_parameters(kwargs, match):
    X = [np.ones((3, 2)), np.zeros((4, 2))]
    with pytest.raises(ParameterError, match=match):
        dtw_distance_matrix(X, **kwargs)
    if "n_jobs" not in kwargs:
        with pytest.raises(ParameterError, match=match):
            dtw(X[0], X[1], **kwargs)
        with pytest.raises(ParameterError, match=match):
            dtw_one_to_many(X[0], X, **kwargs)
