"""Beta-NMF of a ``dask.array`` by row chunks: distributed and out of core (thesis section 2.1.3).

The factorization X ~ W @ H (X: n_samples x n_features, one example per row) splits along the
rows of X: the rows of W that belong to a row chunk X_c depend on X_c and on the dictionary H
only, and the numerator and denominator of the multiplicative update of H (thesis eq. 2.16,
written with our orientation: the thesis' V, W, H are our X.T, H.T, W.T) are sums over rows,

.. math::
    N = \\sum_c (M_c \\odot X_c \\odot (W_c H)^{\\beta-2})^T W_c, \\qquad
    D = \\sum_c (M_c \\odot (W_c H)^{\\beta-1})^T W_c .

So each iteration is one pass over the chunks: a task per chunk, run where the chunk lives,
updates its W_c with exactly the in-memory update (:func:`mmconcepts.nmf._updates.mu_update` on
the chunk's :class:`~mmconcepts.nmf._problem.Problem`), and returns its (N_c, D_c), two
n_features x k arrays (D_c is a k-vector for the I-divergence and a k x k Gram matrix for the
Frobenius loss without a mask, as in memory); the sums are reduced in a tree in chunk order
(the same sums whichever worker runs which chunk), and the task at its root updates H on the
worker that holds the sums, for the next iteration's chunk tasks. The objective of (W, H) is
computed by the chunk tasks of the pass that updates them, and the iterations from one
evaluation of the objective to the next (every ``loss_every``) make one graph, submitted at
once: the client reads only the objectives, so the stopping rule and the iterates are those of
:func:`~mmconcepts.nmf.beta_nmf` on the whole matrix, up to the order of the sums. W never
leaves the workers; H and the sums are the only traffic, at most k x n_features per chunk and
per iteration. On a ``distributed`` cluster, each chunk stays on one worker for the whole fit
(contiguous rows of about the same size per worker), a worker's consecutive chunks of one group
of the tree run as one task per iteration that hands their W to the next iteration's, each sum
runs where its first chunk is, and the new H goes to the workers down a tree of the same
fan-out: a few tasks per worker and iteration, and a few k x n_features arrays in and out of
each worker. With no more workers than the fan-in (``split_every``), the scheduler is left out
of the iterations: each worker runs one task per batch of iterations over all its chunks, sends
its sums to the other workers (a handler of its own on each worker, installed by a worker
plugin) and adds up everyone's itself, in the tree's order, to update its own copy of H: the same
numbers, one exchange between the workers per iteration, and no scheduler round trip but one per
batch. Those tasks wait for each other, so a worker lost during such a fit ends it with
:class:`~mmconcepts.errors.ClusterError` (fit again); the scheduler's graph of the other cases has
a lost chunk's tasks computed again instead, and ``dask.config.set({"mmconcepts.nmf.exchange":
"scheduler"})`` chooses it for a few workers too.

Memory
------
``beta_nmf`` of a dask array keeps, in the cluster's memory and for the whole fit, each chunk's
validated rows (with their CSR transpose when sparse, as the in-memory solver does) and its rows
of W: about twice the nonzeros of X plus n_samples x k, spread over the workers; W twice at the
end of each batch when ``tol > 0`` (the W of the evaluated iteration, the answer if the rule stops
there, beside the next one). The client holds H at the end only.

Out of core
-----------
A matrix too large for memory is stored as a folder of ``.npz`` row chunks (the layout of
:func:`save_npz_chunks`) and read lazily by :func:`load_npz_chunks`;
:func:`beta_nmf_out_of_core` fits it with W kept on disk between passes (one ``.npy`` file per
chunk), one pass per iteration with H updated by the client from the sums, and writes the final
W to a folder of the same layout, chunk by chunk, only once the fit has succeeded.

Written by hand: no maintained library computes beta-divergence NMF on Dask (dask-ml has no NMF).
dask is imported lazily: the rest of :mod:`mmconcepts.nmf` works without it.
"""

from __future__ import annotations

import contextlib
import json
import math
import operator
import os
import shutil
import tempfile
import threading
import uuid
import warnings
import weakref
import zipfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import scipy.sparse as sp

from .._io import atomic_path, replace_dir
from .._validation import check_nonnegative_matrix, check_random_state
from ..errors import ClusterError, ConvergenceWarning, DataError, DataFormatError, ParameterError
from ._beta import check_beta_zeros, mm_exponent
from ._coefficients import solve_coefficients
from . import _kernels
from ._problem import Problem, Side
from ._data import check_factor, check_mask, is_dask_array, validate_data
from ._init import Unreachable, check_factor_not_zero, refuse_unreachable
from ._updates import (
    BETA_NMF_CONSTRAINTS,
    NMFResult,
    Penalty,
    check_objective_range,
    constant_coefficients,
    data_scale,
    in_units_of_X,
    mu_update,
    resolve_penalties,
    scale_penalties,
    sparse_kl_applies,
    sparse_kl_update,
    stopped_message,
)

__all__ = [
    "NPZ_CHUNKS_FORMAT",
    "beta_nmf_dask",
    "beta_nmf_out_of_core",
    "hstack_row_chunks",
    "is_dask_array",
    "load_npz_chunks",
    "save_npz_chunks",
    "solve_coefficients_dask",
]

#: The ``format`` field of the manifest of a folder of ``.npz`` chunks, and its version.
NPZ_CHUNKS_FORMAT = "mmconcepts-npz-chunks"
NPZ_CHUNKS_VERSION = 1
_MANIFEST = "manifest.json"


# ---------------------------------------------------------------------------------------------
# dask, imported lazily


def _require_dask(what: str):
    try:
        import dask
        import dask.array
    except ImportError as exc:  # pragma: no cover - dask is installed in the test environment
        raise ImportError(
            f"{what} needs dask, which is not installed. Install the extra: pip install 'mmconcepts[dask]'."
        ) from exc
    return dask


# ---------------------------------------------------------------------------------------------
# The on-disk layout: a folder of .npz row chunks


def save_npz_chunks(X: Any, folder: str | os.PathLike[str], *, chunk_rows: int | None = None,
                    overwrite: bool = False) -> Path:
    """Write a matrix to ``folder`` as ``.npz`` row chunks, one chunk in memory at a time.

    Layout (version 1)::

        folder/manifest.json      {"format": "mmconcepts-npz-chunks", "version": 1,
                                   "shape": [n_samples, n_features], "dtype": "float64",
                                   "sparse": true, "chunks": [{"file": "chunk-000000.npz",
                                   "rows": 1000}, ...]}
        folder/chunk-000000.npz   rows 0 .. 999: a CSR matrix as written by
                                  scipy.sparse.save_npz (uncompressed) when "sparse",
                                  else numpy.savez with the one array "X"
        ...

    The chunks are listed in row order; every chunk has all the columns. The folder is written
    beside its final place and moved there when complete: a reader never sees a half-written
    folder.

    Parameters
    ----------
    X : {ndarray, sparse matrix, dask.array.Array} of shape (n_samples, n_features), or an iterable of 2-D chunks
        The matrix. A dask array keeps its row chunks (each computed in turn); an iterable
        (e.g. a generator) gives the chunks in row order, each with all the columns, all
        dense or all sparse.
    folder : path
    chunk_rows : int, optional
        Rows per chunk for an ndarray or a sparse matrix (default: all in one chunk).
    overwrite : bool, default=False
        Replace an existing folder (only once the new one is complete).

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    FileExistsError
        ``folder`` exists and ``overwrite`` is False.
    DataError
        Chunks that are not 2-D, disagree on the number of columns, or mix dense and sparse.
    """
    folder = Path(folder)
    if folder.exists() and not overwrite:
        raise FileExistsError(f"{folder} exists; pass overwrite=True to replace it, or choose another folder.")
    if chunk_rows is not None and (isinstance(chunk_rows, bool) or int(chunk_rows) < 1):
        raise ParameterError(f"chunk_rows must be an int >= 1; got {chunk_rows!r}.")
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.partial-", dir=folder.parent))
    try:
        entries: list[dict] = []
        n_cols: int | None = None
        sparse: bool | None = None
        dtype: np.dtype | None = None
        for i, chunk in enumerate(_iter_chunks(X, chunk_rows)):
            is_sparse = sp.issparse(chunk)
            chunk = sp.csr_matrix(chunk) if is_sparse else np.asarray(chunk)
            if chunk.ndim != 2:
                raise DataError(f"chunk {i} must be 2-D; got shape {chunk.shape}.")
            if n_cols is None:
                n_cols, sparse, dtype = chunk.shape[1], is_sparse, chunk.dtype
            if chunk.shape[1] != n_cols:
                raise DataError(f"every chunk must have the {n_cols} columns of chunk 0; chunk {i} has {chunk.shape[1]}.")
            if is_sparse != sparse:
                raise DataError(f"chunk 0 is {'sparse' if sparse else 'dense'} but chunk {i} is not: give one kind.")
            dtype = np.result_type(dtype, chunk.dtype)
            name = f"chunk-{i:06d}.npz"
            if is_sparse:
                sp.save_npz(tmp / name, chunk, compressed=False)
            else:
                np.savez(tmp / name, X=chunk)
            entries.append({"file": name, "rows": int(chunk.shape[0])})
        if n_cols is None:
            raise DataError("X has no chunk to write; give at least one row.")
        manifest = {"format": NPZ_CHUNKS_FORMAT, "version": NPZ_CHUNKS_VERSION,
                    "shape": [sum(e["rows"] for e in entries), n_cols], "dtype": str(np.dtype(dtype)),
                    "sparse": bool(sparse), "chunks": entries}
        (tmp / _MANIFEST).write_text(json.dumps(manifest, indent=1))
        replace_dir(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _iter_chunks(X: Any, chunk_rows: int | None) -> Iterator[Any]:
    if is_dask_array(X):
        check_row_chunks(X, "X")
        for i in range(X.numblocks[0]):
            yield X.blocks[i].compute()
        return
    if sp.issparse(X) or isinstance(X, np.ndarray):
        n = X.shape[0]
        step = n if chunk_rows is None else int(chunk_rows)
        X = sp.csr_matrix(X) if sp.issparse(X) else X
        for start in range(0, max(n, 1), max(step, 1)):
            yield X[start:start + step]
        return
    if isinstance(X, Iterable):
        yield from X
        return
    yield np.asarray(X)


def _read_manifest(folder: Path) -> dict:
    path = folder / _MANIFEST
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise DataFormatError(
            f"{folder} is not a folder of .npz chunks: it has no {_MANIFEST}. Write one with save_npz_chunks."
        ) from exc
    except (OSError, ValueError) as exc:
        raise DataFormatError(f"Cannot read {path}: {exc}.") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != NPZ_CHUNKS_FORMAT:
        raise DataFormatError(f"{path} is not a manifest of format {NPZ_CHUNKS_FORMAT!r}.")
    if manifest.get("version") != NPZ_CHUNKS_VERSION:
        raise DataFormatError(
            f"{path} has version {manifest.get('version')!r}; this mmconcepts reads version {NPZ_CHUNKS_VERSION}."
        )
    try:
        n, m = (int(v) for v in manifest["shape"])
        rows = [int(e["rows"]) for e in manifest["chunks"]]
        files = [str(e["file"]) for e in manifest["chunks"]]
        np.dtype(manifest["dtype"])
        bool(manifest["sparse"])
    except (KeyError, TypeError, ValueError) as exc:
        raise DataFormatError(f"{path} lacks or garbles a field (shape, dtype, sparse, chunks): {exc}.") from exc
    if sum(rows) != n or not rows or any(r < 0 for r in rows) or m < 1:
        raise DataFormatError(f"{path}: the chunks' rows {rows} do not add up to the shape {[n, m]}.")
    if any(os.sep in f or f.startswith(".") for f in files):
        raise DataFormatError(f"{path}: chunk files must be plain names inside the folder; got {files}.")
    return manifest


def _load_chunk(path: str, rows: int, n_cols: int, dtype: str, sparse: bool, index: int):
    """One chunk of a folder of .npz chunks, checked against the manifest."""
    try:
        if sparse:
            out = sp.csr_matrix(sp.load_npz(path))
        else:
            loaded = np.load(path, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):
                raise ValueError("it holds a single array (.npy), not an .npz archive")
            with loaded as f:
                out = f["X"]
    # a file cut short or not a zip archive (EOFError, BadZipFile), a .npy where an .npz belongs (TypeError)
    except (OSError, ValueError, KeyError, EOFError, TypeError, zipfile.BadZipFile) as exc:
        raise DataFormatError(
            f"Cannot read chunk {index} ({path}): {type(exc).__name__}: {exc}. The file is damaged or was not "
            "written by save_npz_chunks; write the folder again."
        ) from exc
    if out.shape != (rows, n_cols):
        raise DataFormatError(
            f"chunk {index} ({path}) has shape {out.shape}; the manifest says {(rows, n_cols)}."
        )
    return out.astype(dtype, copy=False)


def load_npz_chunks(folder: str | os.PathLike[str]):
    """A folder of ``.npz`` row chunks (:func:`save_npz_chunks`) as a lazy ``dask.array``.

    Nothing is read until a chunk is computed; each chunk is read from its file alone.

    Parameters
    ----------
    folder : path

    Returns
    -------
    dask.array.Array of shape (n_samples, n_features)
        Row chunks as stored, one column chunk; scipy.sparse CSR chunks when stored sparse.

    Raises
    ------
    DataFormatError
        No manifest, an unknown format or version, or (when read) a chunk file that is damaged or
        disagrees with the manifest; the message names the chunk and its file.
    ImportError
        dask is not installed (the ``dask`` extra).
    """
    _require_dask("load_npz_chunks")
    import dask.array as da
    from dask.highlevelgraph import HighLevelGraph

    folder = Path(folder)
    man = _read_manifest(folder)
    n, m = (int(v) for v in man["shape"])
    rows = tuple(int(e["rows"]) for e in man["chunks"])
    dtype, sparse = str(np.dtype(man["dtype"])), bool(man["sparse"])
    name = "npz-chunks-" + uuid.uuid4().hex
    layer: dict[Any, Any] = {(name, i, 0): (_load_chunk, str(folder / e["file"]), rows[i], m, dtype, sparse, i)
             for i, e in enumerate(man["chunks"])}
    graph = HighLevelGraph.from_collections(name, layer, dependencies=[])
    meta = sp.csr_matrix((0, 0), dtype=dtype) if sparse else np.empty((0, 0), dtype=dtype)
    return da.Array(graph, name, chunks=(rows, (m,)), dtype=dtype, meta=meta)


# ---------------------------------------------------------------------------------------------
# Checks of the dask input


def check_row_chunks(X: Any, name: str) -> None:
    if X.ndim != 2:
        raise DataError(f"{name} must be 2-D (n_samples, n_features); got a dask array of shape {X.shape}.")
    rows, cols = X.chunks
    if any(isinstance(c, float) and math.isnan(c) for c in (*rows, *cols)):
        raise DataError(
            f"{name} has unknown chunk sizes ({name}.chunks holds NaN, e.g. after boolean indexing); the fit needs "
            f"known row chunks. Fix: {name} = {name}.compute_chunk_sizes()."
        )
    if len(cols) != 1:
        raise DataError(
            f"{name} must be chunked along rows only, each chunk holding all {X.shape[1]} columns; got "
            f"{len(cols)} column chunks {tuple(cols)}. Fix: {name} = {name}.rechunk({{1: -1}})."
        )


def _chunk_bounds(X: Any) -> list[tuple[int, int]]:
    out, start = [], 0
    for r in X.chunks[0]:
        out.append((start, start + int(r)))
        start += int(r)
    return out


def _mask_blocks(mask: Any, X: Any, bounds: list[tuple[int, int]], dask) -> list[Any]:
    """One mask piece per row chunk of X: the blocks of a dask mask chunked like X, or slices of an in-memory one."""
    if mask is None:
        return [None] * len(bounds)
    if is_dask_array(mask):
        if mask.ndim != 2 or mask.shape != X.shape:
            raise DataError(f"mask must have the shape of X, {X.shape}; got {mask.shape}.")
        check_row_chunks(mask, "mask")
        if tuple(mask.chunks[0]) != tuple(X.chunks[0]):
            raise DataError(
                f"mask must be chunked like X: expected row chunks {tuple(X.chunks[0])}; got {tuple(mask.chunks[0])}. "
                "Fix: mask = mask.rechunk(X.chunks)."
            )
        return list(mask.to_delayed().ravel())
    mask = check_mask(mask, X.shape)
    token = uuid.uuid4().hex
    return [dask.delayed(mask[a:b], name=f"mask-{token}-{i}", traverse=False) for i, (a, b) in enumerate(bounds)]


# ---------------------------------------------------------------------------------------------
# Work on one chunk (runs on a worker)


@dataclass(frozen=True)
class _ChunkSpec:
    """What a chunk task needs to know besides its data (small, sent with every task)."""

    index: int
    start: int
    stop: int
    columns: np.ndarray | None = None  # columns of the chunk to keep (transform drops dead features)

    def where(self) -> str:
        return f"chunk {self.index} (rows {self.start} to {self.stop - 1})"


def _as_matrix(x: Any) -> Any:
    if sp.issparse(x):
        return x
    if hasattr(x, "tocsr") and not isinstance(x, np.ndarray):  # pydata/sparse and friends
        return sp.csr_matrix(x.tocsr())
    return x


def _prepare(x: Any, m: Any, spec: _ChunkSpec, beta: float, scale: float = 1.0):
    """The chunk as the in-memory fit sees its rows: :func:`validate_data`, then X / scale.

    Returns ``(Xv, Mv)``, or ``None`` for a chunk with no rows. Errors name the chunk.
    """
    x = _as_matrix(x)
    if spec.columns is not None:
        x = x[:, spec.columns]
        if m is not None:
            m = _as_matrix(m)[:, spec.columns]
    if x.shape[0] == 0:
        return None
    try:
        if m is not None and not _observes_any(m):  # valid, but validate_data refuses a mask that observes nothing
            mv = sp.csr_matrix(m.shape, dtype=bool) if sp.issparse(m) else np.zeros(np.shape(m), dtype=bool)
            if mv.shape != x.shape:
                raise DataError(f"mask must have the shape of X, {x.shape}; got {mv.shape}.")
            dtype = x.dtype if x.dtype in (np.float32, np.float64) else np.float64
            Xv = sp.csr_matrix(x.shape, dtype=dtype) if sp.issparse(x) else np.zeros(x.shape, dtype=dtype)
            return Xv, mv
        Xv, Mv = validate_data(x, m)
        check_beta_zeros(Xv, beta, Mv)
    except DataError as exc:
        raise DataError(f"{spec.where()} of X: {exc}") from exc
    if scale != 1.0:
        Xv = Xv / scale if sp.issparse(Xv) else np.divide(Xv, Xv.dtype.type(scale))
    return Xv, Mv


def _observes_any(m: Any) -> bool:
    if sp.issparse(m):
        return bool(sp.csr_matrix(m).count_nonzero())
    return bool(np.any(np.asarray(m)))


@dataclass
class _Stats:
    """One pass of checks and sums over the chunks (before any fitting)."""

    rows: int = 0
    cols: int | None = None
    dtype: str | None = None
    xmax: float = -np.inf
    total: float = 0.0
    observed: float = 0.0
    errors: list = field(default_factory=list)
    sparse: bool | None = None  # every chunk holding rows is sparse once validated (None: no such chunk)


def _chunk_stats(x: Any, m: Any, spec: _ChunkSpec, beta: float) -> _Stats:
    prep = _prepare(x, m, spec, beta)
    if prep is None:
        return _Stats(rows=0, cols=int(x.shape[1]) if spec.columns is None else len(spec.columns))
    Xv, Mv = prep
    values = Xv.data if sp.issparse(Xv) else Xv
    if Mv is None:
        observed = float(Xv.shape[0]) * float(Xv.shape[1])
    else:
        observed = float(Mv.count_nonzero()) if sp.issparse(Mv) else float(np.count_nonzero(Mv))
    return _Stats(rows=Xv.shape[0], cols=Xv.shape[1], dtype=str(Xv.dtype),
                  xmax=float(values.max()) if values.size else -np.inf,
                  total=float(Xv.sum(dtype=np.float64)), observed=observed, sparse=sp.issparse(Xv))


def _merge_stats(parts: Sequence[_Stats]) -> _Stats:
    out = _Stats()
    dtypes = {p.dtype for p in parts if p.dtype is not None}
    if len(dtypes) > 1:
        raise DataError(f"the chunks of X hold different dtypes {sorted(dtypes)}; give one (X.astype(...)).")
    out.dtype = dtypes.pop() if dtypes else "float64"
    for p in parts:
        out.rows += p.rows
        out.cols = p.cols if out.cols is None else out.cols
        out.xmax = max(out.xmax, p.xmax)
        out.total += p.total
        out.observed += p.observed
        if p.sparse is not None:
            out.sparse = p.sparse if out.sparse is None else out.sparse and p.sparse
    return out


class _Row:
    """A denominator whose rows are all equal (the I-divergence without a mask): only the k-vector travels."""

    def __init__(self, v: np.ndarray):
        self.v = v


class _Gram:
    """The Frobenius denominator without a mask, Ht @ (W^T W): only the k x k Gram matrix travels."""

    def __init__(self, G: np.ndarray):
        self.G = G


@dataclass
class _Partial:
    """A chunk's contribution to the dictionary update and to the objective (summed in a tree)."""

    num: np.ndarray | None = None
    den: Any = None  # ndarray, _Row, _Gram or None
    div: float = 0.0
    pen: float = 0.0
    finite: bool = True
    update_bytes: int = 0  # the size of one chunk's (N_c, D_c), for the traffic model

    def nbytes(self) -> int:
        den = self.den.v if isinstance(self.den, _Row) else self.den.G if isinstance(self.den, _Gram) else self.den
        return sum(int(a.nbytes) for a in (self.num, den) if a is not None)


def _add(a: Any, b: Any) -> Any:
    if a is None:
        return b
    if b is None:
        return a
    if isinstance(a, _Row):
        return _Row(a.v + cast(_Row, b).v)
    if isinstance(a, _Gram):
        return _Gram(a.G + cast(_Gram, b).G)
    return a + b


def _add_into(a: Any, b: Any) -> Any:
    """a + b, in place in ``a`` when it is an array this sum owns."""
    if a is None or b is None or not isinstance(a, np.ndarray):
        return _add(a, b)
    a += b
    return a


def _sum_partials(*parts: _Partial) -> _Partial:
    out = _Partial()
    for i, p in enumerate(parts):
        if i == 0:  # the first is copied, the others added into the copy (never into a task's result)
            out.num = None if p.num is None else np.array(p.num, copy=True)
            out.den = np.array(p.den, copy=True) if isinstance(p.den, np.ndarray) else p.den
        else:
            out.num = _add_into(out.num, p.num)
            out.den = _add_into(out.den, p.den)
        out.div += p.div
        out.pen += p.pen
        out.finite = out.finite and p.finite
    return out


def _h_partial(side: Side, Ht: np.ndarray, W: np.ndarray, beta: float):
    """(N_c, D_c) of the dictionary update from one chunk: the in-memory side-1 formulas on its rows."""
    if side.mask is None and beta == 2.0:
        X = side.X
        num = np.asarray(X @ W) if side.sparse else X.T @ W  # sparse: X is the chunk's X.T in CSR
        return num, _Gram(W.T @ W)
    num, den = side.numerator_denominator(Ht, W, beta)
    if not side.sparse:  # a task's result: the dense I-divergence numerator is the side's reused buffer
        num = np.array(num)
    if den.ndim == 2 and den.shape[0] > 1 and den.strides[0] == 0:  # np.broadcast_to of one row
        return num, _Row(np.array(den[0]))
    return num, np.array(den)


def _full_den(den: Any, Ht: np.ndarray) -> np.ndarray:
    if isinstance(den, _Row):
        return np.broadcast_to(den.v, Ht.shape)
    if isinstance(den, _Gram):
        return Ht @ den.G
    return den


class _Summed:
    """Stands for a :class:`Side` whose numerator and denominator were summed over chunks."""

    def __init__(self, num: np.ndarray, den: np.ndarray):
        self.num, self.den = num, den

    def numerator_denominator(self, L, R, beta, fixed=False):
        return self.num, self.den


@dataclass(frozen=True)
class _Rule:
    """The update settings sent to the chunk tasks."""

    beta: float
    gamma: float
    pen_W: Penalty
    scale: float
    k: int
    dtype: str
    flush_H: float | None = None  # the H update's flush (see mu_update): the in-memory update's for the same X


def _load_w(w: Any) -> np.ndarray:
    if isinstance(w, str):
        return np.load(w, allow_pickle=False)
    return np.array(w, copy=True)  # never update a persisted chunk in place


def _store_w(W: np.ndarray, out: str | None) -> Any:
    if out is None:
        return W
    with atomic_path(out, suffix=".tmp.npy") as tmp:
        np.save(tmp, W)
    return out


def _empty_w(rule: _Rule) -> np.ndarray:
    return np.zeros((0, rule.k), dtype=rule.dtype)


def _make_problem(x: Any, m: Any, spec: _ChunkSpec, beta: float, scale: float) -> Problem | None:
    """The chunk's :class:`Problem` (its rows of X / scale, and their transpose for a sparse X); None if empty."""
    prep = _prepare(x, m, spec, beta, scale)
    return None if prep is None else Problem(*prep)


def _fit_chunk(problem: Problem | None, w, Ht, rule: _Rule, spec: _ChunkSpec, evaluate: bool, update: bool,
               w_out: str | None, own_w: bool = False):
    """One pass over one chunk: [objective of (W_c, H)], [W_c update, (N_c, D_c) with the new W_c].

    The update goes into a copy of W_c unless the caller ``own_w`` (an array nothing else reads).
    """
    W = w if own_w and isinstance(w, np.ndarray) else _load_w(w)
    part = _Partial()
    if problem is None:
        return (_store_w(_empty_w(rule), w_out) if update else w), part
    # the sparse I-divergence's update forms every product the objective needs: read from it (W unpenalised)
    fused = evaluate and update and sparse_kl_applies(problem.sides[0], rule.beta, rule.gamma, rule.pen_W)
    if evaluate:
        part.pen = rule.pen_W.value(W)
        part.finite = bool(np.isfinite(W).all())
        if not fused:
            part.div = problem.divergence(W, Ht, rule.beta)
    if not update:
        return w, part
    if fused:
        W = np.ascontiguousarray(W)
        part.div = sparse_kl_update(problem.sides[0], W, Ht, divergence=True)[0]
    else:
        W = mu_update(problem.sides[0], np.ascontiguousarray(W), Ht, rule.beta, rule.gamma, rule.pen_W)
    part.num, part.den = _h_partial(problem.sides[1], Ht, W, rule.beta)
    return _store_w(W, w_out), part


def _transform_chunk(problem: Problem | None, w, Ht, rule: _Rule, spec: _ChunkSpec, first: bool, n_steps: int,
                     w_out: str | None):
    """``n_steps`` W updates with H fixed, then the objective; with ``first``, the objective before them too."""
    W = np.ascontiguousarray(_load_w(w))
    part0, part = _Partial(), _Partial()
    if problem is None:
        return _store_w(_empty_w(rule), w_out), part0, part
    if first:
        part0.div, part0.pen = problem.divergence(W, Ht, rule.beta), rule.pen_W.value(W)
    for _ in range(n_steps):
        W = mu_update(problem.sides[0], W, Ht, rule.beta, rule.gamma, rule.pen_W)
    part.div, part.pen = problem.divergence(W, Ht, rule.beta), rule.pen_W.value(W)
    part.finite = bool(np.isfinite(W).all())
    return _store_w(W, w_out), part0, part


def _prepare_w(w: Any, spec: _ChunkSpec, k: int, dtype: str, divide: float, w_out: str | None):
    """A given starting W chunk: checked as in memory (check_factor), in X's dtype, divided by the W scale."""
    try:
        A = check_nonnegative_matrix(w, "W", accept_sparse=False)
    except DataError as exc:
        raise DataError(f"{spec.where()} of W: {exc}") from exc
    if A.shape != (spec.stop - spec.start, k):
        raise DataError(f"{spec.where()} of W must have shape {(spec.stop - spec.start, k)}; got {A.shape}.")
    A = np.array(A, dtype=dtype, copy=True)
    if divide != 1.0:
        A /= A.dtype.type(divide)
    return _store_w(A, w_out)


def _same(x: Any) -> Any:
    return x


def _scaled(w: Any, factor: float, dtype: str) -> np.ndarray:
    W = np.load(w, allow_pickle=False) if isinstance(w, str) else w
    return W * np.dtype(dtype).type(factor) if factor != 1.0 else W


def _tree(parts: list, dask, split_every: int):
    """Sum :class:`_Partial` objects in a tree of fan-in ``split_every``."""
    level = 0
    while len(parts) > 1:
        parts = [dask.delayed(_sum_partials, pure=True)(*parts[i:i + split_every],
                                                       dask_key_name=f"sum-{uuid.uuid4().hex}-{level}-{i}")
                 for i in range(0, len(parts), split_every)]
        level += 1
    return parts[0]


# ---------------------------------------------------------------------------------------------
# Which worker holds which chunk (a distributed cluster)


def _chunk_workers(specs: Sequence[_ChunkSpec], n: int) -> list[str] | None:
    """The worker each chunk's rows stay on, on the distributed cluster dask computes with; None on another scheduler.

    Contiguous rows per worker (each chunk goes by the middle of its rows): balanced by rows, and
    the chunks summed together first in the tree are mostly on one worker.
    """
    import dask

    client = _distributed_client(dask)
    if client is None:
        return None
    workers = sorted(client.nthreads())
    if not workers:
        return None
    return [workers[min(len(workers) - 1, (s.start + s.stop) * len(workers) // (2 * max(n, 1)))] for s in specs]


def _persist_placed(dask, refs: Sequence[Any], workers: list[str] | None) -> list[Any]:
    """``dask.persist`` of one delayed value per chunk, each computed and kept on its chunk's worker.

    The restriction is loose: if that worker leaves, the scheduler runs the task elsewhere.
    """
    refs = list(refs)
    if workers is None:
        return list(dask.persist(*refs))
    with _placed(dask, {r.key: w for r, w in zip(refs, workers)}, workers):
        return list(dask.persist(*refs))


def _placed(dask, where: dict, workers: list[str] | None):
    """The annotation that sends the tasks of ``where`` (key: worker) to their worker, the others anywhere."""
    if workers is None:
        return contextlib.nullcontext()
    anywhere = sorted(set(workers))
    return dask.annotate(workers=lambda key: [where[key]] if key in where else anywhere, allow_other_workers=True)


# ---------------------------------------------------------------------------------------------
# Where the W chunks live between passes


class _WStore:
    """W chunks between passes: persisted in the cluster's memory (``folder=None``) or ``.npy`` files."""

    def __init__(self, dask, n_chunks: int, folder: Path | None, in_flight: int = 2,
                 workers: list[str] | None = None):
        self.dask = dask
        self.n_chunks = n_chunks
        self.folder = folder
        self.in_flight = max(1, int(in_flight))
        self.buffer = 0
        self.workers = workers  # the worker of each chunk (in memory, on a distributed cluster)

    def path(self, c: int, buffer: int | None = None) -> str | None:
        if self.folder is None:
            return None
        return str(self.folder / f"w{self.buffer if buffer is None else buffer}-{c:06d}.npy")

    def next_path(self, c: int) -> str | None:
        return self.path(c, 1 - self.buffer)

    def flip(self) -> None:
        self.buffer = 1 - self.buffer

    def put(self, chunks: Iterable[Any]) -> list[Any]:
        """Refs to starting chunks given as numpy arrays or delayed values (computed one at a time on disk)."""
        token = uuid.uuid4().hex
        refs = []
        for c, W in enumerate(chunks):
            if self.folder is None:
                refs.append(W if hasattr(W, "dask") else self.dask.delayed(W, name=f"W0-{token}-{c}", traverse=False))
            else:
                if hasattr(W, "dask"):
                    W = W.compute()
                refs.append(_store_w(np.asarray(W), self.path(c)))
        if self.folder is None:
            refs = _persist_placed(self.dask, refs, self.workers)
        return refs


# ---------------------------------------------------------------------------------------------
# The solver


def beta_nmf_dask(
    X: Any,
    n_components: int | None = None,
    *,
    beta: float,
    solver: str = "mu",
    update_rule: str = "mm",
    init: str | None = None,
    W: Any = None,
    H: Any = None,
    update_H: bool = True,
    mask: Any = None,
    max_iter: int = 200,
    tol: float = 1e-4,
    alpha_W: float = 0.0,
    alpha_H: float | str = "same",
    l1_ratio: float = 0.0,
    sparseness_W: float | None = None,
    sparseness_H: float | None = None,
    loss_every: int = 10,
    random_state: Any = None,
    columns: np.ndarray | None = None,
    w_folder: str | os.PathLike[str] | None = None,
    split_every: int = 8,
    in_flight: int = 2,
) -> NMFResult:
    """:func:`~mmconcepts.nmf.beta_nmf` of a dask array X of row chunks (parameters checked by the caller).

    Same parameters and results as ``beta_nmf`` (same iterates up to the order of the sums),
    except that ``W`` comes back as a dask array with X's row chunks, and that the solver is
    the multiplicative update only (``solver='pg'`` and the Hoyer constraints need the whole
    W at every line-search step: refused). ``columns`` keeps only those columns of each chunk
    (:meth:`NMF.transform`); ``w_folder`` keeps W as ``.npy`` files in that folder between passes
    instead of in the cluster's memory, and reads X anew in every pass (out of core), ``in_flight``
    chunks at a time; ``split_every`` is the fan-in of the tree that sums the chunks' statistics.

    Without ``w_folder``, each chunk's prepared rows (and their CSR transpose when sparse, as the
    in-memory solver keeps) are persisted in the cluster's memory for the whole fit, with W, and
    the iterations between two evaluations of the objective run as one graph, H updated on a
    worker (see the module's docstring).
    """
    dask = _require_dask("beta_nmf of a dask array")
    check_row_chunks(X, "X")
    if solver != "mu":
        raise ParameterError(
            f"solver={solver!r} is not available for a dask array: its line search needs the whole of W at every "
            "trial step. Use solver='mu' (multiplicative updates), or compute X into memory."
        )
    if sparseness_W is not None or sparseness_H is not None:
        raise ParameterError(
            "sparseness_W/sparseness_H are not available for a dask array (Hoyer's projection is a gradient step "
            "with a line search over the whole of W). Use alpha_W/alpha_H (L1 penalties) or compute X into memory."
        )
    if mask is not None and not is_dask_array(mask) and not (sp.issparse(mask) or hasattr(mask, "__array__")):
        mask = np.asarray(mask)
    bounds = _chunk_bounds(X)
    x_blocks = list(X.to_delayed().ravel())
    m_blocks = _mask_blocks(mask, X, bounds, dask)
    specs = [_ChunkSpec(i, a, b, columns) for i, (a, b) in enumerate(bounds)]

    stats = _merge_stats(dask.compute(*[dask.delayed(_chunk_stats)(x, mb, s, beta)
                                        for x, mb, s in zip(x_blocks, m_blocks, specs)]))
    n, m = stats.rows, int(stats.cols if stats.cols is not None else X.shape[1])
    if n == 0:
        raise DataError(f"X is empty: 0 sample(s) (shape={(n, m)}) while a minimum of 1 is required.")
    if mask is not None and stats.observed == 0:
        raise DataError("mask observes no cell of X; at least one cell must be True.")
    dtype = np.dtype(stats.dtype)
    if n_components is None:
        n_components = H.shape[0] if H is not None else (W.shape[1] if W is not None else min(n, m))
    k = int(n_components)

    # The scales of beta_nmf: X / scale for the updates, scale = scale_W * scale_H.
    scale = data_scale(np.array([[stats.xmax]]), beta) if np.isfinite(stats.xmax) else 1.0
    if not update_H:
        scale_H = 1.0 if H is None else data_scale(np.asarray(H, dtype=float), beta)
    else:
        scale_H = scale
    scale_W = scale / scale_H
    rescaled = scale != 1.0 or scale_H != 1.0
    x_mean = (stats.total / scale) / max(stats.observed, 1.0)

    folder = None
    if w_folder is not None:
        w_folder = Path(w_folder)
        w_folder.parent.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(prefix=f".{w_folder.name}.work-", dir=w_folder.parent))
    try:
        store = _WStore(dask, len(specs), folder, in_flight, None if folder is not None else _chunk_workers(specs, n))
        W_refs, Ht = _start(store, x_blocks, m_blocks, specs, n, m, k, dtype, beta, update_H, init, W, H,
                            scale, scale_W, scale_H, x_mean, random_state, dask)
        pen_W, pen_H = resolve_penalties(alpha_W, alpha_H, l1_ratio, n, m)
        if rescaled:
            pen_W, pen_H = scale_penalties(pen_W, pen_H, scale, scale_W, scale_H, beta)
        gamma = mm_exponent(beta) if update_rule == "mm" else 1.0
        # the in-memory H update of a sparse, unmasked X under the I-divergence is the kernel's, with its flush
        kernel_h = (beta == 1.0 and gamma == 1.0 and mask is None and not (pen_H.l1 or pen_H.l2)
                    and bool(stats.sparse))
        rule = _Rule(beta, gamma, pen_W, scale, k, str(dtype), _kernels.flush_below(dtype) if kernel_h else None)
        # Each chunk's Problem (its validated rows of X / scale, and their CSR transpose for sparse data) is
        # built once and kept in the cluster's memory; out of core, it is rebuilt from the file in every pass.
        sources = [dask.delayed(_make_problem)(x, mb, s, beta, scale) for x, mb, s in zip(x_blocks, m_blocks, specs)]
        if folder is None:
            sources = _persist_placed(dask, sources, store.workers)
        loop = _fit_loop if update_H else _transform_loop
        W_refs, Ht, n_iter, hist, its, converged, final = loop(
            store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every, split_every, dask,
            scale if rescaled else None)
        del sources
        if not (final.finite and np.isfinite(Ht).all()):
            raise DataError(f"the fit left the range of {dtype}: its factors are not finite (X spans more than the "
                            "range of its dtype, e.g. subnormal values beside ordinary ones with beta_loss <= 1). "
                            "Set such values to 0, or use beta_loss > 1.")
        divergence = float(in_units_of_X(final.div, scale, beta)) if rescaled else float(final.div)
        if rescaled:
            hist = in_units_of_X(hist, scale, beta)
            Ht = Ht * dtype.type(scale_H)
        W_out = _finish_w(store, W_refs, specs, k, dtype, scale_W, w_folder, dask)
    finally:
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
    if tol > 0 and not converged and max_iter > 0:
        warnings.warn(stopped_message(max_iter, tol, hist[-1]), ConvergenceWarning, stacklevel=3)
    extra = {"divergence": divergence, "n_chunks": len(specs), "bytes_per_iteration": _traffic_bytes(final, Ht, specs)}
    return NMFResult(W_out, np.ascontiguousarray(Ht.T), n_iter, np.asarray(hist), np.asarray(its, dtype=int),
                     converged, extra)


def solve_coefficients_dask(X: Any, W: Any, H: np.ndarray, beta: float, *, mask: Any = None,
                            penalty: Penalty | None = None, columns: np.ndarray | None = None) -> Any:
    """:func:`~mmconcepts.nmf._coefficients.solve_coefficients` of a dask array X, chunk by chunk (lazy).

    Given the dictionary, the rows are independent problems: each row chunk of W (a dask array
    with X's row chunks) is solved against its rows of X where they live, with the in-memory
    steps, and the result is a dask array with X's row chunks. ``columns`` keeps only those
    columns of each chunk (H has only them).
    """
    dask = _require_dask("transform of a dask array")
    import dask.array as da
    from dask.highlevelgraph import HighLevelGraph

    bounds = _chunk_bounds(X)
    m_blocks = _mask_blocks(mask, X, bounds, dask)
    specs = [_ChunkSpec(i, a, b, columns) for i, (a, b) in enumerate(bounds)]
    parts = [dask.delayed(_solve_chunk)(x, mb, w, s, H, beta, penalty)
             for x, mb, w, s in zip(X.to_delayed().ravel(), m_blocks, W.to_delayed().ravel(), specs)]
    name = "nmf-W-solved-" + uuid.uuid4().hex  # built by hand: da.concatenate would drop empty chunks
    layer: dict[Any, Any] = {(name, i, 0): (_same, p.key) for i, p in enumerate(parts)}
    graph = HighLevelGraph.from_collections(name, layer, dependencies=parts)
    return da.Array(graph, name, chunks=(tuple(b - a for a, b in bounds), (H.shape[0],)), dtype=W.dtype,
                    meta=np.empty((0, 0), dtype=W.dtype))


def _solve_chunk(x: Any, m: Any, w: Any, spec: _ChunkSpec, H: np.ndarray, beta: float, penalty: Penalty | None):
    w = np.asarray(w)
    prepared = _prepare(x, m, spec, beta)
    if prepared is None:
        return w
    Xv, Mv = prepared
    return solve_coefficients(Xv, H, w, beta, mask=Mv, penalty=penalty)[0]


def _traffic_bytes(final: _Partial, Ht: np.ndarray, specs: Sequence[_ChunkSpec]) -> int:
    """The model of the traffic of one iteration: H to every chunk, (N_c, D_c) back (before the tree's sums)."""
    return int(len(specs) * (Ht.nbytes + final.update_bytes))


def _start(store: _WStore, x_blocks, m_blocks, specs, n, m, k, dtype, beta, update_H, init, W, H,
           scale, scale_W, scale_H, x_mean, random_state, dask):
    """The starting W chunks (in ``store``) and Ht, as beta_nmf starts on the whole matrix."""

    if not update_H:
        if H is None:
            raise ParameterError("update_H=False needs the fixed dictionary H.")
        Hs = check_factor(H, (k, m), "H", dtype) / dtype.type(scale_H)
        if W is None:
            value = constant_coefficients(np.full((1, 1), x_mean, dtype=dtype), Hs)[0, 0]
            W_refs = store.put(np.full((b.stop - b.start, k), value, dtype=dtype) for b in specs)
        else:
            W_refs = _given_w(store, W, specs, n, k, dtype, scale_W, dask)
        _check_given_start(x_blocks, m_blocks, specs, W_refs, Hs, beta, scale, W is not None, True, dask)
        return W_refs, np.ascontiguousarray(Hs.T)
    if init == "custom" or (init is None and W is not None and H is not None):
        if W is None or H is None:
            raise ParameterError("init='custom' needs both W and H.")
        Hs = check_factor(H, (k, m), "H", dtype)
        Hs /= dtype.type(scale_H)
        W_refs = _given_w(store, W, specs, n, k, dtype, scale_W, dask)
        _check_given_start(x_blocks, m_blocks, specs, W_refs, Hs, beta, scale, True, False, dask)
        return W_refs, np.ascontiguousarray(Hs.T)
    if init is None:
        init = "nndsvda" if k <= min(n, m) else "random"
    rng = check_random_state(random_state)
    if init == "random":  # initialize(): H, then W, from one stream; W drawn chunk by chunk in row order
        s = np.sqrt(max(x_mean, 0.0) / k)
        Hs = np.abs(s * rng.standard_normal((k, m))).astype(dtype, copy=False)
        W_refs = store.put(np.abs(s * rng.standard_normal((b.stop - b.start, k))).astype(dtype, copy=False)
                           for b in specs)
        return W_refs, np.ascontiguousarray(Hs.T)
    return _nndsvd(store, x_blocks, m_blocks, specs, n, m, k, dtype, beta, init, scale, x_mean, rng, dask)


def _unreachable_chunk(x, m, spec: _ChunkSpec, beta: float, scale: float, w, H: np.ndarray,
                       find: bool = True) -> tuple[bool, Unreachable]:
    """Whether the chunk's rows of W hold a nonzero, and (``find``) the cells of X > 0 the start (W, H) leaves
    at zero there (``Unreachable.of``)."""
    W = _load_w(w)
    prep = _prepare(x, m, spec, beta, scale) if find else None
    if prep is None:
        return bool(np.any(W)), Unreachable()
    return bool(np.any(W)), Unreachable.of(prep[0], W, H, row_offset=spec.start)


def _check_given_start(x_blocks, m_blocks, specs, W_refs, Hs: np.ndarray, beta: float, scale: float, w_given: bool,
                       fixed_H: bool, dask) -> None:
    """beta_nmf's check of a given start (``check_given_start``), one pass over the chunks with the W chunks."""
    source = "with update_H=False" if fixed_H else "init='custom'"
    if not fixed_H:
        check_factor_not_zero(Hs, "H", source)
    if not w_given and beta > 1:
        return
    parts = dask.compute(*[dask.delayed(_unreachable_chunk)(x, mb, s, beta, scale, w, Hs, beta <= 1)
                           for x, mb, s, w in zip(x_blocks, m_blocks, specs, W_refs)])
    if w_given and not any(p[0] for p in parts):
        check_factor_not_zero(np.zeros(1), "W", source)
    refuse_unreachable(Unreachable.merge([p[1] for p in parts]), beta, frozen=(True, True), fixed_H=fixed_H)


def _given_w(store: _WStore, W: Any, specs, n: int, k: int, dtype, scale_W: float, dask) -> list:
    if is_dask_array(W):
        if W.shape != (n, k):
            raise DataError(f"W must have shape {(n, k)}; got {W.shape}.")
        W = W.rechunk(([s.stop - s.start for s in specs], (k,)))
        blocks = list(W.to_delayed().ravel())
        if store.folder is None:
            return store.put(dask.delayed(_prepare_w)(b, s, k, str(dtype), scale_W, None)
                             for b, s in zip(blocks, specs))
        dask.compute(*[dask.delayed(_prepare_w)(b, s, k, str(dtype), scale_W, store.path(s.index))
                       for b, s in zip(blocks, specs)])
        return [store.path(s.index) for s in specs]

    Wa = check_factor(W, (n, k), "W", dtype)
    Wa /= dtype.type(scale_W)
    return store.put(Wa[s.start:s.stop] for s in specs)


def _nndsvd(store: _WStore, x_blocks, m_blocks, specs, n, m, k, dtype, beta, init, scale, x_mean, rng, dask):
    """NNDSVD (Boutsidis & Gallopoulos 2008) from dask's randomized SVD (Halko et al. 2011).

    dask.array.linalg.svd_compressed replaces scikit-learn's randomized_svd: the same algorithm
    (10 oversamples, 7 or 4 power iterations as scikit-learn) with its own random draws and QR
    normalisation, so the start approximates the in-memory one without equalling it. U (n x k)
    is kept in the cluster's memory while W is built from it.
    """
    import dask.array as da

    if init not in ("nndsvd", "nndsvda", "nndsvdar"):
        raise ParameterError(f"init must be one of ('random', 'nndsvd', 'nndsvda', 'nndsvdar', 'custom') or None; "
                             f"got {init!r}.")
    if k > min(n, m):
        raise ParameterError(
            f"init={init!r} needs n_components <= min(n_samples, n_features) = {min(n, m)}; got {k}. "
            "Use init='random'."
        )
    seed = int(rng.integers(0, 2**31 - 1))
    fill = x_mean if m_blocks[0] is not None else None
    blocks = []
    for x, mb, s in zip(x_blocks, m_blocks, specs):
        blocks.append(da.from_delayed(dask.delayed(_svd_block)(x, mb, s, beta, scale, fill),
                                      shape=(s.stop - s.start, m), dtype=np.float64))
    A = da.concatenate(blocks, axis=0) if len(blocks) > 1 else blocks[0]
    n_iter = 7 if k < 0.1 * min(n, m) else 4
    U, S, V = da.linalg.svd_compressed(A, k, n_power_iter=n_iter, n_oversamples=10, seed=seed, compute=False)
    U = U.rechunk(([s.stop - s.start for s in specs], (k,))).persist()
    pos, neg = da.maximum(U, 0), da.abs(da.minimum(U, 0))
    S, V, xpn, xnn = dask.compute(S, V, da.sqrt((pos * pos).sum(axis=0)), da.sqrt((neg * neg).sum(axis=0)))
    eps = 1e-6
    Hs = np.zeros((k, m))
    coef = np.zeros(k)  # W[:, j] = coef[j] * max(sign[j] * U[:, j], 0)
    sign = np.zeros(k)
    Hs[0] = np.sqrt(S[0]) * np.abs(V[0])
    coef[0], sign[0] = np.sqrt(S[0]), 0.0  # column 0: sqrt(S0) |U0|
    for j in range(1, k):
        y = V[j]
        yp, yn = np.maximum(y, 0), np.abs(np.minimum(y, 0))
        ypn, ynn = np.linalg.norm(yp), np.linalg.norm(yn)
        mp, mn = xpn[j] * ypn, xnn[j] * ynn
        if mp > mn:
            lbd = np.sqrt(S[j] * mp)
            coef[j], sign[j], Hs[j] = lbd / xpn[j], 1.0, lbd * yp / ypn
        elif mn > 0:
            lbd = np.sqrt(S[j] * mn)
            coef[j], sign[j], Hs[j] = lbd / xnn[j], -1.0, lbd * yn / ynn
        else:
            coef[j], sign[j] = 0.0, 1.0
    Hs[Hs < eps] = 0

    unreached = []  # nndsvd: the cells of X > 0 its zeros leave out of W @ H, chunk by chunk (see initialize)

    def chunks() -> Iterator[np.ndarray]:
        for c in range(len(specs)):  # in row order: nndsvdar's draws are those of one W in memory
            Uc = np.asarray(U.blocks[c].compute())
            Wc = np.where(sign == 0, np.abs(Uc), np.maximum(sign * Uc, 0)) * coef
            Wc[Wc < eps] = 0
            if init == "nndsvd":
                found = dask.compute(dask.delayed(_unreachable_chunk)(x_blocks[c], m_blocks[c], specs[c], beta,
                                                                      scale, Wc, Hs))[0][1]
                unreached.append(found)
                rows = found.rows - specs[c].start
                Wc[rows] = np.where(Wc[rows] == 0, x_mean, Wc[rows])
            elif init == "nndsvda":
                Wc[Wc == 0] = x_mean
            elif init == "nndsvdar":
                Wc[Wc == 0] = np.abs(x_mean * rng.standard_normal(int((Wc == 0).sum())) / 100)
            yield Wc.astype(dtype, copy=False)

    W_refs = store.put(chunks())
    if init == "nndsvd":
        cols = Unreachable.merge(unreached).cols
        Hs[:, cols] = np.where(Hs[:, cols] == 0, x_mean, Hs[:, cols])
    elif init == "nndsvda":
        Hs[Hs == 0] = x_mean
    elif init == "nndsvdar":
        Hs[Hs == 0] = np.abs(x_mean * rng.standard_normal(int((Hs == 0).sum())) / 100)
    return W_refs, np.ascontiguousarray(Hs.astype(dtype, copy=False).T)


def _svd_block(x, m, spec: _ChunkSpec, beta: float, scale: float, fill: float | None):
    """A chunk as the SVD of the in-memory init sees it: X / scale, unobserved cells set to ``fill``."""
    prep = _prepare(x, m, spec, beta, scale)
    if prep is None:
        return np.zeros((0, np.shape(x)[1] if spec.columns is None else len(spec.columns)))
    Xv, Mv = prep
    if Mv is None:
        return Xv.astype(np.float64)
    dense_m = Mv.toarray() if sp.issparse(Mv) else Mv
    return np.asarray(np.where(dense_m, Xv.toarray() if sp.issparse(Xv) else Xv, fill), dtype=np.float64)


def _run_pass(store: _WStore, tasks: list, n_parts: int, update: bool, split_every: int, dask):
    """Run one delayed task per chunk, each returning ``(W ref, part_1, ..., part_n)``; sum each part over chunks.

    In memory, one graph: the new W chunks are persisted where they were computed, the sums
    come back to the client. On disk (``store.folder``), the chunks go in waves of
    ``store.in_flight``, each wave's parts summed before the next starts, so that at most that many
    chunks and (n_features x k) parts are in memory at once whatever the scheduler's order; the
    new W chunks are the files of the other buffer.
    """
    if store.folder is None:
        totals = [_tree([t[1 + j] for t in tasks], dask, split_every) for j in range(n_parts)]
        if update:
            *new, totals_p = dask.persist(*[t[0] for t in tasks], totals)
            return new, list(dask.compute(*totals_p))
        return None, list(dask.compute(*totals))
    sums: list = [None] * n_parts
    for a in range(0, len(tasks), store.in_flight):
        wave = tasks[a:a + store.in_flight]
        parts = dask.compute(*[_tree([t[1 + j] for t in wave], dask, split_every) for j in range(n_parts)])
        sums = [p if s is None else _sum_partials(s, p) for s, p in zip(sums, parts)]
    if not update:
        return None, sums
    new = [store.next_path(c) for c in range(len(tasks))]
    store.flip()
    return new, sums


def _objective_pass(store, sources, specs, W_refs, Ht, rule, evaluate, update, split_every, dask):
    """One pass of :func:`_fit_chunk` over the chunks: new W refs (the old ones without ``update``) and the sum."""
    Ht_d = dask.delayed(Ht, name=f"Ht-{uuid.uuid4().hex}", traverse=False)
    tasks = [dask.delayed(_fit_chunk, nout=2)(src, w, Ht_d, rule, s, evaluate, update,
                                              store.next_path(s.index) if update else None)
             for src, w, s in zip(sources, W_refs, specs)]
    new, (total,) = _run_pass(store, tasks, 1, update, split_every, dask)
    return (new if update else W_refs), total, int(update)


def _objective(part: _Partial, Ht: np.ndarray, pen_H: Penalty) -> float:
    return part.div + part.pen + pen_H.value(Ht)


class _Stopping:
    """scikit-learn's rule on sqrt(2 * objective), as in :func:`mmconcepts.nmf._solver._iterate`."""

    def __init__(self, f0: float, tol: float):
        self.err0 = np.sqrt(2.0 * max(f0, 0.0))
        self.prev = self.err0
        self.tol = tol

    def converged(self, f: float) -> bool:
        err = np.sqrt(2.0 * max(f, 0.0))
        if not np.isfinite(self.err0):
            self.err0 = err
        elif (self.tol > 0 and self.err0 > 0 and np.isfinite(self.prev) and np.isfinite(err)
              and (self.prev - err) / self.err0 < self.tol):
            return True
        self.prev = err
        return False


def _fit_loop(store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every, split_every,
              dask, check_scale):
    """W and H updates: in batches of iterations in the cluster's memory, pass by pass on disk; on a ``distributed``
    cluster of at most ``split_every`` workers, one task per worker and batch (:func:`_fit_loop_exchange`)."""
    client = _distributed_client(dask) if store.folder is None and store.workers else None
    if client is not None and _exchange_setting(dask) == "workers":
        graph = _IterationGraph("layout", [None] * len(specs), specs, rule, pen_H, split_every, store.workers)
        if len(graph.hosts) <= split_every:
            return _fit_loop_exchange(client, graph, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol,
                                      loss_every, dask, check_scale)
    loop = _fit_loop_in_memory if store.folder is None else _fit_loop_on_disk
    return loop(store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every, split_every, dask,
                check_scale)


#: The dask configuration key that chooses how the workers of a distributed fit share their sums.
EXCHANGE_CONFIG = "mmconcepts.nmf.exchange"


def _exchange_setting(dask) -> str:
    """``dask.config`` ``mmconcepts.nmf.exchange``: ``"workers"`` (the default: on a ``distributed`` cluster of
    at most ``split_every`` workers, they send each other their sums, :func:`_fit_loop_exchange`) or
    ``"scheduler"`` (always the scheduler's graph, :class:`_IterationGraph`, whose tasks are computed again on
    another worker if theirs is lost)."""
    value = dask.config.get(EXCHANGE_CONFIG, "workers")
    if value not in ("workers", "scheduler"):
        raise ParameterError(f"dask.config {EXCHANGE_CONFIG!r} must be 'workers' or 'scheduler'; got {value!r}. "
                             f"Fix: dask.config.set({{{EXCHANGE_CONFIG!r}: 'scheduler'}}), or leave it unset.")
    return value


def _checks(max_iter: int, loss_every: int) -> list[int]:
    """The iterations whose objective the stopping rule reads (as :func:`mmconcepts.nmf._solver._iterate`)."""
    return sorted({0, *range(loss_every, max_iter + 1, loss_every), max_iter})


def _record_check(i: int, f: float, hist: list, its: list, stop: _Stopping | None, tol: float, rule: _Rule,
                  check_scale: float | None) -> tuple[_Stopping, bool]:
    """Append the objective of iteration i; returns the stopping rule (made at i = 0) and whether it stops at i."""
    hist.append(f)
    its.append(i)
    if i == 0:
        if check_scale is not None:
            check_objective_range(f, check_scale, rule.beta)
        return _Stopping(f, tol), False
    stop = cast(_Stopping, stop)
    return stop, stop.converged(f)


def _h_step(total: _Partial, Ht: np.ndarray, rule: _Rule, pen_H: Penalty, own: bool = False) -> np.ndarray:
    """The dictionary update from the chunks' summed numerator and denominator: the in-memory side-1 update.

    mu_update divides the numerator in place: a copy of it unless the caller ``own``s ``total``
    (never a task's input).
    """
    num = cast(np.ndarray, total.num if own else np.array(total.num, copy=True))
    summed = cast(Side, _Summed(num, _full_den(total.den, Ht)))
    return mu_update(summed, Ht.copy(), cast(np.ndarray, None), rule.beta, rule.gamma, pen_H,  # no W: summed
                     flush=rule.flush_H)


def _check_part(total: _Partial, Ht: np.ndarray, pen_H: Penalty) -> tuple[float, _Partial]:
    """The objective of a pass's (W, H) and its summary without the sums (what the client reads of a check)."""
    return _objective(total, Ht, pen_H), _Partial(div=total.div, pen=total.pen, finite=total.finite,
                                                  update_bytes=total.nbytes())


def _fit_run(sources: list, prev: Any, Ht: np.ndarray, rule: _Rule, specs: list, evaluate: bool, update: bool,
             summed: bool, own: bool = False) -> tuple[list, list[_Partial]]:
    """:func:`_fit_chunk` on consecutive chunks kept on one worker: ``(their W refs, their parts)``.

    ``prev`` is the chunks' W (a list) or the run's previous output, whose W the run updates in
    place if it ``own``s them (no other task reads them); with ``summed``, the run holds a whole
    group of the tree's first level and returns that group's sum (one part).
    """
    Ws = prev[0] if isinstance(prev, tuple) else prev
    out, parts = [], []
    for src, w, spec in zip(sources, Ws, specs):
        w_new, part = _fit_chunk(src, w, Ht, rule, spec, evaluate, update, None, own_w=own)
        out.append(w_new)
        parts.append(part)
    return out, [_sum_partials(*parts)] if summed else parts


def _sum_nodes(*nodes: Any) -> _Partial:
    """The sum, in order, of parts, lists of parts and runs' outputs (:func:`_fit_run`)."""
    parts: list[_Partial] = []
    for node in nodes:
        node = node[1] if isinstance(node, tuple) else node
        parts.extend(node if isinstance(node, list) else [node])
    return _sum_partials(*parts)


def _tree_sum(fan: int, *nodes: Any) -> _Partial:
    """The sum of the first level's nodes (each one part, or a run's output holding one) up a tree of fan-in
    ``fan``: the sums the tree's tasks make, in the same order (the same numbers), in one task; a new part."""
    level = [_only_part(n) for n in nodes]
    while len(level) > 1:
        level = [_sum_partials(*level[a:a + fan]) for a in range(0, len(level), fan)]
    return level[0] if len(nodes) > 1 else _sum_partials(level[0])  # a copy of a lone node


def _only_part(node: Any) -> _Partial:
    node = node[1] if isinstance(node, tuple) else node
    if isinstance(node, list):
        (node,) = node
    return node


def _tree_h_step(fan: int, Ht: np.ndarray, rule: _Rule, pen_H: Penalty, *nodes: Any) -> np.ndarray:
    """:func:`_h_step` of :func:`_tree_sum`: a worker's own copy of the next H, from every worker's sums."""
    return _h_step(_tree_sum(fan, *nodes), Ht, rule, pen_H, own=True)


def _first_part(run: tuple[list, list[_Partial]]) -> _Partial:
    return run[1][0]


def _run_parts(run: tuple[list, list[_Partial]]) -> list[_Partial]:
    return run[1]


def _run_w(run: tuple[list, list[_Partial]], i: int) -> Any:
    return run[0][i]


class _IterationGraph:
    """The tasks of one iteration over the chunks, laid out once per fit and named anew for each iteration.

    The chunks go in *runs*: consecutive chunks on one worker within one group of the first level
    of the tree that sums the parts (fan-in ``split_every``, in chunk order: the sums, and the
    iterates, do not depend on which worker runs which chunk); without ``workers`` (the worker of
    each chunk, on a distributed cluster), each chunk is a run. Iteration t reads W^t (the chunks'
    keys, or the runs' outputs of iteration t - 1) and H^t, and defines ``run-t-r``
    (:func:`_fit_run`: W and part of each chunk of run r), the sums up the tree (``sum{d}-t-g``;
    a run that holds a whole group stands for its sum), ``H-{t+1}`` (:func:`_h_step` on the root)
    and, when evaluating, ``check-t`` (:func:`_check_part`); ``w-{t+1}-c`` (chunk c's new W) only
    when asked, at the end of a batch. Several iterations chained this way make one graph: the
    client sees only the checks, and the scheduler handles a few tasks per worker and iteration.

    With ``workers``, :meth:`where` also places the tasks: each run on its worker, each sum on the
    worker of its first chunk (the root, the H update and the check on the first chunk's), a part
    read by a sum on another worker taken out of its run first (``part-t-r``, so W stays); and H
    goes down a tree of fan-out ``split_every`` to the other workers (``Hto-t-j``, an identity
    task on the j-th worker, in the order of their first chunk, reading the copy of worker
    (j - 1) // split_every), instead of every worker fetching it from the one that computed it.

    With no more workers than ``split_every`` (``replicated``), the levels above the first are one
    task per worker instead (:func:`_tree_h_step`, ``H-{t+1}`` on the first worker, ``Hto-{t+1}-j``
    on the j-th): it reads the first level's nodes (another worker's run through its ``part``), sums
    them in the tree's order (:func:`_tree_sum`) and updates that worker's H^t; H is copied to the
    workers only at a batch's first iteration, and a batch's last iteration sums once on the first
    worker (``tree-t``, read by the check and the H update persisted for the next batch).
    """

    def __init__(self, name: str, source_keys: list, specs: Sequence[_ChunkSpec], rule: _Rule, pen_H: Penalty,
                 split_every: int, workers: list[str] | None = None):
        self.name = name
        self.sources = source_keys
        self.specs = list(specs)
        self.rule = rule
        self.pen_H = pen_H
        self.fan = split_every
        n = len(self.specs)
        self.workers = workers
        where: list[str | None] = list(workers) if workers else [None] * n
        self.hosts = list(dict.fromkeys(workers)) if workers else []  # in the order of their first chunk
        self.host_of = [self.hosts.index(w) for w in workers] if workers else [0] * n
        self.group_of = [c // split_every for c in range(n)] if n > 1 else [0]
        runs: list[list[int]] = []
        for c in range(n):
            if workers and runs and where[runs[-1][-1]] == where[c] and self.group_of[runs[-1][-1]] == self.group_of[c]:
                runs[-1].append(c)
            else:
                runs.append([c])
        self.runs = runs
        self.whole = [n > 1 and len(r) == len([c for c in range(n) if self.group_of[c] == self.group_of[r[0]]])
                      for r in runs]  # the run holds its whole first-level group
        self.levels: list[list[list[int]]] = []  # above the first level: the nodes summed together
        width = -(-n // split_every) if n > 1 else 0
        while width > 1:
            self.levels.append([list(range(a, min(a + split_every, width))) for a in range(0, width, split_every)])
            width = len(self.levels[-1])
        # a few workers (no more than the fan-in): each sums the first level's nodes and updates H itself, from the
        # same parts in the same order, instead of waiting for H to come down from the root
        self.replicated = 1 < len(self.hosts) <= split_every

    def key(self, what: str, t: int, c: int | None = None) -> str:
        return f"{self.name}-{what}-{t}" if c is None else f"{self.name}-{what}-{t}-{c}"

    def root(self, t: int) -> str:
        """The key of iteration t's summed part."""
        if len(self.specs) == 1:
            return self.key("part", t, 0)
        if self.replicated:
            return self.key("tree", t)
        return self.key(f"sum{len(self.levels)}", t, 0)

    def h_for(self, t: int, host: int, h_key: Any) -> Any:
        """The key of H^t on the host-th worker (its copy down the broadcast tree; H^t itself on the first)."""
        return h_key if host == 0 else self.key("Hto", t, host)

    def _worker(self, c: int) -> str | None:
        return self.workers[c] if self.workers else None

    def layer(self, t: int, w_in: Sequence[Any] | None, h_key: Any, evaluate: bool, update: bool,
              w_out: bool = False, own: bool = False) -> dict:
        """The tasks of iteration t (see the class); ``w_in``: the chunks' W keys (None: the runs of t - 1, updated
        in place if ``own``: not asked for their ``w`` keys)."""
        key = self.key
        out: dict[Any, Any] = {}
        if not self.replicated or w_in is not None:  # replicated: H^t is already on every worker but in a batch's first
            for j in range(1, len(self.hosts)):
                out[key("Hto", t, j)] = (_same, self.h_for(t, (j - 1) // self.fan, h_key))
        groups: dict[int, list] = {}
        remote: dict[str, str] = {}  # a run's key -> the key of its parts alone (read on another worker)
        held_on: dict[str, str | None] = {}  # the worker of each part or run
        for r, (chunks, whole) in enumerate(zip(self.runs, self.whole)):
            prev = [w_in[c] for c in chunks] if w_in is not None else key("run", t - 1, r)
            run = key("run", t, r)
            out[run] = (_fit_run, [self.sources[c] for c in chunks], prev, self.h_for(t, self.host_of[chunks[0]], h_key),
                        self.rule, [self.specs[c] for c in chunks], evaluate, update, whole, own and w_in is None)
            if update and w_out:
                for i, c in enumerate(chunks):
                    out[key("w", t + 1, c)] = (_run_w, run, i)
            g = self.group_of[chunks[0]]
            reader = (g // self.fan) * self.fan ** 2 if whole and self.levels else g * self.fan  # its sum's first chunk
            if self._worker(chunks[0]) != self._worker(reader):
                out[key("part", t, r)] = (_run_parts, run)  # read on another worker: without the W
                run = key("part", t, r)
            elif self.replicated and whole:  # a node of the first level: read on every worker
                out[key("part", t, r)] = (_run_parts, run)
                remote[run] = key("part", t, r)
            groups.setdefault(g, []).append((run, whole))
            held_on[run] = self._worker(chunks[0])
        if len(self.specs) == 1:
            out[key("part", t, 0)] = (_first_part, key("run", t, 0))
        nodes = []
        for g in sorted(groups):
            members = groups[g]
            if len(members) == 1 and members[0][1]:  # the run is the group's sum
                nodes.append(members[0][0])
            elif len(self.specs) > 1:
                out[key("sum0", t, g)] = (_sum_nodes, *[m for m, _ in members])
                nodes.append(key("sum0", t, g))
                held_on[key("sum0", t, g)] = self._worker(g * self.fan)
        if self.replicated:
            read = [[n if held_on[n] == host else remote.get(n, n) for n in nodes] for host in self.hosts]
            if evaluate:  # the last iteration of a batch: the check reads the sum, the next batch copies H^(t+1)
                out[self.root(t)] = (_tree_sum, self.fan, *read[0])
                if update:
                    out[key("H", t + 1)] = (_h_step, self.root(t), h_key, self.rule, self.pen_H)
            elif update:
                for j in range(len(self.hosts)):
                    h_next = key("H", t + 1) if j == 0 else key("Hto", t + 1, j)
                    out[h_next] = (_tree_h_step, self.fan, self.h_for(t, j, h_key), self.rule, self.pen_H, *read[j])
            if evaluate:
                out[key("check", t)] = (_check_part, self.root(t), h_key, self.pen_H)
            return out
        for d, level in enumerate(self.levels, start=1):
            nodes_next = []
            for g, members in enumerate(level):
                out[key(f"sum{d}", t, g)] = (_sum_nodes, *[nodes[j] for j in members])
                nodes_next.append(key(f"sum{d}", t, g))
            nodes = nodes_next
        if nodes and not self.levels and nodes[0] != key("sum0", t, 0):  # one whole group: its run is the root
            out[key("sum0", t, 0)] = (_sum_nodes, nodes[0])
        root = self.root(t)
        if update:
            out[key("H", t + 1)] = (_h_step, root, h_key, self.rule, self.pen_H)
        if evaluate:
            out[key("check", t)] = (_check_part, root, h_key, self.pen_H)
        return out

    def where(self, t: int, evaluate: bool, update: bool) -> dict:
        """The worker of each task of iteration t that has one (empty without ``workers``)."""
        if not self.workers:
            return {}
        key, workers, first = self.key, self.workers, self.workers[0]
        out = {key("run", t, r): workers[chunks[0]] for r, chunks in enumerate(self.runs)}
        out.update({key("part", t, r): workers[chunks[0]] for r, chunks in enumerate(self.runs)})
        out.update({key("Hto", t, j): self.hosts[j] for j in range(1, len(self.hosts))})
        if self.replicated and evaluate:
            out[self.root(t)] = first
        elif self.replicated and update:
            out.update({key("Hto", t + 1, j): self.hosts[j] for j in range(1, len(self.hosts))})
        out.update({key("sum0", t, g): workers[g * self.fan] for g in range(max(self.group_of) + 1)})
        for d, level in enumerate(self.levels, start=1):
            span = self.fan ** (d + 1)  # chunks under one node of level d
            out.update({key(f"sum{d}", t, g): workers[g * span] for g in range(len(level))})
        if update:
            out[key("H", t + 1)] = first
        if evaluate:
            out[key("check", t)] = first
        return out


def _fit_loop_in_memory(store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every, split_every,
                        dask, check_scale):
    """W and H updates in the cluster's memory, one graph per batch of iterations, H updated on a worker.

    A batch runs the iterations after a check up to the next one (the first batch is iteration 0
    alone, whose objective is checked against the data's range before anything else runs): the
    client submits it, keeps W and H of its last iteration (and of the check, when the stopping
    rule may stop there) persisted in the cluster, and reads back the check's objective only. The
    iterates and the objectives are those of the pass-by-pass loop.
    """
    from dask.delayed import Delayed
    from dask.highlevelgraph import HighLevelGraph

    graph = _IterationGraph(f"nmf-{uuid.uuid4().hex}", [s.key for s in sources], specs, rule, pen_H, split_every,
                            store.workers)
    H_ref = dask.delayed(Ht, name=graph.key("H", 0), traverse=False)
    checks = _checks(max_iter, loss_every)
    hist: list[float] = []
    its: list[int] = []
    stop: _Stopping | None = None
    converged = False
    update_bytes = 0
    start = 0
    for q in checks:
        inputs = [*sources, *W_refs, H_ref]
        layer: dict[Any, Any] = {}
        where: dict[Any, str] = {}
        w_in: list | None = [w.key for w in W_refs]
        h_key = H_ref.key
        keep_q = q == max_iter or (tol > 0 and q > 0)  # W^q, H^q: the answer if the rule stops at q
        for t in range(start, q + 1):
            layer.update(graph.layer(t, w_in, h_key, evaluate=t == q, update=t < max_iter,
                                     w_out=t == q or (t == q - 1 and keep_q), own=not (t == q and keep_q)))
            where.update(graph.where(t, evaluate=t == q, update=t < max_iter))
            w_in, h_key = None, graph.key("H", t + 1)
        w_keys = [w.key for w in W_refs] if q == start else [graph.key("w", q, c) for c in range(len(specs))]
        h_key = H_ref.key if q == start else graph.key("H", q)
        name = graph.key("batch", q)
        hlg = HighLevelGraph.from_collections(name, layer, dependencies=inputs)
        keep = [*w_keys, h_key] if keep_q else []
        ahead = [*[graph.key("w", q + 1, c) for c in range(len(specs))], graph.key("H", q + 1)] if q < max_iter else []
        with _placed(dask, where, store.workers):
            persisted = dask.persist(*[Delayed(k, hlg, layer=name) for k in [*keep, *ahead, graph.key("check", q)]])
        del inputs, W_refs, H_ref, hlg, layer
        f, part = dask.compute(persisted[-1])[0]
        stop, converged = _record_check(q, f, hist, its, stop, tol, rule, check_scale)
        update_bytes = part.update_bytes or update_bytes
        if converged or q == max_iter:
            *W_refs, H_ref = persisted[:len(keep)]
            break
        *W_refs, H_ref = persisted[len(keep):-1]
        del persisted
        start = q + 1
    part.update_bytes = update_bytes
    Ht = np.asarray(dask.compute(H_ref)[0])
    return W_refs, Ht, q, hist, its, converged, part


def _fit_loop_on_disk(store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every, split_every,
                      dask, check_scale):
    """W and H updates, one pass per iteration, H updated on the client; the objective of iteration i comes with
    the pass of i + 1."""
    hist: list[float] = []
    its: list[int] = []
    stop: _Stopping | None = None
    converged = False
    i = 0
    update_bytes = 0
    while True:
        check = i == 0 or i % loss_every == 0 or i == max_iter
        if i == max_iter:
            _, part, _ = _objective_pass(store, sources, specs, W_refs, Ht, rule, True, False, split_every, dask)
        else:
            new_refs, part, _ = _objective_pass(store, sources, specs, W_refs, Ht, rule, check, True, split_every,
                                                dask)
        if check:
            stop, converged = _record_check(i, _objective(part, Ht, pen_H), hist, its, stop, tol, rule, check_scale)
            final = part
        if converged or i == max_iter:
            break
        update_bytes = part.nbytes()
        W_refs, Ht = new_refs, _h_step(part, Ht, rule, pen_H, own=True)
        i += 1
    final.update_bytes = update_bytes
    return W_refs, Ht, i, hist, its, converged, final


# ---------------------------------------------------------------------------------------------
# A few workers of a distributed cluster: one task per worker and batch, the sums sent between them


_ABORT = "abort"
_PUT = "mmconcepts_nmf_put"  # the handler the workers of a fit send their parts to
_MAILBOXES: dict[tuple[str, int], _Mailbox] = {}  # (fit token, worker index): that worker's mailbox, in its process
_MAILBOXES_LOCK = threading.Lock()


class _Mailbox:
    """Where the other workers' parts of one fit arrive on one worker.

    The other workers' tasks send them to this worker's ``mmconcepts_nmf_put`` handler (installed by
    :func:`_exchange_plugin`'s plugin; it runs on the worker's event loop and calls :meth:`put`); this worker's task
    reads them with :meth:`take`. One per fit and worker, in :data:`_MAILBOXES`, made by whichever comes
    first (a part may arrive before the task starts) and dropped by the client at the end of the fit.
    """

    def __init__(self) -> None:
        self._box: dict[str, Any] = {}
        self._arrived = threading.Condition()

    @staticmethod
    def of(token: str, host: int) -> _Mailbox:
        with _MAILBOXES_LOCK:
            return _MAILBOXES.setdefault((token, host), _Mailbox())

    def put(self, tag: str, value: Any) -> None:
        with self._arrived:
            self._box[tag] = value
            self._arrived.notify_all()

    def take(self, tag: str, alive: Any, poll: float = 2.0) -> Any:
        """The value put under ``tag``, waiting for it; ``alive()`` is called every ``poll`` seconds of waiting
        (outside the lock: it may wait for this worker's event loop) and raises if waiting is pointless."""
        while True:
            with self._arrived:
                if tag in self._box:
                    return self._box.pop(tag)
                if _ABORT in self._box:
                    host, what = self._box[_ABORT]
                    raise ClusterError(f"the fit stopped: its task on worker {host} failed ({what}).")
                if self._arrived.wait(poll):
                    continue
            alive()


async def _put_handler(token: str, host: int, tag: str, value: Any) -> None:
    """The worker's handler of a part sent by another worker of a fit (see :class:`_Mailbox`)."""
    _Mailbox.of(token, host).put(tag, value)


def _drop_mailboxes(token: str) -> None:
    """Forget this process's mailboxes of a fit (run on the workers at its end)."""
    with _MAILBOXES_LOCK:
        for key in [k for k in _MAILBOXES if k[0] == token]:
            del _MAILBOXES[key]


def _exchange_plugin():
    """A ``distributed`` worker plugin that installs :func:`_put_handler` on every worker (those that join later too),
    as ``distributed``'s own shuffle extension installs its handlers."""
    from distributed import WorkerPlugin

    class _ExchangePlugin(WorkerPlugin):
        name = "mmconcepts-nmf-exchange"

        def setup(self, worker: Any) -> None:
            worker.handlers[_PUT] = _put_handler

    return _ExchangePlugin()


_PLUGGED: weakref.WeakSet = weakref.WeakSet()  # the clients whose clusters have the plugin


def _send(token: str, host: str, j: int, tag: str, value: Any) -> Any:
    """Send ``value`` to the mailbox of the fit on worker ``host`` (the j-th) from a task: a future of the reply."""
    import asyncio

    from distributed import get_worker
    from distributed.protocol import to_serialize

    worker = get_worker()
    call = getattr(worker.rpc(host), _PUT)(token=token, host=j, tag=tag, value=to_serialize(value))
    return asyncio.run_coroutine_threadsafe(call, cast(Any, worker.loop).asyncio_loop)  # tornado on asyncio


@dataclass(frozen=True)
class _Exchange:
    """The layout of a fit whose workers exchange their sums directly (see :func:`_fit_loop_exchange`).

    ``runs``, ``whole`` and the groups are those of :class:`_IterationGraph` (the same sums in the
    same order); ``host_runs[j]``: the runs of the j-th worker (in the order of their first chunk),
    ``groups``: the runs of each group of the tree's first level, in chunk order.
    """

    token: str
    hosts: tuple[str, ...]
    fan: int
    runs: tuple[tuple[int, ...], ...]
    whole: tuple[bool, ...]
    host_runs: tuple[tuple[int, ...], ...]
    groups: tuple[tuple[int, ...], ...]

    @classmethod
    def of(cls, graph: _IterationGraph, token: str) -> _Exchange:
        groups: dict[int, list[int]] = {}
        for r, chunks in enumerate(graph.runs):
            groups.setdefault(graph.group_of[chunks[0]], []).append(r)
        host_runs = tuple(tuple(r for r, chunks in enumerate(graph.runs) if graph.host_of[chunks[0]] == j)
                          for j in range(len(graph.hosts)))
        return cls(token, tuple(graph.hosts), graph.fan, tuple(tuple(r) for r in graph.runs), tuple(graph.whole),
                   host_runs, tuple(tuple(groups[g]) for g in sorted(groups)))

    def total(self, parts: dict[int, list[_Partial]]) -> _Partial:
        """The sum of every run's parts, in the order of the tree of :class:`_IterationGraph` (a new part)."""
        nodes = []
        for runs in self.groups:
            if len(runs) == 1 and self.whole[runs[0]]:  # the run is its group's sum
                nodes.append(parts[runs[0]][0])
            else:
                nodes.append(_sum_nodes(*[parts[r] for r in runs]))
        return _tree_sum(self.fan, *nodes)


@dataclass
class _HostState:
    """What one worker's task of a batch leaves on its worker: its runs' W and its copy of H after the batch
    (W^(q+1), H^(q+1); W^q, H^q when the batch ends at max_iter), W^q and H^q when the stopping rule may stop
    at q, and the checks of the batch: (iteration, objective, summary) (on every worker: the same numbers)."""

    ws: dict[int, list[Any]]
    Ht: np.ndarray
    ws_q: dict[int, list[Any]] | None
    Ht_q: np.ndarray | None
    checks: list[tuple[int, float, _Partial]]


def _hosts_alive(hosts: Sequence[str], client: Any = None) -> None:
    """Raise :class:`ClusterError` if a worker of the fit has left the cluster (its part will never come)."""
    if client is None:
        from distributed import get_client

        client = get_client()
    present = set(client.nthreads())
    gone = [h for h in hosts if h not in present]
    if gone:
        raise ClusterError(f"worker(s) {gone} left the cluster during the fit; their rows of W were lost with them. "
                           "Fit again (the workers that remain take their chunks).")


def _delivered(sent: Any, alive: Any, poll: float = 2.0) -> None:
    """Wait for the reply to a part sent to another worker (:func:`_send`), calling ``alive()`` every ``poll`` seconds
    (a connection to a worker that left is retried for ``distributed.comm.timeouts.connect``)."""
    import concurrent.futures

    while True:
        try:
            sent.result(timeout=poll)
            return
        except concurrent.futures.TimeoutError:
            alive()


def _host_batch(plan: _Exchange, j: int, sources: list, prev: Any, Ht: Any, rule: _Rule,
                pen_H: Penalty, specs: list, start: int, q: int, checks: tuple[int, ...], max_iter: int,
                keep_q: bool) -> _HostState:
    """Iterations ``start`` to ``q`` of the fit on the j-th worker: its runs of chunks (:func:`_fit_run`), its parts
    sent to every other worker and theirs read from its mailbox, then the whole sum in the tree's order
    (:meth:`_Exchange.total`) and its own copy of the next H (:func:`_h_step`), as the other workers do; the
    objective at the iterations of ``checks``.

    ``sources`` and ``specs``: the worker's chunks in the order of its runs; ``prev``: their W (the first
    batch), or the worker's state after the previous batch: the fit's own, updated in place (W^q is
    kept with ``keep_q``). An error stops the other workers' tasks too (they raise :class:`ClusterError`
    naming this one).
    """
    from distributed import get_worker, secede

    peers = [p for p in range(len(plan.hosts)) if p != j]

    def alive() -> None:
        _hosts_alive(plan.hosts)

    try:
        if peers and get_worker().address != plan.hosts[j]:
            raise ClusterError(f"the task of worker {plan.hosts[j]} ran on {get_worker().address}.")
        if peers:
            # a task that waits for tasks on other workers gives its worker's thread back (distributed's long-running
            # tasks): two fits on the same single-threaded workers whose tasks each worker starts in a different
            # order would otherwise wait for each other forever, and other work would wait for the whole batch
            secede()
        box = _Mailbox.of(plan.token, j) if peers else None
        mine = plan.host_runs[j]
        at: dict[int, tuple[list, list]] = {}  # the run's sources and specs
        a = 0
        for r in mine:
            b = a + len(plan.runs[r])
            at[r] = (sources[a:b], specs[a:b])
            a = b
        if isinstance(prev, _HostState):
            ws, Ht = prev.ws, prev.Ht
        else:  # the chunks' W in the order of the runs
            ws, a = {}, 0
            for r in mine:
                ws[r], a = list(prev[a:a + len(plan.runs[r])]), a + len(plan.runs[r])
        pending: list = []
        ws_q = Ht_q = None
        done: list[tuple[int, float, _Partial]] = []
        for t in range(start, q + 1):
            evaluate, update = t in checks, t < max_iter
            keep = t == q and keep_q and update
            if keep:
                ws_q, Ht_q = ws, Ht
            parts: dict[int, list[_Partial]] = {}
            new: dict[int, list[Any]] = {}
            for r in mine:
                new[r], parts[r] = _fit_run(at[r][0], ws[r], Ht, rule, at[r][1], evaluate, update, plan.whole[r],
                                            not keep)
            if update:
                ws = new
            for f in pending:  # the previous iteration's deliveries (an error: a worker that left)
                _delivered(f, alive)
            # sent as they are (serialised on the event loop, later): never changed after this point
            pending = [_send(plan.token, plan.hosts[p], p, f"{t}-{j}", parts) for p in peers]
            every = dict(parts)
            for p in peers:
                every.update(cast(_Mailbox, box).take(f"{t}-{p}", alive))
            total = plan.total(every)
            if evaluate:
                done.append((t, *_check_part(total, Ht, pen_H)))
            if update:
                Ht = _h_step(total, Ht, rule, pen_H, own=True)
        for f in pending:
            _delivered(f, alive)
    except Exception as exc:
        for p in peers:  # not waited for: that worker may be gone
            with contextlib.suppress(Exception):
                _send(plan.token, plan.hosts[p], p, _ABORT, (plan.hosts[j], f"{type(exc).__name__}: {exc}"))
        raise
    return _HostState(ws, Ht, ws_q, Ht_q, done)


def _state_checks(state: _HostState) -> list[tuple[int, float, _Partial]]:
    return state.checks


def _state_w(state: _HostState, r: int, i: int, at_q: bool) -> Any:
    return cast(dict, state.ws_q if at_q else state.ws)[r][i]


def _state_h(state: _HostState, at_q: bool) -> np.ndarray:
    return cast(np.ndarray, state.Ht_q if at_q else state.Ht)


def _distributed_client(dask) -> Any:
    """The ``distributed`` client dask computes with, or None (another scheduler)."""
    client = getattr(dask.base.get_scheduler(), "__self__", None)
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - distributed comes with the dask extra
        return None
    return client if isinstance(client, Client) else None


def _future(client, ref: Any) -> Any:
    """The future of a persisted delayed value (computed now if it has none)."""
    from distributed import futures_of

    found = futures_of(ref)
    return found[0] if len(found) == 1 and found[0].key == ref.key else client.compute(ref)


def _wait_hosts(client, states: list, hosts: Sequence[str]) -> None:
    """Wait for a batch's tasks; on an error, raise the first worker's own error, not the others' stop; a task whose
    worker left (cancelled, its inputs lost with it) raises :class:`ClusterError` naming that worker."""
    import distributed
    from distributed.client import FutureCancelledError, FuturesCancelledError

    def ended() -> bool:
        return any(s.status in ("error", "cancelled") for s in states)

    waiting = list(states)
    with client.as_current():  # distributed.wait reads the current client (it may not be the default one)
        with contextlib.suppress(FutureCancelledError, FuturesCancelledError):
            while waiting and not ended():
                waiting = list(distributed.wait(waiting, return_when="FIRST_COMPLETED").not_done)
        if not ended():
            return
        with contextlib.suppress(distributed.TimeoutError, TimeoutError, FutureCancelledError, FuturesCancelledError):
            distributed.wait(states, timeout=10)  # the others stop once told
    try:
        failed = [s for s in states if s.status == "error"]
        own = [s for s in failed if not isinstance(s.exception(), ClusterError)]
        if own:
            own[0].result()
        _hosts_alive(hosts, client)  # a worker that left: name it
        if failed:
            failed[0].result()
        raise ClusterError(f"the fit's tasks were cancelled ({[s.key for s in states if s.status == 'cancelled']}); "
                           "fit again.")
    finally:
        client.cancel(states)


def _fit_loop_exchange(client, graph: _IterationGraph, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol,
                       loss_every, dask, check_scale):
    """W and H updates with one task per worker and batch of iterations, the sums sent between the workers.

    On a ``distributed`` cluster of at most ``split_every`` workers: the j-th worker's task
    (:func:`_host_batch`) runs the batch's iterations on its chunks; at each, it sends its parts to
    the other workers' mailboxes (:class:`_Mailbox`) and reads theirs, then sums all of them in the
    tree's order and updates its own copy of H, as :class:`_IterationGraph` does with tasks, so the
    iterates are the same bit for bit. The scheduler sees one task per worker and batch (and the
    reads of the check) instead of a few per worker and iteration. A worker that leaves during a
    batch ends the fit with :class:`ClusterError` (its rows of W are lost; the graph's tasks would be
    recomputed, these cannot be, since they wait for each other). A single worker has no mailbox,
    and its task may run elsewhere if it leaves.
    """
    plan = _Exchange.of(graph, uuid.uuid4().hex)
    name = f"nmf-{plan.token}"
    hosts = plan.hosts
    if len(hosts) > 1 and client not in _PLUGGED:
        client.register_plugin(_exchange_plugin())
        _PLUGGED.add(client)
    try:
        chunks = [[c for r in plan.host_runs[j] for c in plan.runs[r]] for j in range(len(hosts))]
        srcs = [[_future(client, sources[c]) for c in cs] for cs in chunks]
        prev: list[Any] = [[_future(client, W_refs[c]) for c in cs] for cs in chunks]
        hs: list[Any] = [client.scatter(Ht, workers=[h], hash=False) for h in hosts]
        del W_refs
        checks = _checks(max_iter, loss_every)
        # the batches: iterations 0 to the second check (the first two checks), then from one check to the next
        batches = [(0, checks[:2])] + [(a + 1, (b,)) for a, b in zip(checks[1:], checks[2:])]
        hist: list[float] = []
        its: list[int] = []
        stop: _Stopping | None = None
        converged = False
        update_bytes = 0
        strict = len(hosts) > 1  # the tasks of a batch wait for each other: each on its own worker
        for start, evaluated in batches:
            q = evaluated[-1]
            keep_q = tol > 0 and 0 < q < max_iter  # W^q, H^q: the answer if the rule stops at q
            states = [client.submit(_host_batch, plan, j, srcs[j], prev[j], hs[j], rule, pen_H,
                                    [specs[c] for c in chunks[j]], start, q, evaluated, max_iter, keep_q,
                                    key=f"{name}-host-{q}-{j}", workers=[h], allow_other_workers=not strict,
                                    pure=False)
                      for j, h in enumerate(hosts)]
            _wait_hosts(client, states, hosts)
            done = client.submit(_state_checks, states[0], key=f"{name}-check-{q}", workers=[hosts[0]],
                                 pure=False).result()
            for t, f, part in done:
                stop, converged = _record_check(t, f, hist, its, stop, tol, rule, check_scale)
                update_bytes = part.update_bytes or update_bytes
            prev, hs = states, [None] * len(hosts)
            if converged or q == max_iter:
                break
        at_q = converged and q < max_iter
        # H first: the client waits for it, and the first worker runs its tasks in the order they come
        h_out = client.submit(_state_h, prev[0], at_q, key=f"{name}-H", workers=[hosts[0]], pure=False)
        W_out: list[Any] = [None] * len(specs)
        for j, h in enumerate(hosts):
            for r in plan.host_runs[j]:
                for i, c in enumerate(plan.runs[r]):
                    W_out[c] = dask.delayed(client.submit(_state_w, prev[j], r, i, at_q, key=f"{name}-w-{c}",
                                                          workers=[h], pure=False))
        Ht = np.asarray(h_out.result())
    finally:
        if len(hosts) > 1:  # on the workers still there (connecting to one that left waits for a timeout)
            present = set(client.nthreads())
            if any(h in present for h in hosts):
                client.run(_drop_mailboxes, plan.token, workers=[h for h in hosts if h in present], on_error="ignore")
    part.update_bytes = update_bytes
    return W_out, Ht, q, hist, its, converged, part


def _transform_loop(store, sources, specs, W_refs, Ht, rule, pen_H, max_iter, tol, loss_every,
                    split_every, dask, check_scale):
    """W updates with H fixed: the updates between two evaluations of the objective run in one pass."""
    Ht_d = dask.delayed(Ht, name=f"Ht-{uuid.uuid4().hex}", traverse=False)
    checks = sorted({*range(loss_every, max_iter + 1, loss_every), max_iter})
    hist: list[float] = []
    its: list[int] = []
    stop: _Stopping | None = None
    converged = False
    done = 0
    final = _Partial()
    for c in checks:
        first = done == 0
        tasks = [dask.delayed(_transform_chunk, nout=3)(src, w, Ht_d, rule, s, first, c - done,
                                                        store.next_path(s.index))
                 for src, w, s in zip(sources, W_refs, specs)]
        W_refs, (part0, part) = _run_pass(store, tasks, 2, True, split_every, dask)
        if first:
            stop, _ = _record_check(0, _objective(part0, Ht, pen_H), hist, its, stop, tol, rule, check_scale)
            if c == 0:  # max_iter == 0
                final = part0
                final.finite = part.finite
                break
        stop, converged = _record_check(c, _objective(part, Ht, pen_H), hist, its, stop, tol, rule, check_scale)
        done = c
        final = part
        if converged:
            break
    final.update_bytes = 0
    return W_refs, Ht, done, hist, its, converged, final


def _finish_w(store: _WStore, W_refs, specs, k: int, dtype, scale_W: float, w_folder, dask):
    """W in X's units: a dask array with X's row chunks (in memory), or written to ``w_folder`` chunk by chunk."""
    import dask.array as da

    if w_folder is None:
        from dask.highlevelgraph import HighLevelGraph

        parts = [dask.delayed(_scaled)(w, scale_W, str(dtype)) for w in W_refs]
        if scale_W != 1.0:
            parts = list(dask.persist(*parts))
        name = "nmf-W-" + uuid.uuid4().hex  # built by hand: da.concatenate would drop empty chunks
        layer: dict[Any, Any] = {(name, i, 0): (_same, p.key) for i, p in enumerate(parts)}
        graph = HighLevelGraph.from_collections(name, layer, dependencies=parts)
        return da.Array(graph, name, chunks=(tuple(s.stop - s.start for s in specs), (k,)), dtype=dtype,
                        meta=np.empty((0, 0), dtype=dtype))
    save_npz_chunks((_scaled(w, scale_W, str(dtype)) for w in W_refs), w_folder, overwrite=True)
    return load_npz_chunks(w_folder)


# ---------------------------------------------------------------------------------------------
# Several dask arrays side by side (the modalities of a multimodal learner)


def _hstack_chunk(weights: tuple[float, ...], *blocks: Any) -> Any:
    scaled = [b * w if w != 1.0 else b for b, w in zip(blocks, weights)]
    if any(sp.issparse(b) for b in scaled):
        return sp.hstack([sp.csr_matrix(b) for b in scaled], format="csr")
    return np.hstack([np.asarray(b) for b in scaled])


def hstack_row_chunks(arrays: Sequence[Any], weights: Sequence[float] | None = None, *, names: Sequence[str] = ()):
    """``[w_1 X_1, w_2 X_2, ...]`` side by side, chunk by chunk: a dask array with the row chunks of X_1.

    For learners that fit several modalities with one factorization (the thesis' multimodal
    NMF, section 6.1.2): each row chunk of the result stacks the matching row chunks of the
    inputs (``scipy.sparse.hstack`` when any is sparse), so the fit still sees one column chunk.

    Parameters
    ----------
    arrays : sequence of dask.array.Array of shape (n_samples, n_features_i)
        Row chunks only, the same row chunks for all.
    weights : sequence of float, optional
        One factor per array (default 1).
    names : sequence of str, optional
        Names of the arrays for the error messages (e.g. the modalities).

    Raises
    ------
    DataError
        An array that is not a dask array, with unknown chunk sizes or column chunks, or whose row
        chunks differ from the first one's.
    """
    _require_dask("hstack_row_chunks")
    import dask.array as da
    from dask.highlevelgraph import HighLevelGraph

    arrays = list(arrays)
    names = list(names) or [f"array {i}" for i in range(len(arrays))]
    if not arrays:
        raise DataError("hstack_row_chunks needs at least one array.")
    for a, nm in zip(arrays, names):
        if not is_dask_array(a):
            raise DataError(f"{nm} must be a dask array like the others; got {type(a).__name__}. Convert it with "
                            f"dask.array.from_array(..., chunks={arrays[0].chunks[0] if is_dask_array(arrays[0]) else '...'}).")
        check_row_chunks(a, nm)
    rows = tuple(arrays[0].chunks[0])
    for a, nm in zip(arrays[1:], names[1:]):
        if tuple(a.chunks[0]) != rows:
            raise DataError(f"{nm} must have the row chunks of {names[0]}, {rows}; got {tuple(a.chunks[0])}. "
                            f"Fix: {nm} = {nm}.rechunk({{0: {rows}}}).")
    w = tuple(float(v) for v in (weights if weights is not None else [1.0] * len(arrays)))
    if len(w) != len(arrays):
        raise ParameterError(f"weights must have one value per array ({len(arrays)}); got {len(w)}.")
    name = "hstack-" + uuid.uuid4().hex
    layer: dict[Any, Any] = {(name, i, 0): (_hstack_chunk, w, *[(a.name, i, 0) for a in arrays])
                             for i in range(len(rows))}
    graph = HighLevelGraph.from_collections(name, layer, dependencies=arrays)
    sparse = any(sp.issparse(getattr(a, "_meta", None)) for a in arrays)
    dtype = np.result_type(*[a.dtype for a in arrays], *[np.float64 for v in w if v != 1.0])
    meta = sp.csr_matrix((0, 0), dtype=dtype) if sparse else np.empty((0, 0), dtype=dtype)
    return da.Array(graph, name, chunks=(rows, (sum(a.shape[1] for a in arrays),)), dtype=dtype, meta=meta)


# ---------------------------------------------------------------------------------------------
# Out of core


def beta_nmf_out_of_core(
    X: Any,
    n_components: int | None = None,
    *,
    out: str | os.PathLike[str],
    mask: Any = None,
    **kwargs: Any,
) -> NMFResult:
    """Fit :func:`~mmconcepts.nmf.beta_nmf` to a matrix on disk, never holding X or W whole.

    Each pass reads the chunks one by one (with dask's scheduler: the synchronous one reads
    one chunk at a time), W stays on disk between passes (``.npy`` files beside ``out``), and
    the final W is written to ``out`` in the layout of :func:`save_npz_chunks`, chunk by chunk,
    once the fit has succeeded: an error (negative values found in a late chunk, say) leaves no
    W behind. Memory: one chunk of X and of W at a time per worker thread, plus H and the sums
    of the dictionary update (a few n_features x n_components arrays).

    Parameters
    ----------
    X : path or dask.array.Array of shape (n_samples, n_features)
        A folder of ``.npz`` chunks (:func:`save_npz_chunks`), or a dask array of row chunks.
    n_components : int, optional
    out : path
        The folder W is written to (replaced if it exists, only once the fit succeeded).
    mask : path or dask.array.Array, optional
        A folder of chunks, or a dask array, chunked like X; True where X is observed.
    **kwargs
        The options of :func:`~mmconcepts.nmf.beta_nmf` (multiplicative updates only).
        Default ``init='random'`` (NNDSVD would hold its SVD's U in memory). Also
        ``in_flight`` (default 2): chunks read and updated at once, and ``split_every``
        (default 8): the fan-in of the tree summing their statistics.

    Returns
    -------
    NMFResult
        ``W`` is ``load_npz_chunks(out)`` (lazy), ``H`` a numpy array.
    """
    from .._validation import validate_params

    if isinstance(X, (str, os.PathLike)):
        X = load_npz_chunks(X)
    if isinstance(mask, (str, os.PathLike)):
        mask = load_npz_chunks(mask)
    if not is_dask_array(X):
        raise DataError(f"X must be a folder of .npz chunks or a dask array; got {type(X).__name__}. Write it with "
                        "save_npz_chunks first.")
    kwargs.setdefault("init", "random")
    params = dict(n_components=n_components, **kwargs)
    beta_loss = params.pop("beta_loss", 2.0)
    validate_params({**params, "beta_loss": beta_loss},
                    {name: BETA_NMF_CONSTRAINTS[name] for name in (*params, "beta_loss")
                     if name in BETA_NMF_CONSTRAINTS},
                    owner="beta_nmf_out_of_core")
    from ._beta import resolve_beta

    return beta_nmf_dask(X, beta=resolve_beta(beta_loss), mask=mask, w_folder=out, **params)
