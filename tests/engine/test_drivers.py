"""``reproduce --concurrent``: experiments run on driver processes that each run one after another.

The experiments are tests/_cluster_experiments.py, loaded through $MMCONCEPTS_EXPERIMENT_MODULES
by this process and by the drivers (spawned: they know only what the environment tells them).
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

import mmconcepts.engine.batch as batch
from mmconcepts.experiments import reproduce
from mmconcepts.engine.data import DataPlan
from mmconcepts.engine.registry import get

TESTS_DIR = Path(__file__).parents[1]
_COMPARED = ("status", "experiment", "preset", "config", "seed", "variant", "metrics", "intervals", "samples",
             "sample_units", "claims", "figures", "notes")


@pytest.fixture
def toy(monkeypatch, tmp_path, registry):
    """The cluster test experiments, known here and in the drivers; caches in tmp_path."""
    monkeypatch.syspath_prepend(str(TESTS_DIR))
    monkeypatch.delitem(sys.modules, "_cluster_experiments", raising=False)
    monkeypatch.setenv("MMCONCEPTS_EXPERIMENT_MODULES", "_cluster_experiments")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(TESTS_DIR), os.environ.get("PYTHONPATH")])))
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    for name in ("CLUSTER_TEST_PID_FILE", "CLUSTER_TEST_EXIT_BETA", "CLUSTER_TEST_SLEEP", "CLUSTER_TEST_SAY"):
        monkeypatch.delenv(name, raising=False)
    return tmp_path


def _common(output: Path, **kw) -> dict:
    """What reproduce gives each run (run_experiment's arguments), its data plan made over the two experiments."""
    plan = DataPlan.build([get("cluster-a"), get("cluster-b")])
    return dict(preset="quick", output=output, data_plan=plan, workers=1, scheduler=None, force=True,
                progress=False, raise_errors=False) | kw


def _drivers() -> list:
    """The driver processes of this process still running (other tests may leave loky workers)."""
    return [p for p in multiprocessing.active_children() if p.name == "mmconcepts-experiments"]


def _pids(path: Path) -> list[int]:
    return [int(x) for x in path.read_text().split()]


def _compared(path: Path) -> dict:
    rec = json.loads(path.read_text())
    return {k: rec.get(k) for k in _COMPARED}


@pytest.mark.slow
def test_concurrent_runs_give_the_records_of_one_at_a_time_on_reused_processes(toy, monkeypatch):
    ids = ["cluster-a", "cluster-b"]
    warm_ups = []  # the kernel warm-up: beside concurrent runs only

    @contextlib.contextmanager
    def warm_up():
        warm_ups.append("started")
        yield None

    monkeypatch.setattr("mmconcepts._warmup.in_background", warm_up)
    local = reproduce(ids=ids, output=toy / "local", progress=False)
    assert warm_ups == []
    monkeypatch.setenv("CLUSTER_TEST_PID_FILE", str(toy / "pids"))
    conc = reproduce(ids=ids, output=toy / "conc", concurrent=2, workers=2, progress=False)
    assert warm_ups == ["started"]
    assert [r.status for r in local] == [r.status for r in conc] == ["ok", "ok"]
    assert [r.experiment for r in conc] == ids  # in the order asked, whichever ends first
    for exp_id in ids:
        assert _compared(toy / "conc" / f"{exp_id}.json") == _compared(toy / "local" / f"{exp_id}.json")
    pids = _pids(toy / "pids")
    assert len(pids) == 2 and os.getpid() not in pids  # not in this process

    # one lane, four runs: one process runs them all
    (toy / "pids").unlink()
    runs = [(get(i), "auto") for i in ids * 2]
    records = batch.run_concurrently(runs, 1, _common(toy / "again"))
    assert [r.status for r in records] == ["ok"] * 4
    assert len(set(_pids(toy / "pids"))) == 1
    assert not _drivers()  # the driver was stopped


@pytest.mark.slow
def test_a_driver_that_dies_fails_its_run_only(toy, monkeypatch):
    """The run whose process dies gets a failed record (exit code, last output); the lane goes on."""
    monkeypatch.setenv("CLUSTER_TEST_EXIT_BETA", "2")  # cluster-b
    monkeypatch.setenv("CLUSTER_TEST_PID_FILE", str(toy / "pids"))
    monkeypatch.setenv("CLUSTER_TEST_SAY", "1")
    runs = [(get("cluster-a"), "auto"), (get("cluster-b"), "auto"), (get("cluster-a"), "auto"),
            (get("cluster-a"), "auto")]
    records = batch.run_concurrently(runs, 1, _common(toy / "out"))
    assert [r.status for r in records] == ["ok", "failed", "ok", "ok"]
    # the exit code and the dying run's own output, not the previous run's
    assert "exit code 3" in records[1].message and "running beta=2\nboom" in records[1].message
    assert "beta=1" not in records[1].message
    assert not (toy / "out" / "cluster-b.json").exists()
    first, died, *after = _pids(toy / "pids")
    assert died == first and len(set(after)) == 1 and after[0] != first  # a new process after the death, then kept

    records = reproduce(ids=["cluster-a", "cluster-b"], output=toy / "both", concurrent=2, progress=False)
    assert [r.status for r in records] == ["ok", "failed"]
    assert "exit code 3" in records[1].message


@pytest.mark.slow  # a driver process
def test_an_error_outside_the_experiment_is_a_failed_record(toy):
    """An argument the runner refuses in the driver (here an unknown variant) fails that run, not the others."""
    runs = [(get("cluster-a"), "nonsense"), (get("cluster-b"), "auto")]
    records = batch.run_concurrently(runs, 1, _common(toy / "out"))
    assert [r.status for r in records] == ["failed", "ok"]
    assert "variant must be" in records[0].message


def test_interrupting_stops_the_drivers_at_once(toy, monkeypatch):
    """Ctrl-C while experiments run: KeyboardInterrupt within seconds, no process left, nothing more started."""
    import _thread

    monkeypatch.setenv("CLUSTER_TEST_SLEEP", "60")
    monkeypatch.setenv("CLUSTER_TEST_PID_FILE", str(toy / "pids"))
    runs = [(get("cluster-a"), "auto"), (get("cluster-b"), "auto"), (get("cluster-a"), "auto")]

    returned = threading.Event()

    def interrupt_when_both_run():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not returned.is_set():
            if (toy / "pids").exists() and len(_pids(toy / "pids")) == 2:
                break
            time.sleep(0.05)
        if not returned.is_set():
            _thread.interrupt_main()

    # Python's own Ctrl-C handler (an earlier test or library may have replaced it)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Thread(target=interrupt_when_both_run, daemon=True).start()
        t0 = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            batch.run_concurrently(runs, 2, _common(toy / "out"))
        assert time.monotonic() - t0 < 40
    finally:
        returned.set()
        signal.signal(signal.SIGINT, previous)
    assert not _drivers()
    assert len(_pids(toy / "pids")) == 2  # the third run never started
    assert not list((toy / "out").glob("*.json"))


@pytest.mark.slow  # driver processes killed
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_drivers_end_when_reproduce_is_killed(toy, monkeypatch):
    monkeypatch.setenv("CLUSTER_TEST_SLEEP", "120")
    monkeypatch.setenv("CLUSTER_TEST_PID_FILE", str(toy / "pids"))
    script = textwrap.dedent(f"""
        from mmconcepts.experiments import reproduce
        reproduce(ids=["cluster-a", "cluster-b"], output={str(toy / "out")!r}, concurrent=2, progress=False)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 120
        while not ((toy / "pids").exists() and len(_pids(toy / "pids")) == 2):
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait()
    drivers = _pids(toy / "pids")
    deadline = time.monotonic() + 10
    while any(_alive(p) for p in drivers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [p for p in drivers if _alive(p)]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (ended, not yet reaped by init) counts as ended
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (OSError, IndexError):
        return True


@pytest.mark.slow  # a driver process and its workers
def test_a_driver_with_workers_ends_when_asked(toy):
    """A driver whose experiment started loky workers ends by itself when closed (exit code 0, not killed):
    multiprocessing would wait for the idle workers' timeout (300 s)."""
    from mmconcepts.engine.lanes import Driver

    driver = Driver(toy)
    record, why = driver.run("cluster-a", "auto", _common(toy / "out", workers=2))
    assert why is None and record.status == "ok" and record.samples["error"]
    t0 = time.monotonic()
    driver.close(wait=20)
    assert driver.process.exitcode == 0 and time.monotonic() - t0 < 20
    assert not list(toy.glob("driver-*.log"))


def test_every_joblib_call_of_a_run_shares_its_workers(toy, monkeypatch):
    """RunContext.parallel and the library's own joblib calls (n_jobs) run on the same loky workers:
    no second pool of processes is started for the plain calls (nor a third on the way back)."""
    from mmconcepts.experiments import run_experiment

    monkeypatch.setenv("CLUSTER_TEST_WORKER_PIDS", str(toy / "workers"))
    assert run_experiment("cluster-a", output=toy / "out", workers=2, progress=False).status == "ok"
    pids = _pids(toy / "workers")
    assert len(pids) == 12 and os.getpid() not in pids
    assert len(set(pids)) <= 2
