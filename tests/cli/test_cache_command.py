"""The cache folder and `mmconcepts cache list / clear`."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmconcepts._paths import data_home
from mmconcepts.cache import cache_entries, clear_cache, parse_age
from mmconcepts.cli import main
from mmconcepts.errors import ParameterError

NOW = 1_800_000_000.0
DAY = 86400.0


def _write(path: Path, size: int, age_days: float) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"x" * size)
    os.utime(path, (NOW - age_days * DAY, NOW - age_days * DAY))
    return path


@pytest.fixture
def cache(tmp_path):
    home = tmp_path / "cache"
    _write(home / "ch3-folds" / "a" / "output.pkl", 100, 10)
    _write(home / "ch3-folds" / "b" / "output.pkl", 50, 1)
    _write(home / "ch5-mfcc" / "x.npz", 7, 3)
    _write(home / "notes.txt", 3, 0.5)
    return home


def _walk_totals(path: Path) -> tuple[int, int]:  # the outside answer: every regular file below, by os.walk
    sizes = [os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs]
    return len(sizes), sum(sizes)


def test_the_folder_is_mmconcepts_data_then_xdg_then_home(monkeypatch, tmp_path):
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "a"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert data_home(create=False) == tmp_path / "a"
    monkeypatch.delenv("MMCONCEPTS_DATA")
    assert data_home(create=False) == tmp_path / "xdg" / "mmconcepts"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/xdg")  # the XDG specification ignores relative paths
    assert data_home(create=False) == Path.home() / ".cache" / "mmconcepts"
    assert data_home(tmp_path / "given", create=False) == tmp_path / "given"


def test_entries_count_every_file_and_byte(cache):
    entries = {e.name: e for e in cache_entries(cache)}
    assert sorted(entries) == ["ch3-folds", "ch5-mfcc", "notes.txt"]
    for name, e in entries.items():
        assert (e.n_files, e.n_bytes) == (_walk_totals(cache / name) if (cache / name).is_dir()
                                          else (1, (cache / name).stat().st_size))
    assert entries["ch3-folds"].newest == pytest.approx(NOW - 1 * DAY)
    assert cache_entries(cache / "missing") == []


def test_clear_older_than_removes_exactly_the_old_files(cache):
    n, size = clear_cache(cache, older_than=2 * DAY, now=NOW)
    assert (n, size) == (2, 107)  # the 10-day and the 3-day files
    assert not (cache / "ch3-folds" / "a").exists()  # emptied folders go too
    assert (cache / "ch3-folds" / "b" / "output.pkl").exists() and (cache / "notes.txt").exists()
    assert not (cache / "ch5-mfcc").exists()
    assert _walk_totals(cache) == (2, 53)


def test_clear_by_name_and_everything(cache):
    assert clear_cache(cache, names=["ch5-mfcc"]) == (1, 7)
    assert sorted(p.name for p in cache.iterdir()) == ["ch3-folds", "notes.txt"]
    with pytest.raises(ParameterError, match="holds no 'ch9'.*cache list"):
        clear_cache(cache, names=["ch9"])
    assert clear_cache(cache) == (3, 153)
    assert list(cache.iterdir()) == []
    assert clear_cache(cache / "missing") == (0, 0)


def test_clear_never_follows_links(tmp_path, cache):
    outside = _write(tmp_path / "precious" / "data.wav", 11, 30)
    (cache / "link-to-data").symlink_to(outside.parent)
    (cache / "ch5-mfcc" / "file-link").symlink_to(outside)
    clear_cache(cache, older_than=DAY, now=NOW)
    clear_cache(cache)
    assert outside.read_bytes() == b"x" * 11


@pytest.mark.parametrize(("text", "seconds"), [("30m", 1800), ("12h", 43200), ("7d", 7 * DAY), ("2w", 14 * DAY),
                                               ("1d12h", 1.5 * DAY), ("0.5h", 1800), ("90s", 90)])
def test_parse_age(text, seconds):
    assert parse_age(text) == seconds


@given(st.text(max_size=8))
def test_parse_age_accepts_only_numbers_with_units(text):
    try:
        seconds = parse_age(text)
    except ParameterError as exc:
        assert "units s, m, h, d or w" in str(exc)
    else:
        assert seconds >= 0 and text.strip()
        assert all(c.isdigit() or c in ".smhdw " for c in text)


def test_the_command(cache, capsys, monkeypatch):
    assert main(["cache", "list", "--cache-dir", str(cache)]) == 0
    out = capsys.readouterr().out
    assert str(cache) in out and "ch3-folds" in out and "total" in out
    assert main(["cache", "clear", "--cache-dir", str(cache), "--older-than", "fortnight"]) == 2
    assert "units s, m, h, d or w" in capsys.readouterr().err
    assert main(["cache", "clear", "--cache-dir", str(cache), "nope"]) == 2
    old = time.time() - 10 * DAY
    for p in cache.rglob("*"):
        if p.is_file():
            os.utime(p, (old, old))
    _write(cache / "fresh" / "f", 5, 0)
    os.utime(cache / "fresh" / "f")  # now
    assert main(["cache", "clear", "--cache-dir", str(cache), "--older-than", "1d"]) == 0
    assert "removed 4 files" in capsys.readouterr().out
    assert [p.name for p in cache.iterdir()] == ["fresh"]
    monkeypatch.setenv("MMCONCEPTS_DATA", str(cache))
    assert main(["cache", "clear"]) == 0
    assert not any(cache.iterdir())


def test_the_lock_files_of_generated_sets_are_not_an_entry(cache):
    """The top-level ``.locks`` folder (lock files of corpora being generated) is not listed."""
    from mmconcepts.cache import LOCKS

    _write(cache / LOCKS / "caregiver-synth-v1-s4-n250-seed0.lock", 0, 0)
    assert sorted(e.name for e in cache_entries(cache)) == ["ch3-folds", "ch5-mfcc", "notes.txt"]
