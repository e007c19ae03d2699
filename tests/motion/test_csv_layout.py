"""The generic motion layout: per-recording CSV files + labels.csv.

A round trip of MSR-like skeletons through CSV gives the same arrays and the same motion
histograms as the skeletons themselves; bad files (missing joints, ragged rows, NaN, text,
a label for a file that does not exist) give a DataFormatError naming the file and the
line, or are skipped and listed with ``on_error="skip"``.
"""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts import datasets as ds
from mmconcepts.errors import DataFormatError, ParameterError
from mmconcepts.motion import MSR_JOINTS, MotionRecording, joint_angles
from mmconcepts.motion.data import MSR_ACTIONS, MotionDataset, load_motion_folder, load_msr_action3d, save_motion_folder
from mmconcepts.motion.histograms import MotionHistograms


def _skeleton(rng, n_frames=12):
    """A plausible MSR-like skeleton: a standing body plus small motion (20 joints, metres)."""
    base = rng.normal(scale=0.3, size=(20, 3)) + np.array([0.0, 0.0, 2.5])
    t = np.arange(n_frames)[:, None, None]
    return base[None] + 0.05 * np.sin(0.3 * t + rng.random((1, 20, 3)) * 6)


def _msr_files(folder, rng, n=4):
    """MSR Action3D text files (x y z confidence, 20 lines per frame), as the real set has them."""
    folder.mkdir()
    for i in range(n):
        P = _skeleton(rng)
        rows = np.concatenate([P.reshape(-1, 3), np.ones((P.shape[0] * 20, 1))], axis=1)
        np.savetxt(folder / f"a{(i % 2) + 1:02d}_s01_e{i + 1:02d}_skeleton3D.txt", rows, fmt="%.6f")
    return load_msr_action3d(folder)


def test_round_trip_of_msr_skeletons_gives_the_same_arrays_and_histograms(tmp_path):
    msr = _msr_files(tmp_path / "msr", np.random.default_rng(0))
    labels_csv = save_motion_folder(msr, tmp_path / "csv")
    assert labels_csv.read_text().splitlines()[0] == "file,labels"
    header = (tmp_path / "csv" / "a01_s01_e01.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["left_shoulder_x", "left_shoulder_y", "left_shoulder_z"] and len(header) == 60
    back = load_motion_folder(tmp_path / "csv", frame_rate=15.0)
    assert [r.record_id for r in back] == [r.record_id for r in msr]
    assert all(r.marker_names == MSR_JOINTS for r in back)
    for a, b in zip(msr, back):
        np.testing.assert_array_equal(a.positions, b.positions)  # 17 significant digits: the same floats
        assert b.frame_rate == 15.0
    # labels: the same names (ids are ranks of the names, since MSR's names are not integers)
    assert [[msr.label_names[l] for l in r.labels] for r in msr] == [[back.label_names[l] for l in r.labels]
                                                                     for r in back]
    # the same features: joint angles and the motion histograms fit on them
    A = [joint_angles(r) for r in msr]
    B = [joint_angles(r) for r in back]
    for a, b in zip(A, B):
        np.testing.assert_array_equal(a, b)
    ha = MotionHistograms(n_bins=5).fit_transform(A)
    hb = MotionHistograms(n_bins=5).fit_transform(B)
    np.testing.assert_array_equal(ha, hb)


def test_joints_in_another_column_order_and_a_joint_subset(tmp_path):
    rng = np.random.default_rng(1)
    P = _skeleton(rng, 5)
    rec = MotionRecording(P[:, ::-1], MSR_JOINTS[::-1], (3,))  # columns in reverse joint order
    save_motion_folder([rec], tmp_path, label_names={3: "wave"})
    back = load_motion_folder(tmp_path, joints=MSR_JOINTS)  # reordered to the order asked for
    np.testing.assert_array_equal(back[0].positions, P)
    assert back.label_names == {0: "wave"} and back[0].labels == (0,)
    sub = load_motion_folder(tmp_path, joints=["Left Shoulder", "neck"])  # names matched loosely
    np.testing.assert_array_equal(sub[0].positions, P[:, [0, 2]])
    with pytest.raises(DataFormatError, match=r"rec0\.csv|line 1.*joint\(s\) \['nose'\] missing"):
        load_motion_folder(tmp_path, joints=["nose"])
    with pytest.raises(ParameterError, match="joints"):
        load_motion_folder(tmp_path, joints=[])


def test_integer_labels_are_their_own_ids_and_label_sets_are_read(tmp_path):
    rng = np.random.default_rng(2)
    recs = [MotionRecording(_skeleton(rng, 3), MSR_JOINTS, labels, record_id=f"r{i}")
            for i, labels in enumerate([(4,), (4, 12), (7,)])]
    save_motion_folder(recs, tmp_path)
    back = load_motion_folder(tmp_path)
    assert [r.labels for r in back] == [(4,), (4, 12), (7,)]
    assert back.label_names == {4: "4", 7: "7", 12: "12"}
    assert back.label_matrix().tolist() == [[1, 0, 0], [1, 0, 1], [0, 1, 0]]


def _write(path, text):
    path.write_text(text, encoding="utf-8")
    return path


def _good_folder(tmp_path, n=3):
    rng = np.random.default_rng(3)
    recs = [MotionRecording(_skeleton(rng, 4), MSR_JOINTS, (i + 1,), record_id=f"r{i}") for i in range(n)]
    save_motion_folder(MotionDataset(recs, dict(MSR_ACTIONS)), tmp_path)
    return tmp_path


@pytest.mark.parametrize("damage, message", [
    (lambda t: t.replace("neck_z", "neck_w", 1), r"r1\.csv, line 1 \(header\): column 'neck_w' is not"),
    (lambda t: t.replace(",neck_z", "", 1), r"r1\.csv, line 1 \(header\): joint 'neck' lacks column\(s\) \['neck_z'\]"),
    (lambda t: "\n".join(l if i != 2 else l + ",1.0" for i, l in enumerate(t.splitlines())),
     r"r1\.csv, line 3: 61 values for 60 columns"),
    (lambda t: "\n".join(l if i != 3 else l.rsplit(",", 1)[0] for i, l in enumerate(t.splitlines())),
     r"r1\.csv, line 4: 59 values for 60 columns"),
    (lambda t: "\n".join(l if i != 2 else "nan" + l[l.index(","):] for i, l in enumerate(t.splitlines())),
     r"r1\.csv, line 3, column 'left_shoulder_x': 'nan'; positions must be finite"),
    (lambda t: "\n".join(l if i != 4 else "abc" + l[l.index(","):] for i, l in enumerate(t.splitlines())),
     r"r1\.csv, line 5, column 'left_shoulder_x': 'abc' is not a number"),
    (lambda t: t.splitlines()[0] + "\n", r"r1\.csv has a header but no frame"),
    (lambda t: "", r"r1\.csv is empty"),
    (lambda t: t.replace("left_shoulder_x", "left_shoulder_y", 1), r"column 'left_shoulder_y' appears twice"),
])
def test_bad_recording_files_name_the_file_and_line_or_are_skipped(tmp_path, damage, message):
    root = _good_folder(tmp_path)
    f = root / "r1.csv"
    _write(f, damage(f.read_text()))
    with pytest.raises(DataFormatError, match=message):
        load_motion_folder(root)
    with pytest.warns(RuntimeWarning, match="1 record"):
        got = load_motion_folder(root, on_error="skip")
    assert [r.record_id for r in got] == ["r0", "r2"]
    assert [s.file for s in got.skipped] == [str(f)] and got.skipped[0].record_id == "r1"


def test_a_recording_with_other_joints_than_the_first(tmp_path):
    root = _good_folder(tmp_path)
    rec = MotionRecording(np.zeros((2, 2, 3)), ("head", "neck"), (1,))
    save_motion_folder([rec], tmp_path / "other")
    (root / "r1.csv").write_text((tmp_path / "other" / "rec0.csv").read_text())
    with pytest.raises(DataFormatError, match=r"r1\.csv, line 1 \(header\): joint\(s\) \[.*'left_shoulder'.*\] missing"):
        load_motion_folder(root)


@pytest.mark.parametrize("labels, message", [
    ("file,labels\nr0.csv,1\nmissing.csv,2\nr2.csv,3\n", r"Motion file .*missing\.csv not found \(.*labels\.csv, line 3\)"),
    ("file,labels\nr0.csv,1\n,2\nr2.csv,3\n", r"labels\.csv, line 3: empty 'file' cell"),
    ("file,labels\nr0.csv,1\nr1.csv,\nr2.csv,3\n", r"labels\.csv, line 3: no label for 'r1\.csv'"),
])
def test_bad_rows_of_labels_csv(tmp_path, labels, message):
    root = _good_folder(tmp_path)
    _write(root / "labels.csv", labels)
    with pytest.raises(DataFormatError, match=message):
        load_motion_folder(root)
    with pytest.warns(RuntimeWarning, match="1 record"):
        got = load_motion_folder(root, on_error="skip")
    assert [r.record_id for r in got] == ["r0", "r2"] and len(got.skipped) == 1


@pytest.mark.parametrize("labels, message", [
    ("path,labels\nr0.csv,1\n", r"labels\.csv: missing column\(s\) \['file'\]; the generic motion layout's labels\.csv "
                                 r"has the header file,labels \(labels separated by ';'\); found \['path', 'labels'\]"),
    ("", r"labels\.csv: missing column\(s\) \['file', 'labels'\]"),
    (b"file,labels\nr0.csv,\xe9\n", r"Cannot read .*labels\.csv"),
])
def test_unusable_labels_csv_raises_whatever_on_error(tmp_path, labels, message):
    root = _good_folder(tmp_path)
    (root / "labels.csv").write_bytes(labels if isinstance(labels, bytes) else labels.encode())
    for mode in ("raise", "skip"):
        with pytest.raises(DataFormatError, match=message):
            load_motion_folder(root, on_error=mode)


def test_folder_errors_and_parameters(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_motion_folder(tmp_path / "nowhere")
    with pytest.raises(DataFormatError, match="has no labels.csv"):
        load_motion_folder(tmp_path)
    root = _good_folder(tmp_path / "ok")
    with pytest.raises(ParameterError, match="on_error"):
        load_motion_folder(root, on_error="ignore")
    with pytest.raises(ParameterError, match="frame_rate"):
        load_motion_folder(root, frame_rate=0)
    assert len(load_motion_folder(root, frame_rate=15)) == 3


def test_the_layout_is_a_named_data_set(tmp_path):
    info = ds.DATASETS["motion"]
    assert info.modality == "motion" and not info.real
    root = _good_folder(tmp_path / "motion")
    assert info.check(root) is None and info.count(root) == 3
    assert len(info.load(root)) == 3
    (root / "labels.csv").write_text("file,what\n")
    assert "lacks column(s) ['labels']; its header is ['file', 'what'], expected file,labels" in info.check(root)
