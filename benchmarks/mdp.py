"""Benchmark: batched planning of many tasks (mmconcepts.tasks) against pymdptoolbox, in the same run.

The chapter-4 learners plan the same grid world for many reward functions at every step
(one task per demonstrated task, thesis section 4.3). This script solves ``--tasks`` random
reward functions on the 10 x 10 grid world of section 4.3.2 (4 actions, success 0.7,
discount 0.9) with

- pymdptoolbox's ``PolicyIteration`` and ``ValueIteration``, one task at a time (it has no
  batch API), and
- mmconcepts' ``policy_iteration`` and ``value_iteration``, all tasks in one call,

and the soft values of the maximum-entropy baseline (``soft_value_iteration``, all tasks in one call) against
the same sweeps with scipy's ``special.logsumexp`` (no other library has soft value iteration),

checks that the optimal values agree (policy iteration: both exact; value iteration: to
the stopping tolerance), times each `--repeats` times in alternation and reports the
median time and the ratio (pymdptoolbox / mmconcepts). BLAS is limited to one thread for
both, as in the experiment's workers.

Run:  .venv/bin/python benchmarks/mdp.py [--tasks 100] [--repeats 7]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

import mmconcepts
from mmconcepts.tasks import grid_world, policy_iteration, soft_value_iteration, value_iteration


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    try:
        import mdptoolbox.mdp as tb
    except ImportError as exc:  # pragma: no cover - optional peer
        raise SystemExit("pymdptoolbox is needed: pip install 'mmconcepts[bench]'") from exc

    world = grid_world(10, success_prob=0.7, discount=0.9)
    R = np.random.default_rng(0).standard_normal((args.tasks, world.n_states, world.n_actions))
    P = world.transitions

    def peer_pi():
        out = []
        for r in R:
            m = tb.PolicyIteration(P, r, world.discount)
            m.run()
            out.append(m.V)
        return np.array(out)

    def peer_vi():
        out = []
        for r in R:
            # epsilon chosen so that its stopping threshold, epsilon (1 - gamma) / gamma, is 1e-10 as ours
            m = tb.ValueIteration(P, r, world.discount, epsilon=1e-10 * world.discount / (1 - world.discount),
                                  max_iter=100_000)
            m.run()
            out.append(m.V)
        return np.array(out)

    def peer_soft():
        from scipy.special import logsumexp

        Pf = P.reshape(-1, world.n_states)  # (A S, S): the same sweeps as ours, all tasks at once
        RT = R.transpose(0, 2, 1).reshape(len(R), -1)
        V = np.zeros((len(R), world.n_states))
        for _ in range(10_000):
            V_new = logsumexp((RT + world.discount * (V @ Pf.T)).reshape(len(R), world.n_actions, -1), axis=1)
            done = np.abs(V_new - V).max() < 1e-10
            V = V_new
            if done:
                break
        return logsumexp((RT + world.discount * (V @ Pf.T)).reshape(len(R), world.n_actions, -1), axis=1)

    cases = {
        "policy_iteration": ("pymdptoolbox", peer_pi, lambda: policy_iteration(world, R)[0], 1e-9),
        "value_iteration": ("pymdptoolbox", peer_vi, lambda: value_iteration(world, R)[0], 1e-7),
        "soft_value_iteration": ("scipy logsumexp", peer_soft, lambda: soft_value_iteration(world, R)[0], 1e-9),
    }
    print(f"{args.tasks} tasks, 10 x 10 grid world; mmconcepts {mmconcepts.__version__}, numpy {np.__version__}, "
          f"python {platform.python_version()}")
    with threadpool_limits(limits=1, user_api="blas"):
        for name, (peer_name, peer, ours, tol) in cases.items():
            v_peer, v_ours = peer(), ours()
            err = float(np.abs(v_peer - v_ours).max())
            t_peer, t_ours = [], []
            for _ in range(args.repeats):
                t = time.perf_counter()
                peer()
                t_peer.append(time.perf_counter() - t)
                t = time.perf_counter()
                ours()
                t_ours.append(time.perf_counter() - t)
            mp, mo = statistics.median(t_peer), statistics.median(t_ours)
            print(f"{name:20s} {peer_name} {1e3 * mp:8.1f} ms   mmconcepts {1e3 * mo:7.1f} ms   "
                  f"speedup x{mp / mo:.1f}   max |V diff| {err:.1e}", flush=True)
            if err > tol:
                print(f"  WARNING: values differ by {err:.2e} > {tol:g}")


if __name__ == "__main__":
    main()
