"""mmconcepts._jit: numba kernels compiled once per machine, not once per process."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile
import textwrap
import time

import numba
import numpy as np
import pytest

from mmconcepts import _jit
from mmconcepts._io import folder_lock

MODULE = textwrap.dedent("""
    from mmconcepts._jit import njit

    @njit(cache=True)
    def inner(x):
        return x * 2.0

    @njit(cache=True, nogil=True)
    def outer(x):
        return inner(x) + 1.0

    @njit(nogil=True)
    def uncached(x):
        return x - 1.0
""")

CHILD = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import jitmod
    print("ready", flush=True)
    assert jitmod.outer(1.5) == 4.0
    stats = jitmod.outer.stats
    print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()), flush=True)
""")


@pytest.fixture
def jitmod(tmp_path, monkeypatch):
    """A module of cached kernels in its own folder, with its own numba cache and lock folder."""
    src = tmp_path / "src"
    src.mkdir()
    (src / "jitmod.py").write_text(MODULE)
    (tmp_path / "tmp").mkdir()
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), TMPDIR=str(tmp_path / "tmp"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    monkeypatch.syspath_prepend(str(src))
    sys.modules.pop("jitmod", None)
    mod = importlib.import_module("jitmod")
    yield mod, src, env
    sys.modules.pop("jitmod", None)


def test_cached_kernels_are_numba_dispatchers_with_the_lock(jitmod):
    mod, _, _ = jitmod
    for f in (mod.inner, mod.outer, mod.uncached):
        assert isinstance(f, numba.core.registry.CPUDispatcher)
    assert "_compile_for_args" in vars(mod.outer) and "_compile_for_args" in vars(mod.inner)
    assert "_compile_for_args" not in vars(mod.uncached)  # cache=False: nothing to share
    assert _jit.lock_file(mod.outer).parent == _jit._lock_dir()
    assert _jit.lock_file(mod.outer) != _jit._lock_dir() / _jit.lock_file(mod.inner).name


def test_a_second_process_waits_for_the_lock_and_loads_the_cache(jitmod):
    """Two processes start at once on an empty cache: exactly one compiles, the other loads its code."""
    mod, src, env = jitmod
    lock = _jit.lock_file(mod.outer)
    with folder_lock(lock.parent, lock.name):  # both children find the kernel's lock held
        procs = [subprocess.Popen([sys.executable, "-c", CHILD, str(src)], env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for _ in range(2)]
        for p in procs:
            assert p.stdout.readline().strip() == "ready", p.stderr.read()
        time.sleep(1.0)  # a child that did not wait for the lock would have compiled and ended by now
        assert [p.poll() for p in procs] == [None, None]
    outs = []
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        outs.append(tuple(int(v) for v in out.split()))
    assert sorted(outs) == [(0, 1), (1, 0)]  # (cache hits, cache misses) of each


def test_same_results_as_numba(jitmod):
    mod, _, _ = jitmod
    x = np.float64(0.25)
    assert mod.outer(x) == mod.outer.py_func(x) == 1.5
    assert mod.uncached(x) == -0.75
    bare = _jit.njit(lambda v: v + 1)
    assert bare(1) == 2


def test_the_package_kernels_compile_under_the_lock():
    from mmconcepts.experiments import _ch7_common
    from mmconcepts.nmf import _kernels
    from mmconcepts.sound import dtw, tree

    found = 0
    for module in (_kernels, tree, dtw, _ch7_common):
        for value in vars(module).values():
            if isinstance(value, numba.core.registry.CPUDispatcher):
                found += 1
                assert "_compile_for_args" in vars(value), value  # made by _jit.njit with cache=True
    assert found >= 30
