"""Speech corpora: the generic audio layout and the ACORNS Caregiver loader (mmconcepts.sound.data)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("soundfile", reason="audio I/O needs the 'audio' extra (soundfile)")

from mmconcepts.errors import DataFormatError, ParameterError
from mmconcepts.sound.audio import write_audio
from mmconcepts.sound.data import (
    SpeechCorpus,
    Utterance,
    WordTiming,
    load_acorns,
    load_generic_audio,
    save_generic_audio,
)

SR = 16000


def _wav(path, rng, seconds=0.5, sr=SR):
    return write_audio(path, 0.1 * rng.standard_normal(int(seconds * sr)).clip(-1, 1), sr)


@pytest.fixture
def generic(tmp_path, rng):
    root = tmp_path / "corpus"
    _wav(root / "a" / "u1.wav", rng, 0.5)
    _wav(root / "a" / "u2.wav", rng, 0.8, sr=22050)
    _wav(root / "b" / "u3.wav", rng, 0.6)
    _wav(root / "b" / "u4.wav", rng, 0.4)
    (root / "labels.csv").write_text(
        "file,speaker,labels,transcription\n"
        "a/u1.wav,s1,car,Where is the car\n"
        "a/u2.wav,s1,mummy;bath,Mummy is in the bath\n"
        "b/u3.wav,s2,book,\n"
        "b/u4.wav,s2,,\n"
    )
    (root / "word_timings.csv").write_text(
        "file,word,start,end\n"
        "a/u1.wav,Where,0.00,0.10\na/u1.wav,is,0.10,0.15\na/u1.wav,the,0.15,0.20\na/u1.wav,car,0.20,0.45\n"
        "a/u2.wav,Mummy,0.05,0.30\na/u2.wav,is,0.30,0.40\na/u2.wav,in,0.40,0.45\na/u2.wav,the,0.45,0.50\n"
        "a/u2.wav,bath,0.50,0.75\n"
    )
    return root


def test_generic_layout_loads_labels_timings_and_audio(generic):
    c = load_generic_audio(generic)
    assert len(c) == 4 and c.skipped == []
    assert c.labels == [("car",), ("mummy", "bath"), ("book",), ()]
    assert c.keywords == ("bath", "book", "car", "mummy")
    assert c.speakers == ("s1", "s2")
    assert c.transcriptions[1] == "Mummy is in the bath" and c.transcriptions[2] == ""
    Y = c.label_matrix()
    np.testing.assert_array_equal(Y, [[0, 0, 1, 0], [1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 0, 0]])
    np.testing.assert_array_equal(c.label_matrix(["mummy", "car"]), [[0, 1], [1, 0], [0, 0], [0, 0]])
    assert c[0].word_timings[-1] == WordTiming("car", 0.20, 0.45)
    assert c[2].word_timings is None
    assert c[1].keyword_span() == (0.05, 0.30) and c[1].keyword_span("bath") == (0.50, 0.75)
    spans = c.keyword_spans()
    np.testing.assert_allclose(spans[:2], [[0.20, 0.45], [0.05, 0.30]])
    assert np.isnan(spans[2:]).all()
    assert c[1].duration == pytest.approx(0.8, abs=1e-3)
    assert c.load(1).size == pytest.approx(0.8 * SR, abs=2)  # resampled from 22.05 kHz
    assert c.load(1, sr=None).size == pytest.approx(0.8 * 22050, abs=1)


def test_subset_by_mask_and_indices(generic):
    c = load_generic_audio(generic)
    s2 = c.subset(c.speaker_ids == "s2")
    assert [u.path.name for u in s2] == ["u3.wav", "u4.wav"]
    assert [u.path.name for u in c.subset([2, 0])] == ["u3.wav", "u1.wav"]
    assert len(c.by_speaker("s1")) == 2
    with pytest.raises(ParameterError, match="mask"):
        c.subset(np.array([True, False]))
    with pytest.raises(ParameterError, match="Unknown speaker"):
        c.by_speaker("s9")


def test_missing_column_raises_naming_labels_csv(tmp_path, rng):
    _wav(tmp_path / "x.wav", rng)
    (tmp_path / "labels.csv").write_text("file,labels\nx.wav,car\n")
    with pytest.raises(DataFormatError, match=r"labels\.csv.*speaker"):
        load_generic_audio(tmp_path)


def test_transcription_column_is_optional(tmp_path, rng):
    _wav(tmp_path / "x.wav", rng)
    (tmp_path / "labels.csv").write_text("file,speaker,labels\nx.wav,s,car;shoe\n")
    c = load_generic_audio(tmp_path)
    assert c[0].labels == ("car", "shoe") and c[0].transcription == ""


def test_skip_mode_reports_bad_files(generic):
    (generic / "b" / "u3.wav").write_bytes(b"not audio at all")
    with open(generic / "labels.csv", "a") as f:
        f.write("b/missing.wav,s2,car,\n")
    with pytest.raises(DataFormatError, match="u3.wav"):
        load_generic_audio(generic)
    with pytest.warns(RuntimeWarning, match="2 file"):
        c = load_generic_audio(generic, on_error="skip")
    assert [u.path.name for u in c] == ["u1.wav", "u2.wav", "u4.wav"]
    skipped = {f.split("/")[-1]: reason for f, reason in c.skipped}
    assert set(skipped) == {"u3.wav", "missing.wav"}
    assert "not found" in skipped["missing.wav"]
    with pytest.raises(ParameterError, match="on_error"):
        load_generic_audio(generic, on_error="ignore")


def test_bad_timings_are_errors(generic):
    path = generic / "word_timings.csv"
    path.write_text("file,word,start,end\na/u1.wav,car,0.2,3.0\n")  # beyond the 0.5 s file
    with pytest.raises(DataFormatError, match="after the end"):
        load_generic_audio(generic)
    path.write_text("file,word,start,end\na/u1.wav,car,0.3,0.2\n")
    with pytest.raises(DataFormatError, match="start <= end"):
        load_generic_audio(generic)
    path.write_text("file,word,start,end\nzz.wav,car,0.1,0.2\n")
    with pytest.raises(DataFormatError, match="not listed"):
        load_generic_audio(generic)
    path.write_text("file,word,start,end\na/u1.wav,car,0.3,0.4\na/u1.wav,the,0.1,0.2\n")
    with pytest.warns(RuntimeWarning):
        c = load_generic_audio(generic, on_error="skip")
    assert [u.path.name for u in c] == ["u2.wav", "u3.wav", "u4.wav"]


def test_save_generic_audio_round_trip(generic, tmp_path):
    c = load_generic_audio(generic)
    (generic / "labels.csv").unlink()
    (generic / "word_timings.csv").unlink()
    save_generic_audio(c, generic)
    d = load_generic_audio(generic)
    assert d.labels == c.labels and d.transcriptions == c.transcriptions and d.speakers == c.speakers
    assert d[1].word_timings == c[1].word_timings


# --------------------------------------------------------------------------- ACORNS

_Y1 = """<?xml version="1.0" encoding="UTF-8"?>
<utterance>
  <style value="ADS"/>
  <audio-file value="{audio}"/>
  <vistag value="{tag}"/>
  <trans value="{trans}"/>
</utterance>
"""

# year 2 spelling, with values as element text and other case/underscore spellings
_Y2 = """<?xml version="1.0"?>
<Utterance>
  <Style>IDS</Style>
  <audio_file>{audio}.wav</audio_file>
  <vistags value="{tag}"/>
  <trans>{trans}</trans>
</Utterance>
"""


@pytest.fixture
def acorns(tmp_path, rng):
    root = tmp_path / "acorns"
    rows = [
        ("Speaker-01", "s01_001", _Y1, "Angus", "Angus is lazy today"),
        ("Speaker-01", "s01_002", _Y1, "mummy", "Now mummy is losing her patience"),
        ("Speaker-02", "s02_001", _Y2, "car", "Now everybody is in the car"),
        ("Speaker-02", "s02_002", _Y2, "nappy shoe", "She puts the nappy in the shoe"),
    ]
    for spk, name, tpl, tag, trans in rows:
        (root / "XML" / spk).mkdir(parents=True, exist_ok=True)
        (root / "XML" / spk / f"{name}.xml").write_text(tpl.format(audio=name, tag=tag, trans=trans))
        _wav(root / "WAV" / spk / f"{name}.wav", rng, 0.3)
    return root


def test_acorns_tree_loads_with_the_right_tags(acorns):
    c = load_acorns(acorns)
    assert len(c) == 4 and c.skipped == []
    assert c.speakers == ("01", "02")
    assert c.labels == [("Angus",), ("mummy",), ("car",), ("nappy", "shoe")]
    assert c.transcriptions[1] == "Now mummy is losing her patience"
    assert c[2].transcription == "Now everybody is in the car"
    assert [u.meta["style"] for u in c] == ["ADS", "ADS", "IDS", "IDS"]
    assert c[3].path.name == "s02_002.wav" and c[3].duration == pytest.approx(0.3, abs=1e-3)
    assert c.label_matrix().shape == (4, 5)
    assert len(load_acorns(acorns, speakers=["1"])) == 2


def test_acorns_unknown_structure_names_the_file(acorns):
    bad = acorns / "XML" / "Speaker-01" / "s01_003.xml"
    bad.write_text("<utterance><speaker value='x'/><trans value='hello'/></utterance>")
    with pytest.raises(DataFormatError, match=r"s01_003\.xml.*unknown ACORNS structure.*vistag"):
        load_acorns(acorns)
    broken = acorns / "XML" / "Speaker-02" / "s02_009.xml"
    broken.write_text("<utterance><audio-file value='s02_009'/>")
    missing_wav = acorns / "XML" / "Speaker-02" / "s02_010.xml"
    missing_wav.write_text(_Y1.format(audio="s02_010", tag="car", trans="x"))
    with pytest.warns(RuntimeWarning, match="3 file"):
        c = load_acorns(acorns, on_error="skip")
    assert len(c) == 4
    reasons = dict(c.skipped)
    assert "unknown ACORNS structure" in reasons[str(bad)]
    assert "not well-formed" in reasons[str(broken)]
    assert "not found" in reasons[str(missing_wav)]


def test_acorns_layout_errors(tmp_path):
    (tmp_path / "XML").mkdir()
    with pytest.raises(DataFormatError, match="WAV"):
        load_acorns(tmp_path)


def test_corpus_from_utterances(tmp_path, rng):
    p = _wav(tmp_path / "z.wav", rng)
    c = SpeechCorpus([Utterance(p, "s", ("a",)), Utterance(p, "t", ("b", "a"))])
    np.testing.assert_array_equal(c.label_matrix(), [[1, 0], [1, 1]])
    assert c.speakers == ("s", "t") and len(c.subset(np.array([False, True]))) == 1


# --------------------------------------------------------------------------- FSDD

from conftest import real_data_path  # noqa: E402

from mmconcepts.errors import DataError  # noqa: E402
from mmconcepts.sound.data import FSDD_WORDS, compose_utterances, composed_sources, load_fsdd  # noqa: E402

FSDD_FILES = [("3", "bob", 1), ("0", "alice", 0), ("1", "alice", 0), ("0", "bob", 0), ("0", "alice", 10),
              ("0", "alice", 2)]


def _fsdd_upstream(root, rng):
    for d, spk, i in FSDD_FILES:
        _wav(root / "recordings" / f"{d}_{spk}_{i}.wav", rng, 0.3 + 0.05 * int(d), sr=8000)
    return root


def test_fsdd_upstream_layout_labels_and_speakers_from_file_names(tmp_path, rng):
    root = _fsdd_upstream(tmp_path / "free-spoken-digit-dataset", rng)
    c = load_fsdd(root)
    assert c.name == "fsdd" and c.skipped == []
    # ordered by speaker, digit, index (numerically: 0_alice_2 before 0_alice_10)
    assert [u.path.name for u in c] == ["0_alice_0.wav", "0_alice_2.wav", "0_alice_10.wav", "1_alice_0.wav",
                                        "0_bob_0.wav", "3_bob_1.wav"]
    assert c.labels == [("zero",), ("zero",), ("zero",), ("one",), ("zero",), ("three",)]
    assert c.speakers == ("alice", "bob") and c[5].transcription == "three"
    assert c[5].meta == {"digit": 3, "index": 1} and c[5].duration == pytest.approx(0.45, abs=1e-3)
    # 8 kHz on disk, 16 kHz for the pipeline
    assert c.load(5, sr=None).size == 3600 and c.load(5).size == pytest.approx(7200, abs=2)
    assert load_fsdd(root / "recordings").labels == c.labels  # the recordings/ folder itself
    assert [u.path.name for u in load_fsdd(root, speakers=["bob"])] == ["0_bob_0.wav", "3_bob_1.wav"]
    with pytest.raises(ParameterError, match="carol"):
        load_fsdd(root, speakers=["bob", "carol"])


def test_fsdd_generic_layout_gives_the_same_corpus(tmp_path, rng):
    up = load_fsdd(_fsdd_upstream(tmp_path / "up", rng))
    root = tmp_path / "generic"
    root.mkdir()
    rows = ["file,speaker,labels,transcription"]
    for d, spk, i in reversed(FSDD_FILES):  # table order must not matter
        name = f"{d}_{spk}_{i}.wav"
        (root / name).write_bytes((tmp_path / "up" / "recordings" / name).read_bytes())
        rows.append(f"{name},{spk},{FSDD_WORDS[int(d)]},{FSDD_WORDS[int(d)]}")
    (root / "labels.csv").write_text("\n".join(rows) + "\n")
    gen = load_fsdd(root)
    assert [u.path.name for u in gen] == [u.path.name for u in up]
    assert gen.labels == up.labels and list(gen.speaker_ids) == list(up.speaker_ids)
    assert [u.meta for u in gen] == [u.meta for u in up]


def test_fsdd_corrupt_wav_is_an_error_or_a_logged_skip(tmp_path, rng, caplog):
    root = _fsdd_upstream(tmp_path / "fsdd", rng)
    (root / "recordings" / "1_alice_0.wav").write_bytes(b"RIFF\x00\x00\x00\x00WAVEgarbage")
    with pytest.raises(DataFormatError, match=r"1_alice_0\.wav"):
        load_fsdd(root)
    with caplog.at_level("WARNING", logger="mmconcepts.sound.data"), pytest.warns(RuntimeWarning, match="1 file"):
        c = load_fsdd(root, on_error="skip")
    assert len(c) == len(FSDD_FILES) - 1 and "one" not in c.keywords
    assert [s.file.split("/")[-1] for s in c.skipped] == ["1_alice_0.wav"]
    assert any("1_alice_0.wav" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)


def test_fsdd_badly_named_file_and_empty_folder(tmp_path, rng):
    root = _fsdd_upstream(tmp_path / "fsdd", rng)
    _wav(root / "recordings" / "hello.wav", rng, 0.2, sr=8000)
    with pytest.raises(DataFormatError, match=r"hello\.wav.*digit"):
        load_fsdd(root)
    with pytest.warns(RuntimeWarning):
        assert len(load_fsdd(root, on_error="skip")) == len(FSDD_FILES)
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataFormatError, match="not an FSDD folder"):
        load_fsdd(tmp_path / "empty")
    with pytest.raises(FileNotFoundError):
        load_fsdd(tmp_path / "nowhere")


def test_fsdd_real_set_file_names_agree_with_labels():
    root = real_data_path("fsdd")
    c = load_fsdd(root, check_audio=False)
    assert len(c) > 0 and set(c.keywords) <= set(FSDD_WORDS)
    for u in c:
        d, spk, _ = u.path.stem.split("_")
        assert u.labels == (FSDD_WORDS[int(d)],) and u.speaker == spk
    first = c.by_speaker(c.speakers[0])
    assert set(first.keywords) == set(FSDD_WORDS)  # every speaker says every digit
    y8, y16 = first.load(0, sr=None), first.load(0)
    assert abs(len(y16) - 2 * len(y8)) <= 2  # 8 kHz resampled explicitly to the pipeline's 16 kHz


# --------------------------------------------------------------------------- composed utterances


@pytest.fixture
def words_corpus(tmp_path, rng):
    """Two speakers, four words each, two recordings per word, at 8 kHz, of different lengths."""
    root = tmp_path / "words"
    rows = ["file,speaker,labels,transcription"]
    for spk in ("s1", "s2"):
        for w, word in enumerate(("red", "green", "blue", "black")):
            for k in range(2):
                name = f"{spk}_{word}_{k}.wav"
                _wav(root / name, rng, 0.2 + 0.03 * w + 0.01 * k, sr=8000)
                rows.append(f"{name},{spk},{word},{word}")
    (root / "labels.csv").write_text("\n".join(rows) + "\n")
    return load_generic_audio(root)


def test_composed_utterances_timings_labels_and_audio_are_exact(words_corpus, tmp_path):
    comp = compose_utterances(words_corpus, tmp_path / "comp", n_utterances=12, n_words=(2, 4),
                              pause_s=(0.1, 0.3), sr=SR, random_state=7)
    assert len(comp) == 12 and comp.speakers == ("s1", "s2")
    sources = composed_sources(comp)
    by_path = {str(u.path): u for u in words_corpus}
    n_words = []
    for u, srcs in zip(comp, sources):
        src = [by_path[p] for p in srcs]
        n_words.append(len(src))
        assert 2 <= len(src) <= 4 and {s.speaker for s in src} == {u.speaker}  # one speaker per utterance
        assert u.labels == tuple(s.labels[0] for s in src) and len(set(u.labels)) == len(u.labels)
        assert [w.word for w in u.word_timings] == list(u.labels)
        y = comp.load(comp.utterances.index(u))
        pieces = [words_corpus.load(words_corpus.utterances.index(s)) for s in src]
        # timings are the cumulative lengths of the recordings and the pauses, in samples
        starts = np.array([w.start for w in u.word_timings]) * SR
        ends = np.array([w.end for w in u.word_timings]) * SR
        np.testing.assert_allclose(ends - starts, [len(p) for p in pieces], atol=1e-6)
        assert starts[0] == 0 and ends[-1] == pytest.approx(len(y), abs=1e-6)
        pauses = (starts[1:] - ends[:-1]) / SR
        assert np.all((pauses >= 0.1 - 1e-4) & (pauses <= 0.3 + 1e-4))
        # the audio is the concatenation (up to 16-bit rounding), silence in the pauses
        for p, a, b in zip(pieces, starts.round().astype(int), ends.round().astype(int)):
            np.testing.assert_allclose(y[a:b], np.clip(p, -1, 1), atol=1.0 / 32767)
        for a, b in zip(ends[:-1].round().astype(int), starts[1:].round().astype(int)):
            assert np.all(y[a:b] == 0)
    assert set(n_words) == {2, 3, 4}


def test_composed_utterances_are_deterministic_and_cached(words_corpus, tmp_path):
    a = compose_utterances(words_corpus, tmp_path / "a", n_utterances=6, random_state=3)
    stamp = (tmp_path / "a" / "00000_s1.wav").stat().st_mtime_ns
    again = compose_utterances(words_corpus, tmp_path / "a", n_utterances=6, random_state=3)
    assert (tmp_path / "a" / "00000_s1.wav").stat().st_mtime_ns == stamp  # reused, not rebuilt
    b = compose_utterances(words_corpus, tmp_path / "b", n_utterances=6, random_state=3)
    assert a.labels == again.labels == b.labels
    assert [u.word_timings for u in a] == [u.word_timings for u in b]
    assert all(np.array_equal(a.load(i), b.load(i)) for i in range(6))
    ss = np.random.SeedSequence(3)
    assert compose_utterances(words_corpus, tmp_path / "c", n_utterances=6, random_state=ss).labels == a.labels
    other = compose_utterances(words_corpus, tmp_path / "a", n_utterances=6, random_state=4)  # rebuilds in place
    assert other.labels != a.labels and not list(tmp_path.glob(".a.*"))


def test_compose_utterances_bad_input(words_corpus, tmp_path):
    with pytest.raises(ParameterError, match="n_words"):
        compose_utterances(words_corpus, tmp_path / "x", n_utterances=2, n_words=(3, 2), random_state=0)
    with pytest.raises(ParameterError, match="pause_s"):
        compose_utterances(words_corpus, tmp_path / "x", n_utterances=2, pause_s=(-0.1, 0.2), random_state=0)
    with pytest.raises(ParameterError, match="random_state"):
        compose_utterances(words_corpus, tmp_path / "x", n_utterances=2, random_state=np.random.default_rng(0))
    two = SpeechCorpus([Utterance(words_corpus[0].path, "s", ("a", "b"))])
    with pytest.raises(DataError, match="exactly one label"):
        compose_utterances(two, tmp_path / "x", n_utterances=2, random_state=0)


def test_composed_utterances_shift_the_word_timings_of_sentences(tmp_path, rng):
    """Sources with word timings (sentences with a keyword amid carrier words) keep every word, shifted."""
    root = tmp_path / "sentences"
    _wav(root / "a.wav", rng, 0.5)
    _wav(root / "b.wav", rng, 0.4)
    (root / "labels.csv").write_text("file,speaker,labels,transcription\na.wav,s,car,the car\nb.wav,s,book,a book\n")
    (root / "word_timings.csv").write_text(
        "file,word,start,end\na.wav,the,0.05,0.15\na.wav,car,0.15,0.45\nb.wav,a,0.0,0.1\nb.wav,book,0.1,0.35\n")
    comp = compose_utterances(load_generic_audio(root), tmp_path / "comp", n_utterances=1, n_words=(2, 2),
                              pause_s=(0.2, 0.2), random_state=0)
    u = comp[0]
    first, second = (0.5, 0.4) if u.labels == ("car", "book") else (0.4, 0.5)
    words = [w.word for w in u.word_timings]
    assert words in (["the", "car", "a", "book"], ["a", "book", "the", "car"])
    offset = first + 0.2  # the second sentence starts after the first and the pause
    src = {"the": (0.05, 0.15), "car": (0.15, 0.45), "a": (0.0, 0.1), "book": (0.1, 0.35)}
    for k, w in enumerate(u.word_timings):
        shift = 0.0 if k < 2 else offset
        assert (w.start, w.end) == pytest.approx((src[w.word][0] + shift, src[w.word][1] + shift), abs=1e-6)
    assert u.duration == pytest.approx(first + 0.2 + second, abs=1e-4)
    assert u.transcription in ("the car a book", "a book the car")
