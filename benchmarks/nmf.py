"""Benchmark: mmconcepts' beta-NMF against scikit-learn's NMF, in the same run.

Same data, same initial factors (init='custom'), 100 multiplicative-update iterations,
tol=0 (no early stop), both libraries on the same BLAS threads. For each case the script
checks that the two final losses agree to 1e-6 (relative), times each library `--repeats`
times in alternation, and reports the median time per iteration and the ratio.

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
from sklearn.decomposition._nmf import _beta_divergence

import mmconcepts
from mmconcepts.nmf import beta_divergence, beta_nmf


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
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        W = model.fit_transform(X, W=W0.copy(), H=H0.copy())
        dt = time.perf_counter() - t
    return dt, W, model.components_


def run_ours(X, W0, H0, beta, n_iter):
    t = time.perf_counter()
    res = beta_nmf(X, W0.shape[1], init="custom", W=W0, H=H0, beta_loss=beta, max_iter=n_iter, tol=0,
                   loss_every=n_iter)
    dt = time.perf_counter() - t
    return dt, res.W, res.H


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
            t_sk, W_sk, H_sk = run_sklearn(X, W0, H0, beta, args.iterations)
            t_us, W_us, H_us = run_ours(X, W0, H0, beta, args.iterations)
            theirs.append(t_sk)
            ours.append(t_us)
        loss_sk = _beta_divergence(X, W_sk, H_sk, beta)
        loss_us = beta_divergence(X, W_us, H_us, beta)
        rel = abs(loss_sk - loss_us) / abs(loss_sk)
        med_sk, med_us = statistics.median(theirs), statistics.median(ours)
        row = dict(case=case, shape=list(X.shape), k=W0.shape[1], beta=beta, iterations=args.iterations,
                   repeats=args.repeats, sklearn_ms_per_iter=1e3 * med_sk / args.iterations,
                   ours_ms_per_iter=1e3 * med_us / args.iterations, speedup=med_sk / med_us,
                   loss_sklearn=loss_sk, loss_ours=loss_us, loss_rel_diff=rel)
        rows.append(row)
        print(f"{case:10s} sklearn {row['sklearn_ms_per_iter']:7.1f} ms/it   mmconcepts {row['ours_ms_per_iter']:7.1f} "
              f"ms/it   speedup x{row['speedup']:.2f}   loss rel. diff {rel:.1e}", flush=True)
        if rel > 1e-6:
            print(f"  WARNING: final losses differ by {rel:.2e} > 1e-6")
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
