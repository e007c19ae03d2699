"""Numba kernels for sparse beta-NMF (internal).

Written by hand because no maintained library computes a low-rank product only at the
nonzeros of a sparse matrix and fuses it with the multiplicative-update numerator.

Every kernel works on one side of the factorization X ~ L @ R.T with X in CSR form:
updating W uses (X, L=W, R=H.T) and updating H uses (X.T in CSR form, L=H.T, R=W).
Rows are processed in parallel (``prange``), so no two threads write the same output row.
"""

from __future__ import annotations

import numba as nb
import numpy as np

# Reassociation lets LLVM vectorise the length-k dot products (results change in the last bits only).
_OPTS = dict(nogil=True, cache=True, fastmath={"reassoc", "contract"}, error_model="numpy")


@nb.njit(parallel=True, **_OPTS)
def lowrank_at_nonzeros(indptr, indices, L, R, out):  # pragma: no cover - compiled
    """out[p] = L[i] . R[j] for every stored entry p = (i, j) of a CSR matrix."""
    n = indptr.shape[0] - 1
    k = L.shape[1]
    for i in nb.prange(n):
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            acc = L.dtype.type(0.0)
            for t in range(k):
                acc += L[i, t] * R[j, t]
            out[p] = acc
    return out


@nb.njit(parallel=True, **_OPTS)
def mu_numerator(indptr, indices, data, weights, L, R, beta, eps, out):  # pragma: no cover
    """out[i] = sum_p w_p * x_p * y_p**(beta - 2) * R[j_p]  with y_p = L[i] . R[j_p].

    This is the numerator of the multiplicative update of L (thesis eq. 2.16, written
    for one side), with ``y`` clipped below at ``eps`` when beta < 2 so that negative
    powers stay finite. ``weights`` is an empty array when there is no mask.
    """
    n = indptr.shape[0] - 1
    k = L.shape[1]
    has_w = weights.shape[0] > 0
    bm2 = beta - 2.0
    for i in nb.prange(n):
        for t in range(k):
            out[i, t] = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            x = data[p]
            if beta == 2.0:
                e = x
            else:
                y = L.dtype.type(0.0)
                for t in range(k):
                    y += L[i, t] * R[j, t]
                if beta < 2.0 and y < eps:
                    y = eps
                if beta == 1.0:
                    e = x / y
                elif beta == 0.0:
                    e = x / (y * y)
                else:
                    e = x * y**bm2
            if has_w:
                e = e * weights[p]
            for t in range(k):
                out[i, t] += e * R[j, t]
    return out


@nb.njit(parallel=True, **_OPTS)
def divide_clipped(X, Y, eps):  # pragma: no cover - compiled
    """Y <- X / max(Y, eps) in place, in one parallel pass (the I-divergence update's ratio)."""
    n, m = Y.shape
    for i in nb.prange(n):
        for j in range(m):
            y = Y[i, j]
            if y < eps:
                y = eps
            Y[i, j] = X[i, j] / y
    return Y
