"""Benchmark: the motion histograms' k-means codebooks against scipy's ``kmeans2``.

:class:`mmconcepts.motion.MotionHistograms` (``method="vq"``) fits one codebook per degree of
freedom on its standardised angle-velocity pairs: k-means++ seeding and Lloyd iterations, as
``scipy.cluster.vq.kmeans2(z, k, iter=50, minit="++", seed=s)``. Ours
(``mmconcepts.motion.histograms._lloyd``) seeds and runs the first iteration with kmeans2,
then runs the other iterations in a compiled loop that makes the same numbers, and stops at the
fixed point (an iteration whose assignments are the previous one's). Both are timed on the same
data with the same seeds, one after the other, ``--repeats`` times, the median reported, and
their codebooks and labels compared: they must be equal to the bit.

The cases (seeded generators below) have chapter 3's sizes: 10 000 samples of 2 features (an
angle and its delayed velocity, the training samples of one degree of freedom, at most
``max_fit_samples``), k = 25 centroids (chapter 6's motion bins) and k = 15, drawn as

- ``gaussian``: one standard normal cloud (no clusters: Lloyd runs most of its 50 iterations);
- ``phase``: a noisy phase portrait, (sin t, cos t) with a little Gaussian noise, as a joint
  moving back and forth draws.

Run:  .venv/bin/python benchmarks/codebooks.py [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import warnings

import numpy as np
import scipy
from scipy.cluster.vq import kmeans2

import mmconcepts
from mmconcepts.motion.histograms import _lloyd


def make_case(name: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if name == "gaussian":
        return rng.standard_normal((n, 2))
    t = rng.uniform(0, 2 * np.pi, n)
    z = np.column_stack([np.sin(t), np.cos(t)]) + 0.15 * rng.standard_normal((n, 2))
    return z / z.std(axis=0)


def timed(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--json", help="also write the results to this file")
    args = ap.parse_args(argv)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # kmeans2's empty-cluster warnings
        _lloyd(make_case("gaussian", 200, np.random.default_rng(0)), 5, seed=0, n_iter=3)  # compile, or load
        for name in ("gaussian", "phase"):
            for k in (15, 25):
                z = make_case(name, args.samples, np.random.default_rng(1))
                t_ours, (cb, lab) = timed(lambda: _lloyd(z, k, seed=3, n_iter=50), args.repeats)
                t_peer, (want_cb, want_lab) = timed(lambda: kmeans2(z, k, iter=50, minit="++", seed=3),
                                                    args.repeats)
                same = bool(np.array_equal(cb, want_cb) and np.array_equal(lab, want_lab))
                rows.append(dict(case=name, k=k, ours_ms=1e3 * t_ours, kmeans2_ms=1e3 * t_peer,
                                 ratio=t_peer / t_ours, identical=same))
                print(f"{name:9s} k={k:3d}  ours {1e3 * t_ours:8.2f} ms  kmeans2 {1e3 * t_peer:8.2f} ms  "
                      f"ratio {t_peer / t_ours:5.2f}x  identical: {same}")
    if args.json:
        with open(args.json, "w") as out:
            json.dump(dict(rows=rows, mmconcepts=mmconcepts.__version__, numpy=np.__version__,
                           scipy=scipy.__version__, python=platform.python_version(),
                           machine=platform.machine()), out, indent=1)
    if not all(r["identical"] for r in rows):
        raise SystemExit("ours and kmeans2 differ")


if __name__ == "__main__":
    main()
