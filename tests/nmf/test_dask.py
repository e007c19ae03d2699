"""Distributed and out-of-core beta-NMF (nmf/_dask.py) against the in-memory solver.

The outside answer is the in-memory :func:`beta_nmf` on the whole matrix: from the same start,
the iterates of the chunked solver must equal its iterates to 1e-10 (relative), for beta in
{0, 0.5, 1, 2}, dense and sparse, with and without a mask.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
import weakref

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

dask = pytest.importorskip("dask")
da = pytest.importorskip("dask.array")

from mmconcepts.errors import ClusterError, DataError, DataFormatError, ParameterError  # noqa: E402
from mmconcepts.nmf import NMF, beta_nmf  # noqa: E402
from mmconcepts.nmf import _dask as nd  # noqa: E402

ROW_CHUNKS = (23, 40, 1, 36)  # uneven, one single-row chunk
N, M, K = sum(ROW_CHUNKS), 17, 4
RTOL = 1e-10


@pytest.fixture(autouse=True)
def _synchronous_and_one_numba_thread():
    """The synchronous scheduler (deterministic, in this thread), numba kernels on one thread.

    numba's parallel kernels on tiny chunks cost more in thread wake-ups than in work on a busy
    machine; the results do not depend on the number of threads (rows are independent).
    """
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    with dask.config.set(scheduler="synchronous"):
        yield
    numba.set_num_threads(before)


def rel(a, b) -> float:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def make_data(rng, sparse: bool, beta: float, masked: bool):
    if sparse:
        X = sp.random(N, M, density=0.35, format="csr", random_state=np.random.RandomState(1),
                      data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
        if beta <= 0:  # beta <= 0 needs positive observed cells
            X = sp.csr_matrix(X.toarray() + 0.25)
    else:
        X = rng.poisson(2.0, (N, M)).astype(np.float64) + (0.25 if beta <= 0 else 0.0)
    mask = rng.random((N, M)) > 0.25 if masked else None
    if masked and not sparse:
        X = X.copy()
        X[~mask] = np.nan  # unobserved cells may hold anything
    W0 = rng.random((N, K)) + 0.1
    H0 = rng.random((K, M)) + 0.1
    return X, mask, W0, H0


def two_hundred_rows():
    """A sparse X of 200 rows and a start (W0, H0), the same in every call: for fits split into many chunks."""
    X = sp.random(200, M, density=0.3, format="csr", random_state=np.random.RandomState(3)) * 10.0
    gen = np.random.default_rng(5)
    return X, gen.random((200, K)) + 0.1, gen.random((K, M)) + 0.1


def to_dask(X, chunks=ROW_CHUNKS):
    return da.from_array(X, chunks=(chunks, -1), asarray=not sp.issparse(X))


def assert_same_fit(r_mem, r_dask, tol=RTOL):
    W = r_dask.W.compute() if nd.is_dask_array(r_dask.W) else r_dask.W
    assert isinstance(r_dask.H, np.ndarray)
    assert rel(W, r_mem.W) < tol
    assert rel(r_dask.H, r_mem.H) < tol
    assert list(r_dask.loss_iterations) == list(r_mem.loss_iterations)
    assert rel(r_dask.loss_history, r_mem.loss_history) < tol
    assert r_dask.n_iter == r_mem.n_iter and r_dask.converged == r_mem.converged


# ------------------------------------------------------------------------------ equality


@pytest.mark.parametrize("masked", [False, True], ids=["nomask", "mask"])
@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0, 2.0])
def test_same_iterates_as_in_memory(rng, beta, sparse, masked):
    X, mask, W0, H0 = make_data(rng, sparse, beta, masked)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=beta, max_iter=12, tol=0, loss_every=5)
    r_mem = beta_nmf(X, K, mask=mask, **kw)
    r_dask = beta_nmf(to_dask(X), K, mask=None if mask is None else to_dask(mask), **kw)
    assert r_dask.W.chunks == (ROW_CHUNKS, (K,))
    assert_same_fit(r_mem, r_dask)
    assert list(r_mem.loss_iterations) == [0, 5, 10, 12]


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cuts=st.lists(st.integers(0, N), min_size=0, max_size=5), beta=st.sampled_from([0.5, 1.0, 2.0]),
       sparse=st.booleans())
@example(cuts=[N, 50], beta=1.0, sparse=True)  # an empty last chunk
@example(cuts=[], beta=2.0, sparse=False)  # one chunk
def test_any_row_chunking_gives_the_same_fit(cuts, beta, sparse):
    """Property: however X is cut into row chunks (empty chunks included), the fit is the in-memory one."""
    bounds = sorted({0, N, *cuts}) + ([N] if N in cuts else [])  # a repeated cut at N gives an empty last chunk
    chunks = tuple(b - a for a, b in zip(bounds[:-1], bounds[1:]))
    X, mask, W0, H0 = make_data(np.random.default_rng(len(cuts)), sparse, beta, True)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=beta, max_iter=4, tol=0, loss_every=2)
    r_mem = beta_nmf(X, K, mask=mask, **kw)
    r_dask = beta_nmf(to_dask(X, chunks), K, mask=to_dask(mask, chunks), **kw)
    assert r_dask.W.chunks[0] == chunks
    assert_same_fit(r_mem, r_dask)


def test_chunk_with_no_observed_cell(rng):
    """A mask chunk that observes nothing is valid (only a mask observing nothing at all is refused)."""
    X, mask, W0, H0 = make_data(rng, False, 1.0, True)
    mask[23:63] = False  # the whole second chunk
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=5, tol=0)
    r_mem = beta_nmf(X, K, mask=mask, **kw)
    r_dask = beta_nmf(to_dask(X), K, mask=to_dask(mask), **kw)
    assert_same_fit(r_mem, r_dask)
    with pytest.raises(DataError, match="observes no cell"):
        beta_nmf(to_dask(X), K, mask=to_dask(np.zeros_like(mask)), **kw)


@pytest.mark.parametrize("beta, update_rule", [(0.5, "heuristic"), (3.0, "mm"), (1.0, "mm")])
def test_same_iterates_update_rules_penalties_stopping(rng, beta, update_rule):
    """Heuristic / MM exponents, L1+L2 penalties, and the stopping rule (tol > 0) stop at the same iteration."""
    X, _, W0, H0 = make_data(rng, True, beta, False)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=beta, update_rule=update_rule, max_iter=200, tol=1e-3,
              loss_every=3, alpha_W=0.01, alpha_H=0.02, l1_ratio=0.3)
    r_mem = beta_nmf(X, K, **kw)
    r_dask = beta_nmf(to_dask(X), K, **kw)
    assert r_mem.converged and r_mem.n_iter < 200
    assert_same_fit(r_mem, r_dask)


def test_same_random_start_and_rescaled_data(rng):
    """init='random' draws H then W chunk by chunk from one stream: the start of the in-memory fit.

    X far from 1 goes through the power-of-two rescaling of beta_nmf (scale computed from the chunks' maxima).
    """
    X = rng.poisson(2.0, (N, M)).astype(np.float64) * 2.0**40
    kw = dict(init="random", random_state=7, beta_loss=1.0, max_iter=8, tol=0, loss_every=4)
    r_mem = beta_nmf(X, K, **kw)
    r_dask = beta_nmf(to_dask(X), K, **kw)
    assert_same_fit(r_mem, r_dask)
    assert r_mem.loss_history[0] > 1e10  # in X's units


def test_max_iter_zero_and_float32(rng):
    X, _, W0, H0 = make_data(rng, False, 1.0, False)
    r = beta_nmf(to_dask(X), K, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=0, tol=0)
    assert r.n_iter == 0 and rel(r.W.compute(), W0) == 0 and rel(r.H, H0) == 0
    X32, W32, H32 = X.astype(np.float32), W0.astype(np.float32), H0.astype(np.float32)
    kw = dict(init="custom", W=W32, H=H32, beta_loss=0.5, max_iter=15, tol=0)
    r_mem = beta_nmf(X32, K, **kw)
    r_dask = beta_nmf(to_dask(X32), K, **kw)
    assert r_dask.H.dtype == np.float32 and r_dask.W.dtype == np.float32 and r_dask.W.compute().dtype == np.float32
    assert rel(r_dask.W.compute(), r_mem.W) < 1e-4 and rel(r_dask.H, r_mem.H) < 1e-4


def test_nndsvd_start_from_dask_svd(rng):
    """NNDSVD from dask's randomized SVD: not the in-memory start, but an SVD start as good as it."""
    X = sp.random(N, M, density=0.4, format="csr", random_state=np.random.RandomState(3),
                  data_rvs=lambda size: rng.poisson(3.0, size) + 1.0)
    for init in ("nndsvd", "nndsvda", "nndsvdar"):
        r_mem = beta_nmf(X, K, init=init, random_state=0, beta_loss=2.0, max_iter=0)
        r_dask = beta_nmf(to_dask(X), K, init=init, random_state=0, beta_loss=2.0, max_iter=0)
        assert r_dask.loss_history[0] == pytest.approx(r_mem.loss_history[0], rel=0.02)
        assert (r_dask.H >= 0).all() and (r_dask.W.compute() >= 0).all()
    with pytest.raises(ParameterError, match="n_components <= min"):
        beta_nmf(to_dask(X), M + 1, init="nndsvd")


def _blocks(rng):
    """Three diagonal blocks over the chunks, of decreasing weight: NNDSVD's two components miss the third."""
    from scipy.linalg import block_diag

    return block_diag(rng.random((60, 10)) + 1.0, rng.random((30, 5)) + 0.5, rng.random((10, 2)) + 0.2)


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_nndsvd_start_from_dask_reaches_every_cell(rng, beta):
    """As in memory: NNDSVD's zeros that leave W @ H zero where X > 0 are filled, so the KL objective is finite."""
    X = _blocks(rng)
    start = beta_nmf(to_dask(X), 2, init="nndsvd", beta_loss=beta, random_state=0, max_iter=0)
    assert ((start.W.compute() @ start.H)[X > 0] > 0).all()
    res = beta_nmf(to_dask(X), 2, init="nndsvd", beta_loss=beta, random_state=0, max_iter=20, tol=0, loss_every=1)
    assert np.isfinite(res.loss_history).all() and res.loss_history[-1] < res.loss_history[0]


@pytest.mark.parametrize("case", ["W row", "H column", "fixed H", "W zero"])
def test_a_given_start_the_fit_cannot_leave_is_refused_as_in_memory(rng, case):
    X = _blocks(rng)
    W, H = rng.random((N, 2)) + 0.1, rng.random((2, M)) + 0.1
    kw = dict(beta_loss=1.0, max_iter=5)
    if case == "W row":
        W[70] = 0.0  # in the last chunk (its rows start at 64)
    elif case == "H column":
        H[:, 12] = 0.0
    elif case == "fixed H":
        H[:, 12] = 0.0
        kw["update_H"] = False
    else:
        W[:] = 0.0
    with pytest.raises(DataError) as mem:
        beta_nmf(X, 2, W=W, H=H, **kw)
    with pytest.raises(DataError) as dist:
        beta_nmf(to_dask(X), 2, W=W, H=H, **kw)
    assert str(dist.value) == str(mem.value)


# ------------------------------------------------------------------------------ the estimator


def test_estimator_fit_transform_transform_features_mask(rng):
    X, mask, W0, H0 = make_data(rng, True, 1.0, True)
    Xd, Md = to_dask(X), to_dask(mask)
    a = NMF(K, beta_loss=1.0, init="custom", max_iter=10, tol=0)
    b = NMF(K, beta_loss=1.0, init="custom", max_iter=10, tol=0)
    Wa = a.fit_transform(X, mask=mask, W=W0, H=H0)
    Wb = b.fit_transform(Xd, mask=Md, W=W0, H=H0)
    assert nd.is_dask_array(Wb) and Wb.chunks[0] == ROW_CHUNKS
    assert isinstance(b.components_, np.ndarray)
    assert rel(Wb.compute(), Wa) < RTOL and rel(b.components_, a.components_) < RTOL
    assert b.reconstruction_err_ == pytest.approx(a.reconstruction_err_, rel=1e-10)
    # transform with a feature subset, a mask, and a dead column (every atom zero there)
    b.components_[:, 3] = 0.0
    a.components_ = b.components_.copy()
    cols = np.r_[1:9, 12]
    for m_mem, m_dask in ((None, None), (mask[:, cols], to_dask(mask[:, cols])), (mask[:, cols], mask[:, cols])):
        Ta = a.transform(X[:, cols], features=cols, mask=m_mem)
        Tb = b.transform(to_dask(X[:, cols]), features=cols, mask=m_dask)
        assert nd.is_dask_array(Tb) and Tb.chunks[0] == ROW_CHUNKS
        assert rel(Tb.compute(), Ta) < RTOL
    R = b.inverse_transform(Tb, features=[0, 2])
    assert nd.is_dask_array(R) and rel(R.compute(), a.inverse_transform(Ta, features=[0, 2])) < RTOL


def test_transform_stopping_rule_matches(rng):
    X, _, _, _ = make_data(rng, False, 0.5, False)
    model = NMF(K, beta_loss=0.5, init="random", random_state=0, max_iter=30, tol=0).fit(X)
    model.set_params(tol=1e-2, max_iter=500, loss_every=4)
    Ta = model.transform(X)
    Tb = model.transform(to_dask(X)).compute()
    assert rel(Tb, Ta) < RTOL


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("tol, max_iter, batches", [(0.0, 6, {4, 6}), (0.1, 12, {4, 8}), (0.0, 0, {0})],
                         ids=["to_max_iter", "stops", "no_iteration"])
def test_local_cluster_equals_in_memory(rng, tol, max_iter, batches):
    """A LocalCluster of two single-threaded workers (threads, 127.0.0.1): the same fit, bit for bit the fit of the
    synchronous scheduler (the workers send each other their sums and add them up in chunk order), one task per
    worker and batch of iterations (iterations 0 to the second check, then from one check to the next), each on
    its worker, contiguous rows per worker; a fit that stops at a check returns that check's (W, H)."""
    distributed = pytest.importorskip("distributed")
    X, mask, W0, H0 = make_data(rng, True, 1.0, True)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=max_iter, tol=tol, loss_every=4)
    r_mem = beta_nmf(X, K, mask=mask, **kw)
    r_sync = beta_nmf(to_dask(X), K, mask=to_dask(mask), **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, host="127.0.0.1", protocol="tcp://",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        Xd = client.persist(to_dask(X))
        Md = client.persist(to_dask(mask))
        with dask.config.set(scheduler=client), distributed.get_task_stream(client) as stream:
            r_dask = beta_nmf(Xd, K, mask=Md, **kw)
            W = r_dask.W.compute()
            assert_same_fit(r_mem, r_dask)
        workers = sorted(client.nthreads())
        assert _fit_keys_left(client, ("-host-",), wait=10.0) == []  # the workers' states, once W is read from them
        assert len(_fit_keys_left(client, ("-w-",), wait=0.0)) == len(ROW_CHUNKS)  # W's chunks
        assert r_dask.converged == (tol > 0) and r_dask.n_iter == max(batches)
        assert np.array_equal(W, r_sync.W.compute()) and np.array_equal(r_dask.H, r_sync.H)
        assert np.array_equal(r_dask.loss_history, r_sync.loss_history)
        del r_dask
        assert _fit_keys_left(client, ("-w-",), wait=10.0) == []
    assert nd._MAILBOXES == {}  # (the workers were threads of this process)
    ran: dict = {}
    seen = set()
    names = [task["key"] if isinstance(task["key"], str) else task["key"][0] for task in stream.data]
    for name, task in zip(names, stream.data):
        if "-host-" in name:
            q, j = name.rsplit("-", 2)[1:]
            ran.setdefault(int(j), set()).add(task["worker"])
            seen.add(int(q))
    # ROW_CHUNKS = (23, 40, 1, 36): the middle of chunk 1 (row 43) is in the first half of the 100 rows, so
    # chunks 0 and 1 go to the first worker, 2 and 3 to the second, in every batch
    assert ran == {0: {workers[0]}, 1: {workers[1]}}
    assert seen == batches and sum("-host-" in n for n in names) == 2 * len(batches)
    assert not any("-run-" in n or "-sum" in n for n in names)  # no task per iteration


def _fit_keys_left(client, parts, wait: float) -> list:
    """The keys of the scheduler's tasks whose names hold one of ``parts``, after up to ``wait`` seconds for them to go."""
    import time

    deadline = time.monotonic() + wait
    while True:
        keys = client.run_on_scheduler(lambda dask_scheduler: [str(k) for k in dask_scheduler.tasks])
        left = [k for k in keys if any(p in k for p in parts)]
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.05)


def test_the_scheduler_graph_on_a_cluster_when_chosen(rng):
    """``mmconcepts.nmf.exchange: scheduler``: the graph of tasks per iteration on a cluster of two workers (the same
    numbers, bit for bit); a value that is neither choice is refused."""
    distributed = pytest.importorskip("distributed")
    X, _, W0, H0 = make_data(rng, True, 1.0, False)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=5, tol=0, loss_every=3)
    r_sync = beta_nmf(to_dask(X), K, **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, host="127.0.0.1",
                                  protocol="tcp://", dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        Xd = client.persist(to_dask(X))
        with dask.config.set({"scheduler": client, nd.EXCHANGE_CONFIG: "scheduler"}), \
                distributed.get_task_stream(client) as stream:
            r_dask = beta_nmf(Xd, K, **kw)
            assert np.array_equal(r_dask.W.compute(), r_sync.W.compute()) and np.array_equal(r_dask.H, r_sync.H)
        names = [str(task["key"]) for task in stream.data]
        assert any("-run-" in n for n in names) and not any("-host-" in n for n in names)
        with dask.config.set({"scheduler": client, nd.EXCHANGE_CONFIG: "tree"}), \
                pytest.raises(ParameterError, match="'workers' or 'scheduler'"):
            beta_nmf(Xd, K, **kw)


def test_worker_processes_exchange_their_sums():
    """Two worker processes: the sums go between processes (the workers' handlers); ten chunks in four groups of the
    tree (fan-in 3), one of them on both workers: the fit is the synchronous scheduler's, bit for bit."""
    distributed = pytest.importorskip("distributed")
    X, W0, H0 = two_hundred_rows()
    kw = dict(init="custom", W=W0, H=H0, beta=1.0, max_iter=5, tol=0, loss_every=2, split_every=3)
    Xd = da.from_array(X, chunks=(20, -1), asarray=False)
    r_sync = nd.beta_nmf_dask(Xd, K, **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        with dask.config.set(scheduler=client), distributed.get_task_stream(client) as stream:
            r_dask = nd.beta_nmf_dask(client.persist(Xd), K, **kw)
            W = r_dask.W.compute()
        hosts = {task["worker"] for task in stream.data if "-host-" in str(task["key"])}
    assert len(hosts) == 2
    assert np.array_equal(W, r_sync.W.compute()) and np.array_equal(r_dask.H, r_sync.H)
    assert np.array_equal(r_dask.loss_history, r_sync.loss_history)


def test_a_worker_lost_during_the_fit_ends_it_with_cluster_error():
    """A worker process killed while the workers' tasks run (its nanny starts a new one at another address): the other
    worker, waiting for its sums, finds it gone and the fit raises ClusterError naming it, instead of waiting forever."""
    import os
    import signal
    import threading
    import time

    distributed = pytest.importorskip("distributed")
    X, W0, H0 = two_hundred_rows()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        Xd = client.persist(da.from_array(X, chunks=(50, -1), asarray=False))
        first, second = sorted(client.nthreads())
        killed = []

        def kill_when_the_tasks_run():
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                running = client.processing()
                if any("-host-" in str(key) for key in running.get(second, ())):
                    os.kill(client.run(os.getpid, workers=[second])[second], signal.SIGKILL)
                    killed.append(second)
                    return
                time.sleep(0.02)

        killer = threading.Thread(target=kill_when_the_tasks_run, daemon=True)
        killer.start()
        started = time.monotonic()
        with dask.config.set(scheduler=client), pytest.raises(ClusterError, match="left the cluster"):
            beta_nmf(Xd, K, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=100_000, tol=0, loss_every=100_000)
        killer.join(5)
        assert killed == [second] and time.monotonic() - started < 30  # not the 30 s of a connection to it


def test_the_workers_tasks_give_their_threads_back():
    """While the workers' tasks of a fit run (they wait for each other), a worker with one thread still runs other
    tasks: they secede from its thread pool, so fits that share single-threaded workers cannot wait for each other."""
    import threading
    import time

    distributed = pytest.importorskip("distributed")
    X, W0, H0 = two_hundred_rows()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, host="127.0.0.1",
                                  protocol="tcp://", dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        Xd = client.persist(da.from_array(X, chunks=(50, -1), asarray=False))
        first = sorted(client.nthreads())[0]
        seen: dict = {}

        def side_task_while_fitting():
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                if any("-host-" in str(key) for key in client.processing().get(first, ())):
                    seen["side"] = client.submit(np.add, 1, 2, workers=[first], pure=False).result(timeout=30)
                    seen["fit still running"] = any("-host-" in str(key) for keys in client.processing().values()
                                                    for key in keys)
                    return
                time.sleep(0.02)

        side = threading.Thread(target=side_task_while_fitting, daemon=True)
        side.start()
        with dask.config.set(scheduler=client):
            beta_nmf(Xd, K, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=1_000, tol=0, loss_every=1_000)
        side.join(30)
    assert seen == {"side": 3, "fit still running": True}


def test_an_error_on_one_worker_stops_the_others_and_is_raised(rng, monkeypatch):
    """The first worker's task fails at an iteration: the second, waiting for its sums, stops too, and the fit raises
    the first one's own error (not the second's stop)."""
    distributed = pytest.importorskip("distributed")
    X, _, W0, H0 = make_data(rng, True, 1.0, False)
    fit_run = nd._fit_run

    calls = {"n": 0}

    def failing_at_third(sources, prev, Ht, rule, specs, *args, **kwargs):
        if specs[0].index == 0:
            calls["n"] += 1
            if calls["n"] == 3:
                raise DataError("boom in chunk 0")
        return fit_run(sources, prev, Ht, rule, specs, *args, **kwargs)

    monkeypatch.setattr(nd, "_fit_run", failing_at_third)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, host="127.0.0.1",
                                  protocol="tcp://", dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        with dask.config.set(scheduler=client), pytest.raises(DataError, match="boom in chunk 0"):
            beta_nmf(client.persist(to_dask(X)), K, init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=6, tol=0,
                     loss_every=4)
        assert calls["n"] == 3


def test_a_mailbox_stops_waiting_when_a_worker_failed_or_left():
    """A worker's mailbox returns what another put (made by whichever comes first), raises ClusterError naming the
    worker whose task failed, asks whether its peers are still there while it waits, and is dropped at the end."""
    import asyncio

    asyncio.run(nd._put_handler("token", 0, "1-1", "parts"))  # before the task made it
    box = nd._Mailbox.of("token", 0)
    assert nd._Mailbox.of("token", 0) is box and nd._Mailbox.of("token", 1) is not box
    assert box.take("1-1", alive=lambda: None) == "parts"
    polls = []

    def gone():
        polls.append(1)
        if len(polls) == 2:
            raise ClusterError("worker left")

    with pytest.raises(ClusterError, match="worker left"):
        box.take("2-1", alive=gone, poll=0.01)
    box.put(nd._ABORT, ("tcp://w1", "DataError: boom"))
    with pytest.raises(ClusterError, match="tcp://w1 failed.*boom"):
        box.take("2-1", alive=lambda: None)
    nd._drop_mailboxes("token")
    assert not any(k[0] == "token" for k in nd._MAILBOXES)


def test_one_worker_fits_without_a_mailbox_and_hosts_alive_names_a_worker_that_left(rng):
    """A cluster of one worker: one task per batch, the synchronous scheduler's numbers, no mailbox left behind; the
    check that the other workers of a fit are still there names the one that is not."""
    distributed = pytest.importorskip("distributed")
    X, _, W0, H0 = make_data(rng, True, 1.0, False)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=5, tol=0, loss_every=3)
    r_sync = beta_nmf(to_dask(X), K, **kw)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, host="127.0.0.1",
                                  protocol="tcp://", dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        with dask.config.set(scheduler=client), distributed.get_task_stream(client) as stream:
            r_dask = beta_nmf(client.persist(to_dask(X)), K, **kw)
            assert np.array_equal(r_dask.W.compute(), r_sync.W.compute()) and np.array_equal(r_dask.H, r_sync.H)
        assert sum("-host-" in str(task["key"]) for task in stream.data) == 2  # iterations 0-3, then 4-5
        assert nd._MAILBOXES == {}
        here = sorted(client.nthreads())
        client.submit(nd._hosts_alive, here).result()
        with pytest.raises(ClusterError, match="tcp://127.0.0.1:1"):
            client.submit(nd._hosts_alive, [*here, "tcp://127.0.0.1:1"]).result()


@pytest.mark.parametrize("tol, checks", [(0.0, [0, 5, 10, 12]), (0.05, [0, 5, 10])], ids=["to_max_iter", "stops"])
def test_one_graph_per_evaluation_of_the_objective(rng, monkeypatch, tol, checks):
    """The iterations between two evaluations of the objective go to the scheduler as one graph: one submission
    per batch (iteration 0, then up to each multiple of loss_every, then max_iter), not one per iteration; a fit
    that stops at a check returns that check's (W, H), not the iteration the batch computed past it."""
    X, _, W0, H0 = make_data(rng, True, 1.0, False)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=12, tol=tol, loss_every=5)
    r_mem = beta_nmf(X, K, **kw)
    submitted = []
    persist, loop = dask.persist, nd._fit_loop_in_memory

    def counting_loop(*args, **kwargs):
        def counting_persist(*collections, **kw):
            submitted.append(len(collections))
            return persist(*collections, **kw)

        monkeypatch.setattr(dask, "persist", counting_persist)
        try:
            return loop(*args, **kwargs)
        finally:
            monkeypatch.setattr(dask, "persist", persist)

    monkeypatch.setattr(nd, "_fit_loop_in_memory", counting_loop)
    r_dask = beta_nmf(to_dask(X), K, **kw)
    assert_same_fit(r_mem, r_dask)
    assert list(r_mem.loss_iterations) == checks and r_mem.converged == (tol > 0)
    assert len(submitted) == len(checks)


def test_h_goes_down_a_tree_to_the_workers_and_the_sums_up_it():
    """On a cluster: one task per run of chunks on a worker; every run reads H from a copy on its worker, each copy
    made from its parent's in a tree of fan-out split_every rooted where H is computed (the first chunk's worker,
    with the root sum): ceil(log_fan(workers)) hops, not one fetch per worker from one place; no sum reads a run
    of another worker (W stays where it is)."""
    from mmconcepts.nmf._updates import Penalty

    n_chunks, fan = 40, 3
    workers = [f"w{c // 2}" for c in range(n_chunks)]  # 20 workers, 2 chunks each
    specs = [nd._ChunkSpec(c, c, c + 1) for c in range(n_chunks)]
    rule = nd._Rule(1.0, 1.0, Penalty(), 1.0, K, "float64")
    graph = nd._IterationGraph("g", [f"src-{c}" for c in range(n_chunks)], specs, rule, Penalty(), fan, workers)
    tasks = graph.layer(7, None, "H7", evaluate=True, update=True)
    where = graph.where(7, evaluate=True, update=True)
    depth = {"H7": 0}

    def hops(key):  # the copies between H7 and a key, each on its own worker
        if key not in depth:
            func, parent = tasks[key]
            assert func is nd._same
            depth[key] = hops(parent) + 1
        return depth[key]

    runs = {k: t for k, t in tasks.items() if "-run-" in k}
    assert sum(len(t[5]) for t in runs.values()) == n_chunks and len(runs) < n_chunks
    for k, (_, sources, prev, h, *_rest) in runs.items():
        chunk_workers = {workers[int(src.rsplit("-", 1)[1])] for src in sources}
        assert chunk_workers == {where[k]} and prev == k.replace("-7-", "-6-")
        assert h == "H7" if where[k] == "w0" else where[h] == where[k]
        assert hops(h) <= 3  # ceil(log3(20))
    assert max(depth.values()) == 3 and len(depth) == 20  # H7 and one copy on each of the 19 other workers
    for k, task in tasks.items():
        if "-sum" in k:
            assert all(where[a] == where[k] or "-run-" not in a for a in task[1:]), k
    root = graph.root(7)
    assert where[root] == where[graph.key("H", 8)] == where[graph.key("check", 7)] == "w0"
    assert tasks[graph.key("H", 8)][1] == root


@pytest.mark.parametrize("layout, fan", [("aaaabbbbbbbb", 8), ("aaaaaabbbbbbcccccc", 3), ("aabbbccc", 2)])
def test_a_few_workers_each_update_their_own_H_from_the_same_sums(layout, fan):
    """At most split_every workers: each worker sums every worker's parts up the tree itself and updates its own copy
    of H (one task, no root to wait for, no copy of H sent down a tree but at a batch's start); every copy reads the
    same parts in the same order, and none reads another worker's run (W stays where it is). More workers than the
    fan-in keep the root and the broadcast tree (the test above)."""
    from mmconcepts.nmf._updates import Penalty

    n = len(layout)
    specs = [nd._ChunkSpec(c, c, c + 1) for c in range(n)]
    rule = nd._Rule(1.0, 1.0, Penalty(), 1.0, K, "float64")
    graph = nd._IterationGraph("g", [f"src-{c}" for c in range(n)], specs, rule, Penalty(), fan, list(layout))
    hosts = list(dict.fromkeys(layout))
    assert graph.replicated == (len(hosts) <= fan)
    if not graph.replicated:
        return
    middle = graph.layer(7, None, "H7", evaluate=False, update=True)
    where = graph.where(7, evaluate=False, update=True)
    assert not any(task[0] is nd._same for task in middle.values())  # H^7 is on every worker already
    updates = [graph.key("H", 8)] + [graph.key("Hto", 8, j) for j in range(1, len(hosts))]
    read = []
    for j, k in enumerate(updates):
        func, fan_in, h_prev, _rule, _pen, *nodes = middle[k]
        assert func is nd._tree_h_step and fan_in == fan and where[k] == hosts[j]
        assert h_prev == ("H7" if j == 0 else graph.key("Hto", 7, j))
        assert all(where[a] == hosts[j] for a in nodes if "-run-" in a)  # another worker's run only through its part
        # the same node (a run, its part or a group's sum) in the same place of every copy's sum
        read.append([a.replace("-part-", "-run-") for a in nodes])
        assert graph.key("H", 8) != k or not any("-Hto-" in a for a in nodes)
    assert all(r == read[0] for r in read)
    # a run reads its own worker's H
    for k, task in middle.items():
        if "-run-" in k:
            assert where[task[3]] == where[k] if task[3] != "H7" else where[k] == hosts[0]
    # a batch's first iteration copies H^t to the other workers; its last sums once for the check and makes H^(t+1)
    # on the first worker alone (the next batch copies it)
    first = graph.layer(7, [f"w-{c}" for c in range(n)], "H7", evaluate=True, update=True)
    copies = {k for k, task in first.items() if task[0] is nd._same}
    assert copies == {graph.key("Hto", 7, j) for j in range(1, len(hosts))}
    assert first[graph.key("check", 7)][1] == graph.root(7) == first[graph.key("H", 8)][1]
    assert not any(graph.key("Hto", 8, j) in first for j in range(1, len(hosts)))


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("layout, split_every", [("aaab", 2), ("abcd", 2), ("aaaa", 8), ("aabb", 8), ("abab", 3)])
def test_fit_with_runs_and_the_broadcast_tree_equals_the_fit_without(rng, monkeypatch, layout, split_every):
    """Runs of chunks, the copies of H and the placement change no number (synchronous scheduler: placement
    ignored, the graph's shape kept)."""
    X, mask, W0, H0 = make_data(rng, False, 0.5, True)
    kw = dict(init="custom", W=W0, H=H0, max_iter=7, tol=1e-3, loss_every=3, split_every=split_every)
    plain = nd.beta_nmf_dask(to_dask(X), K, beta=0.5, mask=to_dask(mask), **kw)
    monkeypatch.setattr(nd, "_chunk_workers", lambda specs, n: list(layout))
    treed = nd.beta_nmf_dask(to_dask(X), K, beta=0.5, mask=to_dask(mask), **kw)
    assert np.array_equal(plain.W.compute(), treed.W.compute()) and np.array_equal(plain.H, treed.H)
    assert np.array_equal(plain.loss_history, treed.loss_history)


@pytest.mark.filterwarnings("ignore:beta_nmf stopped at max_iter")
@pytest.mark.parametrize("layout", ["a" * 9 + "b" * 11, "aaaaaaabbbbbbbcccccc"])
def test_each_workers_own_H_is_the_roots_bit_for_bit(rng, monkeypatch, layout):
    """Twenty chunks, a tree of fan-in 3 two levels above its first (7 groups, then 3, then 1): each worker's
    update of H sums the parts in the tree's order, so the fit is the one without workers, bit for bit."""
    X = sp.random(200, M, density=0.3, format="csr", random_state=np.random.RandomState(3)) * 10.0
    W0, H0 = rng.random((200, K)) + 0.1, rng.random((K, M)) + 0.1
    Xd = da.from_array(X, chunks=(10, -1), asarray=False)
    kw = dict(init="custom", W=W0, H=H0, beta=1.0, max_iter=6, tol=1e-6, loss_every=3, split_every=3)
    plain = nd.beta_nmf_dask(Xd, K, **kw)
    monkeypatch.setattr(nd, "_chunk_workers", lambda specs, n: list(layout))
    shared = nd.beta_nmf_dask(Xd, K, **kw)
    assert np.array_equal(plain.W.compute(), shared.W.compute()) and np.array_equal(plain.H, shared.H)
    assert np.array_equal(plain.loss_history, shared.loss_history)


def test_hstack_row_chunks_for_modalities(rng):
    """Modalities side by side, chunk by chunk: the in-memory stack, fitted alike."""
    X1, _, _, _ = make_data(rng, True, 1.0, False)
    X2 = rng.random((N, 5))
    S = nd.hstack_row_chunks([to_dask(X1), to_dask(X2)], [0.5, 2.0], names=["sound", "motion"])
    assert S.chunks == (ROW_CHUNKS, (M + 5,))
    ref = sp.hstack([X1 * 0.5, sp.csr_matrix(X2 * 2.0)], format="csr")
    assert rel(S.compute().toarray(), ref.toarray()) == 0
    W0, H0 = rng.random((N, K)) + 0.1, rng.random((K, M + 5)) + 0.1
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=4, tol=0)
    assert_same_fit(beta_nmf(ref, K, **kw), beta_nmf(S, K, **kw))
    with pytest.raises(DataError, match=r"motion must have the row chunks of sound"):
        nd.hstack_row_chunks([to_dask(X1), da.from_array(X2, chunks=(50, -1))], names=["sound", "motion"])
    with pytest.raises(DataError, match="must be a dask array"):
        nd.hstack_row_chunks([to_dask(X1), X2])


# ------------------------------------------------------------------------------ out of core


@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
def test_npz_chunks_round_trip(tmp_path, rng, sparse):
    X, _, _, _ = make_data(rng, sparse, 1.0, False)
    folder = nd.save_npz_chunks(X, tmp_path / "x", chunk_rows=30)
    Xd = nd.load_npz_chunks(folder)
    assert Xd.chunks == ((30, 30, 30, 10), (M,)) and Xd.dtype == X.dtype
    back = Xd.compute()
    assert sp.issparse(back) == sparse
    assert np.array_equal(back.toarray() if sparse else back, X.toarray() if sparse else X)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        nd.save_npz_chunks(X, folder)
    # a dask array keeps its chunks; a generator of chunks works
    nd.save_npz_chunks(to_dask(X), tmp_path / "y")
    assert nd.load_npz_chunks(tmp_path / "y").chunks[0] == ROW_CHUNKS
    nd.save_npz_chunks((X[a:a + 50] for a in range(0, N, 50)), tmp_path / "z")
    assert nd.load_npz_chunks(tmp_path / "z").chunks[0] == (50, 50)


def test_out_of_core_fit_equals_in_memory_never_whole(tmp_path, rng, monkeypatch):
    X, mask, W0, H0 = make_data(rng, True, 1.0, True)
    folder = nd.save_npz_chunks(X, tmp_path / "x", chunk_rows=20)
    mfolder = nd.save_npz_chunks(mask.astype(np.float64), tmp_path / "m", chunk_rows=20)
    live: list = []
    peak = [0]
    load = nd._load_chunk

    def counting_load(*args):
        out = load(*args)
        live.append(weakref.ref(out))
        peak[0] = max(peak[0], sum(r() is not None for r in live))
        return out

    monkeypatch.setattr(nd, "_load_chunk", counting_load)
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=7, tol=0, loss_every=3)
    r_mem = beta_nmf(X, K, mask=mask, **kw)
    r_ooc = nd.beta_nmf_out_of_core(folder, K, out=tmp_path / "W", mask=mfolder, **kw)
    assert peak[0] == 2  # one chunk of X and its chunk of the mask at a time, never the 5 + 5
    assert rel(r_ooc.W.compute(), r_mem.W) < RTOL and rel(r_ooc.H, r_mem.H) < RTOL
    assert rel(r_ooc.loss_history, r_mem.loss_history) < RTOL
    written = nd.load_npz_chunks(tmp_path / "W")
    assert written.chunks == ((20,) * 5, (K,))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["W", "m", "x"]  # no working folder left behind


def test_out_of_core_random_start_and_stopping_rule(tmp_path, rng):
    """The stopping rule stops at the same iteration, and the W of that iteration (not the next) is kept."""
    X = rng.poisson(1.0, (N, M)).astype(np.float64)
    folder = nd.save_npz_chunks(X, tmp_path / "x", chunk_rows=33)
    kw = dict(init="random", random_state=3, beta_loss=2.0, max_iter=300, tol=2e-3, loss_every=3)
    r_mem = beta_nmf(X, K, **kw)
    r_ooc = nd.beta_nmf_out_of_core(folder, K, out=tmp_path / "W", **kw)
    assert r_mem.converged and r_mem.n_iter < 300
    assert_same_fit(r_mem, r_ooc)


# ------------------------------------------------------------------------------ bad input


def test_unknown_chunk_sizes(rng):
    X = to_dask(rng.random((N, M)))
    Xn = X[X[:, 0] > 0.3]
    with pytest.raises(DataError, match=r"unknown chunk sizes.*compute_chunk_sizes"):
        beta_nmf(Xn, K)


def test_column_chunks(rng):
    X = da.from_array(rng.random((N, M)), chunks=(50, 8))
    with pytest.raises(DataError, match=r"rows only.*3 column chunks.*rechunk\(\{1: -1\}\)"):
        beta_nmf(X, K)
    with pytest.raises(DataError, match="column chunks"):
        NMF(K).fit(X)


def test_mask_chunks_must_match(rng):
    X, mask, _, _ = make_data(rng, False, 1.0, True)
    with pytest.raises(DataError, match=r"chunked like X.*expected row chunks \(23, 40, 1, 36\).*rechunk"):
        beta_nmf(to_dask(X), K, mask=da.from_array(mask, chunks=(50, -1)))
    with pytest.raises(DataError, match="shape of X"):
        beta_nmf(to_dask(X), K, mask=to_dask(mask[:, :5]))
    with pytest.raises(DataError, match="X is not"):
        beta_nmf(X, K, mask=to_dask(mask))


def test_negative_value_in_late_chunk_names_it_and_writes_no_w(tmp_path, rng):
    X = rng.random((N, M))
    X[95, 3] = -1.0  # in the last chunk (rows 64 to 99)
    with pytest.raises(DataError, match=r"chunk 3 \(rows 64 to 99\).*Negative"):
        beta_nmf(to_dask(X), K, init="random", random_state=0)
    folder = nd.save_npz_chunks(sp.csr_matrix(X), tmp_path / "x", chunk_rows=25)
    with pytest.raises(DataError, match=r"chunk 3 \(rows 75 to 99\)"):
        nd.beta_nmf_out_of_core(folder, K, out=tmp_path / "W", beta_loss=1.0, max_iter=3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x"]  # no W, no working folder


def test_zero_with_beta_nonpositive_names_chunk(rng):
    X = rng.random((N, M)) + 0.5
    X[70, 0] = 0.0
    with pytest.raises(DataError, match=r"chunk 3 .*beta_loss=0 is undefined"):
        beta_nmf(to_dask(X), K, beta_loss=0.0, init="random")


def test_unsupported_options_and_partial_fit(rng):
    X = to_dask(rng.random((N, M)))
    with pytest.raises(ParameterError, match="solver='pg'.*solver='mu'"):
        beta_nmf(X, K, solver="pg")
    with pytest.raises(ParameterError, match="sparseness_W/sparseness_H"):
        beta_nmf(X, K, sparseness_H=0.5)
    with pytest.raises(DataError, match="partial_fit takes one in-memory batch"):
        NMF(K).partial_fit(X)


def test_broken_chunk_folders(tmp_path, rng):
    with pytest.raises(DataFormatError, match="no manifest.json"):
        nd.load_npz_chunks(tmp_path)
    folder = nd.save_npz_chunks(rng.random((10, 3)), tmp_path / "x", chunk_rows=4)
    (folder / "manifest.json").write_text('{"format": "something else"}')
    with pytest.raises(DataFormatError, match="not a manifest"):
        nd.load_npz_chunks(folder)
    folder = nd.save_npz_chunks(rng.random((10, 3)), tmp_path / "y", chunk_rows=4)
    np.savez(folder / "chunk-000001.npz", X=np.ones((5, 3)))
    with pytest.raises(DataFormatError, match=r"chunk 1 .* has shape \(5, 3\); the manifest says \(4, 3\)"):
        nd.load_npz_chunks(folder).compute()


def _corrupt(path, how):
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "garbage":
        path.write_bytes(b"not an npz file at all" * 10)
    elif how == "npy":
        path.unlink()
        with open(path, "wb") as fh:
            np.save(fh, np.ones((4, 3)))
    elif how == "other_key":
        path.unlink()
        with open(path, "wb") as fh:
            np.savez(fh, Y=np.ones((4, 3)))
    elif how == "folder":
        path.unlink()
        path.mkdir()


@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
@pytest.mark.parametrize("how", ["truncated", "empty", "garbage", "npy", "other_key", "folder"])
def test_a_corrupt_chunk_is_named(tmp_path, rng, sparse, how):
    """A chunk file cut short, empty, not an npz, without the array or replaced by a folder: a DataFormatError
    naming the chunk and its file when it is read."""
    X = rng.random((10, 3))
    folder = nd.save_npz_chunks(sp.csr_matrix(X) if sparse else X, tmp_path / "x", chunk_rows=4)
    _corrupt(folder / "chunk-000001.npz", how)
    Xd = nd.load_npz_chunks(folder)
    with pytest.raises(DataFormatError, match=r"Cannot read chunk 1 \(.*chunk-000001\.npz\)"):
        Xd.compute()


def test_package_works_without_dask():
    code = (
        "import sys; sys.modules['dask'] = None; sys.modules['dask.array'] = None\n"
        "import numpy as np\n"
        "from mmconcepts.nmf import NMF, _dask\n"
        "W = NMF(2, max_iter=5, tol=0, init='random', random_state=0).fit_transform(np.ones((6, 4)) + np.eye(6, 4))\n"
        "assert W.shape == (6, 2)\n"
        "try:\n"
        "    _dask.load_npz_chunks('.')\n"
        "except ImportError as exc:\n"
        "    assert 'mmconcepts[dask]' in str(exc), exc\n"
        "else:\n"
        "    raise SystemExit('no ImportError')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


def test_warns_like_in_memory(rng):
    X, _, W0, H0 = make_data(rng, False, 2.0, False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        beta_nmf(to_dask(X), K, init="custom", W=W0, H=H0, max_iter=2, tol=1e-12)
    assert any("max_iter=2" in str(w.message) for w in caught)


@pytest.mark.parametrize("case", ["from_array", "from_delayed", "masked", "alpha_H"])
def test_sparse_kl_h_update_flushes_as_the_in_memory_kernel(rng, case):
    """A sparse I-divergence fit whose H entries fall far below 1e-154: the H update summed over the chunks sets to
    zero the entries the in-memory fit sets to zero (below ``flush_below`` where the in-memory H update is the
    kernel's: sparse chunks, even where the dask array's meta is dense; below the smallest normal number with a
    mask or a penalty on H), and the iterates stay equal."""
    from mmconcepts.nmf import _kernels

    X = sp.random(300, 2000, density=0.01, format="csr", random_state=np.random.RandomState(0),
                  data_rvs=lambda size: rng.poisson(2.0, size) + 1.0)
    X = X[:, np.asarray(X.getnnz(axis=0)) > 0]
    m = X.shape[1]
    W0, H0 = rng.random((300, 10)) + 0.1, rng.random((10, m)) + 0.1
    kw = dict(init="custom", W=W0, H=H0, beta_loss=1.0, max_iter=100, tol=0)
    mask = None
    if case == "masked":
        mask = rng.random((300, m)) > 0.1
    if case == "alpha_H":
        kw.update(alpha_W=0.0, alpha_H=1e-3)
    r_mem = beta_nmf(X, 10, mask=mask, **kw)
    if case == "from_delayed":  # CSR chunks under an ndarray meta
        Xd = da.concatenate([da.from_delayed(dask.delayed(X[a:a + 50]), shape=(50, m), dtype=np.float64)
                             for a in range(0, 300, 50)])
        assert not sp.issparse(Xd._meta)
    else:
        Xd = da.from_array(X, chunks=(50, -1), asarray=False)
    r_dask = beta_nmf(Xd, 10, mask=None if mask is None else da.from_array(mask, chunks=(50, -1)), **kw)
    flush = _kernels.flush_below(np.float64)
    tiny = np.finfo(np.float64).tiny
    assert (r_mem.H == 0).sum() > 1000  # the case reaches the flush
    kept = (r_mem.H > 0) & (r_mem.H < flush)
    if case in ("from_array", "from_delayed"):
        assert not kept.any()
    else:
        assert kept.any() and not ((r_mem.H > 0) & (r_mem.H < tiny)).any()
    np.testing.assert_array_equal(r_dask.H == 0, r_mem.H == 0)
    assert rel(r_dask.H, r_mem.H) < RTOL
