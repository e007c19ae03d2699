"""Histograms of angles and delayed velocities (Thesis section 3.2).

Each degree of freedom (dof) of a recording's angle trajectory becomes a fixed-length
nonnegative vector summing to one; the vectors of all dofs are concatenated. What is
histogrammed (``data``):

- ``"angles"``: the angle values ``x_t`` (all frames);
- ``"velocities"``: the delayed velocities ``x_t - x_{t-d}`` (Thesis section 3.2);
- ``"separate"``: angles and velocities as two separate 1-D dofs each;
- ``"joint"``: the 2-D angle-velocity vectors ``(x_t, x_t - x_{t-d})`` (Thesis Fig. 3.2,
  bottom), a rough phase portrait of each joint.

How (``method``):

- ``"kde"``: a regular grid over the training range of each dof (by default its
  0.5 %-99.5 % quantiles, ``range_quantile``, so that a few tracking glitches do not
  stretch the grid until every ordinary value falls in one bin), counts divided by the
  number of samples, then a Gaussian smoothing kernel (``scipy.ndimage.gaussian_filter``,
  ``smoothing`` bins wide); the mass the kernel pushes beyond the grid's edges is put
  back by renormalising, so each dof's histogram sums to one.
- ``"vq"``: vector quantisation by a k-means codebook per dof (k-means++ seeding and
  Lloyd iterations, ``scipy.cluster.vq.kmeans2``, on the training samples, standardised by their training standard deviation); hard
  assignment counts the proportion of samples nearest to each centroid, soft ("softmax")
  assignment gives each sample weights ``softmax(-||z - c_k||^2 / (2 s^2))`` with
  ``s = softness *`` the median distance of training samples to their nearest centroid.

Grids, codebooks and scales are learned in :meth:`MotionHistograms.fit` on the training
recordings only; :meth:`~MotionHistograms.transform` of new data reuses them (values
outside the grid fall in the edge bins).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any, ClassVar, cast

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.ndimage import gaussian_filter
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.metrics.pairwise import euclidean_distances
from sklearn.utils.validation import check_is_fitted

from .._jit import njit
from .._persist import SaveLoadMixin
from .._validation import Interval, Options, check_random_state, validate_params
from ..errors import DataError, ParameterError

__all__ = ["MotionHistograms"]

_DATA = ("angles", "velocities", "separate", "joint")
_METHODS = ("kde", "vq")
_ASSIGN = ("hard", "soft")


class _IntPair:
    """A pair (tuple or list of two) of ints >= ``low`` (a parameter constraint)."""

    def __init__(self, low: int) -> None:
        self.low = low

    def is_satisfied_by(self, value: Any) -> bool:
        return (isinstance(value, (tuple, list)) and len(value) == 2
                and all(Interval("int", self.low).is_satisfied_by(v) for v in value))

    def __str__(self) -> str:
        return f"a pair of ints >= {self.low}"


#: scipy's ``vq`` measures distances term by term below this many features (from this many on, through a matrix
#: product, whose distances differ in their last bits).
_NAIVE_FEATURES = 5


@njit(cache=True, nogil=True)
def _lloyd_step(zt, cb, labels, best):  # pragma: no cover - compiled
    """One Lloyd iteration as ``kmeans2(z, cb, iter=1, minit="matrix")`` makes it with fewer than five features.

    ``zt`` is ``z.T`` (contiguous, float64); ``labels`` and ``best`` (length n) are overwritten
    with each sample's nearest centroid and its squared distance. The distances are scipy's
    naive ones, ``sum_f (cb[c, f] - z[i, f])^2`` in feature order, the first nearest centroid
    kept on ties; the new centroids are the sums of their samples in sample order divided by
    their counts, an empty cluster keeping its centroid: the same numbers, to the bit. The loop
    runs over the samples innermost, where the compiler vectorises it.
    """
    d, n = zt.shape
    k = cb.shape[0]
    best[:] = np.inf
    if d == 2:  # angle-velocity pairs: the same sums, in one pass over the samples per centroid
        z0, z1 = zt[0], zt[1]
        for c in range(k):
            a0, a1 = cb[c, 0], cb[c, 1]
            for i in range(n):
                e0 = a0 - z0[i]
                e1 = a1 - z1[i]
                s = e0 * e0
                s += e1 * e1
                if s < best[i]:
                    best[i] = s
                    labels[i] = c
    else:
        dist = np.empty(n)
        for c in range(k):
            a = cb[c, 0]
            z0 = zt[0]
            for i in range(n):
                diff = a - z0[i]
                dist[i] = diff * diff
            for f in range(1, d):
                a = cb[c, f]
                zf = zt[f]
                for i in range(n):
                    diff = a - zf[i]
                    dist[i] += diff * diff
            for i in range(n):
                if dist[i] < best[i]:
                    best[i] = dist[i]
                    labels[i] = c
    new = np.zeros((k, d))
    count = np.zeros(k, dtype=np.int64)
    for i in range(n):
        c = labels[i]
        count[c] += 1
        for f in range(d):
            new[c, f] += zt[f, i]
    for c in range(k):
        for f in range(d):
            new[c, f] = new[c, f] / count[c] if count[c] > 0 else cb[c, f]
    return new


def _lloyd(z: np.ndarray, k: int, *, seed: int, n_iter: int) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.cluster.vq.kmeans2(z, k, iter=n_iter, minit="++", seed=seed)``, stopped at its fixed point.

    kmeans2 always runs ``n_iter`` Lloyd iterations. An iteration whose assignments are those
    of the one before gives back the same centroids (the means of the same groups; an empty
    cluster keeps its centroid), and so does every later one: the loop stops there, with the
    centroids and labels that the ``n_iter`` iterations return, to the bit. kmeans2 seeds the
    centroids (k-means++) and runs the first iteration; with fewer than five float64 features
    the others are :func:`_lloyd_step` (the same numbers as kmeans2's, in a compiled loop).

    Returns
    -------
    codebook : ndarray of shape (k, n_features)
    labels : ndarray of shape (n_samples,)
    """
    cb, lab = kmeans2(z, k, iter=1, minit="++", seed=seed)
    if z.ndim == 2 and z.dtype == np.float64 and z.shape[1] < _NAIVE_FEATURES:
        zt = np.ascontiguousarray(z.T)
        labels, best = np.empty(len(z), dtype=np.int64), np.empty(len(z))

        def step(cb):
            return _lloyd_step(zt, cb, labels, best), labels
    else:
        def step(cb):
            return kmeans2(z, cb, iter=1, minit="matrix")
    for _ in range(n_iter - 1):
        cb, new = step(cb)
        if np.array_equal(new, lab):
            break
        lab = new.astype(lab.dtype)  # a copy: the compiled step writes its labels in place
    return cb, lab


def _distinct_rows(z: np.ndarray) -> int:
    """The number of distinct rows of a 2-D array of finite numbers, ``len(np.unique(z, axis=0))`` (-0.0 and 0.0
    are one value), by a lexicographic sort of the columns (numpy's sorts the rows as records, about three times
    slower)."""
    if len(z) == 0:
        return 0
    s = z[np.lexsort(z.T[::-1])]
    return 1 + int(np.count_nonzero((s[1:] != s[:-1]).any(axis=1)))


class MotionHistograms(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """Concatenated per-dof histograms of angles and/or delayed velocities (Thesis 3.2).

    Parameters
    ----------
    data : {"angles", "velocities", "separate", "joint"}, default="joint"
        What each dof's histogram is built on (module docstring).
    method : {"kde", "vq"}, default="kde"
        Regular grid with Gaussian smoothing, or a k-means codebook.
    n_bins : int or (int, int), default=15
        Bins per histogram. For ``data="joint"`` with ``method="kde"`` an int ``n`` gives a
        ``g x g`` grid with ``g = max(2, round(sqrt(n)))`` (the thesis counts the total
        number of bins, Fig. 3.5), and a pair gives (angle bins, velocity bins). For
        ``"vq"`` it is the number of centroids.
    delay : int, default=3
        Delay ``d`` of the velocities ``x_t - x_{t-d}``.
    smoothing : float, default=1.0
        Standard deviation of the KDE Gaussian kernel, in bins (0: plain counts).
    range_quantile : float in [0, 0.5), default=0.005
        The KDE grid of each axis spans the ``range_quantile`` and ``1 - range_quantile``
        quantiles of the training values (0: minimum to maximum); values beyond fall in the
        edge bins. Delayed velocities have heavy tails (a tracking glitch makes one huge
        difference): with the minimum-maximum range a few outliers stretch the grid and
        most samples fall in its central bins; the quantile range spreads them over the
        grid (a measurement is in ``benchmarks/README.md``).
    assignment : {"hard", "soft"}, default="hard"
        Vector-quantisation assignment.
    softness : float, default=1.0
        Width of the soft assignment, relative to the median distance of training
        samples to their centroid.
    period : float, optional
        Wrap velocities of periodic angles (``2 * pi`` for Euler angles).
    max_fit_samples : int, default=10000
        At most this many training samples per dof are used to fit a k-means codebook.
    n_init : int, default=1
        k-means restarts (k-means++ initialisation); 1 keeps fitting fast.
    random_state : int, Generator or None
        Seeds k-means and the subsampling.

    Attributes
    ----------
    n_dof_ : int
        Degrees of freedom of the input trajectories.
    n_channels_ : int
        Histograms per recording (``2 * n_dof_`` for ``"separate"``, else ``n_dof_``).
    bins_per_channel_ : int
    n_features_out_ : int
    edges_ : list of tuple of ndarray
        KDE grid edges per channel (one array per axis).
    codebooks_ : list of ndarray of shape (n_bins, dim)
        VQ centroids per channel, in standardised units.
    scales_ : ndarray of shape ``(n_channels_, dim)``
        VQ standardisation (training standard deviations).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> X = [rng.normal(size=(100, 16)) for _ in range(5)]
    >>> MotionHistograms(n_bins=16).fit_transform(X).shape
    (5, 256)

    A fitted object keeps its grids or codebooks in a file without pickle
    (:meth:`save`, :meth:`load`).
    """

    _parameter_constraints: ClassVar[dict] = {
        "data": [Options(*_DATA)],
        "method": [Options(*_METHODS)],
        "n_bins": [Interval("int", 2), _IntPair(2)],
        "delay": [Interval("int", 1)],
        "smoothing": [Interval("real", 0)],
        "range_quantile": [Interval("real", 0, 0.5, closed="left")],
        "assignment": [Options(*_ASSIGN)],
        "softness": [Interval("real", 0, None, closed="neither")],
        "period": [Interval("real", 0, None, closed="neither"), None],
        "max_fit_samples": [Interval("int", 1)],
        "n_init": [Interval("int", 1)],
        "random_state": ["random_state"],
    }
    _hints: ClassVar[dict] = {
        "n_bins": "A pair (angle bins, velocity bins) is for data='joint' with method='kde' only.",
        "smoothing": "It is in bins; 0 gives plain counts.",
        "period": "Give 2 * pi for Euler angles, or None for angles that do not wrap.",
    }

    def __init__(
        self,
        *,
        data: str = "joint",
        method: str = "kde",
        n_bins: int | tuple[int, int] = 15,
        delay: int = 3,
        smoothing: float = 1.0,
        range_quantile: float = 0.005,
        assignment: str = "hard",
        softness: float = 1.0,
        period: float | None = None,
        max_fit_samples: int = 10000,
        n_init: int = 1,
        random_state=None,
    ) -> None:
        self.data = data
        self.method = method
        self.n_bins = n_bins
        self.delay = delay
        self.smoothing = smoothing
        self.range_quantile = range_quantile
        self.assignment = assignment
        self.softness = softness
        self.period = period
        self.max_fit_samples = max_fit_samples
        self.n_init = n_init
        self.random_state = random_state

    # ------------------------------------------------------------------ checks
    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints, hints=self._hints)
        if isinstance(self.n_bins, (tuple, list)) and not (self.method == "kde" and self.data == "joint"):
            raise ParameterError(
                "MotionHistograms: n_bins may be a pair only for data='joint' with method='kde'; give an int.")

    def _check_X(self, X, *, fitted: bool) -> list[np.ndarray]:
        if isinstance(X, np.ndarray) and X.ndim == 2:
            raise DataError(
                "MotionHistograms takes a list of (n_frames, n_dof) angle arrays, one per recording; got one "
                f"2-D array of shape {X.shape}. Wrap a single recording as [X]."
            )
        try:
            seqs = [np.asarray(x, dtype=float) for x in X]
        except (TypeError, ValueError) as exc:
            raise DataError(f"X must be a list of (n_frames, n_dof) arrays of numbers ({exc}).") from exc
        if not seqs:
            raise DataError("X is empty: give at least one recording.")
        n_dof = self.n_dof_ if fitted else seqs[0].shape[-1] if seqs[0].ndim == 2 else None
        min_len = 1 if self.data == "angles" else self.delay + 1
        for i, x in enumerate(seqs):
            if x.ndim != 2:
                raise DataError(f"Recording {i} must be a 2-D (n_frames, n_dof) array; got shape {x.shape}.")
            if x.shape[1] != n_dof:
                raise DataError(
                    f"Recording {i} has {x.shape[1]} degrees of freedom; expected {n_dof}"
                    + (" (as in fit)." if fitted else " (as the first recording).")
                )
            if x.shape[0] < min_len:
                raise DataError(
                    f"Recording {i} has {x.shape[0]} frame(s); velocities with delay={self.delay} need at least "
                    f"{min_len}."
                )
            if not np.isfinite(x).all():
                t, j = np.argwhere(~np.isfinite(x))[0]
                raise DataError(
                    f"Recording {i} holds {int((~np.isfinite(x)).sum())} NaN or infinite value(s), the first at "
                    f"frame {t}, degree of freedom {j}. Expected finite trajectories: repair the motion "
                    "(MotionRecording(..., on_missing='interpolate' or 'drop')) or leave the recording out."
                )
        return seqs

    # ------------------------------------------------------------------ samples
    def _channels(self, seqs: list[np.ndarray]) -> tuple[list[np.ndarray], np.ndarray]:
        """Samples of every channel, all recordings stacked, and each sample's recording index.

        Returns a list over channels of arrays (n_samples_total, dim), and the recording
        index of each sample.
        """
        d = self.delay
        if self.data == "angles":
            A = np.concatenate(seqs)
            rec = np.repeat(np.arange(len(seqs)), [len(x) for x in seqs])
            return [A[:, [j]] for j in range(A.shape[1])], rec
        A = np.concatenate([x[d:] for x in seqs])
        V = np.concatenate([x[d:] - x[:-d] for x in seqs])
        if self.period is not None:
            V = (V + self.period / 2) % self.period - self.period / 2
        rec = np.repeat(np.arange(len(seqs)), [len(x) - d for x in seqs])
        n = A.shape[1]
        if self.data == "velocities":
            return [V[:, [j]] for j in range(n)], rec
        if self.data == "separate":
            return [A[:, [j]] for j in range(n)] + [V[:, [j]] for j in range(n)], rec
        return [np.stack([A[:, j], V[:, j]], axis=1) for j in range(n)], rec

    def _grid_shape(self, dim: int) -> tuple[int, ...]:
        nb = self.n_bins
        if isinstance(nb, (tuple, list)):  # _check_params: a pair only for data="joint" (dim 2)
            return (int(nb[0]), int(nb[1]))
        if dim == 1:
            return (int(nb),)
        if self.method == "kde":
            g = max(2, int(round(np.sqrt(nb))))
            return (g, g)
        return (int(nb),)

    # ------------------------------------------------------------------ API
    def fit(self, X: Sequence[np.ndarray], y=None) -> MotionHistograms:
        """Learn grids (KDE) or codebooks (VQ) from training trajectories.

        Parameters
        ----------
        X : list of ndarray of shape (n_frames_i, n_dof)
            Angle trajectories, one per recording.
        y : ignored
        """
        self._check_params()
        seqs = self._check_X(X, fitted=False)
        self.n_dof_ = int(seqs[0].shape[1])
        chans, _ = self._channels(seqs)
        self.n_channels_ = len(chans)
        rng = check_random_state(self.random_state)
        self.edges_, self.codebooks_, self.soft_scales_ = [], [], []
        dim = chans[0].shape[1]
        if self.method == "kde":
            shape = self._grid_shape(dim)
            for c in chans:
                if self.range_quantile > 0:
                    lo, hi = np.quantile(c, [self.range_quantile, 1 - self.range_quantile], axis=0)
                else:
                    lo, hi = c.min(axis=0), c.max(axis=0)
                span = np.where(hi - lo > 1e-12, hi - lo, 1.0)
                lo, hi = lo - 1e-6 * span, hi + 1e-6 * span
                self.edges_.append(tuple(np.linspace(lo[k], hi[k], shape[k] + 1) for k in range(dim)))
            self.bins_per_channel_ = int(np.prod(shape))
            self.grid_shape_ = shape
        else:
            k = int(cast(int, self.n_bins))  # _check_params: a pair only with method="kde"
            scales = []
            for c in chans:
                s = c.std(axis=0)
                s = np.where(s > 1e-12, s, 1.0)
                z = c / s
                if len(z) > self.max_fit_samples:
                    z = z[rng.choice(len(z), self.max_fit_samples, replace=False)]
                n_unique = _distinct_rows(z)
                if n_unique < k:
                    raise DataError(
                        f"A degree of freedom has only {n_unique} distinct training value(s), fewer than "
                        f"n_bins={k} centroids; lower n_bins or give more varied training data."
                    )
                cb = self._kmeans(z, k, rng)
                scales.append(s)
                self.codebooks_.append(cb)
                dist = np.sqrt(euclidean_distances(z, cb, squared=True).min(axis=1))
                med = float(np.median(dist))
                self.soft_scales_.append(med if med > 1e-12 else 1.0)
            self.scales_ = np.asarray(scales)
            self.bins_per_channel_ = k
        self.n_features_out_ = self.n_channels_ * self.bins_per_channel_
        return self

    def _kmeans(self, z: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        # scipy's k-means (k-means++ seeding, Lloyd iterations): same algorithm as
        # sklearn.cluster.KMeans, without its per-call thread-pool set-up, which cost ~0.3 s
        # per fit here and dominated the 16-30 small fits a data set needs.
        best: np.ndarray | None = None
        best_inertia = np.inf
        for _ in range(self.n_init):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # empty clusters are re-seeded below
                cb, lab = _lloyd(z, k, seed=int(rng.integers(2**31 - 1)), n_iter=50)
            counts = np.bincount(lab, minlength=k)
            if (counts == 0).any():  # put empty centroids on the worst-fitted samples
                d = euclidean_distances(z, cb, squared=True).min(axis=1)
                far = np.argsort(d)[::-1]
                cb[counts == 0] = z[far[: int((counts == 0).sum())]]
            inertia = float(euclidean_distances(z, cb, squared=True).min(axis=1).sum())
            if best is None or inertia < best_inertia:
                best, best_inertia = cb, inertia
        assert best is not None  # n_init >= 1 (_check_params)
        return best

    def transform(self, X: Sequence[np.ndarray]) -> np.ndarray:
        """Histograms of each recording, with the grids/codebooks learned in :meth:`fit`.

        Parameters
        ----------
        X : list of ndarray of shape (n_frames_i, n_dof)

        Returns
        -------
        H : ndarray of shape ``(n_recordings, n_features_out_)``
            Nonnegative; the ``bins_per_channel_`` columns of each channel sum to one.
        """
        check_is_fitted(self, "n_features_out_")
        seqs = self._check_X(X, fitted=True)
        chans, rec = self._channels(seqs)
        n_rec = len(seqs)
        counts = np.bincount(rec, minlength=n_rec).astype(float)
        nb = self.bins_per_channel_
        out = np.empty((n_rec, self.n_channels_, nb))
        for j, c in enumerate(chans):
            if self.method == "kde":
                out[:, j, :] = self._kde(c, rec, n_rec, counts, self.edges_[j])
            else:
                out[:, j, :] = self._vq(c, rec, n_rec, counts, j)
        return out.reshape(n_rec, -1)

    def _kde(self, c, rec, n_rec, counts, edges) -> np.ndarray:
        shape = self.grid_shape_
        flat = np.zeros(len(c), dtype=np.int64)
        for k, e in enumerate(edges):
            idx = np.clip(np.searchsorted(e, c[:, k], side="right") - 1, 0, shape[k] - 1)
            flat = flat * shape[k] + idx
        nb = int(np.prod(shape))
        h = np.bincount(rec * nb + flat, minlength=n_rec * nb).reshape(n_rec, nb) / counts[:, None]
        if self.smoothing > 0:
            h = gaussian_filter(h.reshape((n_rec,) + shape), sigma=(0,) + (float(self.smoothing),) * len(shape),
                                mode="constant", truncate=3.0).reshape(n_rec, nb)
            h /= h.sum(axis=1, keepdims=True)
        return h

    def _vq(self, c, rec, n_rec, counts, j) -> np.ndarray:
        z = c / self.scales_[j]
        cb = self.codebooks_[j]
        d2 = euclidean_distances(z, cb, squared=True)
        k = cb.shape[0]
        if self.assignment == "hard":
            lab = d2.argmin(axis=1)
            h = np.bincount(rec * k + lab, minlength=n_rec * k).reshape(n_rec, k).astype(float)
        else:
            s = self.softness * self.soft_scales_[j]
            logits = -d2 / (2 * s * s)
            logits -= logits.max(axis=1, keepdims=True)
            w = np.exp(logits)
            w /= w.sum(axis=1, keepdims=True)
            starts = np.searchsorted(rec, np.arange(n_rec))  # samples are grouped by recording
            h = np.add.reduceat(w, starts, axis=0)
        return h / counts[:, None]

    def get_feature_names_out(self, input_features: Sequence[str] | None = None) -> np.ndarray:
        """``<dof>[:angle|:velocity]:bin<k>`` for every output column."""
        check_is_fitted(self, "n_features_out_")
        names = list(input_features) if input_features is not None else [f"dof{j}" for j in range(self.n_dof_)]
        if len(names) != self.n_dof_:
            raise ParameterError(f"input_features must have {self.n_dof_} names; got {len(names)}.")
        if self.data == "separate":
            chans = [f"{n}:angle" for n in names] + [f"{n}:velocity" for n in names]
        else:
            chans = names
        return np.asarray([f"{c}:bin{k}" for c in chans for k in range(self.bins_per_channel_)], dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        tags.transformer_tags.preserves_dtype = []
        return tags
