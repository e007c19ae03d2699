"""Fuzz tests of mmconcepts.nmf's public entry points.

Every example ends in :func:`_fuzz.assert_typed_or_good`: a typed mmconcepts error naming
the problem, or a finite result that is *right* (the ``check`` says what right means:
shapes, nonnegativity, an objective that does not rise where the updates promise it,
scale equivariance, agreement with scikit-learn's multiplicative updates).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from mmconcepts.errors import DataError
from mmconcepts.nmf import (
    NMF,
    LabelNMF,
    beta_divergence,
    beta_nmf,
    dictionary_distance,
    hoyer_sparseness,
    l_full,
    l_full_curve,
    l_given_number,
    l_single,
    match_components,
    project_hoyer,
    threshold_scores,
)

pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore")]

SPECIALS = [np.nan, np.inf, -np.inf, -1.0, 0.0, 1e-320, 1e308]
BETAS = [-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, "frobenius", "kullback-leibler", "itakura-saito"]


def _beta_value(beta) -> float:
    return {"frobenius": 2.0, "kullback-leibler": 1.0, "itakura-saito": 0.0}.get(beta, beta)


@st.composite
def matrices(draw, max_side: int = 7, positive: bool = False):
    """A data matrix: mostly valid nonnegative data at any scale, sometimes special values,
    odd dtypes, wrong dimensions, empty or sparse."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(1, max_side))
    m = draw(st.integers(1, max_side))
    scale = 10.0 ** draw(st.sampled_from([0, 0, 0, -8, 8, -300, 300, -12, 12]))
    X = rng.random((n, m)) * scale
    if positive:
        X += 0.1 * scale
    kind = draw(st.sampled_from(["plain"] * 6 + ["zeros", "special", "constant", "int", "float32", "bool",
                                                  "1d", "3d", "empty", "object", "sparse", "sparse"]))
    if kind == "zeros":
        X[rng.random((n, m)) < 0.5] = 0.0
    elif kind == "special":
        X[rng.integers(n), rng.integers(m)] = draw(st.sampled_from(SPECIALS))
    elif kind == "constant":
        X[:] = draw(st.sampled_from([0.0, 1.0, 1e-300, 1e300]))
    elif kind == "int":
        X = (X * 10 / max(scale, 1e-300)).astype(np.int64)
    elif kind == "float32":
        X = X.astype(np.float32)
    elif kind == "bool":
        X = X > 0.5 * scale
    elif kind == "1d":
        X = X.ravel()
    elif kind == "3d":
        X = X[:, :, None]
    elif kind == "empty":
        X = np.zeros((0, m))
    elif kind == "object":
        X = X.astype(object)
        X[0, 0] = "a"
    elif kind == "sparse":
        X[rng.random((n, m)) < 0.6] = 0.0
        X = sp.random_array((n, m), density=0.5, rng=rng).tocsr() * scale if draw(st.booleans()) else sp.csr_matrix(X)
    return X


def _shape(X):
    return getattr(X, "shape", None)


def _monotone(hist: np.ndarray, rel: float, atol: float) -> bool:
    """The objective never rises by more than rounding (relative to its first value, or ``atol``,
    the rounding of a divergence at the data's scale when the objective is near 0)."""
    hist = np.asarray(hist, dtype=float)
    if hist.size < 2:
        return True
    ref = max(abs(float(hist[0])), atol / rel)
    return bool(np.all(np.diff(hist) <= rel * ref + rel * np.abs(hist[1:])))


def _rounding(X, beta: float) -> float:
    """The size of rounding errors of a beta-divergence summed over X's cells."""
    Xd = X.toarray() if sp.issparse(X) else np.asarray(X, dtype=float)
    finite = Xd[np.isfinite(Xd)] if Xd.dtype.kind in "fc" else Xd.ravel()
    xmax = float(np.max(finite)) if finite.size else 0.0
    with np.errstate(over="ignore"):
        size = Xd.size * (float(np.float64(xmax) ** beta) if xmax > 0 else 1.0)
    return min(1e-12 * size, 1e300)  # (capped: an objective beyond it is refused anyway)


def _nmf_check(res, n, m, k, *, monotone: bool, rel: float, atol: float) -> bool:
    ok = (res.W.shape == (n, k) and res.H.shape == (k, m) and (res.W >= 0).all() and (res.H >= 0).all()
          and res.loss_history.ndim == 1 and res.loss_history.size == res.loss_iterations.size
          and (res.loss_history >= -atol - 1e-9 * abs(float(res.loss_history[0]))).all())
    if ok and monotone:
        ok = _monotone(res.loss_history, rel, atol)
    return bool(ok)


@fuzz_settings(300, suppress_health_check=list(HealthCheck))
@given(
    X=matrices(),
    k=st.sampled_from([None, 1, 2, 3, 0, -1, 10**6]),
    beta=st.sampled_from(BETAS),
    solver=st.sampled_from(["mu", "mu", "pg"]),
    update_rule=st.sampled_from(["mm", "mm", "heuristic"]),
    init=st.sampled_from([None, "random", "nndsvd", "nndsvda", "nndsvdar"]),
    masked=st.sampled_from([None, "dense", "sparse"]),
    sparseness=st.sampled_from([None, None, None, ("H", 0.5), ("W", 0.5), ("H", 1.0), ("W", 0.0), ("H", np.nan),
                                ("W", 1.5)]),
    penalty=st.sampled_from([None, None, (0.1, 0.5), (1.0, 0.0), (-1.0, 0.0), (np.inf, 1.0)]),
    seed=st.integers(0, 2**31 - 1),
)
def test_fuzz_beta_nmf(X, k, beta, solver, update_rule, init, masked, sparseness, penalty, seed):
    rng = np.random.default_rng(seed)
    mask = None
    shape = _shape(X)
    if masked is not None and shape is not None and len(shape) == 2 and 0 not in shape:
        M = rng.random(shape) < 0.7
        M.flat[0] = True
        mask = sp.csr_matrix(M) if masked == "sparse" else M
    kw: dict = {}
    if sparseness is not None:
        kw["sparseness_" + sparseness[0]] = sparseness[1]
    if penalty is not None:
        kw["alpha_W"], kw["l1_ratio"] = penalty
    b = _beta_value(beta)
    # The objective may not rise: MM updates for every beta, the heuristic ones for 1 <= beta <= 2,
    # the projected-gradient and Hoyer steps (they accept only a step that does not increase it; the
    # factor without a Hoyer constraint is updated by the solver and rule given).
    # An L2 penalty (l1_ratio < 1) breaks the MM guarantee of the multiplicative updates (documented).
    monotone = (update_rule == "mm" or 1.0 <= b <= 2.0) and (penalty is None or penalty[1] == 1.0) or solver == "pg"
    rel = 1e-4 if getattr(X, "dtype", None) == np.float32 else 1e-8

    def check(res):
        n, m = shape
        kk = k if k is not None else min(n, m)
        return _nmf_check(res, n, m, kk, monotone=monotone, rel=rel, atol=_rounding(X, b))

    assert_typed_or_good(
        "mmconcepts.nmf.beta_nmf",
        lambda: beta_nmf(X, k, beta_loss=beta, solver=solver, update_rule=update_rule, init=init, mask=mask,
                         max_iter=15, tol=0, loss_every=1, random_state=seed, **kw),
        check=check,
    )


@st.composite
def complex_or_real_matrices(draw, max_side: int = 6):
    """A nonnegative real matrix, or the same values with complex numbers mixed in: a complex array
    (with a random or a zero imaginary part, the imaginary part only in some cells), a sparse complex
    matrix, an object array or nested lists holding one complex number among floats. Returns
    ``(X, is_complex)``."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n, m = draw(st.integers(1, max_side)), draw(st.integers(1, max_side))
    R = rng.random((n, m)) + 0.01
    kind = draw(st.sampled_from(["real", "real", "real_sparse", "complex", "zero_imag", "some_imag",
                                 "sparse_complex", "object", "lists"]))
    if kind == "real":
        return R, False
    if kind == "real_sparse":
        return sp.csr_matrix(R), False
    if kind == "complex":
        return R + 1j * rng.random((n, m)), True
    if kind == "zero_imag":
        return R.astype(complex), True
    if kind == "some_imag":
        C = R.astype(complex)
        C[rng.random((n, m)) < 0.3] += 1j
        return C, True
    if kind == "sparse_complex":
        return sp.csr_matrix(R + 1j * rng.random((n, m))), True
    i, j = rng.integers(n), rng.integers(m)
    if kind == "object":
        O = R.astype(object)
        O[i, j] = complex(R[i, j], 1.0)
        return O, True
    rows = R.tolist()  # "lists": Python floats with one complex among them
    rows[i][j] = complex(rows[i][j], 1.0)
    return rows, True


@fuzz_settings(150, suppress_health_check=list(HealthCheck))
@given(
    Xc=complex_or_real_matrices(),
    masked=st.sampled_from(["dense", "dense", "sparse", "all", None]),
    entry=st.sampled_from(["beta_nmf", "NMF.fit", "beta_divergence"]),
    beta=st.sampled_from([1.0, 2.0, 0.5]),
    seed=st.integers(0, 2**31 - 1),
)
def test_fuzz_complex_masked_input(Xc, masked, entry, beta, seed):
    """Complex numbers in X, with or without a mask, are refused (a typed error, the imaginary part never
    dropped); the real matrix beside them fits."""
    X, is_complex = Xc
    rng = np.random.default_rng(seed)
    n, m = np.shape(X) if not sp.issparse(X) else X.shape
    mask = None
    if masked is not None:
        M = np.ones((n, m), bool) if masked == "all" else rng.random((n, m)) < 0.7
        M.flat[0] = True
        mask = sp.csr_matrix(M) if masked == "sparse" else M
    k = min(2, n, m)
    W, H = rng.random((n, k)) + 0.1, rng.random((k, m)) + 0.1

    def run():
        if entry == "beta_nmf":
            res = beta_nmf(X, k, beta_loss=beta, mask=mask, max_iter=5, tol=0, random_state=seed)
            return res.W, res.H
        if entry == "NMF.fit":
            model = NMF(k, beta_loss=beta, max_iter=5, tol=0, random_state=seed).fit(X, mask=mask)
            return model.components_, model.transform(np.ones((1, m)))
        return beta_divergence(X, W, H, beta, mask=mask)

    def check(res):
        if is_complex:  # complex input never gives a result
            return False
        if entry == "beta_divergence":
            return bool(res >= 0)
        return bool(all((np.asarray(a) >= 0).all() and np.isrealobj(a) for a in res))

    assert_typed_or_good("mmconcepts.nmf[complex or real X, masked]", run, check=check)


#: Ways a given starting factor goes wrong: zeros (a row of W, a column of H, a random pattern, all of
#: it), special values, tiny values, wrong shapes and types.
START_KINDS = ["ok", "zero_row_W", "zero_col_H", "pattern", "pattern", "all_zero_W", "all_zero_H", "nan", "inf",
               "negative", "tiny", "shape_W", "shape_H", "1d", "sparse_W", "int", "float32", "list"]


@st.composite
def starts(draw):
    """Data and a start for it: block-diagonal data, whose NNDSVD start is zero on whole blocks, and
    either an SVD start or given factors (``START_KINDS``)."""
    from scipy.linalg import block_diag

    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n_blocks = draw(st.integers(1, 4))
    blocks = []
    for b in range(n_blocks):  # decreasing weights: the SVD's leading vectors live on the first blocks
        size = (draw(st.integers(1, 4)), draw(st.integers(1, 4)))
        weight = 10.0 ** -draw(st.integers(0, 2)) / (b + 1)
        blocks.append(rng.random(size) * weight + 0.1 * weight)
    # X's positive values (and the products of the "tiny" starts) stay above float32's eps, where the
    # updates clip W @ H and lose their monotonicity when it goes below: a matter of the updates, not
    # of the start
    X = block_diag(*blocks) + draw(st.sampled_from([0.0, 0.0, 1e-3]))
    if draw(st.booleans()):
        X = X[rng.permutation(X.shape[0])][:, rng.permutation(X.shape[1])]
    n, m = X.shape
    k = draw(st.integers(1, min(n, m) + 1))
    init = draw(st.sampled_from(["nndsvd", "nndsvd", "nndsvda", "nndsvdar", "custom", "custom", "custom"]))
    W = H = None
    kind = "ok"
    if init == "custom":
        kind = draw(st.sampled_from(START_KINDS))
        W, H = rng.random((n, k)) + 0.1, rng.random((k, m)) + 0.1
        if kind == "zero_row_W":
            W[rng.integers(n)] = 0.0
        elif kind == "zero_col_H":
            H[:, rng.integers(m)] = 0.0
        elif kind == "pattern":
            W[rng.random(W.shape) < 0.5] = 0.0
            H[rng.random(H.shape) < 0.5] = 0.0
        elif kind == "all_zero_W":
            W[:] = 0.0
        elif kind == "all_zero_H":
            H[:] = 0.0
        elif kind in ("nan", "inf", "negative"):
            W[rng.integers(n), rng.integers(k)] = {"nan": np.nan, "inf": np.inf, "negative": -1.0}[kind]
        elif kind == "tiny":  # products about 1e-6: small, not zero
            W, H = W * 1e-3, H * 1e-3
        elif kind == "shape_W":
            W = W[:, :-1] if k > 1 else W[:-1]
        elif kind == "shape_H":
            H = H[:-1] if k > 1 else H[:, :-1]
        elif kind == "1d":
            W = W.ravel()
        elif kind == "sparse_W":
            W = sp.csr_matrix(W)
        elif kind == "int":
            W, H = (W * 3).astype(int), (H * 3).astype(int)
        elif kind == "float32":
            W, H = W.astype(np.float32), H.astype(np.float32)
        elif kind == "list":
            W, H = W.tolist(), H.tolist()
    if draw(st.booleans()):
        X = sp.csr_matrix(X)
    return X, k, init, W, H, kind


@fuzz_settings(200, suppress_health_check=list(HealthCheck))
@given(start=starts(), beta=st.sampled_from([0.0, 0.5, 1.0, 1.5, 2.0]), solver=st.sampled_from(["mu", "mu", "pg"]),
       update_H=st.sampled_from([True, True, False]), masked=st.booleans(), seed=st.integers(0, 2**31 - 1))
def test_fuzz_beta_nmf_starts(start, beta, solver, update_H, masked, seed):
    """Starts a fit cannot leave: an SVD start or given factors whose zeros leave W @ H zero where X > 0.
    A good result: a start whose W @ H is positive at every positive observed cell of X (an SVD start),
    or a given one whose zeros that product misses are kept (beta > 1); then a fit whose objective is
    finite for beta <= 1 and never rises."""
    X, k, init, W, H, kind = start
    rng = np.random.default_rng(seed)
    mask = None
    if masked:
        mask = rng.random(X.shape) < 0.8
        mask.flat[0] = True
    kw = dict(beta_loss=beta, solver=solver, init=init, W=W, H=H, update_H=update_H if init == "custom" else True,
              mask=mask, tol=0, loss_every=1, random_state=seed)

    def check(fits):
        start, res = fits
        n, m = X.shape
        if not _nmf_check(res, n, m, k, monotone=True, rel=1e-4, atol=_rounding(X, beta)):
            return False
        if not (np.isfinite(res.W).all() and np.isfinite(res.H).all()):
            return False
        if beta <= 1 and not np.isfinite(res.loss_history[-1]):
            return False
        if init != "custom":  # the SVD start reaches every positive observed cell
            Xd = X.toarray() if sp.issparse(X) else X
            positive = (Xd > 0) if mask is None else (Xd > 0) & mask
            return bool(((start.W @ start.H)[positive] > 0).all())
        return True

    assert_typed_or_good("mmconcepts.nmf.beta_nmf[starts]",
                         lambda: (beta_nmf(X, k, max_iter=0, **kw), beta_nmf(X, k, max_iter=15, **kw)), check=check)


@fuzz_settings(80, suppress_health_check=list(HealthCheck))
@given(
    seed=st.integers(0, 2**31 - 1),
    log_scale=st.floats(-12, 12),
    beta=st.sampled_from([1.0, 2.0]),
    init=st.sampled_from(["custom", "random"]),
    sparse=st.booleans(),
)
def test_fuzz_beta_nmf_scale_equivariance(seed, log_scale, beta, init, sparse):
    """Scale-invariant losses give scale-equivariant fits: fit(c X) = (W, c H) (up to the diagonal
    scaling every NMF has: W D, D^-1 H), and the objective scales as c ** beta."""
    rng = np.random.default_rng(seed)
    n, m, k = 12, 9, 3
    X = rng.random((n, k)) @ rng.random((k, m)) + 0.05 * rng.random((n, m))
    if sparse:
        X[rng.random((n, m)) < 0.3] = 0.0
    c = 10.0**log_scale
    W0, H0 = rng.random((n, k)) + 0.1, rng.random((k, m)) + 0.1
    conv = sp.csr_matrix if sparse else np.asarray

    def fit(A, H_start):
        kw = dict(W=W0, H=H_start) if init == "custom" else dict(init="random")
        return beta_nmf(conv(A), k, beta_loss=beta, max_iter=30, tol=0, loss_every=5, random_state=seed, **kw)

    ref = fit(X, H0)

    def check(res):
        if init == "custom":  # exactly (W, c H)
            ok = np.allclose(res.W, ref.W, rtol=1e-6, atol=1e-9 * ref.W.max())
            ok &= np.allclose(res.H / c, ref.H, rtol=1e-6, atol=1e-9 * ref.H.max())
        else:  # up to the diagonal scaling
            ok = np.allclose(res.W @ res.H / c, ref.W @ ref.H, rtol=1e-6, atol=1e-9 * X.max())
            Hn, Hr = res.H / res.H.sum(1, keepdims=True), ref.H / ref.H.sum(1, keepdims=True)
            ok &= np.allclose(Hn, Hr, rtol=1e-6, atol=1e-9)
        ok &= np.allclose(res.loss_history / c**beta, ref.loss_history, rtol=1e-6, atol=1e-12 * ref.loss_history[0])
        return bool(ok)

    assert_typed_or_good("mmconcepts.nmf.beta_nmf[scale equivariance]", lambda: fit(X * c, H0 * c), check=check)


@fuzz_settings(60, suppress_health_check=list(HealthCheck))
@given(seed=st.integers(0, 2**31 - 1), beta=st.sampled_from([1.0, 2.0, 0.5, 1.5]),
       alpha=st.sampled_from([0.0, 0.0, 0.01]), l1_ratio=st.sampled_from([0.0, 1.0, 0.5]))
def test_fuzz_beta_nmf_agrees_with_scikit_learn(seed, beta, alpha, l1_ratio):
    """On ordinary data, from the same start, the multiplicative updates are scikit-learn's (solver='mu')."""
    from sklearn.decomposition import NMF as SkNMF

    rng = np.random.default_rng(seed)
    n, m, k = 10, 8, 3
    X = rng.random((n, k)) @ rng.random((k, m)) + 0.01
    W0, H0 = rng.random((n, k)) + 0.1, rng.random((k, m)) + 0.1
    sk = SkNMF(k, init="custom", solver="mu", beta_loss=beta, max_iter=20, tol=0, alpha_W=alpha,
               l1_ratio=l1_ratio)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        Wsk = sk.fit_transform(X, W=W0.copy(), H=H0.copy())
    # scikit-learn's heuristic exponent is 1 for beta in [1, 2]; its MM exponent outside
    rule = "mm"

    def check(res):
        return bool(np.allclose(res.W, Wsk, rtol=1e-6, atol=1e-10) and np.allclose(res.H, sk.components_, rtol=1e-6,
                                                                                   atol=1e-10))

    assert_typed_or_good(
        "mmconcepts.nmf.beta_nmf[vs scikit-learn]",
        lambda: beta_nmf(X, k, beta_loss=beta, W=W0, H=H0, max_iter=20, tol=0, alpha_W=alpha, l1_ratio=l1_ratio,
                         update_rule=rule),
        check=check,
    )


@fuzz_settings(40, suppress_health_check=list(HealthCheck))
@given(seed=st.integers(0, 2**31 - 1), beta=st.sampled_from([1.0, 2.0, 0.5]))
def test_fuzz_beta_nmf_recovers_exactly_factorisable_data(seed, beta):
    """X = W0 H0 exactly: started next to the truth, the fit reconstructs X (relative error < 1e-3)."""
    rng = np.random.default_rng(seed)
    n, m, k = 15, 12, 3
    W0, H0 = rng.random((n, k)) + 0.1, rng.random((k, m)) + 0.1
    X = W0 @ H0

    def check(res):
        return bool(np.linalg.norm(res.W @ res.H - X) <= 1e-3 * np.linalg.norm(X))

    assert_typed_or_good(
        "mmconcepts.nmf.beta_nmf[exact data]",
        lambda: beta_nmf(X, k, beta_loss=beta, W=W0 * 1.05, H=H0 * 0.95, max_iter=300, tol=0),
        check=check,
    )


@fuzz_settings(150, suppress_health_check=list(HealthCheck))
@given(
    X=matrices(max_side=6),
    k=st.sampled_from([None, 1, 2, 3]),
    beta=st.sampled_from(BETAS),
    features=st.sampled_from([None, "slice", "ints", "bools", "bad_ints", "empty"]),
    method=st.sampled_from(["fit_transform", "transform", "inverse", "partial_fit", "partial_fit2"]),
    seed=st.integers(0, 2**31 - 1),
)
def test_fuzz_nmf_estimator(X, k, beta, features, method, seed):
    shape = _shape(X)

    def run():
        model = NMF(k, beta_loss=beta, max_iter=8, tol=0, random_state=seed)
        if method == "fit_transform":
            return model.fit_transform(X), model.components_
        if method in ("partial_fit", "partial_fit2"):
            model.partial_fit(X)
            if method == "partial_fit2":
                model.partial_fit(X)
            # the objective is >= 0 up to rounding
            return model.components_, model.loss_history_ + _rounding(X, _beta_value(beta))
        model.fit(X)
        m = model.n_features_in_
        sel = {None: None, "slice": slice(0, max(1, m // 2)), "ints": np.arange(m)[::-1][: max(1, m - 1)],
               "bools": np.arange(m) % 2 == 0, "bad_ints": np.array([m + 3]), "empty": np.array([], int)}[features]
        Xd = X.toarray() if sp.issparse(X) else np.asarray(X, dtype=float)
        cols = Xd if sel is None else Xd[:, :1] if features == "bad_ints" else Xd[:, sel]
        if method == "transform":
            return model.transform(cols, features=sel), model.components_
        W = model.transform(cols, features=sel)
        return model.inverse_transform(W, features=sel), W

    def check(res):
        a, b = res
        return bool(np.all(np.asarray(a) >= 0) and np.all(np.asarray(b) >= 0)) and len(shape) == 2

    assert_typed_or_good("mmconcepts.nmf.NMF", run, check=check)


@fuzz_settings(40, suppress_health_check=list(HealthCheck))
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 12),
    n_labels=st.integers(1, 4),
    beta=st.sampled_from([1.0, 2.0, 0.0, 0.5]),
    labels=st.sampled_from(["multi", "single", "empty_rows", "bad_values", "wrong_rows", "nan_X"]),
    threshold=st.sampled_from([0.5, 0.3, np.nan, np.inf]),
)
def test_fuzz_label_nmf(seed, n, n_labels, beta, labels, threshold):
    rng = np.random.default_rng(seed)
    X = rng.random((n, 6))
    if labels == "nan_X":
        X[0, 0] = np.nan
    if labels == "single":
        y = rng.integers(0, n_labels, n)
    else:
        y = (rng.random((n, n_labels)) < 0.5).astype(int)
        if labels == "empty_rows":
            y[:] = 0
        elif labels == "bad_values":
            y = y * 3 - 1
        elif labels == "wrong_rows":
            y = y[:-1] if n > 1 else np.zeros((2, n_labels), int)

    def run():
        model = LabelNMF(n_components=3, beta_loss=beta, max_iter=10, threshold=threshold, random_state=seed)
        model.fit(X, y)
        return model.label_activations(X), model.predict(X)

    def check(res):
        act, pred = res
        return bool(act.shape[0] == n and (act >= 0).all() and len(pred) == n)

    assert_typed_or_good("mmconcepts.nmf.LabelNMF", run, check=check)


@fuzz_settings(400)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(0, 12),
    kind=st.sampled_from(["random", "signed", "constant", "negative", "one_hot", "zeros", "nan", "huge", "tiny"]),
    s=st.one_of(st.floats(0, 1), st.sampled_from([0.0, 1.0, -0.1, 1.1, np.nan])),
    l2=st.sampled_from([1.0, 1.0, 3.5, 1e-300, 1e300, 0.0, -1.0, np.inf, np.nan]),
)
def test_fuzz_project_hoyer(seed, n, kind, s, l2):
    rng = np.random.default_rng(seed)
    x = {"random": rng.random(n), "signed": rng.standard_normal(n), "constant": np.full(n, 0.7),
         "negative": -rng.random(n), "one_hot": np.eye(1, n, 0).ravel() if n else np.zeros(0), "zeros": np.zeros(n),
         "nan": np.full(n, np.nan), "huge": rng.random(n) * 1e300, "tiny": rng.random(n) * 1e-300}[kind]
    l1 = l2 * (np.sqrt(n) - (np.sqrt(n) - 1.0) * s) if n else l2

    def check(v):
        if v.shape != (n,) or (v < 0).any():
            return False
        return bool(abs(v.sum() / l2 - l1 / l2) <= 1e-6 * l1 / l2 and abs(np.linalg.norm(v / l2) - 1.0) <= 1e-6)

    assert_typed_or_good("mmconcepts.nmf.project_hoyer", lambda: project_hoyer(x, l1, l2), check=check)


@fuzz_settings(200)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(0, 8), kind=st.sampled_from(
    ["random", "signed", "constant", "one_hot", "zeros", "nan", "matrix"]))
def test_fuzz_hoyer_sparseness(seed, n, kind):
    rng = np.random.default_rng(seed)
    x = {"random": rng.random(n), "signed": rng.standard_normal(n), "constant": np.full(n, 2.0),
         "one_hot": np.eye(1, n, 0).ravel() if n else np.zeros(0), "zeros": np.zeros(n), "nan": np.full(n, np.nan),
         "matrix": rng.random((3, n))}[kind]
    axis = 1 if kind == "matrix" else None
    if kind == "zeros" and n >= 2:  # documented: NaN, the measure is undefined there
        assert np.isnan(hoyer_sparseness(x))
        return

    def check(s):
        s = np.asarray(s)
        ok = ((s >= -1e-12) & (s <= 1 + 1e-12)).all()
        if kind == "constant":
            ok &= bool(np.allclose(s, 0.0, atol=1e-12))
        if kind == "one_hot":
            ok &= bool(np.allclose(s, 1.0))
        return bool(ok)

    assert_typed_or_good("mmconcepts.nmf.hoyer_sparseness", lambda: hoyer_sparseness(x, axis=axis), check=check)


@fuzz_settings(300, suppress_health_check=list(HealthCheck))
@given(X=matrices(max_side=6), beta=st.sampled_from(BETAS + [np.nan, "nope"]), seed=st.integers(0, 2**31 - 1),
       k=st.integers(1, 3), masked=st.booleans())
def test_fuzz_beta_divergence(X, beta, seed, k, masked):
    rng = np.random.default_rng(seed)
    shape = _shape(X)
    n, m = shape if shape is not None and len(shape) == 2 else (2, 2)
    W, H = rng.random((n, k)), rng.random((k, m))
    mask = (rng.random((n, m)) < 0.7) if masked else None

    def reference():
        Xd = X.toarray() if sp.issparse(X) else np.asarray(X, dtype=float)
        from mmconcepts.nmf import elementwise_beta_divergence

        E = elementwise_beta_divergence(Xd, W @ H, _beta_value(beta))
        if mask is not None:
            E = np.where(mask, E, 0.0)
        return float(E.sum())

    def call():
        d = beta_divergence(X, W, H, beta, mask=mask)
        # documented: inf where the divergence is beyond float64 (e.g. x ** beta of a denormal x, beta < 0)
        return ("inf, the direct sum is not finite either",) if d == np.inf and not np.isfinite(reference()) else d

    def check(d):
        if isinstance(d, tuple):
            return True
        ref = reference()
        return bool(d >= -1e-9 * max(1.0, abs(ref)) and np.isclose(d, ref, rtol=1e-6, atol=1e-12))

    assert_typed_or_good("mmconcepts.nmf.beta_divergence", call, check=check)


@fuzz_settings(300)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(0, 6), n_labels=st.integers(0, 5),
       kind=st.sampled_from(["ok", "ok", "nan_scores", "inf_scores", "bad_labels", "shape", "no_true"]),
       thr=st.sampled_from([0.5, 0.0, np.nan, np.inf]))
def test_fuzz_scores(seed, n, n_labels, kind, thr):
    rng = np.random.default_rng(seed)
    Y = (rng.random((n, n_labels)) < 0.5).astype(int)
    if n and n_labels:
        Y[np.arange(n), rng.integers(0, n_labels, n)] = 1
    S = rng.random((n, n_labels))
    y1 = rng.integers(0, max(n_labels, 1), n)
    if kind == "nan_scores" and S.size:
        S.flat[0] = np.nan
    elif kind == "inf_scores" and S.size:
        S.flat[0] = np.inf
    elif kind == "bad_labels" and Y.size:
        Y.flat[0] = 2
        y1 = y1 - 5
    elif kind == "shape":
        S = S[:, :-1] if n_labels else S.T
    elif kind == "no_true":
        Y[:] = 0
    grid = np.linspace(0, 1, 5)

    def in01(v):
        return bool(0.0 <= v <= 1.0)

    assert_typed_or_good("mmconcepts.nmf.l_single", lambda: l_single(y1, S), check=in01)
    assert_typed_or_good("mmconcepts.nmf.l_given_number", lambda: l_given_number(Y, S), check=in01)
    assert_typed_or_good("mmconcepts.nmf.l_full", lambda: l_full(Y, S, threshold=thr), check=in01)

    def curve_check(c):
        return bool(c.shape == grid.shape and ((c >= 0) & (c <= 1)).all() and (c <= l_given_number(Y, S) + 1e-12).all())

    assert_typed_or_good("mmconcepts.nmf.l_full_curve", lambda: l_full_curve(Y, S, grid), check=curve_check)
    assert_typed_or_good("mmconcepts.nmf.threshold_scores", lambda: threshold_scores(S, thr),
                         check=lambda T: bool(T.shape == S.shape and np.isin(T, (0, 1)).all()))


@fuzz_settings(300)
@given(seed=st.integers(0, 2**31 - 1), ka=st.integers(0, 5), kb=st.integers(0, 5), m=st.integers(0, 6),
       metric=st.sampled_from(["cosine", "euclidean", "l1", "nope"]),
       kind=st.sampled_from(["random", "random", "permuted", "zero_atom", "nan", "negative", "huge", "tiny"]))
def test_fuzz_match_components(seed, ka, kb, m, metric, kind):
    rng = np.random.default_rng(seed)
    A = rng.random((ka, m))
    B = rng.random((kb, m))
    if kind == "permuted":
        B = A[rng.permutation(ka)] * rng.uniform(0.1, 10, (ka, 1))
    elif kind == "zero_atom" and A.size:
        A[0] = 0.0
    elif kind == "nan" and A.size:
        A.flat[0] = np.nan
    elif kind == "negative" and A.size:
        A.flat[0] = -1.0
    elif kind == "huge":
        A, B = A * 1e300, B * 1e300
    elif kind == "tiny":
        A, B = A * 1e-300, B * 1e-300

    def check(res):
        ok = res.distance >= 0 and len(res.rows) == min(A.shape[0], B.shape[0])
        if metric == "cosine":
            ok &= res.distance <= 2.0 + 1e-12
        if kind == "permuted":  # a scaled, permuted copy is at distance 0
            ok &= res.distance <= 1e-9
        return bool(ok)

    assert_typed_or_good("mmconcepts.nmf.match_components", lambda: match_components(A, B, metric=metric),
                         check=check)
    assert_typed_or_good("mmconcepts.nmf.dictionary_distance", lambda: dictionary_distance(A, B, metric=metric),
                         check=lambda d: bool(d >= 0))


_SPARSE_MASK_SCRIPT = r"""
import resource, sys
import numpy as np, scipy.sparse as sp
from mmconcepts.nmf import beta_nmf
n = 20000
rng = np.random.default_rng(0)
X = sp.random_array((n, n), density=0.001, rng=rng, format="csr")
M = (X != 0) + sp.random_array((n, n), density=0.001, rng=rng, format="csr").astype(bool)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
for beta in (1.0, 2.0):
    res = beta_nmf(X, 5, beta_loss=beta, mask=M, max_iter=2, tol=0)
    assert np.isfinite(res.W).all() and np.isfinite(res.loss_history).all()
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print((after - before) * 1024)
"""


def test_masked_sparse_fit_stays_sparse():
    """A masked fit of a sparse 20000 x 20000 matrix (0.1 % nonzeros, a sparse mask) never densifies:
    its peak memory stays far below the 3.2 GB of one dense copy (it once reached 7.24 GB)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _SPARSE_MASK_SCRIPT], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    peak = int(out.stdout.split()[-1])
    assert peak < 300 * 2**20, f"the masked sparse fit grew the peak memory by {peak / 2**20:.0f} MiB"


@pytest.mark.parametrize("beta, c", [(1.0, 1e-8), (2.0, 1e-8), (2.0, 1e150), (1.0, 1e250), (0.0, 1e-200), (0.5, 1e12)])
def test_the_issue_scales_give_the_unscaled_fit(beta, c):
    """KL-NMF of X * 1e-8 rose under the monotone updates and ended at inf, Frobenius of
    X * 1e300 gave NaN factors. Now fit(c X) = (W, c H) from the start (W0, c H0), the objective is
    c ** beta times the unscaled one, and it never rises."""
    rng = np.random.default_rng(0)
    X = rng.random((30, 20)) + 0.01
    W0, H0 = rng.random((30, 5)) + 0.1, rng.random((5, 20)) + 0.1
    ref = beta_nmf(X, 5, beta_loss=beta, W=W0, H=H0, max_iter=50, tol=0, loss_every=1)
    res = beta_nmf(X * c, 5, beta_loss=beta, W=W0, H=H0 * c, max_iter=50, tol=0, loss_every=1)
    np.testing.assert_allclose(res.W, ref.W, rtol=1e-7)
    np.testing.assert_allclose(res.H / c, ref.H, rtol=1e-7)
    np.testing.assert_allclose(res.loss_history / c**beta, ref.loss_history, rtol=1e-7)
    assert np.all(np.diff(res.loss_history) <= 1e-9 * res.loss_history[0])


def test_an_objective_beyond_float64_is_named():
    X = np.random.default_rng(0).random((30, 20))
    with pytest.raises(DataError, match="outside the range of float64"):
        beta_nmf(X * 1e300, 5, beta_loss=2, max_iter=5)
    res = beta_nmf(X * 1e300, 5, beta_loss=1, max_iter=5, tol=0)  # the I-divergence scales by c only
    assert np.isfinite(res.W).all() and np.isfinite(res.H).all() and np.isfinite(res.loss_history).all()


@pytest.mark.parametrize("side", ["W", "H"])
def test_hoyer_sparseness_on_ordinary_data(side):
    """sparseness_H=0.5 (or sparseness_W) on random data raised ZeroDivisionError."""
    from mmconcepts.nmf import hoyer_sparseness

    X = np.random.default_rng(0).random((30, 20))
    res = beta_nmf(X, 5, max_iter=30, tol=0, loss_every=1, random_state=0, **{f"sparseness_{side}": 0.5})
    assert np.isfinite(res.W).all() and np.isfinite(res.H).all()
    assert np.all(np.diff(res.loss_history) <= 1e-12 * res.loss_history[0])
    vectors = res.H if side == "H" else res.W.T
    np.testing.assert_allclose(hoyer_sparseness(vectors, axis=1), 0.5, atol=1e-6)
