"""``verbose=``: the feature extractors and data generators draw a progress bar on stderr when asked, and
nothing otherwise; the results are the same bit for bit either way."""

from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.sparse as sp

from mmconcepts._progress import progress, progress_chunks
from mmconcepts.errors import ParameterError
from mmconcepts.motion.synthetic import make_choreo1, write_choreo2
from mmconcepts.motion.data import load_choreo2
from mmconcepts.sound import HAC
from mmconcepts.vision import ColorHistograms, ImageFeatures, KeypointBag, MidFeatures, make_objects


def _same(a, b) -> None:
    """``a`` and ``b`` equal bit for bit (arrays, sparse matrices, or dicts of them)."""
    if isinstance(a, dict):
        assert list(a) == list(b)
        for k in a:
            _same(a[k], b[k])
        return
    assert type(a) is type(b)
    if sp.issparse(a):
        assert a.shape == b.shape and (a != b).nnz == 0 and a.dtype == b.dtype
    else:
        assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.fixture(scope="module")
def images():
    return make_objects(3, 4, random_state=1)


@pytest.fixture(scope="module")
def sequences():
    rng = np.random.default_rng(0)
    return [rng.normal(size=(int(rng.integers(30, 60)), 6)) for _ in range(8)]


EXTRACTORS = {
    "HAC": (lambda v: HAC(n_clusters=(3, 3, 2), lags=(1, 2), max_iter=10, random_state=0, verbose=v),
            "sequences", "HAC codebooks"),
    "ColorHistograms": (lambda v: ColorHistograms(n_colors=4, random_state=0, verbose=v), "images", "image features"),
    "KeypointBag": (lambda v: KeypointBag(n_words=4, random_state=0, verbose=v), "images", "image features"),
    "MidFeatures": (lambda v: MidFeatures(ColorHistograms(n_colors=4, random_state=0, verbose=v)), "images",
                    "image features"),
    "ImageFeatures": (lambda v: ImageFeatures(random_state=0, verbose=v,
                                              color=ColorHistograms(n_colors=4), keypoints=KeypointBag(n_words=4)),
                      "images", "image features"),
}


@pytest.mark.parametrize("name", sorted(EXTRACTORS))
def test_an_extractor_shows_a_bar_only_when_verbose_and_gives_the_same_numbers(name, request, capsys):
    make, data, label = EXTRACTORS[name]
    X = request.getfixturevalue(data)
    quiet = make(False)
    expected_fit, expected = quiet.fit_transform(X), quiet.transform(X)
    assert capsys.readouterr().err == ""
    loud = make(True)
    got_fit = loud.fit_transform(X)
    err = capsys.readouterr().err
    assert label in err and "|" in err  # a tqdm bar, with its label
    _same(got_fit, expected_fit)
    _same(loud.transform(X), expected)


@pytest.mark.slow  # worker processes
def test_image_features_count_images_over_worker_processes(capsys):
    """With n_jobs, the bar advances by chunks of images and counts images; the features are the same."""
    ims = make_objects(4, 10, random_state=2)  # 40 images: two chunks

    def make(verbose):
        return ImageFeatures(("color",), color=ColorHistograms(n_colors=4), random_state=0, n_jobs=2, verbose=verbose)

    expected = make(False).fit_transform(ims)
    assert capsys.readouterr().err == ""
    got = make(True).fit_transform(ims)
    err = capsys.readouterr().err
    assert "image features" in err and "/40 " in err
    _same(got, expected)


@pytest.mark.parametrize("bad", [-1, 0.5, "yes", None])
def test_verbose_is_a_bool_or_a_level(bad):
    with pytest.raises(ParameterError, match="verbose must be a bool or an int >= 0"):
        HAC(verbose=bad).fit([np.zeros((10, 2))])
    with pytest.raises(ParameterError, match="verbose must be a bool or an int >= 0"):
        ImageFeatures(verbose=bad).fit(make_objects(1, 2, random_state=0))
    with pytest.raises(ParameterError, match="make_choreo1: verbose must be a bool or an int >= 0"):
        make_choreo1("primitive", n_records=1, verbose=bad)


def test_the_choreography_generators_show_a_bar_only_when_verbose(tmp_path, capsys):
    quiet = make_choreo1("mixed_full", data_home=tmp_path / "a", n_records=3, random_state=4)
    assert capsys.readouterr().err == ""
    loud = make_choreo1("mixed_full", data_home=tmp_path / "b", n_records=3, random_state=4, verbose=True)
    err = capsys.readouterr().err
    assert "generated mixed_full" in err and f"/{len(loud)} " in err
    assert [r.labels for r in loud] == [r.labels for r in quiet]
    for a, b in zip(loud, quiet):
        _same(a.positions, b.positions)

    write_choreo2(tmp_path / "c", n_records=2, random_state=4)
    assert capsys.readouterr().err == ""
    write_choreo2(tmp_path / "d", n_records=2, random_state=4, verbose=True)
    err = capsys.readouterr().err
    assert "generated choreo2" in err and "/2 " in err
    for a, b in zip(load_choreo2(tmp_path / "c" / "choreo2.json"), load_choreo2(tmp_path / "d" / "choreo2.json")):
        _same(a.positions, b.positions)


def test_progress_wraps_only_when_verbose(capsys):
    items = [3, 1, 2]
    assert progress(items, verbose=False) is items and progress(items, verbose=0) is items
    assert capsys.readouterr().err == ""
    for level in (True, 2):  # a level above 0 counts as True, as scikit-learn's verbose
        assert list(progress(iter(items), verbose=level, total=3, desc="counting", unit="thing")) == items
        err = capsys.readouterr().err
        assert "counting" in err and "/3 " in err and "thing" in err


def test_progress_chunks_counts_items_and_keeps_the_order(capsys):
    assert list(progress_chunks(iter("abc"), [2, 5, 1], verbose=False)) == ["a", "b", "c"]
    assert capsys.readouterr().err == ""

    def slow():  # results that come slower than tqdm redraws (0.1 s), so each count is drawn
        for r in "abc":
            time.sleep(0.15)
            yield r

    assert list(progress_chunks(slow(), [2, 5, 1], verbose=True, desc="chunked")) == ["a", "b", "c"]
    err = capsys.readouterr().err
    assert "chunked" in err and " 2/8 " in err and " 7/8 " in err  # moved by each chunk's size
