"""The beta-NMF solvers and the :func:`beta_nmf` function (thesis section 2.1.2-2.1.3)."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
import scipy.sparse as sp

from .._validation import check_random_state, validate_params
from ..errors import ConvergenceWarning, DataError, ParameterError
from ._beta import check_beta_zeros, mm_exponent, resolve_beta
from ._init import check_given_start, initialize
from ._data import check_factor, is_dask_array, validate_data
from ._problem import Problem, Side
from ._updates import (
    BETA_NMF_CONSTRAINTS,
    SOLVERS,
    NMFResult,
    Penalty,
    check_fit_in_range,
    check_objective_range,
    constant_coefficients,
    data_scale,
    in_units_of_X,
    infinite_objective_cause,
    mu_update,
    resolve_penalties,
    scale_penalties,
    sparse_kl_applies,
    sparse_kl_update,
    stopped_message,
)
from .sparseness import l1_for_sparseness, project_hoyer

__all__ = ["beta_nmf", "BETA_NMF_CONSTRAINTS", "NMFResult", "SOLVERS"]


@dataclass
class _Hoyer:
    """Hoyer's constraint on the columns of one stored factor (W or Ht)."""

    sparseness: float
    keep_norm: bool  # True: coefficients keep their L2 norms; False: atoms have unit L2 norm

    def project(self, L: np.ndarray) -> np.ndarray:
        out = np.empty_like(L)
        n = L.shape[0]
        for c in range(L.shape[1]):
            col = L[:, c].astype(np.float64)
            l2 = float(np.linalg.norm(col)) if self.keep_norm else 1.0
            if l2 == 0.0 or n < 2:
                out[:, c] = col
                continue
            out[:, c] = project_hoyer(col, l1_for_sparseness(self.sparseness, n, l2), l2)
        return out


class _Solver:
    """Alternating updates of the two stored factors W (side 0) and Ht (side 1)."""

    def __init__(self, problem: Problem, beta: float, solver: str, update_rule: str,
                 penalties: tuple[Penalty, Penalty], hoyer: tuple[_Hoyer | None, _Hoyer | None]):
        self.problem = problem
        self.beta = beta
        self.solver = solver
        self.update_rule = update_rule
        self.gamma = mm_exponent(beta) if update_rule == "mm" else 1.0
        self.penalties = penalties
        self.hoyer = hoyer
        self.step = [1.0, 1.0]  # per-side step sizes of the gradient solvers, carried across iterations
        # per side, (R, R's column sums or None) when R stays fixed across this solver's updates
        self.fixed: list[tuple[np.ndarray, np.ndarray | None] | None] = [None, None]
        # per side, (R, R's column sums) as the update that last changed R summed it
        self.sums: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]
        self.last_divergence = float("nan")  # the divergence part of the last objective evaluated
        self.objective_next = False  # the objective is evaluated after the next update of side 1

    # -- objective -------------------------------------------------------------------
    def objective(self, W: np.ndarray, Ht: np.ndarray) -> float:
        self.last_divergence = self.problem.divergence(W, Ht, self.beta)
        return self.last_divergence + self.penalties[0].value(W) + self.penalties[1].value(Ht)

    def _side_objective(self, s: int, L: np.ndarray, R: np.ndarray) -> float:
        side = self.problem.sides[s]
        return side.divergence(L, R, self.beta) + self.penalties[s].value(L)

    def objective_in_update(self) -> bool:
        """Whether :meth:`update_W_with_objective` applies: W's multiplicative update, W unpenalised and
        unconstrained, and either the I-divergence on a sparse, unmasked X (the update forms every product the
        objective needs) or a beta outside {0, 1, 2} on a dense float64 X (the update forms Y and Y^(beta-1))."""
        side, pen = self.problem.sides[0], self.penalties[0]
        if self.solver != "mu" or self.hoyer[0] is not None:
            return False
        if sparse_kl_applies(side, self.beta, self.gamma, pen):
            return True
        return (not side.sparse and self.beta not in (0.0, 1.0, 2.0) and not (pen.l1 or pen.l2)
                and self.problem.dtype == np.float64)

    def update_W_with_objective(self, W: np.ndarray, Ht: np.ndarray) -> float:
        """W's update in place (:meth:`update`); returns the objective of (W, Ht) before it, as :meth:`objective`
        would, to rounding (where :meth:`objective_in_update`)."""
        side = self.problem.sides[0]
        if side.sparse:
            self.last_divergence = self._sparse_kl(0, W, Ht, divergence=True)
        else:
            side.want_divergence, side.found_divergence = True, None
            try:
                self.update(0, W, Ht)
            finally:
                side.want_divergence = False
            found, side.found_divergence = side.found_divergence, None
            if found is None:  # a W of another type than the problem's (not made by this module)
                raise RuntimeError(f"W's update did not evaluate the divergence: W is {W.dtype}, the problem "
                                   f"{self.problem.dtype}; expected both float64")
            self.last_divergence = found
        return self.last_divergence + self.penalties[1].value(Ht)  # W is unpenalised

    def _sum(self, s: int, R: np.ndarray) -> np.ndarray | None:
        """R's column sums where they are known: R fixed across this solver's updates of side s (computed once), or
        summed by the update that last changed R; else None."""
        fixed = self.fixed[s]
        if fixed is not None and fixed[0] is R:
            if fixed[1] is None:
                fixed = self.fixed[s] = (R, R.sum(axis=0))
            return fixed[1]
        known = self.sums[s]
        return known[1] if known is not None and known[0] is R else None

    def _sparse_kl(self, s: int, L: np.ndarray, R: np.ndarray, divergence: bool = False) -> float:
        """Side s's one-pass I-divergence update of L in place, keeping L's column sums for the other side's next
        update; returns the divergence before it with ``divergence`` (NaN otherwise)."""
        self.sums[1 - s] = None
        f, sums = sparse_kl_update(self.problem.sides[s], L, R, self._sum(s, R), divergence)
        if sums is not None:
            self.sums[1 - s] = (L, sums)
        return f

    # -- one update of the left factor of side s -------------------------------------
    def update(self, s: int, L: np.ndarray, R: np.ndarray) -> np.ndarray:
        side = self.problem.sides[s]
        side.keep_numerator = s == 1 and self.objective_next
        self.sums[1 - s] = None  # L changes: the sums known of it no longer hold
        hoyer = self.hoyer[s]
        if hoyer is not None:
            return self._hoyer_step(s, side, L, R, hoyer)
        if self.solver == "pg":
            return self._pg_step(s, side, L, R)
        if sparse_kl_applies(side, self.beta, self.gamma, self.penalties[s]):
            self._sparse_kl(s, L, R)
            return L
        known = self.fixed[s]
        fixed = known is not None and known[0] is R
        return mu_update(side, L, R, self.beta, self.gamma, self.penalties[s], self._sum(s, R), fixed)

    def _gradient(self, s: int, side: Side, L: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Gradient of the side objective in L (thesis eq. 2.11-2.13): D - N + penalties."""
        num, den = side.numerator_denominator(L, R, self.beta)
        return self.penalties[s].add_to(den, L) - num

    def _pg_step(self, s: int, side: Side, L: np.ndarray, R: np.ndarray,
                 n_inner: int = 5, sigma: float = 0.01, shrink: float = 0.1) -> np.ndarray:
        """Projected gradient (thesis eq. 2.9-2.10) with Lin's (2007) Armijo rule along the projection arc.

        A trial point L' is accepted when f(L') - f(L) <= sigma <grad, L' - L>. Under the unmasked
        Frobenius loss the side objective is quadratic in L, so, with D = L' - L,

        .. math::
            f(L') - f(L) = \\langle \\nabla f, D \\rangle + \\tfrac12 \\langle D, D (R^T R) + l_2 D \\rangle

        (Lin's form of the condition for quadratic sub-problems): each trial costs a (rows x k x k) product
        instead of the (rows x columns x k) product of evaluating the divergence, and is free of the
        cancellation of two objectives that nearly agree. Other losses evaluate the objective.
        """
        l2 = self.penalties[s].l2
        gram = R.T @ R if self.beta == 2.0 and side.mask is None and side.weights is None else None
        f_at: float | None = None  # the side objective at L, when the accepted trial evaluated it
        for _ in range(n_inner):
            grad = self._gradient(s, side, L, R)
            f0 = (self._side_objective(s, L, R) if f_at is None else f_at) if gram is None else 0.0
            alpha = self.step[s]

            def trial(a: float, L=L, grad=grad, f0=f0):
                Ln = np.maximum(L - a * grad, 0.0).astype(L.dtype, copy=False)
                D = Ln - L
                slope = float(np.sum(grad * D, dtype=np.float64))
                fn = None
                if gram is None:  # f0 may be infinite (beta <= 1, W @ H zero where X > 0): leaving it is a decrease
                    fn = self._side_objective(s, Ln, R)
                    ok = bool(np.isfinite(fn)) and fn - f0 <= sigma * slope
                else:
                    change = _quadratic_change(slope, D, gram, l2)
                    ok = bool(np.isfinite(change)) and change <= sigma * slope
                return ok, Ln, fn

            ok, Ln, fn = trial(alpha)
            if ok:  # grow the step while the Armijo condition holds
                for _ in range(20):
                    a2 = alpha / shrink
                    ok2, Ln2, fn2 = trial(a2)
                    if not ok2 or np.array_equal(Ln2, Ln):
                        break
                    alpha, Ln, fn = a2, Ln2, fn2
            else:  # shrink until it holds
                for _ in range(40):
                    alpha *= shrink
                    ok, Ln, fn = trial(alpha)
                    if ok:
                        break
                if not ok:
                    return L  # no decrease along the gradient: L is (numerically) stationary
            self.step[s] = alpha
            L, f_at = Ln, fn  # the next inner step starts where this one's objective is known (same side, same R)
        return L

    def _hoyer_step(self, s: int, side: Side, L: np.ndarray, R: np.ndarray, hoyer: _Hoyer) -> np.ndarray:
        """Hoyer's (2004) gradient step followed by the sparseness projection of each vector."""
        grad = self._gradient(s, side, L, R)
        f0 = self._side_objective(s, L, R)
        mu = self.step[s]
        for _ in range(50):
            Ln = hoyer.project(np.maximum(L - mu * grad, 0.0)).astype(L.dtype, copy=False)
            fn = self._side_objective(s, Ln, R)
            if np.isfinite(fn) and fn <= f0:
                self.step[s] = mu * 1.2
                return Ln
            mu /= 2.0
        self.step[s] = mu
        return L


def _quadratic_change(slope: float, D: np.ndarray, gram: np.ndarray, l2: float) -> float:
    """f(L + D) - f(L) for a side objective quadratic in L (the unmasked Frobenius loss).

    f(L) = ||X - L R^T||^2 / 2 + l1 sum(L) + l2 ||L||^2 / 2 has the gradient G = L R^T R - X R
    + l1 + l2 L and the constant Hessian D -> D R^T R + l2 D, so that f(L + D) - f(L) =
    <G, D> + <D, D R^T R + l2 D> / 2 exactly.

    Parameters
    ----------
    slope : float
        <G, D>.
    D : ndarray of shape (rows, k)
    gram : ndarray of shape (k, k)
        R^T R.
    l2 : float
        The penalty's l2 weight (0: none).
    """
    curvature = D @ gram
    if l2:
        curvature += l2 * D
    return slope + 0.5 * float(np.sum(D * curvature, dtype=np.float64))


def _physical_memory() -> int | None:
    """Bytes of physical memory (None where the platform does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _check_fits_in_memory(n: int, m: int, k: int, dtype: np.dtype) -> None:
    """Refuse a factorization whose arrays cannot fit in memory before allocating them.

    The updates hold W (n, k) and H (k, m) with temporaries of the same shapes (about four
    of each) and, for the Frobenius loss, the (k, k) Gram matrices: an absurd
    ``n_components`` would otherwise fail deep inside numpy or exhaust the machine.
    """
    total = _physical_memory()
    need = (4 * (n + m) * k + 2 * k * k) * np.dtype(dtype).itemsize
    if total is not None and need > total:
        raise ParameterError(
            f"n_components={k} on a {n} x {m} matrix needs about {need / 2**30:.3g} GiB for W, H, their updates and "
            f"the (k, k) Gram matrices, more than this machine's {total / 2**30:.3g} GiB; choose a smaller "
            "n_components (the thesis uses tens to hundreds)."
        )


def beta_nmf(
    X: Any,
    n_components: int | None = None,
    *,
    beta_loss: float | str = 2.0,
    solver: Literal["mu", "pg"] = "mu",
    update_rule: Literal["mm", "heuristic"] = "mm",
    init: str | None = None,
    W: np.ndarray | None = None,
    H: np.ndarray | None = None,
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
) -> NMFResult:
    """Factorize a nonnegative matrix: X ~ W @ H, minimizing a beta-divergence.

    X is (n_samples, n_features); ``H`` (n_components, n_features) is the dictionary,
    one atom per row, and ``W`` (n_samples, n_components) the coefficients. The thesis
    writes V ~ W H with examples as columns: its V, W, H are our X.T, H.T, W.T.

    .. math::
        \\min_{W, H \\ge 0}\\ D_\\beta(X | WH) + \\lambda^{(1)}_W \\|W\\|_1
        + \\tfrac{1}{2}\\lambda^{(2)}_W \\|W\\|_F^2 + \\lambda^{(1)}_H \\|H\\|_1
        + \\tfrac{1}{2}\\lambda^{(2)}_H \\|H\\|_F^2

    with :math:`D_\\beta` of thesis eq. (2.2)-(2.3), optionally restricted to observed
    cells, and optionally under Hoyer's sparseness constraints (eq. 2.20).

    Parameters
    ----------
    X : {array-like, sparse matrix, dask.array.Array} of shape (n_samples, n_features)
        Nonnegative data. A sparse X is never densified: the product WH is evaluated
        at its nonzeros only (numba kernels), and with the multiplicative updates its
        all-zero columns, whose H columns the first update sets to 0, are left out of
        the later iterations (same iterates up to the order of sums). A dask array of row chunks (dense or
        scipy.sparse chunks, one chunk of all the columns) is fitted chunk by chunk on
        dask's current scheduler, never gathered (see Notes).
    n_components : int, optional
        Number of atoms k. Default: min(n_samples, n_features), or H's when given.
    beta_loss : float or {'frobenius', 'kullback-leibler', 'itakura-saito'}, default=2
        Any real beta. beta <= 0 requires X > 0 on observed cells.
    solver : {'mu', 'pg'}, default='mu'
        ``'mu'``: multiplicative updates (thesis eq. 2.15-2.19), W then H at each
        iteration as scikit-learn. ``'pg'``: alternating projected gradient (eq. 2.9-2.13)
        with Armijo step sizes along the projection arc (Lin 2007).
    update_rule : {'mm', 'heuristic'}, default='mm'
        ``'mm'`` raises the multiplicative factor to gamma(beta) of Table 2.2, which
        guarantees that the objective never increases (with no L2 penalty: an L2 penalty's
        gradient is added to the denominator as scikit-learn does, and with a strong one the
        objective can rise); ``'heuristic'`` uses exponent 1 (eq. 2.17), the same for
        1 <= beta <= 2.
    init : {'random', 'nndsvd', 'nndsvda', 'nndsvdar', 'custom'}, optional
        Default: 'nndsvda' if n_components <= min(X.shape), else 'random'; 'custom'
        (or giving W and H) starts from W and H. 'nndsvd' keeps the zeros of NNDSVD except
        those that leave W @ H zero at an observed cell of X > 0: the multiplicative updates
        never move a zero, so such a cell would never be fitted (for beta <= 1 its divergence,
        and the objective, would stay infinite); in their rows of W and columns of H, zeros
        are filled with the mean of X, as 'nndsvda' fills them all.
    W, H : ndarray, optional
        Starting factors (copied). With ``update_H=False``, H is required and kept fixed.
        Their zeros stay zero under the multiplicative updates (a support the fit keeps). A
        factor that is all zero is refused, and so, for beta <= 1, is a start whose zeros leave
        W @ H zero at an observed cell of X > 0 for the whole fit (its divergence is infinite).
    update_H : bool, default=True
        False fits only W with the dictionary H fixed.
    mask : {array-like of bool, sparse matrix, dask.array.Array} of shape (n_samples, n_features), optional
        True where X is observed. Unobserved cells have no influence at all: the
        updates and the loss are weighted by the mask, and their values (NaN included)
        are ignored. With a dask X: a dask array with X's chunks, or an in-memory mask.
    max_iter : int, default=200
    tol : float, default=1e-4
        Stop when the error sqrt(2 * objective), evaluated every ``loss_every``
        iterations, has decreased by less than ``tol`` times its initial value since the
        last check (scikit-learn's rule). 0 runs exactly ``max_iter`` iterations.
    alpha_W, alpha_H, l1_ratio : float
        L1/L2 penalties, with scikit-learn's meaning and scaling (alpha_W is multiplied by
        n_features, alpha_H by n_samples; ``alpha_H='same'`` takes alpha_W).
    sparseness_W, sparseness_H : float in [0, 1], optional
        Hoyer's constraints (eq. 2.20): every atom (row of H) is projected to unit L2
        norm and this sparseness; every column of W (one component's activations across
        samples, a row of the thesis' H) keeps its L2 norm at this sparseness. A
        constrained factor is updated by projected gradient steps (Hoyer 2004).
    loss_every : int, default=10
        Evaluate (and record) the objective every this many iterations.
    random_state : int, numpy.random.Generator or None
        Seeds the random and NNDSVD initialisations.

    Returns
    -------
    NMFResult
        W, H, n_iter, loss_history, loss_iterations, converged, and ``extra['divergence']``
        the divergence of the final factors (``loss_history[-1]`` without the penalties). For a
        dask X, W is a dask array with X's row chunks (held by the cluster).

    Notes
    -----
    A dask array X is fitted by row chunks (``mmconcepts.nmf._dask``): each chunk's rows of W
    are updated where the chunk lives, and the numerator and denominator of the H update
    (eq. 2.16), sums over rows, are summed over the chunks in a tree; one pass over X per
    iteration. From the same start the iterates are those of the in-memory fit up to the order
    of the sums, for every option but ``solver='pg'`` and the Hoyer constraints (refused);
    'random' draws the same start; the NNDSVD starts use dask's randomized SVD
    (``dask.array.linalg.svd_compressed``), which approximates the in-memory SVD with other
    random draws. X is checked in a first pass; an error names the chunk. Out of core, see
    ``mmconcepts.nmf.beta_nmf_out_of_core``.

    The multiplicative updates set to zero an entry of W or H that they lower below the
    smallest normal number (2.2e-308 in float64), or below its square root (1.5e-154) for a
    factor updated by the sparse I-divergence kernel (X sparse, no mask, that factor
    unpenalised): a product that underflows, or that has a subnormal operand, costs the
    processor about a hundred times an ordinary one, and such entries change no product by more
    than that bound times k times the other factor's largest entry. Entries that an update raises
    are kept however small, so underflows become rarer, not impossible.

    Beta-divergences are homogeneous, :math:`d_\\beta(c x | c y) = c^\\beta d_\\beta(x | y)`, so
    the fit of c X from (W0, c H0) is (W, c H) up to rounding (c W with ``update_H=False`` or
    ``sparseness_H``), and the objective scales by :math:`c^\\beta`. (The 'random' start
    scales both factors by sqrt(c), which changes only the diagonal scaling of the result;
    'nndsvda' fills the zeros of its SVD start with the mean of X, as scikit-learn, which is not
    scale-equivariant.) X whose largest value lies outside about [1e-3, 1e6] (a narrower
    upper bound for beta > 5 or beta < -3) is divided by a power of two for the updates (exactly) and the
    result scaled back, so that the clipping of W H at machine epsilon and overflow do not
    depend on the units of X; data in that range is fitted as given. ``loss_history`` is in
    X's units.

    Raises
    ------
    DataError
        Negative, NaN or infinite values in observed cells, empty input, a mask or
        factor of the wrong shape, zeros with beta <= 0; an X whose objective float64
        cannot hold (e.g. Frobenius at 1e300); subnormal values next to ordinary ones with
        beta <= 1; Hoyer-projected starting factors with an infinite objective (beta <= 1); given
        starting factors that are all zero, or (beta <= 1) whose zeros leave W @ H zero where X > 0
        for the whole fit, naming the first such cell.
    ParameterError
        An unknown solver, init or update rule, or a value out of range; for a dask X,
        ``solver='pg'`` or Hoyer constraints.

    Warns
    -----
    ConvergenceWarning
        When ``tol`` > 0 is not met in ``max_iter`` iterations; when the objective is then
        infinite, the warning says why (the first cell where X > 0 and W @ H is 0) instead.
    """
    validate_params(
        dict(n_components=n_components, beta_loss=beta_loss, solver=solver, update_rule=update_rule, init=init,
             update_H=update_H, max_iter=max_iter, tol=tol, alpha_W=alpha_W, alpha_H=alpha_H, l1_ratio=l1_ratio,
             sparseness_W=sparseness_W, sparseness_H=sparseness_H, loss_every=loss_every, random_state=random_state),
        BETA_NMF_CONSTRAINTS, owner="beta_nmf")
    beta = resolve_beta(beta_loss)
    if is_dask_array(X) or is_dask_array(mask):  # distributed / out of core (nmf/_dask.py)
        if not is_dask_array(X):
            raise DataError(
                "mask is a dask array but X is not; give X as a dask array chunked like the mask "
                "(dask.array.from_array(X, chunks=mask.chunks)), or the mask in memory."
            )
        from ._dask import beta_nmf_dask

        return beta_nmf_dask(
            X, n_components, beta=beta, solver=solver, update_rule=update_rule, init=init, W=W, H=H,
            update_H=update_H, mask=mask, max_iter=int(max_iter), tol=float(tol), alpha_W=alpha_W, alpha_H=alpha_H,
            l1_ratio=l1_ratio, sparseness_W=sparseness_W, sparseness_H=sparseness_H, loss_every=int(loss_every),
            random_state=random_state)
    max_iter, loss_every, tol = int(max_iter), int(loss_every), float(tol)
    sparseness_W = None if sparseness_W is None else float(sparseness_W)
    sparseness_H = None if sparseness_H is None else float(sparseness_H)

    X, mask = validate_data(X, mask)
    check_beta_zeros(X, beta, mask)
    n, m = X.shape
    dtype = X.dtype

    if n_components is None:
        n_components = H.shape[0] if H is not None else (W.shape[1] if W is not None else min(n, m))
    k = int(n_components)
    _check_fits_in_memory(n, m, k, dtype)

    scale, scale_W, scale_H = _fit_scales(X, H, beta, update_H, sparseness_H)
    rescaled = scale != 1.0 or scale_H != 1.0
    if scale != 1.0:
        X = X / scale if sp.issparse(X) else np.divide(X, dtype.type(scale))
    given = not update_H or init == "custom" or (init is None and W is not None and H is not None)
    W, H = _starting_factors(X, mask, k, init, W, H, update_H, (scale_W, scale_H), random_state)
    if given:  # the zeros of a factor updated multiplicatively, or of a fixed H, stay zero
        frozen = (solver == "mu" and sparseness_W is None,
                  not update_H or (solver == "mu" and sparseness_H is None))
        check_given_start(X, W, H, beta, frozen=frozen, fixed_H=not update_H)

    pen_W, pen_H = resolve_penalties(alpha_W, alpha_H, l1_ratio, n, m)
    if rescaled:
        pen_W, pen_H = scale_penalties(pen_W, pen_H, scale, scale_W, scale_H, beta)
    hoyer = (
        None if sparseness_W is None else _Hoyer(sparseness_W, keep_norm=True),
        None if sparseness_H is None else _Hoyer(sparseness_H, keep_norm=False),
    )
    problem = Problem(X, mask)
    sol = _Solver(problem, beta, solver, update_rule, (pen_W, pen_H), hoyer)
    W, Ht = _projected_start(sol, hoyer, W, H, update_H)
    H = None  # the fit reads Ht only (the start it was copied from can be freed)
    f0 = None
    if rescaled:
        f0 = sol.objective(W, Ht)
        check_objective_range(f0, scale, beta)
    shrink = _EmptyColumns.of(problem) if (update_H and solver == "mu" and hoyer == (None, None)) else None
    W, Ht, n_iter, hist, its, converged, sol = _iterate(sol, W, Ht, update_H, max_iter, tol, loss_every, shrink, f0)
    check_fit_in_range(X, beta, W, Ht, hist)
    stopped = tol > 0 and not converged and max_iter > 0
    cause = infinite_objective_cause(X, W, Ht, beta, scale) if stopped and not np.isfinite(hist[-1]) else None
    divergence = sol.last_divergence  # of the final factors: the fit always ends on an evaluation
    del sol, problem, shrink  # their scratch buffers, before the result's copy of the dictionary
    if rescaled:  # back to X's units: D_beta(c x | c y) = c ** beta D_beta(x | y)
        hist = in_units_of_X(hist, scale, beta)
        divergence = float(in_units_of_X(divergence, scale, beta))
        W = W * dtype.type(scale_W)
        Ht = Ht * dtype.type(scale_H)
    if stopped:
        warnings.warn(stopped_message(max_iter, tol, hist[-1], cause), ConvergenceWarning, stacklevel=2)
    return NMFResult(W, np.ascontiguousarray(Ht.T), n_iter, hist, its, converged, {"divergence": divergence})


def _fit_scales(X, H, beta: float, update_H: bool, sparseness_H: float | None) -> tuple[float, float, float]:
    """The scales of a fit: X / scale, W = scale_W * W', H = scale_H * H', with scale_W * scale_H = scale.

    The fit runs on X / scale (scale = 1 for data at ordinary scales, else a power of two, so
    the division is exact): the scale goes into H, or into W when H has unit-norm atoms
    (sparseness_H); a fixed H (update_H=False) is brought to an ordinary scale of its own.
    """
    scale = data_scale(X, beta)
    if not update_H:
        scale_H = 1.0 if H is None else data_scale(np.asarray(H, dtype=float), beta)
    else:
        scale_H = 1.0 if sparseness_H is not None else scale
    return scale, scale / scale_H, scale_H


def _starting_factors(X, mask, k: int, init, W, H, update_H: bool, scales: tuple[float, float], random_state):
    """The starting (W, H) of a fit on the scaled X: given (checked, scaled), or initialised (``init``)."""
    n, m = X.shape
    dtype = X.dtype
    scale_W, scale_H = scales
    if not update_H:
        if H is None:
            raise ParameterError("update_H=False needs the fixed dictionary H.")
        H = check_factor(H, (k, m), "H", dtype) / dtype.type(scale_H)
        if W is None:
            W = constant_coefficients(X, H, mask)
        else:
            W = check_factor(W, (n, k), "W", dtype) / dtype.type(scale_W)
    elif init == "custom" or (init is None and W is not None and H is not None):
        if W is None or H is None:
            raise ParameterError("init='custom' needs both W and H.")
        W = check_factor(W, (n, k), "W", dtype)
        H = check_factor(H, (k, m), "H", dtype)
        W /= dtype.type(scale_W)
        H /= dtype.type(scale_H)
    else:
        if init is None:
            init = "nndsvda" if k <= min(n, m) else "random"
        W, H = initialize(X, k, init, check_random_state(random_state), mask=mask)
    return W, H


def _projected_start(sol: "_Solver", hoyer: tuple, W: np.ndarray, H: np.ndarray, update_H: bool):
    """(W, H.T) contiguous, projected onto Hoyer's constraints when there are any (the objective then checked)."""
    W = np.ascontiguousarray(W)
    Ht = np.ascontiguousarray(H.T)
    if hoyer[0] is not None:
        W = hoyer[0].project(W)
    if hoyer[1] is not None and update_H:
        Ht = hoyer[1].project(Ht)
    if hoyer[0] is not None or hoyer[1] is not None:
        f_start = sol.objective(W, Ht)
        if not np.isfinite(f_start):  # the Hoyer steps accept only a finite, not larger objective
            sparseness_W = None if hoyer[0] is None else hoyer[0].sparseness
            sparseness_H = None if hoyer[1] is None else hoyer[1].sparseness
            raise DataError(
                f"with sparseness_W={sparseness_W} and sparseness_H={sparseness_H} the projected starting factors "
                f"leave W @ H zero where X is not, and the beta={sol.beta:g} divergence is infinite there (beta <= 1). "
                "Use a lower sparseness, more components, or beta_loss > 1."
            )
    return W, Ht


class _EmptyColumns:
    """The features (columns of a sparse X) that hold no value, left out of the updates after the first one.

    A column of X that is all zero has a zero numerator in the multiplicative update of its
    column of H (eq. 2.16: only X's values enter it, whatever beta, penalty or update
    rule), so the first update of H sets that column to exactly 0 and it stays 0: from then
    on it adds exactly 0 to every sum the updates and the objective take over the features.
    Iterating on the other columns only gives the same iterates up to the order of those
    sums, and a sparse count matrix such as HAC (110 000 columns, most unseen in a small
    corpus) then costs in proportion to the columns it uses. Only for the multiplicative
    updates of both factors without a mask or Hoyer constraints, and only when the first
    update did zero every such column exactly (otherwise nothing is left out).
    """

    #: Leave columns out only when at least this share of them is empty (else the gain is not worth a copy of X).
    MIN_SHARE = 0.125

    def __init__(self, problem: Problem, keep: np.ndarray, empty: np.ndarray) -> None:
        self.problem, self.keep, self.empty = problem, keep, empty

    @classmethod
    def of(cls, problem: Problem) -> _EmptyColumns | None:
        X = problem.sides[0].X
        if not sp.issparse(X) or problem.mask is not None:
            return None
        counts = np.diff(problem.sides[1].X.indptr)  # stored values per feature (rows of X.T in CSR form)
        empty = np.flatnonzero(counts == 0)
        if len(empty) < cls.MIN_SHARE * X.shape[1] or len(empty) == X.shape[1]:
            return None
        return cls(problem, np.flatnonzero(counts > 0), empty)

    def reduce(self, sol: _Solver, Ht: np.ndarray) -> tuple[_Solver, np.ndarray] | None:
        """The solver on the used columns and their rows of Ht, or None if an empty column's row is not 0."""
        if np.any(Ht.sum(axis=1)[self.empty]):  # Ht >= 0: a row sums to 0 only when it is all 0 (NaN: kept)
            return None
        reduced = _Solver(Problem.used_columns(self.problem, self.keep), sol.beta, sol.solver, sol.update_rule,
                          sol.penalties, sol.hoyer)
        return reduced, np.ascontiguousarray(Ht[self.keep])

    def expand(self, Ht: np.ndarray) -> np.ndarray:
        """Ht of all the features: the used columns' rows, zeros elsewhere."""
        out = np.zeros((self.problem.shape[1], Ht.shape[1]), dtype=Ht.dtype)
        out[self.keep] = Ht
        return out


def _iterate(sol: _Solver, W, Ht, update_H: bool, max_iter: int, tol: float, loss_every: int,
             shrink: _EmptyColumns | None = None, f0: float | None = None):
    """Alternate W and H updates; record the objective every ``loss_every`` iterations.

    With ``shrink``, the all-zero columns of X are left out after the first iteration (see
    :class:`_EmptyColumns`) and put back, as zero rows of Ht, at the end. Returns
    (W, Ht, n_iter, objectives, their iterations, converged, the solver of the last iterations).
    ``f0``: the objective of the start, when the caller has evaluated it.

    Where W's update forms every product the objective needs (:meth:`_Solver.objective_in_update`),
    the objective of an iterate is read from the next iteration's W update, and the fit stops there
    (W as it was before that update) when the stopping rule says so: the same iterates as evaluating
    it apart, the objectives equal to rounding (so the stopping iteration is the same unless a
    decrease falls within that rounding of ``tol``); the last iterate's objective is evaluated apart.
    """
    shrunk = False
    if not update_H:  # W's updates all see the same Ht
        sol.fixed[0] = (Ht, None)
    hist: list[float] = []
    its: list[int] = []
    # Stopping rule of scikit-learn, on the error sqrt(2 * objective). An objective that
    # overflows (KL against a dictionary column of denormal size) cannot measure progress:
    # the rule waits for finite errors and takes the first one as its reference, and an
    # objective that becomes infinite later (a subnormal data cell whose reconstruction
    # underflows to 0) is never read as a decrease: the rule waits for two finite ones again.
    err0 = prev = float("nan")

    def stop_after(n: int, f: float) -> bool:
        """Record the objective f of iteration n; whether the rule stops the fit there."""
        nonlocal err0, prev
        hist.append(f)
        its.append(n)
        err = float(np.sqrt(2.0 * max(f, 0.0)))
        if n == 0 or not np.isfinite(err0):
            err0 = prev = err
            return False
        if tol > 0 and err0 > 0 and np.isfinite(prev) and np.isfinite(err) and (prev - err) / err0 < tol:
            return True
        prev = err
        return False

    fused = max_iter > 0 and sol.objective_in_update()
    due: int | None = 0  # the iteration whose objective the next W update reads (fused), if any
    if not fused or f0 is not None:
        stop_after(0, sol.objective(W, Ht) if f0 is None else f0)
        due = None
    converged = False
    n_iter = 0
    for n_iter in range(1, max_iter + 1):
        if due is not None:
            before = W.copy() if tol > 0 and due > 0 else None  # the iterate to return if the rule stops here
            if stop_after(due, sol.update_W_with_objective(W, Ht)) and before is not None:
                W, n_iter, converged = before, due, True
                break
            due = None
        else:
            W = sol.update(0, W, Ht)
        evaluate = n_iter % loss_every == 0 or n_iter == max_iter
        if update_H:
            # the objective evaluated next may reuse this H update's numerator (Problem.divergence)
            sol.objective_next = evaluate and not (fused and n_iter < max_iter)
            Ht = sol.update(1, Ht, W)
            sol.objective_next = False
            if shrink is not None and n_iter == 1 and n_iter < max_iter:
                reduced = shrink.reduce(sol, Ht)
                if reduced is not None:
                    (sol, Ht), shrunk = reduced, True
        if evaluate:
            if fused and n_iter < max_iter:
                due = n_iter
            elif stop_after(n_iter, sol.objective(W, Ht)):
                converged = True
                break
    if shrunk:
        Ht = cast(_EmptyColumns, shrink).expand(Ht)
    return W, Ht, n_iter, np.asarray(hist), np.asarray(its, dtype=int), converged, sol
