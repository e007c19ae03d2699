"""Tests of mmconcepts.vision: image sets, loaders, descriptors, the synthetic objects."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from conftest import real_data_path

from mmconcepts.errors import DataError, DataFormatError, ParameterError
from mmconcepts.vision import (
    ColorHistograms,
    ImageFeatures,
    ImageSet,
    KeypointBag,
    MidFeatures,
    as_rgb_image,
    dense_sift,
    image_statistics,
    load_coil20,
    load_eth80,
    load_image_folder,
    make_objects,
    n_tuple_columns,
    neighbour_tuples,
    stack_descriptors,
    tuple_columns,
    write_image_folder,
)



@pytest.fixture
def eth80() -> Path:
    """The real ETH-80 folder of the data root (skips the test when absent)."""
    return real_data_path("eth80")


@pytest.fixture
def coil20() -> Path:
    """The real COIL20.mat of the data root (skips the test when absent)."""
    path = real_data_path("coil20") / "COIL20.mat"
    if not path.is_file():
        pytest.skip(f"COIL20.mat absent from {path.parent}")
    return path


@pytest.fixture(scope="module")
def objects() -> ImageSet:
    """6 synthetic objects x 6 views (small, shared by the descriptor tests)."""
    return make_objects(6, 6, random_state=3)


@pytest.fixture(scope="module")
def split(objects):
    v = np.array([int(x) for x in objects.views])
    return objects.subset(v % 2 == 0), objects.subset(v % 2 == 1)


def _small_features(**kw):
    return ImageFeatures(color=ColorHistograms(n_colors=12, n_segments=30),
                         keypoints=KeypointBag(n_words=24), **kw)


# --------------------------------------------------------------------------- image sets


def test_as_rgb_image_conversions():
    g = as_rgb_image(np.full((4, 5), 128, dtype=np.uint8))
    assert g.shape == (4, 5, 3) and g.dtype == np.float64
    np.testing.assert_allclose(g, 128 / 255)
    rgba = as_rgb_image(np.zeros((3, 3, 4), dtype=np.uint16))
    assert rgba.shape == (3, 3, 3)
    assert as_rgb_image(np.ones((2, 2), dtype=bool)).max() == 1.0


@pytest.mark.parametrize("bad", [
    np.full((4, 4, 3), np.nan),
    np.full((4, 4, 3), 1.5),
    -np.ones((4, 4)),
    np.zeros((4, 4, 5)),
    np.zeros(16),
    np.zeros((1, 8, 3)),
    np.array([["a", "b"], ["c", "d"]]),
])
def test_bad_arrays_raise_data_error(bad):
    with pytest.raises(DataError):
        as_rgb_image(bad)
    with pytest.raises(DataError):
        ImageSet([bad], ["x"])


def test_image_set_checks_and_subset():
    ims = [np.zeros((8, 8)), np.ones((8, 8, 3)), np.full((8, 8, 3), 0.5)]
    with pytest.raises(DataError, match="labels"):
        ImageSet(ims, ["a", "b"])
    with pytest.raises(DataError, match="views"):
        ImageSet(ims, ["a", "b", "a"], views=["1"])
    s = ImageSet(ims, ["b", "a", "b"], views=[0, 1, 2])
    assert s.classes == ("a", "b") and s.views == ["0", "1", "2"]
    np.testing.assert_array_equal(s.label_ids, [1, 0, 1])
    sub = s.subset(np.array([True, False, True]))
    assert len(sub) == 2 and sub.labels == ["b", "b"] and sub.views == ["0", "2"]
    assert s.subset([1]).labels == ["a"]
    with pytest.raises(ParameterError):
        s.subset([5])
    assert s.label_matrix().tolist() == [[0, 1], [1, 0], [0, 1]]


# --------------------------------------------------------------------------- generator and folders


def test_generator_write_load_roundtrip(tmp_path):
    s = make_objects(3, 4, random_state=1)
    assert len(s) == 12 and s.classes == ("obj00", "obj01", "obj02")
    assert all(im.shape == (96, 96, 3) for im in s.images)
    labels_csv = write_image_folder(s, tmp_path / "objs")
    assert labels_csv.name == "labels.csv"
    back = load_image_folder(tmp_path / "objs")
    assert back.labels == s.labels and back.views == s.views and back.categories == s.categories
    assert len(back.skipped) == 0
    diff = max(np.abs(a - b).max() for a, b in zip(s.images, back.images))
    assert diff <= 0.5 / 255 + 1e-12
    with pytest.raises(ParameterError, match="overwrite"):
        write_image_folder(s, tmp_path / "objs")
    write_image_folder(s.subset([0, 1]), tmp_path / "objs", overwrite=True)
    assert len(load_image_folder(tmp_path / "objs")) == 2
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left


def test_generator_is_deterministic_and_prefix_stable():
    a = make_objects(2, 3, random_state=7)
    b = make_objects(3, 4, random_state=7)  # more objects and views: the first ones unchanged
    c = make_objects(2, 3, random_state=8)
    for i in range(2):
        for v in range(3):
            np.testing.assert_array_equal(a.images[i * 3 + v], b.images[i * 4 + v])
    assert max(np.abs(x - y).max() for x, y in zip(a.images, c.images)) > 0.2
    assert len({im.tobytes() for im in a.images}) == len(a)  # every view differs


def test_generator_statistics_in_eth80_ranges():
    # ETH-80 (measured, module docstring of vision.synthetic): object area 8-44 % (median
    # 19 %), bounding box 47-76 px (median 67), object centre 44-52 px.
    st = image_statistics(n_objects=12, n_views=4, random_state=5)
    assert 0.12 <= np.median(st["area"]) <= 0.30
    assert 45 <= np.median(st["bbox"]) <= 75
    assert np.all(np.abs(np.median(st["centre"], axis=0) - 48) < 3)
    assert 0.15 <= np.median(st["object_hsv"][:, 1]) <= 0.5  # ETH-80: 0.30


def _write_png(path: Path, arr: np.ndarray) -> None:
    import imageio.v3 as iio

    iio.imwrite(path, arr)


def test_image_folder_errors(tmp_path):
    root = tmp_path / "imgs"
    root.mkdir()
    with pytest.raises(DataFormatError, match="labels.csv"):
        load_image_folder(root)
    _write_png(root / "a.png", np.zeros((10, 10, 3), np.uint8))
    _write_png(root / "g.png", np.full((10, 12), 200, np.uint8))
    (root / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\nthis is not a png")
    (root / "labels.csv").write_text("file,name\na.png,x\n")
    with pytest.raises(DataFormatError, match="label"):
        load_image_folder(root)
    (root / "labels.csv").write_text("file,labels\na.png,x\nbroken.png,y\ng.png,z\nmissing.png,w\n")
    with pytest.raises(DataFormatError, match="broken.png"):
        load_image_folder(root)
    with pytest.warns(RuntimeWarning, match="2 file"):
        s = load_image_folder(root, on_error="skip")
    assert s.labels == ["x", "z"] and s.views is None
    assert s.images[1].shape == (10, 12, 3)  # grayscale promoted
    assert [Path(f).name for f, _ in s.skipped] == ["broken.png", "missing.png"]
    assert "broken.png" in s.skipped[0].reason
    with pytest.raises(ParameterError):
        load_image_folder(root, on_error="ignore")


# --------------------------------------------------------------------------- real data


def test_load_eth80_subset(eth80):
    s = load_eth80(eth80, categories=["cow", "cup"], instances=[1, 2])
    assert s.classes == ("cow1", "cow2", "cup1", "cup2")
    assert len(s) == 4 * 41
    assert set(s.categories) == {"cow", "cup"}
    assert s.views[0] == "000-000" and all(len(v) == 7 for v in s.views)
    assert all(im.shape == (96, 96, 3) and 0 <= im.min() and im.max() <= 1 for im in s.images)
    assert s.paths[0].name == "cow1-000-000.png"
    with pytest.raises(ParameterError, match="zebra"):
        load_eth80(eth80, categories=["zebra"])


def test_load_eth80_corrupt_file(tmp_path, eth80):
    import shutil

    for name in ("cow1-000-000.png", "cow1-022-000.png"):
        shutil.copy(eth80 / name, tmp_path / name)
    (tmp_path / "cow1-045-090.png").write_bytes(b"garbage")
    with pytest.raises(DataFormatError, match="cow1-045-090.png"):
        load_eth80(tmp_path)
    with pytest.warns(RuntimeWarning):
        s = load_eth80(tmp_path, on_error="skip")
    assert len(s) == 2 and len(s.skipped) == 1


@pytest.mark.parametrize("odd", ["folder", "dangling link", "link to a folder"])
def test_load_eth80_reports_what_is_named_like_an_image_but_is_no_file(tmp_path, odd):
    """A folder or a link to nothing named like an ETH-80 image is not passed over in silence: it raises, or
    is skipped and reported as any unreadable file."""
    import imageio.v3 as iio

    for name in ("cow1-000-000.png", "cow1-022-000.png"):
        iio.imwrite(tmp_path / name, np.zeros((6, 6, 3), dtype=np.uint8))
    bad = tmp_path / "cow1-045-090.png"
    if odd == "folder":
        bad.mkdir()
    elif odd == "dangling link":
        bad.symlink_to(tmp_path / "gone.png")
    else:
        (tmp_path / "sub").mkdir()
        bad.symlink_to(tmp_path / "sub")
    what = {"folder": "is a folder", "dangling link": "links to .*gone.png, which does not exist",
            "link to a folder": "is a folder"}[odd]
    with pytest.raises(DataFormatError, match=f"cow1-045-090.png {what}"):
        load_eth80(tmp_path)
    with pytest.warns(RuntimeWarning, match=r"1 file\(s\) of .* could not be read and were skipped"):
        s = load_eth80(tmp_path, on_error="skip")
    assert len(s) == 2 and [Path(k.file).name for k in s.skipped] == ["cow1-045-090.png"]


def _extent(mask: np.ndarray) -> tuple[int, int]:
    rr, cc = np.nonzero(mask)
    return rr.max() - rr.min() + 1, cc.max() - cc.min() + 1


def test_load_coil20_upright(coil20):
    s = load_coil20(coil20)
    assert len(s) == 1440 and len(s.classes) == 20
    assert all(s.labels.count(c) == 72 for c in s.classes)
    im = s.images[0]
    assert im.shape == (32, 32, 3)
    np.testing.assert_array_equal(im[..., 0], im[..., 2])
    ids = np.array([int(l) for l in s.labels])
    views = np.array([int(v) for v in s.views])
    # Checked by looking at the data: objects 3 and 6 are toy cars seen from the side at
    # view 0, much wider than tall when upright (taller than wide if transposed).
    for car in (3, 6):
        img = s.images[int(np.flatnonzero((ids == car) & (views == 0))[0])][..., 0]
        h, w = _extent(img > 0.15)
        assert w > 2 * h
        ht, wt = _extent(img.T > 0.15)
        assert not wt > 2 * ht
    # Object 13 is a lamp-like object: wide cap on top of a narrow stem, in every view; an
    # upside-down image would have the wide part at the bottom.
    lamp = np.stack([s.images[i][..., 0] for i in np.flatnonzero(ids == 13)]) > 0.15
    top, bottom = lamp[:, :11].sum(axis=2).mean(axis=1), lamp[:, -11:].sum(axis=2).mean(axis=1)
    assert np.all(top > bottom)


def test_load_coil20_bad_file(tmp_path):
    p = tmp_path / "COIL20.mat"
    p.write_bytes(b"not a mat file at all")
    with pytest.raises(DataFormatError, match="COIL20.mat"):
        load_coil20(p)


# --------------------------------------------------------------------------- building blocks


@pytest.mark.parametrize("order", [2, 3])
def test_tuple_columns_is_a_bijection(order):
    K = 6
    tuples = np.array(list(itertools.combinations_with_replacement(range(K), order)))
    cols = tuple_columns(tuples)
    assert n_tuple_columns(K, order) == math.comb(K + order - 1, order) == len(tuples)
    np.testing.assert_array_equal(np.sort(cols), np.arange(len(tuples)))


def test_neighbour_tuples_on_a_grid():
    pos = np.array([(r, c) for r in range(3) for c in range(3)], dtype=float)
    pairs = neighbour_tuples(pos, order=2, n_neighbors=4)
    # every grid point links to its 4 (or fewer, at the border: then diagonals) nearest
    adj = {(min(i, j), max(i, j)) for i in range(9) for j in range(9)
           if abs(pos[i] - pos[j]).sum() == 1}
    assert adj <= {tuple(p) for p in pairs}
    assert np.all(pairs[:, 0] < pairs[:, 1]) and len(np.unique(pairs, axis=0)) == len(pairs)
    tri = neighbour_tuples(pos, order=3, n_neighbors=2)
    assert tri.shape[1] == 3 and np.all(np.diff(tri, axis=1) > 0)
    assert neighbour_tuples(pos[:1], order=2).shape == (0, 2)


def test_dense_sift_rotation_invariance_and_grid_paths(objects):
    im = objects.images[0]
    a = dense_sift(im)
    b = dense_sift(np.ascontiguousarray(np.rot90(im)))
    n = im.shape[1]
    where = {tuple(p): i for i, p in enumerate(b.positions)}
    idx = [where[(n - 1 - c, r)] for r, c in a.positions]  # rot90 maps (r, c) to (n-1-c, r)
    np.testing.assert_allclose(a.vectors, b.vectors[idx], atol=1e-10)
    nz = a.vectors.any(axis=1)
    assert nz.sum() > 5 and np.all(a.vectors >= 0)
    np.testing.assert_allclose(np.linalg.norm(a.vectors[nz], axis=1), 1.0)
    # upright: the regular-grid path (step 8) equals the integral-image path (step 2)
    u8 = dense_sift(im, step=8, rotation_invariant=False)
    u2 = dense_sift(im, step=2, rotation_invariant=False)
    where = {tuple(p): i for i, p in enumerate(u2.positions)}
    np.testing.assert_allclose(u8.vectors, u2.vectors[[where[tuple(p)] for p in u8.positions]], atol=1e-10)


# --------------------------------------------------------------------------- descriptors


def test_descriptor_sets_dimensions_nonnegative_and_normalised(split):
    train, test = split
    f = _small_features(descriptors=("color", "color_pairs", "color_triplets", "keypoints", "keypoint_pairs",
                                     "keypoint_triplets"), random_state=0)
    f.fit(train)
    expected = {"color": 12, "color_pairs": 78, "color_triplets": 364, "keypoints": 24, "keypoint_pairs": 300,
                "keypoint_triplets": 2600}
    assert f.n_features_out_ == expected
    X = f.transform(test)
    assert list(X) == list(expected)
    for name, M in X.items():
        assert M.shape == (len(test), expected[name])
        assert sp.issparse(M) == ("pairs" in name or "triplets" in name)
        dense = M.toarray() if sp.issparse(M) else M
        assert np.all(dense >= 0)
        np.testing.assert_allclose(dense.sum(axis=1), 1.0)
    counts = _small_features(descriptors=("color", "keypoint_pairs"), normalize=None, random_state=0).fit(train)
    Xc = counts.transform(test)
    np.testing.assert_allclose(Xc["color"].sum(axis=1), 96 * 96)  # superpixel areas in pixels
    assert np.all(Xc["keypoint_pairs"].data == np.round(Xc["keypoint_pairs"].data))


def test_codebooks_come_from_training_images_only(split):
    train, test = split
    f = _small_features(descriptors=("color", "keypoints"), random_state=0).fit(train)
    cb_c, cb_k = f.color_.codebook_.copy(), f.keypoints_.codebook_.copy()
    X1 = f.transform(test)
    f.transform(train)
    np.testing.assert_array_equal(f.color_.codebook_, cb_c)
    np.testing.assert_array_equal(f.keypoints_.codebook_, cb_k)
    X2 = f.transform(test)
    for k in X1:
        np.testing.assert_array_equal(X1[k], X2[k])
    # a refit on other images gives another codebook
    g = _small_features(descriptors=("color", "keypoints"), random_state=0).fit(test)
    assert not np.allclose(np.sort(g.color_.codebook_, axis=0), np.sort(cb_c, axis=0))


def test_descriptors_deterministic_for_a_seed(split):
    train, test = split
    outs = [_small_features(descriptors=("color", "keypoints", "color_pairs"), random_state=s).fit(train)
            for s in (4, 4, 5)]
    np.testing.assert_array_equal(outs[0].keypoints_.codebook_, outs[1].keypoints_.codebook_)
    X0, X1 = outs[0].transform(test), outs[1].transform(test)
    for k in X0:
        a, b = X0[k], X1[k]
        np.testing.assert_array_equal(a.toarray() if sp.issparse(a) else a, b.toarray() if sp.issparse(b) else b)
    assert not np.array_equal(outs[0].keypoints_.codebook_, outs[2].keypoints_.codebook_)


def test_single_transformers_agree_with_front_object(split):
    train, test = split
    front = ImageFeatures(descriptors=("color", "color_pairs"), color=ColorHistograms(n_colors=12, n_segments=30),
                          random_state=0).fit(train)
    Xf = front.transform(test)
    ch = ColorHistograms(n_colors=12, n_segments=30, random_state=0).fit(train)
    np.testing.assert_allclose(ch.transform(test), Xf["color"])
    mid = MidFeatures(ColorHistograms(n_colors=12, n_segments=30, random_state=0), order=2).fit(train)
    np.testing.assert_allclose(mid.transform(test).toarray(), Xf["color_pairs"].toarray())
    kp = MidFeatures(KeypointBag(n_words=10, random_state=0), order=3, n_neighbors=3).fit(train)
    assert kp.transform(test).shape == (len(test), math.comb(12, 3))


def test_parameter_and_data_errors(split):
    train, _ = split
    with pytest.raises(ParameterError, match="pairs"):
        ImageFeatures(descriptors=("pairs",)).fit(train)
    with pytest.raises(ParameterError):
        ColorHistograms(n_colors=1).fit(train)
    with pytest.raises(ParameterError, match="multiple of 4"):
        KeypointBag(patch_size=18).fit(train)
    with pytest.raises(ParameterError):
        MidFeatures(order=4).fit(train)
    with pytest.raises(DataError, match="distinct"):
        ColorHistograms(n_colors=50, n_segments=4).fit(train.subset([0]))
    with pytest.raises(DataError, match="single image"):
        KeypointBag().fit(train.images[0])
    with pytest.raises(DataError):
        KeypointBag().fit([np.zeros((8, 8, 3))])  # smaller than a patch
    with pytest.raises(DataError):
        ColorHistograms().fit([np.full((20, 20, 3), np.nan)])


def test_stack_descriptors(split):
    train, _ = split
    X = _small_features(descriptors=("color", "keypoints", "color_pairs"), random_state=0).fit_transform(train)
    S = stack_descriptors(X)
    assert sp.isspmatrix_csr(S) and S.shape == (len(train), 12 + 24 + 78)
    np.testing.assert_allclose(S.sum(axis=1), 3.0)
    S2 = stack_descriptors(X, ["keypoints"], weights={"keypoints": 2.0})
    np.testing.assert_allclose(S2.toarray(), 2 * X["keypoints"])
    with pytest.raises(ParameterError):
        stack_descriptors(X, ["nope"])


# --------------------------------------------------------------------------- recognition


def _nn_accuracy(train_X, train_y, test_X, test_y) -> float:
    from sklearn.neighbors import KNeighborsClassifier

    clf = KNeighborsClassifier(n_neighbors=1, metric="cosine").fit(train_X, train_y)
    return float(np.mean(clf.predict(test_X) == np.asarray(test_y)))


def test_nearest_neighbour_recognises_generated_objects_from_new_views():
    s = make_objects(10, 12, random_state=11)
    v = np.array([int(x) for x in s.views])
    train, test = s.subset(v % 2 == 0), s.subset(v % 2 == 1)
    f = ImageFeatures(random_state=0)
    A, B = stack_descriptors(f.fit_transform(train)), stack_descriptors(f.transform(test))
    acc = _nn_accuracy(A, train.labels, B, test.labels)
    assert acc >= 0.35, acc  # chance: 0.10
    # the same images with shuffled training labels are not recognised
    rng = np.random.default_rng(0)
    assert _nn_accuracy(A, rng.permutation(train.labels), B, test.labels) < acc


@pytest.mark.slow
def test_nearest_neighbour_recognises_eth80_objects_from_new_views(eth80):
    s = load_eth80(eth80, instances=[1])  # 8 objects (one per category), 41 views
    v = np.arange(len(s)) % 41
    train, test = s.subset(v % 2 == 0), s.subset(v % 2 == 1)
    f = ImageFeatures(random_state=0)
    A, B = stack_descriptors(f.fit_transform(train)), stack_descriptors(f.transform(test))
    assert _nn_accuracy(A, train.labels, B, test.labels) >= 0.6  # chance: 0.125


@pytest.mark.slow  # worker processes
def test_parallel_extraction_gives_the_same_features():
    s = make_objects(2, 17, random_state=2)  # 34 images: two joblib chunks
    a = _small_features(descriptors=("color", "keypoint_pairs"), random_state=0, n_jobs=1).fit_transform(s)
    b = _small_features(descriptors=("color", "keypoint_pairs"), random_state=0, n_jobs=2).fit_transform(s)
    np.testing.assert_allclose(a["color"], b["color"])
    np.testing.assert_allclose(a["keypoint_pairs"].toarray(), b["keypoint_pairs"].toarray())


def test_features_from_cached_locals_equal_direct_features():
    """extract_locals + fit_locals / transform_locals give fit_transform / transform exactly."""
    s = make_objects(3, 6, random_state=4)
    train, test = s.subset(np.arange(len(s)) % 2 == 0), s.subset(np.arange(len(s)) % 2 == 1)
    direct = _small_features(descriptors=("color", "keypoints", "color_pairs"), random_state=0)
    a_tr, a_te = direct.fit_transform(train), direct.transform(test)
    staged = _small_features(descriptors=("color", "keypoints", "color_pairs"), random_state=0)
    b_tr = staged.fit_locals(*staged.extract_locals(train))
    b_te = staged.transform_locals(*staged.extract_locals(test))
    for name in ("color", "keypoints", "color_pairs"):
        for a, b in ((a_tr[name], b_tr[name]), (a_te[name], b_te[name])):
            a = a.toarray() if hasattr(a, "toarray") else a
            b = b.toarray() if hasattr(b, "toarray") else b
            np.testing.assert_array_equal(a, b)
    only_colour = _small_features(descriptors=("color",), random_state=0)
    c_loc, k_loc = only_colour.extract_locals(train)
    assert k_loc is None and len(c_loc) == len(train)
    with pytest.raises(ParameterError, match="keypoint"):
        _small_features(descriptors=("keypoints",), random_state=0).fit_locals(c_loc, None)


def test_stacked_image_features_take_their_place_in_a_pipeline(split):
    """stack=True: one matrix (the sets side by side, as stack_descriptors), so a Pipeline can go on to an NMF."""
    from sklearn.pipeline import make_pipeline

    from mmconcepts.nmf import NMF

    train, test = split
    sets = _small_features(descriptors=("color", "color_pairs"), random_state=0).fit(train)
    stacked = _small_features(descriptors=("color", "color_pairs"), random_state=0, stack=True).fit(train)
    expected = stack_descriptors(sets.transform(test), ["color", "color_pairs"])
    assert (stacked.transform(test) != expected).nnz == 0
    pipe = make_pipeline(_small_features(descriptors=("color", "color_pairs"), random_state=0, stack=True),
                         NMF(3, max_iter=20, random_state=0))
    W = pipe.fit_transform(train)
    assert W.shape == (len(train), 3) and np.isfinite(W).all()
    assert pipe.transform(test).shape == (len(test), 3)
