"""Benchmark: the coefficients of a fixed dictionary (``NMF.transform``'s solve) against the peers.

Chapter 3's label NMF reads its activations through ``transform``: for 1 <= beta <= 2 the
multiplicative updates start projected Newton steps (``mmconcepts.nmf._coefficients``) that
solve each row to its optimum. The cases have chapter 3's sizes, 125 rows over 256 histogram
bins and a dictionary of 150 atoms (seeded generators below):

- ``mixtures`` (beta = 2 and 1): rows that mix about a tenth of the atoms, gamma-distributed
  entries;
- ``kernel_densities`` (beta = 1): chapter 3's own kind of rows, kernel-density histograms (a
  few Gaussian bumps of width 4 bins, normalised: tails down to 1e-100 of the peak and below),
  over a dictionary learnt from them as chapter 3 learns its own (``beta_nmf``, I-divergence, 200
  iterations).

The start is the same for every method: 50 multiplicative updates from a flat start. Timed,
one BLAS thread, each method ``--repeats`` times in turn, the median reported:

- ``ours``: ``solve_coefficients`` from that start (Newton steps counted);
- beta = 2: ``scipy.optimize.nnls``, one row at a time (active-set NNLS, exact);
- beta = 1: scikit-learn's multiplicative updates (``sklearn.decomposition.non_negative_factorization``
  with ``update_H=False``) for 200 and 2000 further iterations from the same start;
- both: ``scipy.optimize.minimize`` (L-BFGS-B, bounds w >= 0, analytic gradient) per row from
  the same start, to ``ftol=1e-15``.

Each method's answer is scored by its objective's excess over the best of all methods
(summed over rows, relative), and by its worst row's excess over that row's best (a sum can
hide one row far above its minimum): ours and NNLS reach the optimum; multiplicative updates
are cheaper per step and stop short of it. ``ours_start_200`` is ours from another start (200
updates instead of 50, made before the clock): each row's problem is convex with one minimiser,
so its objectives must match ours. A row whose objective is infinite (a cell with x > 0
whose product underflowed to zero) is counted apart, and the excess is summed over the rows
that every method leaves finite.

Run:  .venv/bin/python benchmarks/coefficients.py [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
import warnings

import numpy as np
import scipy
import sklearn
from scipy.optimize import minimize, nnls
from sklearn.decomposition import non_negative_factorization
from threadpoolctl import threadpool_limits

import mmconcepts
import mmconcepts.nmf._coefficients as coefficients
from mmconcepts.nmf import beta_nmf
from mmconcepts.nmf._beta import elementwise_beta_divergence


def make_case(beta: float, rng: np.random.Generator):
    """Histogram-like rows: 125 x 256, 150 atoms (gamma(0.3) entries), each row a mix of about 15 of them."""
    H = rng.gamma(0.3, 1.0, (150, 256))
    W = rng.gamma(0.5, 1.0, (125, 150)) * (rng.random((125, 150)) < 0.1)
    X = W @ H + 0.05 * rng.random((125, 256))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = beta_nmf(X, 150, H=H, update_H=False, beta_loss=beta, max_iter=50, random_state=0).W
    return X, H, start


def make_kernel_density_case(rng: np.random.Generator):
    """125 kernel-density rows over 256 bins (1 to 3 bumps of width 4), the 150-atom dictionary ``beta_nmf``
    learns from them, and 50 multiplicative updates from a flat start."""
    bins = np.arange(256)
    X = np.zeros((125, 256))
    for row in X:
        for centre in rng.uniform(0, 256, rng.integers(1, 4)):
            row += rng.uniform(0.5, 1.0) * np.exp(-0.5 * ((bins - centre) / 4.0) ** 2)
    X /= X.sum(axis=1, keepdims=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        H = beta_nmf(X, 150, beta_loss=1.0, max_iter=200, random_state=1).H
        start = beta_nmf(X, 150, H=H, update_H=False, beta_loss=1.0, max_iter=50, random_state=0).W
    return X, H, start


def objective(X, H, W, beta):
    return elementwise_beta_divergence(X, W @ H, beta).sum(axis=1)


def run_ours(X, H, start, beta):
    steps = []
    directions = coefficients._newton_directions

    def counted(*args):
        steps.append(1)
        return directions(*args)

    coefficients._newton_directions = counted
    try:
        t = time.perf_counter()
        W, converged = coefficients.solve_coefficients(X, H, start, beta)
        dt = time.perf_counter() - t
    finally:
        coefficients._newton_directions = directions
    return dt, W, dict(steps=len(steps), converged=bool(converged))


def run_ours_from_updates(n_updates: int):
    """Ours from another start, ``n_updates`` multiplicative updates from a flat start (made before the clock): each
    row's problem is convex with one minimiser, so both starts must reach the same objective."""
    def run(X, H, start, beta):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            other = beta_nmf(X, H.shape[0], H=H, update_H=False, beta_loss=beta, max_iter=n_updates, tol=0,
                             random_state=0).W
        return run_ours(X, H, other, beta)
    return run


def run_nnls(X, H, start, beta):
    t = time.perf_counter()
    W = np.vstack([nnls(H.T, x)[0] for x in X])
    return time.perf_counter() - t, W, {}


def run_lbfgs(X, H, start, beta):
    def f(w, x):
        y = w @ H
        if beta == 2.0:
            r = y - x
            return 0.5 * r @ r, H @ r
        yy = np.maximum(y, 1e-300)
        val = np.sum(np.where(x > 0, x * np.log(np.where(x > 0, x, 1.0) / yy), 0.0) - x + y)
        return val, H @ (1.0 - x / yy)

    t = time.perf_counter()
    W = np.vstack([minimize(f, w0, args=(x,), jac=True, method="L-BFGS-B", bounds=[(0, None)] * H.shape[0],
                            options=dict(ftol=1e-15, gtol=1e-12, maxiter=20000, maxfun=40000)).x
                   for x, w0 in zip(X, start)])
    return time.perf_counter() - t, W, {}


def run_sklearn_mu(n_iter):
    def run(X, H, start, beta):
        W0 = start.copy()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = time.perf_counter()
            W, _, n = non_negative_factorization(X, W=W0, H=H, n_components=H.shape[0], init="custom",
                                                 update_H=False, solver="mu", beta_loss=beta, max_iter=n_iter,
                                                 tol=0.0)
            dt = time.perf_counter() - t
        return dt, W, dict(iterations=int(n))
    return run


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", help="also write the results to this file")
    args = ap.parse_args(argv)
    rows = []
    cases = [("mixtures", 2.0, lambda: make_case(2.0, np.random.default_rng(0))),
             ("mixtures", 1.0, lambda: make_case(1.0, np.random.default_rng(0))),
             ("kernel_densities", 1.0, lambda: make_kernel_density_case(np.random.default_rng(0)))]
    for case, beta, make in cases:
        X, H, start = make()
        methods = {"ours": run_ours, "ours_start_200": run_ours_from_updates(200), "lbfgsb": run_lbfgs}
        if beta == 2.0:
            methods["scipy_nnls"] = run_nnls
        else:
            methods["sklearn_mu_200"] = run_sklearn_mu(200)
            methods["sklearn_mu_2000"] = run_sklearn_mu(2000)
        times: dict[str, list[float]] = {name: [] for name in methods}
        answers: dict = {}
        with threadpool_limits(1):
            for _ in range(args.repeats):
                for name, method in methods.items():
                    dt, W, info = method(X, H, start, beta)
                    times[name].append(dt)
                    answers[name] = (W, info)
        rows_f = {name: objective(X, H, W, beta) for name, (W, _) in answers.items()}
        # a row whose objective is not finite (a cell with x > 0 left without a product) is counted apart; the
        # excess is over the rows every method leaves finite
        finite = np.logical_and.reduce([np.isfinite(v) for v in rows_f.values()])
        f = {name: v[finite].sum() for name, v in rows_f.items()}
        best = min(f.values())
        row_best = np.min([v[finite] for v in rows_f.values()], axis=0)
        ours = float(np.median(times["ours"]))
        for name in methods:
            med = float(np.median(times[name]))
            row = dict(case=case, beta=beta, method=name, seconds=med, ratio_to_ours=med / ours,
                       excess=float((f[name] - best) / best),
                       worst_row_excess=float(np.max((rows_f[name][finite] - row_best) / row_best)),
                       nonfinite_rows=int((~np.isfinite(rows_f[name])).sum()), **answers[name][1])
            rows.append(row)
            print(f"{case:16s} beta={beta:3.1f} {name:16s} {1e3 * med:9.1f} ms  {med / ours:6.2f}x ours   excess "
                  f"{row['excess']:9.2e}  worst row {row['worst_row_excess']:8.1e}  rows not finite "
                  f"{row['nonfinite_rows']:3d}  {answers[name][1] or ''}")
    if args.json:
        with open(args.json, "w") as out:
            json.dump(dict(rows=rows, mmconcepts=mmconcepts.__version__, numpy=np.__version__,
                           scipy=scipy.__version__, sklearn=sklearn.__version__, python=platform.python_version(),
                           repeats=args.repeats), out, indent=1)


if __name__ == "__main__":
    main()
