"""make_syllable_words: a speech stand-in in the generic audio layout, reproducible, words told apart by their syllables."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("soundfile")

from mmconcepts.errors import ParameterError  # noqa: E402
from mmconcepts.sound import MFCCConfig, load_generic_audio, make_syllable_words, mfcc  # noqa: E402


@pytest.fixture(scope="module")
def words(tmp_path_factory):
    return load_generic_audio(make_syllable_words(tmp_path_factory.mktemp("w") / "words", n_words=4, n_per_word=6,
                                                  n_speakers=3, random_state=5))


def test_layout_labels_and_speakers(words):
    assert len(words) == 24
    assert words.keywords == ("word0", "word1", "word2", "word3")
    assert words.speakers == ("s0", "s1", "s2")
    assert all(0.3 < u.duration < 1.0 for u in words)


def test_same_seed_same_samples(words, tmp_path):
    again = load_generic_audio(make_syllable_words(tmp_path / "w", n_words=4, n_per_word=6, n_speakers=3,
                                                   random_state=5))
    np.testing.assert_array_equal(again.load(7), words.load(7))
    other = load_generic_audio(make_syllable_words(tmp_path / "o", n_words=4, n_per_word=6, n_speakers=3,
                                                   random_state=6))
    assert other.load(7).shape != words.load(7).shape or not np.array_equal(other.load(7), words.load(7))


def test_words_are_told_apart_across_speakers(words):
    """Leave-one-speaker-out 1-NN on time-averaged MFCC: well above chance (1/4), so the words carry their identity."""
    cfg = MFCCConfig(n_mfcc=13)
    feats = np.array([mfcc(words.load(i), cfg)[:, 1:].mean(axis=0) for i in range(len(words))])
    y = np.array([u.labels[0] for u in words])
    spk = np.array([u.speaker for u in words])
    hits = []
    for i in range(len(words)):
        other = spk != spk[i]
        d = np.linalg.norm(feats[other] - feats[i], axis=1)
        hits.append(y[other][np.argmin(d)] == y[i])
    assert np.mean(hits) > 0.6


def test_bounds():
    with pytest.raises(ParameterError, match="n_words <= 60"):
        make_syllable_words("unused", n_words=61)
