"""Initialisation of the factors (internal): random, NNDSVD and its variants, custom."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from sklearn.utils.extmath import randomized_svd

from ..errors import DataError, ParameterError

__all__ = ["initialize", "INITS"]

INITS = ("random", "nndsvd", "nndsvda", "nndsvdar", "custom")


def _observed_mean(X, mask) -> float:
    if mask is None:
        return float(X.mean())
    if sp.issparse(mask):  # never densified; X is zero on unobserved cells (validate_data)
        n_obs = float(mask.count_nonzero())
        if n_obs == 0:
            raise DataError("mask observes no cell of X; at least one cell must be True.")
        total = X.sum() if sp.issparse(X) else float(mask.multiply(X).sum())
        return float(total) / n_obs
    m = np.asarray(mask)
    n_obs = float(m.sum())
    if n_obs == 0:
        raise DataError("mask observes no cell of X; at least one cell must be True.")
    total = X.multiply(m).sum() if sp.issparse(X) else float((X * m).sum())
    return float(total) / n_obs


def _filled_svd(X, mask, fill: float, k: int, seed: int):
    """Truncated SVD of X with its unobserved cells set to ``fill``, for a sparse X and sparse mask.

    The filled matrix A = X - fill * M + fill * 1 1^T (X is zero off the mask) is never formed:
    the steps of scikit-learn's ``randomized_svd`` (Halko, Martinsson & Tropp 2011: same random
    draws, power iterations, LU normalisation and sign convention, so the same factors up to
    rounding) multiply it by thin blocks only. Written by hand: ``randomized_svd`` takes arrays,
    not operators.
    """
    from scipy import linalg
    from sklearn.utils.extmath import svd_flip

    M = sp.csr_matrix(mask, dtype=X.dtype)
    transpose = X.shape[0] < X.shape[1]
    Xo, Mo = (X.T.tocsr(), M.T.tocsr()) if transpose else (X, M)

    def dot(Q):  # A Q
        return np.asarray(Xo @ Q) - fill * np.asarray(Mo @ Q) + fill * Q.sum(axis=0, keepdims=True)

    def tdot(Q):  # A^T Q
        return np.asarray(Xo.T @ Q) - fill * np.asarray(Mo.T @ Q) + fill * Q.sum(axis=0, keepdims=True)

    n_iter = 7 if k < 0.1 * min(X.shape) else 4
    Q = np.random.RandomState(seed).normal(size=(Xo.shape[1], k + 10))
    if X.dtype == np.float32:
        Q = Q.astype(np.float32)
    for _ in range(n_iter):
        Q, _ = linalg.lu(dot(Q), permute_l=True)
        Q, _ = linalg.lu(tdot(Q), permute_l=True)
    Q, _ = linalg.qr(dot(Q), mode="economic")
    Uhat, S, Vt = linalg.svd(tdot(Q).T, full_matrices=False, lapack_driver="gesdd")
    U = Q @ Uhat
    if transpose:
        U, Vt = svd_flip(U, Vt, u_based_decision=False)
        return Vt[:k].T, S[:k], U[:, :k].T
    U, Vt = svd_flip(U, Vt)
    return U[:, :k], S[:k], Vt[:k]


def initialize(X, n_components: int, init: str, rng: np.random.Generator, *, mask=None, eps: float = 1e-6):
    """Return (W, H) to start from, in X's dtype.

    ``random``: |N(0, 1)| scaled by sqrt(mean(X) / k), as scikit-learn.
    ``nndsvd``: Boutsidis & Gallopoulos (2008), zeros kept (they stay zero under MU).
    ``nndsvda``: NNDSVD with zeros filled by the mean of X.
    ``nndsvdar``: NNDSVD with zeros filled by small random values.
    With a mask, unobserved cells are filled with the observed mean before the SVD.
    """
    n, m = X.shape
    dtype = X.dtype
    avg_x = _observed_mean(X, mask)
    if init == "random":
        scale = np.sqrt(max(avg_x, 0.0) / n_components)
        H = np.abs(scale * rng.standard_normal((n_components, m))).astype(dtype, copy=False)
        W = np.abs(scale * rng.standard_normal((n, n_components))).astype(dtype, copy=False)
        return W, H
    if init not in ("nndsvd", "nndsvda", "nndsvdar"):
        raise ParameterError(f"init must be one of {INITS} or None; got {init!r}.")
    if n_components > min(n, m):
        raise ParameterError(
            f"init={init!r} needs n_components <= min(n_samples, n_features) = {min(n, m)}; got {n_components}. "
            "Use init='random'."
        )
    seed = int(rng.integers(0, 2**31 - 1))
    if mask is not None and sp.issparse(mask) and sp.issparse(X):  # stays sparse
        U, S, V = _filled_svd(X, mask, avg_x, n_components, seed)
    else:
        A = X
        if mask is not None:
            m_arr = mask.toarray() if sp.issparse(mask) else np.asarray(mask)
            A = np.where(m_arr > 0, X.toarray() if sp.issparse(X) else X, avg_x)
        U, S, V = randomized_svd(A, n_components, random_state=seed)
    W = np.zeros((n, n_components), dtype=np.float64)
    H = np.zeros((n_components, m), dtype=np.float64)
    W[:, 0] = np.sqrt(S[0]) * np.abs(U[:, 0])
    H[0, :] = np.sqrt(S[0]) * np.abs(V[0, :])
    for j in range(1, n_components):
        x, y = U[:, j], V[j, :]
        xp, yp = np.maximum(x, 0), np.maximum(y, 0)
        xn, yn = np.abs(np.minimum(x, 0)), np.abs(np.minimum(y, 0))
        xpn, ypn, xnn, ynn = (np.linalg.norm(v) for v in (xp, yp, xn, yn))
        mp, mn = xpn * ypn, xnn * ynn
        if mp > mn:
            u, v, sigma = xp / xpn, yp / ypn, mp
        elif mn > 0:
            u, v, sigma = xn / xnn, yn / ynn, mn
        else:
            continue
        lbd = np.sqrt(S[j] * sigma)
        W[:, j] = lbd * u
        H[j, :] = lbd * v
    W[W < eps] = 0
    H[H < eps] = 0
    if init == "nndsvda":
        W[W == 0] = avg_x
        H[H == 0] = avg_x
    elif init == "nndsvdar":
        W[W == 0] = np.abs(avg_x * rng.standard_normal(int((W == 0).sum())) / 100)
        H[H == 0] = np.abs(avg_x * rng.standard_normal(int((H == 0).sum())) / 100)
    return W.astype(dtype, copy=False), H.astype(dtype, copy=False)
