"""The worker processes' memory: what a task freed goes back to the system."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from mmconcepts.engine import workers

_FRAGMENTED_HEAP = textwrap.dedent("""
    import numpy as np
    from mmconcepts.engine.workers import release_free_memory

    def rss_kb():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS"))

    # 3000 blocks of 64 kB (under glibc's mmap threshold: they come from the heap), written so that
    # their pages are resident; every tenth kept, so that free() cannot shrink the heap from its top
    blocks = [np.ones(8192) for _ in range(3000)]
    kept = blocks[::10]
    del blocks
    before = rss_kb()
    released = release_free_memory()
    print(before, rss_kb(), released, len(kept))
""")


@pytest.mark.skipif(not sys.platform.startswith("linux") or workers._malloc_trim() is None,
                    reason="malloc_trim is glibc's (Linux)")
def test_release_free_memory_returns_a_fragmented_heap_to_the_system():
    out = subprocess.run([sys.executable, "-c", _FRAGMENTED_HEAP], capture_output=True, text=True, check=True)
    before, after, released, _ = out.stdout.split()
    freed_kb = 2700 * 64  # the blocks freed, about 170 MB
    assert released == "True"
    assert int(before) - int(after) > 0.8 * freed_kb, (before, after)


def test_each_task_releases_what_it_freed(monkeypatch):
    calls = []
    monkeypatch.setattr(workers, "release_free_memory", lambda: calls.append("trim") or True)

    def task(x):
        calls.append(x)
        return 2 * x

    assert workers.WarningsCarried(task)(4) == (8, [])
    assert calls == [4, "trim"]


def test_release_free_memory_does_nothing_without_malloc_trim(monkeypatch):
    monkeypatch.setattr(workers, "_malloc_trim", lambda: None)
    assert workers.release_free_memory() is False


_HEAP_BLOCKS = textwrap.dedent("""
    import ctypes
    import numpy as np
    from mmconcepts.engine.workers import allocate_from_heap, release_free_memory

    class MallInfo2(ctypes.Structure):
        _fields_ = [(name, ctypes.c_size_t) for name in
                    ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                     "keepcost")]

    mallinfo2 = ctypes.CDLL(None).mallinfo2
    mallinfo2.restype = MallInfo2

    def rss_kb():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS"))

    a = np.ones(8_000_000)  # 64 MB, above glibc's largest automatic mmap threshold (32 MB)
    mapped_before = mallinfo2().hblkhd
    del a
    taken = allocate_from_heap()
    a = np.ones(8_000_000)
    mapped_after, heap_after = mallinfo2().hblkhd, mallinfo2().arena
    del a
    b = np.ones(8_000_000)  # the freed block again: no new pages
    rss_b = rss_kb()
    del b
    kept = rss_kb()
    released = release_free_memory()
    print(taken, mapped_before, mapped_after, heap_after, rss_b, kept, rss_kb(), released)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux") or workers._mallopt() is None
                    or not hasattr(__import__("ctypes").CDLL(None), "mallinfo2"),
                    reason="mallopt and mallinfo2 are glibc's (Linux, glibc 2.33 and later)")
def test_allocate_from_heap_serves_large_arrays_from_the_heap_and_keeps_them_until_released():
    out = subprocess.run([sys.executable, "-c", _HEAP_BLOCKS], capture_output=True, text=True, check=True)
    taken, mapped_before, mapped_after, heap_after, rss_b, kept, after, released = out.stdout.split()
    block = 64_000_000
    assert taken == "True"
    assert int(mapped_before) >= block  # glibc's default: a fresh mmap
    assert int(mapped_after) < block <= int(heap_after)  # now the heap's
    assert int(rss_b) - int(kept) < 0.1 * block / 1024  # freed, the pages stay with the process
    assert released == "True" and int(kept) - int(after) > 0.8 * block / 1024  # until a worker releases them


def test_allocate_from_heap_does_nothing_without_mallopt(monkeypatch):
    monkeypatch.setattr(workers, "_mallopt", lambda: None)
    assert workers.allocate_from_heap() is False


def test_a_worker_allocates_from_the_heap(monkeypatch):
    from joblib.externals.loky import process_executor

    # init_worker raises loky's leak guard and its delay in this process: restored after the test
    monkeypatch.setattr(process_executor, "_MAX_MEMORY_LEAK_SIZE", process_executor._MAX_MEMORY_LEAK_SIZE)
    monkeypatch.setattr(process_executor, "_MEMORY_LEAK_CHECK_DELAY", process_executor._MEMORY_LEAK_CHECK_DELAY)
    calls = []
    monkeypatch.setattr(workers, "end_with_parent", lambda pid: calls.append(("parent", pid)))
    monkeypatch.setattr(workers, "allocate_from_heap", lambda: calls.append("heap") or True)
    workers.init_worker(123)
    assert calls == [("parent", 123), "heap"]
