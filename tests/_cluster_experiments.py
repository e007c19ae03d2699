"""Two small experiments for the cluster tests (not part of the library).

Loaded through ``MMCONCEPTS_EXPERIMENT_MODULES=_cluster_experiments`` (with ``tests/`` on
``PYTHONPATH``), so that the processes ``reproduce --concurrent`` starts know them too. Each
fits seeded NMFs through ``ctx.parallel`` and reports their errors with per-seed samples.

Environment variables let the tests of ``reproduce --concurrent`` watch and upset the
processes that run them: ``CLUSTER_TEST_PID_FILE`` (each run appends its process id),
``CLUSTER_TEST_EXIT_BETA`` (the experiment with that beta writes "boom" to stderr and ends
its process with exit code 3), ``CLUSTER_TEST_SAY`` (each run writes its beta to stderr) and
``CLUSTER_TEST_SLEEP`` (seconds to wait before computing) and ``CLUSTER_TEST_WORKER_PIDS`` (the
process ids of the workers of ``ctx.parallel``, a plain ``joblib.Parallel``, then ``ctx.parallel``
again, one per line).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from mmconcepts.experiments import Claim, Experiment, Result, RunContext, register
from mmconcepts.engine.config import PresetConfig


@dataclass(frozen=True)
class Config(PresetConfig):
    n_seeds: int = 4
    beta: float = 1.0
    seed: int = 0


def _fit(task: tuple[float, int, int]) -> float:
    from mmconcepts.nmf import NMF

    beta, data_seed, learner_seed = task
    X = np.random.default_rng(data_seed).gamma(2.0, size=(30, 12))
    model = NMF(3, beta_loss=beta, max_iter=40, tol=0.0, random_state=learner_seed).fit(X)
    return float(model.reconstruction_err_)


def _test_hooks(config: Config) -> None:
    pid_file = os.environ.get("CLUSTER_TEST_PID_FILE")
    if pid_file:
        with open(pid_file, "a") as f:
            f.write(f"{os.getpid()}\n")
    if os.environ.get("CLUSTER_TEST_SAY"):
        sys.stderr.write(f"running beta={config.beta:g}\n")
    if os.environ.get("CLUSTER_TEST_EXIT_BETA") == f"{config.beta:g}":
        sys.stderr.write("boom\n")
        sys.stderr.flush()
        os._exit(3)
    time.sleep(float(os.environ.get("CLUSTER_TEST_SLEEP", "0")))


def _worker_pid(_: int) -> int:
    return os.getpid()


def compute(config: Config, ctx: RunContext) -> Result:
    _test_hooks(config)
    pid_file = os.environ.get("CLUSTER_TEST_WORKER_PIDS")
    if pid_file:
        from joblib import Parallel, delayed

        pids = ctx.parallel(_worker_pid, range(4))
        pids += Parallel(n_jobs=ctx.workers)(delayed(_worker_pid)(i) for i in range(4))
        pids += ctx.parallel(_worker_pid, range(4))
        with open(pid_file, "w") as f:
            f.write("".join(f"{p}\n" for p in pids))
    data_seq, learner_seq = np.random.SeedSequence(config.seed).spawn(2)
    data_seed = int(data_seq.generate_state(1)[0])
    learner_seeds = [int(s.generate_state(1)[0]) for s in learner_seq.spawn(config.n_seeds)]
    errors = ctx.parallel(_fit, [(config.beta, data_seed, s) for s in learner_seeds], desc="fits")
    return Result(metrics={"error": float(np.mean(errors))}, samples={"error": errors})


@dataclass(frozen=True)
class ConfigB(Config):
    beta: float = 2.0


def _no_figures(result: Result, config: Config) -> dict:
    return {}


for _id, _cls in (("cluster-a", Config), ("cluster-b", ConfigB)):
    register(Experiment(
        id=_id, title=f"Cluster test experiment (beta={_cls().beta:g})", thesis_ref="none (tests)",
        config_cls=_cls, compute=compute, present=_no_figures,
        claims=[Claim("the error is positive", "error > 0")],
    ))
