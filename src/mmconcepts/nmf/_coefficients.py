"""The coefficients of X for a fixed dictionary, to convergence: a projected Newton method (internal).

With the dictionary H fixed, the coefficients solve one problem per row of X,

.. math:: \\min_{w \\ge 0} \\sum_j m_j\\, d_\\beta(x_j | (wH)_j) + \\lambda_1 \\|w\\|_1
          + \\tfrac{1}{2} \\lambda_2 \\|w\\|_2^2,

which is convex for 1 <= beta <= 2 (the second derivative of d_beta(x | y) in y,
(beta - 1) y^(beta-2) + (2 - beta) x y^(beta-3), is then nonnegative). Multiplicative updates
approach a coefficient that is zero at the optimum no faster than geometrically, at a rate
that can be close to one: from a flat start, a few hundred of them leave the coefficients
percents from the optimum. The projected Newton method of Bertsekas (1982) identifies the
zero coefficients in a few steps and then converges quadratically; an Armijo search along the
projection arc and a Levenberg-Marquardt ridge (scaled by each coefficient's curvature, as
Marquardt's) make it converge from any start; a row whose search fails even at the largest
ridge takes multiplicative updates (kept where they lower its objective) before Newton's steps
resume. Where x spans hundreds of orders of magnitude (kernel-density histograms), curvatures
do too: the Newton system is solved scaled to a unit diagonal, a coefficient far below its
optimum climbs by the multiplicative update's factor rather than by Newton's doubling, and a
free coefficient near zero that the coupled step would clip is held for the step. It is
written by hand: scipy's ``nnls`` solves beta = 2 only, without a mask, one row at a time, and
no maintained library solves the other betas.

Rows whose minimiser is not unique (:func:`determined_rows`) keep their start. For
1 < beta < 2 the curvature is infinite where a product vanishes at an x = 0: the steps can stop
short there (about 1e-3 of the largest coefficient on random data with zeros).

Bertsekas, D. P. (1982). Projected Newton methods for optimization problems with simple
constraints. SIAM Journal on Control and Optimization, 20(2), 221-246.

Fevotte, C., & Idier, J. (2011). Algorithms for nonnegative matrix factorization with the
beta-divergence. Neural Computation, 23(9), 2421-2456.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp

from ._beta import EPSILON, elementwise_beta_divergence
from ._kernels import gather_scaled_rows, lowrank_at_nonzeros
from ._updates import Penalty, data_scale, scale_penalties

__all__ = ["determined_rows", "solve_coefficients", "solves_coefficients"]

#: Sufficient decrease of the Armijo rule, and the step halvings tried before the ridge grows.
_SIGMA, _HALVINGS = 1e-4, 30
#: The smallest ridge added to the free coefficients' Hessian, relative to each one's own curvature (its diagonal
#: entry; 1e-14 of the row's largest for a coefficient without any): a singular restriction stays solvable, a regular
#: one keeps its Newton step to about 1e-14 times its scaled condition number. A row whose step needs many halvings
#: gets a larger ridge (Levenberg-Marquardt), up to 1, about half its gradient scaled by its curvature: directions of
#: no curvature (beta = 1, zero x) stay bounded.
_RIDGE = 1e-14
#: Below this ridge a step is a Newton step: a row optimal to the tolerance takes full ones, whose length
#: measures its distance to the optimum.
_NEWTON_RIDGE = 1e-6
#: The floor of the product where the derivatives take its negative powers with x > 0 (x y^(beta-2),
#: x y^(beta-3)): the multiplicative updates clip it at float32's epsilon, which changes the problem where a product is
#: that small; here the terms still fit in float64 at this floor (x / y < 1e106 for the x <= 2^20 of the rescaled data),
#: and below it the objective the line search reads continues its x y^(beta-1) term (x log y) linearly
#: (:func:`_floored_divergence`): the gradient is that objective's own everywhere. The curvature's term without x,
#: (beta - 1) y^(beta-2) for 1 < beta < 2, infinite at y = 0 where the objective is finite, takes the product clipped at
#: float32's epsilon as the updates do: it is only the Newton steps' model.
_FLOOR = 1e-100
#: The most a step may divide a product where x > 0 (beta < 2). The derivative there is -inf at y = 0, so the
#: optimum has y > 0; but the objective stays finite (1 < beta < 2) or grows only as x log(1 / y) (beta = 1),
#: so a projected step that zeroes the only atoms reaching such a cell can lower it, and Newton steps then
#: climb back from y near 0 only by a constant factor each. The line search refuses such steps, and the coefficients
#: held at zero shrink by at most twice this factor per step (their scaled-gradient step to zero would collapse
#: the cells their atom alone reaches at every step length the arc can resolve).
_COLLAPSE = 1e-3
#: The relative decrease of a row's objective below which its rounding (a sum of terms each exact to about 1e-16)
#: may hide it: a step that predicts no more is not searched further.
_RESOLUTION = 1e-13
#: The dictionary's entries (scaled to a largest of about 1) the curvature leaves out: their products would
#: underflow. The curvature is only the Newton steps' model; the gradient and the objective keep them.
_NEGLIGIBLE = 1e-150
#: The smallest normal float64: below it, a product is subnormal.
_TINY = np.finfo(np.float64).tiny
#: The excess -g / den (the multiplicative update's factor minus one) beyond which a coefficient climbs by that factor.
_CLIMB = 3.0
#: The ratio of free counts grouped in one batched Newton solve (padded to the group's largest).
_GROUPING = 1.25
#: How many times a climbing coefficient's factor may be squared after a step (up to factor^64).
_COMPOUNDINGS = 6
#: Floats in the temporaries of one block of rows.
_BLOCK_CELLS = 1 << 22
#: The multiplicative updates a row takes where the search along the projection arc fails at the largest ridge,
#: before Newton's steps resume (5, 20 and 50 gave the same objectives to 1e-7 on kernel-density rows).
_FALLBACK_UPDATES = 20
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

    def objective(self, rows: np.ndarray, W: np.ndarray, start: np.ndarray | None = None,
                  start_products: np.ndarray | None = None) -> np.ndarray:
        """The objective of each of ``rows`` (W holds their coefficients), penalties included.

        With ``start`` (the coefficients a step leaves, beta < 2), a row where the step divides a
        product by more than :data:`_COLLAPSE` where x > 0 reads infinite (see there);
        ``start_products``, where :meth:`products` gave them, are the start's products, not formed again.
        """
        f = self._divergence(rows, W, start, start_products)
        pen = self.penalty
        if pen.l1:
            f = f + pen.l1 * W.sum(axis=1)
        if pen.l2:
            f = f + 0.5 * pen.l2 * np.einsum("ij,ij->i", W, W)
        return f

    @abc.abstractmethod
    def _divergence(self, rows: np.ndarray, W: np.ndarray, start: np.ndarray | None,
                    start_products: np.ndarray | None = None) -> np.ndarray:
        """The divergence of each of ``rows`` (W holds their coefficients), without penalties."""

    def products(self, rows: np.ndarray, W: np.ndarray) -> np.ndarray | None:
        """The products W H of ``rows`` (W holds their coefficients), (len(rows), n_features), where the model reads
        them back in :meth:`objective` (``start_products``) and they are small enough to keep; else None."""
        return None

    @abc.abstractmethod
    def derivatives(self, rows: np.ndarray, W: np.ndarray) -> Iterator[tuple[slice, np.ndarray, np.ndarray,
                                                                               _Curvature]]:
        """Blocks (part, g, den, curvature) over ``rows``, penalties included: ``part`` indexes ``rows``.

        ``den`` is the positive part of the gradient g = den - num (the denominator of the
        multiplicative update, thesis eq. 2.16); ``curvature`` the Hessian's diagonal and, on
        demand, its blocks (a Newton step needs only its free coefficients').
        """

    def _penalised(self, W, num, den, diag, block, product=None):
        pen = self.penalty
        if pen.l1:
            den = den + pen.l1
        if pen.l2:
            den = den + pen.l2 * W
        return den - num, den, _Curvature(diag, block, pen.l2, product)

    def _row_blocks(self, n_rows: int, cells_per_row: int) -> Iterator[slice]:
        step = max(1, _BLOCK_CELLS // max(1, cells_per_row))
        for start in range(0, n_rows, step):
            yield slice(start, min(n_rows, start + step))


def _row_sums(A: sp.csr_matrix, values: np.ndarray) -> np.ndarray:
    """The sum over each row of A of ``values``, one per stored entry of A."""
    return np.bincount(np.repeat(np.arange(A.shape[0]), np.diff(A.indptr)), weights=values, minlength=A.shape[0])


class _Curvature:
    """The Hessian of a block of rows: its diagonal ``diag`` (rows, k), and any of its blocks on demand.

    ``block(order, sel)`` gives, for rows ``sel`` of the block, the (len(sel), f, f) Hessian of the
    coefficients ``order`` (len(sel), f), the L2 penalty ``l2`` included; ``product(V)``, where the model
    forms it, the Hessian of each row times its row of V.
    """

    def __init__(self, diag: np.ndarray, block, l2: float = 0.0, product=None):
        self.diag = diag + l2 if l2 else diag
        self._block, self._l2, self._product = block, l2, product

    @property
    def has_product(self) -> bool:
        """Whether :meth:`product` is formed."""
        return self._product is not None

    def product(self, V: np.ndarray) -> np.ndarray:
        """The Hessian of each row of the block times its row of V (rows, k); formed by the models of dense rows
        (any beta) and of beta = 2 (:attr:`has_product`), not by the sparse I-divergence rows."""
        out = self._product(V)
        return out + self._l2 * V if self._l2 else out

    def block(self, order: np.ndarray, sel: np.ndarray) -> np.ndarray:
        B = self._block(order, sel)
        if self._l2:
            idx = np.arange(order.shape[1])
            B[:, idx, idx] += self._l2
        return B


class _Quadratic(_Rows):
    """beta = 2, every cell observed: the gradient G w - b with G = H H^T, b = H x, and one Hessian G.

    The objective is summed from the residuals (at X's stored values and, for a sparse X, the rest
    through G), not as |x|^2 / 2 - w . b + w G w / 2, whose cancellation would hide the last
    decreases of a row that W H fits exactly.
    """

    def __init__(self, X, Ht, penalty):
        super().__init__(Ht, 2.0, penalty)
        self.X = sp.csr_matrix(X, dtype=np.float64) if sp.issparse(X) else X
        self.G = Ht.T @ Ht
        self.B = np.asarray(X @ Ht, dtype=np.float64)

    def _divergence(self, rows, W, start, start_products=None):
        if not sp.issparse(self.X):
            f = np.empty(len(rows))
            for part in self._row_blocks(len(rows), self.Ht.shape[0]):
                R = np.asarray(self.X[rows[part]], dtype=np.float64) - W[part] @ self.Ht.T
                f[part] = 0.5 * np.einsum("ij,ij->i", R, R)
            return f
        sub = self.X if len(rows) == self.X.shape[0] else self.X[rows]
        y = lowrank_at_nonzeros(sub.indptr, sub.indices, W, self.Ht, np.empty(sub.nnz))
        # (x - y)^2 at the stored values, y^2 elsewhere: w G w minus the stored cells' y^2
        return 0.5 * (_row_sums(sub, (sub.data - y) ** 2 - y**2) + np.einsum("ij,ij->i", W, W @ self.G))

    def derivatives(self, rows, W):
        den, num = W @ self.G, self.B[rows]
        k = W.shape[1]
        G = self.G
        for part in self._row_blocks(len(rows), k * k):
            diag = np.broadcast_to(np.diag(G), (part.stop - part.start, k))
            yield (part, *self._penalised(W[part], num[part], den[part], diag,
                                          lambda order, sel: G[order[:, :, None], order[:, None, :]],
                                          lambda V: V @ G))


class _SparseKL(_Rows):
    """beta = 1, sparse X, every cell observed: only X's stored values enter besides w . (H 1)."""

    def __init__(self, X, Ht, penalty):
        super().__init__(Ht, 1.0, penalty)
        self.X = sp.csr_matrix(X, dtype=np.float64)
        self.colsum = Ht.sum(axis=0)
        self.Ht2 = Ht**2

    def _at_nonzeros(self, rows, W):
        sub = self.X if len(rows) == self.X.shape[0] else self.X[rows]
        y = lowrank_at_nonzeros(sub.indptr, sub.indices, W, self.Ht, np.empty(sub.nnz))
        return sub, y

    def _divergence(self, rows, W, start, start_products=None):
        sub, y = self._at_nonzeros(rows, W)
        x = sub.data
        terms = _floored_divergence(x, y, 1.0) - y  # the products' sum is W @ colsum
        f = _row_sums(sub, terms) + W @ self.colsum
        if start is None:
            return f
        collapsed = _collapsed(x, y, self._at_nonzeros(rows, start)[1])
        return np.where(_row_sums(sub, collapsed.astype(np.float64)) > 0, np.inf, f)

    def derivatives(self, rows, W):
        sub, y = self._at_nonzeros(rows, W)
        yc = np.maximum(y, _FLOOR)
        ratio = sp.csr_matrix((sub.data / yc, sub.indices, sub.indptr), shape=sub.shape)
        num = np.asarray(ratio @ self.Ht)
        den = np.broadcast_to(self.colsum, num.shape)
        c = np.sqrt(sub.data) / yc  # x / y^2 = c^2
        diag = np.asarray(sp.csr_matrix((c**2, sub.indices, sub.indptr), shape=sub.shape) @ self.Ht2)
        Ht, indptr, indices = self.Ht, sub.indptr, sub.indices

        def block(start, order, sel):
            # each row's A = Ht[its columns of X, order] scaled by c (A^T A its Hessian), stacked by a compiled pass
            # over as many rows as _BLOCK_CELLS values hold (a row at least)
            rows = start + np.asarray(sel)
            f = order.shape[1]
            ends = np.cumsum(indptr[rows + 1] - indptr[rows])
            B = np.empty((len(rows), f, f))
            first, done = 0, 0
            while first < len(rows):
                last = max(first + 1, int(np.searchsorted(ends, done + _BLOCK_CELLS // max(f, 1), side="right")))
                stacked = gather_scaled_rows(indptr, indices, c, Ht, rows[first:last], order[first:last],
                                             np.empty((int(ends[last - 1]) - done, f)))
                lo = 0
                for i in range(first, last):
                    hi = int(ends[i]) - done
                    A = stacked[lo:hi]
                    np.matmul(A.T, A, out=B[i])
                    lo = hi
                first, done = last, int(ends[last - 1])
            return B

        for part in self._row_blocks(len(rows), W.shape[1]):
            yield (part, *self._penalised(W[part], num[part], den[part], diag[part],
                                          lambda order, sel, start=part.start: block(start, order, sel)))


class _Dense(_Rows):
    """Any beta in [1, 2], any mask: a block of rows of X (densified when sparse) at a time."""

    def __init__(self, X, Ht, beta, penalty, mask):
        super().__init__(Ht, beta, penalty)
        self.X, self.mask = X, mask
        m, k = Ht.shape
        # the curvature's dictionary: the entries above :data:`_NEGLIGIBLE` (products that underflow to subnormal
        # numbers are a hundred times slower to make and to multiply), atoms as rows, and its squares
        self.Hn = np.ascontiguousarray(np.where(Ht >= _NEGLIGIBLE, Ht, 0.0).T)
        self.Hn2 = (self.Hn**2).T

    def _block(self, rows):
        X = self.X[rows]
        X = X.toarray() if sp.issparse(X) else X
        M = None
        if self.mask is not None:
            M = self.mask[rows]
            M = M.toarray() if sp.issparse(M) else M
            M = np.asarray(M, dtype=np.float64)
        return np.asarray(X, dtype=np.float64), M

    def _divergence(self, rows, W, start, start_products=None):
        f = np.empty(len(rows))
        for part in self._row_blocks(len(rows), self.Ht.shape[0]):
            X, M = self._block(rows[part])
            Y = W[part] @ self.Ht.T
            d = _floored_divergence(X, Y, self.beta)
            if M is not None:
                d = np.where(M > 0, d * M, 0.0)
            f[part] = d.sum(axis=1)
            if start is not None and self.beta < 2.0:
                observed = X > 0 if M is None else (X > 0) & (M > 0)
                Y_start = start[part] @ self.Ht.T if start_products is None else start_products[part]
                collapsed = _collapsed(observed, Y, Y_start)
                f[part] = np.where(collapsed.any(axis=1), np.inf, f[part])
        return f

    def products(self, rows, W):
        if self.beta >= 2.0 or len(rows) * self.Ht.shape[0] > _BLOCK_CELLS:
            return None
        return W @ self.Ht.T

    def derivatives(self, rows, W):
        beta, (m, k) = self.beta, self.Ht.shape
        for part in self._row_blocks(len(rows), 6 * m + k * (m + k)):
            X, M = self._block(rows[part])
            Wp = W[part]
            Y = Wp @ self.Ht.T
            # d_beta(x | y)' = y^(beta-1) - x y^(beta-2): the denominator's and the numerator's terms
            if beta == 2.0:
                den_y, num_y, curv = Y, X, np.ones_like(Y)
            elif beta == 1.0:
                Yf = np.maximum(Y, _FLOOR)
                den_y, num_y = np.ones_like(Y), X / Yf
                curv = num_y / Yf
                curv[curv < _TINY] = 0.0  # subnormal (x itself can be)
            else:
                Yf, Yc = np.maximum(Y, _FLOOR), np.maximum(Y, EPSILON)
                den_y, num_y = np.maximum(Y, 0.0) ** (beta - 1.0), X * Yf ** (beta - 2.0)
                curv = (beta - 1.0) * Yc ** (beta - 2.0) + (2.0 - beta) * X * Yf ** (beta - 3.0)
            if M is not None:
                den_y, num_y, curv = den_y * M, num_y * M, curv * M
            root = np.sqrt(curv)

            def block(order, sel, root=root):
                A = self.Hn[order] * root[sel, None, :]  # (rows, f, m): the free atoms, weighted
                return A @ A.transpose(0, 2, 1)

            yield (part, *self._penalised(Wp, num_y @ self.Ht, den_y @ self.Ht, curv @ self.Hn2, block,
                                          lambda V, curv=curv: ((V @ self.Hn) * curv) @ self.Hn.T))


def _floored_divergence(x: np.ndarray, y: np.ndarray, beta: float) -> np.ndarray:
    """d_beta(x | y) elementwise, its x y^(beta-1) term (x log y at beta = 1) continued linearly below the floor.

    The derivatives take that term's derivative, x y^(beta-2), at the product clipped to the floor: this is the
    objective whose derivatives they are (convex, once differentiable), equal to d_beta wherever the product is
    above the floor, and finite at y = 0.
    """
    if beta == 2.0:
        return elementwise_beta_divergence(x, y, beta)
    yf = np.maximum(y, _FLOOR)
    below = np.minimum(y / _FLOOR - 1.0, 0.0)  # (y - floor) / floor where y < floor, else 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if beta == 1.0:
            # x log(x / y) - x + y with log y continued as log(floor) + (y - floor) / floor
            return np.where(x > 0, x * (np.log(np.where(x > 0, x, 1.0) / yf) - below), 0.0) - x + y
        # x^beta / (beta (beta - 1)) + y^beta / beta - x y^(beta-1) / (beta - 1), the last term continued
        cross = np.where(x > 0, x * yf ** (beta - 1.0) * (1.0 + (beta - 1.0) * below), 0.0)
        return (x**beta + (beta - 1.0) * y**beta - beta * cross) / (beta * (beta - 1.0))


def _collapsed(x_positive, y, y_start) -> np.ndarray:
    """The cells where x > 0 whose product a step divides by more than :data:`_COLLAPSE`."""
    return (x_positive > 0) & (y < _COLLAPSE * y_start)


def _rows_model(X, Ht, beta, penalty, mask) -> _Rows:
    if mask is None and beta == 2.0:
        return _Quadratic(X, Ht, penalty)
    if mask is None and beta == 1.0 and sp.issparse(X):
        return _SparseKL(X, Ht, penalty)
    return _Dense(X, Ht, beta, penalty, mask)


def _newton_directions(model: _Rows, rows: np.ndarray, W: np.ndarray, tol: float, ridge: np.ndarray):
    """g, den, the projected Newton direction d, the active coefficients, the rows optimal to ``tol``, factor, and
    the right-hand side of the free coefficients' Newton system (``slope``).

    Active (Bertsekas 1982): a coefficient at (or within eps of) zero whose gradient pushes it
    down; it moves along its gradient scaled by its curvature. The free ones take the Newton step
    of the problem restricted to them, with ``ridge`` (one per row, relative to each
    coefficient's curvature) on the diagonal, where the model forms the Hessian's product (beta = 2,
    and dense rows at any beta) for the gradient where the active ones' full step lands them
    (``slope``; g elsewhere); a climbing one (update factor above 1 +
    :data:`_CLIMB`) takes that factor (``factor``, 1 elsewhere). Optimality is read in the
    multiplicative update's terms: with g = den - num, the ratio num / den (the update's factor)
    must be at most 1 + ``tol``, and at least 1 - ``tol`` where w is more than ``tol`` times the
    row's largest coefficient (the Karush-Kuhn-Tucker conditions, free of units; :func:`_optimality`).
    """
    n, k = W.shape
    g, den_all, d, slope = np.empty((n, k)), np.empty((n, k)), np.empty((n, k)), np.empty((n, k))
    active = np.empty((n, k), dtype=bool)
    optimal = np.empty(n, dtype=bool)
    factor = np.empty((n, k))
    for part, gp, den, curvature in model.derivatives(rows, W):
        Wp = W[part]
        excess, optimal[part], _ = _optimality(gp, den, Wp, tol)
        diag = curvature.diag
        scale = diag.max(axis=1, keepdims=True)
        scale = np.where(scale > 0, scale, 1.0)
        # each coefficient's own curvature (they span hundreds of orders of magnitude where products are tiny);
        # one without any (the objective is linear in it) a floor far below the row's largest
        safe = np.where(diag > 0, diag, _RIDGE * scale)
        with np.errstate(over="ignore"):
            moved = np.abs(Wp - np.maximum(Wp - gp / safe, 0.0)).max(axis=1)
        eps = np.minimum(_EPS_CAP * np.maximum(Wp.max(axis=1), _TINY), moved)[:, None]
        # held at zero: near it and pushed down, or pushed down without curvature (the objective is linear in
        # it: under beta = 1, an atom that sees only zero x)
        act = ((Wp <= eps) | (diag == 0)) & (gp > 0)
        # far below its optimum, where the product it makes is far below x, a coefficient's Newton steps only double
        # it (the curvature of -x log y grows as y shrinks): it takes the multiplicative update's factor num / den
        # instead, along a geometric arc, and is held out of the Newton system
        up = ~act & (Wp > 0) & (excess < -_CLIMB) & np.isfinite(excess) & (model.beta < 2.0)
        act = act | up
        everyone = np.arange(len(Wp))
        # where the model forms the Hessian's product (beta = 2; dense rows at any beta): the free coefficients' step
        # is taken where the held ones' own full step leaves the gradient (held ones zeroed at once change the fit
        # the free ones' step assumes, and the next step undoes it: rows then alternate between most atoms held and
        # none; under beta < 2, a coefficient near zero lifted by its own gradient at one step, pushed back down at
        # the next)
        pushed = act & (gp > 0) if curvature.has_product else np.zeros_like(act)
        rhs = gp
        if pushed.any():
            with np.errstate(over="ignore", invalid="ignore"):
                moves = np.where(pushed, np.minimum(gp / safe, Wp), 0.0)
            rhs = np.where(act, gp, gp - curvature.product(moves))
        # beta < 2: each row's scaled system, read back if the row is solved again below
        systems: list | None = [None] * len(Wp) if model.beta < 2.0 else None
        dp = _restricted_newton(curvature, everyone, rhs, act, safe, ridge[part], systems)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            factor[part] = np.where(up, 1.0 - excess, 1.0)
        dp[up] = Wp[up] * excess[up]  # w - d = w num / den
        # beta < 2: a free coefficient near zero that the coupled step drives below it (though its own gradient
        # pushes it up) would be clipped at every step length the arc can resolve: it is held out of the Newton
        # system and takes its own curvature-scaled gradient step (up), the others' step solved without it (at
        # beta = 2 the projection arc alone reaches the exact least-squares solution; holding there stops short)
        held = ~act & (Wp <= eps) & (dp > Wp) & (model.beta < 2.0)
        redo = np.flatnonzero(held.any(axis=1))
        if redo.size:
            dp[redo] = _restricted_newton(curvature, redo, rhs[redo], act[redo] | held[redo], safe[redo],
                                          ridge[part][redo], known=None if systems is None else [systems[i] for i in redo])
            with np.errstate(over="ignore"):
                dp[held] = (gp / safe)[held]
            act = act | held
        g[part], den_all[part], active[part], d[part], slope[part] = gp, den, act, dp, rhs
    return g, den_all, d, active, optimal, factor, slope


def _optimality(g: np.ndarray, den: np.ndarray, W: np.ndarray, tol: float):
    """The excess g / den (the multiplicative update's factor minus one), and which rows are optimal and which
    stationary to ``tol``.

    Optimal: the factor at most 1 + ``tol`` everywhere, and at least 1 - ``tol`` where w is more
    than ``tol`` times the row's largest coefficient (the Karush-Kuhn-Tucker conditions).
    Stationary: the factor within ``tol`` of 1 at every coefficient above ``tol`` times the row's
    largest (those below are left out whichever way they are pushed).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        excess = np.where(den > 0, g / den, np.where(g == 0, 0.0, np.sign(g) * np.inf))
    # pushed up: excess < 0 is a violation at any w; pushed down: only where w is not negligible
    size = np.maximum(W.max(axis=1, keepdims=True), _TINY)
    down = np.minimum(np.maximum(excess, 0.0), W / size)
    optimal = np.maximum(np.maximum(-excess, 0.0), down).max(axis=1) <= tol
    stationary = np.where(W > tol * size, np.abs(excess), 0.0).max(axis=1) <= tol
    return excess, optimal, stationary


def _stationary_rows(model: _Rows, rows: np.ndarray, W: np.ndarray, tol: float) -> np.ndarray:
    """Which of ``rows`` (W holds their coefficients) are stationary to ``tol``: the gradient alone, no Newton
    system formed."""
    out = np.empty(len(rows), dtype=bool)
    for part, gp, den, _curvature in model.derivatives(rows, W):
        out[part] = _optimality(gp, den, W[part], tol)[2]
    return out


def _restricted_newton(curvature: _Curvature, sel: np.ndarray, g: np.ndarray, act: np.ndarray, safe: np.ndarray,
                       ridge: np.ndarray, systems: list | None = None, known: list | None = None) -> np.ndarray:
    """Each row's step: the Newton step of its free coefficients, the curvature-scaled gradient of the active ones.

    The free coefficients' system is scaled by their curvatures (``safe``) to a unit diagonal,
    where ``ridge`` (one per row) is added (Levenberg-Marquardt with Marquardt's scaling): its
    solution does not depend on the coefficients' units, however far apart their curvatures.
    The free coefficients are moved first (a stable sort keeps their order), and only the
    leading block of the largest free count is formed and solved: with many coefficients held at
    zero, far smaller systems than (k, k). ``sel`` are the rows of ``curvature``'s block that
    ``g``, ``act``, ``safe`` and ``ridge`` hold.

    ``systems`` (a list, one entry per row) receives each row's scaled system and its free
    coefficients; ``known``, such entries of a first solve of the same rows with the same
    ``safe`` and ``ridge``, where every coefficient free now was free then (the caller's
    guarantee, not checked): the systems are then read from them (their rows and columns of the
    coefficients still free) instead of formed, equal to those formed again up to the rounding of
    the products that form them.
    """
    k = g.shape[1]
    n_free = k - act.sum(axis=1)
    with np.errstate(over="ignore"):
        d = g / safe  # the active coefficients' step (and every coefficient's when none is free)
    order = np.argsort(act, axis=1, kind="stable")  # each row's free coefficients first
    # rows solved by groups of similar free counts (each padded to its largest: the cost grows as its cube)
    size = np.ceil(np.log(np.maximum(n_free, 1)) / np.log(_GROUPING))
    for key in np.unique(size[n_free > 0]):
        group = np.flatnonzero((size == key) & (n_free > 0))
        f = int(n_free[group].max())
        rows_order = order[group, :f]
        free = np.arange(f) < n_free[group, None]  # the leading block holds active ones in rows with fewer free
        unit = 1.0 / np.sqrt(np.take_along_axis(safe[group], rows_order, axis=1))
        idx = np.arange(f)
        if known is None:
            sub = curvature.block(rows_order, sel[group])
            sub *= free[:, :, None] & free[:, None, :]
            sub *= unit[:, :, None]  # |H_ij| <= sqrt(H_ii H_jj): one factor at a time, nothing overflows
            sub *= unit[:, None, :]
            # free coefficients: the ridge; active ones: their own curvature (1 once scaled)
            sub[:, idx, idx] = np.where(free, sub[:, idx, idx] + ridge[group, None], 1.0)
            if systems is not None:
                for j, i in enumerate(group):
                    systems[i] = (sub[j, :n_free[i], :n_free[i]], rows_order[j, :n_free[i]])
        else:
            sub = np.zeros((len(group), f, f))
            sub[:, idx, idx] = 1.0
            for j, i in enumerate(group):
                system, then = known[i]
                still = np.flatnonzero(~act[i, then])  # (the free coefficients keep their order)
                sub[j, :still.size, :still.size] = system[np.ix_(still, still)]
        rhs = (np.take_along_axis(g[group], rows_order, axis=1) * unit)[:, :, None]
        step = np.linalg.solve(sub, rhs)[:, :, 0] * unit
        rows_d = d[group]
        np.put_along_axis(rows_d, rows_order, step, axis=1)
        d[group] = rows_d
    return d


def determined_rows(X, H: np.ndarray, beta: float, *, mask=None, penalty: Penalty | None = None) -> np.ndarray:
    """Which rows have one minimiser: a strictly convex problem in w (boolean, one per row of X).

    With an L2 penalty, every row. Otherwise the atoms that see the features (the rows of H
    that are not all zero; the others' coefficients do not enter the objective) must be
    linearly independent, to within a condition number of 1e6, and each row must observe at
    least as many cells as there are such atoms (the objective depends on w only through the
    observed cells of w H); under the I-divergence (beta = 1), as many observed cells where
    x > 0, since a cell where x = 0 adds (w H)_j, linear in w, to the objective. Elsewhere (more
    atoms than the features can tell apart, as with a dictionary of 150 atoms seen through 3
    features) the minimisers form a set, and the updates' coefficients are kept as one of its
    points.
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
    if beta == 1.0:  # a cell with x = 0 adds (w H)_j, linear in w: no curvature
        observed = X if mask is None else (X.multiply(mask) if sp.issparse(X) else np.where(mask, X, 0.0))
        return _count_per_row(observed) >= k
    if mask is None:
        return np.ones(n, dtype=bool)
    return _count_per_row(mask) >= k


def _count_per_row(A) -> np.ndarray:
    """The nonzero entries of each row of A (dense or sparse)."""
    if sp.issparse(A):
        A = sp.csr_matrix(A)
        A.eliminate_zeros()
        return np.diff(A.indptr)
    return np.count_nonzero(A, axis=1)


def _project_newton(model: _Rows, W: np.ndarray, rows: np.ndarray, max_iter: int,
                    tol: float) -> tuple[np.ndarray, bool]:
    """Projected Newton steps with an Armijo search along the projection arc, each row until it is optimal."""
    f_all = np.empty(W.shape[0])
    f_all[rows] = model.objective(rows, W[rows])
    ridge_all = np.full(W.shape[0], _RIDGE)
    settled = np.zeros(W.shape[0], dtype=bool)
    for _ in range(max_iter):
        # Optimal to tol (where the objective no longer resolves the decreases the line search needs): full
        # Newton steps, converging quadratically; settled when one moves no coefficient by more than tol times the
        # row's largest (a flat minimum can meet tol far from its optimum: the step measures that distance), and
        # done when the point it reached is stationary (the step moves the free coefficients to the minimum of
        # the quadratic model at the held ones' old values, which the same step may zero; a coefficient below tol
        # times the largest is within the step's resolution): read from the gradient alone, before any Newton
        # system is formed
        if settled[rows].any():
            check = rows[settled[rows]]
            settled[check] = False
            rows = rows[~np.isin(rows, check[_stationary_rows(model, check, W[check], tol)])]
        if rows.size == 0:
            return W, True
        Wr, f, ridge = W[rows], f_all[rows], ridge_all[rows]
        g, den, d, active, optimal, factor, slope = _newton_directions(model, rows, Wr, tol, ridge)
        kept: list = []  # the products of Wr, formed on first use and read back by every trial's collapse test

        def start_products(sel):
            if not kept:
                kept.append(model.products(rows, Wr))
            return None if kept[0] is None else kept[0][sel]

        newtonian = ridge < 2.0 * _NEWTON_RIDGE  # (the ridge moves by factors of ten, not exactly)
        newton = optimal & newtonian
        # beta < 2: the held coefficients shrink by at most 2 _COLLAPSE per searched step (see there); a full step
        # takes them to zero exactly unless that collapses a cell with x > 0
        floor = np.where(active, 2.0 * _COLLAPSE * Wr, 0.0) if model.beta < 2.0 else np.zeros_like(Wr)
        full = np.maximum(Wr[newton] - d[newton], 0.0)
        if model.beta < 2.0 and full.size:
            # the objective read infinite where the step collapses a cell (and where it is infinite anyway): those
            # rows' held coefficients stop at the floor instead, and their objective is evaluated again
            f_full = model.objective(rows[newton], full, Wr[newton], start_products(newton))
            collapsing = ~np.isfinite(f_full)
            full[collapsing] = np.maximum(Wr[newton] - d[newton], floor[newton])[collapsing]
            f_full[collapsing] = model.objective(rows[newton][collapsing], full[collapsing])
        else:
            f_full = model.objective(rows[newton], full)
        size = np.maximum(np.abs(full).max(axis=1), np.abs(Wr[newton]).max(axis=1))
        # a full step that raises the objective beyond its rounding (the held coefficients zeroed at once can, where
        # the quadratic model is not the objective) is searched instead, like any other step: taken, rows can cycle
        with np.errstate(invalid="ignore"):
            raised = np.isfinite(f[newton]) & ~(f_full <= f[newton] + _RESOLUTION * np.abs(f[newton]))
        full_rows = np.flatnonzero(newton)
        W[rows[full_rows[~raised]]] = full[~raised]
        f_all[rows[full_rows[~raised]]] = f_full[~raised]
        short = ~raised & (np.abs(full - Wr[newton]).max(axis=1) <= tol * size)
        settled[rows[full_rows[short]]] = True
        newton[full_rows[raised]] = False
        done = np.zeros(rows.size, dtype=bool)
        pending = np.flatnonzero(~newton)
        alpha = np.ones(pending.size)
        todo = np.arange(pending.size)
        stuck = np.zeros(pending.size, dtype=bool)
        for _ in range(_HALVINGS):
            if todo.size == 0:
                break
            p = pending[todo]
            trial = np.maximum(Wr[p] - alpha[todo, None] * d[p], floor[p])
            climbing = factor[p] != 1.0
            trial[climbing] = (Wr[p] * factor[p] ** alpha[todo, None])[climbing]
            ft = model.objective(rows[p], trial, Wr[p], start_products(p))
            # Armijo along the projection arc: the decrease the gradient predicts from the active ones' actual move,
            # and the free coefficients' Newton step against its own right-hand side (the gradient where the active
            # ones land, where the model forms the Hessian's product: the quadratic model's decrease along it, which
            # the raw gradient can understate)
            predicted = np.where(active[p], g[p] * (Wr[p] - trial), alpha[todo, None] * slope[p] * d[p]).sum(axis=1)
            # from an infinite objective (beta = 1, a cell whose product underflowed to 0), any finite one is progress
            with np.errstate(invalid="ignore"):
                ok = np.isfinite(ft) & (~np.isfinite(f[p]) | (f[p] - ft >= _SIGMA * predicted))
                # a decrease the objective's rounding hides: halving further only makes it smaller
                hidden = ~ok & np.isfinite(f[p]) & (predicted <= _RESOLUTION * np.abs(f[p]))
            W[rows[p[ok]]] = trial[ok]
            f_all[rows[p[ok]]] = ft[ok]
            stuck[todo[hidden]] = True
            todo = todo[~ok & ~hidden]
            alpha[todo] *= 0.5
        # climbing coefficients after a full step (or one too small to see): their factor compounded while the
        # objective falls (a coefficient 20 orders of magnitude below its optimum climbs in a few steps)
        full_or_hidden = np.flatnonzero(((alpha == 1.0) & ~np.isin(np.arange(pending.size), todo)) | stuck)
        lift = full_or_hidden[(factor[pending[full_or_hidden]] != 1.0).any(axis=1)]
        if lift.size:
            rose = _compound(model, rows[pending[lift]], W, f_all, Wr[pending[lift]], factor[pending[lift]])
            stuck[lift[rose]] = False
            alpha[lift[rose]] = 1.0
        # a decrease the objective cannot resolve along Newton's own step: stationary up to rounding; along a step
        # the ridge damped: a failed search, as one that ran out of halvings
        done[pending[stuck & newtonian[pending]]] = True
        stuck &= ~newtonian[pending]
        alpha[stuck] = 0.0
        todo = np.union1d(todo, np.flatnonzero(stuck))
        # no decrease along the arc even at the largest ridge
        r = rows[pending[todo]]
        failed = pending[todo][ridge_all[r] >= 1.0]
        # Levenberg-Marquardt: a row whose full step was taken trusts Newton more, one that needed halvings less
        r = rows[pending]
        ridge_all[r] = np.where(alpha == 1.0, np.maximum(ridge_all[r] / 10.0, _RIDGE), ridge_all[r])
        ridge_all[r] = np.where(alpha < 0.125, np.minimum(ridge_all[r] * 100.0, 1.0), ridge_all[r])
        # a failed search is no sign of a minimum (the arc can fail where held coefficients shrink at every step
        # length): the row takes multiplicative updates, kept where they lower its objective, and Newton's steps
        # again from where they lead; a row they do not lower beyond its rounding is stationary up to rounding
        if failed.size:
            lowered = _fall_back(model, rows[failed], W, f_all)
            ridge_all[rows[failed[lowered]]] = _RIDGE
            done[failed[~lowered]] = True
        rows = rows[~done]
    return W, rows.size == 0


def _fall_back(model: _Rows, rows: np.ndarray, W: np.ndarray, f_all: np.ndarray) -> np.ndarray:
    """:data:`_FALLBACK_UPDATES` multiplicative updates of ``rows`` (thesis eq. 2.15-2.16, w <- w num / den with
    g = den - num), kept where they lower the row's objective by more than its rounding (:data:`_RESOLUTION`; W and
    f_all updated in place); which rows.

    For 1 <= beta <= 2, without an L2 penalty, each update is a majorisation-minimisation step (Fevotte & Idier
    2011) and never raises the objective; with one (its term in the denominator is a majorisation only at
    beta = 2) the updates can oscillate, and the objective decides whether they are kept.
    """
    V = W[rows]
    with np.errstate(all="ignore"):  # a factor that overflows makes the row's objective infinite: not kept
        for _ in range(_FALLBACK_UPDATES):
            for part, g, den, _curvature in model.derivatives(rows, V):
                V[part] *= np.where(den > 0, (den - g) / np.where(den > 0, den, 1.0), 1.0)
        f = model.objective(rows, V)
        lowered = np.isfinite(f) & np.isfinite(V).all(axis=1) & (f < f_all[rows] - _RESOLUTION * np.abs(f_all[rows]))
    W[rows[lowered]] = V[lowered]
    f_all[rows[lowered]] = f[lowered]
    return lowered


def _compound(model: _Rows, rows: np.ndarray, W: np.ndarray, f_all: np.ndarray, start: np.ndarray,
              factor: np.ndarray) -> np.ndarray:
    """The climbing coefficients (``factor`` != 1) of ``rows`` at ``start`` times factor^2, ^4, ... while each
    power leaves the row's objective no higher (W and f_all updated in place); which rows moved.

    No higher rather than lower: a coefficient far below its optimum changes the objective by less than its
    rounding until it has climbed most of the way."""
    climbing = factor != 1.0
    rose = np.zeros(len(rows), dtype=bool)
    todo = np.arange(len(rows))
    power = 2.0
    for _ in range(_COMPOUNDINGS):
        if todo.size == 0:
            break
        now = W[rows[todo]]
        trial = now.copy()
        with np.errstate(over="ignore", invalid="ignore"):
            trial[climbing[todo]] = (start[todo] * factor[todo] ** power)[climbing[todo]]
        # a power that overflows stops the row's compounding (its objective is not evaluated)
        ft = np.full(todo.size, np.inf)
        finite = np.isfinite(trial).all(axis=1)
        ft[finite] = model.objective(rows[todo[finite]], trial[finite], now[finite])
        with np.errstate(invalid="ignore"):
            lower = np.isfinite(ft) & (ft <= f_all[rows[todo]])
        W[rows[todo[lower]]] = trial[lower]
        f_all[rows[todo[lower]]] = ft[lower]
        rose[todo[lower]] = True
        todo = todo[lower]
        power *= 2.0
    return rose


def solve_coefficients(X, H: np.ndarray, W: np.ndarray, beta: float, *, mask=None, penalty: Penalty | None = None,
                       max_iter: int = 100, tol: float = 1e-7) -> tuple[np.ndarray, bool]:
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
        Newton steps at most.
    tol : float, default=1e-7
        Optimality: the factor of the multiplicative update, num / den with g = den - num, is at
        most 1 + ``tol``, and at least 1 - ``tol`` where w is more than ``tol`` times the row's
        largest coefficient. From there a row takes full Newton steps, and stops after one that
        moves no coefficient by more than ``tol`` times its largest and leaves it optimal.

    Returns
    -------
    W : ndarray of shape (n_samples, n_components), W's dtype
    converged : bool
        Whether every row stopped before ``max_iter``.
    """
    penalty = penalty or Penalty()
    dtype = W.dtype
    # Homogeneity, d(c x | c y) = c^beta d(x | y): the problem on X / a and H / b (powers of two, exact) has the
    # solution W b / a, and data at any scale is solved as data near 1 is.
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
    out, converged = _project_newton(model, W0, rows, max_iter, tol)
    return (out * (a / b)).astype(dtype, copy=False), converged
