"""The kernel warm-up (mmconcepts._warmup): what it compiles, when it starts, its marker."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import types

import pytest

from mmconcepts import _warmup

# In a fresh numba cache: the warm-up's package steps (librosa's left out: they compile in librosa's own
# cache folder too, and take long), then, in a second process, the same steps again and a count of the
# kernels compiled there, and of the kernels made with compile_apart=True that the steps called.
WARM_THEN_COUNT = textwrap.dedent("""
    import json, sys
    import numba
    from numba.core import event
    from mmconcepts import _jit, _warmup
    from mmconcepts.nmf import _kernels
    from mmconcepts.sound import dtw, tree

    steps = tuple(w for w in _warmup.WARMERS if not w.endswith(":_mfcc"))
    if sys.argv[1] == "warm":
        _jit._IN_PLACE = True
        sys.exit(len(_warmup.warm_up(steps)))
    compiled = []

    class Listener(event.Listener):
        def on_start(self, ev):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)

        def on_end(self, ev):
            pass

    event.register("numba:compile", Listener())
    failed = _warmup.warm_up(steps)
    kernels = {f"{m.__name__}.{n}": v for m in (_kernels, tree, dtw) for n, v in vars(m).items()
               if isinstance(v, numba.core.registry.CPUDispatcher) and _jit.compiles_apart(v)}
    print(json.dumps({"failed": failed, "compiled": compiled,
                      "apart_called": sorted(k for k, v in kernels.items() if v.signatures),
                      "apart": sorted(kernels)}))
""")


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_warm_up_writes_every_compile_apart_kernel_to_the_cache(tmp_path):
    """After the warm-up, its steps compile nothing, and they call every kernel that compiles apart."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), MMCONCEPTS_DATA=str(tmp_path / "data"),
               MMCONCEPTS_QUIET="1")
    run = [sys.executable, "-c", WARM_THEN_COUNT]
    warm = subprocess.run([*run, "warm"], env=env, text=True, capture_output=True, timeout=540)
    assert warm.returncode == 0, warm.stderr
    again = subprocess.run([*run, "count"], env=env, text=True, capture_output=True, timeout=240)
    assert again.returncode == 0, again.stderr
    seen = json.loads(again.stdout)
    assert seen["failed"] == []
    assert seen["compiled"] == []  # every kernel the steps call came from numba's disk cache
    assert seen["apart_called"] == seen["apart"] and seen["apart"]


def test_the_mfcc_step_runs():
    assert _warmup.warm_up(("mmconcepts._warmup:_mfcc",)) == []


def test_a_step_that_raises_is_reported_and_the_others_still_run(monkeypatch):
    calls = []
    mod = types.ModuleType("warmmod")
    mod.bad = lambda: (_ for _ in ()).throw(ImportError("no such package"))
    mod.good = lambda: calls.append("good")
    monkeypatch.setitem(sys.modules, "warmmod", mod)
    assert _warmup.warm_up(("warmmod:bad", "warmmod:good")) == ["warmmod:bad"]
    assert calls == ["good"]


def test_main_writes_the_marker_only_when_every_step_ran(monkeypatch, tmp_path):
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path))
    monkeypatch.setattr("mmconcepts._jit._IN_PLACE", False)
    monkeypatch.setattr(_warmup, "warm_up", lambda: ["x:y"])
    assert _warmup.main() == 1
    assert not _warmup.marker_path().exists()
    monkeypatch.setattr(_warmup, "warm_up", lambda: [])
    assert _warmup.main() == 0
    assert _warmup.marker_path().exists()
    assert _warmup.marker_path().parent.name == "numba"  # the lock folder of mmconcepts._jit


class _FakeProcess:
    started: list = []

    def __init__(self, args, **kwargs):
        self.args, self.killed, self.waits = args, False, []
        self.running = True
        _FakeProcess.started.append(self)

    def poll(self):
        return None if self.running else 0

    def wait(self, timeout=None):
        self.waits.append(timeout)
        if not self.killed and timeout is not None:
            raise subprocess.TimeoutExpired(self.args, timeout)
        self.running = False
        return 0

    def kill(self):
        self.killed = True


@pytest.fixture
def fake_popen(monkeypatch, tmp_path):
    monkeypatch.setenv("MMCONCEPTS_DATA", str(tmp_path))
    monkeypatch.delenv("MMCONCEPTS_WARMUP")
    _FakeProcess.started = []
    monkeypatch.setattr(subprocess, "Popen", _FakeProcess)
    return _FakeProcess


def test_in_background_starts_the_warm_up_and_ends_it_if_it_outlives_the_block(fake_popen):
    with _warmup.in_background() as proc:
        assert proc is fake_popen.started[0]
        assert proc.args == [sys.executable, "-m", "mmconcepts._warmup"]
    assert proc.waits == [_warmup.STOP_TIMEOUT, None] and proc.killed  # waited STOP_TIMEOUT, then ended it


def test_in_background_ends_the_warm_up_at_once_when_the_block_raises(fake_popen):
    with pytest.raises(KeyboardInterrupt), _warmup.in_background() as proc:
        raise KeyboardInterrupt
    assert proc.killed and proc.waits == [None]


@pytest.mark.parametrize("why", ["marker", "switched off"])
def test_in_background_starts_nothing_after_a_complete_warm_up_or_when_switched_off(fake_popen, monkeypatch, why):
    if why == "marker":
        _warmup.marker_path().parent.mkdir(parents=True)
        _warmup.marker_path().touch()
    else:
        monkeypatch.setenv("MMCONCEPTS_WARMUP", "0")
    with _warmup.in_background() as proc:
        assert proc is None
    assert fake_popen.started == []


def test_the_marker_changes_with_the_interpreter(fake_popen, monkeypatch):
    before = _warmup.marker_path()
    monkeypatch.setattr(sys, "executable", sys.executable + "-other")
    assert _warmup.marker_path() != before
