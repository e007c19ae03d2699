"""The coefficients of X for a fixed dictionary, to convergence: a projected Newton method (internal).

With the dictionary H fixed, the coefficients solve one problem per row of X,

.. math:: \\min_{w \\ge 0} \\sum_j m_j\\, d_\\beta(x_j | (wH)_j) + \\lambda_1 \\|w\\|_1
          + \\tfrac{1}{2} \\lambda_2 \\|w\\|_2^2,

which is convex for 1 <= beta <= 2 (the second derivative of d_beta(x | y) in y,
(beta - 1) y^(beta-2) + (2 - beta) x y^(beta-3), is then nonnegative). Multiplicative updates
approach a coefficient that is zero at the optimum no faster than geometrically, at a rate
that can be close to one: from a flat start, a few hundred of them leave the coefficients
percents from the optimum. The projected Newton method of Bertsekas (1982) identifies the
zero coefficients in a few steps and then converges quadratically. It is written by hand: scipy's ``nnls`` solves beta = 2
only, without a mask, one row at a time, and no maintained library solves the other betas.

Bertsekas, D. P. (1982). Projected Newton methods for optimization problems with simple
constraints. SIAM Journal on Control and Optimization, 20(2), 221-246.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp

from ._beta import EPSILON, elementwise_beta_divergence
from ._kernels import lowrank_at_nonzeros
from ._updates import Penalty, data_scale, scale_penalties

__all__ = ["determined_rows", "solve_coefficients", "solves_coefficients"]

#: Sufficient decrease of the Armijo rule, and the step halvings tried before a row is called stationary.
_SIGMA, _HALVINGS = 1e-4, 30
#: Floats in the temporaries of one block of rows.
_BLOCK_CELLS = 1 << 22
#: Bertsekas' epsilon: a coefficient within this fraction of its row's largest (and within one scaled
#: gradient step) of zero, whose gradient pushes it down, is held at zero for the step.
_EPS_CAP = 0.1


def solves_coefficients(beta: float) -> bool:
    """Whether :func:`solve_coefficients` applies: the problem in W is convex for 1 <= beta <= 2."""
    return 1.0 <= beta <= 2.0


class _Rows(abc.ABC):
    """The objective of each row, its gradient and Hessian in w, for rows of W (float64)."""

    def __init__(self, Ht: np.ndarray, beta: float, penalty: Penalty):
        self.Ht, self.beta, self.penalty = Ht, beta, penalty

    def objective(self, rows: np.ndarray, W: np.ndarray) -> np.ndarray:
        """The objective of each of ``rows`` (W holds their coefficients), penalties included."""
        f = self._divergence(rows, W)
        pen = self.penalty
        if pen.l1:
            f = f + pen.l1 * W.sum(axis=1)
        if pen.l2:
            f = f + 0.5 * pen.l2 * np.einsum("ij,ij->i", W, W)
        return f

    @abc.abstractmethod
    def _divergence(self, rows: np.ndarray, W: np.ndarray) -> np.ndarray:
        """The divergence of each of ``rows`` (W holds their coefficients), without penalties."""

    @abc.abstractmethod
    def derivatives(self, rows: np.ndarray, W: np.ndarray) -> Iterator[tuple[slice, np.ndarray, np.ndarray]]:
        """Blocks (part, g, Hs) over ``rows``, penalties included: ``part`` indexes ``rows``; Hs is (rows, k, k)."""

    def _penalised(self, W, g, Hs):
        pen = self.penalty
        if pen.l1:
            g = g + pen.l1
        if pen.l2:
            g = g + pen.l2 * W
            Hs = Hs + pen.l2 * np.eye(W.shape[1])
        return g, Hs

    def _row_blocks(self, n_rows: int, cells_per_row: int) -> Iterator[slice]:
        step = max(1, _BLOCK_CELLS // max(1, cells_per_row))
        for start in range(0, n_rows, step):
            yield slice(start, min(n_rows, start + step))


class _Quadratic(_Rows):
    """beta = 2, every cell observed: f = |x|^2 / 2 - w . b + w G w / 2 with G = H H^T, b = H x."""

    def __init__(self, X, Ht, penalty):
        super().__init__(Ht, 2.0, penalty)
        self.G = Ht.T @ Ht
        self.B = np.asarray(X @ Ht, dtype=np.float64)
        sq = X.multiply(X).sum(axis=1) if sp.issparse(X) else np.einsum("ij,ij->i", X, X)
        self.half_sq = 0.5 * np.asarray(sq, dtype=np.float64).ravel()

    def _divergence(self, rows, W):
        return self.half_sq[rows] + np.einsum("ij,ij->i", W, 0.5 * (W @ self.G) - self.B[rows])

    def derivatives(self, rows, W):
        g = W @ self.G - self.B[rows]
        k = W.shape[1]
        for part in self._row_blocks(len(rows), k * k):
            Hs = np.broadcast_to(self.G, (part.stop - part.start, k, k))
            yield (part, *self._penalised(W[part], g[part], Hs))


class _SparseKL(_Rows):
    """beta = 1, sparse X, every cell observed: only X's stored values enter besides w . (H 1)."""

    def __init__(self, X, Ht, penalty):
        super().__init__(Ht, 1.0, penalty)
        self.X = sp.csr_matrix(X, dtype=np.float64)
        self.colsum = Ht.sum(axis=0)

    def _at_nonzeros(self, rows, W):
        sub = self.X if len(rows) == self.X.shape[0] else self.X[rows]
        y = lowrank_at_nonzeros(sub.indptr, sub.indices, W, self.Ht, np.empty(sub.nnz))
        return sub, y

    def _divergence(self, rows, W):
        sub, y = self._at_nonzeros(rows, W)
        x = sub.data
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = np.where(x > 0, x * np.log(np.where(x > 0, x, 1.0) / y), 0.0) - x
        per_row = np.add.reduceat(terms, sub.indptr[:-1]) if sub.nnz else np.zeros(sub.shape[0])
        per_row[np.diff(sub.indptr) == 0] = 0.0  # reduceat gives the next row's first value for an empty row
        return per_row + W @ self.colsum

    def derivatives(self, rows, W):
        sub, y = self._at_nonzeros(rows, W)
        yc = np.maximum(y, EPSILON)
        ratio = sp.csr_matrix((sub.data / yc, sub.indices, sub.indptr), shape=sub.shape)
        g = self.colsum - np.asarray(ratio @ self.Ht)
        c = np.sqrt(sub.data) / yc  # x / y^2 = c^2
        k = W.shape[1]
        for part in self._row_blocks(len(rows), k * k):
            Hs = np.empty((part.stop - part.start, k, k))
            for i, r in enumerate(range(part.start, part.stop)):
                lo, hi = sub.indptr[r], sub.indptr[r + 1]
                A = self.Ht[sub.indices[lo:hi]] * c[lo:hi, None]
                np.matmul(A.T, A, out=Hs[i])
            yield (part, *self._penalised(W[part], g[part], Hs))


class _Dense(_Rows):
    """Any beta in [1, 2], any mask: a block of rows of X (densified when sparse) at a time."""

    def __init__(self, X, Ht, beta, penalty, mask):
        super().__init__(Ht, beta, penalty)
        self.X, self.mask = X, mask
        m, k = Ht.shape
        iu = np.triu_indices(k)
        self.iu = iu
        self.outer = Ht[:, iu[0]] * Ht[:, iu[1]]  # (m, k (k + 1) / 2): row j holds the upper triangle of h_j h_j^T

    def _block(self, rows):
        X = self.X[rows]
        X = X.toarray() if sp.issparse(X) else X
        M = None
        if self.mask is not None:
            M = self.mask[rows]
            M = M.toarray() if sp.issparse(M) else M
            M = np.asarray(M, dtype=np.float64)
        return np.asarray(X, dtype=np.float64), M

    def _divergence(self, rows, W):
        f = np.empty(len(rows))
        for part in self._row_blocks(len(rows), self.Ht.shape[0]):
            X, M = self._block(rows[part])
            with np.errstate(over="ignore"):
                d = elementwise_beta_divergence(X, W[part] @ self.Ht.T, self.beta)
            if M is not None:
                d = np.where(M > 0, d * M, 0.0)
            f[part] = d.sum(axis=1)
        return f

    def derivatives(self, rows, W):
        beta, (m, k) = self.beta, self.Ht.shape
        for part in self._row_blocks(len(rows), 4 * m + 2 * k * k):
            X, M = self._block(rows[part])
            Wp = W[part]
            Y = Wp @ self.Ht.T
            Yc = np.maximum(Y, EPSILON) if beta < 2.0 else Y
            if beta == 2.0:
                grad_y, curv = Yc - X, np.ones_like(Yc)
            elif beta == 1.0:
                grad_y, curv = 1.0 - X / Yc, X / (Yc * Yc)
            else:
                grad_y = Yc ** (beta - 1.0) - X * Yc ** (beta - 2.0)
                curv = (beta - 1.0) * Yc ** (beta - 2.0) + (2.0 - beta) * X * Yc ** (beta - 3.0)
            if M is not None:
                grad_y *= M
                curv *= M
            g = grad_y @ self.Ht
            upper = curv @ self.outer
            Hs = np.empty((len(Wp), k, k))
            Hs[:, self.iu[0], self.iu[1]] = upper
            Hs[:, self.iu[1], self.iu[0]] = upper
            yield (part, *self._penalised(Wp, g, Hs))


def _rows_model(X, Ht, beta, penalty, mask) -> _Rows:
    if mask is None and beta == 2.0:
        return _Quadratic(X, Ht, penalty)
    if mask is None and beta == 1.0 and sp.issparse(X):
        return _SparseKL(X, Ht, penalty)
    return _Dense(X, Ht, beta, penalty, mask)


def _newton_directions(model: _Rows, rows: np.ndarray, W: np.ndarray, gtol: float):
    """g, the projected Newton direction d, the active coefficients, and the rows already optimal.

    Active (Bertsekas 1982): a coefficient at (or within eps of) zero whose gradient pushes it
    down; it moves along its gradient scaled by its curvature. The free ones take the Newton step
    of the problem restricted to them. A row whose scaled projected gradient is at most ``gtol``
    times its largest coefficient satisfies the optimality conditions (up to the conditioning
    of its Hessian): it is done, and no system is solved for it.
    """
    n, k = W.shape
    g, d = np.empty((n, k)), np.zeros((n, k))
    active = np.empty((n, k), dtype=bool)
    done = np.empty(n, dtype=bool)
    tiny = np.finfo(np.float64).tiny
    for part, gp, Hs in model.derivatives(rows, W):
        Wp = W[part]
        diag = np.einsum("ijj->ij", Hs)
        scale = np.maximum(diag.max(axis=1, keepdims=True), tiny)
        safe = np.maximum(diag, 1e-10 * scale)
        # a row without curvature (every observed x zero under beta = 1) has infinite scaled steps: to zero
        with np.errstate(over="ignore"):
            moved = np.abs(Wp - np.maximum(Wp - gp / safe, 0.0)).max(axis=1)
        size = np.maximum(Wp.max(axis=1), tiny)
        ok = moved <= gtol * size
        eps = np.minimum(_EPS_CAP * size, moved)[:, None]
        act = (Wp <= eps) & (gp > 0)
        g[part], active[part], done[part] = gp, act, ok
        todo = np.flatnonzero(~ok)
        if todo.size:
            d[part.start + todo] = _restricted_newton(Hs[todo], gp[todo], act[todo], safe[todo], scale[todo])
    return g, d, active, done


def _restricted_newton(Hs: np.ndarray, g: np.ndarray, act: np.ndarray, safe: np.ndarray,
                       scale: np.ndarray) -> np.ndarray:
    """Each row's step: the Newton step of its free coefficients, the curvature-scaled gradient of the active ones.

    The free coefficients are moved first (a stable sort keeps their order), and only the
    leading block of the largest free count is solved: with many coefficients held at zero,
    far smaller systems than (k, k).
    """
    r, k = g.shape
    n_free = k - act.sum(axis=1)
    f = int(n_free.max())
    with np.errstate(over="ignore"):
        d = g / safe  # the active coefficients' step (and every coefficient's when none is free)
    if f == 0:
        return d
    order = np.argsort(act, axis=1, kind="stable")[:, :f]  # each row's free coefficients first
    sub = Hs[np.arange(r)[:, None, None], order[:, :, None], order[:, None, :]]
    free = np.arange(f) < n_free[:, None]  # the leading block holds some active ones in rows with fewer free
    sub *= free[:, :, None] & free[:, None, :]
    idx = np.arange(f)
    # free coefficients: a small ridge keeps a singular restriction (more atoms than the row can tell
    # apart) solvable; active ones: their own curvature
    sub[:, idx, idx] += np.where(free, 1e-10 * scale, np.take_along_axis(safe, order, axis=1))
    step = np.linalg.solve(sub, np.take_along_axis(g, order, axis=1)[:, :, None])[:, :, 0]
    np.put_along_axis(d, order, step, axis=1)
    return d


def determined_rows(X, H: np.ndarray, beta: float, *, mask=None, penalty: Penalty | None = None) -> np.ndarray:
    """Which rows have one minimiser: a strictly convex problem in w (boolean, one per row of X).

    With an L2 penalty, every row. Otherwise the atoms that see the features (the rows of H
    that are not all zero; the others' coefficients do not enter the objective) must be
    linearly independent, to within a condition number of 1e6, and each row must observe at
    least as many cells as there are such atoms (the objective depends on w only through the
    observed cells of w H). Elsewhere (more atoms than the features can tell apart, as with a
    dictionary of 150 atoms seen through 3 features) the minimisers form a set, and the
    updates' coefficients are kept as one of its points.
    """
    n = X.shape[0]
    if penalty is not None and penalty.l2 > 0:
        return np.ones(n, dtype=bool)
    H = np.asarray(H, dtype=np.float64)
    norms = np.linalg.norm(H, axis=1)
    seen = H[norms > 0] / norms[norms > 0, None]
    k = seen.shape[0]
    if k == 0:
        return np.ones(n, dtype=bool)
    if k > H.shape[1]:
        return np.zeros(n, dtype=bool)
    eig = np.linalg.eigvalsh(seen @ seen.T)
    if not eig[0] > 1e-12 * eig[-1]:
        return np.zeros(n, dtype=bool)
    if mask is None:
        return np.ones(n, dtype=bool)
    counts = sp.csr_matrix(mask, dtype=bool).getnnz(axis=1) if sp.issparse(mask) else np.count_nonzero(mask, axis=1)
    return np.asarray(counts).ravel() >= k


def _project_newton(model: _Rows, W: np.ndarray, rows: np.ndarray, max_iter: int,
                    xtol: float) -> tuple[np.ndarray, bool]:
    """Projected Newton steps with an Armijo search along the projection arc, each row until it is done."""
    f_all = np.empty(W.shape[0])
    f_all[rows] = model.objective(rows, W[rows])
    for _ in range(max_iter):
        if rows.size == 0:
            return W, True
        Wr, f = W[rows], f_all[rows]
        g, d, active, done = _newton_directions(model, rows, Wr, 1e-3 * xtol)
        full = np.maximum(Wr - d, 0.0)
        size = np.maximum(np.abs(full).max(axis=1), np.abs(Wr).max(axis=1))
        # a full step this small is (to second order) the distance to the optimum: take it and stop
        small = ~done & (np.abs(full - Wr).max(axis=1) <= xtol * size)
        W[rows[small]] = full[small]
        done |= small
        pending = np.flatnonzero(~done)
        alpha = np.ones(pending.size)
        todo = np.arange(pending.size)
        for _ in range(_HALVINGS):
            if todo.size == 0:
                break
            p = pending[todo]
            trial = np.maximum(Wr[p] - alpha[todo, None] * d[p], 0.0)
            ft = model.objective(rows[p], trial)
            # Armijo along the projection arc: the decrease the gradient predicts from the free coefficients'
            # Newton step and the active ones' actual move
            predicted = np.where(active[p], g[p] * (Wr[p] - trial), alpha[todo, None] * g[p] * d[p]).sum(axis=1)
            ok = np.isfinite(ft) & (f[p] - ft >= _SIGMA * predicted)
            W[rows[p[ok]]] = trial[ok]
            f_all[rows[p[ok]]] = ft[ok]
            todo = todo[~ok]
            alpha[todo] *= 0.5
        done[pending[todo]] = True  # no decrease along the projection arc: stationary up to rounding
        rows = rows[~done]
    return W, rows.size == 0


def solve_coefficients(X, H: np.ndarray, W: np.ndarray, beta: float, *, mask=None, penalty: Penalty | None = None,
                       max_iter: int = 100, xtol: float = 1e-7) -> tuple[np.ndarray, bool]:
    """The coefficients W >= 0 minimising the penalised beta-divergence of X to W @ H, from W.

    Only the rows with one minimiser (:func:`determined_rows`) are solved; the others keep
    their start.

    Parameters
    ----------
    X : {ndarray, sparse matrix} of shape (n_samples, n_features)
        Checked, nonnegative, zero where ``mask`` is False.
    H : ndarray of shape (n_components, n_features)
        The dictionary, fixed.
    W : ndarray of shape (n_samples, n_components)
        The start (e.g. after multiplicative updates); not modified.
    beta : float in [1, 2]
    mask : {ndarray, sparse matrix} of shape (n_samples, n_features), optional
        True where X is observed.
    penalty : Penalty, optional
        L1 and L2 penalties on W (the resolved ``alpha_W``).
    max_iter : int, default=100
        Newton steps at most; a row stops when its full step changes none of its
        coefficients by more than ``xtol`` times its largest one.

    Returns
    -------
    W : ndarray of shape (n_samples, n_components), W's dtype
    converged : bool
        Whether every row stopped before ``max_iter``.
    """
    penalty = penalty or Penalty()
    dtype = W.dtype
    # Homogeneity, d(c x | c y) = c^beta d(x | y): the problem on X / a and H / b (powers of two, exact) has the
    # solution W b / a, and data at any scale meets the clipping of the product at EPSILON as data near 1 does.
    a = data_scale(X, beta)
    b = data_scale(H, beta)
    if a != 1.0:
        X = X / a
    if a != 1.0 or b != 1.0:
        penalty, _ = scale_penalties(penalty, Penalty(), a, a / b, b, beta)
    Ht = np.ascontiguousarray(np.asarray(H, dtype=np.float64).T / b)
    W0 = np.array(W, dtype=np.float64) * (b / a)
    model = _rows_model(X, Ht, beta, penalty, mask)
    rows = np.flatnonzero(determined_rows(X, H, beta, mask=mask, penalty=penalty))
    out, converged = _project_newton(model, W0, rows, max_iter, xtol)
    return (out * (a / b)).astype(dtype, copy=False), converged
