"""Experiments on a Dask cluster: ``--scheduler``, ``reproduce --concurrent``.

One ``LocalCluster`` of two single-threaded worker processes on 127.0.0.1 serves the module.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason="the dask extra (dask.distributed) is not installed")

from mmconcepts.cli import main  # noqa: E402
from mmconcepts.errors import ExperimentError, ParameterError  # noqa: E402
from mmconcepts.experiments import RunContext, run_experiment  # noqa: E402
from mmconcepts.engine.cluster import (LOCAL_CLUSTER_CONFIG, local_cluster, map_in_order, open_client,  # noqa: E402
                                       parse_scheduler)

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def client():
    cluster = local_cluster(2)  # the cluster --scheduler local:2 starts
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


# ------------------------------------------------------------------ module-level task functions (they pickle)
def _square_warn(x: int) -> int:
    warnings.warn(f"note {x}", UserWarning)
    return x * x


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("item three is bad")
    return x


def _die_once(item: tuple[int, str]) -> int:
    """Kill the worker process the first time item 2 runs (a marker file remembers), then succeed."""
    x, marker = item
    if x == 2 and not os.path.exists(marker):
        Path(marker).write_text("died")
        os._exit(1)
    return 10 * x


# ------------------------------------------------------------------ parsing and connecting
@pytest.mark.parametrize("spec, expected", [
    ("local:1", ("local", 1)),
    ("local:8", ("local", 8)),
    ("tcp://10.0.0.5:8786", ("address", "tcp://10.0.0.5:8786")),
    ("head-node:8786", ("address", "tcp://head-node:8786")),
    ("tls://h.example.org:8786", ("address", "tls://h.example.org:8786")),
    (" local:2 ", ("local", 2)),
])
def test_parse_scheduler_accepts(spec, expected):
    assert parse_scheduler(spec) == expected


@pytest.mark.parametrize("spec", ["local:0", "local:", "local:-1", "local", "", "http://h:8786", "h:99999", "h:",
                                  "tcp://h", 8786])
def test_parse_scheduler_refuses(spec):
    with pytest.raises(ParameterError, match="local:N"):
        parse_scheduler(spec)


def test_cli_refuses_a_bad_scheduler_as_a_usage_error(capsys):
    assert main(["run", "ch2-nmf-recovery", "--scheduler", "local:0"]) == 2
    assert "local:N" in capsys.readouterr().err


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_is_a_clear_error_within_seconds(tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.perf_counter()
    with pytest.raises(ExperimentError, match="could not reach the Dask scheduler at " + address):
        with open_client(address, timeout=2):
            pass
    assert time.perf_counter() - t0 < 15


def test_cli_unreachable_scheduler_names_it(tmp_path, capsys, monkeypatch):
    import mmconcepts.engine.cluster as cluster

    monkeypatch.setattr(cluster, "DEFAULT_CONNECT_TIMEOUT", 2.0)
    address = f"tcp://127.0.0.1:{_free_port()}"
    code = main(["run", "ch2-nmf-recovery", "--scheduler", address, "-o", str(tmp_path / "out"), "-q"])
    assert code == 1
    assert address in capsys.readouterr().err
    assert not (tmp_path / "out" / "ch2-nmf-recovery.json").exists()  # nothing half-written


# ------------------------------------------------------------------ RunContext.parallel on the cluster
def _periodic(dask_worker=None, dask_scheduler=None) -> dict:
    """The periodic callbacks of a worker or the scheduler, with their periods in ms, and its dask settings."""
    import dask

    server = dask_worker if dask_worker is not None else dask_scheduler
    return dict(callbacks={k: pc.callback_time for k, pc in server.periodic_callbacks.items()},
                config={k: dask.config.get(k) for k in LOCAL_CLUSTER_CONFIG})


def test_the_local_cluster_runs_with_its_quiet_settings_and_leaves_the_callers(client):
    """Each worker process and the scheduler started with LOCAL_CLUSTER_CONFIG (no sampling profiler, rarer ticks
    and monitors), whatever this process's dask configuration, which stays as it was."""
    import dask

    before = {k: dask.config.get(k, None) for k in LOCAL_CLUSTER_CONFIG}
    workers = client.run(_periodic)
    assert len(workers) == 2
    for seen in workers.values():
        assert seen["config"] == LOCAL_CLUSTER_CONFIG
        assert "profile" not in seen["callbacks"] and "profile-cycle" not in seen["callbacks"]
        assert seen["callbacks"]["memory_monitor"] == 500
        assert seen["callbacks"]["monitor"] == 2000
        assert seen["callbacks"]["tick"] == 200
    scheduler = client.run_on_scheduler(_periodic)
    assert scheduler["callbacks"]["tick"] == 200 and scheduler["callbacks"]["monitor"] == 2000
    assert {k: dask.config.get(k, None) for k in LOCAL_CLUSTER_CONFIG} == before
    assert before["distributed.worker.profile.enabled"] is True  # distributed's default, untouched here


def test_parallel_on_the_cluster_equals_the_loop_in_order_with_warnings(client):
    ctx = RunContext(client=client)
    seen: list[tuple[int, int]] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = ctx.parallel(_square_warn, range(7), on_result=lambda i, r: seen.append((i, r)))
    assert out == [x * x for x in range(7)]
    assert seen == list(enumerate(out))  # in order, each once
    assert [str(w.message) for w in caught if w.category is UserWarning] == [f"note {x}" for x in range(7)]


def test_parallel_on_the_cluster_raises_the_task_error(client):
    with pytest.raises(ValueError, match="item three is bad"):
        RunContext(client=client).parallel(_fail_on_three, range(5))


def test_a_dead_worker_has_its_task_run_again_and_nothing_finished_is_lost(client, tmp_path):
    marker = str(tmp_path / "died")
    seen: list[int] = []
    out = map_in_order(client, _die_once, [(x, marker) for x in range(5)], on_result=lambda i, r: seen.append(i))
    assert Path(marker).exists()  # the worker did die once
    assert out == [0, 10, 20, 30, 40] and seen == [0, 1, 2, 3, 4]
    client.wait_for_workers(2, timeout=60)


def test_empty_items(client):
    assert map_in_order(client, _square_warn, []) == []


# ------------------------------------------------------------------ whole experiments: same records
#: What must be the same (tables are left out: some hold wall-clock seconds).
_COMPARED = ("status", "experiment", "preset", "config", "seed", "variant", "metrics", "intervals", "samples",
             "sample_units", "claims", "figures", "notes")


def _record(path: Path) -> dict:
    rec = json.loads(path.read_text())
    return {k: rec.get(k) for k in _COMPARED}


@pytest.mark.slow  # a Dask cluster
def test_an_experiment_on_the_cluster_gives_the_local_record(client, tmp_path):
    local = run_experiment("ch2-nmf-recovery", preset="smoke", output=tmp_path / "local", progress=False)
    before = _task_events(client)
    remote = run_experiment("ch2-nmf-recovery", preset="smoke", output=tmp_path / "cluster", scheduler=client,
                            progress=False)
    assert local.status == remote.status == "ok"
    a, b = _record(tmp_path / "local" / "ch2-nmf-recovery.json"), _record(tmp_path / "cluster" / "ch2-nmf-recovery.json")
    assert a["metrics"] and a == b
    assert _task_events(client) > before  # the experiment's items did run on the workers, not here


def _task_events(client) -> int:
    """How many task-state events the scheduler has seen for RunContext.parallel's tasks."""
    def count(dask_scheduler):
        prefix = dask_scheduler.task_prefixes.get("WarningsCarried")
        return 0 if prefix is None else int(sum(prefix.state_counts.values()))
    return client.run_on_scheduler(count)


@pytest.mark.slow
def test_cli_run_with_a_local_cluster_and_reproduce_concurrently(tmp_path, monkeypatch, registry):
    """`run --scheduler local:2` and `reproduce --concurrent 2 --scheduler ADDR` write the records of a local run.

    The experiments are tests/_cluster_experiments.py, loaded through $MMCONCEPTS_EXPERIMENT_MODULES (by this
    process and by the processes `reproduce --concurrent` starts).
    """
    tests_dir = str(Path(__file__).parents[1])
    monkeypatch.delitem(sys.modules, "_cluster_experiments", raising=False)  # registers again in the fresh registry
    monkeypatch.setenv("MMCONCEPTS_EXPERIMENT_MODULES", "_cluster_experiments")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [tests_dir, os.environ.get("PYTHONPATH")])))
    monkeypatch.syspath_prepend(tests_dir)
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    ids = ["cluster-a", "cluster-b"]
    assert main(["reproduce", "--only", *ids, "-o", str(tmp_path / "local"), "-q"]) == 0
    assert main(["run", "cluster-a", "--scheduler", "local:2", "-o", str(tmp_path / "run"), "-q"]) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = distributed.LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None)
    with lc:
        assert main(["reproduce", "--only", *ids, "--concurrent", "2", "--scheduler", lc.scheduler_address,
                     "-o", str(tmp_path / "conc"), "-q"]) == 0
    metrics = set()
    for exp_id in ids:
        a = _record(tmp_path / "local" / f"{exp_id}.json")
        assert a["status"] == "ok" and len(a["samples"]["error"]) == 4
        metrics.add(a["metrics"]["error"])
        assert _record(tmp_path / "conc" / f"{exp_id}.json") == a, exp_id
    assert len(metrics) == 2  # two different experiments
    assert _record(tmp_path / "run" / "cluster-a.json") == _record(tmp_path / "local" / "cluster-a.json")
    assert (tmp_path / "conc" / "report.html").exists()


def test_reproduce_refuses_a_bad_concurrency(tmp_path):
    from mmconcepts.experiments import reproduce

    for bad in (0, -1, 1.5, True):
        with pytest.raises(ParameterError, match="concurrent"):
            reproduce(ids=["ch2-nmf-recovery"], output=tmp_path, concurrent=bad)
    np.testing.assert_equal(list(tmp_path.iterdir()), [])
