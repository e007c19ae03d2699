"""The experiments' disk caches: one entry per call, and no cache may unpickle.

Each cache (chapter-3 folds, chapter-5 MFCC, chapter-6 folds and image local features) is a
folder of ``.npz`` entries (arrays + the structure as JSON) under ``ctx.cache_dir/<name>``
(:meth:`RunContext.memory`, :mod:`mmconcepts.engine.cache`). What the tests pin: an
entry is reused for the same data, parameters and code fingerprint; a change of code
fingerprint recomputes; a torn entry recomputes instead of crashing; the result is the same
(types, dtypes, bits) whether it was computed or read back; nothing in the cache folder is
ever unpickled (a planted pickle is ignored and the value recomputed); an interrupted
parallel run keeps the calls it finished.
"""

from __future__ import annotations

import json
import pathlib
import struct
import tempfile
import types

import hypothesis.extra.numpy as hnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _planted import Plant, planted_pickle
from mmconcepts import _codec, _store
from mmconcepts._codec import HEADER, MARK
from mmconcepts._store import ENTRY_FORMAT
from mmconcepts.experiments import RunContext
from mmconcepts.engine.context import cached_call
from mmconcepts.experiments.ch3 import protocol as ch3
from mmconcepts.experiments.ch5 import protocol as ch5
from mmconcepts.experiments.protocols import speech as speech_protocol
from mmconcepts.experiments.ch6 import protocol as ch6


def _entries(folder):
    """The cache entries under ``folder`` (not the temporary files of entries being written)."""
    return sorted(p for p in folder.rglob("*.npz") if not p.name.startswith("."))


def _tear(path):
    """Cut an entry in half, as a run killed while writing it would leave it without an atomic write."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _counting(monkeypatch, module, name):
    """Replace ``module.name`` by a wrapper that counts its calls (still computing the real thing)."""
    real, calls = getattr(module, name), []

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


# --------------------------------------------------------------------------- chapter 3: one entry per learner and fold
def _ch3_args(rng):
    angles = [rng.normal(size=(20, 3)) + (i % 2) for i in range(12)]
    Y = np.eye(2)[np.arange(12) % 2]
    return angles, Y, ch3.kfold_splits(12, 3, seed=0), dict(
        features={"data": "joint", "method": "kde", "n_bins": 5, "delay": 1}, learners=("chance", "svm"),
        params={}, streams=ch3.streams(0), single=True)


def _same_folds(a, b):
    assert len(a) == len(b)
    for fa, fb in zip(a, b):
        np.testing.assert_array_equal(fa["test"], fb["test"])
        for name in ("chance", "svm"):
            np.testing.assert_array_equal(fa[name]["scores"], fb[name]["scores"])


def test_ch3_folds_reused_for_the_same_code_recomputed_for_another(rng, tmp_path, monkeypatch):
    angles, Y, splits, args = _ch3_args(rng)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    calls = _counting(monkeypatch, ch3, "_histograms")
    fits = _counting(monkeypatch, ch3, "_learner_result")
    first = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    # the histograms once per fold, each learner once per fold, one entry per learner and fold
    assert len(calls) == 3 and len(fits) == 6 and len(_entries(tmp_path / "ch3-folds")) == 6
    again = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 3 and len(fits) == 6  # same data, parameters and code: all read back
    _same_folds(first, again)
    monkeypatch.setattr(ch3, "code_fingerprint", lambda: "another code")
    other = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 6 and len(_entries(tmp_path / "ch3-folds")) == 12
    _same_folds(first, other)
    # any parameter is part of the key: a changed learner parameter recomputes
    ch3.evaluate_folds(ctx, angles, Y, splits, **dict(args, streams=ch3.streams(1)))
    assert len(calls) == 9


def test_ch3_torn_fold_is_recomputed(rng, tmp_path, monkeypatch):
    angles, Y, splits, args = _ch3_args(rng)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    first = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    entries = _entries(tmp_path / "ch3-folds")
    _tear(entries[1])
    calls = _counting(monkeypatch, ch3, "_histograms")
    fits = _counting(monkeypatch, ch3, "_learner_result")
    again = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 1 and len(fits) == 1  # only the torn learner of one fold
    _same_folds(first, again)
    assert ch3.evaluate_folds(ctx, angles, Y, splits, **args) and len(fits) == 1  # and it was written again


def test_ch3_folds_cached_by_worker_processes(rng, tmp_path):
    """With two workers each fold's entry is written by the process that computed it; same folds as serial."""
    angles, Y, splits, args = _ch3_args(rng)
    pooled = ch3.evaluate_folds(RunContext(workers=2, cache_dir=tmp_path / "a", show_progress=False), angles, Y,
                                splits, **args)
    assert len(_entries(tmp_path / "a" / "ch3-folds")) == 6
    serial = ch3.evaluate_folds(RunContext(workers=1, cache_dir=tmp_path / "b", show_progress=False), angles, Y,
                                splits, **args)
    _same_folds(pooled, serial)
    _same_folds(pooled, ch3.evaluate_folds(RunContext(workers=1, cache_dir=tmp_path / "a", show_progress=False),
                                           angles, Y, splits, **args))


# --------------------------------------------------------------------------- chapter 5: MFCC of a corpus
@pytest.fixture
def wav_corpus(tmp_path, rng):
    import soundfile as sf

    paths = []
    for i in range(3):
        path = tmp_path / "wav" / f"u{i}.wav"
        path.parent.mkdir(exist_ok=True)
        sf.write(path, 0.1 * rng.normal(size=4000 + 800 * i), 16000)
        paths.append(path)
    return types.SimpleNamespace(paths=paths)


def test_ch5_mfcc_reused_recomputed_and_torn(wav_corpus, tmp_path, monkeypatch):
    from mmconcepts.sound.features import MFCCConfig

    ctx = RunContext(workers=1, cache_dir=tmp_path / "cache", show_progress=False)
    calls = _counting(monkeypatch, speech_protocol, "_mfcc_one")
    first = ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=13))
    assert len(calls) == 3 and [s.shape[1] for s in first] == [13] * 3
    (entry,) = _entries(tmp_path / "cache" / "ch5-mfcc")
    again = ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=13))
    assert len(calls) == 3
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    _tear(entry)
    torn = ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=13))
    assert len(calls) == 6  # recomputed, not a crash
    for a, b in zip(first, torn):
        np.testing.assert_array_equal(a, b)
    ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=12))  # another configuration
    assert len(calls) == 9
    monkeypatch.setattr(speech_protocol, "code_fingerprint", lambda: "another code")
    ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=13))
    assert len(calls) == 12
    wav_corpus.paths[0].write_bytes(wav_corpus.paths[1].read_bytes() + b"\0\0")  # a file changed (size)
    ch5.corpus_mfcc(ctx, wav_corpus, MFCCConfig(n_mfcc=13))
    assert len(calls) == 15


# --------------------------------------------------------------------------- chapter 6: folds and image features
def _fake_fold(task):
    return {"n_train": float(len(task["train"])), "first": float(task["mfcc"][task["test"][0]].sum())}


def test_ch6_folds_reused_recomputed_and_torn(rng, tmp_path, monkeypatch):
    n = 20
    data = {"mfcc": [rng.normal(size=(5, 4)) for _ in range(n)], "angles": [rng.normal(size=(6, 3)) for _ in range(n)],
            "y": np.arange(n) % 4, "fold": np.arange(n) % 2, "n_folds": 2}
    monkeypatch.setattr(ch6, "load_pairs", lambda ctx, **kw: data)
    monkeypatch.setattr(ch6, "_fold", _fake_fold)
    calls = _counting(monkeypatch, ch6, "_fold")

    def config(**kw):
        return types.SimpleNamespace(**{"seed": 0, "n_per_speaker": 5, "n_motion": n, "n_folds": 2, "k": 3,
                                        "n_iter": 5, "motion_bins": 4, "hac_fit_frames": 1000, **kw})

    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    _, first = ch6.evaluate(ctx, config())
    assert len(calls) == 2 and first[0]["n_train"] == 10.0
    entries = _entries(tmp_path / "ch6-folds")
    assert len(entries) == 2  # one per fold
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 2
    _tear(entries[0])
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 3  # the torn fold: recomputed
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 3
    ch6.evaluate(ctx, config(k=4))
    assert len(calls) == 5  # a setting of the learners is part of the key
    ch6.evaluate(ctx, config(hac_fit_frames=500))
    assert len(calls) == 7  # and of the features
    ch6.evaluate(ctx, config(seed=1))
    assert len(calls) == 9  # so are the seeds
    kept = data["mfcc"][3]
    data["mfcc"][3] = kept + 1.0  # and the data
    ch6.evaluate(ctx, config())
    assert len(calls) == 11
    data["mfcc"][3] = kept
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 11
    monkeypatch.setattr(ch6, "code_fingerprint", lambda: "another code")
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 13


def test_ch6_interrupted_evaluation_keeps_the_folds_it_finished(rng, tmp_path, monkeypatch):
    n = 30
    data = {"mfcc": [rng.normal(size=(5, 4)) for _ in range(n)], "angles": [rng.normal(size=(6, 3)) for _ in range(n)],
            "y": np.arange(n) % 4, "fold": np.arange(n) % 3, "n_folds": 3}
    monkeypatch.setattr(ch6, "load_pairs", lambda ctx, **kw: data)
    config = types.SimpleNamespace(seed=0, n_per_speaker=5, n_motion=n, n_folds=3, k=3, n_iter=5, motion_bins=4,
                                   hac_fit_frames=1000)
    calls = []

    def stop_at_third(task):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return _fake_fold(task)

    monkeypatch.setattr(ch6, "_fold", stop_at_third)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    with pytest.raises(KeyboardInterrupt):
        ch6.evaluate(ctx, config)
    assert len(_entries(tmp_path / "ch6-folds")) == 2
    calls.clear()
    monkeypatch.setattr(ch6, "_fold", lambda task: (calls.append(1), _fake_fold(task))[1])
    _, resumed = ch6.evaluate(ctx, config)
    assert len(calls) == 1 and resumed == [_fake_fold(t) for t in ch6.fold_tasks(data, config, ch6.streams(0))]


def test_ch6_image_locals_reused_recomputed_and_torn(rng, tmp_path, monkeypatch):
    def fake_chunk(images):
        return [float(im.sum()) for im in images], [im.shape for im in images]

    monkeypatch.setattr(ch6, "_locals_chunk", fake_chunk)
    calls = _counting(monkeypatch, ch6, "_locals_chunk")
    images = [rng.random((4, 5, 3)) for _ in range(5)]
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    first = ch6.image_locals(ctx, images, chunk=2)
    assert len(calls) == 3 and first == fake_chunk(images)
    assert ch6.image_locals(ctx, images, chunk=2) == first and len(calls) == 3
    assert ch6.image_locals(ctx, images[::-1], chunk=2) != first and len(calls) == 6  # other images
    assert len(_entries(tmp_path / "ch6-image-locals")) == 2
    for entry in _entries(tmp_path / "ch6-image-locals"):
        _tear(entry)
    assert ch6.image_locals(ctx, images, chunk=2) == first and len(calls) == 9  # torn: recomputed
    monkeypatch.setattr(ch6, "code_fingerprint", lambda: "another code")
    assert ch6.image_locals(ctx, images, chunk=2) == first and len(calls) == 12



# --------------------------------------------------------------------------- the store itself
def _add(a, b):
    return a + b


def test_run_context_memory_lives_under_the_cache_dir(tmp_path):
    memory = RunContext(cache_dir=tmp_path, show_progress=False).memory("ch3-folds")
    cached = memory.cache(_add)
    assert cached(1, 2) == 3 and cached(1, 2) == 3 and cached_call(cached, 1, 2) == 3
    assert len(_entries(tmp_path / "ch3-folds")) == 1
    # the entries under the store's folder, their locks under the cache folder's one lock folder
    assert all(p.is_relative_to(tmp_path / "ch3-folds") or p.is_relative_to(tmp_path / ".locks")
               for p in tmp_path.rglob("*"))
    (lock,) = (tmp_path / ".locks").rglob("*.lock")
    assert lock.relative_to(tmp_path / ".locks").parts[0] == "ch3-folds"
    assert not list(tmp_path.rglob("*.pkl"))


_computed = []


def _planted_target(x, note):
    _computed.append(x)
    return {"x": np.arange(x), "note": note}


def test_a_planted_pickle_is_never_loaded(tmp_path):
    marker = tmp_path / "marker"
    planted = planted_pickle(marker)
    store = RunContext(cache_dir=tmp_path / "cache", show_progress=False).memory("ch3-folds")
    cached = store.cache(_planted_target, ignore=["note"])
    entry = cached.path(cached.key(3, "a"))
    # where an old joblib cache kept its outputs, and at the entry's own name
    old = tmp_path / "cache" / "ch3-folds" / "joblib" / __name__ / "_planted_target" / "0123abcd" / "output.pkl"
    old.parent.mkdir(parents=True)
    old.write_bytes(planted)
    entry.parent.mkdir(parents=True)
    entry.write_bytes(planted)
    _computed.clear()
    value = cached_call(cached, 3, "a")
    assert not marker.exists() and _computed == [3]  # recomputed, not loaded
    np.testing.assert_array_equal(value["x"], np.arange(3))
    again = cached_call(cached, 3, "b")  # note is not hashed: the (rewritten) entry is read back
    assert _computed == [3] and again["note"] == "a" and not marker.exists()
    # an npz archive in our format whose array member is a pickled object
    header = json.dumps({"format": ENTRY_FORMAT, "key": cached.key(4, "a"),
                         "value": {"x": {MARK: "array", "entry": "a0"}, "note": "a"}})
    planted_npz = cached.path(cached.key(4, "a"))
    with open(planted_npz, "wb") as fh:
        np.savez(fh, **{HEADER: np.array(header)}, a0=np.array([Plant(marker)], dtype=object))
    value = cached_call(cached, 4, "a")
    assert not marker.exists() and _computed == [3, 4]
    np.testing.assert_array_equal(value["x"], np.arange(4))
    # an entry naming a class outside the package as a named tuple or an estimator is not built either
    for x, node in ((5, {MARK: "namedtuple", "class": "pathlib:Path.touch", "fields": [], "items": []}),
                    (6, {MARK: "estimator", "class": "pathlib.Path", "params": {}, "state": {}})):
        header = json.dumps({"format": ENTRY_FORMAT, "key": cached.key(x, "a"), "value": node})
        with open(cached.path(cached.key(x, "a")), "wb") as fh:
            np.savez(fh, **{HEADER: np.array(header)})
        assert cached_call(cached, x, "a")["x"].shape == (x,) and _computed[-1] == x
    assert _computed == [3, 4, 5, 6] and not marker.exists()


def test_an_unsupported_result_is_a_clear_error(tmp_path):
    from mmconcepts.errors import ExperimentError

    cached = RunContext(cache_dir=tmp_path, show_progress=False).memory("x").cache(_identity_value)
    for bad, what in (({1, 2}, "a set"), (np.array([None]), "Python objects"), ([object()], "an object"),
                      (b"raw", "a bytes"), ({"k": [np.random.default_rng(0)]}, r"result\.k\[0\]: a numpy\.random")):
        with pytest.raises(ExperimentError, match=what):
            cached(bad)
    assert not _entries(tmp_path)


def _identity_value(x):
    _computed.append("identity")
    return x


def assert_same(a, b, where="value"):
    """``a`` and ``b`` are the same: types, dtypes, shapes and bits (NaN payloads and -0.0 included)."""
    assert type(a) is type(b), (where, type(a), type(b))
    if isinstance(a, np.ndarray) and a.dtype == object:  # strings: compared as such (tobytes gives addresses)
        assert b.dtype == object and a.shape == b.shape and a.ravel().tolist() == b.ravel().tolist(), where
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), where
    elif isinstance(a, np.generic):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), where
    elif isinstance(a, float):
        assert struct.pack("<d", a) == struct.pack("<d", b), (where, a, b)
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    else:
        assert a == b, (where, a, b)


_DTYPES = st.sampled_from([np.float64, np.float32, np.float16, np.int64, np.int32, np.uint8, np.bool_,
                           np.complex128, "U3", "datetime64[s]"])
_ARRAYS = hnp.arrays(_DTYPES, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4))
_FLOATS = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([-0.0, float("nan"), -float("nan"),
                                                                              struct.unpack("<d", b"\x01\0\0\0\0\0\xf8\x7f")[0]])
_LEAVES = (st.none() | st.booleans() | st.integers() | _FLOATS | st.text(max_size=8) | _ARRAYS
           | _ARRAYS.filter(lambda a: a.ndim == 0).map(lambda a: a[()])
           | st.lists(st.text(max_size=3), max_size=4).map(lambda xs: np.array(xs, dtype=object)))
_TREES = st.recursive(
    _LEAVES,
    lambda kids: (st.lists(kids, max_size=4) | st.lists(kids, max_size=4).map(tuple)
                  | st.dictionaries(st.text(max_size=6) | st.just(MARK), kids, max_size=4)
                  | st.dictionaries(st.integers() | st.tuples(st.integers(), st.text(max_size=2)) | st.none(), kids,
                                    max_size=4)),
    max_leaves=25,
)


def _local_features():
    from mmconcepts.vision.features import LocalFeatures

    n = st.integers(0, 5)
    return n.flatmap(lambda k: st.builds(
        LocalFeatures, hnp.arrays(np.float64, (k, 3), elements=_FLOATS), hnp.arrays(np.float64, (k, 2)),
        hnp.arrays(np.float64, (k,))))


_CH3_FOLD = st.builds(  # ch3.protocol._fold: test indices, seconds, per learner scores / pred / threshold
    lambda n, L, learners, data: {"test": data.draw(hnp.arrays(np.int64, n)), "feature_seconds": data.draw(_FLOATS),
                                  **{name: {"scores": data.draw(hnp.arrays(np.float64, (n, L), elements=_FLOATS)),
                                            "pred": data.draw(hnp.arrays(np.int64, (n, L))),
                                            "threshold": data.draw(_FLOATS), "seconds": data.draw(_FLOATS)}
                                     for name in learners}},
    st.integers(0, 6), st.integers(1, 4), st.lists(st.sampled_from(["nmf_kl", "svm", "chance"]), unique=True),
    st.data())
_CH6_FOLD = st.dictionaries(st.text(min_size=1, max_size=30), _FLOATS | _FLOATS.map(np.float64))
_CH5_MFCC = st.lists(hnp.arrays(st.sampled_from([np.float32, np.float64]), hnp.array_shapes(min_dims=2, max_dims=2,
                                                                                          min_side=0)))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(value=_TREES | _CH3_FOLD | _CH6_FOLD | _CH5_MFCC
       | st.tuples(st.lists(st.deferred(_local_features)), st.lists(st.deferred(_local_features))))
def test_round_trip_is_exact(value):
    """What is read back from an entry is what was computed: types (tuples stay tuples), dtypes, shapes, bits."""
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "e.npz"
        _store.write_entry(path, value, "k")
        assert_same(value, _store.read_entry(path, "k"))
        arrays = {}
        structure = _codec.encode(value, arrays)
        assert_same(value, _codec.decode(json.loads(json.dumps(structure, allow_nan=False)), arrays))


def test_a_hit_returns_what_the_miss_returned(tmp_path):
    from mmconcepts.vision.features import LocalFeatures

    value = ({"a": np.float64(0.1), "b": [1, 2.5, None, True, "x", (1, 2)], "c": np.arange(3, dtype=np.int32)},
             [LocalFeatures(np.zeros((2, 3)), np.ones((2, 2), np.float32), np.ones(2))], float("nan"))
    cached = RunContext(cache_dir=tmp_path, show_progress=False).memory("x").cache(_identity_value)
    _computed.clear()
    miss = cached(value)
    hit = cached(value)
    assert _computed == ["identity"]  # the second call was read back
    assert_same(value, miss)
    assert_same(miss, hit)
    assert type(hit[1][0]) is LocalFeatures


def _logged_square(x, log_dir, fail_on):
    """x * x, writing a file per call to ``log_dir``; the call ``x == fail_on`` waits, then fails."""
    import os
    import time

    (pathlib.Path(log_dir) / f"{x}-{os.getpid()}-{time.monotonic_ns()}").touch()
    if x == fail_on:
        time.sleep(1.0)  # the other calls end first
        raise RuntimeError("interrupted")
    return {"x": x, "square": np.array([x * x])}


def test_an_interrupted_parallel_run_keeps_the_calls_it_finished(tmp_path):
    log = tmp_path / "log"
    log.mkdir()
    ctx = RunContext(workers=2, cache_dir=tmp_path / "cache", show_progress=False)
    cached = ctx.memory("squares").cache(_logged_square, ignore=["log_dir", "fail_on"])
    with pytest.raises(RuntimeError, match="interrupted"):
        ctx.parallel_cached(cached, [(x, str(log), 5) for x in range(6)])
    assert len({p.name.split("-")[1] for p in log.iterdir()}) == 2  # two worker processes ran them
    assert len(_entries(tmp_path / "cache" / "squares")) == 5  # each written by its worker as it ended
    for p in log.iterdir():
        p.unlink()
    out = ctx.parallel_cached(cached, [(x, str(log), -1) for x in range(6)])
    assert [p.name.split("-")[0] for p in log.iterdir()] == ["5"]  # only the unfinished call ran again
    assert [o["x"] for o in out] == list(range(6)) and [int(o["square"][0]) for o in out] == [x * x for x in range(6)]


def test_an_entry_that_cannot_be_written_or_read_is_computed(tmp_path, caplog):
    """A folder where the entry should be (neither readable nor replaceable): computed each time, no crash."""
    cached = RunContext(cache_dir=tmp_path, show_progress=False).memory("x").cache(_identity_value)
    cached.path(cached.key(7)).mkdir(parents=True)
    _computed.clear()
    assert cached(7) == 7 and cached(7) == 7 and _computed == ["identity"] * 2
    assert "not written" in caplog.text


def test_the_temporary_file_of_a_killed_writer_is_removed_later(tmp_path):
    import os
    import time

    store = RunContext(cache_dir=tmp_path, show_progress=False).memory("x")
    cached = store.cache(_identity_value)
    cached(1)
    old, new = cached.location / ".abc.npz.x1.tmp.npz", cached.location / ".def.npz.x2.tmp.npz"
    old.write_bytes(b"PK")
    new.write_bytes(b"PK")
    os.utime(old, (time.time() - 7200,) * 2)
    store.cache(_identity_value)
    assert not old.exists() and new.exists() and len(_entries(tmp_path)) == 1  # a recent one may be being written


def _slow_logged(x, log_dir):
    """x + 1 after 0.5 s, leaving one file per call in ``log_dir`` (to count the calls across processes)."""
    import os
    import time

    (pathlib.Path(log_dir) / f"{x}-{os.getpid()}-{time.monotonic_ns()}").touch()
    time.sleep(0.5)
    return {"x": np.array([x + 1])}


_BARRIER = None  # set before the worker processes are forked: both calls start together


def _call_cached(args):
    import os

    cache_dir, log_dir, x, via_compute = args
    cached = RunContext(cache_dir=cache_dir, show_progress=False).memory("slow").cache(_slow_logged,
                                                                                       ignore=["log_dir"])
    _BARRIER.wait(timeout=60)  # fails (BrokenBarrierError) unless two processes got here at once
    return int((cached.compute(x, log_dir) if via_compute else cached(x, log_dir))["x"][0]), os.getpid()


@pytest.mark.parametrize("via_compute", [False, True], ids=["call", "compute after a miss"])
def test_concurrent_processes_compute_a_missing_entry_once(tmp_path, via_compute, monkeypatch):
    """Two processes sharing a cache folder (``reproduce --concurrent``) asking for the same missing
    entry at the same time: one computes it, the other waits for it and reads it."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("fork")
    monkeypatch.setitem(globals(), "_BARRIER", ctx.Barrier(2))  # inherited by the forked workers
    log = tmp_path / "log"
    log.mkdir()
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        out = list(pool.map(_call_cached, [(str(tmp_path / "cache"), str(log), 3, via_compute)] * 2))
    assert [v for v, _ in out] == [4, 4] and out[0][1] != out[1][1]  # two processes
    assert len(list(log.iterdir())) == 1
    assert len(_entries(tmp_path / "cache" / "slow")) == 1


def test_an_unwritable_cache_folder_computes_without_a_lock(tmp_path):
    """No lock can be made where the store cannot be created: the value is still computed."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    cached = RunContext(cache_dir=blocker, show_progress=False).memory("x").cache(_identity_value)
    _computed.clear()
    assert cached(5) == 5 and _computed == ["identity"]
