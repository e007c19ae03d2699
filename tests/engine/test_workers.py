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
