"""Numba kernels for sparse beta-NMF (internal).

Written by hand because no maintained library computes a low-rank product only at the
nonzeros of a sparse matrix and fuses it with the multiplicative-update numerator.

Every kernel works on one side of the factorization X ~ L @ R.T with X in CSR form:
updating W uses (X, L=W, R=H.T) and updating H uses (X.T in CSR form, L=H.T, R=W).
Rows are processed in parallel (``prange`` over groups of consecutive rows), so no two threads
write the same output row.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._jit import njit

#: Lower clip of the low-rank product where negative powers of it are taken (as scikit-learn).
EPSILON = float(np.finfo(np.float32).eps)

# Reassociation lets LLVM vectorise the length-k dot products (results change in the last bits only).
_OPTS: dict[str, Any] = dict(nogil=True, cache=True, fastmath={"reassoc", "contract"}, error_model="numpy")


# Bytes of R's rows that one pass over a block of columns keeps in use (within a core's L2, half
# of 1 MB): beyond it, every row of X would fetch R's rows from memory again.
_TILE_BYTES = 512 * 1024
_NO_DEN = np.empty(0)  # mu_numerator: no fused update
_NO_WEIGHTS = np.empty(0)
_NO_RATIOS = np.empty(0)  # kl_update: the ratios x / y not kept
_NO_SUMS = np.empty((0, 0))  # kl_update: the updated factor's column sums not kept
#: Rows per partial column sum in ``kl_update``: each thread's rows are whole blocks of this many, so the partial
#: sums, and their total, do not depend on the number of threads.
SUM_ROWS = 64


def _tiling(indptr, R) -> tuple[int, int]:
    """(row groups, columns per tile): one group of consecutive rows per numba thread.

    Asked here rather than inside the kernels, which numba could then not cache on disk.
    """
    tile = max(64, _TILE_BYTES // max(1, R.shape[1] * R.itemsize))
    return min(len(indptr) - 1, nb.get_num_threads()), tile


def lowrank_at_nonzeros(indptr, indices, L, R, out):
    """out[p] = L[i] . R[j] for every stored entry p = (i, j) of a CSR matrix.

    Visits the entries by tiles of R's rows (see ``mu_numerator``); each value is computed
    the same way whatever the tiling.
    """
    return _lowrank_at_nonzeros(indptr, indices, L, R, out, *_tiling(indptr, R))


def flush_below(dtype) -> Any:
    """The square root of the smallest normal number of ``dtype`` (1.5e-154 in float64, 1.1e-19 in float32):
    ``kl_update`` sets the entries it lowers below it to zero, so that products of two such entries do not
    underflow."""
    dtype = np.dtype(dtype)
    return dtype.type(np.sqrt(np.finfo(dtype).tiny))


def _factors(indptr, data, weights, L, groups: int) -> np.ndarray:
    """Scratch for ``_mu_numerator``: one row per group, as long as the longest row of X, of the
    type the entries' factors are computed in (that of ``data``, ``L`` and ``weights`` together)."""
    longest = int(np.diff(indptr).max()) if len(indptr) > 1 else 0
    dtype = np.result_type(data, L, weights) if weights.shape[0] else np.result_type(data, L)
    return np.empty((groups, longest), dtype=dtype)


def mu_numerator(indptr, indices, data, weights, L, R, beta, eps, out):
    """out[i] = sum_p w_p * x_p * y_p**(beta - 2) * R[j_p]  with y_p = L[i] . R[j_p].

    This is the numerator of the multiplicative update of L (thesis eq. 2.16, written
    for one side), with ``y`` clipped below at ``eps`` when beta < 2 so that negative
    powers stay finite. ``weights`` is an empty array when there is no mask.

    Each thread takes a group of consecutive rows and walks them tile by tile: the entries
    of every row whose column falls in the first ``tile`` rows of R, then the next tile,
    and so on, so that a tile of R is read from memory once per group rather than once per
    row (which matters when R is larger than a core's cache, as for 110 000 HAC columns). A row's
    entries are still summed in their stored order, so the result is the same, bit for bit,
    as the plain row-by-row loop, for any tile size and even with unsorted column indices
    (which only lose the cache benefit).
    """
    groups, tile = _tiling(indptr, R)
    return _mu_numerator(indptr, indices, data, weights, L, R, beta, eps, L.dtype.type(0.0), out, _NO_DEN, groups, tile,
                         _factors(indptr, data, weights, L, groups), _NO_RATIOS, _NO_SUMS)


def kl_update(indptr, indices, data, L, R, den, out, ratios=_NO_RATIOS, sums=_NO_SUMS):
    """The I-divergence multiplicative update of L in place, with its numerator's last pass.

    L <- L * (N / den) with N = ``mu_numerator`` at beta = 1 (thesis eq. 2.16 with gamma = 1)
    and ``den`` the (k,) denominator row (R's column sums, zeros replaced by the caller). The
    kernel divides each row of N by ``den`` as soon as it is complete, while it is in the cache,
    and multiplies that row of L by the ratios: the same numbers, bit for bit, as the numerator
    followed by ``L *= N / den`` in numpy, apart from the flush below (the kernel is compiled without reassociation, so
    ``L * (N / den)`` is not turned into ``(L * N) / den``). ``out`` receives N / den.

    ``ratios``, a float64 array of one value per stored entry p, receives x_p / y_p with the
    product y_p of the L it starts from, not clipped (1 where x_p = 0): the I-divergence of that
    L is sum_p x_p log(ratios_p) - sum_p x_p + sum of all products (thesis eq. 2.3), with no
    product formed again. Empty (the default): not kept.

    An entry that the update lowers below :func:`flush_below` (the square root of the smallest
    normal number, 1.5e-154 in float64) is set to zero, so that products of two entries above it
    do not underflow. The updates take some entries of a sparse X's factors down towards zero by many
    orders of magnitude per iteration, and a product that underflows to a subnormal number costs
    the processor about a hundred times an ordinary one (``benchmarks/README.md``). An
    entry that rises (a start of subnormal size, say) is kept however small. The flush changes a
    product by at most k times 1.5e-154 times the other factor's largest entry; a flushed entry
    stays zero, where the updates would have had to raise it by 150 orders of magnitude for it
    to matter.

    ``sums``, a float64 array of shape (ceil(rows / SUM_ROWS), k), receives the column sums of the
    updated L over each block of :data:`SUM_ROWS` consecutive rows, each summed in row order while
    the row is in the cache (their sum over blocks is L's column sums, the next update's
    denominator on the other side). Empty (the default): not kept.
    """
    groups, tile = _tiling(indptr, R)
    _mu_numerator(indptr, indices, data, _NO_WEIGHTS, L, R, 1.0, L.dtype.type(EPSILON), flush_below(L.dtype), out, den, groups, tile,
                  _factors(indptr, data, _NO_WEIGHTS, L, groups), ratios, sums)
    return L


@njit(**_OPTS)
def _row_dot(L, i, R, j, k):  # pragma: no cover - compiled
    """L[i] . R[j] over the first k entries (vectorised: reassociated)."""
    acc = L.dtype.type(0.0)
    for t in range(k):
        acc += L[i, t] * R[j, t]
    return acc


@njit(parallel=True, compile_apart=True, **_OPTS)
def _lowrank_at_nonzeros(indptr, indices, L, R, out, groups, tile):  # pragma: no cover - compiled
    n = indptr.shape[0] - 1
    m, k = R.shape[0], L.shape[1]
    for g in nb.prange(groups):
        r0, r1 = g * n // groups, (g + 1) * n // groups
        pos = indptr[r0:r1].copy()
        for c1 in range(tile, m + tile, tile):
            for i in range(r0, r1):
                p, end = pos[i - r0], indptr[i + 1]
                while p < end and indices[p] < c1:
                    out[p] = _row_dot(L, i, R, indices[p], k)
                    p += 1
                pos[i - r0] = p
    return out


# Without reassociation: the numerator's sums over a row's entries then run in their stored order
# (each term one fused multiply-add), whatever the grouping of entries below.
_OPTS_ORDERED: dict[str, Any] = dict(_OPTS, fastmath={"contract"})


@njit(parallel=True, compile_apart=True, **_OPTS_ORDERED)
def _mu_numerator(indptr, indices, data, weights, L, R, beta, eps, tiny, out, den, groups, tile, factors,  # pragma: no cover
                  ratios, sums):
    # Two passes over each row's entries in a tile: their factors e_p first (a dot product each,
    # independent of one another), then out[i] += e_p R[j_p], four entries per sweep over out[i]
    # (one load and store of out[i] per four entries instead of one per entry). Each out[i, t]
    # still receives e_p R[j_p, t] one entry after the other in stored order, as a plain loop would.
    n = indptr.shape[0] - 1
    m, k = R.shape[0], L.shape[1]
    has_w = weights.shape[0] > 0
    fused = den.shape[0] > 0
    keep = ratios.shape[0] > 0 and beta == 1.0
    summed = fused and sums.shape[0] > 0
    bm2 = beta - 2.0
    unit = SUM_ROWS if summed else 1  # with sums, whole blocks of SUM_ROWS rows per group: no two threads add into
    units = (n + unit - 1) // unit  # one block's sums
    for g in nb.prange(groups):
        r0, r1 = min(n, g * units // groups * unit), min(n, (g + 1) * units // groups * unit)
        pos = indptr[r0:r1].copy()
        factor = factors[g]
        for i in range(r0, r1):
            for t in range(k):
                out[i, t] = 0.0
        if summed:
            for b in range(r0 // SUM_ROWS, (r1 + SUM_ROWS - 1) // SUM_ROWS):
                for t in range(k):
                    sums[b, t] = 0.0
        last = max(m, 1)  # one pass even without columns, for the fused update
        for c1 in range(tile, last + tile, tile):
            for i in range(r0, r1):
                p0, end = pos[i - r0], indptr[i + 1]
                p = p0
                while p < end and indices[p] < c1:
                    x = data[p]
                    if beta == 2.0:
                        e = x
                    else:
                        y = _row_dot(L, i, R, indices[p], k)
                        if keep:
                            ratios[p] = np.float64(x) / np.float64(y) if x > 0 else 1.0
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
                    factor[p - p0] = e
                    p += 1
                pos[i - r0] = p
                q, cnt = 0, p - p0
                while q + 4 <= cnt:
                    j0, j1, j2, j3 = indices[p0 + q], indices[p0 + q + 1], indices[p0 + q + 2], indices[p0 + q + 3]
                    e0, e1, e2, e3 = factor[q], factor[q + 1], factor[q + 2], factor[q + 3]
                    for t in range(k):
                        acc = out[i, t]
                        acc += e0 * R[j0, t]
                        acc += e1 * R[j1, t]
                        acc += e2 * R[j2, t]
                        acc += e3 * R[j3, t]
                        out[i, t] = acc
                    q += 4
                while q < cnt:
                    j0, e0 = indices[p0 + q], factor[q]
                    for t in range(k):
                        out[i, t] += e0 * R[j0, t]
                    q += 1
                if fused and c1 >= last:  # the row's last tile: its numerator is complete, L[i] no longer read
                    for t in range(k):
                        out[i, t] /= den[t]
                        v = L[i, t] * out[i, t]
                        L[i, t] = 0.0 if v < tiny and out[i, t] < 1.0 else v  # (see kl_update)
                    if summed:
                        b = i // SUM_ROWS
                        for t in range(k):
                            sums[b, t] += L[i, t]
    return out


# Serial on purpose: OpenMP threads left spinning after a parallel region slow down the BLAS
# products that come next in the dense update (measured on 2 cores against scikit-learn: x0.83
# with prange, x1.46 serial). The pass is memory-bound: splitting it over plain threads gained
# nothing measurable either.
@njit(parallel=False, **_OPTS)
def divide_clipped(X, Y, eps):  # pragma: no cover - compiled
    """Y <- X / max(Y, eps) in place, in one pass (the I-divergence update's ratio)."""
    n, m = Y.shape
    for i in range(n):
        for j in range(m):
            y = Y[i, j]
            if y < eps:
                y = eps
            Y[i, j] = X[i, j] / y
    return Y


@njit(parallel=False, **_OPTS)
def dense_divergence(X, Y, M, beta, with_x=True):  # pragma: no cover - compiled
    """sum_ij m_ij d_beta(X_ij | Y_ij) in one pass, accumulated in float64 (thesis eq. 2.2-2.3).

    ``M`` is an empty array when every cell is observed. 0 log 0 = 0, and a term whose cell is
    unobserved counts 0 even when it is infinite. For beta outside {0, 1, 2}, ``with_x=False``
    leaves out the terms x^beta / (beta (beta - 1)), which do not depend on Y
    (the caller sums them once).
    """
    n, m = X.shape
    has_m = M.shape[0] > 0
    total = 0.0
    for i in range(n):
        for j in range(m):
            w = 1.0
            if has_m:
                w = M[i, j]
                if w == 0.0:
                    continue
            x = np.float64(X[i, j])
            y = np.float64(Y[i, j])
            if beta == 2.0:
                d = 0.5 * (x - y) * (x - y)
            elif beta == 1.0:
                d = y - x
                if x > 0.0:
                    d += x * np.log(x / y)
            elif beta == 0.0:
                r = x / y
                d = r - np.log(r) - 1.0 if r != np.inf else np.inf  # inf - log(inf) would be NaN
            else:
                yb = y**beta
                d = (beta - 1.0) * yb
                if with_x:
                    d += x**beta
                if x > 0.0:  # y^(beta-1) as y^beta / y: one power fewer (y = 0: 0 or inf, by the power)
                    d -= beta * x * (yb / y if y > 0.0 else y ** (beta - 1.0))
                d /= beta * (beta - 1.0)
            total += w * d
    return total


@njit(parallel=False, **_OPTS)
def fractional_divergence_from_power(X, Y, Yb1, M, beta):  # pragma: no cover - compiled
    r"""sum_ij m_ij d_beta(X_ij | Y_ij) less the terms in X alone, from Y and Y^(beta - 1), in float64.

    For beta outside {0, 1, 2} (thesis eq. 2.3), with y^beta = y y^(beta-1):

    .. math:: d_\beta(x|y) - \frac{x^\beta}{\beta(\beta-1)} = y^{\beta-1}\Big(\frac{y}{\beta}
              - \frac{x}{\beta-1}\Big)

    ``Yb1`` is Y^(beta - 1) as the multiplicative update forms it; no power is taken here (the
    value of :func:`dense_divergence` with ``with_x=False``, to rounding). A cell with x = 0 counts
    y^beta / beta; ``M`` is an empty array when every cell is observed, and an unobserved cell
    counts 0. Y must be positive where beta < 1 (as the update makes it, y >= eps).
    """
    n, m = X.shape
    has_m = M.shape[0] > 0
    a, c = 1.0 / beta, 1.0 / (beta - 1.0)
    total = 0.0
    for i in range(n):
        for j in range(m):
            w = 1.0
            if has_m:
                w = M[i, j]
                if w == 0.0:
                    continue
            p = np.float64(Yb1[i, j])
            d = p * (a * np.float64(Y[i, j]))
            x = np.float64(X[i, j])
            if x > 0.0:
                d -= p * (c * x)
            total += w * d
    return total


@njit(parallel=False, **_OPTS)
def kl_log_ratio_pass(X, Y, M, out):  # pragma: no cover - compiled
    """The first pass of the I-divergence of a block: out <- x / y (1 where x = 0 or unobserved).

    Returns sum_ij m_ij (y_ij - x_ij) in float64; numpy then takes the log of ``out`` (vectorised,
    several times faster than a scalar log per cell) and :func:`weighted_sum` adds sum_ij x_ij log(x_ij / y_ij):
    with 0 log 0 = 0 the two sums are the I-divergence (thesis eq. 2.3, beta = 1). ``M`` is an
    empty array when every cell is observed; ``out`` is float64 whatever X's type.
    """
    n, m = X.shape
    has_m = M.shape[0] > 0
    total = 0.0
    for i in range(n):
        for j in range(m):
            if has_m and M[i, j] == 0.0:  # unobserved: counts 0, even where the product overflowed
                out[i, j] = 1.0
                continue
            x = np.float64(X[i, j])
            y = np.float64(Y[i, j])
            total += y - x
            out[i, j] = x / y if x > 0.0 else 1.0
    return total


@njit(parallel=False, **_OPTS)
def weighted_sum(X, V):  # pragma: no cover - compiled
    """sum_ij x_ij v_ij, accumulated in float64."""
    n, m = X.shape
    total = 0.0
    for i in range(n):
        for j in range(m):
            total += np.float64(X[i, j]) * V[i, j]
    return total


@njit(nogil=True, cache=True)
def gather_scaled_rows(indptr, indices, scale, R, rows, cols, out):  # pragma: no cover - compiled
    """Stack, for each ``rows[i]`` of a CSR matrix, ``R[j, cols[i]] * scale[p]`` over its stored entries p = (row, j).

    ``out`` (sum of the rows' entry counts, ``cols.shape[1]``) receives the rows' blocks one
    after another, each ``R[indices[p], cols[i]] * scale[p]`` in the order of the entries:
    numpy's ``R[indices[lo:hi, None], cols[i]] * scale[lo:hi, None]``, the same numbers, without
    building an index array per row. One product per value, no reassociation: bit for bit.
    """
    p = 0
    for i in range(rows.shape[0]):
        r = rows[i]
        for e in range(indptr[r], indptr[r + 1]):
            j = indices[e]
            s = scale[e]
            for q in range(cols.shape[1]):
                out[p, q] = R[j, cols[i, q]] * s
            p += 1
    return out
