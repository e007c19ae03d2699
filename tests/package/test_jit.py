"""mmconcepts._jit: numba kernels compiled once per machine, not once per process."""

from __future__ import annotations

import contextlib
import importlib
import os
import subprocess
import sys
import tempfile
import textwrap
import threading
import time

import numba
import numpy as np
import pytest

from mmconcepts import _jit
from mmconcepts._io import folder_lock
from mmconcepts._progress import QUIET_ENV

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

    @njit(cache=True, compile_apart=True)
    def apart(x):
        return inner(x) * 3.0

    @njit(cache=True, compile_apart=True)
    def untypable(x):
        return x.no_such_attribute
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
    assert _jit.lock_file(mod.outer).parent == _jit.lock_dir()
    assert _jit.lock_file(mod.outer) != _jit.lock_dir() / _jit.lock_file(mod.inner).name


@pytest.mark.slow  # two processes compiling
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
    from mmconcepts.experiments.ch7 import protocol as ch7_protocol
    from mmconcepts.nmf import _kernels
    from mmconcepts.sound import dtw, tree

    found = 0
    for module in (_kernels, tree, dtw, ch7_protocol):
        for value in vars(module).values():
            if isinstance(value, numba.core.registry.CPUDispatcher):
                found += 1
                assert "_compile_for_args" in vars(value), value  # made by _jit.njit with cache=True
    assert found >= 30


FIRST_USE_CHILD = textwrap.dedent("""
    from mmconcepts import _jit
    print("ready", flush=True)
    with _jit.first_use("probe"):
        print("inside", flush=True)
""")


def test_first_use_waits_for_a_process_that_holds_its_lock(tmp_path, monkeypatch):
    """A process entering a first-use block waits while another process holds that name's lock."""
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
    lock = _jit.lock_dir() / "first-use.probe.lock"
    with folder_lock(lock.parent, lock.name):
        child = subprocess.Popen([sys.executable, "-c", FIRST_USE_CHILD], env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
        assert child.stdout.readline().strip() == "ready", child.stderr.read()
        time.sleep(1.0)
        assert child.poll() is None  # still waiting at the block
    out, err = child.communicate(timeout=60)
    assert child.returncode == 0, err
    assert out.strip() == "inside"


@pytest.fixture
def taken(monkeypatch):
    """The names of the locks first_use takes (recorded instead of taken), none used yet in this process."""
    names = []

    @contextlib.contextmanager
    def spy(folder, name):
        names.append(name)
        yield

    monkeypatch.setattr(_jit, "folder_lock", spy)
    monkeypatch.setattr(_jit, "_FIRST_USES", set())
    return names


def test_first_use_locks_until_a_block_completes_then_never_again(taken):
    with pytest.raises(ZeroDivisionError):
        with _jit.first_use("probe"):
            1 / 0
    assert taken == ["first-use.probe.lock"]
    with _jit.first_use("probe"):  # the first block failed: locked again
        pass
    with _jit.first_use("probe"):
        pass
    with _jit.first_use("other"):
        pass
    assert taken == ["first-use.probe.lock", "first-use.probe.lock", "first-use.other.lock"]


def test_mfcc_imports_librosa_under_the_first_use_lock(taken):
    """librosa compiles its numba ufuncs at import: the first MFCC of a process runs under the lock."""
    pytest.importorskip("librosa")
    from mmconcepts.sound.features import mfcc

    y = np.random.default_rng(0).standard_normal(16000).astype(np.float32) * 0.1
    first = mfcc(y)
    assert taken == ["first-use.librosa.lock"]
    np.testing.assert_array_equal(mfcc(y), first)
    assert taken == ["first-use.librosa.lock"]


def test_the_compile_locks_are_in_the_user_s_cache_folder(tmp_path, monkeypatch):
    # never a machine-wide temporary folder shared with other users: under the cache folder's lock folder
    from mmconcepts._store import LOCKS

    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "cache"))
    assert _jit.lock_dir() == tmp_path / "cache" / LOCKS / "numba"


# --------------------------------------------------------------------------- the notice of compilation


@pytest.fixture
def notice(tmp_path, monkeypatch):
    """This process has given no notice yet, its group neither (a lock folder of its own), and -q is not set."""
    monkeypatch.setattr(_jit, "_NOTICE_GIVEN", threading.Event())
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "data"))
    monkeypatch.delenv(QUIET_ENV, raising=False)


def test_a_process_that_compiles_says_so_once(jitmod, notice, capsys):
    mod, _, _ = jitmod
    assert mod.outer(1.5) == 4.0  # compiles outer and inner: an empty cache
    assert capsys.readouterr().err.count(_jit.COMPILE_NOTICE) == 1
    assert mod.outer(np.float32(1.0)) == 3.0  # compiles again, for float32
    assert sum(mod.outer.stats.cache_misses.values()) == 2
    assert capsys.readouterr().err == ""  # once per process


def test_without_a_lock_folder_a_process_still_says_it_once(jitmod, notice, capsys, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "file"))  # no folder can be made there: no group marker
    mod, _, _ = jitmod
    assert mod.outer(1.5) == 4.0 and mod.inner(np.float32(2.0)) == 4.0  # compiled unlocked, twice
    assert sum(mod.inner.stats.cache_misses.values()) == 2
    assert capsys.readouterr().err.count(_jit.COMPILE_NOTICE) == 1


def test_no_notice_when_the_kernels_come_from_the_cache(jitmod, notice, capsys, monkeypatch, tmp_path):
    mod, src, _ = jitmod
    mod.outer(1.5)
    capsys.readouterr()
    sys.modules.pop("jitmod")
    again = importlib.import_module("jitmod")  # new dispatchers, the same disk cache
    monkeypatch.setattr(_jit, "_NOTICE_GIVEN", threading.Event())  # as a new process of another command
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path / "other"))
    assert again.outer(1.5) == 4.0
    assert sum(again.outer.stats.cache_hits.values()) == 1  # loaded, not compiled
    assert capsys.readouterr().err == ""


def test_no_notice_under_quiet(jitmod, notice, capsys, monkeypatch):
    monkeypatch.setenv(QUIET_ENV, "1")
    mod, _, _ = jitmod
    mod.outer(1.5)
    assert sum(mod.outer.stats.cache_misses.values()) == 1
    assert capsys.readouterr().err == ""


def test_a_compilation_in_a_first_use_block_gives_the_notice(notice, capsys, monkeypatch):
    """librosa's kernels, compiled when it is first imported, under first_use."""
    monkeypatch.setattr(_jit, "_FIRST_USES", set())
    with _jit.first_use("probe-compile"):
        assert numba.njit(lambda v: v + 1)(1) == 2
    assert capsys.readouterr().err.count(_jit.COMPILE_NOTICE) == 1
    with _jit.first_use("probe-nothing"):
        pass
    assert capsys.readouterr().err == ""


NOTICE_CHILD = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import jitmod
    assert jitmod.outer(1.5) == 4.0
    print(sum(jitmod.outer.stats.cache_misses.values()), flush=True)
""")


@pytest.mark.slow  # three processes compiling
def test_one_notice_for_the_processes_of_one_command(jitmod, tmp_path):
    """Processes of one process group (a command and its workers), each compiling with an empty cache of its
    own, give one notice between them; a process of another group gives its own."""
    _, src, env = jitmod
    env = {k: v for k, v in env.items() if k != QUIET_ENV}
    env["MMCONCEPTS_DATA"] = str(tmp_path / "data")  # the lock folder, with the group's marker
    errs = []
    for i, new_group in enumerate((False, False, True)):
        child = subprocess.run([sys.executable, "-c", NOTICE_CHILD, str(src)], text=True, capture_output=True,
                               env=dict(env, NUMBA_CACHE_DIR=str(tmp_path / f"numba{i}")),
                               start_new_session=new_group, timeout=120)
        assert child.returncode == 0, child.stderr
        assert child.stdout.split() == ["1"]  # it compiled
        errs.append(child.stderr.count(_jit.COMPILE_NOTICE))
    assert errs == [1, 0, 1]


RUN_COUNTING_COMPILATIONS = textwrap.dedent("""
    import sys
    from numba.core import event

    compiled = []

    class Count(event.Listener):
        def on_start(self, ev):
            compiled.append(1)

        def on_end(self, ev):
            pass

    event.register("numba:compile", Count())
    from mmconcepts.cli import main

    code = main(["run", "ch2-nmf-recovery", "--smoke", "--variant", "synthetic", "-q", "-o", sys.argv[1]])
    print(len(compiled), code)
""")


@pytest.mark.slow  # two processes run an experiment, the first compiling its kernels
def test_a_second_process_never_compiles(tmp_path):
    """The first `mmconcepts run` with an empty numba cache compiles the kernels it calls and writes them to the
    cache; a second process (the experiment's own caches emptied, so it computes again) loads them all and
    compiles nothing."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), MMCONCEPTS_QUIET="1")
    counts = []
    for i in range(2):
        env["MMCONCEPTS_DATA"] = str(tmp_path / f"data{i}")
        child = subprocess.run([sys.executable, "-c", RUN_COUNTING_COMPILATIONS, str(tmp_path / f"out{i}")],
                               env=env, text=True, capture_output=True, timeout=600)
        assert child.returncode == 0, child.stderr
        compiled, code = child.stdout.split()[-2:]
        assert code in ("0", "None"), child.stdout
        counts.append(int(compiled))
    assert counts[0] > 0 and counts[1] == 0, counts


def _compiled_here(kernel):
    return sum(kernel.stats.cache_misses.values()), sum(kernel.stats.cache_hits.values())


def test_a_kernel_compiled_apart_is_compiled_by_a_child_and_loaded_from_the_cache(jitmod, notice, capfd):
    mod, _, _ = jitmod
    with numba.core.event.install_recorder("numba:compile") as compiled:
        assert mod.apart(1.5) == 9.0
    assert _compiled_here(mod.apart) == (0, 1)  # no compilation in this process: loaded from the cache
    here = [e for e in compiled.buffer if getattr(e[1].data.get("dispatcher"), "py_func", None) is mod.apart.py_func]
    assert not here
    assert capfd.readouterr().err.count(_jit.COMPILE_NOTICE) == 1  # the child says it compiles
    assert mod.apart(np.float32(1.0)) == 6.0  # new types: a child again
    assert _compiled_here(mod.apart) == (0, 2)
    assert mod.apart(2.0) == mod.apart.py_func(2.0) == 12.0


def test_no_child_when_the_cache_holds_the_types(jitmod, monkeypatch):
    mod, _, _ = jitmod
    mod.apart(1.5)
    sys.modules.pop("jitmod")
    again = importlib.import_module("jitmod")  # new dispatchers, the same disk cache
    assert _jit.in_disk_cache(again.apart, (numba.float64,)) is True
    assert _jit.in_disk_cache(again.apart, (numba.int16,)) is False
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: pytest.fail("a child was started"))
    assert again.apart(1.5) == 9.0
    assert _compiled_here(again.apart) == (0, 1)


def test_where_no_child_can_run_the_process_compiles_itself(jitmod, monkeypatch):
    mod, _, _ = jitmod
    monkeypatch.setattr(sys, "executable", "")
    assert _jit.compile_in_child(mod.apart, (1.5,)) is False
    assert mod.apart(1.5) == 9.0
    assert _compiled_here(mod.apart) == (1, 0)


def test_a_failed_child_leaves_numba_s_own_error_to_the_caller(jitmod, capfd):
    mod, _, _ = jitmod
    assert _jit.compile_in_child(mod.untypable, (1.5,)) is False
    assert "no_such_attribute" not in capfd.readouterr().err  # the child failed silently: the error comes once
    with pytest.raises(numba.core.errors.TypingError, match="no_such_attribute"):
        mod.untypable(1.5)


def test_whether_the_cache_holds_a_kernel_without_a_cache_cannot_be_told(jitmod):
    mod, _, _ = jitmod
    assert _jit.in_disk_cache(mod.uncached, (numba.float64,)) is None


def test_the_package_kernels_that_compile_longest_compile_apart():
    """The cluster tree's, DTW's and the sparse NMF kernels called from Python: each a child's work, once."""
    from mmconcepts.nmf import _kernels
    from mmconcepts.sound import dtw, tree

    apart = {f"{m.__name__}.{name}" for m in (_kernels, tree, dtw) for name, value in vars(m).items()
             if isinstance(value, numba.core.registry.CPUDispatcher) and _jit.compiles_apart(value)}
    assert apart == {"mmconcepts.sound.tree._search_batch", "mmconcepts.sound.tree._insert_batch",
                     "mmconcepts.sound.tree._kmeans", "mmconcepts.sound.dtw._pairs_serial",
                     "mmconcepts.nmf._kernels._mu_numerator", "mmconcepts.nmf._kernels._lowrank_at_nonzeros"}


EAGER = textwrap.dedent("""
    from mmconcepts._jit import njit

    @njit(cache=True, compile_apart=True)
    def eager(x):
        return x + 1.0

    WARM = eager(1.0)  # called as the module is imported: in the compiling child too
""")


@pytest.mark.timeout(300)
def test_a_kernel_called_at_import_compiles_apart_without_waiting_for_its_own_lock(tmp_path):
    """The child imports the kernel's module; a kernel called there must not wait for the lock its caller holds."""
    (tmp_path / "eagermod.py").write_text(EAGER)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), MMCONCEPTS_DATA=str(tmp_path / "data"),
               MMCONCEPTS_QUIET="1")
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import eagermod; "
            "print(eagermod.WARM, *(sum(v.values()) for v in (eagermod.eager.stats.cache_misses, "
            "eagermod.eager.stats.cache_hits)))")
    child = subprocess.run([sys.executable, "-c", code, str(tmp_path)], env=env, text=True, capture_output=True,
                           timeout=240)
    assert child.returncode == 0, child.stderr
    assert child.stdout.split() == ["2.0", "0", "1"]  # compiled by the child, loaded from the cache
