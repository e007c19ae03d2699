"""The experiments' disk caches (issue 13: joblib.Memory instead of hand-rolled pickle caches).

Each cache (chapter-3 folds, chapter-5 MFCC, chapter-6 folds and image local features) is a
:class:`joblib.Memory` under ``ctx.cache_dir/<name>`` (:meth:`RunContext.memory`). What the
tests pin: an entry is reused for the same data, parameters and code fingerprint; a change
of code fingerprint recomputes; a torn entry recomputes instead of crashing; the result is
the same whether it was computed or read back.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from mmconcepts.experiments import RunContext
from mmconcepts.experiments import _ch3_common as ch3
from mmconcepts.experiments import _ch5_common as ch5
from mmconcepts.experiments import _ch6_common as ch6


def _entries(folder):
    return sorted(folder.rglob("output.pkl"))


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


# --------------------------------------------------------------------------- chapter 3: one entry per fold
def _ch3_args(rng):
    angles = [rng.normal(size=(20, 3)) + (i % 2) for i in range(12)]
    Y = np.eye(2)[np.arange(12) % 2]
    return angles, Y, ch3.kfold_splits(12, 3, seed=0), dict(
        features={"data": "joint", "method": "kde", "n_bins": 5, "delay": 1}, learners=("chance", "svm"),
        params={}, seed=0, single=True)


def _same_folds(a, b):
    assert len(a) == len(b)
    for fa, fb in zip(a, b):
        np.testing.assert_array_equal(fa["test"], fb["test"])
        for name in ("chance", "svm"):
            np.testing.assert_array_equal(fa[name]["scores"], fb[name]["scores"])


def test_ch3_folds_reused_for_the_same_code_recomputed_for_another(rng, tmp_path, monkeypatch):
    angles, Y, splits, args = _ch3_args(rng)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    calls = _counting(monkeypatch, ch3, "_fold")
    first = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 3 and len(_entries(tmp_path / "ch3-folds")) == 3
    again = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 3  # same data, parameters and code: all read back
    _same_folds(first, again)
    monkeypatch.setattr(ch3, "code_fingerprint", lambda: "another code")
    other = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 6 and len(_entries(tmp_path / "ch3-folds")) == 6
    _same_folds(first, other)
    # any parameter is part of the key: a changed learner parameter recomputes
    ch3.evaluate_folds(ctx, angles, Y, splits, **dict(args, seed=1))
    assert len(calls) == 9


def test_ch3_torn_fold_is_recomputed(rng, tmp_path, monkeypatch):
    angles, Y, splits, args = _ch3_args(rng)
    ctx = RunContext(workers=1, cache_dir=tmp_path, show_progress=False)
    first = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    entries = _entries(tmp_path / "ch3-folds")
    _tear(entries[1])
    calls = _counting(monkeypatch, ch3, "_fold")
    again = ch3.evaluate_folds(ctx, angles, Y, splits, **args)
    assert len(calls) == 1  # only the torn fold
    _same_folds(first, again)
    assert ch3.evaluate_folds(ctx, angles, Y, splits, **args) and len(calls) == 1  # and it was written again


def test_ch3_folds_cached_by_worker_processes(rng, tmp_path):
    """With two workers each fold's entry is written by the process that computed it; same folds as serial."""
    angles, Y, splits, args = _ch3_args(rng)
    pooled = ch3.evaluate_folds(RunContext(workers=2, cache_dir=tmp_path / "a", show_progress=False), angles, Y,
                                splits, **args)
    assert len(_entries(tmp_path / "a" / "ch3-folds")) == 3
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
    calls = _counting(monkeypatch, ch5, "_mfcc_one")
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
    monkeypatch.setattr(ch5, "code_fingerprint", lambda: "another code")
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
                                        "n_iter": 5, "motion_bins": 4, **kw})

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
    ch6.evaluate(ctx, config(seed=1))
    assert len(calls) == 7  # so are the seeds
    kept = data["mfcc"][3]
    data["mfcc"][3] = kept + 1.0  # and the data
    ch6.evaluate(ctx, config())
    assert len(calls) == 9
    data["mfcc"][3] = kept
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 9
    monkeypatch.setattr(ch6, "code_fingerprint", lambda: "another code")
    assert ch6.evaluate(ctx, config())[1] == first and len(calls) == 11


def test_ch6_interrupted_evaluation_keeps_the_folds_it_finished(rng, tmp_path, monkeypatch):
    n = 30
    data = {"mfcc": [rng.normal(size=(5, 4)) for _ in range(n)], "angles": [rng.normal(size=(6, 3)) for _ in range(n)],
            "y": np.arange(n) % 4, "fold": np.arange(n) % 3, "n_folds": 3}
    monkeypatch.setattr(ch6, "load_pairs", lambda ctx, **kw: data)
    config = types.SimpleNamespace(seed=0, n_per_speaker=5, n_motion=n, n_folds=3, k=3, n_iter=5, motion_bins=4)
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


def _add(a, b):
    return a + b


def test_run_context_memory_lives_under_the_cache_dir(tmp_path):
    memory = RunContext(cache_dir=tmp_path, show_progress=False).memory("ch3-folds")
    cached = memory.cache(_add)
    assert cached(1, 2) == 3 and cached(1, 2) == 3
    assert _entries(tmp_path / "ch3-folds") and all(p.is_relative_to(tmp_path) for p in tmp_path.rglob("*"))


class _SlowRepr:
    """An argument whose repr (written to the cache entry's metadata) takes longer than joblib's 0.5 s."""

    def __repr__(self):
        import time

        time.sleep(0.6)
        return "slow"


def _identity(x):
    return 1


def test_cached_call_keeps_joblibs_slow_write_note_out_of_the_run(tmp_path, recwarn):
    import warnings

    from mmconcepts.experiments.base import cached_call

    cached = RunContext(cache_dir=tmp_path, show_progress=False).memory("slow").cache(_identity)
    warnings.simplefilter("always")
    assert cached(_SlowRepr()) == 1
    assert any("Persisting input arguments took" in str(w.message) for w in recwarn)  # what it keeps out
    recwarn.clear()
    cached.clear(warn=False)
    assert cached_call(cached, _SlowRepr()) == 1 and not recwarn.list
