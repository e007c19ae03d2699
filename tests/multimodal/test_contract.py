"""The estimator contract for the multimodal learner and the image and motion transformers.

MultimodalNMF, ImageFeatures, ColorHistograms, KeypointBag, MidFeatures and MotionHistograms:
scikit-learn estimators (clone, get_params/set_params), parameters declared once in
``_parameter_constraints`` and checked at the start of fit, NotFittedError when unfitted, and
save/load without pickle.

scikit-learn's ``check_estimator`` feeds 2-D numeric tables (n_samples, n_features). The image
transformers take a list of (H, W, 3) images and MotionHistograms a list of (n_frames, n_dof)
recordings, and their tags say so (``two_d_array=False``), on which scikit-learn skips every
check. To run its whole list anyway, the checks below see each transformer through a subclass
that claims to take tables: the checks that do not feed data pass; the ones that feed a table
are listed as expected failures with the reason, and the properties they would test are tested
below on images and recordings instead. MultimodalNMF takes a mapping of modality names to
matrices, which no check of scikit-learn can build; its contract is tested directly.
"""

from __future__ import annotations

import inspect
import json
import warnings

import numpy as np
import pytest
from sklearn.base import BaseEstimator, clone
from sklearn.exceptions import NotFittedError
from sklearn.utils.estimator_checks import check_estimator

from mmconcepts.errors import DataError, DataFormatError, ParameterError, VersionMismatchError
from mmconcepts.motion import MotionHistograms
from mmconcepts.multimodal import FORMAT_VERSION, MultimodalNMF
from mmconcepts.nmf import NMF
from mmconcepts.vision import ColorHistograms, ImageFeatures, KeypointBag, MidFeatures, make_objects

# --------------------------------------------------------------------------- scikit-learn's checks

_TABLE = "fit takes a list of {what}, not a 2-D array (n_samples, n_features); the check feeds a table"
#: The checks that feed a 2-D table; each fails because the estimator refuses a table (a DataError
#: naming what it takes), before anything else happens. What they test is tested below on real input.
_TABLE_CHECKS = [
    "check_fit_score_takes_y", "check_estimators_overwrite_params", "check_dont_overwrite_parameters",
    "check_estimators_fit_returns_self", "check_readonly_memmap_input", "check_n_features_in_after_fitting",
    "check_estimators_dtypes", "check_dtype_object", "check_pipeline_consistency", "check_estimators_pickle",
    "check_f_contiguous_array_estimator", "check_transformer_data_not_an_array", "check_transformer_general",
    "check_methods_sample_order_invariance", "check_methods_subset_invariance", "check_dict_unchanged",
    "check_fit_idempotent", "check_fit_check_is_fitted", "check_n_features_in", "check_fit2d_predict1d",
]
_SPECIFIC = {
    "check_positive_only_tag_during_fit": "the table is refused as not {what}, not for its negative values",
    "check_complex_data": "the table is refused as not {what} before its values are read",
    "check_estimators_nan_inf": "the table is refused as not {what} before its values are read; NaN and inf in "
                                "real input raise DataError (test_nan_and_inf_in_the_input_raise)",
    "check_estimators_empty_data_messages": "the table is refused as not {what}; the message does not count "
                                            "samples and features, which a list of {what} does not have",
    "check_fit2d_1sample": "the table is refused as not {what}; the message does not count samples",
    "check_fit2d_1feature": "the table is refused as not {what}; the message does not count features",
    "check_estimator_sparse_tag": "{what} are never sparse: a sparse table is refused as not {what}",
    "check_estimator_sparse_array": "{what} are never sparse: a sparse table is refused as not {what}",
    "check_estimator_sparse_matrix": "{what} are never sparse: a sparse table is refused as not {what}",
}


def _expected_failed(what: str, extra: tuple[str, ...] = ()) -> dict[str, str]:
    out = {name: _TABLE.format(what=what) for name in _TABLE_CHECKS + list(extra)}
    out.update({name: reason.format(what=what) for name, reason in _SPECIFIC.items()})
    return out


_IMAGES = "(H, W, 3) images"
_RECORDINGS = "(n_frames, n_dof) recordings"
EXPECTED_FAILED_CHECKS = {
    "ImageFeatures": _expected_failed(_IMAGES),
    "ColorHistograms": _expected_failed(_IMAGES),
    "KeypointBag": _expected_failed(_IMAGES),
    # MidFeatures returns CSR matrices of float64 (counts or proportions), so scikit-learn also
    # runs its dtype-preservation check, which feeds a table too.
    "MidFeatures": _expected_failed(_IMAGES, ("check_transformer_preserve_dtypes",)),
    "MotionHistograms": _expected_failed(_RECORDINGS),
}


def _as_table(cls: type) -> type:
    """``cls`` claiming to take 2-D tables, so that scikit-learn runs all of its checks."""

    def __sklearn_tags__(self):
        tags = cls.__sklearn_tags__(self)
        tags.input_tags.two_d_array = True
        tags.input_tags.three_d_array = False
        return tags

    return type(cls.__name__, (cls,), {"__sklearn_tags__": __sklearn_tags__})


#: Checks that feed no data; every estimator must pass them.
API_CHECKS = {
    "check_estimator_cloneable", "check_estimator_tags_renamed", "check_valid_tag_types", "check_estimator_repr",
    "check_no_attributes_set_in_init", "check_estimators_unfitted", "check_do_not_raise_errors_in_init_or_set_params",
    "check_mixin_order", "check_transformers_unfitted", "check_transformer_n_iter",
    "check_parameters_default_constructible", "check_get_params_invariance", "check_set_params", "check_fit1d",
}


@pytest.mark.parametrize("cls", [ImageFeatures, ColorHistograms, KeypointBag, MidFeatures, MotionHistograms],
                         ids=lambda c: c.__name__)
def test_sklearn_estimator_checks(cls):
    """Default parameters; every check runs, and exactly the listed ones fail."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = check_estimator(_as_table(cls)(), on_fail=None)
    failed = {r["check_name"] for r in results if r["status"] == "failed"}
    passed = {r["check_name"] for r in results if r["status"] == "passed"}
    assert failed == set(EXPECTED_FAILED_CHECKS[cls.__name__])  # no unexpected failure, no stale entry
    assert passed == API_CHECKS


@pytest.mark.parametrize("cls", [ImageFeatures, ColorHistograms, KeypointBag, MidFeatures, MotionHistograms])
def test_the_tags_say_what_the_input_is_and_scikit_learn_then_skips_its_checks(cls):
    from sklearn.utils import get_tags

    tags = get_tags(cls())
    assert not tags.input_tags.two_d_array and tags.input_tags.three_d_array
    assert tags.transformer_tags is not None  # ImageFeatures' missing transformer tags crashed check_estimator
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scikit-learn's SkipTestWarning: "Can't test estimator ..."
        results = check_estimator(cls(), on_fail=None)  # with the true tags: no crash, only the data-free check
    assert [r["status"] for r in results] == ["passed"]


# --------------------------------------------------------------------------- data


@pytest.fixture(scope="module")
def images():
    s = make_objects(3, 4, random_state=5)  # 12 synthetic 96 x 96 object views
    return list(s.images)


def _recordings(seed: int = 0, n: int = 6):
    rng = np.random.default_rng(seed)
    return [np.cumsum(rng.normal(size=(int(rng.integers(20, 40)), 3)), axis=0) for _ in range(n)]


def _small(cls):
    """The smallest useful parameters (the defaults' 256-word codebooks need far more images)."""
    return {
        ImageFeatures: lambda: ImageFeatures(("color", "keypoints", "color_pairs", "keypoint_triplets"),
                                             color=ColorHistograms(n_colors=6, n_segments=20),
                                             keypoints=KeypointBag(n_words=6), random_state=0),
        ColorHistograms: lambda: ColorHistograms(n_colors=6, n_segments=20, random_state=0),
        KeypointBag: lambda: KeypointBag(n_words=6, rotation_invariant=False, random_state=0),
        MidFeatures: lambda: MidFeatures(KeypointBag(n_words=5, random_state=0), order=3, n_neighbors=3),
        MotionHistograms: lambda: MotionHistograms(method="vq", n_bins=5, random_state=0),
    }[cls]()


def _input(cls, images):
    return _recordings() if cls is MotionHistograms else images


def _dense(out):
    """A transform's output as a dict of dense arrays (ImageFeatures gives a dict, CSR for mid-features)."""
    out = out if isinstance(out, dict) else {"": out}
    return {k: (v.toarray() if hasattr(v, "toarray") else np.asarray(v)) for k, v in out.items()}


def _assert_same(a, b):
    a, b = _dense(a), _dense(b)
    assert list(a) == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


TRANSFORMERS = [ImageFeatures, ColorHistograms, KeypointBag, MidFeatures, MotionHistograms]


# --------------------------------------------------------------------------- what the table checks would test


@pytest.mark.parametrize("cls", TRANSFORMERS, ids=lambda c: c.__name__)
def test_fit_returns_self_keeps_params_is_idempotent_and_order_invariant(cls, images):
    X = _input(cls, images)
    est = _small(cls)
    before = repr(est.get_params(deep=True))
    assert est.fit(X) is est
    assert repr(est.get_params(deep=True)) == before  # fit does not write to parameters (nor nested ones)
    first = est.transform(X)
    _assert_same(est.fit(X).transform(X), first)  # refitting gives the same model
    perm = np.random.default_rng(1).permutation(len(X))
    shuffled = est.transform([X[i] for i in perm])
    for k, v in _dense(shuffled).items():
        np.testing.assert_array_equal(v, _dense(first)[k][perm])
    one = est.transform(X[:1])  # a batch of one gives its row of the full batch
    for k, v in _dense(one).items():
        np.testing.assert_array_equal(v, _dense(first)[k][:1])
    _assert_same(clone(est).fit(X).transform(X), first)  # a clone fits the same


@pytest.mark.parametrize("cls", TRANSFORMERS, ids=lambda c: c.__name__)
def test_nan_and_inf_in_the_input_raise(cls, images):
    X = list(_input(cls, images))
    X[1] = X[1].copy()
    X[1][3, 2] = np.nan
    with pytest.raises(DataError):
        _small(cls).fit(X)
    X[1][3, 2] = np.inf
    with pytest.raises(DataError):
        _small(cls).fit(X)


@pytest.mark.parametrize("cls", TRANSFORMERS, ids=lambda c: c.__name__)
def test_unfitted_transform_raises_not_fitted_error(cls, images):
    with pytest.raises(NotFittedError):
        _small(cls).transform(_input(cls, images))


# --------------------------------------------------------------------------- parameter constraints

ESTIMATORS = TRANSFORMERS + [MultimodalNMF]


@pytest.mark.parametrize("cls", ESTIMATORS, ids=lambda c: c.__name__)
def test_constraints_declare_every_parameter(cls):
    params = set(inspect.signature(cls.__init__).parameters) - {"self"}
    assert set(cls._parameter_constraints) == params
    assert cls.get_params is BaseEstimator.get_params and cls.set_params is BaseEstimator.set_params


BAD = [
    (ImageFeatures, "descriptors", ("color", "pairs")), (ImageFeatures, "descriptors", ()),
    (ImageFeatures, "descriptors", ("color", "color")), (ImageFeatures, "color", KeypointBag()),
    (ImageFeatures, "keypoints", ColorHistograms()), (ImageFeatures, "n_neighbors", 1),
    (ImageFeatures, "normalize", "l2"), (ImageFeatures, "n_jobs", 1.5), (ImageFeatures, "random_state", -1),
    (ColorHistograms, "n_colors", 1), (ColorHistograms, "n_segments", 0), (ColorHistograms, "compactness", 0.0),
    (ColorHistograms, "normalize", "l2"), (ColorHistograms, "max_fit_samples", 0), (ColorHistograms, "n_jobs", "2"),
    (ColorHistograms, "random_state", "seed"),
    (KeypointBag, "n_words", 1), (KeypointBag, "patch_size", 18), (KeypointBag, "patch_size", 0),
    (KeypointBag, "step", 0), (KeypointBag, "contrast_threshold", -0.1), (KeypointBag, "rotation_invariant", 1),
    (KeypointBag, "max_fit_samples", 2.0),
    (MidFeatures, "base", NMF()), (MidFeatures, "order", 4), (MidFeatures, "order", True),
    (MidFeatures, "n_neighbors", 0), (MidFeatures, "normalize", "max"),
    (MotionHistograms, "data", "both"), (MotionHistograms, "method", "gmm"), (MotionHistograms, "n_bins", 1),
    (MotionHistograms, "n_bins", (4, 1)), (MotionHistograms, "n_bins", (4, 4, 4)), (MotionHistograms, "delay", 0),
    (MotionHistograms, "smoothing", -1.0), (MotionHistograms, "range_quantile", 0.5),
    (MotionHistograms, "assignment", "fuzzy"), (MotionHistograms, "softness", 0.0), (MotionHistograms, "period", 0),
    (MotionHistograms, "max_fit_samples", 0), (MotionHistograms, "n_init", 0), (MotionHistograms, "random_state", 1.5),
    (MultimodalNMF, "n_components", 0), (MultimodalNMF, "beta_loss", "manhattan"), (MultimodalNMF, "max_iter", -1),
    (MultimodalNMF, "transform_max_iter", 2.5), (MultimodalNMF, "tol", -1e-3), (MultimodalNMF, "normalize", "l2"),
    (MultimodalNMF, "init", "custom"), (MultimodalNMF, "random_state", "x"), (MultimodalNMF, "forget", 0.0),
    (MultimodalNMF, "forget", 1.5), (MultimodalNMF, "partial_max_iter", 0),
]


@pytest.mark.parametrize("cls, name, value", BAD, ids=[f"{c.__name__}-{n}-{v!r}" for c, n, v in BAD])
def test_a_bad_parameter_is_refused_before_the_data_are_read(cls, name, value):
    est = cls().set_params(**{name: value})
    with pytest.raises(ParameterError, match=rf"^{cls.__name__}: {name} must be .*; got "):
        est.fit(None)  # no data at all: the parameter is checked first


@pytest.mark.parametrize("cls, name, value", [
    (ImageFeatures, "descriptors", "color"), (ImageFeatures, "n_jobs", None), (ColorHistograms, "compactness", 0.5),
    (KeypointBag, "patch_size", np.int64(8)), (MidFeatures, "order", np.int64(3)), (MotionHistograms, "n_bins", (3, 4)),
    (MotionHistograms, "period", 2 * np.pi), (MultimodalNMF, "beta_loss", 0.5), (MultimodalNMF, "beta_loss", "KL"),
    (MultimodalNMF, "init", None), (MultimodalNMF, "max_iter", 0),
])
def test_good_parameters_pass_the_constraints(cls, name, value):
    from mmconcepts._validation import validate_params

    validate_params(cls().set_params(**{name: value}), cls._parameter_constraints)


def test_cross_parameter_rules_are_still_checked(images):
    with pytest.raises(ParameterError, match="n_neighbors must be >= 2 for triplets"):
        MidFeatures(order=3, n_neighbors=1).fit(images)
    MidFeatures(ColorHistograms(n_colors=4, n_segments=10, random_state=0), order=2, n_neighbors=1).fit(images)
    with pytest.raises(ParameterError, match="pair only for data='joint' with method='kde'"):
        MotionHistograms(method="vq", n_bins=(3, 3)).fit(_recordings())
    with pytest.raises(ParameterError, match="ColorHistograms: n_colors must be an int >= 2"):
        ImageFeatures(("color",), color=ColorHistograms(n_colors=1)).fit(images)  # the nested estimators too


# --------------------------------------------------------------------------- save / load of the transformers


@pytest.mark.parametrize("cls", TRANSFORMERS, ids=lambda c: c.__name__)
def test_save_load_gives_the_same_transform_and_params(cls, images, tmp_path):
    X = _input(cls, images)
    est = _small(cls).fit(X)
    path = est.save(tmp_path / "model")
    assert path.name == "model.npz"
    with np.load(path, allow_pickle=False) as z:
        header = json.loads(str(z["header"]))
    assert header["format"] == f"mmconcepts.{cls.__name__}"
    loaded = cls.load(path)
    assert type(loaded) is cls
    assert repr(loaded.get_params(deep=True)) == repr(est.get_params(deep=True))
    _assert_same(loaded.transform(X), est.transform(X))


def test_saved_motion_histograms_keep_their_kde_grids(tmp_path):
    X = _recordings()
    est = MotionHistograms(data="joint", n_bins=(3, 4)).fit(X)
    loaded = MotionHistograms.load(est.save(tmp_path / "kde"))
    assert loaded.grid_shape_ == (3, 4)
    np.testing.assert_array_equal(loaded.transform(X), est.transform(X))


def test_a_saved_image_features_keeps_its_fitted_codebooks(images, tmp_path):
    est = _small(ImageFeatures).fit(images)
    loaded = ImageFeatures.load(est.save(tmp_path / "f"))
    np.testing.assert_array_equal(loaded.color_.codebook_, est.color_.codebook_)
    np.testing.assert_array_equal(loaded.keypoints_.codebook_, est.keypoints_.codebook_)
    assert loaded.descriptors_ == est.descriptors_ and loaded.n_features_out_ == est.n_features_out_


def test_loading_the_wrong_file_raises(images, tmp_path):
    path = ColorHistograms(n_colors=4, n_segments=10, random_state=0).fit(images).save(tmp_path / "c")
    with pytest.raises(DataFormatError, match="mmconcepts.ColorHistograms"):
        KeypointBag.load(path)
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays.pop("header")))
    header["format_version"] = 99
    np.savez(tmp_path / "future.npz", header=np.array(json.dumps(header)), **arrays)
    with pytest.raises(VersionMismatchError, match="99"):
        ColorHistograms.load(tmp_path / "future.npz")
    with pytest.raises(NotFittedError):
        MotionHistograms().save(tmp_path / "unfitted")


# --------------------------------------------------------------------------- MultimodalNMF


def _modalities(seed: int = 0, n: int = 40):
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 3, n)
    out = {}
    for name, d, s in (("sound", 9, 1.0), ("motion", 7, 20.0)):
        P = rng.random((3, d)) ** 3
        out[name] = s * (P[y] + 0.05 * rng.random((n, d)))
    return out


def test_multimodal_nmf_is_a_scikit_learn_estimator():
    """check_estimator cannot run on it (X is a mapping of modalities); its contract is tested here."""
    from sklearn.base import TransformerMixin
    from sklearn.utils import get_tags

    model = MultimodalNMF(3, max_iter=20, random_state=0)
    assert isinstance(model, BaseEstimator) and isinstance(model, TransformerMixin)
    assert not get_tags(model).input_tags.two_d_array and get_tags(model).input_tags.dict
    twin = clone(model)
    assert twin is not model and twin.get_params() == model.get_params()
    assert model.get_params(deep=True) == model.get_params(deep=False) == dict(
        n_components=3, beta_loss="kullback-leibler", max_iter=20, transform_max_iter=None, tol=0.0,
        normalize="l1", init="random", random_state=0, forget_factor=1.0, partial_max_iter=None, forget="deprecated",
        modalities=None)
    X = _modalities()
    fitted = clone(model).set_params(n_components=4).fit(X)  # set_params reaches fit
    assert fitted.components_.shape == (4, 16) and fitted.nmf_.n_components == 4
    assert fitted.nmf_.n_iter_ == 20
    assert fitted.components_ is fitted.nmf_.components_  # one dictionary, not a placeholder copy
    assert clone(fitted).__dict__.keys() == model.__dict__.keys()  # a clone of a fitted model is unfitted
    np.testing.assert_array_equal(clone(fitted).fit_transform(X), fitted.fit_transform(X))  # seeded


#: The parameters MultimodalNMF shares with NMF, under NMF's names.
MULTIMODAL_SHARED = {"n_components", "beta_loss", "max_iter", "transform_max_iter", "tol", "init", "random_state",
                     "forget_factor"}
#: A value of each shared parameter that is neither MultimodalNMF's nor NMF's default (all distinct).
_SHARED_VALUES = dict(n_components=3, beta_loss=1.5, max_iter=6, transform_max_iter=4, tol=1e-3, init="nndsvda",
                      random_state=5, forget_factor=0.6)


def test_multimodal_nmf_shares_nmfs_parameters_under_nmfs_names():
    """One spelling: these are the parameters in common with NMF; of the others, only the
    deprecated ``forget`` is an NMF parameter under another spelling (a prefix of forget_factor)."""
    ours, nmfs = set(MultimodalNMF().get_params()), set(NMF().get_params())
    assert ours & nmfs == MULTIMODAL_SHARED == set(_SHARED_VALUES)

    def key(name):
        return name.replace("_", "").lower()

    near = {a for a in ours - nmfs for b in nmfs if key(a) == key(b) or b.startswith(a) or a.startswith(b)}
    assert near == {"forget"}


def test_multimodal_nmf_takes_the_shared_constraints_from_nmfs_table():
    """The same constraint objects as NMF's, except three narrower ones, each refusing a value NMF takes."""
    from mmconcepts._validation import validate_params

    own = {name for name in MULTIMODAL_SHARED
           if MultimodalNMF._parameter_constraints[name] is not NMF._parameter_constraints[name]}
    assert own == {"n_components", "init", "forget_factor"}
    for name, value in (("n_components", None), ("init", "custom"), ("forget_factor", 0.0)):
        validate_params(NMF().set_params(**{name: value}), NMF._parameter_constraints)
        with pytest.raises(ParameterError, match=rf"^MultimodalNMF: {name} must be "):
            validate_params(MultimodalNMF().set_params(**{name: value}), MultimodalNMF._parameter_constraints)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_every_shared_parameter_of_multimodal_nmf_reaches_its_nmf():
    """fit: each shared parameter, at a value that is neither default, is nmf_'s, and NMF's
    other parameters keep NMF's defaults; the deprecated forget arrives as forget_factor."""
    assert all(v != MultimodalNMF().get_params()[k] and v != NMF().get_params()[k] for k, v in _SHARED_VALUES.items())
    X = _modalities()
    model = MultimodalNMF(**_SHARED_VALUES).fit(X)
    assert model.nmf_.get_params() == {**NMF().get_params(), **_SHARED_VALUES}
    old = {**_SHARED_VALUES, "forget_factor": 1.0, "forget": 0.6}
    with pytest.warns(FutureWarning, match="forget_factor"):
        assert MultimodalNMF(**old).fit(X).nmf_.get_params() == model.nmf_.get_params()


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_each_partial_fit_gives_the_nmf_the_learners_current_parameters():
    """partial_fit runs the inner NMF with the learner's parameters at the time of the call
    (max_iter: partial_max_iter after the first call, given back afterwards)."""
    X = _modalities(n=40)
    first, second = ({k: v[rows] for k, v in X.items()} for rows in (slice(0, 20), slice(20, 40)))
    model = MultimodalNMF(**_SHARED_VALUES, partial_max_iter=2).partial_fit(first)
    assert model.nmf_.get_params() == {**NMF().get_params(), **_SHARED_VALUES}
    assert model.nmf_.n_iter_ == 6
    changed = dict(transform_max_iter=3, tol=2e-3, init="nndsvd", random_state=8, forget_factor=0.9)
    model.set_params(**changed, partial_max_iter=5).partial_fit(second)
    assert model.nmf_.n_iter_ == 5
    assert model.nmf_.get_params() == {**NMF().get_params(), **_SHARED_VALUES, **changed}


def test_multimodal_nmf_not_fitted_and_failed_fits_leave_no_state():
    X = _modalities()
    model = MultimodalNMF(3)
    for call in (lambda: model.transform(X), lambda: model.reconstruct(np.ones((1, 3)), "sound"),
                 lambda: model.component_slice("sound"), lambda: model.save("never")):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()
    # a fit that fails inside the factorization (zeros with the Itakura-Saito divergence) leaves
    # the learner unfitted, not half-fitted with a layout and no dictionary
    with pytest.raises(DataError):
        model.set_params(beta_loss="itakura-saito").fit({"sound": np.eye(4), "motion": np.ones((4, 2))})
    assert [k for k in vars(model) if k.endswith("_")] == []
    with pytest.raises(NotFittedError):
        model.transform({"sound": np.eye(4)})


def test_multimodal_nmf_save_load_version_2(tmp_path):
    X = _modalities()
    model = MultimodalNMF(3, max_iter=30, random_state=np.random.default_rng(4)).fit(X)
    path = model.save(tmp_path / "learner")
    with np.load(path, allow_pickle=False) as z:
        header = json.loads(str(z["header"]))
        # the dictionary is saved once, inside the nested NMF
        assert sum(np.array_equal(z[k], model.components_) for k in z.files if k != "header") == 1
    assert header["format_version"] == FORMAT_VERSION == 2
    assert header["state"]["nmf_"]["class"].endswith(".NMF") and "components_" not in header["state"]
    loaded = MultimodalNMF.load(path)
    assert loaded.get_params() == {**model.get_params(), "random_state": None}  # a Generator is saved as None
    assert loaded.modalities_ == model.modalities_ and loaded.n_features_ == model.n_features_
    assert loaded.scales_ == model.scales_
    assert loaded.components_ is loaded.nmf_.components_
    for obs in ({"sound": X["sound"]}, {"motion": X["motion"]}, X):
        np.testing.assert_array_equal(loaded.transform(obs), model.transform(obs))
    W = model.transform(X)
    np.testing.assert_array_equal(loaded.reconstruct(W, ["motion", "sound"]), model.reconstruct(W, ["motion", "sound"]))
    assert loaded.component_slice("motion") == model.component_slice("motion") == slice(9, 16)


def _write_v1(path, model: MultimodalNMF) -> None:
    """A file in the layout mmconcepts wrote before format version 2 (MultimodalNMF.save of 0.1.0)."""
    header = {
        "format": "mmconcepts.MultimodalNMF", "format_version": 1, "mmconcepts_version": "0.1.0",
        "params": model.get_params(), "modalities": model.modalities_, "n_features": model.n_features_,
        "scales": model.scales_,
    }
    np.savez(path, components=model.components_, header=np.array(json.dumps(header)))


def test_multimodal_nmf_loads_version_1_files(tmp_path):
    X = _modalities(1)
    model = MultimodalNMF(3, max_iter=25, transform_max_iter=40, random_state=2).fit(X)
    _write_v1(tmp_path / "v1.npz", model)
    loaded = MultimodalNMF.load(tmp_path / "v1.npz")
    assert loaded.get_params() == model.get_params()
    assert loaded.modalities_ == ["sound", "motion"] and loaded.scales_ == model.scales_
    for obs in ({"sound": X["sound"]}, {"motion": X["motion"]}, X):
        np.testing.assert_array_equal(loaded.transform(obs), model.transform(obs))
    W = model.transform(X)
    np.testing.assert_array_equal(loaded.reconstruct(W, "motion"), model.reconstruct(W, "motion"))
    # and it saves again in the current format
    again = MultimodalNMF.load(loaded.save(tmp_path / "v2"))
    np.testing.assert_array_equal(again.transform(X), model.transform(X))


def test_multimodal_nmf_refuses_corrupt_wrong_and_newer_files(tmp_path):
    X = _modalities(1)
    model = MultimodalNMF(3, max_iter=5, random_state=2).fit(X)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(DataFormatError, match="bad.npz"):
        MultimodalNMF.load(bad)
    _write_v1(tmp_path / "v1.npz", model)
    with np.load(tmp_path / "v1.npz", allow_pickle=False) as z:
        header = str(z["header"])
    np.savez(tmp_path / "short.npz", components=np.ones((3, 5)), header=np.array(header))
    with pytest.raises(DataFormatError, match="does not match its header"):
        MultimodalNMF.load(tmp_path / "short.npz")
    np.savez(tmp_path / "nocomp.npz", header=np.array(header))
    with pytest.raises(DataFormatError, match="corrupt"):
        MultimodalNMF.load(tmp_path / "nocomp.npz")
    h = json.loads(header)
    h["format_version"] = 3
    np.savez(tmp_path / "future.npz", components=model.components_, header=np.array(json.dumps(h)))
    with pytest.raises(VersionMismatchError, match="format version 3"):
        MultimodalNMF.load(tmp_path / "future.npz")
    other = MotionHistograms().fit(_recordings()).save(tmp_path / "hist")
    with pytest.raises(DataFormatError, match="MotionHistograms"):
        MultimodalNMF.load(other)


# --------------------------------------------------------------------------- public functions


def test_public_functions_check_their_parameters():
    from mmconcepts.multimodal import crossmodal_distances, matching_success_rate, pairwise_divergence
    from mmconcepts.vision import dense_sift, n_tuple_columns, neighbour_tuples, stack_descriptors, superpixel_colors

    A = np.ones((2, 3))
    image = np.random.default_rng(0).random((32, 32, 3))
    cases = [
        (lambda: pairwise_divergence(A, A, "manhattan"), "pairwise_divergence: metric must be one of 'idiv'"),
        (lambda: crossmodal_distances(None, {}, {}, space="joint"), "crossmodal_distances: space must be one of"),
        (lambda: crossmodal_distances(None, {}, {}, metric="l1"), "crossmodal_distances: metric must be one of"),
        (lambda: matching_success_rate(np.zeros((1, 1)), [0], [0], n_draws=0),
         "matching_success_rate: n_draws must be an int >= 1; got 0"),  # was a ZeroDivisionError
        (lambda: matching_success_rate(np.zeros((1, 1)), [0], [0], random_state=-2), "random_state must be"),
        (lambda: dense_sift(image, patch_size=10), "dense_sift: patch_size must be an int >= 4 and a multiple of 4"),
        (lambda: dense_sift(image, step=0), "dense_sift: step must be an int >= 1"),
        (lambda: dense_sift(image, contrast_threshold=-1), "contrast_threshold must be a real number >= 0"),
        (lambda: dense_sift(image, rotation_invariant="yes"), "rotation_invariant must be a bool"),
        (lambda: superpixel_colors(image, n_segments=0), "superpixel_colors: n_segments must be an int >= 1"),
        (lambda: superpixel_colors(image, compactness=0), "compactness must be a real number >= 1e-06"),
        (lambda: neighbour_tuples(np.zeros((3, 2)), order=4), "neighbour_tuples: order must be one of 2, 3"),
        (lambda: neighbour_tuples(np.zeros((3, 2)), n_neighbors=0), "n_neighbors must be an int >= 1"),
        (lambda: n_tuple_columns(4, 0), "n_tuple_columns: order must be an int >= 1"),
        (lambda: stack_descriptors({"a": A}, weights=[1.0]), "stack_descriptors: weights must be"),
    ]
    for call, message in cases:
        with pytest.raises(ParameterError, match=message.replace("(", r"\(")):
            call()
    assert matching_success_rate(np.array([[0.0, 1.0]]), [0], [0, 1], n_draws=1) == 1.0
    assert n_tuple_columns(0, 2) == 0
