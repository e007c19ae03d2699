"""Faults of the command line: a run killed with SIGKILL, two runs into one folder.

The runs are real ``mmconcepts`` command lines in subprocesses. Their experiments are small
test experiments written into a temporary folder and put in place of the package's
(``EXPERIMENT_PACKAGES``) by the launcher below: each calls a slow cached function over
``ctx.parallel_cached``, the path the folds of chapters 3 and 6 take, and logs every call it
computes, so that a test can tell what a rerun computed again.
"""

from __future__ import annotations

import html.parser
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc to find the workers")

_EXPERIMENT = '''
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mmconcepts.experiments import Experiment, Result, register
from mmconcepts.engine.config import PresetConfig


@dataclass(frozen=True)
class Config(PresetConfig):
    n_calls: int = 8
    seconds: float = 1.5
    seed: int = 0


def _call(i, seconds, log):
    Path(log, f"{i}-{os.getpid()}-{time.monotonic_ns()}").touch()
    time.sleep(seconds)
    return {"i": i, "square": np.array([float(i) ** 2])}


def compute(config, ctx):
    cached = ctx.memory("fault-test").cache(_call, ignore=["log"])
    calls = [(i, config.seconds, os.environ["FAULT_LOG"]) for i in range(config.n_calls)]
    out = ctx.parallel_cached(cached, calls, desc="calls")
    return Result(metrics={"total": float(sum(o["square"][0] for o in out))})


for _id in ("fault-a", "fault-b"):
    register(Experiment(id=_id, title=f"Test experiment {_id}", thesis_ref="none", config_cls=Config,
                        compute=compute))
'''

# FAULT_SLOW_REPORT=S: the report's files are written S seconds after the records were read
# (a slow disk), so that another run's report lands in between.
_LAUNCHER = """
import os
import sys
import time

import mmconcepts.engine.registry as e

e.EXPERIMENT_PACKAGES = ("_fault_experiment",)
if os.environ.get("FAULT_SLOW_REPORT"):
    import mmconcepts.report as report

    write = report.atomic_write

    def slow_write(*args, **kwargs):
        time.sleep(float(os.environ["FAULT_SLOW_REPORT"]))
        return write(*args, **kwargs)

    report.atomic_write = slow_write
from mmconcepts.cli import main

sys.exit(main(sys.argv[1:]))
"""


def _setup(tmp_path, n_calls=8, seconds=1.5):
    mod = tmp_path / "mod"
    mod.mkdir()
    (mod / "_fault_experiment.py").write_text(
        _EXPERIMENT.replace("n_calls: int = 8", f"n_calls: int = {n_calls}")
        .replace("seconds: float = 1.5", f"seconds: float = {seconds}"))
    log = tmp_path / "log"
    log.mkdir()
    env = dict(os.environ, FAULT_LOG=str(log), MMCONCEPTS_DATA=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(mod), *filter(None, [os.environ.get("PYTHONPATH")])]))
    env.pop("MMCONCEPTS_DATA_ROOT", None)
    return env, log


def _start(env, *args):
    """``mmconcepts ARGS`` in a new session (its own process group), for the test experiments."""
    return subprocess.Popen([sys.executable, "-c", _LAUNCHER, *args], env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _group(pgid):
    """Pids of the live (not zombie) processes of process group ``pgid``."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2:].split()  # state, ppid, pgrp, ...
        if int(fields[2]) == pgid and fields[0] != "Z":
            pids.append(int(stat.parent.name))
    return pids


def _entries(tmp_path):
    """The cache entries written (not the temporary files of entries being written)."""
    return sorted(p for p in (tmp_path / "cache" / "fault-test").rglob("*.npz") if not p.name.startswith("."))


def _computed(log):
    """Indices of the calls computed (logged) so far."""
    return sorted(int(p.name.split("-")[0]) for p in log.iterdir())


@pytest.mark.slow
def test_sigkill_leaves_no_worker_and_the_rerun_keeps_what_was_finished(tmp_path):
    env, log = _setup(tmp_path, n_calls=8, seconds=1.5)
    out = tmp_path / "out"
    args = ("run", "fault-a", "--workers", "2", "-o", str(out), "-q")
    proc = _start(env, *args)
    pgid = proc.pid
    try:
        deadline = time.monotonic() + 120
        while not _entries(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert _entries(tmp_path), f"no call finished: {proc.communicate()}"
        workers = [p for p in _group(pgid) if p != proc.pid]
        assert len(workers) >= 2, "the run has no worker processes to orphan"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        left = _group(pgid)
        deadline = time.monotonic() + 5
        while left and time.monotonic() < deadline:
            time.sleep(0.1)
            left = _group(pgid)
        assert not left, f"processes of the killed run still alive 5 s later: {left}"
    finally:
        try:
            os.killpg(pgid, signal.SIGKILL)  # the test's own process group
        except ProcessLookupError:
            pass
    finished = len(_entries(tmp_path))
    assert 1 <= finished < 8
    assert not list(out.glob("*.json")) or all(json.loads(p.read_text()) for p in out.glob("*.json"))
    for p in log.iterdir():
        p.unlink()
    rerun = subprocess.run([sys.executable, "-c", _LAUNCHER, *args], env=env, capture_output=True, text=True,
                           timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert len(_computed(log)) == 8 - finished  # what was finished is read back, not computed again
    assert len(_entries(tmp_path)) == 8
    record = json.loads((out / "fault-a.json").read_text())
    assert record["status"] == "ok" and record["metrics"]["total"] == float(sum(i * i for i in range(8)))


class _Parser(html.parser.HTMLParser):
    """Checks that tags are balanced (a torn or interleaved file is not)."""

    VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}

    def __init__(self):
        super().__init__()
        self.stack = []

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in self.VOID:
            return
        assert self.stack and self.stack[-1] == tag, f"</{tag}> closes <{self.stack[-1] if self.stack else None}>"
        self.stack.pop()


def _check_folder(out, ids):
    for path in out.rglob("*.json"):
        record = json.loads(path.read_text())  # complete JSON, not torn
        assert record["status"] == "ok", (path, record.get("message"))
    assert {p.stem for p in out.glob("*.json")} == set(ids)
    text = (out / "report.html").read_text()
    parser = _Parser()
    parser.feed(text)
    parser.close()
    assert parser.stack == [], f"unclosed tags {parser.stack}"
    md = (out / "report.md").read_text()
    for exp_id in ids:
        assert exp_id in text and exp_id in md, f"the report does not list {exp_id}"
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")]


def assert_both_end_well(tmp_path, env, out, force, slow_a=None, delay_b=0.0):
    """Runs a and b into one folder (b started `delay_b` s later): both exit 0, the folder holds both records."""
    env_a = dict(env, FAULT_SLOW_REPORT=str(slow_a)) if slow_a else env
    procs = [_start(env_a, "reproduce", "--only", "fault-a", "-o", str(out), "-q", *force)]
    time.sleep(delay_b)
    procs.append(_start(env, "reproduce", "--only", "fault-b", "-o", str(out), "-q", *force))
    try:
        results = [p.communicate(timeout=300) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)  # the test's own process group
    for p, (_, stderr) in zip(procs, results):
        assert p.returncode == 0, stderr
    _check_folder(out, ["fault-a", "fault-b"])


@pytest.mark.slow
def test_two_runs_into_one_folder(tmp_path):
    """Two ``reproduce`` runs write records and the report of one folder at once; nothing is torn or lost."""
    env, log = _setup(tmp_path, n_calls=3, seconds=0.3)
    out = tmp_path / "out"
    assert_both_end_well(tmp_path, env, out, ())  # started together, they end together
    # run a reads the records and writes its report 4 s later; b's report (both records) comes in
    # between: a must not then replace it with its own (without b)
    assert_both_end_well(tmp_path, env, tmp_path / "out2", (), slow_a=4.0, delay_b=2.0)


def test_folder_lock_makes_a_second_holder_wait(tmp_path):
    import threading

    from mmconcepts._io import folder_lock

    events = []

    def second():
        with folder_lock(tmp_path / "out", ".report.lock"):
            events.append(("second", time.monotonic()))

    with folder_lock(tmp_path / "out", ".report.lock"):
        thread = threading.Thread(target=second)
        thread.start()
        time.sleep(0.5)
        events.append(("first leaves", time.monotonic()))
    thread.join(10)
    assert [e for e, _ in events] == ["first leaves", "second"]
    assert (tmp_path / "out" / ".report.lock").is_file()


def test_folder_lock_says_it_waits_and_marks_when_it_was_taken(tmp_path, caplog):
    """A holder that has to wait logs it (a concurrent experiment should not look hung), and the
    lock file's modification time is when it was last taken (a clean-up by age spares a held lock)."""
    import logging
    import os
    import threading

    from mmconcepts._io import folder_lock

    lock = tmp_path / "out" / ".x.lock"
    with caplog.at_level(logging.INFO, logger="mmconcepts"):
        with folder_lock(tmp_path / "out", ".x.lock"):
            pass
        assert "waiting" not in caplog.text  # free: taken at once, nothing said
        os.utime(lock, (time.time() - 7200,) * 2)  # made two hours ago
        with folder_lock(tmp_path / "out", ".x.lock"):
            assert time.time() - lock.stat().st_mtime < 60
            def second():
                with folder_lock(tmp_path / "out", ".x.lock"):
                    pass

            thread = threading.Thread(target=second)
            thread.start()
            time.sleep(0.5)
        thread.join(10)
    assert f"waiting for {lock}" in caplog.text
