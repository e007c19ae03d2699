"""Data root, named data sets and `data fetch` (mmconcepts.datasets)."""

from __future__ import annotations

import functools
import gzip
import hashlib
import http.server
import io
import logging
import os
import tarfile
import threading
import warnings
import wave
import zipfile
from pathlib import Path

import numpy as np
import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from conftest import DATA_ROOT
from mmconcepts import datasets as ds
from mmconcepts.errors import DataError, ParameterError

# --------------------------------------------------------------------------- helpers


def _wav_bytes(n: int = 800, rate: int = 8000, seed: int = 0) -> bytes:
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        x = np.random.default_rng(seed).integers(-3000, 3000, n).astype("<i2")
        w.writeframes(x.tobytes())
    return buf.getvalue()


def _tar_gz(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    return buf.getvalue()


#: A miniature of the FSDD tag archive: free-spoken-digit-dataset-<tag>/recordings/*.wav.
FSDD_FILES = ["0_jackson_0.wav", "0_theo_1.wav", "7_nicolas_12.wav", "9_george_3.wav", "3_yweweler_49.wav"]


def _fsdd_archive() -> bytes:
    top = "free-spoken-digit-dataset-1.0.9"
    members = {f"{top}/recordings/{f}": _wav_bytes(seed=i) for i, f in enumerate(FSDD_FILES)}
    members[f"{top}/README.md"] = b"# Free Spoken Digit Dataset (test miniature)\n"
    members[f"{top}/metadata.py"] = b"metadata = {}\n"
    return _tar_gz(members)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):  # keep test output clean
        pass


@pytest.fixture
def server(tmp_path, monkeypatch):
    """A loopback HTTP server (127.0.0.1, free port) serving the folder it returns, and its base URL."""
    for var in ("HTTP_PROXY", "HTTPS_PROXY", "http_proxy", "https_proxy", "ALL_PROXY", "all_proxy"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    served = tmp_path / "served"
    served.mkdir()
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(served)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield served, f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(5)


@pytest.fixture
def no_env_root(monkeypatch):
    monkeypatch.delenv(ds.DATA_ROOT_ENV, raising=False)


# --------------------------------------------------------------------------- registry


def test_registry_names_and_fields():
    assert list(ds.DATASETS) == ["fsdd", "msr-action3d", "eth80", "coil20", "choreo1", "choreo2", "acorns",
                                 "audio", "motion", "images"]
    assert ds.DATASETS["eth80"].folders == ("eth80", "eth80-96px")
    for info in ds.DATASETS.values():
        assert info.modality in ("speech", "motion", "images")
        assert info.title and info.layout and info.source and info.licence and info.obtain
        assert info.real == (info.name not in ("audio", "motion", "images"))
        assert (info.url is None) or (info.sha256 is not None and len(info.sha256) == 64)
        assert info.citation or not info.real
    # Only FSDD has a stable public download with a published hash.
    assert [n for n, i in ds.DATASETS.items() if i.url] == ["fsdd"]
    with pytest.raises(ParameterError, match="msr"):
        ds.find_dataset("msr")


def test_every_loader_resolves():
    import importlib

    for info in ds.DATASETS.values():
        module, _, funcs = info.loader.partition(":")
        mod = importlib.import_module(module)
        assert any(callable(getattr(mod, f, None)) for f in funcs.split("|")), info.loader


def test_load_reads_a_found_set(tmp_path, no_env_root):
    _make_msr(tmp_path / "msr-action3d", 2)
    rec = ds.DATASETS["msr-action3d"].load(ds.find_dataset("msr-action3d", tmp_path))
    assert len(rec) == 2


# --------------------------------------------------------------------------- data root


def test_data_root_explicit_wins_over_env(tmp_path, monkeypatch):
    monkeypatch.setenv(ds.DATA_ROOT_ENV, str(tmp_path / "env"))
    assert ds.data_root(tmp_path / "explicit") == tmp_path / "explicit"
    assert ds.data_root(str(tmp_path / "explicit")) == tmp_path / "explicit"
    assert ds.data_root() == tmp_path / "env"


def test_data_root_none_without_env_never_shared(no_env_root, monkeypatch):
    # Even run from the checkout, whose sibling ../shared/data may exist, nothing is guessed.
    monkeypatch.chdir(Path(__file__).resolve().parents[2])
    assert ds.data_root() is None
    assert ds.find_datasets() == {}
    assert ds.find_dataset("fsdd") is None
    assert all(row["found"] is None and row["problem"] is None for row in ds.dataset_status())


def test_data_root_expands_user_and_is_absolute(tmp_path, no_env_root, monkeypatch):
    assert ds.data_root("~/x") == Path.home() / "x"
    monkeypatch.chdir(tmp_path)
    assert ds.data_root("rel") == tmp_path / "rel"
    monkeypatch.setenv(ds.DATA_ROOT_ENV, "rel-env")
    assert ds.data_root() == tmp_path / "rel-env"


# --------------------------------------------------------------------------- finding sets


def _make_msr(folder: Path, n: int = 2) -> None:
    folder.mkdir(parents=True)
    for i in range(n):
        (folder / f"a01_s0{i + 1}_e01_skeleton3D.txt").write_text("0 1 2 1\n" * 20)


def _make_eth80(folder: Path, names=("cow1-000-000.png", "cow1-022-090.png", "apple2-045-180.png")) -> None:
    import imageio.v3 as iio

    folder.mkdir(parents=True)
    for name in names:
        iio.imwrite(folder / name, np.zeros((4, 4, 3), np.uint8))


def test_find_dataset_present_absent(tmp_path, no_env_root):
    _make_msr(tmp_path / "msr-action3d", 3)
    assert ds.find_dataset("msr-action3d", tmp_path) == tmp_path / "msr-action3d"
    assert ds.DATASETS["msr-action3d"].count(tmp_path / "msr-action3d") == 3
    assert ds.find_dataset("fsdd", tmp_path) is None
    assert ds.find_dataset("fsdd", tmp_path / "no-such-root") is None
    assert ds.find_datasets(tmp_path) == {"msr-action3d": tmp_path / "msr-action3d"}
    assert ds.find_datasets(tmp_path, names=["fsdd"]) == {}


def test_find_dataset_uses_env_root(tmp_path, monkeypatch):
    _make_msr(tmp_path / "msr-action3d")
    monkeypatch.setenv(ds.DATA_ROOT_ENV, str(tmp_path))
    assert ds.find_dataset("msr-action3d") == tmp_path / "msr-action3d"


def test_wrong_layout_is_ignored_with_a_warning(tmp_path, no_env_root, caplog):
    bad = tmp_path / "fsdd"
    bad.mkdir()
    (bad / "notes.txt").write_text("not a data set")
    with caplog.at_level(logging.WARNING, logger="mmconcepts.datasets"):
        assert ds.find_dataset("fsdd", tmp_path) is None
    assert str(bad) in caplog.text and "labels.csv" in caplog.text
    # labels.csv present but no FSDD-named WAV: still wrong.
    (bad / "labels.csv").write_text("file,speaker,labels,transcription\n")
    assert ds.DATASETS["fsdd"].check(bad) == "no {digit}_{speaker}_{index}.wav file"
    assert not ds.DATASETS["fsdd"].is_valid(bad)


def test_first_sound_folder_wins_and_bad_one_is_named(tmp_path, no_env_root, caplog):
    (tmp_path / "eth80").mkdir()  # present but empty: wrong layout
    _make_eth80(tmp_path / "eth80-96px")
    with caplog.at_level(logging.WARNING, logger="mmconcepts.datasets"):
        assert ds.find_dataset("eth80", tmp_path) == tmp_path / "eth80-96px"
    assert str(tmp_path / "eth80") + ":" in caplog.text
    assert ds.DATASETS["eth80"].count(tmp_path / "eth80-96px") == 3
    _make_eth80(tmp_path / "eth80" / "cow" / "cow1", names=("cow1-000-000.png",))
    assert ds.find_dataset("eth80", tmp_path) == tmp_path / "eth80"  # first in folders order


def test_checks_and_counts_of_every_layout(tmp_path):
    import json

    import scipy.io

    coil = tmp_path / "coil20"
    coil.mkdir()
    scipy.io.savemat(coil / "COIL20.mat", {"fea": np.zeros((6, 1024)), "gnd": np.arange(6)[:, None] + 1})
    assert ds.DATASETS["coil20"].check(coil) is None and ds.DATASETS["coil20"].count(coil) == 6
    (coil / "COIL20.mat").write_bytes(b"garbage")
    assert "not a readable MATLAB file" in ds.DATASETS["coil20"].check(coil)

    c1 = tmp_path / "choreo1"
    c1.mkdir()
    (c1 / "primitive.json").write_text(json.dumps({"records": [{"data-id": i, "labels": [1]} for i in range(4)]}))
    (c1 / "mixed_full.json").write_text(json.dumps({"records": [{"data-id": 0, "labels": [1, 2]}]}))
    assert ds.DATASETS["choreo1"].check(c1) is None and ds.DATASETS["choreo1"].count(c1) == 5
    c2 = tmp_path / "choreo2"
    c2.mkdir()
    assert ds.DATASETS["choreo2"].check(c2) == "no choreo2.json"
    (c2 / "choreo2.json").write_text(json.dumps({"records": [{"data_id": 0, "labels": [3]}] * 7}))
    assert ds.DATASETS["choreo2"].count(c2) == 7

    ac = tmp_path / "acorns"
    (ac / "xml" / "Speaker-01").mkdir(parents=True)
    assert "WAV/" in ds.DATASETS["acorns"].check(ac)
    (ac / "WAV" / "Speaker-01").mkdir(parents=True)
    (ac / "WAV" / "Speaker-01" / "u1.wav").write_bytes(_wav_bytes())
    assert ds.DATASETS["acorns"].check(ac) is None and ds.DATASETS["acorns"].count(ac) == 1

    au = tmp_path / "audio"
    au.mkdir()
    (au / "labels.csv").write_text("file,label\nx.wav,a\n")
    assert "lacks column(s) ['speaker']; its header is ['file', 'label'], expected file,labels,speaker" in \
        ds.DATASETS["audio"].check(au)  # 'label', the old spelling of 'labels', is accepted
    (au / "labels.csv").write_text("file,speaker\nx.wav,s\n")
    assert "lacks column(s) ['labels']" in ds.DATASETS["audio"].check(au)
    (au / "labels.csv").write_text("file,speaker,labels,transcription\nx.wav,s,a,\ny.wav,s,b,\n")
    assert ds.DATASETS["audio"].check(au) is None and ds.DATASETS["audio"].count(au) == 2
    im = tmp_path / "images"
    im.mkdir()
    (im / "labels.csv").write_text("file,labels,view\na.png,cup,0\n")
    assert ds.DATASETS["images"].check(im) is None and ds.DATASETS["images"].count(im) == 1
    assert ds.DATASETS["images"].check(tmp_path / "nothing").endswith("is not a folder")


def test_dataset_status(tmp_path, no_env_root):
    _make_msr(tmp_path / "msr-action3d", 2)
    (tmp_path / "coil20").mkdir()
    (tmp_path / "coil20" / "COIL20.mat").write_bytes(b"not a mat file")
    rows = {r["name"]: r for r in ds.dataset_status(tmp_path)}
    assert list(rows) == list(ds.DATASETS)
    keys = {"name", "title", "found", "n", "problem", "obtain", "licence"}
    assert all(keys <= set(r) for r in rows.values())
    assert rows["msr-action3d"]["found"] == tmp_path / "msr-action3d"
    assert rows["msr-action3d"]["n"] == 2 and rows["msr-action3d"]["problem"] is None
    assert rows["coil20"]["found"] is None and rows["coil20"]["n"] is None
    assert str(tmp_path / "coil20") in rows["coil20"]["problem"]
    assert rows["fsdd"]["found"] is None and rows["fsdd"]["problem"] is None
    assert rows["fsdd"]["obtain"].startswith("mmconcepts data fetch fsdd")
    assert rows["fsdd"]["licence"] == "CC BY-SA 4.0"


# --------------------------------------------------------------------------- fetch


def _leftovers(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir()) if root.exists() else []


def test_fetch_fsdd_from_loopback(server, tmp_path, no_env_root):
    served, base = server
    data = _fsdd_archive()
    (served / "v1.0.9.tar.gz").write_bytes(data)
    root = tmp_path / "root"
    out = ds.fetch_dataset("fsdd", root, url=f"{base}/v1.0.9.tar.gz", sha256=_sha256(data), progressbar=True)
    assert out == root / "fsdd"
    assert _leftovers(root) == ["fsdd"]  # no staging folder or download left
    assert ds.find_dataset("fsdd", root) == out
    assert ds.DATASETS["fsdd"].count(out) == len(FSDD_FILES)
    assert sorted(p.name for p in out.glob("*.wav")) == sorted(FSDD_FILES)
    lines = (out / "labels.csv").read_text().splitlines()
    assert lines[0] == "file,labels,speaker,transcription"
    assert "7_nicolas_12.wav,seven,nicolas,seven" in lines and len(lines) == 1 + len(FSDD_FILES)
    assert (out / "upstream-README.md").is_file() and "sha256" in (out / "SOURCE.txt").read_text()
    # The generic audio loader reads the result.
    from mmconcepts.sound.data import load_generic_audio

    corpus = load_generic_audio(out)
    assert len(corpus) == len(FSDD_FILES)
    assert len(ds.DATASETS["fsdd"].load(out)) == len(FSDD_FILES)
    # Present already: returned untouched, nothing downloaded (the served file is gone).
    (served / "v1.0.9.tar.gz").unlink()
    assert ds.fetch_dataset("fsdd", root, url=f"{base}/v1.0.9.tar.gz", sha256=_sha256(data)) == out


def test_fetch_uses_env_root_and_creates_it(server, tmp_path, monkeypatch):
    served, base = server
    data = _fsdd_archive()
    (served / "a.tar.gz").write_bytes(data)
    monkeypatch.setenv(ds.DATA_ROOT_ENV, str(tmp_path / "new" / "root"))
    out = ds.fetch_dataset("fsdd", url=f"{base}/a.tar.gz", sha256="sha256:" + _sha256(data).upper())
    assert out == tmp_path / "new" / "root" / "fsdd" and ds.DATASETS["fsdd"].count(out) == 5


def test_fetch_corrupt_download_leaves_nothing(server, tmp_path, no_env_root):
    served, base = server
    good = _fsdd_archive()
    bad = bytearray(good)
    bad[len(bad) // 2] ^= 0xFF
    (served / "v1.0.9.tar.gz").write_bytes(bytes(bad))
    root = tmp_path / "root"
    with pytest.raises(DataError) as err:
        ds.fetch_dataset("fsdd", root, url=f"{base}/v1.0.9.tar.gz", sha256=_sha256(good))
    msg = str(err.value)
    assert f"expected sha256 {_sha256(good)}" in msg and f"got {_sha256(bytes(bad))}" in msg
    assert "Fix:" in msg
    assert _leftovers(root) == []
    assert ds.find_dataset("fsdd", root) is None


def test_fetch_archive_without_the_layout_leaves_nothing(server, tmp_path, no_env_root):
    served, base = server
    data = _tar_gz({"something/else.txt": b"hello"})
    (served / "x.tar.gz").write_bytes(data)
    root = tmp_path / "root"
    with pytest.raises(DataError, match="no {digit}_{speaker}_{index}.wav"):
        ds.fetch_dataset("fsdd", root, url=f"{base}/x.tar.gz", sha256=_sha256(data))
    assert _leftovers(root) == []


def test_fetch_refuses_unsafe_archive(server, tmp_path, no_env_root):
    served, base = server
    data = _tar_gz({"../evil.wav": b"x", "top/0_a_0.wav": _wav_bytes()})
    (served / "evil.tar.gz").write_bytes(data)
    root = tmp_path / "root"
    with pytest.raises(DataError, match="outside"):
        ds.fetch_dataset("fsdd", root, url=f"{base}/evil.tar.gz", sha256=_sha256(data))
    assert _leftovers(root) == [] and not (tmp_path / "evil.wav").exists()


def test_fetch_other_set_with_user_url_and_hash(server, tmp_path, no_env_root):
    import imageio.v3 as iio

    served, base = server
    members = {}
    for name in ("cup1-000-000.png", "cup1-022-090.png"):
        buf = io.BytesIO()
        iio.imwrite(buf, np.zeros((4, 4, 3), np.uint8), extension=".png")
        members[f"eth80-cropped-close128/cup/cup1/{name}"] = buf.getvalue()
    data = _tar_gz(members)
    (served / "eth80.tgz").write_bytes(data)
    root = tmp_path / "root"
    # Without a hash nothing is fetched, and the message says why and what to give.
    with pytest.raises(DataError, match="--sha256"):
        ds.fetch_dataset("eth80", root, url=f"{base}/eth80.tgz")
    assert _leftovers(root) == []
    out = ds.fetch_dataset("eth80", root, url=f"{base}/eth80.tgz", sha256=_sha256(data))
    assert out == root / "eth80" and ds.DATASETS["eth80"].count(out) == 2


def test_fetch_without_public_download_says_how_to_obtain(tmp_path, no_env_root):
    for name in ("msr-action3d", "coil20", "acorns"):
        with pytest.raises(DataError) as err:
            ds.fetch_dataset(name, tmp_path)
        assert ds.DATASETS[name].obtain in str(err.value)
    assert _leftovers(tmp_path) == []


def test_fetch_needs_a_data_root_and_refuses_to_overwrite(server, tmp_path, no_env_root):
    with pytest.raises(DataError, match=ds.DATA_ROOT_ENV):
        ds.fetch_dataset("fsdd")
    (tmp_path / "fsdd").mkdir()
    (tmp_path / "fsdd" / "mine.txt").write_text("user's file")
    served, base = server
    data = _fsdd_archive()
    (served / "a.tar.gz").write_bytes(data)
    with pytest.raises(DataError, match="move or remove it"):
        ds.fetch_dataset("fsdd", tmp_path, url=f"{base}/a.tar.gz", sha256=_sha256(data))
    assert (tmp_path / "fsdd" / "mine.txt").read_text() == "user's file"
    with pytest.raises(ParameterError, match="64 hexadecimal"):
        ds.fetch_dataset("fsdd", tmp_path / "other", url=f"{base}/a.tar.gz", sha256="abc")


def test_fetch_http_error_is_a_data_error(server, tmp_path, no_env_root):
    _, base = server
    with pytest.raises(DataError, match="Cannot download"):
        ds.fetch_dataset("fsdd", tmp_path / "root", url=f"{base}/missing.tar.gz", sha256="0" * 64)
    assert _leftovers(tmp_path / "root") == []


# --------------------------------------------------------------------------- real data


EXPECTED_COUNTS = {"fsdd": 1500, "msr-action3d": 567, "eth80": 1640, "coil20": 1440}


def test_real_data_root_sets_and_counts():
    if DATA_ROOT is None:
        pytest.skip("no data root (set MMCONCEPTS_DATA_ROOT or put ../shared/data beside the checkout)")
    found = ds.find_datasets(DATA_ROOT, names=list(EXPECTED_COUNTS))
    missing = sorted(set(EXPECTED_COUNTS) - set(found))
    if missing:
        pytest.skip(f"real data set(s) {missing} absent from the data root {DATA_ROOT}")
    counts = {n: ds.DATASETS[n].count(p) for n, p in found.items()}
    assert counts == EXPECTED_COUNTS
    rows = {r["name"]: r for r in ds.dataset_status(DATA_ROOT)}
    assert {n: rows[n]["n"] for n in EXPECTED_COUNTS} == EXPECTED_COUNTS


# --------------------------------------------------------------------------- one definition of each set's file names
def test_the_registry_recognises_a_set_by_its_loader_s_own_file_names(tmp_path, no_env_root):
    """What the registry counts as a recording is what the loader reads: speaker names with digits (FSDD),
    a prefix before MSR's name, upper-case ETH-80 names; names the loader refuses the registry refuses."""
    from mmconcepts.motion.data import load_msr_action3d
    from mmconcepts.sound.data import FSDD_WORDS, load_fsdd
    from mmconcepts.vision.data import load_eth80

    fsdd = tmp_path / "fsdd"
    fsdd.mkdir()
    names = ["3_spk2_0.wav", "4_spk2_1.wav", "5_o_brien_0.wav"]
    for name in names:
        (fsdd / name).write_bytes(_wav_bytes())
    (fsdd / "notes_3.wav.txt").write_text("not a recording")
    (fsdd / "labels.csv").write_text("file,speaker,labels\n" + "".join(
        f"{n},{n.split('_', 1)[1].rsplit('_', 1)[0]},{FSDD_WORDS[int(n[0])]}\n"
        for n in names))
    info = ds.DATASETS["fsdd"]
    assert info.check(fsdd) is None and info.count(fsdd) == len(names)
    assert len(load_fsdd(fsdd)) == info.count(fsdd)

    msr = tmp_path / "msr"
    _make_msr(msr)
    first = sorted(msr.glob("*.txt"))[0]
    first.rename(msr / ("x" + first.name))  # the loader finds the name anywhere in the file's name
    info = ds.DATASETS["msr-action3d"]
    assert info.check(msr) is None
    assert info.count(msr) == len(load_msr_action3d(msr, on_error="skip").recordings) + \
        len(load_msr_action3d(msr, on_error="skip").skipped)

    eth = tmp_path / "eth"
    _make_eth80(eth, names=("COW1-000-000.png", "cow1-022-090.png", "cow1-22-090.png"))
    info = ds.DATASETS["eth80"]
    assert info.count(eth) == 2 == len(load_eth80(eth, on_error="skip").labels)


def test_the_registry_holds_no_copy_of_the_loaders_file_name_patterns():
    import ast

    tree = ast.parse(Path(ds.__file__).read_text())
    patterns = [n.args[0].value for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, "attr", "") == "compile" and n.args and isinstance(n.args[0], ast.Constant)]
    assert not [p for p in patterns if any(k in p for k in ("skeleton3D", r"\.wav", r"\.png"))]


# --------------------------------------------------------------------------- bounded unpacking


MSR_FILE = "a01_s01_e01_skeleton3D.txt"


def _zip(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return buf.getvalue()


def _serve(server, name: str, data: bytes) -> tuple[str, str]:
    served, base = server
    (served / name).write_bytes(data)
    return f"{base}/{name}", _sha256(data)


def test_fetch_refuses_a_zip_bomb_before_reading_any_member(server, tmp_path, no_env_root, monkeypatch):
    data = _zip({f"top/{MSR_FILE}": b"\0" * 5_000_000})
    assert len(data) < 20_000  # a small archive declaring 5 MB
    url, sha = _serve(server, "bomb.zip", data)
    opened = []
    real_open = zipfile.ZipFile.open
    monkeypatch.setattr(zipfile.ZipFile, "open", lambda self, *a, **k: opened.append(a) or real_open(self, *a, **k))
    root = tmp_path / "root"
    with pytest.raises(DataError) as err:
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_unpacked_bytes=1_000_000)
    msg = str(err.value)
    assert "5,000,000 bytes" in msg and "1,000,000" in msg and "max_unpacked_bytes" in msg and "--max-size" in msg
    assert opened == []  # refused from the declared sizes: no member was read, nothing written
    assert _leftovers(root) == []
    # The same archive under a bound it fits in unpacks.
    out = ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_unpacked_bytes=5_000_000)
    assert (out / MSR_FILE).stat().st_size == 5_000_000


def test_fetch_refuses_too_many_files(server, tmp_path, no_env_root):
    data = _tar_gz({f"top/a01_s01_e{i:02d}_skeleton3D.txt": b"1 2 3 4\n" for i in range(30)})
    url, sha = _serve(server, "many.tar.gz", data)
    root = tmp_path / "root"
    with pytest.raises(DataError) as err:
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_files=10)
    msg = str(err.value)
    assert "more than 10 entries" in msg and "max_files" in msg and "--max-files" in msg
    assert _leftovers(root) == []
    out = ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_files=30)  # no folder entry in the archive
    assert ds.DATASETS["msr-action3d"].count(out) == 30


def test_a_member_declaring_more_than_the_default_bound_is_refused_from_its_header(tmp_path):
    """A 2 kB tar whose one member declares 20 GB (its data absent): refused by the default bound
    from the header alone, before the missing data is noticed."""
    info = tarfile.TarInfo(f"top/{MSR_FILE}")
    info.size = 20 * 10**9
    archive = tmp_path / "huge.tar"
    archive.write_bytes(info.tobuf(format=tarfile.GNU_FORMAT) + b"\0" * 1024)
    dest = tmp_path / "dest"
    with pytest.raises(DataError) as err:
        ds._safe_extract(archive, dest, ds._Bounds(ds._MAX_UNPACKED_BYTES, ds._MAX_FILES))
    assert "20,000,000,000 bytes" in str(err.value) and f"{ds._MAX_UNPACKED_BYTES:,}" in str(err.value)
    assert not dest.exists() or not any(dest.iterdir())


def test_the_set_s_own_bounds_apply_and_an_option_raises_them(server, tmp_path, no_env_root, monkeypatch):
    import dataclasses
    from types import MappingProxyType

    fsdd = ds.DATASETS["fsdd"]
    assert fsdd.max_files is not None and fsdd.max_unpacked_bytes is not None
    small = dataclasses.replace(fsdd, max_files=4)
    monkeypatch.setattr(ds, "DATASETS", MappingProxyType({**ds.DATASETS, "fsdd": small}))
    data = _fsdd_archive()  # 7 files (no folder entry)
    url, sha = _serve(server, "v1.0.9.tar.gz", data)
    root = tmp_path / "root"
    with pytest.raises(DataError, match="more than 4 entries.*'fsdd'"):
        ds.fetch_dataset("fsdd", root, url=url, sha256=sha)
    assert _leftovers(root) == []
    out = ds.fetch_dataset("fsdd", root, url=url, sha256=sha, max_files=7)
    assert ds.DATASETS["fsdd"].count(out) == len(FSDD_FILES)


def test_the_registry_bounds_hold_the_real_sets_with_room_to_spare():
    """FSDD and ETH-80 declare bounds well above what their real copies hold (a copy of 1500 of FSDD's
    2500 recordings and of 1640 of ETH-80's 3280 images at 96 px: the full sets need under twice the files
    and, at 128 px, under four times the bytes)."""
    for name in ("fsdd", "eth80"):
        info = ds.DATASETS[name]
        assert 0 < info.max_files <= ds._MAX_FILES and 0 < info.max_unpacked_bytes <= ds._MAX_UNPACKED_BYTES
    if DATA_ROOT is None:
        pytest.skip("no data root (set MMCONCEPTS_DATA_ROOT or put ../shared/data beside the checkout)")
    found = ds.find_datasets(DATA_ROOT, names=["fsdd", "eth80"])
    if len(found) < 2:
        pytest.skip(f"fsdd or eth80 absent from the data root {DATA_ROOT}")
    for name, path in found.items():
        files = [p for p in path.rglob("*") if p.is_file()]
        n_bytes = sum(p.stat().st_size for p in files)
        info = ds.DATASETS[name]
        assert 2 * 2 * len(files) <= info.max_files, name
        assert 2 * 4 * n_bytes <= info.max_unpacked_bytes, name


def test_a_member_holding_more_than_it_declares_is_stopped_while_writing(tmp_path, monkeypatch):
    """Declared sizes are checked first; a member whose data runs past its declared size (a lying
    header, a decoder bug) is stopped at that size, not written to the end."""
    archive = tmp_path / "a.tar"
    archive.write_bytes(_tar_gz({"top/x.bin": b"0123456789"}))
    monkeypatch.setattr(tarfile.TarFile, "extractfile", lambda self, member: io.BytesIO(b"\1" * 3_000_000))
    dest = tmp_path / "dest"
    with pytest.raises(DataError, match="more than the 10 bytes it declares"):
        ds._safe_extract(archive, dest, ds._Bounds(10**6, 10))
    written = dest / "top" / "x.bin"
    assert not written.exists() or written.stat().st_size <= 10


def test_fetch_checks_free_space_before_downloading_and_before_unpacking(server, tmp_path, no_env_root, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    data = _zip({f"top/{MSR_FILE}": b"\0" * 3_000_000})
    url, sha = _serve(server, "a.zip", data)
    root = tmp_path / "root"
    free = {"bytes": 1000}
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**12, 0, free["bytes"]))
    with pytest.raises(DataError) as err:  # the download (its Content-Length) does not fit
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha)
    assert f"{len(data):,} bytes" in str(err.value) and "1,000 bytes free" in str(err.value)
    assert _leftovers(root) == []
    free["bytes"] = ds._FREE_MARGIN + 1_000_000  # the download fits, its 3 MB of content does not
    with pytest.raises(DataError) as err:
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha)
    assert "3,000,000 bytes" in str(err.value) and "free" in str(err.value)
    assert _leftovers(root) == []
    free["bytes"] = ds._FREE_MARGIN + 4_000_000 + 8192
    assert ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha) == root / "msr-action3d"


def test_a_write_error_while_unpacking_is_a_one_line_cli_error_naming_the_file(server, tmp_path, no_env_root,
                                                                             monkeypatch, capsys):
    """A real write error from the kernel (a file size limit: EFBIG, as a full disk gives ENOSPC):
    `data fetch` prints one line naming the file and exits 1; nothing is left behind."""
    import resource
    import signal

    from mmconcepts.cli import main

    url, sha = _serve(server, "a.zip", _zip({f"top/{MSR_FILE}": b"1 2 3 4\n" * 400_000}))  # 3.2 MB, 3 kB zipped
    root = tmp_path / "root"
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, hard))
    try:
        rc = main(["data", "fetch", "msr-action3d", "--data-root", str(root), "--url", url, "--sha256", sha, "-q"])
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old)
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith("error: ")
    assert f"Cannot write {root}" in err and MSR_FILE in err and "File too large" in err and "corrupt" not in err
    assert _leftovers(root) == []


def test_a_folder_that_cannot_be_written_is_a_data_error_naming_it(server, tmp_path, no_env_root, monkeypatch):
    import errno
    import tempfile

    url, sha = _serve(server, "a.zip", _zip({f"top/{MSR_FILE}": b"1 2 3 4\n"}))

    def refuse(*args, dir=None, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(dir))

    monkeypatch.setattr(tempfile, "mkdtemp", refuse)
    root = tmp_path / "root"
    with pytest.raises(DataError) as err:
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha)
    assert str(root) in str(err.value) and "Permission denied" in str(err.value) and "--data-root" in str(err.value)


def test_a_disk_full_while_downloading_is_a_data_error_naming_the_file(server, tmp_path, no_env_root, monkeypatch):
    import errno

    url, sha = _serve(server, "a.zip", _zip({f"top/{MSR_FILE}": b"1 2 3 4\n"}))

    class Full(io.BytesIO):
        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

    real_open = open
    def full_open(file, mode="r", *args, **kwargs):
        return Full() if "w" in mode else real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(ds, "open", full_open, raising=False)
    root = tmp_path / "root"
    with pytest.raises(DataError, match="No space left on device") as err:
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha)
    assert str(root) in str(err.value)
    assert _leftovers(root) == []


def test_a_download_larger_than_any_archive_within_the_bounds_is_refused(server, tmp_path, no_env_root, monkeypatch):
    data = np.random.default_rng(0).bytes(2_000_000)  # more than 1000 bytes in 2 entries and the archive's 1 MiB
    url, sha = _serve(server, "big.bin", data)
    root = tmp_path / "root"
    with pytest.raises(DataError, match="2,000,000 bytes"):  # from its Content-Length, before downloading
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_unpacked_bytes=1000, max_files=2)
    assert _leftovers(root) == []
    monkeypatch.setattr(ds, "_content_length", lambda url: None)  # a server that does not say: stopped midway
    with pytest.raises(DataError, match="larger than"):
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha, max_unpacked_bytes=1000, max_files=2)
    assert _leftovers(root) == []


def test_a_corrupt_member_is_a_data_error(server, tmp_path, no_env_root):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        zf.writestr(f"top/{MSR_FILE}", b"1 2 3 4\n" * 100)
    data = bytearray(buf.getvalue())
    data[data.index(b"1 2 3 4\n") + 3] ^= 0xFF  # its CRC no longer matches (the sha256 is of the damaged file)
    url, sha = _serve(server, "bad.zip", bytes(data))
    root = tmp_path / "root"
    with pytest.raises(DataError, match=f"corrupt.*{MSR_FILE}"):
        ds.fetch_dataset("msr-action3d", root, url=url, sha256=sha)
    assert _leftovers(root) == []


@pytest.mark.parametrize("kw", [dict(max_unpacked_bytes=0), dict(max_unpacked_bytes=-5), dict(max_files=0),
                                dict(max_files=1.5), dict(max_unpacked_bytes="1GB"), dict(max_files=True)])
def test_bounds_must_be_positive_ints(tmp_path, no_env_root, kw):
    with pytest.raises(ParameterError, match=f"fetch_dataset: {next(iter(kw))} must be an int >= 1"):
        ds.fetch_dataset("fsdd", tmp_path, **kw)
    assert _leftovers(tmp_path) == []


def test_cli_data_fetch_bounds_options(server, tmp_path, no_env_root, capsys):
    from mmconcepts.cli import main

    url, sha = _serve(server, "bomb.zip", _zip({f"top/{MSR_FILE}": b"\0" * 5_000_000}))
    root = tmp_path / "root"
    args = ["data", "fetch", "msr-action3d", "--data-root", str(root), "--url", url, "--sha256", sha, "-q"]
    assert main([*args, "--max-size", "1MB"]) == 1
    err = capsys.readouterr().err
    assert "more than 1,000,000 bytes" in err and "--max-size" in err and err.count("\n") == 1
    assert main([*args, "--max-size", "4.9MB"]) == 1 and "4,900,000" in capsys.readouterr().err
    assert main([*args, "--max-files", "1", "--max-size", "5MB"]) == 0
    assert (root / "msr-action3d" / MSR_FILE).stat().st_size == 5_000_000


# --------------------------------------------------------------------------- fuzz: archives against bounds


def _archive_bytes(fmt: str, members: list[tuple[str, bytes | None]]) -> bytes:
    """``members`` (name, content; None: a folder; b"->target": a symbolic link) as a zip, tar or tar.gz."""
    buf = io.BytesIO()
    if fmt == "zip":
        with warnings.catch_warnings(), zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            warnings.simplefilter("ignore")  # duplicate names are meant
            for name, data in members:
                zf.writestr(name.rstrip("/") + "/" if data is None else name, b"" if data is None else data)
        return buf.getvalue()
    with tarfile.open(fileobj=buf, mode="w") as tf:
        for name, data in members:
            info = tarfile.TarInfo(name)
            if data is None:
                info.type = tarfile.DIRTYPE
                tf.addfile(info)
            elif data.startswith(b"->"):
                info.type, info.linkname = tarfile.SYMTYPE, data[2:].decode()
                tf.addfile(info)
            else:
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))
    return gzip.compress(buf.getvalue(), mtime=0) if fmt == "tar.gz" else buf.getvalue()


@st.composite
def _bounded_fetches(draw):
    """An archive of random entries (MSR skeleton files, other files, folders, now and then a hostile name,
    a link, a file where a folder goes), bounds around or at random from what it holds, now and then
    damaged bytes or a write that fails."""
    members: list[tuple[str, bytes | None]] = [("top/a01_s01_e00_skeleton3D.txt", b"1 2 3 4\n")]
    for i in range(draw(st.integers(0, 10))):
        kind = draw(st.sampled_from(["msr"] * 6 + ["other", "other", "dir", "nested", "dup"]))
        size = draw(st.sampled_from([0, 1, 100, 5_000]) | st.integers(0, 120_000))
        data = (draw(st.sampled_from([b"\0", b"1 2 3 4\n", b"\xff\x17"])) * size)[:size]
        if kind == "msr":
            members.append((f"top/a01_s01_e{i + 1:02d}_skeleton3D.txt", data))
        elif kind == "other":
            members.append((f"top/notes{i}.txt", data))
        elif kind == "dir":
            members.append((f"top/sub{i}", None))
        elif kind == "nested":
            members.append((f"top/sub/deeper{i}/x.bin", data))
        else:
            members.append((members[-1][0], data))
    bad = draw(st.sampled_from([None] * 6 + ["../escape.txt", "top/../../escape.txt", "/abs.txt", "link",
                                             "clash"]))
    if bad is not None:
        entry = {"link": ("top/link", b"->/etc/passwd"), "clash": ("top/sub", b"x")}.get(bad, (bad, b"x"))
        members.insert(draw(st.integers(0, len(members))), entry)  # clash: a file where a folder goes, or after it
    fmt = draw(st.sampled_from(["zip", "tar", "tar.gz"]))
    if fmt == "zip":
        members = [(n, d) for n, d in members if d is None or not d.startswith(b"->")]
    raw = _archive_bytes(fmt, members)
    damage = draw(st.sampled_from([None] * 8 + ["truncate", "flip"]))
    if damage == "truncate":
        raw = raw[: draw(st.integers(0, max(len(raw) - 1, 0)))]
    elif damage == "flip":
        i = draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1:]
    n, content = len(members), sum(len(d) for _, d in members if d is not None)
    relation = draw(st.sampled_from(["fits"] * 3 + ["too many", "too large", "random"]))
    if relation == "random":
        bounds = dict(max_unpacked_bytes=draw(st.integers(1, 400_000)), max_files=draw(st.integers(1, 12)))
    else:
        bounds = dict(max_unpacked_bytes=max(content + draw(st.integers(0, 50_000)), 1),
                      max_files=n + draw(st.integers(0, 5)))
        if relation == "too many":
            bounds["max_files"] = n - 1 if n > 1 else bounds["max_files"]
        elif relation == "too large" and content > 0:
            bounds["max_unpacked_bytes"] = max(content - draw(st.integers(1, content)), 1)
    failing_write = draw(st.sampled_from([None] * 8 + [0, 1, 3, 10]))
    errno_ = draw(st.sampled_from(["ENOSPC", "EACCES", "EROFS", "EIO", "EDQUOT"]))
    return fmt, members, raw, damage, bounds, failing_write, errno_


@pytest.mark.fuzz
@fuzz_settings(60, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                          HealthCheck.data_too_large])
@given(case=_bounded_fetches())
def test_fuzz_fetch_within_bounds(server, no_env_root, case):
    """A fetch of any archive, under any bounds, with or without a failing write, is a one-line DataError
    with nothing left behind, or the set within the bounds with every file as the archive holds it."""
    import errno
    import tempfile

    fmt, members, raw, damage, bounds, failing_write, errno_name = case
    served, base = server
    name = f"{_sha256(raw)[:16]}.{fmt}"
    (served / name).write_bytes(raw)
    writes = {"n": 0}
    real_open = open

    class Failing(io.BufferedWriter):
        def write(self, data):
            writes["n"] += 1
            if writes["n"] > failing_write:
                code = getattr(errno, errno_name)
                raise OSError(code, os.strerror(code))
            return super().write(data)

    def faulty_open(file, mode="r", *args, **kwargs):
        if "w" in mode and failing_write is not None:
            return Failing(real_open(file, mode.replace("b", "") + "b", buffering=0))
        return real_open(file, mode, *args, **kwargs)

    import pooch

    log = pooch.get_logger()
    level = log.level
    log.setLevel(logging.WARNING)  # not a line per download
    with tempfile.TemporaryDirectory() as tmp, pytest.MonkeyPatch.context() as mp:
        root = Path(tmp) / "root"
        mp.setattr(ds, "open", faulty_open, raising=False)

        def call():
            try:
                return ds.fetch_dataset("msr-action3d", root, url=f"{base}/{name}", sha256=_sha256(raw), **bounds)
            except DataError as exc:
                assert "\n" not in str(exc), f"a message of several lines: {exc}"
                assert _leftovers(root) == [], f"left behind after {exc}: {_leftovers(root)}"
                raise

        def check(out):
            """Within the bounds; and, from an undamaged archive, every file as the archive holds it."""
            files = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*")
                     if p.is_file() and p.name != "SOURCE.txt"}
            within = sum(map(len, files.values())) <= bounds["max_unpacked_bytes"] and len(files) <= bounds["max_files"]
            if damage is not None:  # a damaged archive may still be a sound one (cut at a member's end)
                return within and _leftovers(root) == ["msr-action3d"]
            expected = {n[4:]: d for n, d in members if d is not None and n.startswith("top/") and ".." not in n}
            declared = sum(len(d) for _, d in members if d is not None)
            return (within and _leftovers(root) == ["msr-action3d"] and files == expected
                    and declared <= bounds["max_unpacked_bytes"] and len(members) <= bounds["max_files"])

        try:
            assert_typed_or_good("datasets.fetch_dataset(archive, bounds)", call, check=check)
        finally:
            log.setLevel(level)
