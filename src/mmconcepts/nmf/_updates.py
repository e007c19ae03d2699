"""The update step every beta-NMF fit shares: the penalties, the multiplicative update, the scale of X.

The in-memory solver (:mod:`._solver`), the distributed one (:mod:`._dask`), the estimator's
``partial_fit`` and ``transform`` (:mod:`._estimator`) and the multimodal learner all update a
factor with :func:`mu_update` (thesis eq. 2.15-2.17), penalise it with a :class:`Penalty`
(:func:`resolve_penalties`, :func:`scale_penalties`) and run on X divided by
:func:`data_scale`; :data:`BETA_NMF_CONSTRAINTS` declares their parameters once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .._validation import Interval, Options
from ..errors import DataError
from ._beta import EPSILON, BetaLoss, zero_product_cells
from ._init import INITS
from ._problem import Side


__all__ = ["BETA_NMF_CONSTRAINTS", "NMFResult", "Penalty", "SOLVERS", "UPDATE_RULES", "check_fit_in_range",
           "check_objective_range", "constant_coefficients", "data_scale", "in_units_of_X",
           "infinite_objective_cause", "mu_update", "resolve_penalties", "scale_penalties", "sparse_kl_applies",
           "sparse_kl_update", "stopped_message"]


SOLVERS = ("mu", "pg")


UPDATE_RULES = ("mm", "heuristic")


@dataclass
class NMFResult:
    """What :func:`beta_nmf` returns.

    Attributes
    ----------
    W : ndarray of shape (n_samples, n_components)
        Coefficients (the thesis' H, transposed).
    H : ndarray of shape (n_components, n_features)
        Dictionary, one atom per row (the thesis' W, transposed).
    n_iter : int
        Iterations done.
    loss_history : ndarray
        The objective (divergence + penalties) at ``loss_iterations``.
    loss_iterations : ndarray of int
        Iteration number of each entry of ``loss_history`` (0 is the initialisation).
    converged : bool
        Whether the tolerance was met before ``max_iter`` (always False with tol=0).
    """

    W: np.ndarray
    H: np.ndarray
    n_iter: int
    loss_history: np.ndarray
    loss_iterations: np.ndarray
    converged: bool
    extra: dict = field(default_factory=dict)


@dataclass
class Penalty:
    l1: float = 0.0
    l2: float = 0.0

    def value(self, L: np.ndarray) -> float:
        out = 0.0
        if self.l1:
            out += self.l1 * float(L.sum(dtype=np.float64))
        if self.l2:
            out += 0.5 * self.l2 * float(np.sum(L * L, dtype=np.float64))
        return out

    def add_to(self, den: np.ndarray, L: np.ndarray) -> np.ndarray:
        if self.l1 or self.l2:
            den = den + self.l1 if self.l1 else np.array(den)
            if self.l2:
                den = den + self.l2 * L
        return den


def sparse_kl_applies(side: Side, beta: float, gamma: float, penalty: Penalty) -> bool:
    """Whether :func:`mu_update` runs the one-pass kernel: the I-divergence's update (gamma = 1) of an
    unpenalised factor on a sparse, unmasked side."""
    return (beta == 1.0 and gamma == 1.0 and not (penalty.l1 or penalty.l2) and isinstance(side, Side)
            and side.sparse and side.mask is None)


def sparse_kl_update(side: Side, L: np.ndarray, R: np.ndarray, R_sum: np.ndarray | None = None,
                     divergence: bool = False) -> tuple[float, np.ndarray | None]:
    """The update of :func:`mu_update` where :func:`sparse_kl_applies`, L in place; returns (with ``divergence``, the
    I-divergence of the L it started from, else NaN; the updated L's column sums or None), see
    :meth:`Side.kl_update`."""
    den_row = R.sum(axis=0) if R_sum is None else R_sum
    if np.any(den_row == 0):
        den_row = np.where(den_row == 0, L.dtype.type(EPSILON), den_row)
    return side.kl_update(L, R, den_row, divergence)


def mu_update(side: Side, L: np.ndarray, R: np.ndarray, beta: float, gamma: float, penalty: Penalty,
              R_sum: np.ndarray | None = None, fixed: bool = False, flush: float | None = None) -> np.ndarray:
    """One multiplicative update of L in place (thesis eq. 2.15-2.16; eq. 2.17 when gamma = 1).

    ``R_sum`` is R's column sums when the caller already has them (R fixed across updates,
    as in ``transform``); the sparse, unmasked I-divergence update uses them as its denominator.
    ``fixed``: R stays the same across the caller's updates (see :meth:`Side.numerator_denominator`).

    An entry that the update lowers below ``flush`` is set to zero (:func:`flush_falling`), by
    default (None) the smallest normal number of L's type (2.2e-308 in float64): a subnormal entry makes
    every product it enters take the processor about a hundred times longer
    (``benchmarks/README.md``). An entry that rises is kept however small. (The sparse, unmasked I-divergence update
    flushes from a higher level: see :func:`~mmconcepts.nmf._kernels.kl_update`.)
    """
    if sparse_kl_applies(side, beta, gamma, penalty):
        sparse_kl_update(side, L, R, R_sum)
        return L
    num, den = side.numerator_denominator(L, R, beta, fixed)
    den = penalty.add_to(den, L)
    if np.any(den == 0):
        den = np.where(den == 0, L.dtype.type(EPSILON), den)
    ratio = np.divide(num, den, out=num if num.flags.writeable else None)
    if gamma != 1.0:
        ratio **= gamma
    L *= ratio
    return flush_falling(L, ratio, flush)


def flush_falling(L: np.ndarray, factor: np.ndarray, flush: float | None = None) -> np.ndarray:
    """L's entries below ``flush`` (default: the smallest normal number of L's type) whose last update
    multiplied them by a ``factor`` below 1, set to zero in place (see :func:`mu_update`); returns L."""
    low = L < (np.finfo(L.dtype).tiny if flush is None else flush)
    if low.any():
        low &= factor < 1.0
        L[low] = 0.0
    return L


def resolve_penalties(alpha_W, alpha_H, l1_ratio, n_samples, n_features):
    # validated by the caller's constraints table (BETA_NMF_CONSTRAINTS)
    alpha_W = float(alpha_W)
    alpha_H = alpha_W if isinstance(alpha_H, str) and alpha_H == "same" else float(alpha_H)
    l1_ratio = float(l1_ratio)
    # Scaled as scikit-learn: the penalty on W grows with n_features, the one on H with n_samples.
    pen_W = Penalty(l1=n_features * alpha_W * l1_ratio, l2=n_features * alpha_W * (1 - l1_ratio))
    pen_H = Penalty(l1=n_samples * alpha_H * l1_ratio, l2=n_samples * alpha_H * (1 - l1_ratio))
    return pen_W, pen_H


#: The parameters of :func:`beta_nmf`, declared once (the estimators built on it reuse the entries).
BETA_NMF_CONSTRAINTS: dict[str, list] = {
    "n_components": [Interval("int", 1), None],
    "beta_loss": [BetaLoss()],
    "solver": [Options(*SOLVERS)],
    "update_rule": [Options(*UPDATE_RULES)],
    "init": [Options(*INITS), None],
    "update_H": ["boolean"],
    "max_iter": [Interval("int", 0)],
    "tol": [Interval("real", 0)],
    "alpha_W": [Interval("real", 0)],
    "alpha_H": [Interval("real", 0), Options("same")],
    "l1_ratio": [Interval("real", 0, 1)],
    "sparseness_W": [Interval("real", 0, 1), None],
    "sparseness_H": [Interval("real", 0, 1), None],
    "loss_every": [Interval("int", 1)],
    "random_state": ["random_state"],
}


#: Data whose largest observed value lies in [2 ** _SAFE_LO, 2 ** _SAFE_HI] is fitted as given;
#: beyond, it is rescaled (the clipping of the low-rank product at EPSILON and the powers of it
#: are not scale-invariant, and float64 overflows near 1e308).
_SAFE_LO, _SAFE_HI = -10, 20


def data_scale(X, beta: float) -> float:
    """The power of two X is divided by for the fit: 1 when X's largest value is at an ordinary scale.

    Beta-divergences are homogeneous, d_beta(c x | c y) = c ** beta d_beta(x | y), so the
    minimisers scale with X: fitting X / s and multiplying one factor by s gives the fit of X.
    In floating point the updates are not scale-invariant at extreme scales (the product is
    clipped below at EPSILON, powers of it overflow), so X far from 1 is brought near 1. A
    power of two divides exactly; data at ordinary scales is not touched at all.
    """
    values = X.data if sp.issparse(X) else X
    if values.size == 0:
        return 1.0
    xmax = float(values.max())
    if not xmax > 0.0 or not np.isfinite(xmax):
        return 1.0
    exponent = math.frexp(xmax)[1]  # xmax = f * 2 ** exponent, 0.5 <= f < 1
    hi = min(_SAFE_HI, int(100 / max(2.0, abs(beta), abs(beta - 1.0) + 1.0)))
    if _SAFE_LO <= exponent <= hi:
        return 1.0
    return math.ldexp(1.0, exponent - 1)  # X / scale has its largest value in [1, 2); 2 ** 1024 would overflow


def check_fit_in_range(X, beta: float, W: np.ndarray, Ht: np.ndarray, hist) -> None:
    """Refuse a fit whose factors left the range of the float type.

    Checked after the fit rather than refused up front: data with subnormal values beside
    ordinary ones (e.g. the tails of kernel density histograms, chapter 3) gives finite
    factors in practice, though its beta <= 1 objective may overflow (``hist`` is then
    infinite, which is not refused here: the factors are usable). Only non-finite factors
    are refused, naming the subnormal values when they are the likely cause.
    """
    if np.isfinite(W).all() and np.isfinite(Ht).all():
        return
    values = X.data if sp.issparse(X) else X
    tiny = np.finfo(values.dtype).tiny
    cause = ""
    if beta <= 1.0 and values.size and bool(np.any((values > 0) & (values < tiny))):
        cause = (f" X spans more than the range of {values.dtype}: its smallest nonzero values are subnormal "
                 f"(below {tiny:.3g} times its largest), and with beta_loss={beta:g} <= 1 their divergence terms "
                 "overflow. Set them to 0 (beta > 0) or use beta_loss > 1.")
    raise DataError(f"the fit left the range of {values.dtype}: its factors are not finite.{cause}")


def infinite_objective_cause(X, W: np.ndarray, Ht: np.ndarray, beta: float, scale: float = 1.0) -> str:
    """Why the objective of (W, Ht) on X (the fit's X, X's units times 1 / ``scale``) is not finite, in words.

    Names the first cell where X > 0 and W @ H is 0 (with beta <= 1 its divergence is infinite),
    else says that the objective overflowed.
    """
    values = X.data if sp.issparse(X) else X
    dtype = values.dtype
    rows, cols = zero_product_cells(X, W, Ht) if beta <= 1 else (np.zeros(0), np.zeros(0))
    if rows.size == 0:
        return (f"it exceeds the range of {dtype} (X spans more than that range, or W @ H overflows). Rescale X, "
                "or use a beta_loss closer to 1.")
    i, j = int(rows[0]), int(cols[0])
    x = float(X[i, j])
    where = (f"W @ H is 0 at {rows.size} cell{'s' if rows.size > 1 else ''} where X > 0 (the first: sample {i}, "
             f"feature {j}, where X = {x * scale:.3g}), and the beta={beta:g} divergence is infinite there (beta <= 1)")
    if x < np.finfo(dtype).tiny:
        return (f"{where}: X's value there is subnormal, and its reconstruction underflows to 0. Set such values "
                "of X to 0, or use beta_loss > 1.")
    return (f"{where}: a zero of W or H never moves under the multiplicative updates. Start from factors whose "
            "product is positive wherever X is (init='nndsvda'), or use beta_loss > 1.")


def stopped_message(max_iter: int, tol: float, objective: float, cause: str | None = None) -> str:
    """The ConvergenceWarning of a fit that ran ``max_iter`` iterations without meeting ``tol``.

    An objective that is not finite cannot show progress, whatever ``tol``: the message then says
    why it is not finite (``cause``) rather than asking for more iterations.
    """
    if np.isfinite(objective):
        return (f"beta_nmf stopped at max_iter={max_iter} before the objective settled (tol={tol:g}); "
                "increase max_iter or tol.")
    return (f"beta_nmf stopped at max_iter={max_iter} with an infinite objective, whose progress tol={tol:g} cannot "
            f"measure: {cause or 'W @ H is 0 where X > 0 (beta <= 1), or the objective overflowed'}")


def scale_penalties(pen_W: Penalty, pen_H: Penalty, scale: float, scale_W: float, scale_H: float, beta: float):
    """The penalties of the fit on X / scale that give the minimisers of the fit on X.

    With W = a W', H = b H' (a = scale_W, b = scale_H, a b = scale) the objective is
    scale ** beta * [D(X' | W' H') + (l1_W a |W'| + l2_W a^2 |W'|^2 / 2 + l1_H b |H'| + l2_H b^2 |H'|^2 / 2)
    / scale ** beta].
    """
    s = np.float64(scale)

    def times(value: float, factor) -> float:  # 0 stays 0 (no penalty), whatever the factor
        return float(value * factor) if value else 0.0

    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        out = []
        for pen, f in ((pen_W, np.float64(scale_W)), (pen_H, np.float64(scale_H))):
            out.append(Penalty(l1=times(pen.l1, f / s**beta), l2=times(pen.l2, f * f / s**beta)))
    if not all(np.isfinite(v) for p in out for v in (p.l1, p.l2)):
        raise DataError(
            f"X's largest value is about {scale:.3g}: at that scale the penalties (alpha_W, alpha_H) outweigh the "
            f"beta={beta:g} divergence by more than the range of float64 (the fit would be W = 0). Rescale X by a "
            "constant c first (the divergence scales as c ** beta) or lower the penalties."
        )
    return out[0], out[1]


def in_units_of_X(values, scale: float, beta: float) -> np.ndarray:
    """Objectives of the fit on X / scale in X's units: times scale ** beta.

    A divergence is >= 0: values at or below 0 are 0 up to rounding and stay 0 (a rounding error
    times a huge scale ** beta would otherwise read -inf)."""
    values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        return np.where(values == 0, 0.0, values * np.float64(scale) ** beta)


def check_objective_range(f0: float, scale: float, beta: float) -> None:
    """Refuse data whose objective (in X's units) float64 cannot hold: the fit itself would be fine."""
    with np.errstate(over="ignore", under="ignore"):
        f = float(np.float64(f0) * np.float64(scale) ** beta) if f0 > 0 else 0.0
    if f0 > 0 and (not np.isfinite(f) or f < np.finfo(np.float64).tiny):
        raise DataError(
            f"X's largest value is about {scale:.3g}: at that scale the beta={beta:g} objective (about "
            f"{f0:.3g} * {scale:.3g} ** {beta:g}) is outside the range of float64. Rescale X by a constant c "
            "first: the fit of c X is (W, c H)."
        )


def constant_coefficients(X, H: np.ndarray, mask=None) -> np.ndarray:
    """A flat start for W given a fixed H: every entry equal, so that mean(W H) = mean(X)."""
    n, k = X.shape[0], H.shape[0]
    if mask is None:
        x_mean = float(X.mean())
    elif sp.issparse(mask):  # X is zero off the mask (validate_data); the mask is never densified
        x_mean = float(X.sum() if sp.issparse(X) else mask.multiply(X).sum()) / max(float(mask.count_nonzero()), 1.0)
    else:
        x_mean = float((X.multiply(mask) if sp.issparse(X) else X * mask).sum()) / max(float(mask.sum()), 1.0)
    h_mean = float(H.mean())
    value = x_mean / (k * h_mean) if h_mean > 0 else 0.0
    return np.full((n, k), max(value, np.sqrt(np.finfo(X.dtype).eps)), dtype=X.dtype)
