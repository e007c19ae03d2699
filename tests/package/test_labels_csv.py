"""One header for every generic layout's ``labels.csv``: ``file,labels`` (``;`` between labels), then the layout's
own columns. The old spelling ``label`` is read the same, with one FutureWarning per table read."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mmconcepts.errors import DataFormatError, DataWarning
from mmconcepts.motion.data import load_motion_folder, save_motion_folder
from mmconcepts.sound.data import load_generic_audio, save_generic_audio
from mmconcepts.vision.data import load_image_folder
from mmconcepts.vision.synthetic import write_image_folder


def _audio(root, header):
    for name in ("a.wav", "b.wav"):
        (root / name).write_bytes(b"RIFF")
    rows = {"file,labels,speaker,transcription": "a.wav,car;shoe,s1,the car\nb.wav,book,s2,a book\n",
            "file,speaker,label,transcription": "a.wav,s1,car;shoe,the car\nb.wav,s2,book,a book\n"}[header]
    (root / "labels.csv").write_text(f"{header}\n{rows}")
    corpus = load_generic_audio(root, check_audio=False)
    return [(u.path.name, u.labels, u.speaker, u.transcription) for u in corpus]


def _images(root, header):
    import imageio.v3 as iio

    for name in ("a.png", "b.png"):
        iio.imwrite(root / name, np.zeros((4, 4), dtype=np.uint8))
    rows = {"file,labels,view": "a.png,cup,0\nb.png,ball,1\n", "file,label,view": "a.png,cup,0\nb.png,ball,1\n"}
    (root / "labels.csv").write_text(f"{header}\n{rows[header]}")
    images = load_image_folder(root)
    return list(images.labels), list(images.views or ())


def _motion(root, header):
    for name in ("r0.csv", "r1.csv"):
        (root / name).write_text("hand_x,hand_y,hand_z\n0,0,0\n1,1,1\n")
    rows = {"file,labels": "r0.csv,wave;clap\nr1.csv,clap\n", "file,label": "r0.csv,wave;clap\nr1.csv,clap\n"}
    (root / "labels.csv").write_text(f"{header}\n{rows[header]}")
    data = load_motion_folder(root)
    return [tuple(data.label_names[i] for i in r.labels) for r in data]


LAYOUTS = [
    (_audio, "file,labels,speaker,transcription", "file,speaker,label,transcription", "file,labels,speaker[,transcription]"),
    (_images, "file,labels,view", "file,label,view", "file,labels[,view][,category]"),
    (_motion, "file,labels", "file,label", "file,labels"),
]


@pytest.mark.parametrize("load, new, old, expected", LAYOUTS, ids=["audio", "images", "motion"])
def test_the_old_spelling_reads_the_same_with_one_warning_per_file(tmp_path, load, new, old, expected):
    (tmp_path / "new").mkdir()
    (tmp_path / "old").mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("error", FutureWarning)  # the new header: no warning
        got_new = load(tmp_path / "new", new)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got_old = load(tmp_path / "old", old)
    assert got_old == got_new
    future = [w for w in caught if issubclass(w.category, FutureWarning)]
    assert len(future) == 1  # one per table, not one per row
    message = str(future[0].message)
    assert message.startswith(f"{tmp_path / 'old' / 'labels.csv'}: the column 'label' is the old spelling of 'labels'")
    assert f"Write the header {expected} (several labels in a cell separated by ';')" in message


def test_labels_are_split_at_semicolons(tmp_path):
    assert _audio(tmp_path, "file,labels,speaker,transcription")[0][1] == ("car", "shoe")
    (tmp_path / "m").mkdir()
    assert _motion(tmp_path / "m", "file,labels")[0] == ("wave", "clap")


def test_an_image_takes_one_label(tmp_path):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "a.png", np.zeros((4, 4), dtype=np.uint8))
    (tmp_path / "labels.csv").write_text("file,labels\na.png,cup;ball\n")
    with pytest.raises(DataFormatError, match=r"line 2: 2 labels for 'a\.png' \('cup;ball'\); the generic image "
                                              r"layout takes one label per image"):
        load_image_folder(tmp_path)


def test_a_table_without_labels_names_the_header_expected(tmp_path):
    (tmp_path / "r0.csv").write_text("hand_x,hand_y,hand_z\n0,0,0\n")
    (tmp_path / "labels.csv").write_text("file,tags\nr0.csv,wave\n")
    with pytest.raises(DataFormatError, match=r"missing column\(s\) \['labels'\]; the generic motion layout's labels"
                                              r"\.csv has the header file,labels \(labels separated by ';'\); found "
                                              r"\['file', 'tags'\]"):
        load_motion_folder(tmp_path)


def test_the_writers_write_the_one_header(tmp_path):
    for name in ("a.wav", "b.wav"):
        (tmp_path / name).write_bytes(b"RIFF")
    (tmp_path / "labels.csv").write_text("file,speaker,labels\na.wav,s1,car;shoe\nb.wav,s2,book\n")
    corpus = load_generic_audio(tmp_path, check_audio=False)
    lines = save_generic_audio(corpus, tmp_path).read_text().splitlines()
    assert lines[:2] == ["file,labels,speaker,transcription", "a.wav,car;shoe,s1,"]
    (tmp_path / "m").mkdir()
    _motion(tmp_path / "m", "file,labels")
    out = save_motion_folder(load_motion_folder(tmp_path / "m"), tmp_path / "m2")
    assert out.read_text().splitlines()[0] == "file,labels"
    (tmp_path / "i").mkdir()
    _images(tmp_path / "i", "file,labels,view")
    out = write_image_folder(load_image_folder(tmp_path / "i"), tmp_path / "i2")
    assert out.read_text().splitlines()[0] == "file,labels,view"


def _three_files(root, layout):
    import imageio.v3 as iio

    for i in range(3):
        if layout == "audio":
            (root / f"f{i}.wav").write_bytes(b"RIFF")
        elif layout == "images":
            iio.imwrite(root / f"f{i}.png", np.zeros((4, 4), dtype=np.uint8))
        else:
            (root / f"f{i}.csv").write_text("hand_x,hand_y,hand_z\n0,0,0\n1,1,1\n")


_COMPLETE = {"audio": "file,labels,speaker\nf0.wav,car,s1\nf1.wav,book,s2\nf2.wav,shoe,s3",
             "images": "file,labels,view\nf0.png,cup,0\nf1.png,ball,1\nf2.png,cup,2",
             "motion": "file,labels\nf0.csv,wave\nf1.csv,clap\nf2.csv,wave"}
_CUT = {  # the last row cut short: fewer cells than the header, or a quoted cell left open
    ("audio", "cells"): "file,labels,speaker\nf0.wav,car,s1\nf1.wav,book,s2\nf2.wav,sh",
    ("audio", "quote"): 'file,labels,speaker\nf0.wav,car,s1\nf1.wav,book,s2\nf2.wav,shoe,"s',
    ("images", "cells"): "file,labels,view\nf0.png,cup,0\nf1.png,ball,1\nf2.png,cu",
    ("images", "quote"): 'file,labels,view\nf0.png,cup,0\nf1.png,ball,1\nf2.png,"cup;\n',
    ("motion", "cells"): "file,labels\nf0.csv,wave\nf1.csv,clap\nf2.cs",
    ("motion", "quote"): 'file,labels\nf0.csv,wave\nf1.csv,clap\nf2.csv,"wave;cl',
}
_LOADERS = {"audio": lambda root, **kw: load_generic_audio(root, check_audio=False, **kw),
            "images": load_image_folder, "motion": load_motion_folder}


@pytest.mark.parametrize("layout", ["audio", "images", "motion"])
@pytest.mark.parametrize("cut", ["cells", "quote"])
def test_a_table_that_ends_early_is_named_or_counted(tmp_path, layout, cut):
    """A labels.csv cut short (its last row with fewer cells than the header and no line break after it, or a
    quoted cell still open at the end) is not loaded in part silently: on_error='raise' names the file and the
    line, on_error='skip' leaves the cut row out with a DataWarning counting the rows read."""
    _three_files(tmp_path, layout)
    path = tmp_path / "labels.csv"
    path.write_text(_CUT[layout, cut])
    load = _LOADERS[layout]
    with pytest.raises(DataFormatError, match=rf"{path} ends early: its last row, line 4, "):
        load(tmp_path)
    with pytest.warns(DataWarning, match=rf"{path} ended early: its last row, line 4, .* left out; 2 row\(s\) read"):
        data = load(tmp_path, on_error="skip")
    assert len(data) == 2


@pytest.mark.parametrize("layout", ["audio", "images", "motion"])
def test_a_complete_last_row_without_a_line_break_is_read(tmp_path, layout):
    _three_files(tmp_path, layout)
    (tmp_path / "labels.csv").write_text(_COMPLETE[layout])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(_LOADERS[layout](tmp_path)) == 3
