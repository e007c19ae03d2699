"""The package's cache facility (mmconcepts._store): generated folders, their keys and locks, and entries.

What is pinned: a generated folder is built once and reused while its manifest, its code and its
files are unchanged, and built again when any of them changes; an interrupted build leaves neither
the folder nor a temporary one, and the next call builds it; a build killed mid-way leaves a
temporary folder that the next build removes; two processes asking at once build it once; every
lock lives in ``<home>/.locks``; an entry never unpickles, and an entry of the previous format is
still read.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from _planted import Plant, planted_pickle

from mmconcepts import _store
from mmconcepts._codec import HEADER, MARK, CorruptFile
from mmconcepts._store import (
    ENTRY_FORMAT,
    LOCKS,
    MANIFEST,
    MISSING,
    cache_key,
    generated_folder,
    read_entry,
    store_lock,
    versioned,
    write_entry,
)
from mmconcepts.cache import cache_entries
from mmconcepts.errors import ParameterError


class _Builder:
    """A build that writes two files and counts its calls; it fails after the first file when ``fail`` is set."""

    def __init__(self, fail: BaseException | None = None, content: str = "a"):
        self.calls = 0
        self.fail = fail
        self.content = content

    def __call__(self, folder: Path) -> None:
        self.calls += 1
        (folder / "sub").mkdir()
        (folder / "sub" / "x.txt").write_text(self.content)
        if self.fail is not None:
            raise self.fail
        (folder / "y.bin").write_bytes(b"\0" * 10)


def _siblings(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.parent.iterdir())


def test_a_folder_is_built_once_and_reused(tmp_path):
    build = _Builder()
    root = tmp_path / "set"
    assert generated_folder(root, {"n": 3}, build) == root
    assert generated_folder(root, {"n": 3}, build) == root
    assert build.calls == 1
    assert (root / "sub" / "x.txt").read_text() == "a" and (root / "y.bin").stat().st_size == 10
    manifest = json.loads((root / MANIFEST).read_text())
    assert manifest["manifest"] == {"n": 3} and (manifest["files"], manifest["bytes"]) == (2, 11)
    assert manifest["scheme"] == _store.KEY_SCHEME and len(manifest["code"]) == 16  # the code fingerprint
    assert _siblings(root) == [LOCKS, "set"]
    assert (tmp_path / LOCKS / "set.lock").is_file()
    assert [e.name for e in cache_entries(tmp_path)] == ["set"]  # the lock folder is no entry


def test_a_changed_manifest_code_or_content_rebuilds(tmp_path, monkeypatch):
    build = _Builder()
    root = tmp_path / "set"
    generated_folder(root, {"n": 3}, build)
    generated_folder(root, {"n": 4}, build)  # another manifest
    assert build.calls == 2 and json.loads((root / MANIFEST).read_text())["manifest"] == {"n": 4}
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 1))  # another code
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 1))
    assert build.calls == 3
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 2))
    assert build.calls == 4
    (root / "y.bin").unlink()  # a file gone (e.g. cleared by age): incomplete
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 2))
    assert build.calls == 5 and (root / "y.bin").is_file()
    (root / "y.bin").write_bytes(b"\0" * 3)  # a file cut short
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 2))
    assert build.calls == 6
    generated_folder(root, {"n": 4}, build, code=versioned("gen", 2), force=True)
    assert build.calls == 7
    # the default code is the package's fingerprint: another fingerprint rebuilds
    generated_folder(root, {"n": 4}, build)
    monkeypatch.setattr(_store, "code_fingerprint", lambda: "another code")
    generated_folder(root, {"n": 4}, build)
    assert build.calls == 9
    assert _siblings(root) == [LOCKS, "set"]  # no old copy, no temporary folder left


@pytest.mark.mutation
@pytest.mark.parametrize("error", [RuntimeError("disk full"), KeyboardInterrupt()])
def test_an_interrupted_build_leaves_nothing_and_the_next_call_builds(tmp_path, error):
    root = tmp_path / "set"
    with pytest.raises(type(error)):
        generated_folder(root, {"n": 3}, _Builder(fail=error))
    assert _siblings(root) == [LOCKS]  # neither the folder nor its temporary build
    build = _Builder()
    generated_folder(root, {"n": 3}, build)
    assert build.calls == 1 and (root / "y.bin").is_file()
    # a failed rebuild keeps the complete folder as it was
    with pytest.raises(RuntimeError):
        generated_folder(root, {"n": 3}, _Builder(fail=RuntimeError(), content="b"), force=True)
    assert (root / "sub" / "x.txt").read_text() == "a" and _siblings(root) == [LOCKS, "set"]
    generated_folder(root, {"n": 3}, build)
    assert build.calls == 1


def _killed_build(root: str) -> None:
    def build(folder: Path) -> None:
        (folder / "half").write_text("x")
        os._exit(3)  # killed: no exception, no clean-up

    generated_folder(Path(root), {"n": 3}, build)


def test_the_leftover_of_a_killed_build_is_removed_by_the_next(tmp_path):
    import multiprocessing

    root = tmp_path / "set"
    (tmp_path / "set.other").mkdir()  # a sibling whose name starts the same: not a leftover of root
    (tmp_path / ".set.other.abcdefgh.building").mkdir()
    child = multiprocessing.get_context("fork").Process(target=_killed_build, args=(str(root),))
    child.start()
    child.join(60)
    assert child.exitcode == 3
    (left,) = [p for p in tmp_path.iterdir() if p.name.startswith(".set.") and p.name != ".set.other.abcdefgh.building"]
    assert (left / "half").is_file() and not root.exists()
    build = _Builder()
    generated_folder(root, {"n": 3}, build)
    assert build.calls == 1 and not left.exists()
    assert _siblings(root) == [LOCKS, ".set.other.abcdefgh.building", "set", "set.other"]


_BARRIER = None  # set before the worker processes are forked: both calls start together


def _build_in_child(args):
    root, log = args

    def build(folder: Path) -> None:
        (Path(log) / f"{os.getpid()}-{time.monotonic_ns()}").touch()
        time.sleep(0.3)
        (folder / "pid").write_text(str(os.getpid()))

    _BARRIER.wait(timeout=60)  # fails (BrokenBarrierError) unless two processes got here at once
    generated_folder(Path(root), {"n": 3}, build)
    return (Path(root) / "pid").read_text(), os.getpid()


@pytest.mark.mutation
def test_two_processes_asking_at_once_build_once(tmp_path, monkeypatch):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("fork")
    monkeypatch.setitem(globals(), "_BARRIER", ctx.Barrier(2))  # inherited by the forked workers
    log = tmp_path / "log"
    log.mkdir()
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        (a, pa), (b, pb) = pool.map(_build_in_child, [(str(tmp_path / "home" / "set"), str(log))] * 2)
    assert pa != pb and a == b  # two processes, one folder
    assert len(list(log.iterdir())) == 1  # built once
    assert _siblings(tmp_path / "home" / "set") == [LOCKS, "set"]


def test_the_lock_lives_under_the_home_and_mirrors_the_path(tmp_path):
    home = tmp_path / "home"
    generated_folder(home / "a" / "b" / "set", {"n": 1}, _Builder(), home=home)
    assert sorted(p.relative_to(home).as_posix() for p in (home / LOCKS).rglob("*.lock")) == [".locks/a/b/set.lock"]
    with store_lock(home, home / "a" / "entry.npz"):
        assert (home / LOCKS / "a" / "entry.npz.lock").is_file()
    with pytest.raises(ParameterError, match="not inside the cache folder"):
        generated_folder(tmp_path / "elsewhere", {"n": 1}, _Builder(), home=home)
    with pytest.raises(ParameterError, match="JSON"):
        generated_folder(home / "set", {"n": object()}, _Builder())


def test_the_key_follows_the_code_and_the_parts(monkeypatch):
    a = cache_key("f", [1, 2], np.arange(3))
    assert a == cache_key("f", [1, 2], np.arange(3)) and len(a) == 32
    assert a != cache_key("f", [1, 2], np.arange(4)) and a != cache_key("g", [1, 2], np.arange(3))
    assert cache_key("f", code="gen/v1") != cache_key("f", code="gen/v2")
    monkeypatch.setattr(_store, "code_fingerprint", lambda: "another code")
    assert a != cache_key("f", [1, 2], np.arange(3))
    assert versioned("gen", 3) == "gen/v3"


# --------------------------------------------------------------------------- entries


def test_a_planted_pickle_is_never_unpickled(tmp_path):
    marker = tmp_path / "marker"
    planted = planted_pickle(marker)
    entry = tmp_path / "e.npz"
    entry.write_bytes(planted)
    with pytest.raises(CorruptFile):
        read_entry(entry, "k")
    np.save(tmp_path / "e.npy", np.array([Plant(marker)], dtype=object), allow_pickle=True)
    (tmp_path / "e.npy").replace(entry)
    with pytest.raises(CorruptFile):
        read_entry(entry, "k")
    header = json.dumps({"format": ENTRY_FORMAT, "key": "k", "value": {MARK: "array", "entry": "a0"}})
    with open(entry, "wb") as fh:  # an archive of the format whose array is a pickled object
        np.savez(fh, **{HEADER: np.array(header)}, a0=np.array([Plant(marker)], dtype=object))
    with pytest.raises(CorruptFile, match="cannot be read"):
        read_entry(entry, "k")
    assert not marker.exists()
    assert read_entry(tmp_path / "absent.npz", "k") is MISSING


def test_an_entry_of_the_previous_format_is_read(tmp_path):
    """The figure data of older runs: structure bytes in ``__structure__``, one-key nodes."""
    structure = {"format": "mmconcepts-cache/1", "key": "k", "value": {"dict": [
        ["x", {"array": "a0"}], ["t", {"tuple": [1, {"scalar": "a1"}, {"nan": "010000000000f87f"}]}],
        ["l", {"list": [None, "s", float("inf")]}], [MARK, {"dict": []}]]}}
    entry = tmp_path / "old.npz"
    np.savez(entry, __structure__=np.frombuffer(json.dumps(structure).encode("ascii"), np.uint8),
             a0=np.arange(3), a1=np.float32(2.5))
    value = read_entry(entry, "k")
    assert list(value) == ["x", "t", "l", MARK] and value[MARK] == {}
    np.testing.assert_array_equal(value["x"], np.arange(3))
    one, scalar, nan = value["t"]
    assert one == 1 and type(scalar) is np.float32 and scalar == 2.5
    assert nan != nan and np.float64(nan).tobytes().hex() == "010000000000f87f"
    assert value["l"] == [None, "s", float("inf")]
    with pytest.raises(CorruptFile):
        read_entry(entry, "another key")


def test_an_entry_round_trips_and_refuses_what_needs_pickle(tmp_path):
    value = {"a": np.float32(1.5), 3: (np.arange(2), [None, -0.0]), "s": np.array(["x", "y\0"], dtype=object)}
    write_entry(tmp_path / "e.npz", value, "k")
    back = read_entry(tmp_path / "e.npz", "k")
    assert list(back) == ["a", 3, "s"] and type(back["a"]) is np.float32 and type(back[3]) is tuple
    assert str(back[3][1][1]) == "-0.0" and back["s"].tolist() == ["x", "y\0"]
    with pytest.raises(ParameterError, match=r"result\[3\]\[1\]: a set cannot be saved without pickle"):
        write_entry(tmp_path / "f.npz", {3: (1, {2})}, "k")
    assert not (tmp_path / "f.npz").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["e.npz"]
