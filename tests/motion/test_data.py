"""Choreo1 / Choreo2 / MSR Action3D loaders: round trips, name matching, corrupt files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import real_data_path

from mmconcepts.errors import DataError, DataFormatError, ParameterError
from mmconcepts.motion import (
    CHOREO1_MARKERS,
    MotionRecording,
    load_choreo1,
    load_choreo1_text,
    load_choreo2,
    load_msr_action3d,
    normalize_marker_name,
    save_choreo1,
    save_choreo1_text,
    save_choreo2,
)


def _recs(rng, n=3, markers=CHOREO1_MARKERS, orient=False):
    out = []
    for i in range(n):
        T = 5 + i
        q = None
        if orient:
            q = rng.normal(size=(T, len(markers), 4))
            q /= np.linalg.norm(q, axis=2, keepdims=True)
        out.append(MotionRecording(rng.normal(size=(T, len(markers), 3)), markers, (i + 1, 23), orientations=q))
    return out


def test_choreo1_round_trip(tmp_path, rng):
    recs = _recs(rng)
    path = save_choreo1(recs, tmp_path, "mixed_full")
    meta = json.loads(path.read_text())
    assert set(meta) == {"marker-names", "data-file", "records"}
    assert meta["records"][0] == {"data-id": 0, "labels": [1, 23]}
    ds = load_choreo1(path)
    assert len(ds) == 3 and ds.skipped == []
    for a, b in zip(recs, ds):
        np.testing.assert_array_equal(a.positions, b.positions)
        assert b.labels == a.labels
    Y = ds.label_matrix([1, 2, 3, 23])
    np.testing.assert_array_equal(Y, [[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1]])


def test_choreo2_round_trip(tmp_path, rng):
    names = ("head", "neck", "torso")
    recs = _recs(rng, 2, names, orient=True)
    path = save_choreo2(recs, tmp_path)
    assert set(json.loads(path.read_text())) >= {"marker_names", "data_file", "records", "label_descriptions"}
    ds = load_choreo2(tmp_path)
    np.testing.assert_array_equal(ds[1].orientations, recs[1].orientations)
    np.testing.assert_array_equal(ds[1].positions, recs[1].positions)
    assert ds.label_names[0].startswith("both legs")


def test_text_layout_round_trip(tmp_path, rng):
    rec = _recs(rng, 1)[0]
    save_choreo1_text(rec, tmp_path / "r.txt")
    line = (tmp_path / "r.txt").read_text().splitlines()[0].split()
    assert len(line) == 72 and "e" in line[0]
    back = load_choreo1_text(tmp_path / "r.txt")
    np.testing.assert_allclose(back.positions, rec.positions, rtol=0, atol=1e-15)
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(DataFormatError, match=r"bad\.txt, line 1: 3 values, expected 72"):
        load_choreo1_text(tmp_path / "bad.txt")


def test_marker_names_matched_loosely(rng):
    rec = MotionRecording(rng.normal(size=(4, 2, 3)), ("Left Shoulder", "right-hand"), source="f.npz", record_id="7")
    assert normalize_marker_name("Left__Shoulder") == "left_shoulder"
    np.testing.assert_array_equal(rec.marker("left_shoulder"), rec.positions[:, 0])
    np.testing.assert_array_equal(rec.marker("RIGHT HAND"), rec.positions[:, 1])
    with pytest.raises(DataError, match=r"'left_knee'.*file f\.npz, record 7"):
        rec.marker("left_knee")


def _corrupt_choreo1(tmp_path, rng):
    recs = _recs(rng, 3)
    path = save_choreo1(recs, tmp_path, "primitive")
    # record 1 gets the wrong shape
    with np.load(tmp_path / "primitive.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["1"] = arrays["1"][:, :5]
    np.savez(tmp_path / "primitive.npz", **arrays)
    return path


def test_corrupt_record_raises_naming_file_and_record(tmp_path, rng):
    path = _corrupt_choreo1(tmp_path, rng)
    with pytest.raises(DataFormatError, match=r"primitive\.npz: record 1 has shape"):
        load_choreo1(path)


def test_corrupt_record_skipped_and_reported(tmp_path, rng):
    path = _corrupt_choreo1(tmp_path, rng)
    with pytest.warns(RuntimeWarning, match="1 record"):
        ds = load_choreo1(path, on_error="skip")
    assert [r.record_id for r in ds] == ["0", "2"]
    assert len(ds.skipped) == 1 and ds.skipped[0].record_id == "1" and "shape" in ds.skipped[0].reason


def test_garbage_npz_and_json(tmp_path, rng):
    path = save_choreo1(_recs(rng, 2), tmp_path, "primitive")
    (tmp_path / "primitive.npz").write_bytes(b"this is not a zip archive")
    with pytest.raises(DataFormatError, match=r"primitive\.npz: not a valid NPZ"):
        load_choreo1(path)
    path.write_text("{not json")
    with pytest.raises(DataFormatError, match=r"primitive\.json: not valid JSON"):
        load_choreo1(path)


def test_wrong_format_keys_explained(tmp_path, rng):
    save_choreo2(_recs(rng, 1, ("head",), orient=True), tmp_path)
    with pytest.raises(DataFormatError, match="other Choreo format"):
        load_choreo1(tmp_path / "choreo2.json")
    with pytest.raises(ParameterError):
        load_choreo1(tmp_path / "choreo2.json", on_error="ignore")


@pytest.mark.parametrize(("load", "save", "sep"), [(load_choreo1, lambda r, d: save_choreo1(r, d, "primitive"), "-"),
                                                    (load_choreo2, save_choreo2, "_")])
def test_both_formats_check_their_own_key_spelling(tmp_path, rng, load, save, sep):
    """load_choreo1 and load_choreo2 share their code; each still names its own keys."""
    path = save(_recs(rng, 2, ("head", "neck"), orient=True), tmp_path)
    meta = json.loads(path.read_text())
    meta[f"marker{sep}names"] = [1, 2]
    path.write_text(json.dumps(meta))
    with pytest.raises(DataFormatError, match=f"'marker{sep}names' must be a list of strings"):
        load(path)
    meta[f"marker{sep}names"] = ["head", "neck"]
    meta["records"][1][f"data{sep}id"] = 7
    path.write_text(json.dumps(meta))
    with pytest.raises(DataFormatError, match=f"no array for record 7 .key '7'. listed in .*{path.name}"):
        load(path)
    with pytest.warns(RuntimeWarning, match="1 record") as caught:
        ds = load(path, on_error="skip", frame_rate=12.5)
    assert caught[0].filename == __file__  # the warning points at the caller
    assert [r.record_id for r in ds] == ["0"] and ds[0].frame_rate == 12.5
    assert (ds[0].orientations is None) == (sep == "-")


def test_choreo2_gesture_names(tmp_path, rng):
    from mmconcepts.motion import CHOREO2_GESTURES

    path = save_choreo2(_recs(rng, 1, ("head",), orient=True), tmp_path, name="mine", label_descriptions=("a", "b"))
    ds = load_choreo2(path)
    assert ds.name == "mine" and ds.label_names == {0: "a", 1: "b"}
    meta = json.loads(path.read_text())
    del meta["label_descriptions"], meta["name"]
    path.write_text(json.dumps(meta))
    ds = load_choreo2(path)
    assert ds.name == "choreo2" and ds.label_names == dict(enumerate(CHOREO2_GESTURES))
    meta["label_descriptions"] = "squat"
    path.write_text(json.dumps(meta))
    (tmp_path / "choreo2.npz").unlink()  # the index is checked before the data file is opened
    with pytest.raises(DataFormatError, match="'label_descriptions' must be a list of strings"):
        load_choreo2(path)

def test_msr_loader_bad_file(tmp_path):
    (tmp_path / "a01_s01_e01_skeleton3D.txt").write_text("1 2 3 1\n" * 19)
    good = "\n".join("0.1 0.2 2.0 1.0" for _ in range(20)) + "\n"
    (tmp_path / "a02_s01_e01_skeleton3D.txt").write_text(good * 2)
    with pytest.raises(DataFormatError, match="a01_s01_e01"):
        load_msr_action3d(tmp_path)
    with pytest.warns(RuntimeWarning):
        ds = load_msr_action3d(tmp_path, on_error="skip")
    assert len(ds) == 1 and ds[0].labels == (2,) and ds.skipped[0].record_id == "a01_s01_e01"


def test_msr_lost_frames_interpolated(tmp_path):
    frames = [np.full((20, 4), float(k)) for k in range(5)]
    frames[2][:, :3] = 0.0  # tracking lost in the middle frame
    frames[0][:, :3] = 0.0  # and at the start
    (tmp_path / "a03_s02_e01_skeleton3D.txt").write_text(
        "\n".join(" ".join(map(str, row)) for f in frames for row in f) + "\n")
    rec = load_msr_action3d(tmp_path)[0]
    assert rec.n_frames == 4  # leading lost frame dropped
    np.testing.assert_allclose(rec.positions[1], 2.0)  # interpolated between 1 and 3
    assert load_msr_action3d(tmp_path, lost_frames="drop")[0].n_frames == 3


def test_msr_real_data_all_zero_frames_handled():
    ds = load_msr_action3d(real_data_path("msr-action3d"), actions=[13, 20])
    assert len(ds) > 50
    for r in ds:
        assert not np.any(np.all(r.positions == 0, axis=(1, 2)))
    # a13_s09_e02 has no tracked frame at all: left out and reported
    assert [s.record_id for s in ds.skipped] == ["a13_s09_e02"]
    # a13_s02_e02 had 12 lost frames inside; interpolation keeps its length
    r = next(r for r in ds if r.record_id == "a13_s02_e02")
    assert r.n_frames == 30
    head = r.marker("head")[:, 1]
    feet = r.marker("left_foot")[:, 1]
    assert np.all(head > feet)  # joint order: head above feet
