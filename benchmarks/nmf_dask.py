"""Benchmark: distributed and out-of-core beta-NMF (mmconcepts.nmf on dask arrays, issue 16).

Two measurements, each compared with a reference in the same run (ratios, not timed tests):

``outofcore``
    A sparse matrix of HAC-like counts (default 2 000 000 x 110 000, 0.05 % nonzeros, about
    1.3 GB of nonzeros) is written to disk as a folder of ``.npz`` chunks and fitted with
    ``beta_nmf_out_of_core`` (k = 50, KL, 10 iterations, synchronous scheduler: one chunk at a
    time), in a child process whose peak resident memory is read from ``getrusage``. The
    reference is the in-memory ``beta_nmf`` of a row slice that fits (``--slice-rows``), and the
    out-of-core fit of that same slice, each in its own child process: time per iteration and
    peak memory.
``scaling``
    The sparse KL case of ``benchmarks/nmf.py`` grown 10x (200 000 x 2 000, 1 % nonzeros,
    k = 50), persisted on a ``LocalCluster`` (the one ``--scheduler local:N`` starts,
    ``mmconcepts.engine.cluster.local_cluster``: 127.0.0.1, worker processes with one thread, numba
    and BLAS on one thread) of 1 and of 2 workers, fitted in alternation ``--repeats`` times with
    the in-memory ``beta_nmf`` in this process (one thread) as the reference (``--clusters one``,
    the default: each fit on a cluster started for it alone and warmed up by a 2-iteration fit;
    ``both``: the two clusters up through all the fits, each fit beside the other's idle
    processes): median time per
    iteration (the fit's iterations, the objective's evaluations at the first and the last included,
    over the number of iterations; not the set-up), the ratio, and the bytes moved per iteration
    (the model: H to every chunk and each chunk's numerator/denominator back, an upper bound; and
    the worker-to-worker transfers the workers logged during the iterations). From those, the
    projected time per iteration on 8, 32 and 128 machines. Also the CPU this process (client,
    scheduler, nannies) takes per iteration, and what the idle cluster of 2 workers takes per
    second (this process and each worker, over 5 s before the fits): on a machine with as many
    cores as workers, that time is taken from the workers.

Run:  .venv/bin/python benchmarks/nmf_dask.py [--quick] [--cases outofcore scaling] [--json out.json]
      (--quick: 50 000 x 11 000 out of core, 20 000 x 2 000 scaling, 3 iterations: about a minute on an
      idle machine)
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

SINGLE_THREAD_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                     "MKL_NUM_THREADS": "1"}


# ---------------------------------------------------------------------------------------------- data


def hac_like_chunks(n: int, m: int, density: float, chunk_rows: int, seed: int = 0):
    """Row chunks of a sparse count matrix: Zipf-like column popularity, Poisson(1) + 1 counts.

    Each chunk comes from its own stream (SeedSequence(seed).spawn), so any slice of rows can be
    regenerated alone. HAC histograms of speech are counts of co-occurring codewords: a few
    codewords are frequent, most rare; the column weights follow 1 / rank ** 0.7.
    """
    weights = 1.0 / np.arange(1, m + 1) ** 0.7
    cdf = np.cumsum(weights / weights.sum())
    perm = np.random.default_rng(seed).permutation(m)  # frequent columns are not the first ones
    per_row = density * m
    for c, ss in enumerate(np.random.SeedSequence(seed).spawn((n + chunk_rows - 1) // chunk_rows)):
        rng = np.random.default_rng(ss)
        rows = min(chunk_rows, n - c * chunk_rows)
        counts = rng.poisson(per_row, rows)
        nnz = int(counts.sum())
        cols = perm[np.minimum(np.searchsorted(cdf, rng.random(nnz)), m - 1)]
        indptr = np.concatenate(([0], np.cumsum(counts)))
        X = sp.csr_matrix((rng.poisson(1.0, nnz) + 1.0, cols, indptr), shape=(rows, m))
        X.sum_duplicates()  # a repeated codeword adds up
        yield X


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


# ---------------------------------------------------------------------------------------------- children


def child_outofcore(folder: str, out: str, k: int, iterations: int) -> dict:
    """Out-of-core fit of a folder (synchronous scheduler); time of each pass over the chunks."""
    import dask

    from mmconcepts.nmf import _dask as nd

    passes: list[float] = []
    inner = nd._objective_pass

    def timed(*args, **kwargs):
        t = time.perf_counter()
        res = inner(*args, **kwargs)
        passes.append(time.perf_counter() - t)
        return res

    nd._objective_pass = timed
    before = peak_rss_mb()
    t = time.perf_counter()
    with dask.config.set(scheduler="synchronous"):
        res = nd.beta_nmf_out_of_core(folder, k, out=out, beta_loss=1.0, init="random", random_state=0,
                                      max_iter=iterations, tol=0, loss_every=iterations)
    total = time.perf_counter() - t
    return dict(total_s=total, pass_s=passes, iteration_s=statistics.median(passes[:iterations]),
                final_loss=float(res.loss_history[-1]), peak_rss_mb=peak_rss_mb(), rss_before_fit_mb=before,
                n_chunks=int(res.extra["n_chunks"]))


def child_inmemory(folder: str, rows: int, k: int, iterations: int) -> dict:
    """In-memory fit of the first ``rows`` rows of a folder of chunks (read chunk by chunk, then stacked)."""
    from mmconcepts.nmf import _dask as nd
    from mmconcepts.nmf import beta_nmf

    X = nd.load_npz_chunks(folder)[:rows].compute()
    X = sp.csr_matrix(X)
    beta_nmf(X[:200], k, beta_loss=1.0, init="random", random_state=0, max_iter=1, tol=0)  # compile first
    t = time.perf_counter()
    res = beta_nmf(X, k, beta_loss=1.0, init="random", random_state=0, max_iter=iterations, tol=0,
                   loss_every=iterations)
    total = time.perf_counter() - t
    return dict(total_s=total, iteration_s=total / iterations, final_loss=float(res.loss_history[-1]),
                peak_rss_mb=peak_rss_mb(), nnz=int(X.nnz))


def _run_child(kind: str, payload: dict, threads: int) -> dict:
    cmd = [sys.executable, os.path.abspath(__file__), "--child", kind, json.dumps(payload)]
    env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads),
           "OPENBLAS_NUM_THREADS": str(threads)}
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------------------------- cases


def case_outofcore(args) -> dict:
    from mmconcepts.nmf import _dask as nd

    root = tempfile.mkdtemp(prefix="mmc-ooc-", dir=args.tmp)
    try:
        t = time.perf_counter()
        folder = nd.save_npz_chunks(hac_like_chunks(args.rows, args.cols, args.density, args.chunk_rows),
                                    os.path.join(root, "X"))
        write_s = time.perf_counter() - t
        disk = sum(os.path.getsize(os.path.join(folder, f)) for f in os.listdir(folder))
        print(f"outofcore: wrote {args.rows} x {args.cols} ({disk / 2**30:.2f} GiB on disk) in {write_s:.0f} s",
              flush=True)
        slice_folder = os.path.join(root, "Xslice")
        nd.save_npz_chunks(hac_like_chunks(args.slice_rows, args.cols, args.density, args.chunk_rows),
                           slice_folder)  # the same rows as the first slice_rows of X (same streams)
        payload = dict(k=args.k, iterations=args.iterations)
        mem = _run_child("inmemory", dict(payload, folder=str(folder), rows=args.slice_rows), args.threads)
        print(f"  in memory, {args.slice_rows} rows ({mem['nnz']} nonzeros): {mem['iteration_s']:.2f} s/it, "
              f"peak {mem['peak_rss_mb']:.0f} MB", flush=True)
        ooc_slice = _run_child("outofcore", dict(payload, folder=slice_folder, out=os.path.join(root, "Wslice")), args.threads)
        print(f"  out of core, same slice: {ooc_slice['iteration_s']:.2f} s/it, peak {ooc_slice['peak_rss_mb']:.0f} MB"
              f" (loss rel. diff to in memory {abs(ooc_slice['final_loss'] - mem['final_loss']) / mem['final_loss']:.1e})",
              flush=True)
        full = _run_child("outofcore", dict(payload, folder=str(folder), out=os.path.join(root, "W")), args.threads)
        print(f"  out of core, all {args.rows} rows: {full['iteration_s']:.2f} s/it over {full['n_chunks']} chunks, "
              f"peak {full['peak_rss_mb']:.0f} MB, total {full['total_s']:.0f} s", flush=True)
        return dict(case="outofcore", threads=args.threads, rows=args.rows, cols=args.cols, density=args.density, k=args.k,
                    iterations=args.iterations, chunk_rows=args.chunk_rows, disk_bytes=disk, write_s=write_s,
                    slice_rows=args.slice_rows, inmemory_slice=mem, outofcore_slice=ooc_slice, outofcore_full=full,
                    slice_overhead=ooc_slice["iteration_s"] / mem["iteration_s"],
                    full_vs_slice_per_row=(full["iteration_s"] / args.rows) / (mem["iteration_s"] / args.slice_rows))
    finally:
        shutil.rmtree(root, ignore_errors=True)


def case_scaling(args) -> dict:
    import dask
    import dask.array as da
    import distributed

    from mmconcepts.engine.cluster import local_cluster
    from mmconcepts.nmf import _dask as nd
    from mmconcepts.nmf import beta_nmf

    loops: list[tuple[float, float, float]] = []
    inner = nd._fit_loop
    current: dict = {}

    def timed(*a, **kw):  # time the iterations (not the checks and set-up of the fit, nor the final W's scaling)
        client = current["client"]
        before = sum(client.run(_transfer_bytes).values())
        cpu = _process_cpu()
        t = time.perf_counter()
        res = inner(*a, **kw)
        elapsed = time.perf_counter() - t
        cpu = _process_cpu() - cpu  # this process: the client, the scheduler and the nannies
        loops.append((elapsed, sum(client.run(_transfer_bytes).values()) - before, cpu))
        return res

    n, m, k = args.scaling_rows, 2000, 50
    rng = np.random.default_rng(0)
    X = sp.random(n, m, density=0.01, format="csr", random_state=np.random.RandomState(0),
                  data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
    s = np.sqrt(X.mean() / k)
    W0 = np.abs(s * rng.standard_normal((n, k)))
    H0 = np.abs(s * rng.standard_normal((k, m)))
    chunk = n // args.scaling_chunks
    env = {**os.environ, **SINGLE_THREAD_ENV}
    old_env = dict(os.environ)
    os.environ.update(SINGLE_THREAD_ENV)  # inherited by the worker processes
    clusters: dict = {}

    def start(w: int):
        cluster = local_cluster(w, memory_limit="4GiB")  # the cluster `--scheduler local:N` starts
        return cluster, distributed.Client(cluster, set_as_default=False)

    def stop(pair) -> None:
        pair[1].close()
        pair[0].close()

    try:
        del env
        if args.clusters == "both":
            clusters = {w: start(w) for w in (1, 2)}
            idle = _idle_cpu(clusters[2][1], seconds=5.0)
        else:
            pair = start(2)
            try:
                idle = _idle_cpu(pair[1], seconds=5.0)
            finally:
                stop(pair)
        times: dict[int, list[float]] = {0: [], 1: [], 2: []}
        traffic: dict[int, list[float]] = {1: [], 2: []}
        client_cpu: dict[int, list[float]] = {1: [], 2: []}
        model = 0
        results = {}
        for rep in range(args.repeats + 1):  # the first round warms the workers up (numba compilation)
            its = 2 if rep == 0 else args.iterations
            with threadpool_limits(1), _numba_threads(1):  # the reference: beta_nmf in this process, one thread
                t = time.perf_counter()
                res = beta_nmf(X, k, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=its, tol=0, loss_every=its)
                if rep > 0:
                    times[0].append((time.perf_counter() - t) / its)
                    results[0] = float(res.loss_history[-1])
            for w in (1, 2):
                if args.clusters == "both":
                    cluster, client = clusters[w]
                else:  # this cluster alone on the machine, warmed up by a short fit (its workers load the kernels)
                    clusters[w] = start(w)
                    cluster, client = clusters[w]
                Xd = client.persist(da.from_array(X, chunks=(chunk, -1), asarray=False))
                with client.as_current():
                    distributed.wait(Xd)
                with dask.config.set(scheduler=client), warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message="Sending large graph")  # W0, once, at the start
                    if args.clusters == "one":
                        beta_nmf(Xd, k, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=2, tol=0, loss_every=2)
                    client.run(_reset_transfer_counters)
                    current["client"] = client
                    loops.clear()
                    nd._fit_loop = timed
                    try:
                        res = beta_nmf(Xd, k, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=its, tol=0,
                                       loss_every=its)
                    finally:
                        nd._fit_loop = inner
                if args.clusters == "one":
                    stop(clusters.pop(w))
                if rep > 0:
                    elapsed, moved, cpu = loops[0]
                    times[w].append(elapsed / its)
                    traffic[w].append(moved / its)  # the iterations' worker-to-worker bytes (set-up excluded)
                    client_cpu[w].append(cpu / its)
                    model = res.extra["bytes_per_iteration"]
                    results[w] = float(res.loss_history[-1])
        t0, t1, t2 = (statistics.median(times[w]) for w in (0, 1, 2))
        row = dict(case="scaling", shape=[n, m], k=k, nnz=int(X.nnz), chunks=args.scaling_chunks,
                   clusters=args.clusters, iterations=args.iterations, repeats=args.repeats, s_per_iter_in_memory=t0, s_per_iter_1=t1,
                   s_per_iter_2=t2, speedup_2_vs_1=t1 / t2, model_bytes_per_iter=model,
                   s_per_iter_all={str(w): v for w, v in times.items()},
                   worker_transfer_bytes_per_iter_1=statistics.median(traffic[1]),
                   worker_transfer_bytes_per_iter_2=statistics.median(traffic[2]),
                   loss_rel_diff_1_vs_2=abs(results[1] - results[2]) / results[1],
                   loss_rel_diff_1_vs_in_memory=abs(results[1] - results[0]) / results[0],
                   client_cpu_s_per_iter_1=statistics.median(client_cpu[1]),
                   client_cpu_s_per_iter_2=statistics.median(client_cpu[2]), idle_cpu_per_s=idle)
        print(f"scaling: {n} x {m}, {args.scaling_chunks} chunks: in memory {t0 * 1e3:.0f} ms/it, 1 worker "
              f"{t1 * 1e3:.0f} ms/it, 2 workers {t2 * 1e3:.0f} ms/it, speedup x{t1 / t2:.2f}; model "
              f"{model / 1e6:.1f} MB/it, worker-to-worker {row['worker_transfer_bytes_per_iter_2'] / 1e6:.1f} MB/it "
              "(2 workers)", flush=True)
        print(f"  CPU of this process (client, scheduler, nannies) per iteration: 1 worker "
              f"{row['client_cpu_s_per_iter_1'] * 1e3:.0f} ms, 2 workers {row['client_cpu_s_per_iter_2'] * 1e3:.0f} ms; "
              f"idle cluster of 2 workers, CPU-s per second: this process {idle['client']:.3f}, workers "
              + ", ".join(f"{v:.3f}" for v in idle["workers"]), flush=True)
        return row
    finally:
        for pair in clusters.values():
            stop(pair)
        os.environ.clear()
        os.environ.update(old_env)


def _process_cpu(pid: int | None = None) -> float:
    """User + system CPU seconds of a process so far (this one by default)."""
    import psutil

    times = psutil.Process(pid).cpu_times()
    return times.user + times.system


def _idle_cpu(client, seconds: float) -> dict:
    """CPU seconds per second that an idle cluster takes: this process (client, scheduler, nannies) and each worker
    process (heartbeats, monitors, the workers' sampling profiler), over ``seconds`` with no task."""
    pids = sorted(client.run(os.getpid).values())
    before = [_process_cpu()] + [_process_cpu(p) for p in pids]
    time.sleep(seconds)
    after = [_process_cpu()] + [_process_cpu(p) for p in pids]
    per_s = [(b - a) / seconds for a, b in zip(before, after)]
    return dict(client=per_s[0], workers=per_s[1:], seconds=seconds)


@contextlib.contextmanager
def _numba_threads(n: int):
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _reset_transfer_counters(dask_worker=None):
    dask_worker._mmc_base = _transfer_bytes(dask_worker)  # type: ignore[union-attr]


def _transfer_bytes(dask_worker=None) -> float:
    total = float(getattr(dask_worker, "transfer_outgoing_bytes_total", 0) or 0)
    return total - float(getattr(dask_worker, "_mmc_base", 0.0))


def project(row: dict, *, bandwidth: float, latency: float, machines=(8, 32, 128)) -> dict:
    """Time per iteration on p machines from the 1- and 2-worker measurements of the scaling case."""
    h_bytes = row["k"] * row["shape"][1] * 8
    part_bytes = max(row["model_bytes_per_iter"] / row["chunks"] - h_bytes, 0)
    overhead = max(row["s_per_iter_2"] - row["s_per_iter_1"] / 2, 0.0)
    return project_from(row["s_per_iter_1"], overhead, h_bytes, part_bytes, bandwidth=bandwidth, latency=latency,
                        machines=machines)


def project_from(t1: float, overhead: float, h_bytes: float, part_bytes: float, *, bandwidth: float, latency: float,
                 machines=(8, 32, 128)) -> dict:
    """compute(p) + overhead + communication(p) for one iteration on p machines.

    compute(p) = t1 / p: the chunk work divides (at least one chunk per machine); ``overhead`` is
    what the 2-worker run showed beyond t1 / 2 (scheduling, serialisation, waiting for the slowest
    chunk), taken as constant. Communication, as the fit places its tasks (contiguous chunks per
    machine, the first sums within a machine): the chunks' numerators/denominators
    (``part_bytes`` each, k x n_features) summed up a tree of fan-in 8 over the machines
    (ceil(log8 p) levels, each reducer receiving 8 of them), and the new H (k x n_features,
    ``h_bytes``) sent down a tree of the same fan-out (each level: a machine sends it to 8
    others), at ``bandwidth`` bytes/s and ``latency`` per message. ``flat_broadcast_s`` is the time
    with H fetched by every machine from the one that computed it (p messages from one link).
    """
    import math

    out = {}
    for p in machines:
        levels = max(1, math.ceil(math.log(p, 8)))
        reduce_s = levels * (8 * part_bytes / bandwidth + latency)
        comm = levels * (8 * h_bytes / bandwidth + latency) + reduce_s
        flat_comm = p * (h_bytes / bandwidth + latency) + reduce_s
        compute = t1 / p
        out[str(p)] = dict(compute_s=compute, overhead_s=overhead, comm_s=comm, s_per_iter=compute + overhead + comm,
                           flat_broadcast_s=compute + overhead + flat_comm)
    return out


# ---------------------------------------------------------------------------------------------- main


def _print_projections(rows: list, args) -> None:
    sc = next((r for r in rows if r["case"] == "scaling"), None)
    if sc is not None:
        sc["projection"] = project(sc, bandwidth=args.bandwidth, latency=args.latency)
        for p, v in sc["projection"].items():
            print(f"  scaling case projected on {p:>3} machines: {v['s_per_iter'] * 1e3:.0f} ms/it "
                  f"(compute {v['compute_s'] * 1e3:.0f}, overhead {v['overhead_s'] * 1e3:.0f}, "
                  f"communication {v['comm_s'] * 1e3:.0f}; {v['flat_broadcast_s'] * 1e3:.0f} ms/it with H fetched "
                  "from one machine)")
    ooc = next((r for r in rows if r["case"] == "outofcore"), None)
    if ooc is not None:  # the out-of-core problem on p machines, its chunks in their memory
        overhead = max(sc["s_per_iter_2"] - sc["s_per_iter_1"] / 2, 0.0) if sc else 0.0
        h = ooc["k"] * ooc["cols"] * 8
        ooc["projection"] = project_from(ooc["outofcore_full"]["iteration_s"], overhead, h, h + ooc["k"] * 8,
                                         bandwidth=args.bandwidth, latency=args.latency)
        for p, v in ooc["projection"].items():
            print(f"  out-of-core problem projected on {p:>3} machines: {v['s_per_iter']:.1f} s/it "
                  f"(compute {v['compute_s']:.1f}, communication {v['comm_s']:.1f}; "
                  f"{v['flat_broadcast_s']:.1f} s/it with H fetched from one machine)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=["outofcore", "scaling"])
    ap.add_argument("--quick", action="store_true", help="small sizes, 3 iterations (under a minute)")
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--cols", type=int, default=110_000)
    ap.add_argument("--density", type=float, default=0.0005)
    ap.add_argument("--k", type=int, default=50)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--chunk-rows", type=int, default=50_000)
    ap.add_argument("--slice-rows", type=int, default=200_000)
    ap.add_argument("--scaling-rows", type=int, default=200_000)
    ap.add_argument("--scaling-chunks", type=int, default=16)
    ap.add_argument("--clusters", choices=["one", "both"], default="one",
                    help="scaling: start each fit's cluster alone, warm it up, close it after (one, the default), or "
                         "keep the 1- and 2-worker clusters up through all the fits (both: each fit shares the "
                         "machine with the other cluster's idle processes)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--bandwidth", type=float, default=1.25e9, help="bytes/s between machines (10 GbE)")
    ap.add_argument("--latency", type=float, default=5e-4, help="seconds per message")
    ap.add_argument("--threads", type=int, default=1,
                    help="numba/BLAS threads of the out-of-core and in-memory children (default 1)")
    ap.add_argument("--tmp", default=None, help="folder for the data on disk (default: the system's)")
    ap.add_argument("--json", help="also write the results to this file")
    ap.add_argument("--project", nargs="+", metavar="JSON",
                    help="only print the projections from results saved with --json")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        kind, payload = args.child[0], json.loads(args.child[1])
        fn = {"outofcore": child_outofcore, "inmemory": child_inmemory}[kind]
        print(json.dumps(fn(**payload)))
        return None
    if args.quick:
        args.rows, args.cols, args.chunk_rows, args.slice_rows = 50_000, 11_000, 10_000, 20_000
        args.scaling_rows, args.scaling_chunks, args.iterations, args.repeats = 20_000, 8, 3, 1
    if args.project:  # projections from saved results (e.g. the two cases run at different times)
        rows = [r for f in args.project for r in json.load(open(f))["results"]]
        _print_projections(rows, args)
        return rows
    load = os.getloadavg()
    print(f"load average before: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores", flush=True)
    rows = []
    if "outofcore" in args.cases:
        rows.append(case_outofcore(args))
    if "scaling" in args.cases:
        rows.append(case_scaling(args))
    _print_projections(rows, args)
    import dask

    import mmconcepts

    meta = dict(mmconcepts=mmconcepts.__version__, dask=dask.__version__, numpy=np.__version__,
                python=platform.python_version(), machine=platform.machine(), cpus=os.cpu_count(),
                loadavg_before=load, loadavg_after=os.getloadavg(), quick=args.quick)
    print(f"load average after: {meta['loadavg_after'][0]:.1f}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(meta=meta, results=rows), fh, indent=2)
    return rows


if __name__ == "__main__":
    main()
