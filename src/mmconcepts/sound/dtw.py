"""Dynamic time warping between sequences of feature frames (Thesis section 5.2.3).

The thesis compares fixed-length MFCC windows (80 or 150 ms, i.e. about 8 or 15 frames)
with a dynamic time warping (DTW) distance, which "takes into account possible insertions
and deletions in the feature sequence" and "enables to compare sound feature vectors of
different length" (Thesis section 5.2.3, paragraph *Dynamic time warping*). The
incremental clustering of section 5.2.3 only needs distances between sequences, so this
module provides one distance, a distance matrix, and a one-query-against-many search.

Definition
----------
For sequences :math:`a = (a_1, \\dots, a_n)` and :math:`b = (b_1, \\dots, b_m)` of frames in
:math:`\\mathbb{R}^d`, a *warping path* is a sequence of index pairs from :math:`(1, 1)` to
:math:`(n, m)` whose steps are :math:`(1, 0)`, :math:`(0, 1)` or :math:`(1, 1)`. The
classic DTW accumulates a local cost along the best path:

.. math::

    D(i, j) = c(a_i, b_j) + \\min\\{D(i-1, j-1),\\ D(i-1, j),\\ D(i, j-1)\\},
    \\qquad D(0, 0) = 0,\\ D(i, 0) = D(0, j) = +\\infty,

with two local costs:

- ``local="euclidean"`` (default): :math:`c(x, y) = \\lVert x - y \\rVert_2` and the
  distance is :math:`D(n, m)`, the usual textbook DTW;
- ``local="sqeuclidean"``: :math:`c(x, y) = \\lVert x - y \\rVert_2^2` and the distance is
  :math:`\\sqrt{D(n, m)}`, exactly the definition of ``dtaidistance`` (``dtw_ndim.distance``),
  so the two libraries can be compared value for value.

Both are symmetric, zero for identical sequences, and not metrics (no triangle inequality;
Thesis section 5.2.3 notes the consequence: no inner product, hence no k-means).

Sakoe-Chiba window
------------------
``window=r`` (an int >= 0, in frames) restricts paths to the band :math:`|i - j| \\le r`,
*widened by* :math:`|n - m|` *on the side of the longer sequence* so that the end cell
:math:`(n, m)` is always reachable: with :math:`n \\ge m`, cell :math:`(i, j)` is allowed
when :math:`-r - (n - m) \\le j - i \\le r`. A window smaller than the length difference
therefore still gives a finite distance (it is never an error); ``window=0`` with equal
lengths is the sum of frame-to-frame costs along the diagonal. This is the band of
tslearn's ``sakoe_chiba_mask`` (current versions) and of dtaidistance, whose ``window=w``
is our ``window=w - 1`` (dtaidistance counts the diagonal itself as one). ``window=None`` means no
restriction.

Implementation
--------------
Written by hand with numba: no maintained library offers a multivariate DTW distance
matrix over variable-length sequences that is parallel and cheap to call many times with
few candidates (dtaidistance, the reference it is checked and benchmarked against, is
three to five times slower here; see ``benchmarks/dtw.py``). Sequences are packed into one
contiguous array plus offsets (lists are packed by increasing length). The "column"
sequences are interleaved four at a time, frame by frame, so that the local costs of a row
frame against four sequences are one SIMD loop and the four recurrences run side by side
in SIMD lanes; two rows of the DP are kept. The kernels are exact: no early abandoning,
no lower-bound pruning, no reassociation of the sums, so a distance does not depend on
which function computed it, nor on the order of its two arguments (the recursion is
symmetric in ``a`` and ``b`` bit for bit), and equals dtaidistance's to the last bit on
the tests and the benchmark.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba as nb
import numpy as np

from .._jit import njit
from .._validation import Interval, Options, validate_params
from ..errors import DataError

__all__ = ["dtw", "dtw_distance_matrix", "dtw_one_to_many"]

ArrayLike = Any
SequencesLike = np.ndarray | Sequence[ArrayLike]

_LOCALS = ("euclidean", "sqeuclidean")

# Number of column sequences whose DP runs side by side in SIMD lanes (one AVX2 register of
# float64). A compile-time constant: the recurrence's dependence distance must be known for
# LLVM to vectorise it. Measured on the project machine, 4, 8 and 16 lanes are equally fast
# (the local costs dominate once the DP is vectorised); 4 wastes least on padding.
_LANES = 4

# Lane groups per work unit (the granularity of the parallel split): 16 groups = 64 columns.
_UNIT_GROUPS = 16

# Rows of local costs computed in one pass before the recurrence consumes them (bounds the
# buffer to 32 x 4 x the longest column sequence, whatever the row sequence's length).
_ROW_CHUNK = 32

# Below this many DP cells in total the serial kernel is used. Measured on the project
# machine (2 shared cores, with the earlier numba prange kernel), two threads break even near
# 30 000 cells and gain x1.5 at 100 000; the margin keeps thread start-up away from the many
# small calls of the incremental cluster tree.
_PARALLEL_MIN_CELLS = 100_000

# No fastmath: the +inf boundary of the DP must survive, and reassociating the d-term sums
# would make a distance depend on the kernel that computed it. FMA contraction is not
# enabled either, so results are reproducible across machines with and without FMA.
# ``fastmath=False`` is written out: a kernel that does not set it inherits the fastmath
# flags of a compiled caller (numba's flag inheritance), and the cluster tree's kernels,
# which call :func:`dtw_to_rows`, are compiled with fastmath.
_OPTS: dict[str, Any] = dict(nogil=True, cache=True, error_model="numpy", fastmath=False)


# --------------------------------------------------------------------------------------
# numba kernels (internal)
# --------------------------------------------------------------------------------------


@njit(**_OPTS)
def _costs(A, a0, n, BT, f0, F, C, r0, c0):  # pragma: no cover - compiled
    """C[r0 + i, c0 + f] = sum_k (A[a0 + i, k] - BT[k, f0 + f])**2 for i < n, f < F.

    Frames of the column side are the inner loop (SIMD); the d terms are added in order
    k = 0, 1, ... (four at a time to save loads and stores of C, same rounding).
    """
    d = A.shape[1]
    for i in range(n):
        Ci = C[r0 + i, c0 : c0 + F]
        x = A[a0 + i, 0]
        B0 = BT[0, f0 : f0 + F]
        for f in range(F):
            t = x - B0[f]
            Ci[f] = t * t
        k = 1
        while k + 4 <= d:
            x0 = A[a0 + i, k]
            x1 = A[a0 + i, k + 1]
            x2 = A[a0 + i, k + 2]
            x3 = A[a0 + i, k + 3]
            B0 = BT[k, f0 : f0 + F]
            B1 = BT[k + 1, f0 : f0 + F]
            B2 = BT[k + 2, f0 : f0 + F]
            B3 = BT[k + 3, f0 : f0 + F]
            for f in range(F):
                t0 = x0 - B0[f]
                t1 = x1 - B1[f]
                t2 = x2 - B2[f]
                t3 = x3 - B3[f]
                Ci[f] = (((Ci[f] + t0 * t0) + t1 * t1) + t2 * t2) + t3 * t3
            k += 4
        while k < d:
            x = A[a0 + i, k]
            Bk = BT[k, f0 : f0 + F]
            for f in range(F):
                t = x - Bk[f]
                Ci[f] += t * t
            k += 1


@njit(**_OPTS)
def _groups(b_off):  # pragma: no cover - compiled
    """Column sequences in groups of L consecutive ones: (g_off, lengths).

    Group g (sequences gL .. gL + L - 1) is stored interleaved as a (d, W_g) block with
    W_g = g_off[g + 1] - g_off[g] = L * (its longest length), at BI[d g_off[g]:d g_off[g + 1]]
    (see :func:`_interleave`); ``lengths`` has L entries per group, 0 for the lanes past the
    last sequence.
    """
    L = _LANES
    nB = b_off.shape[0] - 1
    ng = (nB + L - 1) // L
    lengths = np.zeros(ng * L, dtype=np.int64)
    for c in range(nB):
        lengths[c] = b_off[c + 1] - b_off[c]
    g_off = np.empty(ng + 1, dtype=np.int64)
    g_off[0] = 0
    for g in range(ng):
        mmax = 0
        for l in range(L):
            mmax = max(mmax, lengths[g * L + l])
        g_off[g + 1] = g_off[g] + mmax * L
    return g_off, lengths


@njit(**_OPTS)
def _interleave(B, b_off, lengths, g, BT):  # pragma: no cover - compiled
    """BT[k, j L + l] = coefficient k of frame j of column sequence gL + l (0 past its end)."""
    L = _LANES
    d = B.shape[1]
    mmax = BT.shape[1] // L
    for l in range(L):
        c = g * L + l
        m_l = lengths[c]
        if m_l > 0:
            S = B[b_off[c] : b_off[c] + m_l]
            for j in range(m_l):
                for k in range(d):
                    BT[k, j * L + l] = S[j, k]
        for j in range(m_l, mmax):
            for k in range(d):
                BT[k, j * L + l] = 0.0


@njit(**_OPTS)
def _interleave_all(B, b_off, g_off, lengths):  # pragma: no cover - compiled
    """Every group interleaved once, for problems where each group meets many rows."""
    d = B.shape[1]
    ng = g_off.shape[0] - 1
    BI = np.empty(d * g_off[ng])
    for g in range(ng):
        _interleave(B, b_off, lengths, g, BI[d * g_off[g] : d * g_off[g + 1]].reshape((d, g_off[g + 1] - g_off[g])))
    return BI


@njit(**_OPTS)
def _lane_group(A, a0, n, BT, lengths, radius, squared, work, res):  # pragma: no cover
    """DTW between the row sequence A[a0:a0 + n] and the L interleaved column sequences of
    BT (d, m L) (see :func:`_interleave`; ``lengths`` are theirs, 0 for an empty lane).

    The local costs of a chunk of row frames against all lanes are computed in one pass
    (long SIMD loops; at most ``_ROW_CHUNK`` rows are stored), then the recurrence

        D(i, j) = c(i, j) + min(D(i-1, j-1), D(i-1, j), D(i, j-1))

    runs on L pairs at once, written as u = c + min(D(i-1, j-1), D(i-1, j)) (vectorised
    over the row) then D(i, j) = min(u, c + D(i, j-1)) (vectorised across lanes; same value
    bit for bit, since rounding is monotone). Two rows of D are kept, slot (j + 1) L + l for
    column j, slots 0..L-1 for the boundary. With a Sakoe-Chiba band, local costs are
    computed on the union of the lanes' bands only, and every cell outside a lane's own band
    gets cost +inf, hence D = +inf: the recurrence itself always runs on full rows (it is
    cheap next to the costs, and full rows need no bookkeeping of stale slots). Lane l's
    result D(n, m_l) is read at slot m_l L + l of the last row (cells beyond a lane's length
    never feed cells before it). ``res[l]`` gets the distance (garbage for empty lanes).
    """
    L = _LANES
    inf = np.inf
    W = BT.shape[1]
    mmax = W // L
    C, prev, cur, u, ms, wl, wh = work
    zero = np.int64(0)  # not literals: one compiled version of _costs
    one = np.int64(1)
    for l in range(L):
        ms[l] = lengths[l] if lengths[l] > 0 else mmax
        if radius >= 0:
            wl[l] = radius + max(0, n - ms[l])
            wh[l] = radius + max(0, ms[l] - n)
    for f in range(L):
        prev[f] = 0.0
    for f in range(L, W + L):
        prev[f] = inf
    for i0 in range(0, n, _ROW_CHUNK):
        nr = min(_ROW_CHUNK, n - i0)
        # local costs of rows i0 .. i0 + nr - 1
        if radius < 0:
            _costs(A, a0 + i0, nr, BT, zero, W, C, zero, zero)
            if not squared:
                for r in range(nr):
                    Cr = C[r, :W]
                    for f in range(W):
                        Cr[f] = np.sqrt(Cr[f])
        else:
            # the union of the lanes' bands, +inf outside each lane's own band
            for r in range(nr):
                i = i0 + r
                lo_u = mmax
                hi_u = -1
                for l in range(L):
                    lo_u = min(lo_u, max(0, i - wl[l]))
                    hi_u = max(hi_u, min(ms[l] - 1, i + wh[l]))
                flo = lo_u * L
                fhi = (hi_u + 1) * L
                Cr = C[r, :W]
                for f in range(flo):
                    Cr[f] = inf
                for f in range(fhi, W):
                    Cr[f] = inf
                _costs(A, a0 + i, one, BT, flo, fhi - flo, C, r, flo)
                if not squared:
                    Cb = Cr[flo:fhi]
                    for f in range(fhi - flo):
                        Cb[f] = np.sqrt(Cb[f])
                for l in range(L):
                    for j in range(lo_u, max(0, i - wl[l])):
                        Cr[j * L + l] = inf
                    for j in range(min(ms[l] - 1, i + wh[l]) + 1, hi_u + 1):
                        Cr[j * L + l] = inf
        # the recurrence, on full rows (the band, if any, is in the +inf costs)
        for r in range(nr):
            Cr = C[r, :W]
            for f in range(W):
                u[f] = Cr[f] + min(prev[f], prev[f + L])
            for f in range(L):
                cur[f] = inf
            for f in range(W):
                cur[f + L] = min(u[f], Cr[f] + cur[f])
            prev, cur = cur, prev
    for l in range(L):
        v = prev[ms[l] * L + l]
        res[l] = np.sqrt(v) if squared else v


@njit(**_OPTS)
def _units(  # pragma: no cover - compiled
    A, a_off, B, b_off, BI, g_off, lengths, rperm, cperm, symmetric, radius, squared, u0, u1, out
):
    """Work units u0 <= u < u1, u = q * n_blocks + b: row sequence q (and, when symmetric,
    its mirror n_A - 1 - q, so that every q has about n_A pairs) against the lane groups of
    block b (``_UNIT_GROUPS`` consecutive ones). Symmetric problems only visit groups
    holding a column c > r and only write those columns (the upper triangle). Results go
    to out[rperm[r], cperm[c]] (and the transposed cell when symmetric).

    ``BI`` holds every group interleaved (:func:`_interleave_all`), or is empty: then each
    group is interleaved when it is used (one row only: the data is read once anyway, and
    is still in cache when its costs are computed).
    """
    L = _LANES
    nA = a_off.shape[0] - 1
    nB = out.shape[1]
    ng = g_off.shape[0] - 1
    d = A.shape[1]
    nblk = (ng + _UNIT_GROUPS - 1) // _UNIT_GROUPS
    maxW = 0
    for g in range(ng):
        maxW = max(maxW, g_off[g + 1] - g_off[g])
    work = (
        np.empty((_ROW_CHUNK, maxW)),
        np.empty(maxW + L),
        np.empty(maxW + L),
        np.empty(maxW),
        np.empty(L, dtype=np.int64),
        np.empty(L, dtype=np.int64),
        np.empty(L, dtype=np.int64),
    )
    scratch = np.empty(d * maxW)
    on_the_fly = BI.shape[0] == 0
    res = np.empty(L)
    for unit in range(u0, u1):
        q = unit // nblk
        b = unit % nblk
        for side in range(2 if symmetric else 1):
            r = q if side == 0 else nA - 1 - q
            if side == 1 and r == q:
                break
            g0 = b * _UNIT_GROUPS
            g1 = min(ng, g0 + _UNIT_GROUPS)
            if symmetric:
                g0 = max(g0, (r + 1) // L)
            for g in range(g0, g1):
                W = g_off[g + 1] - g_off[g]
                if on_the_fly:
                    BT = scratch[: d * W].reshape((d, W))
                    _interleave(B, b_off, lengths, g, BT)
                else:
                    BT = BI[d * g_off[g] : d * g_off[g + 1]].reshape((d, W))
                _lane_group(A, a_off[r], a_off[r + 1] - a_off[r], BT, lengths[g * L : g * L + L],
                            radius, squared, work, res)
                for l in range(L):
                    c = g * L + l
                    if c < nB and (not symmetric or c > r):
                        out[rperm[r], cperm[c]] = res[l]
                        if symmetric:
                            out[cperm[c], rperm[r]] = res[l]
    return out


@njit(**_OPTS)
def _n_units(nA, ng, symmetric):  # pragma: no cover - compiled
    nrow = (nA + 1) // 2 if symmetric else nA
    return nrow * ((ng + _UNIT_GROUPS - 1) // _UNIT_GROUPS)


@njit(**_OPTS)
def _prepare(A, a_off, B, b_off):  # pragma: no cover - compiled
    """Groups of the column side, interleaved up front unless there is one row sequence."""
    g_off, lengths = _groups(b_off)
    if a_off.shape[0] - 1 > 1:
        BI = _interleave_all(B, b_off, g_off, lengths)
    else:
        BI = np.empty(0)
    return BI, g_off, lengths


@njit(parallel=False, compile_apart=True, **_OPTS)
def _pairs_serial(A, a_off, B, b_off, rperm, cperm, symmetric, radius, squared, out):  # pragma: no cover
    BI, g_off, lengths = _prepare(A, a_off, B, b_off)
    U = _n_units(a_off.shape[0] - 1, g_off.shape[0] - 1, symmetric)
    return _units(A, a_off, B, b_off, BI, g_off, lengths, rperm, cperm, symmetric, radius, squared,
                  np.int64(0), U, out)


@njit(**_OPTS)
def _all_finite(x):  # pragma: no cover - compiled
    ok = True
    for e in range(x.shape[0]):
        ok &= np.isfinite(x[e])  # no early exit: the loop vectorises
    return ok


@njit(parallel=False, **_OPTS)
def _fixed_serial(q, X, radius, squared, out):  # pragma: no cover - compiled
    """out[0, c] = DTW(q, X[c]) for a (T, d) query and (n, T', d) candidates, one call.

    The small-call path of :func:`dtw_one_to_many` and :func:`dtw`: the finiteness check and
    the packing happen here, without Python overhead. Returns -1 when done, -2 if the
    query holds NaN/inf, or the index of the first candidate that does (nothing computed).
    """
    n, T, d = X.shape
    Tq = q.shape[0]
    if not _all_finite(q.reshape(Tq * d)):
        return -2
    Xf = X.reshape((n, T * d))
    for c in range(n):
        if not _all_finite(Xf[c]):
            return c
    a_off = np.zeros(2, dtype=np.int64)
    a_off[1] = Tq
    B = X.reshape((n * T, d))
    b_off = np.arange(n + 1) * T
    g_off, lengths = _groups(b_off)
    # non-literal arguments, so that the callees compile once for all entry points
    symmetric = n < 0
    U = _n_units(a_off.shape[0] - 1, g_off.shape[0] - 1, symmetric)
    _units(q, a_off, B, b_off, np.empty(0), g_off, lengths, np.zeros(1, dtype=np.int64), np.arange(n),
           symmetric, radius, squared, np.int64(0), U, out)
    return -1


@njit(**_OPTS)
def dtw_to_rows(q, T, R, ids, buf, out):  # pragma: no cover - compiled
    """out[j] = DTW between the window ``q`` and the window in row ``ids[j]`` of ``R``.

    The compiled path of the cluster tree (:class:`~mmconcepts.sound.tree.ClusterTree` with
    ``metric="dtw"``): ``q`` (T d,) and the rows of ``R`` (n_rows, T d) are flattened (T, d)
    windows; the local cost is Euclidean, without window (the defaults of
    :func:`dtw_one_to_many`, whose values these are, bit for bit: the same lane kernel).
    ``buf`` is a work array of at least ``len(ids) * R.shape[1]`` values.
    """
    m = ids.shape[0]
    D = R.shape[1]
    d = D // T
    for j in range(m):
        r = ids[j]
        for t in range(D):
            buf[j * D + t] = R[r, t]
    _fixed_serial(q.reshape((T, d)), buf[: m * D].reshape((m, T, d)), np.int64(-1), m < 0, out[:m].reshape((1, m)))


# --------------------------------------------------------------------------------------
# input checks and packing
# --------------------------------------------------------------------------------------


#: The parameters of the public functions, checked by :func:`mmconcepts._validation.validate_params`.
_PARAMETER_CONSTRAINTS: dict[str, list] = {
    "window": [None, Interval("int", 0, None)],
    "local": [Options(*_LOCALS)],
    "n_jobs": [None, Interval("int", 1, None), Interval("int", None, -1)],
}
_HINTS = {
    "window": "It is a Sakoe-Chiba radius in frames; None means no window.",
    "n_jobs": "-1 uses as many threads as NUMBA_NUM_THREADS, -2 one fewer, ...",
}


def _check_params(owner: str, window: Any, local: Any, n_jobs: Any = None) -> tuple[bool, int]:
    """Validate the options; return (squared local cost, Sakoe-Chiba radius or -1 for none)."""
    validate_params({"window": window, "local": local, "n_jobs": n_jobs}, _PARAMETER_CONSTRAINTS, owner=owner,
                    hints=_HINTS)
    radius = -1 if window is None else min(int(window), 2**40)  # a window longer than the sequences is no window
    return local == "sqeuclidean", radius


def _n_threads(n_jobs: Any) -> int:
    """Number of threads for ``n_jobs``, counted as numba counts them (None: numba's current setting)."""
    if n_jobs is None:
        return nb.get_num_threads()
    # numba sets its config attributes at run time (numba/core/config.py, _EnvReloader), so its
    # stubs do not show them
    max_threads = nb.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    if n_jobs < 0:
        return max(1, max_threads + 1 + int(n_jobs))
    return min(int(n_jobs), max_threads)


def _pairs_in_threads(n_threads: int, A: np.ndarray, a_off: np.ndarray, B: np.ndarray, b_off: np.ndarray,
                      rperm: np.ndarray, cperm: np.ndarray, symmetric: bool, radius: int, squared: bool,
                      out: np.ndarray) -> np.ndarray:
    """What :func:`_pairs_serial` computes, on ``n_threads`` Python threads.

    The work units are split into ``8 * n_threads`` contiguous ranges, each run by :func:`_units`,
    which releases the GIL; no two units write the same cell of ``out``, and every cell is computed
    by the same code as in the serial kernel, so the results are the same, bit for bit. Threads
    rather than a numba ``prange`` kernel, which was among the package's slowest kernels to compile
    on a fresh install (``benchmarks/README.md``), and whose OpenMP threads spin after each parallel
    region.
    """
    BI, g_off, lengths = _prepare(A, a_off, B, b_off)
    n_units = int(_n_units(a_off.shape[0] - 1, g_off.shape[0] - 1, symmetric))
    n_chunks = min(8 * n_threads, n_units)
    bounds = [np.int64(ch * n_units // n_chunks) for ch in range(n_chunks + 1)]

    def run(ch: int) -> None:
        _units(A, a_off, B, b_off, BI, g_off, lengths, rperm, cperm, symmetric, radius, squared, bounds[ch],
               bounds[ch + 1], out)

    with ThreadPoolExecutor(n_threads, thread_name_prefix="mmconcepts-dtw") as pool:
        list(pool.map(run, range(n_chunks)))  # list: re-raises a thread's exception
    return out


def _as_float_array(x: Any, what: str) -> np.ndarray:
    x = np.asarray(x)
    if np.iscomplexobj(x):
        raise DataError(f"{what} holds complex numbers; DTW needs real frames.")
    if x.dtype == object:
        try:
            x = x.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{what} must hold numbers; got an object array ({exc}).") from None
    elif not (np.issubdtype(x.dtype, np.number) or x.dtype == bool):
        raise DataError(f"{what} must hold numbers; got dtype {x.dtype}.")
    return x


def _check_sequence(x: Any, what: str, *, check_finite: bool = True) -> np.ndarray:
    """One sequence as a C-contiguous float64 (n_frames, d) array; 1-D means d = 1.

    ``check_finite=False`` leaves the NaN/inf check to the caller (:func:`_fixed_serial`).
    """
    if not (type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 2 and x.flags.c_contiguous):
        x = _as_float_array(x, what)
        if x.ndim == 1:
            x = x[:, None]
        elif x.ndim != 2:
            raise DataError(f"{what} must be a (n_frames, d) array (or 1-D for d = 1); got shape {x.shape}.")
        x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape[0] == 0 or x.shape[1] == 0:
        raise DataError(f"{what} is empty: shape {x.shape}; every sequence needs at least one frame of d >= 1 values.")
    if check_finite and not np.isfinite(x).all():
        raise DataError(f"{what} contains NaN or infinite values; remove or impute them first.")
    return x


def _check_fixed(X: np.ndarray, name: str) -> np.ndarray:
    """A numeric ndarray of sequences as a C-contiguous float64 (n, T, d) array."""
    if not (X.dtype == np.float64 and X.flags.c_contiguous):
        X = np.ascontiguousarray(_as_float_array(X, name), dtype=np.float64)
    if X.ndim != 3:
        raise DataError(
            f"{name} must be a 3-D array (n_sequences, n_frames, d) or a list of (n_frames_i, d) "
            f"arrays; got an array of shape {X.shape}."
            + (f" For univariate sequences use {name}[:, :, None]." if X.ndim == 2 else "")
        )
    n, T, d = X.shape
    if n == 0:
        raise DataError(f"{name} holds no sequence (shape {X.shape}).")
    if T == 0 or d == 0:
        raise DataError(f"{name}[0] is empty: every sequence has shape {(T, d)}; each needs at least one frame.")
    if not np.isfinite(X).all():
        bad = int(np.flatnonzero(~np.isfinite(X).reshape(n, T * d).all(axis=1))[0])
        raise DataError(f"{name}[{bad}] contains NaN or infinite values; remove or impute them first.")
    return X


def _is_fixed(X: Any) -> bool:
    return isinstance(X, np.ndarray) and X.dtype != object


_ONE = np.zeros(1, dtype=np.int64)  # the permutation of a single sequence (read-only use)


class _Packed:
    """Sequences packed row-wise into one (total frames, d) array.

    Sequence s is ``rows[offsets[s]:offsets[s + 1]]`` and is the input's ``perm[s]``-th.
    """

    __slots__ = ("offsets", "perm", "rows")

    def __init__(self, rows: np.ndarray, offsets: np.ndarray, perm: np.ndarray) -> None:
        self.rows = rows
        self.offsets = offsets
        self.perm = perm

    @classmethod
    def single(cls, x: np.ndarray) -> _Packed:
        return cls(x, np.array([0, x.shape[0]], dtype=np.int64), _ONE)

    @classmethod
    def fixed(cls, X: np.ndarray) -> _Packed:
        n, T, d = X.shape
        idx = np.arange(n + 1, dtype=np.int64)
        return cls(X.reshape(n * T, d), idx * T, idx[:n])

    @property
    def d(self) -> int:
        return self.rows.shape[1]

    def __len__(self) -> int:
        return self.offsets.shape[0] - 1


def _pack(X: Any, name: str) -> _Packed:
    """Validate a collection of sequences (3-D array or list of 2-D/1-D arrays) and pack it.

    A list is packed in order of increasing length (stable), so that the sequences that
    share SIMD lanes have about the same length (less padding).
    """
    if _is_fixed(X):
        return _Packed.fixed(_check_fixed(X, name))
    if isinstance(X, (str, bytes)) or not isinstance(X, Sequence):
        raise DataError(
            f"{name} must be a 3-D array (n_sequences, n_frames, d) or a list of (n_frames_i, d) arrays; "
            f"got {type(X).__name__}."
        )
    if len(X) == 0:
        raise DataError(f"{name} holds no sequence (empty list).")
    seqs = []
    d0 = None
    for idx, x in enumerate(X):
        s = _check_sequence(x, f"{name}[{idx}]")
        if d0 is None:
            d0 = s.shape[1]
        elif s.shape[1] != d0:
            raise DataError(
                f"{name}[{idx}] has d = {s.shape[1]} values per frame but {name}[0] has d = {d0}; "
                "all sequences must have the same number of features."
            )
        seqs.append(s)
    lengths = np.array([s.shape[0] for s in seqs], dtype=np.int64)
    perm = np.argsort(lengths, kind="stable").astype(np.int64)
    offsets = np.zeros(len(seqs) + 1, dtype=np.int64)
    np.cumsum(lengths[perm], out=offsets[1:])
    return _Packed(np.concatenate([seqs[i] for i in perm], axis=0), offsets, perm)


def _run(rows: _Packed, cols: _Packed, symmetric: bool, radius: int, squared: bool, n_jobs: Any) -> np.ndarray:
    """Distances between every sequence of ``rows`` and of ``cols`` (upper triangle if symmetric),
    as an (n_rows, n_cols) array in the input order (zeros where nothing is computed)."""
    nA, nB = len(rows), len(cols)
    out = np.zeros((nA, nB), dtype=np.float64)
    if symmetric and nA < 2:
        return out
    a_off, b_off = rows.offsets, cols.offsets
    # total DP cells, to skip the thread team for small problems
    if symmetric:
        la = np.diff(a_off).astype(np.float64)
        cells = 0.5 * (float(a_off[-1]) ** 2 - float(la @ la))
    else:
        cells = float(a_off[-1]) * float(b_off[-1])
    n_threads = 1 if cells < _PARALLEL_MIN_CELLS else _n_threads(n_jobs)
    args = (rows.rows, a_off, cols.rows, b_off, rows.perm, cols.perm, symmetric, radius, squared)
    if n_threads == 1:
        return _pairs_serial(*args, out)
    return _pairs_in_threads(n_threads, *args, out)


# --------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------


def dtw(a: ArrayLike, b: ArrayLike, *, window: int | None = None, local: str = "euclidean") -> float:
    """Dynamic time warping distance between two sequences of frames (Thesis section 5.2.3).

    .. math::

        D(i, j) = c(a_i, b_j) + \\min\\{D(i-1, j-1), D(i-1, j), D(i, j-1)\\},\\quad
        \\mathrm{DTW}(a, b) = D(n, m) \\text{ (euclidean) or } \\sqrt{D(n, m)} \\text{ (sqeuclidean)}

    Parameters
    ----------
    a : array-like of shape (n, d) or (n,)
        First sequence, one frame per row (e.g. MFCC vectors). 1-D means d = 1.
    b : array-like of shape (m, d) or (m,)
        Second sequence, with the same d; its length may differ.
    window : int >= 0 or None, default=None
        Sakoe-Chiba radius in frames: only cells with ``|i - j| <= window`` are allowed, the
        band being widened by ``|n - m|`` on the side of the longer sequence so that a path
        always exists (a window narrower than the length difference is not an error).
        dtaidistance's ``window=w`` is ``window=w - 1`` here. None: no restriction.
    local : {"euclidean", "sqeuclidean"}, default="euclidean"
        Local cost. ``"euclidean"``: frame distance :math:`\\lVert a_i - b_j \\rVert`, and the
        result is the summed cost of the best path (the usual DTW). ``"sqeuclidean"``:
        squared frame distance, and the result is the square root of the best summed cost,
        the definition of ``dtaidistance.dtw_ndim.distance``.

    Returns
    -------
    float
        The DTW distance (>= 0, 0 for identical sequences, symmetric in ``a`` and ``b``).

    Raises
    ------
    DataError
        If a sequence is empty, not 1-D/2-D, holds NaN or inf, or the two have different d.
    ParameterError
        If ``window`` or ``local`` is not allowed.

    See Also
    --------
    dtw_distance_matrix : all pairwise distances, in parallel.
    dtw_one_to_many : one query against many candidates.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.array([0.0, 1.0, 2.0, 2.0, 3.0])
    >>> b = np.array([0.0, 1.0, 2.0, 3.0])
    >>> dtw(a, b)
    0.0
    """
    squared, radius = _check_params("dtw", window, local)
    a = _check_sequence(a, "a", check_finite=False)
    b = _check_sequence(b, "b", check_finite=False)
    if a.shape[1] != b.shape[1]:
        raise DataError(
            f"a and b must have the same number of values per frame; got d = {a.shape[1]} for a "
            f"and d = {b.shape[1]} for b."
        )
    out = np.empty((1, 1))
    status = _fixed_serial(a, b[None], radius, squared, out)
    if status != -1:
        raise DataError(f"{'a' if status == -2 else 'b'} contains NaN or infinite values; remove or impute them first.")
    return float(_finite_distances(out)[0, 0])


def dtw_distance_matrix(
    X: SequencesLike,
    Y: SequencesLike | None = None,
    *,
    window: int | None = None,
    local: str = "euclidean",
    n_jobs: int | None = None,
) -> np.ndarray:
    """Pairwise DTW distances between collections of sequences (Thesis section 5.2.3).

    Parameters
    ----------
    X : list of array-like of shape (n_frames_i, d), or ndarray of shape (n_X, T, d)
        Sequences, possibly of different lengths (list), or of one length (3-D array).
        Items of a list may be 1-D (d = 1). A 2-D array is refused as ambiguous: pass
        ``X[:, :, None]`` for univariate sequences.
    Y : same as X, or None, default=None
        Second collection. None computes the symmetric matrix of X against itself from its
        upper triangle only (the diagonal is 0).
    window : int >= 0 or None, default=None
        Sakoe-Chiba radius in frames, see :func:`dtw`.
    local : {"euclidean", "sqeuclidean"}, default="euclidean"
        Local cost, see :func:`dtw`.
    n_jobs : int or None, default=None
        Number of threads, counted as numba counts them: None uses numba's current setting
        (:func:`numba.get_num_threads`), -1 all of ``NUMBA_NUM_THREADS``, -2 all but one,
        and so on; values above ``NUMBA_NUM_THREADS`` are clipped to it. Small problems run
        on one thread whatever the setting.

    Returns
    -------
    ndarray of shape (n_X, n_Y), float64
        ``D[i, j] = dtw(X[i], Y[j], window=window, local=local)``, bit for bit.

    Raises
    ------
    DataError
        If a collection is empty or a sequence is empty, holds NaN or inf, or has another d
        than the first one (the message names the index, e.g. ``X[3]``).
    ParameterError
        If ``window``, ``local`` or ``n_jobs`` is not allowed.
    """
    squared, radius = _check_params("dtw_distance_matrix", window, local, n_jobs)
    PX = _pack(X, "X")
    if Y is None:
        return _finite_distances(_run(PX, PX, True, radius, squared, n_jobs))
    PY = _pack(Y, "Y")
    if PY.d != PX.d:
        raise DataError(
            f"Y[0] has d = {PY.d} values per frame but X[0] has d = {PX.d}; X and Y must have the same d."
        )
    return _finite_distances(_run(PX, PY, False, radius, squared, n_jobs))


def _finite_distances(D: np.ndarray) -> np.ndarray:
    """The distances, or a DataError when they overflowed (inputs are finite and paths always exist)."""
    if not np.isfinite(D).all():
        raise DataError(
            "DTW distances overflow float64: the frames are too large (their squared differences exceed "
            "about 1e308); divide the sequences by a constant (DTW distances scale with it)."
        )
    return D


def dtw_one_to_many(
    query: ArrayLike,
    candidates: SequencesLike,
    *,
    window: int | None = None,
    local: str = "euclidean",
    n_jobs: int | None = None,
) -> np.ndarray:
    """DTW distances from one sequence to each of many (Thesis section 5.2.3).

    Meant for nearest-neighbour searches called many times with few candidates (the
    incremental cluster tree). With a C-contiguous float64 (n, T, d) array of candidates
    and fewer than 100 000 DP cells in all (n T T_query), the checks and the work are one
    compiled call on the calling thread (a few microseconds of overhead, no copy, no thread
    start-up); larger calls run in parallel.

    Parameters
    ----------
    query : array-like of shape (T, d) or (T,)
        The query sequence.
    candidates : ndarray of shape (n, T_c, d), or list of array-like of shape (T_i, d)
        The sequences to compare with; their length may differ from the query's.
    window : int >= 0 or None, default=None
        Sakoe-Chiba radius in frames, see :func:`dtw`.
    local : {"euclidean", "sqeuclidean"}, default="euclidean"
        Local cost, see :func:`dtw`.
    n_jobs : int or None, default=None
        Number of threads for large calls, see :func:`dtw_distance_matrix`.

    Returns
    -------
    ndarray of shape (n,), float64
        ``out[k] = dtw(query, candidates[k], window=window, local=local)``, bit for bit.

    Raises
    ------
    DataError
        If the query or a candidate is empty, holds NaN or inf, or has another d (the
        message names the candidate's index).
    ParameterError
        If ``window``, ``local`` or ``n_jobs`` is not allowed.
    """
    if window is None and n_jobs is None and isinstance(local, str) and local == "euclidean":
        squared, radius = False, -1  # the defaults, as the cluster tree calls it: nothing to check
    else:
        squared, radius = _check_params("dtw_one_to_many", window, local, n_jobs)
    q = _check_sequence(query, "query", check_finite=False)
    X = candidates
    if (
        type(X) is np.ndarray
        and X.ndim == 3
        and X.dtype == np.float64
        and X.flags.c_contiguous
        and X.size > 0
        and X.shape[2] == q.shape[1]
        and float(X.shape[0]) * X.shape[1] * q.shape[0] < _PARALLEL_MIN_CELLS
    ):
        # the incremental cluster tree's call: one compiled call does the checks and the work
        out = np.empty((1, X.shape[0]))
        status = _fixed_serial(q, X, radius, squared, out)
        if status == -1:
            return _finite_distances(out)[0]
        if status >= 0:
            raise DataError(f"candidates[{status}] contains NaN or infinite values; remove or impute them first.")
    if not np.isfinite(q).all():
        raise DataError("query contains NaN or infinite values; remove or impute them first.")
    C = _pack(candidates, "candidates")
    if C.d != q.shape[1]:
        raise DataError(
            f"candidates have d = {C.d} values per frame but query has d = {q.shape[1]}; they must match."
        )
    return _finite_distances(_run(_Packed.single(q), C, False, radius, squared, n_jobs))[0]
