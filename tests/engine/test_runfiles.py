"""A run's files: an edited record is not reused, a full or unwritable folder is refused before computing, a failed
write keeps what was computed and leaves nothing half-written, two runs of one experiment into one folder compute it
once."""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import multiprocessing
import os
import time
from collections import namedtuple
from pathlib import Path

import pytest

from mmconcepts.errors import MMConceptsError
from mmconcepts.experiments import load_record, run_experiment

_Usage = namedtuple("_Usage", "total used free")


# --------------------------------------------------------------------------- an edited record


def test_an_edited_metric_is_computed_again_with_a_warning_naming_the_file(toy, tmp_path, caplog):
    first = run_experiment("toy-mean", output=tmp_path, progress=False)
    path = tmp_path / "toy-mean.json"
    stored = json.loads(path.read_text())
    stored["metrics"]["mean"] = 1.5  # edited into "the sample mean exceeds one": holds
    stored["claims"][1]["verdict"], stored["claims"][1]["holds"] = "holds", True
    path.write_text(json.dumps(stored, indent=2))
    with caplog.at_level(logging.INFO, logger="mmconcepts"):
        again = run_experiment("toy-mean", output=tmp_path, progress=False)
    assert toy.CALLS == [0, 0]  # computed again, not reused
    assert str(path) in caplog.text and "digest" in caplog.text
    assert any(r.levelno == logging.WARNING and str(path) in r.getMessage() for r in caplog.records)
    assert again.metrics["mean"] == first.metrics["mean"] and again.claims[1].verdict == "fails"
    assert load_record(path).digest_ok is True
    run_experiment("toy-mean", output=tmp_path, progress=False)
    assert toy.CALLS == [0, 0]  # the record written again is up to date


def test_a_record_of_an_older_schema_is_computed_again_once(toy, tmp_path, caplog):
    run_experiment("toy-mean", output=tmp_path, progress=False)
    path = tmp_path / "toy-mean.json"
    stored = json.loads(path.read_text())
    stored["schema_version"] = 4
    del stored["digest"]
    path.write_text(json.dumps(stored, indent=2))
    with caplog.at_level(logging.INFO, logger="mmconcepts"):
        run_experiment("toy-mean", output=tmp_path, progress=False)
    assert toy.CALLS == [0, 0]
    assert f"{path}: written by an older version of the record schema (4)" in caplog.text
    run_experiment("toy-mean", output=tmp_path, progress=False)
    assert toy.CALLS == [0, 0]


# --------------------------------------------------------------------------- a folder without room


def _full_disk_under(folder: Path, suffix: str = ""):
    """``mmconcepts._io.atomic_path`` on a disk that is full under ``folder`` (for the files whose name has
    ``suffix``): the temporary file (and its folder) made, then no space left to write it."""
    from mmconcepts import _io

    real = _io.atomic_path

    @contextlib.contextmanager
    def atomic_path(path, **kwargs):
        with real(path, **kwargs) as tmp:
            if Path(folder) in Path(path).parents and suffix in Path(path).name:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
            yield tmp

    return atomic_path


@pytest.mark.parametrize("full_at", [".json", ".png"])  # the disk is full when the record, or a figure, is written
def test_a_full_disk_is_one_error_keeps_the_result_and_leaves_nothing_half_written(toy, tmp_path, monkeypatch,
                                                                                  full_at):
    from mmconcepts import _io

    out = tmp_path / "out"
    out.mkdir()
    (out / "other.txt").write_text("kept")
    with monkeypatch.context() as mp:
        mp.setattr(_io, "atomic_path", _full_disk_under(out, full_at))
        with pytest.raises(MMConceptsError) as info:
            run_experiment("toy-mean", output=out, progress=False)
    message = str(info.value)
    assert "\n" not in message and "toy-mean" in message and os.strerror(errno.ENOSPC) in message
    assert "will not be computed again" in message
    assert toy.CALLS == [0]
    # nothing half-written: no record, no (empty) figure folder, no temporary file
    assert sorted(p.name for p in out.iterdir() if p.name != ".locks") == ["other.txt"]
    record = run_experiment("toy-mean", output=out, progress=False)  # room again
    assert toy.CALLS == [0]  # not computed again: the kept result is written
    assert record.status == "ok" and load_record(out / "toy-mean.json").digest_ok is True
    assert (out / "toy-mean" / "hist.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert record.metrics == run_experiment("toy-mean", output=tmp_path / "fresh", progress=False).metrics
    run_experiment("toy-mean", output=out, progress=False)
    assert toy.CALLS == [0, 0]  # the kept result was used once (the second call: the fresh folder)


def test_a_full_disk_with_nowhere_to_keep_the_result_prints_its_metrics(toy, tmp_path, monkeypatch, caplog):
    from mmconcepts import _codec, _io

    with monkeypatch.context() as mp:
        mp.setattr(_io, "atomic_path", _full_disk_under(tmp_path))  # the cache is on the same full disk
        mp.setattr(_codec, "atomic_path", _full_disk_under(tmp_path))
        with pytest.raises(MMConceptsError) as info, caplog.at_level(logging.WARNING, logger="mmconcepts"):
            run_experiment("toy-mean", output=tmp_path / "out", progress=False)
    assert "\n" not in str(info.value) and "could not be kept" in str(info.value)
    assert "mean = 0." in caplog.text and "1.chunk_mean = " in caplog.text


def test_a_nearly_full_output_folder_is_refused_before_computing(toy, tmp_path, monkeypatch):
    import shutil

    monkeypatch.setattr(shutil, "disk_usage", lambda path: _Usage(10**12, 10**12 - 2**20, 2**20))  # 1 MiB free
    with pytest.raises(MMConceptsError, match=r"free space.*1,048,576 bytes free") as info:
        run_experiment("toy-mean", output=tmp_path / "out", progress=False)
    assert "\n" not in str(info.value) and "--output" in str(info.value)
    assert toy.CALLS == [] and not (tmp_path / "out").exists()


def test_an_unwritable_output_folder_is_refused_before_computing(toy, tmp_path):
    (tmp_path / "file").write_text("x")
    for output in (tmp_path / "file", "/proc/self/no-results"):
        with pytest.raises(MMConceptsError, match="output folder"):
            run_experiment("toy-mean", output=output, progress=False)
    assert toy.CALLS == []


# --------------------------------------------------------------------------- two runs into one folder


def _count_and_wait(config, ctx):
    from mmconcepts.experiments import Result

    with open(os.environ["RUNFILES_COUNT"], "a") as fh:
        fh.write(f"{os.getpid()}\n")
    time.sleep(3.0)
    return Result(metrics={"value": 1.0})


def _run_counting(output: str, answer: str) -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from _toy_experiment import make_experiment

    record = run_experiment(make_experiment("toy-count", _count_and_wait), output=output, progress=False)
    Path(answer).write_text(record.started_at)


@pytest.mark.slow
def test_two_runs_of_one_experiment_into_one_folder_compute_it_once(tmp_path, monkeypatch):
    count = tmp_path / "count.txt"
    monkeypatch.setenv("RUNFILES_COUNT", str(count))
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    context = multiprocessing.get_context("spawn")
    runs = [context.Process(target=_run_counting, args=(str(tmp_path / "out"), str(tmp_path / f"answer-{i}")))
            for i in range(2)]
    for run in runs:
        run.start()
    for run in runs:
        run.join(120)
    assert [run.exitcode for run in runs] == [0, 0]
    assert len(count.read_text().split()) == 1  # computed once
    started = [(tmp_path / f"answer-{i}").read_text() for i in range(2)]
    assert started[0] == started[1]  # the second returned the first's record
    assert load_record(tmp_path / "out" / "toy-count.json").status == "ok"
