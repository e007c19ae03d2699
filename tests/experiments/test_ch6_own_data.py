"""Chapter 6 on the user's own recordings (``--data audio=DIR``): every utterance of every speaker is used."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("soundfile")

from mmconcepts.engine import RunContext  # noqa: E402
from mmconcepts.experiments.protocols import pairs, speech  # noqa: E402
from mmconcepts.sound import make_syllable_words  # noqa: E402


@pytest.fixture(scope="module")
def own_words(tmp_path_factory):
    return make_syllable_words(tmp_path_factory.mktemp("own") / "words", n_words=3, n_per_word=8, n_speakers=3,
                               random_state=0)


def test_own_audio_is_used_whole_every_speaker(own_words, tmp_path):
    ctx = RunContext(data={"audio": own_words}, cache_dir=tmp_path, show_progress=False)
    got = pairs.load_speech(ctx, n_per_speaker=4, streams=pairs.Streams(0))
    assert len(got["y"]) == got["n_available"] == 24  # no first-speaker subset, no subsample to n_per_speaker
    assert got["speaker"] == "s0, s1 and s2"
    assert sorted(np.bincount(got["y"]).tolist()) == [8, 8, 8]
    assert "24 of the 24 utterances of speaker s0, s1 and s2" in pairs.speech_note(ctx, got)


def test_a_thesis_corpus_keeps_the_first_speaker(own_words, tmp_path):
    ctx = RunContext(data={"fsdd": own_words}, cache_dir=tmp_path, show_progress=False)  # read as FSDD
    sub, speaker, keywords, y = speech.chapter6_utterances(ctx, n_per_speaker=4)
    assert speaker == "s0" and len(y) == 9 and {u.speaker for u in sub} == {"s0"}


@pytest.mark.parametrize("names, text", [(["b"], "b"), (["b", "a"], "a and b"), (["c", "a", "b"], "a, b and c"),
                                         ([f"s{i}" for i in range(5)], "s0, ..., s4 (5 speakers)")])
def test_speakers_name(names, text):
    assert speech.speakers_name(names) == text
