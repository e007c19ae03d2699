"""Benchmark: the first-use compilation of the numerical kernels, with an empty cache and with a full one.

What a fresh install pays once (and what the notice of ``mmconcepts._jit`` announces): numba
compiles the package's kernels (``_jit.njit(cache=True)``) the first time each is called, and
librosa compiles its own when it is first imported. Later processes load the machine code from
numba's disk cache.

The script runs the same work twice in fresh child processes that share one new, empty numba
cache folder (``NUMBA_CACHE_DIR``), each with a new cache folder of the package of its own
(``MMCONCEPTS_DATA``: the experiments' own caches are cold both times): first with numba's cache
empty, then with it filled by the first run. The work: the first MFCC (librosa's
import), then the smoke preset of experiments that, between them, call every kernel of the package
(``--experiments``; the real sets of ``$MMCONCEPTS_DATA_ROOT`` if set, else generated data). Each child
reports its wall time per step and the time numba spent compiling (its ``numba:compile`` events,
outermost only); the difference between the two runs is the first-use cost.

Run:  .venv/bin/python benchmarks/compile.py [--experiments ch5-nmf-keywords ch7-compositional ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

DEFAULT_EXPERIMENTS = ("ch2-nmf-recovery", "ch5-nmf-keywords", "ch5-tree", "ch5-incremental", "ch7-compositional")


def child(experiments: list[str], output: str) -> dict:
    """One run in this process: seconds of wall time and of numba compilation, per step."""
    from numba.core import event

    class Compiling(event.Listener):
        def __init__(self) -> None:
            self.depth, self.start, self.seconds = 0, 0.0, 0.0

        def on_start(self, ev) -> None:
            if self.depth == 0:
                self.start = time.perf_counter()
            self.depth += 1

        def on_end(self, ev) -> None:
            self.depth -= 1
            if self.depth == 0:
                self.seconds += time.perf_counter() - self.start

    compiling = Compiling()
    event.register("numba:compile", compiling)
    import numpy as np

    steps = []

    def step(name, fn) -> None:
        t, c = time.perf_counter(), compiling.seconds
        status = fn()
        steps.append({"step": name, "status": status, "wall_s": time.perf_counter() - t,
                      "compile_s": compiling.seconds - c})

    def first_mfcc() -> str:
        from mmconcepts.sound.features import mfcc

        mfcc(np.random.default_rng(0).normal(size=16000).astype(np.float32) * 0.1)
        return "ok"

    step("first MFCC (librosa)", first_mfcc)
    from mmconcepts.engine import get, load_experiments, run_experiment

    load_experiments()
    for exp in experiments:
        step(exp, lambda: run_experiment(get(exp), preset="smoke", output=output, workers=1, progress=False,
                                         force=True, raise_errors=False).status)
    return {"steps": steps}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--experiments", nargs="+", default=list(DEFAULT_EXPERIMENTS))
    parser.add_argument("--json", help="write the results there")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.experiments, args.child)))
        return
    runs = {}
    with tempfile.TemporaryDirectory(prefix="mmconcepts-compile-") as tmp:
        for i, name in enumerate(("empty cache", "full cache")):
            env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba"),
                       MMCONCEPTS_DATA=os.path.join(tmp, f"data{i}"), MMCONCEPTS_QUIET="1")
            t = time.perf_counter()
            out = subprocess.run([sys.executable, __file__, "--child", os.path.join(tmp, f"results{i}"),
                                  "--experiments", *args.experiments], env=env, capture_output=True, text=True,
                                 check=True)
            runs[name] = {**json.loads(out.stdout.strip().splitlines()[-1]), "process_s": time.perf_counter() - t}
    print(f"{'step':<24} {'status':<8} {'empty: wall s':>14} {'compile s':>10} {'full: wall s':>13} {'compile s':>10}")
    for a, b in zip(runs["empty cache"]["steps"], runs["full cache"]["steps"]):
        print(f"{a['step']:<24} {a['status']:<8} {a['wall_s']:>14.1f} {a['compile_s']:>10.1f} {b['wall_s']:>13.1f} "
              f"{b['compile_s']:>10.1f}")
    cold, warm = runs["empty cache"]["process_s"], runs["full cache"]["process_s"]
    print(f"whole process: {cold:.1f} s with an empty cache, {warm:.1f} s with a full one: first use costs "
          f"{cold - warm:.1f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(runs, f, indent=1)


if __name__ == "__main__":
    main()
