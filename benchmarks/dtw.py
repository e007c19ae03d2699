"""Benchmark: mmconcepts' DTW distance matrix against dtaidistance's C version, in the same run.

Target (the issue): a distance matrix of 200 sequences of 20-40 frames x 13 coefficients at
least as fast as ``dtaidistance.dtw_ndim.distance_matrix_fast`` (ratio >= 1).

Data: ``--n`` random-walk sequences with a fixed seed, lengths uniform in [20, 40] frames,
13 coefficients whose scale decreases with the coefficient index like MFCCs. Both libraries
compute the same thing: with ``local="sqeuclidean"`` ours is dtaidistance's default
definition (sqrt of the best summed squared frame distance), with ``local="euclidean"``
it is dtaidistance's ``inner_dist="euclidean"`` (best summed frame distance); no window,
no pruning bound (ours has none; dtaidistance's default ``max_dist=None``).

For each local cost the script first checks that the two matrices agree to 1e-9
(relative), then times both, warm-up runs excluded (numba compilation), alternating the two
libraries ``--repeats`` times, once with one thread each (ours ``n_jobs=1``, dtaidistance
``parallel=False``) and once with all threads (ours ``n_jobs=-1``, i.e. all numba threads;
dtaidistance ``parallel=True``, OpenMP with its default thread count). It reports the median
times and the ratio dtaidistance time / our time (above 1: mmconcepts is faster).

Run:  .venv/bin/python benchmarks/dtw.py [--repeats 9] [--n 200] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numba
import numpy as np

import mmconcepts
from mmconcepts.sound.dtw import dtw_distance_matrix

try:
    import dtaidistance
    from dtaidistance import dtw_ndim
except ImportError:  # pragma: no cover - the peer library is needed to run this script
    raise SystemExit("benchmarks/dtw.py needs dtaidistance (pip install dtaidistance) with its C extension.")


def make_sequences(n: int, d: int, min_len: int, max_len: int, seed: int) -> list[np.ndarray]:
    """MFCC-like random walks: coefficient k has scale 1 / (1 + k), start ~ N(0, 4 scale^2)."""
    rng = np.random.default_rng(seed)
    scale = 1.0 / (1.0 + np.arange(d))
    seqs = []
    for _ in range(n):
        T = int(rng.integers(min_len, max_len + 1))
        start = 2.0 * scale * rng.standard_normal(d)
        steps = scale * rng.standard_normal((T, d))
        seqs.append(np.ascontiguousarray(start + np.cumsum(steps, axis=0)))
    return seqs


def run_ours(X, local, n_jobs):
    t = time.perf_counter()
    D = dtw_distance_matrix(X, local=local, n_jobs=n_jobs)
    return time.perf_counter() - t, D


def run_dtai(X, local, parallel):
    inner = "squared euclidean" if local == "sqeuclidean" else "euclidean"
    t = time.perf_counter()
    D = dtw_ndim.distance_matrix_fast(X, parallel=parallel, inner_dist=inner)
    return time.perf_counter() - t, D


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=9, help="timed runs per library and case (>= 7 advised)")
    ap.add_argument("--n", type=int, default=200, help="number of sequences")
    ap.add_argument("--d", type=int, default=13, help="coefficients per frame")
    ap.add_argument("--lengths", type=int, nargs=2, default=[20, 40], metavar=("MIN", "MAX"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--locals", nargs="+", default=["sqeuclidean", "euclidean"], choices=["sqeuclidean", "euclidean"])
    ap.add_argument("--json", help="also write the results to this file")
    args = ap.parse_args(argv)

    X = make_sequences(args.n, args.d, args.lengths[0], args.lengths[1], args.seed)
    n_all = numba.config.NUMBA_NUM_THREADS
    print(f"{args.n} sequences of {args.lengths[0]}-{args.lengths[1]} frames x {args.d}, seed {args.seed}; "
          f"{args.repeats} timed runs each, medians. numba threads: 1 / {n_all} (cpu_count {os.cpu_count()}, "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}).", flush=True)
    print(f"{'local':12s} {'threads':>8s} {'dtaidistance ms':>16s} {'mmconcepts ms':>14s} {'ratio':>7s} "
          f"{'max rel. diff':>14s}", flush=True)
    rows = []
    for local in args.locals:
        # agreement first (these calls also compile our kernels and warm both libraries up)
        _, D_us = run_ours(X, local, 1)
        _, D_dt = run_dtai(X, local, False)
        run_ours(X, local, -1)
        run_dtai(X, local, True)
        rel = float(np.max(np.abs(D_us - D_dt) / np.maximum(1.0, np.abs(D_dt))))
        if not rel <= 1e-9:
            raise SystemExit(f"{local}: the two matrices differ by {rel:.2e} > 1e-9 (relative); not timing.")
        for label, n_jobs, parallel in (("1", 1, False), (f"all={n_all}", -1, True)):
            ours, theirs = [], []
            for _ in range(args.repeats):
                theirs.append(run_dtai(X, local, parallel)[0])
                ours.append(run_ours(X, local, n_jobs)[0])
            med_dt, med_us = statistics.median(theirs), statistics.median(ours)
            row = dict(local=local, threads=label, n=args.n, d=args.d, lengths=args.lengths, repeats=args.repeats,
                       dtaidistance_ms=1e3 * med_dt, ours_ms=1e3 * med_us, ratio=med_dt / med_us,
                       max_rel_diff=rel, dtaidistance_all_ms=[1e3 * t for t in theirs],
                       ours_all_ms=[1e3 * t for t in ours])
            rows.append(row)
            print(f"{local:12s} {label:>8s} {row['dtaidistance_ms']:16.1f} {row['ours_ms']:14.1f} "
                  f"{row['ratio']:7.2f} {rel:14.1e}", flush=True)
    meta = dict(mmconcepts=mmconcepts.__version__, dtaidistance=dtaidistance.__version__, numba=numba.__version__,
                numpy=np.__version__, python=platform.python_version(), machine=platform.machine(),
                cpu_count=os.cpu_count(), numba_threads=n_all)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(meta=meta, results=rows), fh, indent=2)
    return rows


if __name__ == "__main__":
    main()
