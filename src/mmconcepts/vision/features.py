r"""Image descriptors: colour words, keypoint words and their mid-features (Thesis 6.5.3).

The thesis' robot describes each view of an object by bags of quantised local features
(Thesis section 6.5.3, steps 2-4): SURF descriptors, the HSV colour of superpixels, and
"mid-features", pairs and triplets of the closest features. It uses five of them: SURF,
SURF couples, colour, colour couples and colour triplets. This module computes the same
representations with what scikit-image offers on small (96 x 96) images:

``"color"`` (:class:`ColorHistograms`)
    SLIC superpixels (:func:`skimage.segmentation.slic`, ``n_segments`` of them,
    ``compactness``); the mean RGB colour of each superpixel converted to HSV
    (:func:`skimage.color.rgb2hsv`) and embedded in the HSV cone
    :math:`(s v \cos 2\pi h,\ s v \sin 2\pi h,\ v)`, where hue is an angle and is
    meaningless for grey or dark colours; a k-means codebook of ``n_colors`` such colours
    learnt on the training superpixels; the histogram of each image's superpixel colour
    words weighted by superpixel area (pixels).
``"keypoints"`` (:class:`KeypointBag`)
    Dense SIFT-like descriptors (Lowe 2004 layout: a ``patch_size`` square split in
    4 x 4 cells, an 8-bin gradient-orientation histogram per cell with linear
    interpolation between orientation bins, a Gaussian window of width half the patch,
    L2 normalisation, clipping at 0.2 and renormalisation, 128 values) on a regular grid
    of ``step`` pixels; patches whose mean gradient magnitude is below
    ``contrast_threshold`` (intensity units per pixel) are left out, as a detector finds no
    keypoint in flat regions. Each patch is described in the frame of its dominant
    gradient orientation (rotation invariant, as SURF) unless ``rotation_invariant=False``
    (upright, as U-SURF). A k-means codebook of ``n_words`` descriptors
    (:class:`sklearn.cluster.MiniBatchKMeans`) learnt on the training descriptors; the
    bag-of-features histogram.
``"color_pairs"``, ``"color_triplets"``, ``"keypoint_pairs"``, ``"keypoint_triplets"``
    (:class:`MidFeatures`). Each local feature i (superpixel centroid, kept patch
    centre) is linked to its ``n_neighbors`` nearest features in the image plane
    (Euclidean distance, ties broken by feature order). Pairs are the distinct unordered
    feature pairs {i, j} with j among i's neighbours (or i among j's); triplets are the
    distinct sets {i, j, k} with j and k two neighbours of i. A pair of visual words (a, b), sorted so that a <= b, is counted
    in column :math:`a + b(b + 1)/2`; a triplet a <= b <= c in column
    :math:`a + b(b + 1)/2 + c(c + 1)(c + 2)/6` (the co-lexicographic rank of the
    multiset). With K words there are exactly :math:`K(K + 1)/2` pair columns and
    :math:`K(K + 1)(K + 2)/6` triplet columns, nothing hashed, returned as CSR matrices.

Every descriptor set is a nonnegative histogram per image; with ``normalize="l1"``
(default) each row sums to one (a row with no feature, e.g. no keypoint in a flat image,
stays zero). Codebooks are learnt in ``fit`` on the training images only
and ``transform`` reuses them; a fitted transformer keeps them in a file without pickle
(``save``, ``load``). :class:`ImageFeatures` computes any subset of the six sets,
extracting superpixels and descriptors once per image.

Decisions, and how they differ from the thesis:

- Dense SIFT instead of SURF. scikit-image has no SURF; its SIFT detector finds few
  keypoints on the small ETH-80 images and is slow, which makes both the bags and the
  neighbourhoods thin and the extraction slow. A dense grid (at most 121 patches of
  16 x 16 pixels with the defaults, flat ones left out) covers every image evenly. The
  descriptor is written here because :func:`skimage.feature.hog` and
  :func:`skimage.feature.daisy` are upright only and slower on the same grid (the
  measurements are in ``benchmarks/README.md``). The default is rotation invariant, as
  SURF; on ETH-80 (objects mostly upright) the upright descriptors recognise objects
  about as well.
- Codebooks are batch k-means codebooks, not the thesis' incrementally grown
  dictionaries, and mid-features are counted as word pairs / triplets rather than
  quantised as concatenated feature vectors.
- No proto-object segmentation (step 1 of the thesis): the whole image is described,
  background included.
"""

from __future__ import annotations

import abc
import math
import numbers
from collections.abc import Iterable, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import map_coordinates
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.metrics.pairwise import euclidean_distances
from sklearn.utils.validation import check_is_fitted

from .._optional import optional_import
from .._persist import SaveLoadMixin
from .._progress import progress, progress_chunks
from .._validation import InstanceOf, Interval, Options, is_finite_real, check_random_state, validate_params
from ..errors import DataError, ParameterError
from .data import as_rgb_image, check_images

__all__ = [
    "DESCRIPTORS",
    "THESIS_DESCRIPTORS",
    "ColorHistograms",
    "ImageFeatures",
    "KeypointBag",
    "LocalFeatures",
    "MidFeatures",
    "dense_sift",
    "n_tuple_columns",
    "neighbour_tuples",
    "stack_descriptors",
    "superpixel_colors",
    "tuple_columns",
]

#: Names of the descriptor sets :class:`ImageFeatures` computes.
DESCRIPTORS: tuple[str, ...] = (
    "color", "color_pairs", "color_triplets", "keypoints", "keypoint_pairs", "keypoint_triplets",
)

#: The five representations of the thesis' experiments (Thesis 6.5.3): SURF, SURF couples,
#: colour, colour couples, colour triplets.
THESIS_DESCRIPTORS: tuple[str, ...] = ("keypoints", "keypoint_pairs", "color", "color_pairs", "color_triplets")

_N_ORIENT = 8
_CHUNK = 32  # images per joblib task


class LocalFeatures(NamedTuple):
    """Local features of one image.

    Attributes
    ----------
    vectors : ndarray of shape (n_local, dim)
        Feature vectors (HSV-cone colours, or SIFT-like descriptors).
    positions : ndarray of shape (n_local, 2)
        (row, column) of each feature in pixels (superpixel centroid, patch centre).
    weights : ndarray of shape (n_local,)
        Weight of each feature in the bag (superpixel area in pixels, or 1).
    """

    vectors: np.ndarray
    positions: np.ndarray
    weights: np.ndarray


# --------------------------------------------------------------------------- parameter constraints


class _MultipleOf:
    """An int >= ``low`` that is a multiple of ``step`` (a parameter constraint)."""

    def __init__(self, step: int, low: int, why: str) -> None:
        self.step, self.low, self.why = step, low, why

    def is_satisfied_by(self, value: Any) -> bool:
        return Interval("int", self.low).is_satisfied_by(value) and value % self.step == 0

    def __str__(self) -> str:
        return f"an int >= {self.low} and a multiple of {self.step} ({self.why})"


class _DescriptorNames:
    """A descriptor-set name or a non-empty sequence of distinct names among :data:`DESCRIPTORS`."""

    def is_satisfied_by(self, value: Any) -> bool:
        if not isinstance(value, (str, list, tuple, np.ndarray)):
            return False
        names = [value] if isinstance(value, str) else list(value)
        return (bool(names) and all(isinstance(n, str) and n in DESCRIPTORS for n in names)
                and len(set(names)) == len(names))

    def __str__(self) -> str:
        return f"a non-empty sequence of distinct names among {DESCRIPTORS}"


#: Parameters of the public functions, checked by :func:`~mmconcepts._validation.validate_params`.
_SUPERPIXEL_CONSTRAINTS: dict[str, list] = {
    "n_segments": [Interval("int", 1)],
    # scikit-image's SLIC squares compactness / grid step: below ~1e-150 that underflows to 0 and SLIC
    # corrupts memory (observed: "double free or corruption" with 1e-300); useful values are 0.01-100
    "compactness": [Interval("real", 1e-6, None, closed="left")],
}
_SUPERPIXEL_HINTS = {"compactness": "SLIC's useful range is about 0.01-100 (10 by default); smaller values make "
                                     "its spatial weight underflow."}
_SIFT_CONSTRAINTS: dict[str, list] = {
    "patch_size": [_MultipleOf(4, 4, "4 x 4 cells")],
    "step": [Interval("int", 1)],
    "contrast_threshold": [Interval("real", 0)],
    "rotation_invariant": ["boolean"],
}
_TUPLE_CONSTRAINTS: dict[str, list] = {"order": [Options(2, 3)], "n_neighbors": [Interval("int", 1)]}
_N_TUPLE_CONSTRAINTS: dict[str, list] = {"n_words": [Interval("int", 0)], "order": [Interval("int", 1)]}
_STACK_CONSTRAINTS: dict[str, list] = {"weights": [dict, None]}


# --------------------------------------------------------------------------- local features


def superpixel_colors(image: np.ndarray, *, n_segments: int = 50, compactness: float = 10.0) -> LocalFeatures:
    r"""HSV colour of the SLIC superpixels of an RGB image (Thesis 6.5.3, "HSV of superpixels").

    Parameters
    ----------
    image : ndarray of shape (H, W, 3)
        Float RGB in [0, 1], or any image :func:`~mmconcepts.vision.as_rgb_image` reads
        (gray (H, W) or (H, W, 1), gray + alpha (H, W, 2), RGBA (H, W, 4); integer types
        scaled by their maximum): the answer is the one on ``as_rgb_image(image)``.
    n_segments : int
        Approximate number of superpixels (:func:`skimage.segmentation.slic`).
    compactness : float
        SLIC's balance between colour and space (higher: more square superpixels); at
        least 1e-6.

    Returns
    -------
    LocalFeatures
        ``vectors`` (n_superpixels, 3): the mean RGB colour of each superpixel in HSV
        (:func:`skimage.color.rgb2hsv`), as the cone coordinates
        :math:`(s v \cos 2\pi h, s v \sin 2\pi h, v)`; ``positions`` the centroids;
        ``weights`` the areas in pixels.
    """
    rgb2hsv = optional_import("skimage.color", "vision", "superpixel_colors").rgb2hsv
    slic = optional_import("skimage.segmentation", "vision", "superpixel_colors").slic

    validate_params({"n_segments": n_segments, "compactness": compactness}, _SUPERPIXEL_CONSTRAINTS,
                    owner="superpixel_colors", hints=_SUPERPIXEL_HINTS)
    image = as_rgb_image(image, name="superpixel_colors' image")
    seg = slic(image, n_segments=n_segments, compactness=compactness, start_label=0, channel_axis=-1)
    _, seg = np.unique(seg, return_inverse=True)  # consecutive labels
    seg = seg.reshape(image.shape[:2])
    n = int(seg.max()) + 1
    flat = seg.ravel()
    area = np.bincount(flat, minlength=n).astype(np.float64)
    rgb = np.stack([np.bincount(flat, image[:, :, c].ravel(), minlength=n) for c in range(3)], axis=1) / area[:, None]
    hsv = rgb2hsv(np.clip(rgb, 0.0, 1.0)[None, :, :])[0]
    ang = 2 * np.pi * hsv[:, 0]
    sv = hsv[:, 1] * hsv[:, 2]
    cone = np.stack([sv * np.cos(ang), sv * np.sin(ang), hsv[:, 2]], axis=1)
    rows, cols = np.indices(seg.shape)
    pos = np.stack([np.bincount(flat, rows.ravel(), minlength=n), np.bincount(flat, cols.ravel(), minlength=n)],
                   axis=1) / area[:, None]
    return LocalFeatures(cone, pos, area)


def dense_sift(
    image: np.ndarray,
    *,
    patch_size: int = 16,
    step: int = 8,
    contrast_threshold: float = 0.01,
    rotation_invariant: bool = True,
) -> LocalFeatures:
    """SIFT-like descriptors of square patches on a regular grid (stands in for SURF, Thesis 6.5.3).

    Lowe's (2004) descriptor layout without detection or scale: the patch is split in
    4 x 4 cells, each cell holds an 8-bin histogram of gradient orientations weighted by
    gradient magnitude (linear interpolation between the two nearest bins), samples are
    weighted by a Gaussian window of standard deviation ``patch_size / 2``, and the 128
    values are L2-normalised, clipped at 0.2 and renormalised.

    With ``rotation_invariant`` (as SURF and SIFT), each patch is first given its dominant
    gradient orientation (peak of a 36-bin, smoothed, magnitude-weighted orientation
    histogram, refined by a parabola), and the patch is resampled (bilinear interpolation
    of the gradient images) in a frame turned by that angle, gradients expressed in that
    frame. Without it (upright, as U-SURF), cells are summed directly, on a regular grid
    when ``step`` is a multiple of the cell side, else with an integral image. Written
    here because scikit-image has no dense SIFT: its ``hog`` and ``daisy`` are upright
    only and slower on the same grid (timings in ``benchmarks/README.md``).

    Parameters
    ----------
    image : ndarray of shape (H, W, 3) or (H, W)
        RGB in [0, 1] (converted to gray with :func:`skimage.color.rgb2gray`), gray, or any
        image :func:`~mmconcepts.vision.as_rgb_image` reads (gray + alpha (H, W, 2) and RGBA
        lose their alpha channel; integer types are scaled by their maximum).
    patch_size : int
        Side of the square patches in pixels; a multiple of 4, at most the image's sides.
    step : int
        Grid spacing in pixels; the grid is centred in the image.
    contrast_threshold : float
        Patches whose mean gradient magnitude (intensity per pixel) is below this are left
        out, as a detector finds no keypoint in flat regions (background, saturated
        areas); 0 keeps every patch.
    rotation_invariant : bool
        Describe each patch in the frame of its dominant orientation.

    Returns
    -------
    LocalFeatures
        ``vectors`` (n_kept, 128), unit norm (all zeros for a patch without any gradient,
        which only ``contrast_threshold=0`` keeps); ``positions`` the patch centres (row,
        column); ``weights`` ones.
    """
    rgb2gray = optional_import("skimage.color", "vision", "dense_sift").rgb2gray

    validate_params({"patch_size": patch_size, "step": step, "contrast_threshold": contrast_threshold,
                     "rotation_invariant": rotation_invariant}, _SIFT_CONSTRAINTS, owner="dense_sift")
    raw_ndim = np.ndim(image)
    rgb = as_rgb_image(image, name="dense_sift's image")
    one_channel = raw_ndim == 2 or (raw_ndim == 3 and np.shape(image)[2] in (1, 2))  # gray, or gray + alpha
    gray = rgb[:, :, 0] if one_channel else rgb2gray(rgb)
    H, W = gray.shape
    if patch_size > min(H, W):
        raise DataError(f"An image of shape {gray.shape} is smaller than patch_size={patch_size}.")
    gy, gx = np.gradient(gray)
    mag = np.hypot(gx, gy)
    ang = np.arctan2(gy, gx) % (2 * np.pi)
    if rotation_invariant:
        return _rotated_sift(gx, gy, mag, ang, patch_size, step, contrast_threshold)
    b = ang * (_N_ORIENT / (2 * np.pi))
    lo = np.floor(b).astype(np.int64) % _N_ORIENT
    w_hi = b - np.floor(b)
    hi = (lo + 1) % _N_ORIENT
    base = np.arange(H * W, dtype=np.int64) * _N_ORIENT
    orient = np.bincount(np.concatenate([base + lo.ravel(), base + hi.ravel()]),
                         weights=np.concatenate([(mag * (1 - w_hi)).ravel(), (mag * w_hi).ravel()]),
                         minlength=H * W * _N_ORIENT).reshape(H, W, _N_ORIENT)
    cs = patch_size // 4
    oy, ox = ((H - patch_size) % step) // 2, ((W - patch_size) % step) // 2
    Y0, X0 = _grid(H, W, patch_size, step)
    a = np.arange(4)
    if step % cs == 0:  # cells tile a regular grid: sum them by reshaping (numpy's cumsum is slow)
        ny, nx = (H - oy) // cs, (W - ox) // cs
        grid = orient[oy: oy + ny * cs, ox: ox + nx * cs].reshape(ny, cs, nx, cs, _N_ORIENT).sum(axis=(1, 3))
        ci = ((Y0 - oy) // cs)[:, None] + a[None, :]
        cj = ((X0 - ox) // cs)[:, None] + a[None, :]
        cells = grid[ci[:, :, None], cj[:, None, :]]  # (n, 4, 4, 8)
    else:  # integral image
        S = np.zeros((H + 1, W + 1, _N_ORIENT))
        S[1:, 1:] = orient.cumsum(0).cumsum(1)
        ya = (Y0[:, None] + a[None, :] * cs)[:, :, None]  # (n, 4, 1): cell rows
        xa = (X0[:, None] + a[None, :] * cs)[:, None, :]  # (n, 1, 4): cell columns
        cells = S[ya + cs, xa + cs] - S[ya, xa + cs] - S[ya + cs, xa] + S[ya, xa]  # (n, 4, 4, 8)
    contrast = cells.sum(axis=(1, 2, 3)) / patch_size**2
    centre = (np.arange(4) - 1.5) * cs
    g = np.exp(-(centre[:, None] ** 2 + centre[None, :] ** 2) / (2 * (patch_size / 2) ** 2))
    desc = (cells * g[None, :, :, None]).reshape(len(Y0), 16 * _N_ORIENT)
    return _finish_sift(desc, contrast, contrast_threshold, Y0, X0, patch_size)


def _grid(H: int, W: int, patch_size: int, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Top-left corners (rows, columns) of the patches of a grid centred in the image."""
    oy, ox = ((H - patch_size) % step) // 2, ((W - patch_size) % step) // 2
    Y0, X0 = np.meshgrid(np.arange(oy, H - patch_size + 1, step), np.arange(ox, W - patch_size + 1, step),
                         indexing="ij")
    return Y0.ravel(), X0.ravel()


def _finish_sift(desc, contrast, contrast_threshold, Y0, X0, patch_size) -> LocalFeatures:
    keep = contrast >= contrast_threshold
    desc, Y0, X0 = desc[keep], Y0[keep], X0[keep]
    desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    desc = np.minimum(desc, 0.2)
    desc /= np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    pos = np.stack([Y0 + (patch_size - 1) / 2, X0 + (patch_size - 1) / 2], axis=1).astype(np.float64)
    return LocalFeatures(desc, pos, np.ones(len(Y0)))


def _rotated_sift(gx, gy, mag, ang, patch_size: int, step: int, contrast_threshold: float) -> LocalFeatures:
    """Dense SIFT in each patch's dominant-orientation frame (see :func:`dense_sift`)."""
    H, W = mag.shape
    P, cs = patch_size, patch_size // 4
    Y0, X0 = _grid(H, W, P, step)
    n = len(Y0)
    off = np.arange(P)
    V, U = (a.ravel() for a in np.meshgrid(off, off, indexing="ij"))  # sample (row, col) in the patch
    gw = np.exp(-((U - (P - 1) / 2) ** 2 + (V - (P - 1) / 2) ** 2) / (2 * (P / 2) ** 2))
    rows, cols = Y0[:, None] + V[None, :], X0[:, None] + U[None, :]  # (n, P*P)
    m = mag[rows, cols]
    contrast = m.mean(axis=1)
    # dominant orientation: 36-bin histogram, smoothed twice with [1, 2, 1] / 4, parabola at the peak
    nb = 36
    idx = np.minimum((ang * (nb / (2 * np.pi))).astype(np.int64), nb - 1)[rows, cols]
    hist: np.ndarray = np.bincount((np.arange(n)[:, None] * nb + idx).ravel(), (m * gw[None, :]).ravel(),
                       minlength=n * nb).reshape(n, nb)
    for _ in range(2):
        hist = (np.roll(hist, 1, axis=1) + 2 * hist + np.roll(hist, -1, axis=1)) / 4
    k = hist.argmax(axis=1)
    left, mid, right = (hist[np.arange(n), (k + d) % nb] for d in (-1, 0, 1))
    den = left - 2 * mid + right
    shift = np.where(den < 0, 0.5 * (left - right) / np.where(den < 0, den, -1.0), 0.0)
    theta = 2 * np.pi * (k + 0.5 + shift) / nb
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    # resample the gradients on the turned patch
    u, v = (U - (P - 1) / 2)[None, :], (V - (P - 1) / 2)[None, :]
    cy, cx = (Y0 + (P - 1) / 2)[:, None], (X0 + (P - 1) / 2)[:, None]
    xs, ys = cx + c * u - s * v, cy + s * u + c * v
    g = map_coordinates(gx + 1j * gy, [ys, xs], order=1, mode="nearest")  # bilinear, edge values outside
    mg = np.abs(g) * gw[None, :]  # a rotation keeps the norm and shifts the angle by -theta
    b = ((np.angle(g) - theta[:, None]) % (2 * np.pi)) * (_N_ORIENT / (2 * np.pi))
    lo = np.floor(b).astype(np.int64) % _N_ORIENT
    w_hi = b - np.floor(b)
    cell = ((V // cs) * 4 + (U // cs))[None, :]
    base = (np.arange(n)[:, None] * 16 + cell) * _N_ORIENT
    desc = np.bincount(np.concatenate([(base + lo).ravel(), (base + (lo + 1) % _N_ORIENT).ravel()]),
                       np.concatenate([(mg * (1 - w_hi)).ravel(), (mg * w_hi).ravel()]),
                       minlength=n * 16 * _N_ORIENT).reshape(n, 16 * _N_ORIENT)
    return _finish_sift(desc, contrast, contrast_threshold, Y0, X0, P)


# --------------------------------------------------------------------------- mid-features


def neighbour_tuples(positions: np.ndarray, *, order: int = 2, n_neighbors: int = 4) -> np.ndarray:
    """Pairs or triplets of spatially neighbouring local features (Thesis 6.5.3, "mid-features").

    Parameters
    ----------
    positions : ndarray of shape (n_local, 2)
    order : {2, 3}
        Pairs {i, j}: j is among the ``n_neighbors`` nearest features of i (or i of j).
        Triplets {i, j, k}: j and k are two of the ``n_neighbors`` nearest features of i.
    n_neighbors : int
        Neighbours per feature (fewer if the image has fewer features). Ties in distance
        are broken by feature index.

    Returns
    -------
    ndarray of shape (n_tuples, order), int
        Distinct tuples of feature indices, each sorted, in lexicographic order.
    """
    validate_params({"order": order, "n_neighbors": n_neighbors}, _TUPLE_CONSTRAINTS, owner="neighbour_tuples")
    try:
        pos = np.asarray(positions, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"positions must be an array of shape (n_local, 2) of numbers ({exc}).") from None
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise DataError(f"positions must have shape (n_local, 2) (row, column); got {pos.shape}.")
    if not np.isfinite(pos).all():
        raise DataError("positions hold NaN or infinite values.")
    n = len(pos)
    k = min(n_neighbors, n - 1)
    if n < order or k < order - 1:
        return np.zeros((0, order), dtype=np.int64)
    d2 = ((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    nbr = np.argsort(d2, axis=1, kind="stable")[:, :k]  # (n, k)
    i = np.repeat(np.arange(n), k)
    if order == 2:
        tup = np.stack([i, nbr.ravel()], axis=1)
    else:
        jj, kk = np.triu_indices(k, 1)
        tup = np.stack([np.repeat(np.arange(n), len(jj)), nbr[:, jj].ravel(), nbr[:, kk].ravel()], axis=1)
    tup.sort(axis=1)
    return np.unique(tup, axis=0)


def n_tuple_columns(n_words: int, order: int) -> int:
    """Number of distinct unordered ``order``-tuples (multisets) of ``n_words`` words: C(K + order - 1, order)."""
    validate_params({"n_words": n_words, "order": order}, _N_TUPLE_CONSTRAINTS, owner="n_tuple_columns")
    return math.comb(n_words + order - 1, order)


def tuple_columns(words: np.ndarray) -> np.ndarray:
    r"""Column of each sorted word tuple: the co-lexicographic rank of the multiset.

    A row :math:`w_0 \le w_1 \le \dots \le w_{r-1}` gets :math:`\sum_t \binom{w_t + t}{t + 1}`:
    :math:`a + b(b+1)/2` for pairs, :math:`a + b(b+1)/2 + c(c+1)(c+2)/6` for triplets. The
    ranks of all tuples over K words are exactly ``0 .. n_tuple_columns(K, r) - 1``.

    Parameters
    ----------
    words : ndarray of shape (n_tuples, r), int
        Word indices (nonnegative), one unordered tuple per row: rows are sorted here, so
        ``(3, 1)`` and ``(1, 3)`` get the same column.

    Raises
    ------
    DataError
        If ``words`` is not a 2-D array of nonnegative integers with at least one column.
    """
    w = np.asarray(words)
    if w.ndim != 2 or w.shape[1] < 1:
        raise DataError(f"words must have shape (n_tuples, r >= 1); got {w.shape}.")
    if w.size and not (np.issubdtype(w.dtype, np.integer) and w.min() >= 0):
        raise DataError(f"words must be nonnegative integer word indices; got dtype {w.dtype}"
                        + (f", min {w.min()}." if np.issubdtype(w.dtype, np.number) else "."))
    w = np.sort(w.astype(np.int64), axis=1)
    col = np.zeros(len(w), dtype=np.int64)
    for t in range(w.shape[1]):
        x = w[:, t] + t
        term = np.ones(len(w), dtype=np.int64)
        for m in range(t + 1):  # C(x, t + 1) = prod_{m=0..t} (x - m) / (m + 1), exact in integers
            term = term * (x - m) // (m + 1)
        col += term
    return col


# --------------------------------------------------------------------------- helpers


def _check_real(value, name: str, *, low: float = 0.0) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not is_finite_real(value) or value < low:
        raise ParameterError(f"{name} must be a real >= {low}; got {value!r}.")
    return float(value)


#: Constraints shared by the bags of words (:class:`ColorHistograms`, :class:`KeypointBag`).
_BAG_CONSTRAINTS: dict[str, list] = {
    "normalize": [Options("l1", None)],
    "max_fit_samples": [Interval("int", 1)],
    "n_jobs": [Interval("int"), None],
    "random_state": ["random_state"],
    "verbose": ["verbose"],
}


def _n_jobs_chunks(images: list[np.ndarray], func, kwargs: dict, *, n_jobs, verbose) -> list:
    """Apply ``func(image, **kwargs)`` to every image, in chunks, with joblib (a bar over the images if ``verbose``)."""
    desc = "image features"
    if n_jobs in (None, 1) or len(images) <= _CHUNK:
        return [func(im, **kwargs) for im in progress(images, verbose=verbose, desc=desc, unit="image")]
    from joblib import Parallel, delayed

    chunks = [images[i: i + _CHUNK] for i in range(0, len(images), _CHUNK)]
    out = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(_apply_chunk)(func, ch, kwargs) for ch in chunks)
    parts = progress_chunks(out, [len(ch) for ch in chunks], verbose=verbose, desc=desc, unit="image")
    return [x for part in parts for x in part]


def _apply_chunk(func, images, kwargs):
    return [func(im, **kwargs) for im in images]


def _fit_codebook(vectors: np.ndarray, k: int, max_samples: int, rng: np.random.Generator, what: str) -> np.ndarray:
    """k-means codebook (k-means++ seeding, mini-batch k-means) of at most ``max_samples`` vectors."""
    from sklearn.cluster import MiniBatchKMeans

    if len(vectors) > max_samples:
        vectors = vectors[np.sort(rng.choice(len(vectors), max_samples, replace=False))]
    n_distinct = len(np.unique(np.ascontiguousarray(vectors).view(np.dtype((np.void, vectors.dtype.itemsize
                                                                            * vectors.shape[1])))))
    if n_distinct < k:
        raise DataError(
            f"The training images give only {n_distinct} distinct {what}, fewer than the {k} codebook entries "
            "asked for; give more training images or a smaller codebook."
        )
    km = MiniBatchKMeans(n_clusters=k, n_init=1, batch_size=2048, max_iter=100,
                         random_state=int(rng.integers(2**31 - 1)))
    km.fit(vectors)
    return np.asarray(km.cluster_centers_, dtype=np.float64)


def _quantize(vectors: np.ndarray, codebook: np.ndarray) -> np.ndarray:
    if len(vectors) == 0:
        return np.zeros(0, dtype=np.int64)
    return euclidean_distances(vectors, codebook, squared=True).argmin(axis=1)


def _bag(words_list: Sequence[np.ndarray], weights_list: Sequence[np.ndarray], k: int, normalize) -> np.ndarray:
    H = np.zeros((len(words_list), k))
    for i, (w, a) in enumerate(zip(words_list, weights_list)):
        H[i] = np.bincount(w, weights=a, minlength=k)
    if normalize == "l1":
        s = H.sum(axis=1, keepdims=True)
        H = np.divide(H, s, out=np.zeros_like(H), where=s > 0)
    return H


def _mid(words_list, positions_list, k: int, order: int, n_neighbors: int, normalize) -> sp.csr_matrix:
    n_cols = n_tuple_columns(k, order)
    indptr, indices, data = [0], [], []
    u: np.ndarray
    cnt: np.ndarray  # counts, as floats
    for w, p in zip(words_list, positions_list):
        tup = neighbour_tuples(p, order=order, n_neighbors=n_neighbors)
        if len(tup):
            cols = tuple_columns(np.sort(w[tup], axis=1))
            u, cnt = np.unique(cols, return_counts=True)
            cnt = cnt.astype(np.float64)
            if normalize == "l1":
                cnt /= cnt.sum()
        else:
            u, cnt = np.zeros(0, np.int64), np.zeros(0)
        indices.append(u)
        data.append(cnt)
        indptr.append(indptr[-1] + len(u))
    return sp.csr_matrix((np.concatenate(data), np.concatenate(indices), np.asarray(indptr)),
                         shape=(len(words_list), n_cols))


# --------------------------------------------------------------------------- bags of words


class _WordBag(SaveLoadMixin, TransformerMixin, BaseEstimator, abc.ABC):
    """Shared machinery: local features -> k-means codebook -> histogram of words.

    A fitted bag saves and loads its codebook without pickle (:meth:`save`, :meth:`load`).
    """

    _what = "local features"
    _parameter_constraints: ClassVar[dict] = {}

    @abc.abstractmethod
    def _n_codewords(self) -> int:
        """Size of the codebook."""

    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints)

    def _min_size(self) -> int:
        return 2

    @abc.abstractmethod
    def _local_function(self):
        """The function extracting the local features of one image."""

    def _extract(self, images: list[np.ndarray]) -> list[LocalFeatures]:
        func, kwargs = self._local_function()
        return _n_jobs_chunks(images, func, kwargs, n_jobs=self.n_jobs, verbose=self.verbose)

    def _fit_locals(self, locals_: Sequence[LocalFeatures], rng: np.random.Generator) -> None:
        vectors = np.concatenate([l.vectors for l in locals_])
        self.codebook_ = _fit_codebook(vectors, self._n_codewords(), self.max_fit_samples, rng, self._what)
        self.n_features_out_ = self._n_codewords()

    def _words(self, locals_: Sequence[LocalFeatures]) -> list[np.ndarray]:
        return [_quantize(l.vectors, self.codebook_) for l in locals_]

    def _histograms(self, locals_: Sequence[LocalFeatures]) -> np.ndarray:
        return _bag(self._words(locals_), [l.weights for l in locals_], self.n_features_out_, self.normalize)

    def fit(self, images, y=None):
        """Learn the codebook from training images.

        Parameters
        ----------
        images : ImageSet or sequence of ndarray of shape (H, W, 3)
            Training images (float RGB in [0, 1], or anything
            :func:`~mmconcepts.vision.as_rgb_image` accepts).
        y : ignored
        """
        self.fit_transform(images)
        return self

    def fit_transform(self, images, y=None) -> np.ndarray:
        """Learn the codebook and return the training histograms (local features extracted once)."""
        self._check_params()
        ims = check_images(images, min_size=self._min_size())
        rng = check_random_state(self.random_state)
        locals_ = self._extract(ims)
        self._fit_locals(locals_, rng)
        return self._histograms(locals_)

    def transform(self, images) -> np.ndarray:
        """Histogram of visual words of each image, with the codebook learnt in :meth:`fit`.

        Parameters
        ----------
        images : ImageSet or sequence of ndarray of shape (H, W, 3)

        Returns
        -------
        ndarray of shape ``(n_images, n_features_out_)``
            Nonnegative; rows sum to one with ``normalize="l1"``.
        """
        check_is_fitted(self, "codebook_")
        ims = check_images(images, min_size=self._min_size())
        return self._histograms(self._extract(ims))

    def local_words(self, images) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(words, positions, weights)`` of each image's local features (fitted codebook)."""
        check_is_fitted(self, "codebook_")
        locals_ = self._extract(check_images(images, min_size=self._min_size()))
        return [(w, l.positions, l.weights) for w, l in zip(self._words(locals_), locals_)]

    def get_feature_names_out(self, input_features=None) -> np.ndarray:
        """``<prefix><k>`` for each visual word."""
        check_is_fitted(self, "codebook_")
        return np.asarray([f"{self._prefix}{k}" for k in range(self.n_features_out_)], dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        tags.transformer_tags.preserves_dtype = []
        tags.non_deterministic = False
        return tags


class ColorHistograms(_WordBag):
    r"""Histograms of quantised superpixel colours (Thesis 6.5.3, "HSV superpixels (color)").

    Each image is cut into SLIC superpixels; the mean colour of each superpixel, in the
    HSV cone :math:`(s v \cos 2\pi h, s v \sin 2\pi h, v)` (:func:`superpixel_colors`), is
    assigned to the nearest of ``n_colors`` k-means centroids learnt on the training
    superpixels, and each word counts the superpixel's area.

    Parameters
    ----------
    n_colors : int, default=64
        Codebook size (output dimension).
    n_segments : int, default=50
        Approximate number of superpixels per image (about 180 pixels each at 96 x 96).
    compactness : float, default=10.0
        SLIC compactness (>= 1e-6).
    normalize : {"l1", None}, default="l1"
        ``"l1"``: each histogram sums to one (area fractions); None: areas in pixels.
    max_fit_samples : int, default=50000
        At most this many training superpixels (drawn at random) fit the codebook.
    n_jobs : int, optional
        Parallel superpixel extraction (joblib); 1 runs in-process.
    random_state : int, Generator or None
        Seeds the subsampling and k-means.
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the images whose superpixels are
        extracted; an int above 0 counts as True. The results are the same.

    Attributes
    ----------
    codebook_ : ndarray of shape (n_colors, 3)
        Centroids in HSV-cone coordinates.
    n_features_out_ : int
    """

    _what = "superpixel colours"
    _prefix = "color"
    _parameter_constraints: ClassVar[dict] = {
        "n_colors": [Interval("int", 2)],
        **_SUPERPIXEL_CONSTRAINTS,
        **_BAG_CONSTRAINTS,
    }

    def __init__(self, *, n_colors: int = 64, n_segments: int = 50, compactness: float = 10.0,
                 normalize: str | None = "l1", max_fit_samples: int = 50000, n_jobs: int | None = 1,
                 random_state=None, verbose: bool | int = False) -> None:
        self.n_colors = n_colors
        self.n_segments = n_segments
        self.compactness = compactness
        self.normalize = normalize
        self.max_fit_samples = max_fit_samples
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.verbose = verbose

    def _n_codewords(self) -> int:
        return int(self.n_colors)

    def _local_function(self):
        return superpixel_colors, {"n_segments": int(self.n_segments), "compactness": float(self.compactness)}


class KeypointBag(_WordBag):
    """Bag of quantised dense SIFT-like descriptors (Thesis 6.5.3, stands in for "SURF").

    Descriptors (:func:`dense_sift`) on a grid of ``step`` pixels are assigned to the
    nearest of ``n_words`` k-means centroids learnt on training descriptors.

    Parameters
    ----------
    n_words : int, default=256
        Codebook size (output dimension).
    patch_size : int, default=16
        Patch side in pixels (multiple of 4).
    step : int, default=8
        Grid spacing in pixels (121 patches on a 96 x 96 image with the defaults).
    contrast_threshold : float, default=0.01
        Mean gradient magnitude (intensity per pixel) below which a patch is flat and left
        out. The default sits just above what camera noise on a flat background gives
        (see benchmarks/README.md, "Measurements quoted by the code's design decisions").
    rotation_invariant : bool, default=True
        Describe each patch in the frame of its dominant gradient orientation (as SURF);
        False gives upright descriptors (as U-SURF): one orientation estimate less per
        patch, and the orientation itself stays informative when objects are always upright.
    normalize : {"l1", None}, default="l1"
        ``"l1"``: each histogram sums to one; None: counts.
    max_fit_samples : int, default=50000
        At most this many training descriptors fit the codebook.
    n_jobs : int, optional
    random_state : int, Generator or None
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the images whose descriptors are
        computed; an int above 0 counts as True. The results are the same.

    Attributes
    ----------
    codebook_ : ndarray of shape (n_words, 128)
    n_features_out_ : int
    """

    _what = "keypoint descriptors"
    _prefix = "keypoint"
    _parameter_constraints: ClassVar[dict] = {
        "n_words": [Interval("int", 2)],
        **_SIFT_CONSTRAINTS,
        **_BAG_CONSTRAINTS,
    }

    def __init__(self, *, n_words: int = 256, patch_size: int = 16, step: int = 8, contrast_threshold: float = 0.01,
                 rotation_invariant: bool = True, normalize: str | None = "l1", max_fit_samples: int = 50000,
                 n_jobs: int | None = 1, random_state=None, verbose: bool | int = False) -> None:
        self.n_words = n_words
        self.patch_size = patch_size
        self.step = step
        self.contrast_threshold = contrast_threshold
        self.rotation_invariant = rotation_invariant
        self.normalize = normalize
        self.max_fit_samples = max_fit_samples
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.verbose = verbose

    def _n_codewords(self) -> int:
        return int(self.n_words)

    def _min_size(self) -> int:
        return int(self.patch_size)

    def _local_function(self):
        return dense_sift, {"patch_size": int(self.patch_size), "step": int(self.step),
                            "contrast_threshold": float(self.contrast_threshold),
                            "rotation_invariant": bool(self.rotation_invariant)}


class MidFeatures(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """Histograms of pairs or triplets of neighbouring visual words (Thesis 6.5.3, "mid-features").

    The base bag (a :class:`ColorHistograms` or :class:`KeypointBag`, cloned and fitted
    on the training images) gives each local feature a word and a position; the word
    tuples of neighbouring features (:func:`neighbour_tuples`) are counted in the
    columns :func:`tuple_columns` gives.

    Parameters
    ----------
    base : ColorHistograms or KeypointBag, optional
        Default ``ColorHistograms()``. Its ``random_state`` seeds the codebook, and its
        ``verbose`` shows the progress of the local features' extraction.
    order : {2, 3}, default=2
        Pairs or triplets.
    n_neighbors : int, default=4
        Spatial neighbours per local feature.
    normalize : {"l1", None}, default="l1"

    Attributes
    ----------
    base_ : fitted clone of ``base``
    n_features_out_ : int
        ``K (K + 1) / 2`` for pairs, ``K (K + 1) (K + 2) / 6`` for triplets, K the base's
        codebook size.

    Notes
    -----
    A fitted object saves and loads without pickle (:meth:`save`, :meth:`load`).
    """

    _parameter_constraints: ClassVar[dict] = {
        "base": [InstanceOf(_WordBag, description="a ColorHistograms or a KeypointBag"), None],
        "order": [Options(2, 3)],
        "n_neighbors": [Interval("int", 1)],
        "normalize": [Options("l1", None)],
    }
    _hints: ClassVar[dict] = {"order": "2 counts pairs, 3 triplets."}

    def __init__(self, base=None, *, order: int = 2, n_neighbors: int = 4, normalize: str | None = "l1") -> None:
        self.base = base
        self.order = order
        self.n_neighbors = n_neighbors
        self.normalize = normalize

    def _check_params(self) -> None:
        validate_params(self, self._parameter_constraints, hints=self._hints)
        if self.order == 3 and self.n_neighbors < 2:
            raise ParameterError(
                f"MidFeatures: n_neighbors must be >= 2 for triplets (order=3); got {self.n_neighbors}.")

    def fit(self, images, y=None):
        """Fit the base codebook on training images."""
        self.fit_transform(images)
        return self

    def fit_transform(self, images, y=None) -> sp.csr_matrix:
        """Fit the base codebook and return the training mid-feature histograms."""
        self._check_params()
        self.base_ = clone(self.base if self.base is not None else ColorHistograms())
        self.base_._check_params()
        ims = check_images(images, min_size=self.base_._min_size())
        locals_ = self.base_._extract(ims)
        self.base_._fit_locals(locals_, check_random_state(self.base_.random_state))
        self.n_features_out_ = n_tuple_columns(self.base_.n_features_out_, self.order)
        return self._from_locals(locals_)

    def _from_locals(self, locals_):
        return _mid(self.base_._words(locals_), [l.positions for l in locals_], self.base_.n_features_out_,
                    self.order, self.n_neighbors, self.normalize)

    def transform(self, images) -> sp.csr_matrix:
        """Mid-feature histograms, shape ``(n_images, n_features_out_)``, CSR, nonnegative."""
        check_is_fitted(self, "base_")
        ims = check_images(images, min_size=self.base_._min_size())
        return self._from_locals(self.base_._extract(ims))

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        return tags


# --------------------------------------------------------------------------- front object


def _both(image, color_kw, kp_kw):
    c = superpixel_colors(image, **color_kw) if color_kw is not None else None
    k = dense_sift(image, **kp_kw) if kp_kw is not None else None
    return c, k


class ImageFeatures(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """Named descriptor sets of images, any subset of them (Thesis 6.5.3).

    ``transform`` returns a dict ``{name: matrix}`` so that an experiment can use each
    set alone or several combined (:func:`stack_descriptors`). Superpixels and keypoint
    descriptors are extracted once per image and shared by the sets that need them.

    ====================== ========================= =================================
    name                   what                      columns (defaults)
    ====================== ========================= =================================
    ``color``              superpixel colour words   ``n_colors`` = 64, dense
    ``color_pairs``        pairs of colour words     K(K+1)/2 = 2080, CSR
    ``color_triplets``     triplets of colour words  K(K+1)(K+2)/6 = 45760, CSR
    ``keypoints``          dense-SIFT words          ``n_words`` = 256, dense
    ``keypoint_pairs``     pairs of keypoint words   32896, CSR
    ``keypoint_triplets``  triplets of keypoint      2829056, CSR
                           words
    ====================== ========================= =================================

    Parameters
    ----------
    descriptors : sequence of str, default=THESIS_DESCRIPTORS
        Which sets to compute, among :data:`DESCRIPTORS`. The default is the thesis' five:
        keypoints (SURF), keypoint pairs (SURF couples), colour, colour pairs, colour
        triplets.
    color : ColorHistograms, optional
        Colour parameters (default ``ColorHistograms()``); cloned. Its ``normalize``,
        ``n_jobs``, ``verbose`` and ``random_state`` are replaced by this object's.
    keypoints : KeypointBag, optional
        Keypoint parameters (default ``KeypointBag()``); cloned, as ``color``.
    n_neighbors : int, default=4
        Spatial neighbours of each local feature for pairs and triplets.
    normalize : {"l1", None}, default="l1"
        Applies to every set (overrides the sub-estimators' own).
    n_jobs : int, optional
        Parallel extraction (joblib).
    random_state : int, Generator or None
        Resolved once; seeds the colour codebook, then the keypoint codebook.
    stack : bool, default=False
        Return the sets side by side as one CSR matrix (:func:`stack_descriptors`, in the
        order of ``descriptors``) instead of a dict, so that the estimator takes its place in
        a scikit-learn :class:`~sklearn.pipeline.Pipeline` (e.g. before
        :class:`~mmconcepts.nmf.NMF`). :meth:`fit_locals` and :meth:`transform_locals` always
        return the dict.
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the images whose local features are
        extracted (the slow part); an int above 0 counts as True. The results are the same.

    Attributes
    ----------
    color_ : ColorHistograms or None
        Fitted colour codebook (None if no colour set was asked for).
    keypoints_ : KeypointBag or None
    n_features_out_ : dict of str to int

    Notes
    -----
    A fitted object saves and loads its codebooks without pickle (:meth:`save`,
    :meth:`load`).

    Examples
    --------
    >>> from mmconcepts.vision import make_objects                   # doctest: +SKIP
    >>> imgs = make_objects(4, 6, random_state=0)                    # doctest: +SKIP
    >>> feats = ImageFeatures(random_state=0).fit(imgs)               # doctest: +SKIP
    >>> X = feats.transform(imgs)             # {"keypoints": ..., ...}  # doctest: +SKIP
    >>> Xall = stack_descriptors(X)                                  # doctest: +SKIP
    """

    _parameter_constraints: ClassVar[dict] = {
        "descriptors": [_DescriptorNames()],
        "color": [InstanceOf(ColorHistograms), None],
        "keypoints": [InstanceOf(KeypointBag), None],
        "n_neighbors": [Interval("int", 2)],
        "normalize": [Options("l1", None)],
        "n_jobs": [Interval("int"), None],
        "random_state": ["random_state"],
        "stack": ["boolean"],
        "verbose": ["verbose"],
    }

    def __init__(self, descriptors: Sequence[str] = THESIS_DESCRIPTORS, *, color: ColorHistograms | None = None,
                 keypoints: KeypointBag | None = None, n_neighbors: int = 4, normalize: str | None = "l1",
                 n_jobs: int | None = 1, random_state=None, stack: bool = False,
                 verbose: bool | int = False) -> None:
        self.descriptors = descriptors
        self.color = color
        self.keypoints = keypoints
        self.n_neighbors = n_neighbors
        self.normalize = normalize
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.stack = stack
        self.verbose = verbose

    def _check_params(self) -> list[str]:
        """Validate the parameters; the descriptor-set names, as a list."""
        validate_params(self, self._parameter_constraints)
        return [self.descriptors] if isinstance(self.descriptors, str) else list(self.descriptors)

    def _extract(self, ims, need_c: bool, need_k: bool, c_est, k_est):
        ckw = c_est._local_function()[1] if need_c else None
        kkw = k_est._local_function()[1] if need_k else None
        pairs = _n_jobs_chunks(ims, _both, {"color_kw": ckw, "kp_kw": kkw}, n_jobs=self.n_jobs, verbose=self.verbose)
        return [p[0] for p in pairs], [p[1] for p in pairs]

    def fit(self, images, y=None) -> ImageFeatures:
        """Learn the colour and keypoint codebooks from training images.

        Parameters
        ----------
        images : ImageSet or sequence of ndarray of shape (H, W, 3)
        y : ignored
        """
        self.fit_transform(images)
        return self

    def fit_transform(self, images, y=None) -> dict[str, np.ndarray | sp.csr_matrix] | sp.csr_matrix:
        """Learn the codebooks and return the training descriptor sets (extracted once); see :meth:`transform`."""
        return self._output(self.fit_locals(*self.extract_locals(images)))

    def _output(self, sets: dict[str, np.ndarray | sp.csr_matrix]
                ) -> dict[str, np.ndarray | sp.csr_matrix] | sp.csr_matrix:
        return stack_descriptors(sets, self.descriptors_) if self.stack else sets

    def _estimators(self):
        """Unfitted colour and keypoint estimators with this object's normalisation (None if not needed)."""
        names = self._check_params()
        need_c = any(n.startswith("color") for n in names)
        need_k = any(n.startswith("keypoint") for n in names)
        c_est = clone(self.color if self.color is not None else ColorHistograms()) if need_c else None
        k_est = clone(self.keypoints if self.keypoints is not None else KeypointBag()) if need_k else None
        for est in (c_est, k_est):
            if est is not None:
                est.set_params(normalize=self.normalize, n_jobs=self.n_jobs, verbose=self.verbose)
                est._check_params()
        return names, c_est, k_est

    def extract_locals(self, images) -> tuple[list | None, list | None]:
        """Local colour and keypoint features of each image (no codebook involved).

        They depend only on the images and the extraction parameters, not on the
        codebooks, so a caller may compute them once and fit many codebooks on subsets
        (:meth:`fit_locals`, :meth:`transform_locals`).

        Returns
        -------
        (colour locals, keypoint locals) : lists of :class:`LocalFeatures` (None when unused)
        """
        _, c_est, k_est = self._estimators()
        ims = check_images(images, min_size=k_est._min_size() if k_est is not None else 2)
        c_loc, k_loc = self._extract(ims, c_est is not None, k_est is not None, c_est, k_est)
        return (c_loc if c_est is not None else None), (k_loc if k_est is not None else None)

    def fit_locals(self, c_loc, k_loc) -> dict[str, np.ndarray | sp.csr_matrix]:
        """:meth:`fit_transform` from local features of :meth:`extract_locals`."""
        names, self.color_, self.keypoints_ = self._estimators()
        rng = check_random_state(self.random_state)
        for est, loc, what in ((self.color_, c_loc, "colour"), (self.keypoints_, k_loc, "keypoint")):
            if est is not None and loc is None:
                raise ParameterError(f"{what} local features are needed by {names}; got None.")
        if self.color_ is not None:
            self.color_._fit_locals(c_loc, rng)
        if self.keypoints_ is not None:
            self.keypoints_._fit_locals(k_loc, rng)
        self.descriptors_ = tuple(names)
        self.n_features_out_ = {}
        for n in names:
            est = self.color_ if n.startswith("color") else self.keypoints_
            K = est.n_features_out_
            self.n_features_out_[n] = K if n in ("color", "keypoints") else \
                n_tuple_columns(K, 2 if n.endswith("pairs") else 3)
        return self._compute(c_loc, k_loc)

    def transform_locals(self, c_loc, k_loc) -> dict[str, np.ndarray | sp.csr_matrix]:
        """:meth:`transform` from local features of :meth:`extract_locals`."""
        check_is_fitted(self, "n_features_out_")
        return self._compute(c_loc, k_loc)

    def _compute(self, c_loc, k_loc) -> dict[str, np.ndarray | sp.csr_matrix]:
        out: dict[str, np.ndarray | sp.csr_matrix] = {}
        words = {}
        for n in self.descriptors_:
            kind = "color" if n.startswith("color") else "keypoints"
            est, loc = (self.color_, c_loc) if kind == "color" else (self.keypoints_, k_loc)
            if kind not in words:
                words[kind] = est._words(loc)
            K = est.n_features_out_
            if n == kind:
                out[n] = _bag(words[kind], [l.weights for l in loc], K, self.normalize)
            else:
                out[n] = _mid(words[kind], [l.positions for l in loc], K, 2 if n.endswith("pairs") else 3,
                              int(self.n_neighbors), self.normalize)
        return out

    def transform(self, images) -> dict[str, np.ndarray | sp.csr_matrix] | sp.csr_matrix:
        """Descriptor sets of images with the codebooks learnt in :meth:`fit`.

        Parameters
        ----------
        images : ImageSet or sequence of ndarray of shape (H, W, 3)

        Returns
        -------
        dict of str to ndarray or csr_matrix of shape (n_images, n_features_out_[name])
            In the order of ``descriptors``; ``color`` and ``keypoints`` dense, the
            mid-features CSR. Nonnegative; rows sum to one with ``normalize="l1"``
            (or are zero when an image has no such feature). With ``stack=True``, one
            csr_matrix of shape (n_images, sum of ``n_features_out_``) instead.
        """
        check_is_fitted(self, "n_features_out_")
        need_c, need_k = self.color_ is not None, self.keypoints_ is not None
        ims = check_images(images, min_size=self.keypoints_._min_size() if need_k else 2)
        c_loc, k_loc = self._extract(ims, need_c, need_k, self.color_, self.keypoints_)
        return self._output(self._compute(c_loc, k_loc))

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False  # a list of images, as the bags of words
        tags.input_tags.three_d_array = True
        tags.transformer_tags.preserves_dtype = []  # transform returns a dict of matrices (one CSR matrix if stack)
        return tags


def stack_descriptors(
    features: dict[str, np.ndarray | sp.spmatrix],
    names: Iterable[str] | None = None,
    *,
    weights: dict[str, float] | None = None,
) -> sp.csr_matrix:
    """Concatenate descriptor sets column-wise into one CSR matrix.

    Parameters
    ----------
    features : dict of str to matrix
        As returned by :meth:`ImageFeatures.transform`.
    names : iterable of str, optional
        Which sets, in which order (default: all, in the dict's order).
    weights : dict of str to float, optional
        Multiply a set by a nonnegative weight (default 1 each: with ``normalize="l1"``
        each set then has the same total mass per image).

    Returns
    -------
    csr_matrix of shape (n_images, sum of the sets' columns)
    """
    validate_params({"weights": weights}, _STACK_CONSTRAINTS, owner="stack_descriptors")
    keys = list(features) if names is None else list(names)
    if not keys:
        raise ParameterError("names must hold at least one descriptor set.")
    missing = [k for k in keys if k not in features]
    if missing:
        raise ParameterError(f"Descriptor set(s) {missing} not in features; available: {list(features)}.")
    blocks = []
    n = None
    for k in keys:
        m = sp.csr_matrix(features[k])
        if n is not None and m.shape[0] != n:
            raise DataError(f"Descriptor set {k!r} has {m.shape[0]} rows, the first one {n}.")
        n = m.shape[0]
        w = 1.0 if weights is None else _check_real(weights.get(k, 1.0), f"weights[{k!r}]")
        blocks.append(m * w if w != 1.0 else m)
    return sp.hstack(blocks, format="csr")
