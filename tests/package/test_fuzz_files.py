"""Corrupt or tampered files: an error naming the file, or the data read right.

Valid files are written in a temporary folder, then one of them is damaged by hypothesis
(truncated, emptied, a byte flipped, text or garbage in place of data, an edited JSON
index, an NPZ with a pickle inside, a skeleton file with text in its numbers...). Each
loader is then called with ``on_error="raise"`` (a DataFormatError naming the damaged
file, or a result equal to the valid one where the damage left the data readable) and with
``on_error="skip"`` (the other files loaded, the damaged one listed in ``.skipped`` with a
RuntimeWarning). No loader may unpickle.
"""

from __future__ import annotations

import io
import json
import tempfile
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from _fuzz import PickleBomb, assert_typed_or_good, fuzz_settings
from mmconcepts.errors import DataFormatError
from mmconcepts.motion.data import MotionRecording, load_choreo1, load_msr_action3d, save_choreo1
from mmconcepts.sound.audio import load_audio, write_audio
from mmconcepts.sound.data import load_generic_audio
from mmconcepts.vision.data import load_image, load_image_folder

pytestmark = pytest.mark.fuzz

SETTINGS = dict(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
N_FILES = 3




def _pickle_npz(entries: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, arr in entries.items():
            with zf.open(name + ".npy", "w") as fh:
                np.lib.format.write_array(fh, np.asarray(arr), allow_pickle=True)
    return buf.getvalue()


@st.composite
def byte_damage(draw, raw: bytes):
    """A damaged copy of ``raw`` and the name of the damage."""
    kind = draw(st.sampled_from(["truncate", "truncate", "empty", "flip", "flip", "text", "garbage_prefix",
                                 "garbage_suffix"]))
    if kind == "truncate":
        return kind, raw[: draw(st.integers(0, max(len(raw) - 1, 0)))]
    if kind == "empty":
        return kind, b""
    if kind == "flip":
        i = draw(st.integers(0, len(raw) - 1))
        return kind, raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1:]
    if kind == "text":
        return kind, b"this is a text file, not data\n"
    junk = draw(st.binary(min_size=1, max_size=64))
    return kind, (junk + raw) if kind == "garbage_prefix" else (raw + junk)


def _load_both(name, load, damaged: Path, n_good: int, *, count, skipped_files, equal_to_valid):
    """Run ``load(on_error)`` for both modes through the harness."""

    def call_raise():
        try:
            return load("raise")
        except DataFormatError as exc:
            assert str(damaged) in str(exc) or damaged.name in str(exc), f"the error does not name {damaged}: {exc}"
            raise

    def check_raise(res):
        return not PickleBomb.ran and (n_good is None or count(res) == n_good + 1) and equal_to_valid(res)

    def call_skip():
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            res = load("skip")
        return res, [x for x in w if issubclass(x.category, RuntimeWarning)]

    def check_skip(out):
        res, warned = out
        skipped = skipped_files(res)
        if PickleBomb.ran:
            return False
        if not skipped:  # the damage left the file readable
            return (n_good is None or count(res) == n_good + 1) and equal_to_valid(res)
        return ((n_good is None or count(res) == n_good) and any(damaged.name in s for s in skipped)
                and bool(warned))

    PickleBomb.ran = False
    assert_typed_or_good(f"{name}(on_error='raise')", call_raise, check=check_raise)
    PickleBomb.ran = False
    assert_typed_or_good(f"{name}(on_error='skip')", call_skip, check=check_skip)
    assert not PickleBomb.ran


# ----------------------------------------------------------------------------- WAV


def _write_audio_set(root: Path):
    rng = np.random.default_rng(0)
    rows = ["file,speaker,labels,transcription"]
    for i in range(N_FILES):
        write_audio(root / f"u{i}.wav", (0.1 * rng.standard_normal(4000)).astype(np.float32), 16000)
        rows.append(f"u{i}.wav,s{i},w{i},hello")
    (root / "labels.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


@fuzz_settings(60, **SETTINGS)
@given(data=st.data(), header_damage=st.booleans())
def test_fuzz_wav_files(data, header_damage):
    """A damaged WAV in the generic audio layout (truncated, wrong header, zero length, non-audio bytes)."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        _write_audio_set(root)
        target = root / "u1.wav"
        raw = target.read_bytes()
        if header_damage:  # a wrong header: a byte of the first 44 changed
            i = data.draw(st.integers(0, 43))
            damaged = raw[:i] + bytes([raw[i] ^ data.draw(st.integers(1, 255))]) + raw[i + 1:]
        else:
            _, damaged = data.draw(byte_damage(raw))
        target.write_bytes(damaged)
        valid = load_audio(root / "u0.wav", sr=None)

        def check_audio(y):
            return y.ndim == 1 and y.size > 0 and np.abs(y).max() <= 1.0

        assert_typed_or_good("mmconcepts.sound.load_audio", lambda: load_audio(target, sr=None), check=check_audio,
                             typed=(FileNotFoundError,))
        assert valid.size
        _load_both("mmconcepts.sound.load_generic_audio", lambda e: load_generic_audio(root, on_error=e), target,
                   N_FILES - 1, count=len, skipped_files=lambda c: [s.file for s in c.skipped],
                   equal_to_valid=lambda c: [u.path.name for u in c] == [f"u{i}.wav" for i in range(N_FILES)])


# ----------------------------------------------------------------------------- PNG


def _write_image_set(root: Path):
    import imageio.v3 as iio

    rng = np.random.default_rng(0)
    rows = ["file,labels"]
    for i in range(N_FILES):
        iio.imwrite(root / f"im{i}.png", (rng.random((8, 9, 3)) * 255).astype(np.uint8))
        rows.append(f"im{i}.png,c{i}")
    (root / "labels.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


@fuzz_settings(60, **SETTINGS)
@given(data=st.data())
def test_fuzz_png_files(data):
    """A damaged PNG (truncated, zero bytes, a text file named .png, flipped bytes)."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        _write_image_set(root)
        target = root / "im1.png"
        _, damaged = data.draw(byte_damage(target.read_bytes()))
        target.write_bytes(damaged)

        def check_image(im):
            return im.shape == (8, 9, 3) and im.min() >= 0 and im.max() <= 1

        assert_typed_or_good("mmconcepts.vision.load_image", lambda: load_image(target), check=check_image,
                             typed=(FileNotFoundError,))
        _load_both("mmconcepts.vision.load_image_folder", lambda e: load_image_folder(root, on_error=e), target,
                   N_FILES - 1, count=len, skipped_files=lambda s: [k.file for k in s.skipped],
                   equal_to_valid=lambda s: all(im.shape == (8, 9, 3) for im in s.images))


# ----------------------------------------------------------------------------- labels CSV

_CSV_DAMAGE = ["missing_file_column", "missing_label_column", "latin1", "binary", "empty", "header_only",
               "truncate", "extra_cells", "missing_cells", "unknown_file", "nul_bytes", "bom", "crlf"]


def _damage_csv(kind: str, text: str, draw) -> bytes:
    lines = text.splitlines()
    if kind == "missing_file_column":
        return text.replace("file,", "path,", 1).encode()
    if kind == "missing_label_column":
        return text.replace(",label", ",class", 1).encode()
    if kind == "latin1":
        return text.replace("c1", "c\xe9").replace("w1", "w\xe9").encode("latin-1")
    if kind == "binary":
        return bytes(range(256))
    if kind == "empty":
        return b""
    if kind == "header_only":
        return (lines[0] + "\n").encode()
    if kind == "truncate":
        raw = text.encode()
        return raw[: draw(st.integers(0, len(raw) - 1))]
    if kind == "extra_cells":
        return "\n".join(lines[:2] + [lines[2] + ",x,y,z"] + lines[3:]).encode()
    if kind == "missing_cells":
        return "\n".join(lines[:2] + [lines[2].split(",")[0]] + lines[3:]).encode()
    if kind == "unknown_file":
        return (text + lines[1].replace("0", "9") + "\n").encode()
    if kind == "nul_bytes":
        return text.replace("c1", "c\x001").replace("w1", "w\x001").encode()
    if kind == "bom":
        return b"\xef\xbb\xbf" + text.encode()
    return text.replace("\n", "\r\n").encode()


@fuzz_settings(60, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(_CSV_DAMAGE), layout=st.sampled_from(["image", "audio"]))
def test_fuzz_labels_csv(data, kind, layout):
    """A damaged labels.csv: a DataFormatError naming it, or the rows that are right."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        (_write_image_set if layout == "image" else _write_audio_set)(root)
        labels = root / "labels.csv"
        text = labels.read_text(encoding="utf-8")
        if layout == "audio":
            text = text.replace("labels", "label", 1) if kind == "missing_label_column" else text
        labels.write_bytes(_damage_csv(kind, text, data.draw))
        load = (lambda e: load_image_folder(root, on_error=e)) if layout == "image" else (
            lambda e: load_generic_audio(root, on_error=e))

        def call(mode):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    return load(mode)
            except DataFormatError as exc:
                assert "labels.csv" in str(exc) or ".png" in str(exc) or ".wav" in str(exc), str(exc)
                raise

        def check(res):
            # every loaded item is one of the valid files, in order, with its own label
            names = [Path(p).name for p in (res.paths if layout == "image" else [u.path for u in res])]
            if len(names) + len(res.skipped) < 1 and kind not in ("header_only", "empty", "truncate"):
                return False
            valid = [f"im{i}.png" if layout == "image" else f"u{i}.wav" for i in range(N_FILES)]
            return names == [n for n in valid if n in names] and len(names) <= N_FILES

        for mode in ("raise", "skip"):
            assert_typed_or_good(f"labels.csv of the {layout} layout (on_error={mode!r})", lambda: call(mode),
                                 check=check)


# ----------------------------------------------------------------------------- Choreo1 JSON + NPZ


def _write_choreo(root: Path) -> Path:
    rng = np.random.default_rng(0)
    recs = [MotionRecording(rng.random((5, 3, 3)), ("a", "b", "c"), (i + 1,)) for i in range(N_FILES)]
    return save_choreo1(recs, root, "subset")


_JSON_EDITS = [
    ("records", {}), ("records", None), ("records", [1, 2]), ("records", [{"data-id": 0}]),
    ("records", [{"data-id": 0, "labels": "1"}]), ("records", [{"data-id": 0, "labels": [True]}]),
    ("records", [{"data-id": 99, "labels": [1]}]), ("records", [{"data-id": [0], "labels": [1]}]),
    ("marker-names", "abc"), ("marker-names", [1, 2, 3]), ("marker-names", ["a", "b"]),
    ("data-file", 3), ("data-file", "missing.npz"), ("data-file", "../subset.json"), ("data-file", ""),
    ("data-file", None), (None, [1, 2, 3]), (None, "text"), (None, 5),
]


@fuzz_settings(80, **SETTINGS)
@given(data=st.data(), target=st.sampled_from(["json_bytes", "json_edit", "json_deep", "npz_bytes", "npz_pickle",
                                               "npz_shape", "npz_nan", "npz_text"]))
def test_fuzz_choreo_files(data, target):
    """A damaged Choreo1 index (truncated, wrong types) or NPZ (truncated, a pickle or bad arrays inside)."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        json_path = _write_choreo(root)
        npz_path = root / "subset.npz"
        damaged = json_path
        if target == "json_bytes":
            _, raw = data.draw(byte_damage(json_path.read_bytes()))
            json_path.write_bytes(raw)
        elif target == "json_edit":
            meta = json.loads(json_path.read_text())
            key, value = data.draw(st.sampled_from(_JSON_EDITS))
            meta = value if key is None else {**meta, key: value}
            json_path.write_text(json.dumps(meta))
        elif target == "json_deep":
            json_path.write_text("[" * 100_000 + "]" * 100_000)
        else:
            damaged = npz_path
            with np.load(npz_path) as z:
                entries = {k: z[k] for k in z.files}
            if target == "npz_bytes":
                _, raw = data.draw(byte_damage(npz_path.read_bytes()))
                npz_path.write_bytes(raw)
            elif target == "npz_pickle":
                entries[data.draw(st.sampled_from(sorted(entries)))] = np.array([PickleBomb()], dtype=object)
                npz_path.write_bytes(_pickle_npz(entries))
            elif target == "npz_shape":
                entries["1"] = data.draw(st.sampled_from([np.zeros((0, 3, 3)), np.zeros((5, 3)), np.zeros((5, 2, 3)),
                                                          np.array("x"), np.zeros((5, 3, 3), dtype=bool)]))
                npz_path.write_bytes(_pickle_npz(entries))
            elif target == "npz_nan":
                entries["1"] = np.full((5, 3, 3), data.draw(st.sampled_from([np.nan, np.inf, -np.inf])))
                npz_path.write_bytes(_pickle_npz(entries))
            else:
                npz_path.write_text("not an archive")
        # an edited index (or one whose flipped byte still parses: a label 2 -> 3) is a different valid index:
        # any count of records with integer labels is right
        edited = target in ("json_edit", "json_bytes")
        _load_both("mmconcepts.motion.load_choreo1", lambda e: load_choreo1(json_path, on_error=e), damaged,
                   None if edited else N_FILES - 1, count=len, skipped_files=lambda ds: [f"{s.file}: {s.reason}" for s in ds.skipped],
                   equal_to_valid=lambda ds: (all(all(isinstance(x, int) for x in r.labels) for r in ds) and len(ds) <= 3)
                   if edited else [r.labels for r in ds] == [(1,), (2,), (3,)])


# ----------------------------------------------------------------------------- MSR Action3D skeletons


def _msr_text(rng, n_frames=3) -> str:
    vals = rng.random((n_frames * 20, 4))
    return "\n".join(" ".join(f"{v:.6f}" for v in row) for row in vals) + "\n"


@fuzz_settings(80, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(["bytes", "drop_line", "extra_value", "missing_value", "text_number",
                                             "nan", "inf", "empty", "blank_lines", "comma_separated", "all_zero",
                                             "folder", "dangling_link"]))
def test_fuzz_msr_skeleton_files(data, kind):
    """A damaged aAA_sSS_eEE_skeleton3D.txt (wrong number of values, text in numbers, ...)."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        rng = np.random.default_rng(0)
        names = [f"a0{i + 1}_s01_e01_skeleton3D.txt" for i in range(N_FILES)]
        for n in names:
            (root / n).write_text(_msr_text(rng))
        target = root / names[1]
        text = target.read_text()
        lines = text.splitlines()
        i = data.draw(st.integers(0, len(lines) - 1))
        if kind == "bytes":
            _, raw = data.draw(byte_damage(text.encode()))
            target.write_bytes(raw)
        elif kind == "drop_line":
            target.write_text("\n".join(lines[:i] + lines[i + 1:]) + "\n")
        elif kind == "extra_value":
            lines[i] += " 1.0"
            target.write_text("\n".join(lines) + "\n")
        elif kind == "missing_value":
            lines[i] = " ".join(lines[i].split()[:3])
            target.write_text("\n".join(lines) + "\n")
        elif kind == "text_number":
            parts = lines[i].split()
            parts[data.draw(st.integers(0, 3))] = data.draw(st.sampled_from(["abc", "1.2.3", "--", "0x10", "1e"]))
            lines[i] = " ".join(parts)
            target.write_text("\n".join(lines) + "\n")
        elif kind in ("nan", "inf"):
            parts = lines[i].split()
            parts[data.draw(st.integers(0, 2))] = kind
            lines[i] = " ".join(parts)
            target.write_text("\n".join(lines) + "\n")
        elif kind == "empty":
            target.write_bytes(b"")
        elif kind == "blank_lines":
            target.write_text("\n\n".join(lines) + "\n")
        elif kind == "comma_separated":
            target.write_text(text.replace(" ", ","))
        elif kind == "all_zero":
            target.write_text("\n".join("0 0 0 0" for _ in lines) + "\n")
        elif kind == "folder":
            target.unlink()
            target.mkdir()
        else:
            target.unlink()
            target.symlink_to(root / "nowhere.txt")

        def equal(ds):
            return [r.record_id for r in ds] == [n.split("_skeleton3D")[0] for n in names] and all(
                r.positions.shape[1:] == (20, 3) and np.isfinite(r.positions).all() for r in ds)

        if kind == "all_zero":  # no motion at all: listed in skipped whatever on_error (documented)
            ds = load_msr_action3d(root)
            assert len(ds) == N_FILES - 1 and ds.skipped and ds.skipped[0].source == str(target)
            return
        _load_both("mmconcepts.motion.load_msr_action3d", lambda e: load_msr_action3d(root, on_error=e), target,
                   N_FILES - 1, count=len, skipped_files=lambda ds: [s.source for s in ds.skipped],
                   equal_to_valid=equal)


# ----------------------------------------------------------------------------- a saved model with a pickle inside


@fuzz_settings(40, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(["pickle_header", "pickle_array", "truncate", "text"]))
def test_fuzz_saved_model_with_pickle(data, kind):
    """Any SaveLoadMixin model (here NMF and ColorHistograms): DataFormatError naming the file, never unpickling."""
    from mmconcepts.nmf import NMF
    from mmconcepts.tasks import GradIRL, grid_world

    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        which = data.draw(st.sampled_from(["nmf", "gradirl"]))
        if which == "nmf":
            cls, model = NMF, NMF(2, max_iter=5, random_state=0).fit(np.random.default_rng(0).random((6, 4)))
        else:
            mdp = grid_world(2)
            cls, model = GradIRL, GradIRL(max_iter=2).fit(mdp, [[np.array([[0, 1], [1, 2]])]])
        path = model.save(root / "m.npz")
        with np.load(path) as z:
            entries = {k: z[k] for k in z.files}
        if kind == "pickle_header":
            entries["header"] = np.array([PickleBomb()], dtype=object)
            path.write_bytes(_pickle_npz(entries))
        elif kind == "pickle_array":
            entries[data.draw(st.sampled_from(sorted(k for k in entries if k != "header")))] = np.array(
                [PickleBomb()], dtype=object)
            path.write_bytes(_pickle_npz(entries))
        elif kind == "truncate":
            raw = path.read_bytes()
            path.write_bytes(raw[: data.draw(st.integers(0, len(raw) - 1))])
        else:
            path.write_text("text")
        PickleBomb.ran = False

        def call():
            try:
                return cls.load(path)
            except DataFormatError as exc:
                assert str(path) in str(exc), str(exc)
                raise

        assert_typed_or_good(f"{cls.__name__}.load of a damaged file", call, check=lambda m: not PickleBomb.ran)
        assert not PickleBomb.ran


def test_choreo_skip_names_the_index_for_a_bad_record_entry_and_the_archive_for_a_bad_array(tmp_path):
    json_path = _write_choreo(tmp_path)
    meta = json.loads(json_path.read_text())
    meta["records"][0]["labels"] = "1"  # the index is wrong
    meta["records"][1]["data-id"] = 99  # the archive has no such array
    json_path.write_text(json.dumps(meta))
    with pytest.warns(RuntimeWarning, match="2 record"):
        ds = load_choreo1(json_path, on_error="skip")
    assert [r.labels for r in ds] == [(3,)]
    assert [s.file for s in ds.skipped] == [str(json_path), str(tmp_path / "subset.npz")]
    meta["data-file"] = "gone.npz"
    json_path.write_text(json.dumps(meta))
    with pytest.raises(DataFormatError, match=r"subset\.json names the data file 'gone\.npz', which is missing"):
        load_choreo1(json_path)


# ----------------------------------------------------------------------------- COIL-20 .mat


@fuzz_settings(60, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(["bytes", "bytes", "fea", "gnd", "missing", "intact"]))
def test_fuzz_coil20_mat(data, kind):
    """A damaged or edited COIL20.mat: a DataFormatError naming it, or the images read right."""
    import scipy.io

    from mmconcepts.vision.data import load_coil20

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "COIL20.mat"
        rng = np.random.default_rng(0)
        fea, gnd = rng.random((4, 16)), np.array([[1], [1], [2], [2]])
        if kind == "fea":
            fea = data.draw(st.sampled_from([np.zeros((0, 16)), np.zeros((4, 0)), np.zeros((4, 15)), rng.random((4, 1)),
                                             np.full((4, 16), np.nan), rng.random((4, 16)) * 300, -rng.random((4, 16)),
                                             np.array([["a"] * 16] * 4), rng.random((4, 16)) > 0.5,
                                             (rng.random((4, 16)) * 255).astype(np.uint8)]))
        elif kind == "gnd":
            gnd = data.draw(st.sampled_from([np.array([[np.nan]] * 4), np.array([["x"]] * 4), np.zeros((3, 1)),
                                             np.array([[1.5]] * 4), np.zeros((0, 1)), np.array([[1e300]] * 4)]))
        mdict = {"fea": fea, "gnd": gnd}
        if kind == "missing":
            del mdict[data.draw(st.sampled_from(["fea", "gnd"]))]
        scipy.io.savemat(path, mdict)
        if kind == "bytes":
            _, raw = data.draw(byte_damage(path.read_bytes()))
            path.write_bytes(raw)

        def call():
            try:
                return load_coil20(path)
            except DataFormatError as exc:
                assert str(path) in str(exc), str(exc)
                raise

        def check(s):
            n = len(s)
            return (n == len(s.labels) and n >= 1 and all(im.ndim == 3 and im.shape[2] == 3 and im.shape[0] == im.shape[1]
                                                           and im.min() >= 0 and im.max() <= 1 for im in s.images))

        assert_typed_or_good("mmconcepts.vision.load_coil20", call, check=check)


# ----------------------------------------------------------------------------- ACORNS XML

_ACORNS_XML = ('<?xml version="1.0"?>\n<utterance>\n  <audio-file value="u{i}"/>\n  <vistag value="w{i}"/>\n'
               '  <trans>hello w{i}</trans>\n</utterance>\n')
_XML_EDITS = [
    "<utterance><vistag value='w'/></utterance>", "<utterance><audio-file value='u1'/></utterance>",
    "<utterance><audio-file value='u1'/><audio-file value='u2'/><vistag value='w'/></utterance>",
    "<utterance><audio-file value=''/><vistag value='w'/></utterance>",
    "<utterance><audio-file value='u1'/><vistag value=' ,; '/></utterance>",
    "<utterance><audio-file value='nowhere'/><vistag value='w'/></utterance>",
    "<a>" * 50_000 + "</a>" * 50_000,
    '<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">'
    '<!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;"><!ENTITY f "&e;&e;&e;&e;&e;&e;&e;&e;&e;&e;">'
    '<!ENTITY g "&f;&f;&f;&f;&f;&f;&f;&f;&f;&f;"><!ENTITY h "&g;&g;&g;&g;&g;&g;&g;&g;&g;&g;">]>'
    "<utterance><audio-file value='u1'/><vistag value='&h;'/></utterance>",
    '<?xml version="1.0"?><!DOCTYPE u [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
    "<utterance><audio-file value='u1'/><vistag value='w'/><trans>&x;</trans></utterance>",
]


@fuzz_settings(60, **SETTINGS)
@given(data=st.data(), kind=st.sampled_from(["bytes", "bytes", "edit"]))
def test_fuzz_acorns_xml(data, kind):
    """A damaged ACORNS XML file (cut, flipped, unknown structure, deep nesting, entity expansion, external entity)."""
    from mmconcepts.sound.data import load_acorns

    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        (root / "XML" / "Speaker-01").mkdir(parents=True)
        (root / "WAV" / "Speaker-01").mkdir(parents=True)
        rng = np.random.default_rng(0)
        for i in range(N_FILES):
            (root / "XML" / "Speaker-01" / f"u{i}.xml").write_text(_ACORNS_XML.format(i=i))
            write_audio(root / "WAV" / "Speaker-01" / f"u{i}.wav", (0.1 * rng.standard_normal(4000)).astype(np.float32),
                        16000)
        target = root / "XML" / "Speaker-01" / "u1.xml"
        if kind == "bytes":
            _, raw = data.draw(byte_damage(target.read_bytes()))
            target.write_bytes(raw)
        else:
            target.write_text(data.draw(st.sampled_from(_XML_EDITS)))

        def equal(c):
            return all(len(u.labels) >= 1 and "root:" not in u.transcription for u in c) and len(c) <= N_FILES

        _load_both("mmconcepts.sound.load_acorns", lambda e: load_acorns(root, on_error=e), target, N_FILES - 1,
                   count=len, skipped_files=lambda c: [s.file for s in c.skipped],
                   equal_to_valid=equal)


_CRASH_SCRIPT = """
import sys
from pathlib import Path
from mmconcepts.vision.data import load_coil20
raw, path = Path(sys.argv[1]).read_bytes(), Path(sys.argv[2])
cases = [raw[:i] + bytes([raw[i] ^ x]) + raw[i + 1:] for i in range(len(raw)) for x in (0x01, 0x80, 0xFF)]
cases += [raw[:n] for n in range(len(raw))]
for k, damaged in enumerate(cases):
    path.write_bytes(damaged)
    print(k, flush=True)
    try:
        load_coil20(path)
    except Exception:  # any exception is fine here; a crash is not
        pass
print("done", len(cases))
"""


@pytest.mark.parametrize("compressed", [False, True])
def test_no_damaged_coil20_mat_crashes_the_process(tmp_path, compressed):
    """scipy.io.loadmat dies with SIGSEGV/SIGBUS on some flipped bytes (matrix dimensions); load_coil20 checks
    the file's structure first. Every single-byte flip (three masks) and every truncation, loaded one after the
    other in a child process that must reach the end."""
    import subprocess
    import sys

    import scipy.io

    valid = tmp_path / "valid.mat"
    rng = np.random.default_rng(0)
    scipy.io.savemat(valid, {"fea": rng.random((4, 16)), "gnd": np.array([[1], [1], [2], [2]])},
                     do_compression=compressed)
    proc = subprocess.run([sys.executable, "-c", _CRASH_SCRIPT, str(valid), str(tmp_path / "COIL20.mat")],
                          capture_output=True, text=True, timeout=300)
    last = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else "nothing"
    assert proc.returncode == 0 and last.startswith("done"), (
        f"the child died (return code {proc.returncode}) after case {last}: {proc.stderr[-500:]}")
