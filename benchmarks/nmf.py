"""Benchmark: mmconcepts' NMF against scikit-learn's NMF, in the same run.

Each library's whole `NMF(...).fit` as a user calls it (validation, the start, the updates, the
objective evaluations and the final reconstruction error): same data, same initial factors
(init='custom'), 100 multiplicative-update iterations, tol=0 (no early stop), both libraries on the
same BLAS threads. For each case the script checks that the two fitted dictionaries agree to 1e-10
(largest difference relative to the largest entry: the same iterates) and the two reconstruction
errors to 1e-10, times each library `--repeats` times in alternation, and reports the median time
per fit, per iteration, and the ratio.

The C allocator matters for scikit-learn, which allocates new n x m temporaries at every
iteration: with glibc's fixed default (blocks over 128 kB are fresh memory-mapped pages, so every
temporary page-faults) it runs much slower than when freed memory is kept and reused. glibc's
dynamic threshold makes which of the two a process gets depend on its allocation history, so
by default the script measures both, each in its own child process (`--allocator both`):
`mmap` sets MALLOC_MMAP_THRESHOLD_=131072; `heap` sets MALLOC_MMAP_THRESHOLD_ and
MALLOC_TRIM_THRESHOLD_ to 1 GB; `inherit` runs in this process with the environment as given.

Run:  .venv/bin/python benchmarks/nmf.py [--repeats 5] [--cases sparse_kl dense_kl dense_fro]
                                         [--allocator both|mmap|heap|inherit]
The case sparse_kl_hac (HAC-like: 300 x 110 000, 3 % nonzeros) is not run by default: scikit-learn is
slow there, so run it with --iterations 20.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np
import scipy.sparse as sp
import sklearn
from sklearn.decomposition import NMF as SkNMF

import mmconcepts
from mmconcepts.nmf import NMF


def make_case(name: str, rng: np.random.Generator):
    if name == "sparse_kl":
        n, m, k, beta = 20000, 2000, 50, 1.0
        X = sp.random(n, m, density=0.01, format="csr", random_state=np.random.RandomState(0),
                      data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
    elif name == "sparse_kl_hac":  # HAC-like: few utterances, 110 000 columns, a dictionary of 44 MB
        n, m, k, beta = 300, 110_000, 50, 1.0
        X = sp.random(n, m, density=0.03, format="csr", random_state=np.random.RandomState(1),
                      data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
    elif name == "dense_kl":
        n, m, k, beta = 2000, 1000, 50, 1.0
        X = rng.poisson(2.0, (n, m)).astype(np.float64) + rng.random((n, m))
    elif name == "dense_fro":
        n, m, k, beta = 2000, 1000, 50, 2.0
        X = rng.poisson(2.0, (n, m)).astype(np.float64) + rng.random((n, m))
    else:
        raise SystemExit(f"unknown case {name}")
    scale = np.sqrt(X.mean() / k)
    W0 = np.abs(scale * rng.standard_normal((n, k)))
    H0 = np.abs(scale * rng.standard_normal((k, m)))
    return X, W0, H0, beta


def run_sklearn(X, W0, H0, beta, n_iter):
    model = SkNMF(W0.shape[1], init="custom", solver="mu", beta_loss=beta, max_iter=n_iter, tol=0)
    W, H = W0.copy(), H0.copy()  # scikit-learn updates the given factors in place
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        model.fit(X, W=W, H=H)
        dt = time.perf_counter() - t
    return dt, model


def run_ours(X, W0, H0, beta, n_iter):
    model = NMF(W0.shape[1], init="custom", beta_loss=beta, max_iter=n_iter, tol=0)
    t = time.perf_counter()
    model.fit(X, W=W0, H=H0)
    dt = time.perf_counter() - t
    return dt, model


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--cases", nargs="+", default=["sparse_kl", "dense_kl", "dense_fro"])
    ap.add_argument("--json", help="also write the results to this file")
    ap.add_argument("--allocator", choices=["both", "mmap", "heap", "inherit"], default="both",
                    help="glibc allocator setting(s) to measure under (see above); default both")
    args = ap.parse_args(argv)
    if args.allocator != "inherit":
        return _run_children(args)
    rng = np.random.default_rng(0)
    rows = []
    for case in args.cases:
        X, W0, H0, beta = make_case(case, rng)
        run_ours(X[:50], W0[:50], H0, beta, 2)  # compile the numba kernels first
        ours, theirs = [], []
        for _ in range(args.repeats):
            t_sk, sk_model = run_sklearn(X, W0, H0, beta, args.iterations)
            t_us, us_model = run_ours(X, W0, H0, beta, args.iterations)
            theirs.append(t_sk)
            ours.append(t_us)
        H_sk, H_us = sk_model.components_, us_model.components_
        h_diff = float(np.abs(H_us - H_sk).max() / np.abs(H_sk).max())
        err_sk, err_us = float(sk_model.reconstruction_err_), float(us_model.reconstruction_err_)
        err_diff = abs(err_sk - err_us) / abs(err_sk)
        med_sk, med_us = statistics.median(theirs), statistics.median(ours)
        n = args.iterations
        row = dict(case=case, shape=list(X.shape), k=W0.shape[1], beta=beta, iterations=n, repeats=args.repeats,
                   sklearn_ms=1e3 * med_sk, ours_ms=1e3 * med_us, sklearn_ms_per_iter=1e3 * med_sk / n,
                   ours_ms_per_iter=1e3 * med_us / n, speedup=med_sk / med_us, sklearn_runs_ms=[1e3 * t for t in theirs],
                   ours_runs_ms=[1e3 * t for t in ours], components_rel_diff=h_diff,
                   reconstruction_err_sklearn=err_sk, reconstruction_err_ours=err_us, reconstruction_err_rel_diff=err_diff)
        rows.append(row)
        print(f"{case:10s} whole fit: sklearn {row['sklearn_ms']:8.1f} ms ({row['sklearn_ms_per_iter']:6.2f} ms/it)   "
              f"mmconcepts {row['ours_ms']:8.1f} ms ({row['ours_ms_per_iter']:6.2f} ms/it)   speedup x{row['speedup']:.2f}   "
              f"H rel. diff {h_diff:.1e}   error rel. diff {err_diff:.1e}", flush=True)
        if h_diff > 1e-10 or err_diff > 1e-10:
            print(f"  WARNING: the fits differ: dictionaries by {h_diff:.2e}, reconstruction errors by {err_diff:.2e} "
                  "(> 1e-10)")
    meta = dict(mmconcepts=mmconcepts.__version__, sklearn=sklearn.__version__, numpy=np.__version__,
                python=platform.python_version(), machine=platform.machine())
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(meta=meta, results=rows), fh, indent=2)
    return rows


ALLOCATOR_ENV = {
    "mmap": {"MALLOC_MMAP_THRESHOLD_": "131072"},
    "heap": {"MALLOC_MMAP_THRESHOLD_": "1073741824", "MALLOC_TRIM_THRESHOLD_": "1073741824"},
}


def _run_children(args):
    """Rerun this script once per allocator setting, each in a fresh process, and gather the rows."""
    settings = ["mmap", "heap"] if args.allocator == "both" else [args.allocator]
    rows, meta = [], {}
    for name in settings:
        print(f"--- allocator: {name} ({' '.join(f'{k}={v}' for k, v in ALLOCATOR_ENV[name].items())})", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "rows.json")
            cmd = [sys.executable, os.path.abspath(__file__), "--allocator", "inherit", "--repeats", str(args.repeats),
                   "--iterations", str(args.iterations), "--json", out, "--cases", *args.cases]
            subprocess.run(cmd, check=True, env={**os.environ, **ALLOCATOR_ENV[name]})
            with open(out) as fh:
                data = json.load(fh)
        meta = data["meta"]
        rows += [dict(row, allocator=name) for row in data["results"]]
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(meta=meta, results=rows), fh, indent=2)
    return rows


if __name__ == "__main__":
    main()
