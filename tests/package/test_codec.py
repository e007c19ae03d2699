"""The package's one no-pickle codec (mmconcepts._codec), shared by saved models and cache entries.

What is pinned: models saved in the file format of ``format_version`` 1 (the files in
``tests/data/saved_models``, written with mmconcepts 0.2.0.dev0, with the answers the models gave
then) load and answer the same; a saved model and a cache entry are the same kind of archive; a
value comes back with its types (numpy scalars stay numpy scalars, tuples stay tuples); a file
that names a class outside the package, or holds a pickle, builds nothing and runs nothing.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from _planted import Plant, planted_pickle

from mmconcepts._codec import HEADER, MARK, CorruptFile, decode, encode, read_npz, write_npz
from mmconcepts._store import read_entry, write_entry
from mmconcepts.errors import DataFormatError, ParameterError
from mmconcepts.multimodal import MultimodalNMF
from mmconcepts.nmf import NMF, LabelNMF
from mmconcepts.sound import HAC, ClusterTree

SAVED = Path(__file__).resolve().parents[1] / "data" / "saved_models"


@pytest.fixture(scope="module")
def answers():
    with np.load(SAVED / "answers.npz", allow_pickle=False) as z:
        return dict(z)


def test_models_saved_in_the_previous_files_load_and_answer_the_same(answers):
    X = answers["probe_X"]
    seqs = [answers[f"seq{i}"] for i in range(6)]
    nmf = NMF.load(SAVED / "nmf.npz")
    assert type(nmf.n_components_) is int and nmf.random_state == 0
    np.testing.assert_array_equal(nmf.components_, answers["nmf"])
    label = LabelNMF.load(SAVED / "label_nmf.npz")
    assert isinstance(label.nmf_, NMF) and type(label.threshold_) is float
    np.testing.assert_array_equal(label.nmf_.components_, answers["label_nmf"])
    assert label.threshold_ == answers["label_nmf_threshold"]
    multi = MultimodalNMF.load(SAVED / "multimodal_nmf.npz")
    assert multi.modalities_ == ["A", "B"] and multi.components_ is multi.nmf_.components_
    np.testing.assert_array_equal(multi.components_, answers["multimodal_nmf"])
    np.testing.assert_array_equal(HAC.load(SAVED / "hac.npz").transform(seqs).toarray(), answers["hac"])
    np.testing.assert_array_equal(ClusterTree.load(SAVED / "cluster_tree.npz").predict(X), answers["cluster_tree"])


def test_a_model_saved_now_is_an_archive_of_the_codec_and_loads_back(tmp_path, answers):
    X = answers["probe_X"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a short fit does not converge
        model = NMF(3, max_iter=20, random_state=0).fit(X)
    model.tol_seen_ = np.float32(0.25)  # a numpy scalar comes back as one
    path = model.save(tmp_path / "m")
    header, npz = read_npz(path)
    with npz:
        assert header["format"] == "mmconcepts.NMF" and header["format_version"] == 1
        assert decode(header["state"], npz)["components_"].tobytes() == model.components_.tobytes()
    back = NMF.load(path)
    assert type(back.tol_seen_) is np.float32 and back.tol_seen_ == np.float32(0.25)
    np.testing.assert_array_equal(back.components_, model.components_)
    # a fitted estimator is a value the caches keep too
    write_entry(tmp_path / "e.npz", {"model": model}, "k")
    again = read_entry(tmp_path / "e.npz", "k")["model"]
    assert type(again) is NMF and again.get_params() == model.get_params()
    np.testing.assert_array_equal(again.components_, model.components_)


def test_values_come_back_with_their_types():
    value = {"f32": np.float32(1.5), "i": np.int64(3), "b": np.bool_(True), "t": (1, [2, (3,)]), "nan": float("-nan"),
             "inf": float("-inf"), 7: "int key", (1, "a"): None, MARK: 1, "s": np.array([["a"], ["b\0"]], dtype=object)}
    arrays: dict = {}
    structure = json.loads(json.dumps(encode(value, arrays), allow_nan=False))  # strict JSON
    back = decode(structure, arrays)
    assert list(back) == list(value)
    for k in ("f32", "i", "b"):
        assert type(back[k]) is type(value[k]) and back[k] == value[k]
    assert back["t"] == (1, [2, (3,)]) and type(back["t"][1][1]) is tuple
    assert np.float64(back["nan"]).tobytes() == np.float64(value["nan"]).tobytes()  # the sign of the NaN kept
    assert back["inf"] == float("-inf") and back[7] == "int key" and back[(1, "a")] is None and back[MARK] == 1
    assert back["s"].shape == (2, 1) and back["s"].ravel().tolist() == ["a", "b\0"]


@pytest.mark.parametrize("node, match", [
    ({MARK: "estimator", "class": "pathlib.Path", "params": {}, "state": {}}, "not one of the package's"),
    ({MARK: "estimator", "class": "mmconcepts.errors.DataError", "params": {}, "state": {}}, "not a model"),
    ({MARK: "namedtuple", "class": "os:stat_result", "fields": [], "items": []}, "not one of the package's"),
    ({MARK: "array", "entry": HEADER}, "no array"),
    ({MARK: "float", "value": "1e308"}, "a bad float"),
    ({MARK: "pickle", "entry": "a0"}, "unknown node kind"),
    ({MARK: "dict", "items": [[[1], 2]]}, "no key"),
])
def test_a_structure_the_codec_does_not_write_builds_nothing(node, match):
    with pytest.raises(CorruptFile, match=match):
        decode(node, {})


def test_a_planted_model_file_runs_nothing(tmp_path):
    marker = tmp_path / "marker"
    (tmp_path / "pickled.npz").write_bytes(planted_pickle(marker))
    header = {"format": "mmconcepts.NMF", "format_version": 1, "mmconcepts_version": "0",
              "params": {}, "state": {"components_": {MARK: "array", "entry": "a0"}}}
    with open(tmp_path / "object.npz", "wb") as fh:
        np.savez(fh, header=np.array(json.dumps(header)), a0=np.array([Plant(marker)], dtype=object))
    for name in ("pickled.npz", "object.npz"):
        with pytest.raises(DataFormatError, match="NMF"):
            NMF.load(tmp_path / name)
    assert not marker.exists()
    with pytest.raises(ParameterError, match="cannot be named"):
        write_npz(tmp_path / "x.npz", {}, {HEADER: np.zeros(1)})
