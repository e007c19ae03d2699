"""Choosing the number of components by the error on held-out entries (masked NMF).

A rank r is scored by fitting X ~ W @ H (W: (n_samples, r), H: (r, n_features)) on a random
part of X's entries and measuring the beta-divergence on the entries the fit did not see.
Entries, not rows, are held out: a held-out row would need coefficients the fit never
learnt, while a held-out entry x_ij has its W_i and H_j learnt from the rest of row i and
column j. Too small a rank cannot explain the held-out entries; too large a rank fits the
noise of the observed ones, and the held-out error rises again (Wold 1978; Kanagal &
Sindhwani 2010 for NMF). The thesis fixes its ranks by hand; this module is beyond it.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from .._validation import Interval, Options, check_random_state, validate_params
from ..errors import ConvergenceWarning, DataError, ParameterError
from ._beta import resolve_beta
from ._data import validate_data
from ._problem import beta_divergence
from ._solver import beta_nmf
from ._updates import BETA_NMF_CONSTRAINTS

__all__ = ["RankSelection", "select_rank", "RANK_RULES"]

#: How :func:`select_rank` picks a rank from the held-out errors.
RANK_RULES = ("one-standard-error", "min")

SELECT_RANK_CONSTRAINTS: dict = {
    "n_splits": [Interval("int", 1)],
    "holdout": [Interval("real", 0, 1, closed="neither")],
    **{name: BETA_NMF_CONSTRAINTS[name] for name in ("beta_loss", "max_iter", "tol", "random_state")},
    "rule": [Options(*RANK_RULES)],
}


@dataclass(frozen=True)
class RankSelection:
    """What :func:`select_rank` found: per rank, the held-out error of every split.

    Attributes
    ----------
    ranks : ndarray of int, shape (n_ranks,)
        The ranks tried, in increasing order.
    heldout : ndarray of shape (n_ranks, n_splits)
        Mean beta-divergence per held-out entry, :math:`D_\\beta(X | WH)` over the held-out
        entries of the split divided by their number, with W, H fitted on the others.
    train : ndarray of shape (n_ranks, n_splits)
        The same on the entries the fit saw (it decreases with the rank).
    rank : int
        The rank chosen by ``rule``.
    rule : str
        'one-standard-error' or 'min'.
    """

    ranks: np.ndarray
    heldout: np.ndarray
    train: np.ndarray
    rank: int
    rule: str

    @property
    def mean(self) -> np.ndarray:
        """Held-out error per rank, averaged over the splits, shape (n_ranks,)."""
        return self.heldout.mean(axis=1)

    @property
    def sem(self) -> np.ndarray:
        """Standard error of :attr:`mean` over the splits, shape (n_ranks,) (0 with one split)."""
        return _sem(self.heldout)

    @property
    def best_rank(self) -> int:
        """The rank of the smallest mean held-out error."""
        return int(self.ranks[int(np.argmin(self.mean))])


def _sem(heldout: np.ndarray) -> np.ndarray:
    n = heldout.shape[1]
    return heldout.std(axis=1, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(heldout.shape[0])


def _choose(ranks: np.ndarray, mean: np.ndarray, sem: np.ndarray, rule: str) -> int:
    best = int(np.argmin(mean))
    if rule == "min":
        return int(ranks[best])
    # the smallest rank whose mean error is within one standard error of the best one
    within = np.flatnonzero(mean <= mean[best] + sem[best])
    return int(ranks[within[0]])


def _check_ranks(ranks: Any) -> np.ndarray:
    arr = np.asarray(ranks)
    if arr.ndim != 1 or arr.size == 0 or not np.issubdtype(arr.dtype, np.integer) or (arr < 1).any():
        raise ParameterError(
            f"select_rank: ranks must be a non-empty sequence of ints >= 1 (e.g. range(1, 9)); got {ranks!r}."
        )
    if np.unique(arr).size != arr.size:
        raise ParameterError(f"select_rank: ranks holds repeated values; give each rank once; got {ranks!r}.")
    return np.sort(arr.astype(int))


def select_rank(
    X: Any,
    ranks: Sequence[int] | np.ndarray,
    *,
    n_splits: int = 5,
    holdout: float = 0.1,
    mask: Any = None,
    beta_loss: float | str = "frobenius",
    max_iter: int = 1000,
    tol: float = 1e-6,
    rule: str = "one-standard-error",
    random_state: Any = None,
) -> RankSelection:
    """Choose the number of components of X ~ W @ H by its error on held-out entries.

    For each of ``n_splits`` splits, a random ``holdout`` share of the observed entries is
    held out; for every rank r in ``ranks``, :func:`~mmconcepts.nmf.beta_nmf` fits
    W (n_samples, r) and H (r, n_features) with the held-out entries masked (they have no
    influence on the fit), and the error of that fit is measured on the held-out entries:

    .. math:: e(r) = \\frac{1}{|T|} \\sum_{(i, j) \\in T} d_\\beta\\big(X_{ij} | (W H)_{ij}\\big)

    with :math:`d_\\beta` of thesis eq. (2.2)-(2.3) and T the held-out entries. Every rank
    sees the same splits, so their errors are compared on the same entries. The thesis
    (V ~ W H, examples as columns) fixes its ranks by hand; this is beyond it.

    Parameters
    ----------
    X : {array-like, sparse matrix} of shape (n_samples, n_features)
        Nonnegative data.
    ranks : sequence of int
        The ranks to try, each >= 1 (e.g. ``range(1, 9)``).
    n_splits : int, default=5
        Number of random splits (drawn independently: two splits may share held-out entries).
    holdout : float in (0, 1), default=0.1
        Share of the observed entries held out in each split.
    mask : array-like of bool of shape (n_samples, n_features), optional
        True where X is observed; only observed entries are held out or fitted.
    beta_loss : float or {'frobenius', 'kullback-leibler', 'itakura-saito'}, default='frobenius'
    max_iter : int, default=1000
        Iterations of each fit; a rank's error is only meaningful once its fit has settled.
    tol : float, default=1e-6
        Stopping tolerance of each fit (see :func:`~mmconcepts.nmf.beta_nmf`).
    rule : {'one-standard-error', 'min'}, default='one-standard-error'
        'min': the rank of the smallest mean held-out error. 'one-standard-error': the
        smallest rank whose mean error is at most the smallest mean plus its standard
        error over the splits (Breiman et al. 1984; Hastie, Tibshirani & Friedman,
        *The Elements of Statistical Learning*, section 7.10): the simplest model the
        splits cannot tell from the best.
    random_state : int, numpy.random.Generator or None
        Draws the splits and seeds each fit's initialisation.

    Returns
    -------
    RankSelection
        ``heldout`` and ``train`` errors of shape (n_ranks, n_splits), their ``mean`` and
        ``sem``, and the chosen ``rank``.

    Raises
    ------
    ParameterError
        A rank that is not an int >= 1, or a parameter out of its range.
    DataError
        X not a nonnegative matrix, or too few observed entries to hold some out.

    Notes
    -----
    Fits that stop at ``max_iter`` before settling are not reported (their
    ConvergenceWarning is silenced); increase ``max_iter`` if the errors of large ranks look
    noisy. The masks are dense boolean arrays of X's shape.

    Examples
    --------
    >>> import numpy as np
    >>> from mmconcepts.nmf import select_rank
    >>> rng = np.random.default_rng(0)
    >>> V = rng.gamma(1.0, 1.0, (60, 4)) @ rng.gamma(1.0, 1.0, (4, 40))   # rank 4
    >>> X = np.maximum(V + 0.05 * V.std() * rng.standard_normal(V.shape), 0.0)
    >>> result = select_rank(X, range(2, 7), n_splits=3, random_state=0)
    >>> result.rank
    4
    """
    validate_params(dict(n_splits=n_splits, holdout=holdout, beta_loss=beta_loss, max_iter=max_iter, tol=tol,
                         rule=rule, random_state=random_state), SELECT_RANK_CONSTRAINTS, owner="select_rank")
    beta = resolve_beta(beta_loss)
    Xv, maskv = validate_data(X, mask)
    n, m = Xv.shape
    r = _check_ranks(ranks)
    observed = np.ones((n, m), dtype=bool) if maskv is None else np.asarray(
        maskv.toarray() if sp.issparse(maskv) else maskv, dtype=bool)
    obs_idx = np.flatnonzero(observed)
    n_test = int(round(holdout * obs_idx.size))
    if n_test < 1 or n_test >= obs_idx.size:
        raise DataError(
            f"select_rank: holding out {holdout:g} of {obs_idx.size} observed entries leaves {n_test} held out and "
            f"{obs_idx.size - n_test} to fit; both must be >= 1. Use more data or another holdout."
        )
    rng = check_random_state(random_state)
    heldout = np.empty((r.size, n_splits))
    train = np.empty((r.size, n_splits))
    for s in range(n_splits):
        test = np.zeros(n * m, dtype=bool)
        test[rng.choice(obs_idx, size=n_test, replace=False)] = True
        test = test.reshape(n, m)
        fit_mask = observed & ~test
        seeds = rng.integers(0, 2**31 - 1, size=r.size)
        for i, (k, seed) in enumerate(zip(r, seeds)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                res = beta_nmf(Xv, int(k), beta_loss=beta, mask=fit_mask, max_iter=max_iter, tol=tol,
                               init="random" if k > min(n, m) else None, random_state=int(seed))
            heldout[i, s] = beta_divergence(Xv, res.W, res.H, beta, mask=test) / n_test
            train[i, s] = beta_divergence(Xv, res.W, res.H, beta, mask=fit_mask) / (obs_idx.size - n_test)
    chosen = _choose(r, heldout.mean(axis=1), _sem(heldout), rule)
    return RankSelection(ranks=r, heldout=heldout, train=train, rank=chosen, rule=rule)
