"""Histograms of acoustic co-occurrences (HAC), Thesis section 5.3.

MFCC sequences (22 coefficients in the thesis) are extended with the thesis' delta and
delta-delta (:func:`mmconcepts.sound.features.delta`); each of the three streams is vector
quantised by its own k-means codebook (150, 150 and 100 centroids), which turns every
frame into three discrete acoustic events; for each stream and each lag ``delta`` in
(2, 5), the pairs ``(e_t, e_{t+delta})`` are counted in a ``k x k`` histogram. The HAC
vector is the concatenation of these histograms: ``2 x (150^2 + 150^2 + 100^2) = 110 000``
dimensions with the defaults, returned as a sparse CSR matrix of counts.

Counts are additive (the thesis' "additive property"): the HAC of two concatenated
words is the sum of their HACs up to the few pairs that straddle the boundary.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._progress import progress
from .._validation import Interval, check_random_state, validate_params
from ..errors import DataError
from .features import delta

__all__ = ["HAC", "cooccurrence_counts"]


class _PositiveInts:
    """A constraint: a tuple or list (or 1-D array) of ints >= 1, of a given length or non-empty."""

    def __init__(self, length: int | None, description: str):
        self.length = length
        self.description = description

    def is_satisfied_by(self, value: Any) -> bool:
        if not isinstance(value, (tuple, list, np.ndarray)) or np.ndim(value) != 1:
            return False
        n_ok = len(value) == self.length if self.length is not None else len(value) > 0
        if not n_ok:
            return False
        return all(isinstance(v, (numbers.Integral, np.integer)) and not isinstance(v, (bool, np.bool_)) and int(v) >= 1
                   for v in value)

    def __str__(self) -> str:
        return self.description


_COOCCURRENCE_CONSTRAINTS = {"n_events": [Interval("int", 1, None)], "lag": [Interval("int", 1, None)]}


def _kmeans_from_centers(centers: np.ndarray) -> KMeans:
    """A fitted KMeans whose ``predict`` assigns to ``centers``, as the KMeans that found them did.

    The fit only sets the fitted attributes ``predict`` reads; it moves the centres by
    rounding (KMeans centres the data), so the saved centres are put back afterwards.
    """
    km = KMeans(n_clusters=centers.shape[0], init=centers, n_init=1, max_iter=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # coinciding centres
        km.fit(centers)
    km.cluster_centers_ = centers
    return km


def cooccurrence_counts(
    events: Sequence[np.ndarray], n_events: int, lag: int
) -> sp.csr_matrix:
    """Co-occurrence histograms of discrete event streams at one lag (Thesis 5.3.2).

    Parameters
    ----------
    events : sequence of int arrays, each of shape (n_frames_i,)
        Event ids in ``[0, n_events)``.
    n_events : int
        Size of the event alphabet ``k``.
    lag : int
        The delay ``delta``: pairs ``(e_t, e_{t+delta})``.

    Returns
    -------
    csr_matrix of shape (len(events), n_events ** 2), int64 counts
        Column ``a * n_events + b`` counts the pairs ``(a, b)``.
    """
    validate_params({"n_events": n_events, "lag": lag}, _COOCCURRENCE_CONSTRAINTS, owner="cooccurrence_counts")
    rows, cols = [], []
    for i, e in enumerate(events):
        e = np.asarray(e)
        if e.ndim != 1 or (e.size and e.dtype.kind not in "iu"):
            raise DataError(f"events[{i}] must be a 1-D array of integer event ids; got shape {e.shape}, dtype {e.dtype}.")
        e = e.astype(np.int64, copy=False)
        if e.size and (e.min() < 0 or e.max() >= n_events):
            raise DataError(
                f"events[{i}] holds event ids in [{e.min()}, {e.max()}], outside [0, n_events={n_events}): "
                "pass the codebook size as n_events."
            )
        if e.size > lag:
            c = e[:-lag] * n_events + e[lag:]
            rows.append(np.full(c.size, i, dtype=np.int64))
            cols.append(c)
    n = len(events)
    width = n_events * n_events
    if not rows:
        return sp.csr_matrix((n, width), dtype=np.int64)
    key = np.concatenate(rows) * width + np.concatenate(cols)
    uniq, counts = np.unique(key, return_counts=True)
    return sp.csr_matrix((counts, (uniq // width, uniq % width)), shape=(n, width), dtype=np.int64)


class HAC(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """Histograms of acoustic co-occurrences as a scikit-learn transformer (Thesis 5.3).

    Input is a list of MFCC sequences (one (n_frames, n_mfcc) array per utterance, see
    :func:`mmconcepts.sound.features.mfcc`; the thesis uses 22 coefficients). The
    codebooks are learnt in :meth:`fit` on training utterances only.

    Parameters
    ----------
    n_clusters : tuple of 3 ints, default=(150, 150, 100)
        Codebook sizes for the static, delta and delta-delta streams (Thesis 5.3.1).
    lags : tuple of ints, default=(2, 5)
        Co-occurrence delays in frames (Thesis 5.3.2).
    standardize : bool, default=True
        Scale each coefficient of each stream by its training standard deviation before
        k-means, so the codebook is not dominated by the energy coefficient. (The thesis
        does not say how its codebooks were scaled; this is our choice.)
    max_fit_frames : int, default=100000
        At most this many training frames (drawn at random without replacement) are used
        to fit each codebook; assignment always uses every frame.
    max_iter : int, default=100
        Lloyd iterations of k-means (scikit-learn's :class:`~sklearn.cluster.KMeans`,
        k-means++ seeding, one initialisation).
    random_state : int, Generator or None
        Seeds the frame subsample and k-means.
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the three codebooks :meth:`fit` learns,
        the slow part of the fit; an int above 0 counts as True. The results are the same.

    Attributes
    ----------
    codebooks_ : list of 3 ndarrays, shapes (k_s, n_mfcc)
        Centroids in standardised units.
    scales_ : list of 3 ndarrays of shape (n_mfcc,)
        Per-coefficient scale of each stream.
    n_mfcc_ : int
    n_features_out_ : int
        ``len(lags) * sum(k_s ** 2)``.

    Notes
    -----
    The input is a list of sequences of different lengths (or a 3-D array of equal-length
    ones), not one 2-D array, so scikit-learn's estimator checks, which feed 2-D arrays,
    are skipped (the ``two_d_array`` input tag is False, ``three_d_array`` True);
    ``tests/sound/test_contract.py`` runs the ones that apply on sequences. A single 2-D
    array is refused: it is one utterance, not a list of them. A fitted HAC saves and
    loads without pickle (:meth:`save`, :meth:`load`).
    """

    _STREAMS = ("static", "delta", "delta2")

    _parameter_constraints: dict[str, list] = {
        "n_clusters": [_PositiveInts(3, "three ints >= 1 (static, delta, delta-delta)")],
        "lags": [_PositiveInts(None, "a non-empty tuple of ints >= 1")],
        "standardize": ["boolean"],
        "max_fit_frames": [Interval("int", 1, None)],
        "max_iter": [Interval("int", 1, None)],
        "random_state": ["random_state"],
        "verbose": ["verbose"],
    }
    _HINTS = {
        "n_clusters": "Give the codebook sizes of the three streams, e.g. (150, 150, 100) as in the thesis.",
        "lags": "Give the co-occurrence delays in frames, e.g. (2, 5) as in the thesis.",
    }

    def __init__(
        self,
        n_clusters: tuple[int, int, int] = (150, 150, 100),
        lags: tuple[int, ...] = (2, 5),
        *,
        standardize: bool = True,
        max_fit_frames: int = 100_000,
        max_iter: int = 100,
        random_state=None,
        verbose: bool | int = False,
    ) -> None:
        self.n_clusters = n_clusters
        self.lags = lags
        self.standardize = standardize
        self.max_fit_frames = max_fit_frames
        self.max_iter = max_iter
        self.random_state = random_state
        self.verbose = verbose

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False  # a list of (n_frames, n_mfcc) sequences of different lengths
        tags.input_tags.three_d_array = True
        return tags

    # -- validation ---------------------------------------------------------------------
    def _check_X(self, X, *, fitted: bool) -> list[np.ndarray]:
        if isinstance(X, np.ndarray) and X.ndim == 2:
            raise DataError(
                "HAC takes a list of MFCC sequences (one (n_frames, n_mfcc) array per utterance), "
                "not a single 2-D array."
            )
        seqs = [np.asarray(x, dtype=np.float64) for x in X]
        if not seqs:
            raise DataError("HAC needs at least one utterance; got an empty list.")
        d = self.n_mfcc_ if fitted else seqs[0].shape[-1] if seqs[0].ndim == 2 else None
        for i, x in enumerate(seqs):
            if x.ndim != 2 or x.shape[0] == 0:
                raise DataError(f"utterance {i}: expected a non-empty (n_frames, n_mfcc) array; got shape {x.shape}.")
            if x.shape[1] != d:
                raise DataError(f"utterance {i} has {x.shape[1]} coefficients; expected {d}.")
            if not np.all(np.isfinite(x)):
                raise DataError(f"utterance {i} contains NaN or infinite values.")
        return seqs

    @staticmethod
    def _streams(x: np.ndarray) -> list[np.ndarray]:
        d1 = delta(x)
        return [x, d1, delta(d1)]

    # -- fit / transform ----------------------------------------------------------------
    def fit(self, X: Sequence[np.ndarray], y=None) -> HAC:
        """Learn the three codebooks on training MFCC sequences."""
        validate_params(self, self._parameter_constraints, hints=self._HINTS)
        seqs = self._check_X(X, fitted=False)
        rng = check_random_state(self.random_state)
        self.n_mfcc_ = seqs[0].shape[1]
        streams = [np.concatenate(s) for s in zip(*(self._streams(x) for x in seqs))]
        n_frames = streams[0].shape[0]
        take = (
            np.sort(rng.choice(n_frames, self.max_fit_frames, replace=False))
            if n_frames > self.max_fit_frames
            else slice(None)
        )
        self.codebooks_, self.scales_, self._kmeans = [], [], []
        for s, k in progress(zip(streams, self.n_clusters), verbose=self.verbose, total=len(streams),
                             desc="HAC codebooks", unit="codebook"):
            sample = s[take]
            if sample.shape[0] < k:
                raise DataError(
                    f"HAC needs at least {k} training frames for a {k}-word codebook; got {sample.shape[0]}."
                )
            scale = sample.std(axis=0) if self.standardize else np.ones(s.shape[1])
            scale = np.where(scale > 0, scale, 1.0)
            km = KMeans(
                n_clusters=int(k),
                n_init=1,
                max_iter=self.max_iter,
                random_state=int(rng.integers(2**31 - 1)),
            ).fit(sample / scale)
            self.scales_.append(scale)
            self.codebooks_.append(km.cluster_centers_)
            self._kmeans.append(km)
        self.n_features_out_ = len(tuple(self.lags)) * sum(int(k) ** 2 for k in self.n_clusters)
        return self

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        self._kmeans = [_kmeans_from_centers(c) for c in self.codebooks_]

    def events(self, X: Sequence[np.ndarray]) -> list[list[np.ndarray]]:
        """The three event streams of each utterance: ``[[static, delta, delta2], ...]``."""
        check_is_fitted(self, "codebooks_")
        seqs = self._check_X(X, fitted=True)
        lengths = [x.shape[0] for x in seqs]
        streams = [np.concatenate(s) for s in zip(*(self._streams(x) for x in seqs))]
        codes = [km.predict(s / sc) for km, s, sc in zip(self._kmeans, streams, self.scales_)]
        bounds = np.cumsum([0] + lengths)
        return [[c[a:b] for c in codes] for a, b in zip(bounds[:-1], bounds[1:])]

    def transform(self, X: Sequence[np.ndarray]) -> sp.csr_matrix:
        """HAC vectors (counts) of MFCC sequences.

        Returns
        -------
        csr_matrix of shape ``(n_utterances, n_features_out_)``, float64
            Blocks ordered by lag, then stream (static, delta, delta-delta); in each block
            column ``a * k + b`` counts the pairs ``(a, b)``.
        """
        ev = self.events(X)
        blocks = []
        for lag in self.lags:
            for s, k in enumerate(self.n_clusters):
                blocks.append(cooccurrence_counts([e[s] for e in ev], int(k), int(lag)))
        return sp.hstack(blocks, format="csr", dtype=np.float64)

    def get_feature_names_out(self, input_features=None) -> np.ndarray:
        check_is_fitted(self, "codebooks_")
        names: list[str] = []
        for lag in self.lags:
            for s, k in zip(self._STREAMS, self.n_clusters):
                names.extend(f"lag{lag}_{s}_{a}_{b}" for a in range(k) for b in range(k))
        return np.asarray(names, dtype=object)
