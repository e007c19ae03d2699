"""Initialisation of the factors (internal): random, NNDSVD and its variants, custom.

Every update of the multiplicative solver multiplies: a zero of W or H stays zero for the whole
fit, whatever beta, and so does a cell of W @ H whose row of W and column of H have no nonzero
component in common. :func:`unreachable_cells` finds the cells of X > 0 a start leaves at zero in
this way; NNDSVD's start fills them (:func:`initialize`) and a given start is refused when their
divergence is infinite (:func:`check_given_start`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from sklearn.utils.extmath import randomized_svd

from ..errors import DataError, ParameterError
from ._beta import zero_product_cells

__all__ = ["initialize", "INITS", "Unreachable", "check_factor_not_zero", "check_given_start",
           "refuse_unreachable", "unreachable_cells"]

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
    ``nndsvd``: Boutsidis & Gallopoulos (2008), scikit-learn's, its zeros kept (a sparse start)
    except those that leave W @ H zero at a cell where X > 0 (:func:`unreachable_cells`): in the
    rows of W and the columns of H of such cells, zeros are filled with the mean of X, as
    ``nndsvda`` fills them all. The multiplicative updates never move a zero, so such a cell would
    never be fitted, for every beta, and for beta <= 1 its divergence, hence the objective, would
    be infinite for the whole fit. (scikit-learn keeps them and warns that the 'mu' solver cannot
    update zeros; filling them costs nothing where NNDSVD leaves none, and its other zeros are kept.)
    ``nndsvda``: NNDSVD with zeros filled by the mean of X.
    ``nndsvdar``: NNDSVD with zeros filled by small random values.
    With a mask, unobserved cells are filled with the observed mean before the SVD (and only
    observed cells count as cells of X > 0: X is zero elsewhere, as ``validate_data`` leaves it).
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
    if init == "nndsvd":
        found = Unreachable.of(X, W, H)
        W[found.rows] = np.where(W[found.rows] == 0, avg_x, W[found.rows])
        H[:, found.cols] = np.where(H[:, found.cols] == 0, avg_x, H[:, found.cols])
    elif init == "nndsvda":
        W[W == 0] = avg_x
        H[H == 0] = avg_x
    elif init == "nndsvdar":
        W[W == 0] = np.abs(avg_x * rng.standard_normal(int((W == 0).sum())) / 100)
        H[H == 0] = np.abs(avg_x * rng.standard_normal(int((H == 0).sum())) / 100)
    return W.astype(dtype, copy=False), H.astype(dtype, copy=False)


def unreachable_cells(X, W: np.ndarray | None, H: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the cells where X > 0 and W @ H stays 0 while the zeros of W and H do.

    That is, the cells (i, j) where row i of W and column j of H have no nonzero component in
    common, in row-major order. A factor given as None may become nonzero anywhere (the projected
    gradient moves zeros): its support is taken as full. X is dense or sparse, zero off its mask.
    """
    n, m = X.shape
    if W is not None:
        k = np.shape(W)[1]
    elif H is not None:
        k = np.shape(H)[0]
    else:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    if (W is None or bool(np.all(np.asarray(W) > 0))) and (H is None or bool(np.all(np.asarray(H) > 0))):
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)  # full supports: every cell is reachable
    Ws = np.ones((n, k)) if W is None else (np.asarray(W) > 0).astype(np.float64)
    Hts = np.ones((m, k)) if H is None else np.ascontiguousarray((np.asarray(H) > 0).T, dtype=np.float64)
    return zero_product_cells(X, Ws, Hts)


@dataclass
class Unreachable:
    """The cells of X > 0 a start leaves at zero (:func:`unreachable_cells`), summed up."""

    count: int = 0
    first: tuple[int, int] | None = None  # the first in row-major order (rows counted in the whole X)
    why: str = ""  # why the first one is unreachable
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))  # distinct rows, sorted
    cols: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))  # distinct columns, sorted

    @classmethod
    def of(cls, X, W: np.ndarray | None, H: np.ndarray | None, row_offset: int = 0) -> Unreachable:
        """Those of X (rows ``row_offset`` on of a larger matrix, of which W holds the same rows)."""
        rows, cols = unreachable_cells(X, W, H)
        if rows.size == 0:
            return cls()
        i, j = int(rows[0]), int(cols[0])
        if W is not None and not np.any(W[i]):
            why = f"row {i + row_offset} of W is all zero"
        elif H is not None and not np.any(H[:, j]):
            why = f"column {j} of H is all zero"
        else:
            why = f"row {i + row_offset} of W and column {j} of H have no nonzero component in common"
        return cls(int(rows.size), (i + row_offset, j), why, np.unique(rows) + row_offset, np.unique(cols))

    @classmethod
    def merge(cls, parts: list[Unreachable]) -> Unreachable:
        """Those of consecutive blocks of rows, given in row order."""
        found = [p for p in parts if p.count]
        if not found:
            return cls()
        return cls(sum(p.count for p in found), found[0].first, found[0].why,
                   np.concatenate([p.rows for p in found]), np.unique(np.concatenate([p.cols for p in found])))


def check_factor_not_zero(A, name: str, source: str) -> None:
    """Refuse an all-zero starting factor, as scikit-learn does: the multiplicative updates would keep it zero."""
    if not np.any(A):
        raise DataError(
            f"{source}: {name} is all zero, and the multiplicative updates never move a zero: the fit would "
            f"stay at {name} = 0. Give a starting {name} with positive entries, or use init='nndsvda'."
        )


def refuse_unreachable(found: Unreachable, beta: float, *, frozen: tuple[bool, bool], fixed_H: bool) -> None:
    """Raise :class:`DataError` when beta <= 1 and a given start leaves W @ H zero at a cell of X > 0.

    Kept for beta > 1: a given zero is a support the updates keep, and the divergence there is
    finite. Refused for beta <= 1: the divergence there, hence the objective, is infinite for the
    whole fit. ``frozen`` says, for W and H, whether its zeros stay zero (multiplicative updates,
    or H fixed); with neither frozen (the projected gradient), ``found`` are the cells whose row of
    W is zero while some other cell of X > 0 has a zero column of H, which stops both steps.
    """
    if beta > 1 or not found.count or found.first is None:
        return
    i, j = found.first
    source = "with update_H=False" if fixed_H else "init='custom'"
    n_cells = f"{found.count} cell{'s' if found.count > 1 else ''}"
    fix = ("drop the columns of X and H where H is all zero (they carry no information on W, as "
           "NMF.transform does), mask the cells, or use beta_loss > 1." if fixed_H else
           "give starting factors whose product is positive wherever X is (e.g. replace their zeros by a small "
           "positive value), mask those cells, use init='nndsvda', or beta_loss > 1.")
    stuck = []
    if frozen[0] or (frozen[1] and not fixed_H):
        stuck.append("the multiplicative updates never move a zero")
    if fixed_H:
        stuck.append("H is fixed (update_H=False)")
    if not stuck:
        stuck.append("the projected gradient step of each factor has an infinite objective whatever it does while the "
                     "other leaves a cell of X > 0 at zero (a zero row of W stops H's step, a zero column of H stops "
                     "W's), and neither moves")
    raise DataError(
        f"{source}: W @ H is zero at {n_cells} where X > 0 (the first: sample {i}, feature {j}): {found.why}. "
        f"As {' and '.join(stuck)}, W @ H stays zero there and the beta={beta:g} divergence (beta <= 1) is "
        f"infinite for the whole fit. To fit it, {fix}"
    )


def check_given_start(X, W: np.ndarray, H: np.ndarray, beta: float, *, frozen: tuple[bool, bool],
                      fixed_H: bool = False) -> None:
    """Refuse a given start (W, H) that cannot be fitted: an all-zero factor that will be updated
    (:func:`check_factor_not_zero`), or, for beta <= 1, a cell of X > 0 that W @ H leaves at 0 for
    the whole fit (:func:`refuse_unreachable`).

    Raises
    ------
    DataError
        Naming the factor, or the number of such cells, the first of them and why it is unreachable.
    """
    source = "with update_H=False" if fixed_H else "init='custom'"
    check_factor_not_zero(W, "W", source)
    if not fixed_H:
        check_factor_not_zero(H, "H", source)
    if beta > 1:
        return
    if frozen[0] or frozen[1]:
        found = Unreachable.of(X, W if frozen[0] else None, H if frozen[1] else None)
    else:  # both move: stopped only when a zero row of W and a zero column of H each miss a cell of X > 0
        found = Unreachable.of(X, W, None)
        if found.count and not Unreachable.of(X, None, H).count:
            found = Unreachable()
    refuse_unreachable(found, beta, frozen=frozen, fixed_H=fixed_H)
