"""Fuzz tests of mmconcepts.vision: a typed error or a correct result.

Images come in every shape a user may hold: gray (H, W), (H, W, 1), gray + alpha
(H, W, 2), RGB, RGBA, wrong channel counts, tiny and empty images, integer, boolean and
float dtypes, NaN and out-of-range values. What a valid image means is
:func:`mmconcepts.vision.as_rgb_image`'s decision (gray repeated over RGB, alpha dropped,
integers scaled by their type's maximum); every descriptor must give the same answer on
an image as on ``as_rgb_image(image)``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from _fuzz import assert_typed_or_good, fuzz_settings
from mmconcepts.vision import (
    ColorHistograms,
    ImageFeatures,
    KeypointBag,
    MidFeatures,
    as_rgb_image,
    check_images,
    dense_sift,
    n_tuple_columns,
    neighbour_tuples,
    stack_descriptors,
    superpixel_colors,
    tuple_columns,
)

SETTINGS = dict(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning",
                                        "ignore::sklearn.exceptions.ConvergenceWarning")]


@st.composite
def images(draw, max_side=24, valid_only=False, min_side=2):
    """An image-like array of any common (and some uncommon) shape, dtype and value range."""
    if not valid_only and draw(st.booleans()):
        valid_only = True  # half the examples are valid images
    H = draw(st.integers(min_side, max_side) if valid_only else st.sampled_from([0, 1, 2, 3, 16, max_side]))
    W = draw(st.integers(min_side, max_side) if valid_only else st.sampled_from([0, 1, 2, 5, 16, max_side]))
    channels = draw(st.sampled_from([None, 1, 2, 3, 3, 3, 4] + ([] if valid_only else [0, 5])))
    shape = (H, W) if channels is None else (H, W, channels)
    if not valid_only and draw(st.integers(0, 9)) == 0:
        shape = draw(st.sampled_from([(H,), (H, W, 3, 1), ()]))
    dtype = draw(st.sampled_from(["float", "float", "uint8", "uint16", "bool"] + ([] if valid_only else
                                                                                   ["int16", "float32", "complex"])))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    kind = draw(st.sampled_from(["random", "random", "constant", "blocks"]))
    base = rng.random(shape) if kind == "random" else np.full(shape, 0.5)
    if kind == "blocks" and len(shape) >= 2:
        base[: shape[0] // 2] = 0.1
    if dtype in ("float", "float32"):
        a = base.astype(dtype)
        if not valid_only and a.size:
            bad = draw(st.sampled_from([None, None, np.nan, np.inf, -0.5, 2.0, 255.0]))
            if bad is not None:
                a.flat[0] = bad
        return a
    if dtype == "uint8":
        return (base * 255).astype(np.uint8)
    if dtype == "uint16":
        return (base * 65535).astype(np.uint16)
    if dtype == "int16":
        return (base * 200 - 100).astype(np.int16)
    if dtype == "complex":
        return base.astype(complex)
    return base > 0.5


def _same_locals(a, b):
    return all(np.allclose(x, y) for x, y in zip(a, b)) and all(x.shape == y.shape for x, y in zip(a, b))


@fuzz_settings(300, **SETTINGS)
@given(image=images())
def test_fuzz_as_rgb_image(image):
    """(H, W, 3) float in [0, 1]; gray is repeated, gray + alpha and RGBA lose the alpha, integers are scaled."""

    def check(rgb):
        if rgb.shape != image.shape[:2] + (3,) or rgb.dtype != np.float64 or rgb.min() < 0 or rgb.max() > 1:
            return False
        a = np.asarray(image)
        if a.ndim == 3 and a.shape[2] in (1, 2):
            a = a[:, :, 0]
        if a.ndim == 3:
            a = a[:, :, :3]
        if a.dtype.kind in "ui":
            a = a / np.iinfo(a.dtype).max
        a = a.astype(float)
        if a.ndim == 2:
            a = a[:, :, None]
        return np.allclose(rgb, np.broadcast_to(a, rgb.shape))

    assert_typed_or_good("mmconcepts.vision.as_rgb_image", lambda: as_rgb_image(image), check=check)


@fuzz_settings(200, **SETTINGS)
@given(image=images(), n_segments=st.sampled_from([-1, 0, 2**40, 2.5, np.nan] + [1, 5, 50] * 4),
       compactness=st.sampled_from([10.0] * 10 + [0.0, -1.0, np.nan, np.inf, 1e-300, 0.01]))
def test_fuzz_superpixel_colors(image, n_segments, compactness):
    """Areas cover the image, centroids lie inside it, colours lie in the HSV cone, and the
    answer is the one on ``as_rgb_image(image)`` (one meaning of every image shape)."""

    def call():
        got = superpixel_colors(image, n_segments=n_segments, compactness=compactness)
        return got, superpixel_colors(as_rgb_image(image), n_segments=n_segments, compactness=compactness)

    def check(res):
        (v, pos, w), ref = res
        H, W = image.shape[:2]
        n = len(w)
        return (v.shape == (n, 3) and pos.shape == (n, 2) and n >= 1 and np.isclose(w.sum(), H * W)
                and (pos >= 0).all() and (pos[:, 0] <= H - 1).all() and (pos[:, 1] <= W - 1).all()
                and (v[:, 2] >= -1e-12).all() and (v[:, 2] <= 1 + 1e-12).all()
                and (np.hypot(v[:, 0], v[:, 1]) <= v[:, 2] + 1e-9).all() and _same_locals(res[0], ref))

    assert_typed_or_good("mmconcepts.vision.superpixel_colors", call, check=check)


@fuzz_settings(200, **SETTINGS)
@given(image=images(max_side=32, min_side=8), patch_size=st.sampled_from([-4, 0, 3, 2**40] + [4, 8, 16] * 4),
       step=st.sampled_from([-1, 0] + [1, 4, 7] * 4), contrast=st.sampled_from([-1.0, np.nan, np.inf] + [0.0, 0.01] * 4),
       rotation_invariant=st.booleans())
def test_fuzz_dense_sift(image, patch_size, step, contrast, rotation_invariant):
    """Unit-norm 128-d descriptors of patches inside the image, the same on ``as_rgb_image(image)``."""
    kw = dict(patch_size=patch_size, step=step, contrast_threshold=contrast, rotation_invariant=rotation_invariant)

    def call():
        return dense_sift(image, **kw), dense_sift(as_rgb_image(image), **kw)

    def check(res):
        (v, pos, w), ref = res
        H, W = image.shape[:2]
        n = len(w)
        return (v.shape == (n, 128) and pos.shape == (n, 2) and np.allclose(w, 1.0)
                and np.all(np.isclose(np.linalg.norm(v, axis=1), 1.0) | ((v == 0).all(axis=1) & (contrast == 0)))
                and (pos >= 0).all()
                and (pos[:, 0] <= H).all() and (pos[:, 1] <= W).all()
                and _same_locals(res[0], ref))

    assert_typed_or_good("mmconcepts.vision.dense_sift", call, check=check)


@fuzz_settings(100, **SETTINGS)
@given(ims=st.lists(images(max_side=20), min_size=0, max_size=3), min_size=st.sampled_from([2, 2, 8, 0, -1]))
def test_fuzz_check_images(ims, min_size):
    def check(out):
        return len(out) == len(ims) and all(o.shape == np.asarray(i).shape[:2] + (3,) and min(o.shape[:2]) >= min_size
                                            for o, i in zip(out, ims))

    assert_typed_or_good("mmconcepts.vision.check_images", lambda: check_images(ims, min_size=min_size), check=check)


def _bag_check(n_images, k, normalize="l1"):
    def check(H):
        H = H.toarray() if sp.issparse(H) else H
        if H.shape != (n_images, k) or (H < 0).any():
            return False
        return normalize != "l1" or np.allclose(H.sum(axis=1)[H.sum(axis=1) > 0], 1.0)

    return check


@fuzz_settings(40, **SETTINGS)
@given(ims=st.lists(images(max_side=20, valid_only=True), min_size=1, max_size=3),
       n_colors=st.sampled_from([0, 1, 3, 3, 3, 1000]), normalize=st.sampled_from(["l1", "l1", None, "l2"]))
def test_fuzz_color_histograms(ims, n_colors, normalize):
    """Fit/transform: (n_images, n_colors) nonnegative histograms, rows summing to one with l1."""

    def call():
        est = ColorHistograms(n_colors=n_colors, n_segments=6, normalize=normalize, random_state=0)
        a = est.fit_transform(ims)
        return a, est.transform(ims)

    def check(res):
        a, b = res
        return _bag_check(len(ims), n_colors, normalize)(a) and np.allclose(a, b)

    assert_typed_or_good("mmconcepts.vision.ColorHistograms", call, check=check)


@fuzz_settings(40, **SETTINGS)
@given(ims=st.lists(images(max_side=32, valid_only=True, min_side=12), min_size=1, max_size=3),
       n_words=st.sampled_from([0, 2, 4, 4, 10_000]), patch_size=st.sampled_from([0, 8, 8, 8, 12, 32]),
       contrast=st.sampled_from([0.0, 0.0, 0.01, 10.0]))
def test_fuzz_keypoint_bag(ims, n_words, patch_size, contrast):
    def call():
        est = KeypointBag(n_words=n_words, patch_size=patch_size, step=4, contrast_threshold=contrast, random_state=0)
        a = est.fit_transform(ims)
        return a, est.transform(ims)

    def check(res):
        a, b = res
        return _bag_check(len(ims), n_words)(a) and np.allclose(a, b)

    assert_typed_or_good("mmconcepts.vision.KeypointBag", call, check=check)


@fuzz_settings(30, **SETTINGS)
@given(ims=st.lists(images(max_side=24, valid_only=True, min_side=8), min_size=1, max_size=3),
       descriptors=st.sampled_from([("color",), ("color", "color_pairs"), ("keypoints", "keypoint_pairs"), (),
                                    ("nope",), ("color", "color")]),
       order_kind=st.sampled_from(["ok", "ok", "ok", "bad_base"]))
def test_fuzz_image_features(ims, descriptors, order_kind):
    """Named descriptor sets with one row per image; stack_descriptors keeps the rows and sums the columns."""

    def call():
        est = ImageFeatures(descriptors,
                            color=ColorHistograms(n_colors=3, n_segments=6, random_state=0),
                            keypoints=KeypointBag(n_words=3, patch_size=8, step=4, contrast_threshold=0.0,
                                                  random_state=0) if order_kind == "ok" else "nope")
        out = est.fit_transform(ims)
        return out, stack_descriptors(out)

    def check(res):
        out, stacked = res
        return (list(out) == list(descriptors) and all(m.shape[0] == len(ims) for m in out.values())
                and stacked.shape == (len(ims), sum(m.shape[1] for m in out.values())))

    assert_typed_or_good("mmconcepts.vision.ImageFeatures", call, check=check)


@fuzz_settings(30, **SETTINGS)
@given(ims=st.lists(images(max_side=20, valid_only=True), min_size=1, max_size=2),
       order=st.sampled_from([1, 2, 2, 3, 4]), n_neighbors=st.sampled_from([0, 1, 4, 4, 100]))
def test_fuzz_mid_features(ims, order, n_neighbors):
    def call():
        base = ColorHistograms(n_colors=3, n_segments=6, random_state=0)
        return MidFeatures(base, order=order, n_neighbors=n_neighbors).fit_transform(ims)

    def check(M):
        return M.shape == (len(ims), n_tuple_columns(3, order)) and (M.toarray() >= 0).all()

    assert_typed_or_good("mmconcepts.vision.MidFeatures", call, check=check)


@fuzz_settings(300, **SETTINGS)
@given(pos=st.sampled_from([(0, 2), (1, 2), (5, 2), (5, 3), (5,)]).flatmap(
    lambda s: arrays(float, s, elements=st.one_of(st.floats(-100, 100), st.sampled_from([np.nan, np.inf])))),
    order=st.sampled_from([1, 2, 3, 4]), n_neighbors=st.sampled_from([-1, 0, 1, 4, 100]))
def test_fuzz_neighbour_tuples(pos, order, n_neighbors):
    """Tuples of distinct indices of existing positions."""

    def check(t):
        return (t.ndim == 2 and t.shape[1] == order and (t >= 0).all() and (t < len(pos)).all()
                and all(len(set(row)) == order for row in t.tolist()))

    assert_typed_or_good("mmconcepts.vision.neighbour_tuples",
                         lambda: neighbour_tuples(pos, order=order, n_neighbors=n_neighbors), check=check)


@fuzz_settings(300, **SETTINGS)
@given(words=st.sampled_from([(0, 2), (3, 2), (3, 3), (3, 1), (3,), (3, 0)]).flatmap(
    lambda s: arrays(int, s, elements=st.integers(-2, 10))))
def test_fuzz_tuple_columns(words):
    """Column indices in [0, n_tuple_columns(K, r)) for words < K; a tuple maps to one column whatever its order."""

    def check(cols):
        if cols.shape != (len(words),) or (cols < 0).any():
            return False
        if words.size and cols.max() >= n_tuple_columns(int(words.max()) + 1, words.shape[1]):
            return False
        return np.array_equal(cols, tuple_columns(words[:, ::-1])) if words.size else True

    assert_typed_or_good("mmconcepts.vision.tuple_columns", lambda: tuple_columns(words), check=check)
