"""Fuzz tests of mmconcepts.multimodal: a typed error or a correct result.

Modalities come mismatched (rows, columns, names), empty, negative, NaN, infinite, sparse
or all zeros; saved models come truncated, empty, with bytes flipped, with an edited JSON
header, or with a pickle inside. Loading must give a DataFormatError naming the file and
never unpickle; a model that loads must work (its transform is called in the same call, so
a model that loads and fails later counts as an untyped error).
"""

from __future__ import annotations

import functools
import io
import json
import zipfile

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from _fuzz import PickleBomb, assert_typed_or_good, fuzz_settings
from mmconcepts.errors import DataFormatError
from mmconcepts.multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate, pairwise_divergence

SETTINGS = dict(suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])
pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore::mmconcepts.errors.ConvergenceWarning",
                                        "ignore::sklearn.exceptions.ConvergenceWarning")]

VALUES = st.one_of(st.floats(0, 10), st.sampled_from([0.0, 1e-300, 1e300, -1.0, np.nan, np.inf]))


@st.composite
def modality(draw, n, d, *, valid):
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    X = rng.random((n, d)) * draw(st.sampled_from([1.0, 1e-8, 1e8]))
    if not valid:
        kind = draw(st.sampled_from(["nan", "inf", "negative", "zeros", "empty_rows", "empty_cols", "1d", "object",
                                     "wrong_rows"]))
        if kind == "nan":
            X[0, 0] = np.nan
        elif kind == "inf":
            X[0, 0] = np.inf
        elif kind == "negative":
            X[0, 0] = -1.0
        elif kind == "zeros":
            X[:] = 0.0
        elif kind == "empty_rows":
            X = X[:0]
        elif kind == "empty_cols":
            X = X[:, :0]
        elif kind == "1d":
            X = X[:, 0]
        elif kind == "object":
            X = X.astype(object)
            X[0, 0] = "a"
        elif kind == "wrong_rows":
            X = X[:-1]
    if draw(st.booleans()) and getattr(X, "ndim", 0) == 2 and X.dtype != object:
        X = sp.csr_matrix(X)
    return X


@st.composite
def modality_sets(draw, n=None, *, names=("sound", "motion", "image"), valid=None):
    n = draw(st.integers(2, 8)) if n is None else n
    m = draw(st.integers(1, len(names)))
    ok = draw(st.integers(0, 3)) > 0 if valid is None else valid
    bad = draw(st.integers(0, m - 1)) if not ok else -1
    return {name: draw(modality(n, draw(st.integers(1, 6)), valid=i != bad)) for i, name in enumerate(names[:m])}


@functools.lru_cache(maxsize=None)
def _fitted_once(n_components=2, seed=0, n=6):
    rng = np.random.default_rng(seed)
    X = {"sound": rng.random((n, 5)), "motion": rng.random((n, 4))}
    return MultimodalNMF(n_components, max_iter=20, random_state=0).fit(X), X


def _fitted():
    """One fitted learner (fit once per session: the examples only read it) and its training data."""
    est, X = _fitted_once()
    return est, {k: v.copy() for k, v in X.items()}


@fuzz_settings(100, **SETTINGS)
@given(X=modality_sets(), k=st.sampled_from([0, 1, 2, 2, 2, 3, 10**9]),
       normalize=st.sampled_from(["l1", "l1", None, "l2"]), max_iter=st.sampled_from([0, 1, 10, 10, 10]))
def test_fuzz_multimodal_fit_transform(X, k, normalize, max_iter):
    """W (n, k) nonnegative; transform from all the modalities works; reconstructions are nonnegative of the right widths."""

    def call():
        est = MultimodalNMF(k, normalize=normalize, max_iter=max_iter, random_state=0)
        W = est.fit_transform(X)
        return est, W, est.transform(X), est.reconstruct(W, list(X))

    def check(res):
        est, W, W2, R = res
        n = next(iter(X.values())).shape[0]
        return (W.shape == (n, k) and (W >= 0).all() and W2.shape == (n, k) and (W2 >= 0).all()
                and R.shape == (n, sum(x.shape[1] for x in X.values())) and (R >= 0).all())

    assert_typed_or_good("mmconcepts.multimodal.MultimodalNMF.fit_transform", call, check=check)


@fuzz_settings(100, **SETTINGS)
@given(data=st.data(), subset=st.sampled_from([("sound",), ("motion",), ("sound", "motion"), ("image",), (),
                                               ("sound", "image")]),
       width=st.sampled_from(["same", "same", "same", "wider", "narrower"]))
def test_fuzz_multimodal_transform(data, subset, width):
    """Representations from any subset of known modalities; unknown names, other widths or bad values are typed errors."""
    est, Xtrain = _fitted()
    n = data.draw(st.integers(0, 5))
    valid = data.draw(st.integers(0, 3)) > 0
    X = {}
    for name in subset:
        d = Xtrain.get(name, np.zeros((1, 3))).shape[1] + {"same": 0, "wider": 1, "narrower": -1}[width]
        X[name] = data.draw(modality(max(n, 1), max(d, 0), valid=valid))

    def check(W):
        rows = {np.shape(x)[0] for x in X.values()}  # one modality cut short is a valid smaller input
        return len(rows) == 1 and W.shape == (rows.pop(), 2) and (W >= 0).all()

    assert_typed_or_good("mmconcepts.multimodal.MultimodalNMF.transform", lambda: est.transform(X), check=check)


@fuzz_settings(100, **SETTINGS)
@given(W=st.sampled_from([(3, 2), (3, 3), (0, 2), (2,), (1, 2)]).flatmap(lambda s: arrays(float, s, elements=VALUES)),
       modality=st.sampled_from(["sound", "motion", ["sound", "motion"], [], "image", 3]))
def test_fuzz_multimodal_reconstruct(W, modality):
    est, X = _fitted()

    def check(R):
        names = [modality] if isinstance(modality, str) else modality
        return R.shape == (len(W), sum(X[m].shape[1] for m in names)) and (R >= -1e-12).all()

    assert_typed_or_good("mmconcepts.multimodal.MultimodalNMF.reconstruct", lambda: est.reconstruct(W, modality),
                         check=check)


@fuzz_settings(300, **SETTINGS)
@given(shapes=st.sampled_from([((3, 4), (2, 4)), ((1, 1), (1, 1)), ((0, 3), (2, 3)), ((3, 4), (2, 5)), ((3,), (3,)),
                               ((2, 3), (2, 3))]),
       data=st.data(), metric=st.sampled_from(["kl", "kl_reversed", "kl_symmetric", "idiv", "euclidean", "cosine",
                                               "l1"]))
def test_fuzz_pairwise_divergence(shapes, data, metric):
    """Shape (n_a, n_b), nonnegative (up to round-off) and zero between a row and itself."""
    A = data.draw(arrays(float, shapes[0], elements=VALUES))
    B = data.draw(arrays(float, shapes[1], elements=VALUES))

    def call():
        return pairwise_divergence(A, B, metric), (pairwise_divergence(A, A, metric) if A.ndim == 2 else None)

    def check(res):
        D, DAA = res
        scale = 1e-6 * (1 + min(np.abs(A).max(), 1e150) ** 2 if A.size else 1)
        return (D.shape == (len(A), len(B)) and (D >= -scale).all()
                and (metric in ("idiv", "cosine") or np.allclose(np.diag(DAA), 0.0, atol=scale)))

    assert_typed_or_good("mmconcepts.multimodal.pairwise_divergence", call, check=check)


@fuzz_settings(60, **SETTINGS)
@given(data=st.data(), space=st.sampled_from(["internal", "test", "reference", "other"]),
       metric=st.sampled_from(["kl", "euclidean", "cosine", "idiv"]),
       test_mods=st.sampled_from([("sound",), ("motion",), ("sound", "motion"), ()]),
       ref_mods=st.sampled_from([("motion",), ("sound",), ("image",)]))
def test_fuzz_crossmodal_distances(data, space, metric, test_mods, ref_mods):
    est, Xtrain = _fitted()
    valid = data.draw(st.integers(0, 3)) > 0
    X_test = {m: data.draw(modality(3, Xtrain[m].shape[1], valid=valid)) for m in test_mods}
    X_ref = {m: data.draw(modality(4, Xtrain.get(m, np.zeros((1, 2))).shape[1], valid=True)) for m in ref_mods}

    def check(D):
        n_test = {np.shape(x)[0] for x in X_test.values()}  # a modality cut short is a valid smaller input
        return len(n_test) == 1 and D.shape == (n_test.pop(), 4) and (D >= -1e-9).all()

    assert_typed_or_good("mmconcepts.multimodal.crossmodal_distances",
                         lambda: crossmodal_distances(est, X_test, X_ref, space=space, metric=metric), check=check)


@fuzz_settings(300, **SETTINGS)
@given(n_test=st.integers(0, 5), n_ref=st.integers(0, 6), n_classes=st.integers(1, 3),
       kind=st.sampled_from(["perfect", "perfect", "random", "nan", "inf", "shape", "missing_class"]),
       n_draws=st.sampled_from([0, 1, 3, 3]))
def test_fuzz_matching_success_rate(n_test, n_ref, n_classes, kind, n_draws):
    """A rate in [0, 1]; 1 when every test example is closest to the references of its class."""
    y_test = np.arange(n_test) % n_classes
    y_ref = np.arange(n_ref) % n_classes
    if kind == "missing_class":
        y_test = y_test + n_classes
    D = (y_test[:, None] != y_ref[None, :]).astype(float)
    if kind == "random":
        D = np.random.default_rng(0).random(D.shape)
    elif kind == "nan" and D.size:
        D[0, 0] = np.nan
    elif kind == "inf" and D.size:
        D[0, 0] = np.inf
    elif kind == "shape":
        D = D.T

    def check(rate):
        return 0.0 <= rate <= 1.0 and (kind != "perfect" or rate == 1.0)

    assert_typed_or_good("mmconcepts.multimodal.matching_success_rate",
                         lambda: matching_success_rate(D, y_test, y_ref, n_draws=n_draws, random_state=0), check=check)


# ----------------------------------------------------------------------------- save / load of damaged files


def _npz_with(entries: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, arr in entries.items():
            with zf.open(name + ".npy", "w") as fh:
                np.lib.format.write_array(fh, arr, allow_pickle=True)
    return buf.getvalue()




_HEADER_EDITS = [
    ("state.modalities_", ["sound"]), ("state.modalities_", ["sound", "motion", "image"]),
    ("state.modalities_", 3), ("state.n_features_.sound", 99), ("state.n_features_.sound", -1),
    ("state.n_features_", {}), ("state.scales_.sound", -1.0), ("state.scales_.sound", 0.0),
    ("state.scales_.sound", {"__mmconcepts__": "float", "value": "nan"}), ("state.scales_", None),
    ("state.nmf_", None), ("state.nmf_.class", "os.system"), ("state.nmf_.class", "mmconcepts.nmf.Nope"),
    ("state.nmf_.params.n_components", 7), ("state.nmf_.state.components_.entry", "nope"),
    ("params.n_components", 5), ("params.n_components", -1), ("params.bogus", 1), ("params", []),
    ("format_version", 1), ("format_version", 99), ("format", "mmconcepts.NMF"), ("state", []),
    ("state.nmf_.state.components_", {"__mmconcepts__": "pickle"}),
]


def _edit(header, dotted, value):
    parts = dotted.split(".")
    node = header
    for p in parts[:-1]:
        if not isinstance(node, dict) or p not in node:
            return header
        node = node[p]
    if isinstance(node, dict):
        node[parts[-1]] = value
    return header


@fuzz_settings(150, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(["intact", "truncate", "empty", "flip", "edit_header", "pickle_header",
                                             "pickle_array", "bad_array", "text", "header_not_json",
                                             "header_not_object", "nan_components"]))
def test_fuzz_multimodal_load(tmp_path_factory, data, kind):
    """Loading a damaged file: DataFormatError (or VersionMismatchError) naming the file, never unpickling;
    a model that loads transforms as the saved one did (intact file) or at least works."""
    tmp = tmp_path_factory.mktemp("mm")
    est, X = _fitted()
    path = est.save(tmp / "model.npz")
    raw = path.read_bytes()
    with np.load(path, allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    header = json.loads(str(entries["header"]))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif kind == "empty":
        raw = b""
    elif kind == "flip":
        i = data.draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ data.draw(st.integers(1, 255))]) + raw[i + 1:]
    elif kind == "edit_header":
        dotted, value = data.draw(st.sampled_from(_HEADER_EDITS))
        entries["header"] = np.array(json.dumps(_edit(header, dotted, value)))
        raw = _npz_with(entries)
    elif kind == "pickle_header":
        entries["header"] = np.array([PickleBomb()], dtype=object)
        raw = _npz_with(entries)
    elif kind == "pickle_array":
        name = data.draw(st.sampled_from(sorted(k for k in entries if k != "header")))
        entries[name] = np.array([PickleBomb()], dtype=object)
        raw = _npz_with(entries)
    elif kind == "bad_array":
        name = data.draw(st.sampled_from(sorted(k for k in entries if k != "header")))
        entries[name] = data.draw(st.sampled_from([np.zeros((0,)), np.zeros((2, 2, 2)), np.array("x"),
                                                   np.array([1, 2], dtype=np.int8)]))
        raw = _npz_with(entries)
    elif kind == "nan_components":
        name = data.draw(st.sampled_from(sorted(k for k in entries if k != "header")))
        entries[name] = np.full_like(entries[name], np.nan) if entries[name].dtype.kind == "f" else entries[name]
        raw = _npz_with(entries)
    elif kind == "text":
        raw = b"this is not a model\n"
    elif kind == "header_not_json":
        entries["header"] = np.array("{not json")
        raw = _npz_with(entries)
    elif kind == "header_not_object":
        entries["header"] = np.array(json.dumps([1, 2]))
        raw = _npz_with(entries)
    bad = tmp / "damaged.npz"
    bad.write_bytes(raw)
    PickleBomb.ran = False
    expected = est.transform(X)

    def call():
        try:
            model = MultimodalNMF.load(bad)
        except DataFormatError as exc:
            assert str(bad) in str(exc), f"the error does not name the file: {exc}"
            raise
        return model, model.transform(X), model.reconstruct(expected, model.modalities_)

    def check(res):
        model, W, R = res
        if PickleBomb.ran:
            return False
        if kind == "intact":
            return np.allclose(W, expected)
        return W.shape == expected.shape and (W >= 0).all() and (R >= 0).all()

    assert_typed_or_good("mmconcepts.multimodal.MultimodalNMF.load", call, check=check)
    assert not PickleBomb.ran, "loading unpickled an object"
