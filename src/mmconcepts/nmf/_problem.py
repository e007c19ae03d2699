"""One side of a (masked, dense or sparse) beta-NMF problem (internal).

The factorization X ~ W @ H is stored as X ~ W @ Ht.T with W (n, k) and Ht = H.T (m, k),
both C-contiguous. Every update is written once, for the *left* factor L of
X_side ~ L @ R.T: side 0 is (X, L=W, R=Ht) and side 1 is (X.T, L=Ht, R=W). For a dense X
the two sides share X in its stored layout; for a sparse X each side keeps
its own CSR copy so that the numba kernels run row-parallel with no write conflicts.

In the thesis' notation (V ~ W_thesis H_thesis, examples as columns), V = X.T,
W_thesis = Ht and H_thesis = W.T, so thesis eq. (2.16)'s H-update is our side 0.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import scipy.sparse as sp

from ..errors import DataError
from . import _kernels
from ._beta import (
    EPSILON,
    check_beta_zeros,
    dense_blocks,
    elementwise_beta_divergence,
    gather,
    mask_block,
    resolve_beta,
    sum_power_lowrank,
)
from ._data import validate_data

__all__ = ["Side", "Problem", "beta_divergence"]

#: Bytes of one block of the dense I-divergence numerator's product (1 to 8 MB measured on the
#: 2-core project machine, ``benchmarks/README.md``: 4 MB was fastest).
_BLOCK_BYTES = 4 << 20
#: Bytes of one block of the product when the divergence of a dense X is evaluated.
_DIVERGENCE_BLOCK_BYTES = 1 << 20

_blas: Any = None  # threadpoolctl's controller of the BLAS libraries, made on first use
_pool: ThreadPoolExecutor | None = None
_limiter: Any = None  # the BLAS limit in force while the blocks run on threads, else None


def _blas_threads() -> int:
    """The threads the blocked numerator may use: numpy's BLAS threads, from the main thread only.

    The BLAS thread count is process-wide, so only the main thread lowers it to one while its
    blocks run on threads; from any other thread (a user's thread pool, dask's threaded
    scheduler) the blocks run one after the other with BLAS as it is, and BLAS calls made
    concurrently by other threads never see a limit they did not set.
    """
    global _blas
    if threading.current_thread() is not threading.main_thread():
        return 1
    if _blas is None:
        from threadpoolctl import ThreadpoolController

        _blas = ThreadpoolController().select(user_api="blas")
    return max([lib.num_threads for lib in _blas.lib_controllers], default=1)


def _after_fork_in_child() -> None:
    """A forked child has none of its parent's threads, and must not inherit a BLAS limit of one."""
    global _pool, _limiter
    _pool = None
    if _limiter is not None:
        _limiter.restore_original_limits()
        _limiter = None


os.register_at_fork(after_in_child=_after_fork_in_child)


@functools.lru_cache(maxsize=256)
def _stripe_starts(n: int, b: int, n_stripes: int) -> tuple[tuple[int, ...], ...]:
    """The starts 0, b, 2b, ... (< n) of the row blocks, in ``n_stripes`` contiguous stripes (``np.array_split``'s
    split), kept for the next call on the same shape: a fit asks for the same stripes at every update."""
    return tuple(tuple(int(s) for s in part) for part in np.array_split(np.arange(0, n, b), n_stripes))


def _stripes_in_threads(run: Callable[[int, int], None], n_stripes: int, T: int) -> None:
    """Call ``run(i, t)`` for every stripe i, on T threads (t = 0 .. T-1) with one BLAS thread each.

    Thread t runs stripes t, t + T, ... (with its own scratch buffers); the calling (main)
    thread is thread 0. One thread runs every stripe in order, with BLAS as it is. The blocked
    products of the stripes are then each on one core, in its own cache, rather than every
    product split over all cores (``benchmarks/README.md``, dense KL).
    """
    if T <= 1:
        for i in range(n_stripes):
            run(i, 0)
        return

    def thread(t: int) -> None:
        for i in range(t, n_stripes, T):
            run(i, t)

    global _pool, _limiter
    if _pool is None or _pool._max_workers < T - 1:  # only the main thread gets here
        if _pool is not None:
            _pool.shutdown(wait=False)
        _pool = ThreadPoolExecutor(max_workers=T - 1, thread_name_prefix="mmconcepts-nmf")
    _limiter = _blas.limit(limits=1)
    try:
        futures = [_pool.submit(thread, t) for t in range(1, T)]
        try:
            thread(0)
        finally:
            for f in futures:
                f.result()
    finally:
        _limiter.restore_original_limits()
        _limiter = None


#: Below this fraction of ||X||^2 / 2, the Frobenius objective is formed directly (see Problem.divergence).
_CANCELLATION = 1e-4


@dataclass
class _StripeBuffers:
    """Scratch space of :meth:`Side._kl_numerator_blocked`, kept while ``key`` matches."""

    key: tuple
    num: np.ndarray  # the numerator (n, k), or its transpose (k, m) on the transposed side; the caller may
    # overwrite what is returned, not keep it
    blocks: list[np.ndarray]  # per thread: one block of rows of the product
    parts: list[np.ndarray]  # per thread: one block's contribution, transposed
    partial: np.ndarray  # (transposed side) the sums of stripes 1.. (one at a time when one thread runs);
    # stripe 0 sums into num


def _divergence_block_rows(n: int, m: int) -> int:
    """Rows per block of a dense divergence (at least 16, about :data:`_DIVERGENCE_BLOCK_BYTES` of float64)."""
    return max(16, min(n, _DIVERGENCE_BLOCK_BYTES // (8 * max(m, 1))))


@dataclass
class Side:
    """Data for updating the left factor of X_side ~ L @ R.T."""

    X: np.ndarray | sp.csr_matrix  # sparse: CSR of X (side 0) or of X.T (side 1); dense: X itself
    mask: np.ndarray | sp.csr_matrix | None  # same layout as X, float; None = all observed
    weights: np.ndarray | None  # sparse X only: mask values at X's stored entries
    transposed: bool  # dense only: this side updates the right factor (X ~ R @ L.T)
    buffer: np.ndarray | None = None  # scratch space, reused: the dense product, or the sparse I-divergence ratio
    block_buffer: _StripeBuffers | None = None  # dense only: scratch space of the blocked I-divergence update
    divergence_buffers: list[np.ndarray] = field(default_factory=list)  # dense only: a block of the product per
    # thread, for the divergence
    frobenius_buffers: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # dense only: see _frobenius_buffers
    fixed_products: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # dense, beta = 2, unmasked: (R, X R,
    # R^T R) for an R the caller keeps fixed across updates (see numerator_denominator)
    keep_numerator: bool = False  # dense, beta = 2, unmasked, float64: keep the next update's numerator X^T R ...
    kept_numerator: tuple[np.ndarray, np.ndarray] | None = None  # ... as (R, a copy of it), for Problem.divergence
    x_terms: dict[float, float] = field(default_factory=dict)  # dense only: per beta, the divergence's terms in X
    # alone (beta outside {0, 1, 2}: sum m x^beta / (beta (beta - 1))), summed once
    want_divergence: bool = False  # dense, beta outside {0, 1, 2}, float64: the next update also forms ...
    found_divergence: float | None = None  # ... D_beta(X | L R^T) of the L it starts from (see _dense_nd)

    @property
    def sparse(self) -> bool:
        return sp.issparse(self.X)

    # --- the two halves of the multiplicative update (thesis eq. 2.16) -------------
    def numerator_denominator(self, L: np.ndarray, R: np.ndarray, beta: float, fixed: bool = False):
        """Return (N, D) with the update L <- L * (N / D) ** gamma.

        .. math::
            N = (M \\odot X \\odot Y^{\\beta-2}) R, \\qquad D = (M \\odot Y^{\\beta-1}) R,
            \\qquad Y = L R^T

        ``fixed``: the caller does not change R between this call and its next ones with the
        same R (a ``transform``'s dictionary). For dense, unmasked data under beta = 2, X R and
        R^T R are then formed once for that R, and each update forms only ``D = L (R^T R)``:
        the same products, so the same numbers, at ``O(n k^2)`` per update instead of
        ``O(n m k + m k^2)``.
        """
        if self.sparse:
            return self._sparse_nd(L, R, beta)
        return self._dense_nd(L, R, beta, fixed)

    def kl_update(self, L: np.ndarray, R: np.ndarray, den_row: np.ndarray,
                  divergence: bool = False) -> tuple[float, np.ndarray | None]:
        """L <- L * N / den_row in place for a sparse, unmasked side under the I-divergence (one pass).

        ``den_row`` is the (k,) denominator, R's column sums with zeros replaced; the numbers
        are those of ``numerator_denominator`` followed by the division and the product.
        Returns (the I-divergence of the L it started from, the (k,) column sums of the updated L).
        The divergence (the value of :meth:`divergence`, thesis eq. 2.3) is read from the products
        the update forms anyway, with ``divergence`` only (NaN otherwise); the column sums are
        added by the kernel while each row is in the cache, for an L of at least
        :data:`_KERNEL_SUM_ROWS` rows (None for a smaller one, whose sums cost little).
        """
        X = cast("sp.csr_matrix", self.X)
        den_row = np.ascontiguousarray(den_row, dtype=L.dtype)
        buf = self.buffer
        if buf is None or buf.shape != L.shape or buf.dtype != L.dtype:  # N / den, reused across iterations
            buf = self.buffer = np.empty_like(L)
        sums = _kernels._NO_SUMS
        if L.shape[0] >= _KERNEL_SUM_ROWS:
            sums = np.empty((-(-L.shape[0] // _kernels.SUM_ROWS), L.shape[1]))
        f, ratios = float("nan"), _kernels._NO_RATIOS
        if divergence:
            # sum_p x_p log(x_p / y_p) - x_p at the stored entries, and every product's sum through the factors' sums
            f = float(L.sum(axis=0, dtype=np.float64) @ R.sum(axis=0, dtype=np.float64)) - self._data_sum
            ratios = np.empty(X.nnz)
        _kernels.kl_update(X.indptr, X.indices, X.data, L, R, den_row, buf, ratios, sums)
        if divergence:
            with np.errstate(divide="ignore", invalid="ignore"):
                np.log(ratios, out=ratios)
                ratios *= X.data  # (not np.dot: BLAS's threads, left spinning, would slow the kernel's next calls)
            f += float(ratios.sum())
        return f, (sums.sum(axis=0).astype(L.dtype, copy=False) if sums.shape[0] else None)

    @functools.cached_property
    def _data_sum(self) -> float:
        """The sum of X's stored values, in float64."""
        return float(np.sum(cast("sp.csr_matrix", self.X).data, dtype=np.float64))

    def _dense_nd(self, L, R, beta, fixed=False):
        # Dense data stays in its stored (C) orientation: side 1 computes Y = R @ L.T, the
        # product in the original orientation, and lets BLAS read the transposes for free.
        X, M, t = self.X, self.mask, self.transposed
        if beta == 1.0 and M is None:
            return self._kl_numerator_blocked(L, R), np.broadcast_to(R.sum(axis=0), L.shape)

        def rdot(E):  # E (in the stored orientation) times R, for this side
            return E.T @ R if t else E @ R

        if beta == 2.0 and M is None:
            # X R formed transposed, (k, rows) = R^T X^T: OpenBLAS runs the wide-output form faster
            # on these shapes (the form scikit-learn's H update uses); copied back to L's layout, in
            # which the update's elementwise passes run about twice as fast
            # Into buffers kept across updates (the same products as fresh arrays): three fresh blocks per update
            # are fresh pages, whose faults cost a third of an iteration when freed memory goes back to the system.
            wide, num, den = self._frobenius_buffers(L, R)
            known = self.fixed_products if fixed else None
            if known is not None and known[0] is R:
                np.copyto(num, known[1])  # (the caller divides num in place)
                gram = known[2]
            else:
                np.matmul(R.T, X if t else X.T, out=wide)
                np.copyto(num, wide.T)
                gram = R.T @ R
                self.fixed_products = (R, num.copy(), gram) if fixed else None
            if self.keep_numerator and num.dtype == np.float64:
                self.kept_numerator = (R, num.copy())  # the caller divides num in place
            np.matmul(L, gram, out=den)
            return num, den
        Y = self._product(L, R)
        if beta == 2.0:
            Y *= M
            return rdot(M * X), rdot(Y)
        if beta == 1.0:
            _kernels.divide_clipped(X, Y, Y.dtype.type(EPSILON))
            Y *= M
            return rdot(Y), rdot(M)
        # the divergence of L (wanted by the caller): from the powers the update forms where no cell is clipped
        fused = self.want_divergence and beta not in (0.0, 1.0) and Y.dtype == np.float64
        observed = M if M is not None or not fused else np.empty((0, 0), dtype=X.dtype)  # kernels: empty = every cell
        if fused and beta < 2.0 and not Y.min() >= EPSILON:  # a cell will be clipped: the divergence of Y as it is
            self.found_divergence = self._x_terms(beta) + float(_kernels.dense_divergence(X, Y, observed, beta, False))
            fused = False
        np.maximum(Y, EPSILON if beta < 2.0 else 0.0, out=Y)
        Yb1 = Y ** (beta - 1.0)  # Y^(beta-1)
        if fused:
            self.found_divergence = self._x_terms(beta) + float(
                _kernels.fractional_divergence_from_power(X, Y, Yb1, observed, beta))
        if beta == 0.0:
            Y = Yb1 * Yb1  # Y^-2
        elif beta < 2.0:  # Y >= eps > 0: Y^(beta-2) = Y^(beta-1) / Y, a division where a power costs ten times more
            np.divide(Yb1, Y, out=Y)
        else:  # Y may be 0, where Y^(beta-2) is 0 and the ratio would not be
            Y **= beta - 2.0
        Y *= X
        if M is not None:
            Y *= M
            Yb1 *= M
        return rdot(Y), rdot(Yb1)

    def _frobenius_buffers(self, L: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Scratch (k, rows), numerator and denominator (rows, k) of the unmasked beta = 2 update, reused.

        The caller may overwrite what :meth:`numerator_denominator` returns, not keep it past the
        side's next update.
        """
        dtype = np.result_type(L, R, self.X)
        bufs = self.frobenius_buffers
        if bufs is None or bufs[1].shape != L.shape or bufs[1].dtype != dtype:
            bufs = self.frobenius_buffers = (np.empty(L.shape[::-1], dtype=dtype), np.empty(L.shape, dtype=dtype),
                                             np.empty(L.shape, dtype=dtype))
        return bufs

    def _kl_numerator_blocked(self, L, R) -> np.ndarray:
        """(X / max(L R^T, eps)) R for a dense, fully observed X, by blocks of X's stored rows.

        The I-divergence numerator with the ratio never held whole: each block of rows of the
        product (about 4 MB) is computed, divided into X and multiplied by its factor while it is
        still in cache. The blocks are grouped in a fixed number of contiguous stripes (at most 8).
        Called from the main thread while numpy's BLAS may use several threads, the stripes run on
        that many Python threads with one BLAS thread each (:func:`_stripes_in_threads`); else
        one after the other. Where the blocks' contributions are summed (``transposed``), each
        stripe sums its blocks in order and the stripes are summed in order, so with two stripes
        or more the result does not depend on the number of threads. With one stripe (a small X,
        or n < 4 k) the products run on BLAS as it is, whose last bits can depend on its own
        thread count. Same operations as the unblocked form; faster when the product and X together
        overflow the cache (``benchmarks/README.md``, dense KL).
        """
        X = self.X
        n, m = X.shape
        k = L.shape[1]
        b = max(16, min(n, _BLOCK_BYTES // (L.dtype.itemsize * m)))
        starts = range(0, n, b)
        # At most 8 stripes, and their partial sums (transposed side) at most a quarter of X's size.
        n_stripes = max(1, min(8, len(starts), n // (4 * k)))
        stripes = _stripe_starts(n, b, n_stripes)
        eps = L.dtype.type(EPSILON)
        buf = self._stripe_buffers(n_stripes, (b, m), L)
        # The products with the factor are formed transposed, (k, rows): OpenBLAS runs the
        # wide-output form about 20 % faster than the (rows, k) one on these shapes.
        if not self.transposed:  # L = W (n, k), R = Ht (m, k): rows of the numerator are rows of X
            num = buf.num

            def run(i: int, t: int) -> None:
                for s in stripes[i]:
                    e = min(s + b, n)
                    P = buf.blocks[t][: e - s]
                    np.matmul(L[s:e], R.T, out=P)
                    _kernels.divide_clipped(X[s:e], P, eps)
                    T = buf.parts[t].reshape(-1)[: k * (e - s)].reshape(k, e - s)
                    np.matmul(R.T, P.T, out=T)
                    num[s:e] = T.T

            _stripes_in_threads(run, n_stripes, len(buf.blocks))
            return num

        # L = Ht (m, k), R = W (n, k): sum the blocks' contributions, stripe by stripe, then the stripes
        numT = buf.num  # (k, m): the numerator transposed

        threaded = len(buf.blocks) > 1  # else one stripe sum at a time, added as soon as it is done

        def run_t(i: int, t: int) -> None:
            acc = numT if i == 0 else buf.partial[i - 1 if threaded else 0]
            for first, s in zip((True, *([False] * (len(stripes[i]) - 1))), stripes[i]):
                e = min(s + b, n)
                P = buf.blocks[t][: e - s]
                np.matmul(R[s:e], L.T, out=P)
                _kernels.divide_clipped(X[s:e], P, eps)
                if first:
                    np.matmul(R[s:e].T, P, out=acc)
                else:
                    np.matmul(R[s:e].T, P, out=buf.parts[t])
                    acc += buf.parts[t]
            if i > 0 and not threaded:
                np.add(numT, acc, out=numT)

        _stripes_in_threads(run_t, n_stripes, len(buf.blocks))
        if threaded:  # the same sums in the same order as one thread's
            for i in range(1, n_stripes):
                numT += buf.partial[i - 1]
        return numT.T

    def _stripe_buffers(self, n_stripes: int, block: tuple[int, int], L: np.ndarray) -> _StripeBuffers:
        """Scratch space of the blocked numerator, reused across iterations (one block per thread)."""
        count = min(n_stripes, _blas_threads())
        key = (L.dtype, L.shape, block, n_stripes, count)
        buf = self.block_buffer
        if buf is None or buf.key != key:
            k = L.shape[1]
            if self.transposed:  # the numerator, each stripe's sum and each block's part are (k, m)
                num_shape, part_shape = (k, L.shape[0]), (k, L.shape[0])
                extra = (n_stripes - 1 if count > 1 else 1) if n_stripes > 1 else 0
            else:  # the numerator is (n, k); each block's part (k, rows) is copied into it
                num_shape, part_shape, extra = L.shape, (k, block[0]), 0
            buf = self.block_buffer = _StripeBuffers(
                key,
                np.empty(num_shape, dtype=L.dtype),
                [np.empty(block, dtype=L.dtype) for _ in range(count)],
                [np.empty(part_shape, dtype=L.dtype) for _ in range(count)],
                np.empty((extra, *num_shape), dtype=L.dtype),
            )
        return buf

    def _product(self, L, R) -> np.ndarray:
        """The dense product in the stored orientation, in a buffer reused across iterations."""
        buf = self.buffer
        if buf is None or buf.dtype != L.dtype:
            buf = self.buffer = np.empty(self.X.shape, dtype=L.dtype)
        return np.matmul(R, L.T, out=buf) if self.transposed else np.matmul(L, R.T, out=buf)

    def _sparse_nd(self, L, R, beta):
        X, M = cast("sp.csr_matrix", self.X), self.mask  # the sparse side: X is CSR
        w = self.weights if self.weights is not None else np.empty(0, dtype=L.dtype)
        if beta == 2.0 and M is None:
            num = np.asarray(X @ R)
        else:
            num = _kernels.mu_numerator(
                X.indptr, X.indices, X.data, w, L, R, beta, L.dtype.type(EPSILON), np.empty_like(L)
            )
        if beta == 1.0:
            den = np.broadcast_to(R.sum(axis=0), L.shape) if M is None else np.asarray(M @ R)
        elif beta == 2.0 and M is None:
            den = L @ (R.T @ R)
        elif sp.issparse(M):  # (M * max(Y, eps) ** (beta - 1)) R at the observed cells only
            Ms = cast("sp.csr_matrix", M)
            Y = _kernels.lowrank_at_nonzeros(Ms.indptr, Ms.indices, L, R, np.empty(Ms.nnz, dtype=L.dtype))
            np.maximum(Y, EPSILON if beta < 2.0 else 0.0, out=Y)
            if beta != 2.0:
                Y **= beta - 1.0
            Y *= Ms.data
            den = np.asarray(sp.csr_matrix((Y, Ms.indices, Ms.indptr), shape=Ms.shape) @ R)
        else:
            den = np.empty_like(L)
            for rows in dense_blocks(L.shape[0], R.shape[0]):
                Y = L[rows] @ R.T
                np.maximum(Y, EPSILON if beta < 2.0 else 0.0, out=Y)
                if beta != 2.0:
                    Y **= beta - 1.0
                if M is not None:
                    Y *= mask_block(M, rows)
                den[rows] = Y @ R
        return num, den

    def divergence(self, L: np.ndarray, R: np.ndarray, beta: float) -> float:
        """D_beta(X_side | L R^T) over observed cells (same value on both sides)."""
        X, M = self.X, self.mask
        if self.sparse:
            Xs = cast("sp.csr_matrix", X)  # self.sparse: X is CSR (the property hides it from mypy)
            Y = _kernels.lowrank_at_nonzeros(Xs.indptr, Xs.indices, L, R, np.empty(Xs.nnz, dtype=L.dtype))
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                on_nnz = elementwise_beta_divergence(Xs.data, Y, beta)
                zero_term = None
                if beta > 0:
                    zero_term = Y if beta == 1.0 else np.maximum(Y, 0.0) ** beta / beta
            if self.weights is not None:
                on_nnz = on_nnz * self.weights
                if zero_term is not None:
                    zero_term = zero_term * self.weights
            total = float(np.sum(on_nnz, dtype=np.float64))
            if zero_term is not None:
                total -= float(np.sum(zero_term, dtype=np.float64))
                total += (1.0 if beta == 1.0 else 1.0 / beta) * sum_power_lowrank(L, R, beta, M)
            return total
        return self._dense_divergence(L, R, beta)

    @staticmethod
    def _x_power_sum(X: np.ndarray, M: np.ndarray | None, beta: float) -> float:
        """sum m x^beta / (beta (beta - 1)) over a block in float64: the beta-divergence's terms in X alone."""
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            P = np.asarray(X, dtype=np.float64) ** beta
            if M is not None:
                P = np.where(M != 0, P * M, 0.0)  # an unobserved cell counts 0 even where x^beta is infinite
        return float(P.sum()) / (beta * (beta - 1.0))

    def _x_terms(self, beta: float) -> float:
        """sum m x^beta / (beta (beta - 1)) over a dense X (beta outside {0, 1, 2}), summed once per beta by the
        divergence's blocks of rows."""
        if beta not in self.x_terms:
            X, M = self.X, self.mask
            b = _divergence_block_rows(*X.shape)
            self.x_terms[beta] = sum(self._x_power_sum(X[s:s + b], None if M is None else M[s:s + b], beta)
                                     for s in range(0, X.shape[0], b))
        return self.x_terms[beta]

    def _dense_divergence(self, L: np.ndarray, R: np.ndarray, beta: float) -> float:
        """D_beta of a dense X by blocks of its stored rows, each block of the product used while in cache.

        The blocks are grouped in at most 8 contiguous stripes run as the blocked numerator runs
        them (:func:`_stripes_in_threads`); each block's terms are summed in float64, each stripe
        sums its blocks in order and the stripes are added in order, whatever the number of
        threads. For beta = 1 the logarithms are taken by numpy, vectorised
        (:func:`_kernels.kl_log_ratio_pass`).
        """
        X, M = self.X, self.mask
        n, m = X.shape
        b = _divergence_block_rows(n, m)
        starts = range(0, n, b)
        n_stripes = max(1, min(8, len(starts)))
        stripes = _stripe_starts(n, b, n_stripes)
        count = min(n_stripes, _blas_threads())
        bufs = self.divergence_buffers
        if len(bufs) != count or bufs[0].dtype != L.dtype or bufs[0].shape != (min(b, n), m):
            bufs = self.divergence_buffers = [np.empty((min(b, n), m), dtype=L.dtype) for _ in range(count)]
        empty = np.empty((0, 0), dtype=X.dtype)
        sums = [0.0] * n_stripes
        # fractional beta: the terms in X alone are the same at every evaluation, summed once
        fractional = beta not in (0.0, 1.0, 2.0)
        constant = self._x_terms(beta) if fractional else 0.0

        def run(i: int, t: int) -> None:
            total = 0.0
            for s in stripes[i]:
                e = min(s + b, n)
                P = bufs[t][: e - s]
                np.matmul(R[s:e], L.T, out=P) if self.transposed else np.matmul(L[s:e], R.T, out=P)
                Mb = empty if M is None else M[s:e]
                if beta == 1.0:
                    Q = P if P.dtype == np.float64 else np.empty(P.shape, dtype=np.float64)
                    part = _kernels.kl_log_ratio_pass(X[s:e], P, Mb, Q)
                    with np.errstate(divide="ignore"):
                        np.log(Q, out=Q)
                    part += _kernels.weighted_sum(X[s:e], Q)
                else:
                    part = _kernels.dense_divergence(X[s:e], P, Mb, beta, not fractional)
                total += float(part)
            sums[i] = total

        _stripes_in_threads(run, n_stripes, count)
        return float(sum(sums)) + constant


#: The sparse I-divergence update adds the updated factor's column sums in its kernel from this many rows on.
_KERNEL_SUM_ROWS = 4096


class Problem:
    """Both sides of X ~ W @ Ht.T, built once per fit."""

    def __init__(self, X, mask=None):
        self.shape = X.shape
        self.dtype = X.dtype
        if mask is not None:
            mask = mask.astype(X.dtype) if sp.issparse(mask) else np.asarray(mask, dtype=X.dtype)
            if sp.issparse(mask):
                mask = sp.csr_matrix(mask)
        if sp.issparse(X):
            XT = sp.csr_matrix(X.T)  # CSC of X reinterpreted: rows are features
            XT.sort_indices()
            w0 = w1 = None
            MT = None
            if mask is not None:
                rows0 = np.repeat(np.arange(X.shape[0]), np.diff(X.indptr))
                w0 = np.ascontiguousarray(gather(mask, rows0, X.indices), dtype=X.dtype)
                MT = sp.csr_matrix(mask.T) if sp.issparse(mask) else np.ascontiguousarray(mask.T)
                rows1 = np.repeat(np.arange(XT.shape[0]), np.diff(XT.indptr))
                w1 = np.ascontiguousarray(gather(MT, rows1, XT.indices), dtype=X.dtype)
            self.sides = (Side(X, mask, w0, False), Side(XT, MT, w1, False))
        else:
            if sp.issparse(mask):
                mask = mask.toarray()
            X = np.ascontiguousarray(X)  # the blocked kernels slice rows
            self.sides = (Side(X, mask, None, False), Side(X, mask, None, True))
        self.mask = mask

    @classmethod
    def used_columns(cls, problem: Problem, keep: np.ndarray) -> Problem:
        """The problem on the columns ``keep`` of a sparse, unmasked problem whose other columns hold no value.

        Shares the stored values with ``problem``: X keeps its values and row pointers (its
        column numbers are renumbered), and X.T keeps its values and column numbers (the
        rows of the empty columns, which hold nothing, are dropped from its row pointers).
        """
        X, XT = cast("sp.csr_matrix", problem.sides[0].X), cast("sp.csr_matrix", problem.sides[1].X)
        new = np.full(X.shape[1], -1, dtype=X.indices.dtype)
        new[keep] = np.arange(len(keep), dtype=X.indices.dtype)
        Xr = sp.csr_matrix((X.data, new[X.indices], X.indptr), shape=(X.shape[0], len(keep)), copy=False)
        indptr = np.append(XT.indptr[keep], XT.indptr[-1]).astype(XT.indptr.dtype, copy=False)
        XTr = sp.csr_matrix((XT.data, XT.indices, indptr), shape=(len(keep), XT.shape[1]), copy=False)
        out = cls.__new__(cls)
        out.shape, out.dtype, out.mask = Xr.shape, problem.dtype, None
        out.sides = (Side(Xr, None, None, False), Side(XTr, None, None, False))
        return out

    def divergence(self, W: np.ndarray, Ht: np.ndarray, beta: float) -> float:
        """D_beta(X | W Ht^T); under beta = 2, from the numerator of the last H update when it was kept for it.

        When side 1 kept the numerator ``N = X^T W`` of an update made with this very ``W``
        (:attr:`Side.keep_numerator`, dense, unmasked, float64), half the squared Frobenius norm
        is formed without the product W Ht^T, as scikit-learn forms it:

        .. math:: \\tfrac12 \\|X - W H\\|^2 = \\tfrac12 \\|X\\|^2 - \\langle H_t, N \\rangle
                  + \\tfrac12 \\langle W^T W, H_t^T H_t \\rangle

        (``O((n + m) k^2)`` instead of ``O(n m k)``). The three terms nearly cancel on a close
        fit; below :data:`_CANCELLATION` times the first, where the rounding would exceed about
        1e-11 of the value, the divergence is formed directly. The kept numerator is used once.
        """
        kept, self.sides[1].kept_numerator = self.sides[1].kept_numerator, None
        if beta == 2.0 and kept is not None and kept[0] is W and self.mask is None:
            half_sq = self._half_squared_norm
            value = (half_sq - float(np.vdot(Ht, kept[1]))
                     + 0.5 * float(np.vdot(W.T @ W, Ht.T @ Ht)))
            if value >= _CANCELLATION * half_sq:
                return value
        return self.sides[0].divergence(W, Ht, beta)

    @functools.cached_property
    def _half_squared_norm(self) -> float:
        """||X||^2 / 2 of a dense X, computed once."""
        X = np.asarray(self.sides[0].X)
        return 0.5 * float(np.vdot(X, X))


def beta_divergence(
    X: Any,
    W: np.ndarray,
    H: np.ndarray,
    beta: float | str = 2.0,
    *,
    mask: Any = None,
) -> float:
    """Beta-divergence between X and the low-rank product W @ H (thesis eq. 2.2).

    .. math:: D_\\beta(X | WH) = \\sum_{ij} m_{ij}\\, d_\\beta(X_{ij} | (WH)_{ij})

    X is (n_samples, n_features) as everywhere in :mod:`mmconcepts.nmf`; the thesis'
    V (features x examples) is ``X.T``. For beta = 2 this is half the squared
    Frobenius norm, for beta = 1 the I-divergence (generalized KL), for beta = 0 the
    Itakura-Saito divergence. It equals scikit-learn's ``_beta_divergence`` on data
    without zeros.

    Parameters
    ----------
    X : {ndarray, sparse matrix} of shape (n_samples, n_features)
        Nonnegative data. A sparse X is never densified: the product is evaluated only
        at its nonzeros, and the terms of the zeros are summed blockwise.
    W : ndarray of shape (n_samples, n_components)
    H : ndarray of shape (n_components, n_features)
    beta : float or {'frobenius', 'kullback-leibler', 'itakura-saito'}, default=2
    mask : {ndarray, sparse matrix} of shape (n_samples, n_features), optional
        True (or 1) where X is observed; unobserved cells do not count.

    Returns
    -------
    float
        The divergence (``inf`` if WH is zero where X is not, for beta <= 1, or where it exceeds
        the range of float64).

    Raises
    ------
    DataError
        X negative, NaN or infinite on observed cells, zero with beta <= 0, W or H of the wrong
        shape, negative or not finite.
    """
    beta = resolve_beta(beta)
    X, mask = validate_data(X, mask)
    check_beta_zeros(X, beta, mask)
    W = np.ascontiguousarray(W, dtype=np.result_type(np.asarray(W).dtype, np.float32))
    Ht = np.ascontiguousarray(np.asarray(H, dtype=W.dtype).T)
    if W.ndim != 2 or Ht.ndim != 2 or W.shape[0] != X.shape[0] or Ht.shape[0] != X.shape[1] or W.shape[1] != Ht.shape[1]:
        raise DataError(
            f"W and H must have shapes (n_samples, k) and (k, n_features) with X of shape {X.shape}; got "
            f"{W.shape} and {np.shape(H)}."
        )
    if not (np.isfinite(W).all() and np.isfinite(Ht).all()) or (W < 0).any() or (Ht < 0).any():
        raise DataError("W and H must be finite and nonnegative.")
    if sp.issparse(X):
        X = sp.csr_matrix(X)
        if X.dtype != W.dtype:
            X = X.astype(W.dtype)
    else:
        X = np.asarray(X, dtype=W.dtype)
    return Problem(X, mask).divergence(W, Ht, beta)
