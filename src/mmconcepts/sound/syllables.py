"""Made-up spoken words from vowel-like syllables: a small speech stand-in that needs no text-to-speech.

Each word is a fixed sequence of two or three syllables drawn from a shared inventory; a
syllable is a voiced sound (a glottal pulse train at the speaker's pitch) shaped by the
resonances (formants) of its vowel, with a short noise burst for its consonant. Speakers
differ by pitch and vocal-tract length (formants scaled together), utterances by rate,
loudness and noise. The words are told apart by their syllable sequences, as real words,
not by a single tone; they share syllables, so a learner must use their order and mix.

It is a stand-in for examples and documentation when no recorded speech is at hand (the
real sets are FSDD and ACORNS, :mod:`mmconcepts.sound.data`; the thesis-like generated
corpus is :func:`mmconcepts.sound.synthetic.fetch_caregiver`, which needs the ``speech``
extra and takes minutes).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy import signal

from .._io import atomic_dir
from .._validation import check_positive_int, check_random_state
from ..errors import ParameterError
from .audio import write_audio
from .data import Utterance, save_generic_audio

__all__ = ["VOWEL_FORMANTS", "make_syllable_words"]

#: First three formants (Hz) of a few vowels of an adult male voice (Peterson and Barney, 1952, rounded).
VOWEL_FORMANTS: dict[str, tuple[float, float, float]] = {
    "i": (270.0, 2290.0, 3010.0), "e": (530.0, 1840.0, 2480.0), "a": (730.0, 1090.0, 2440.0),
    "o": (570.0, 840.0, 2410.0), "u": (300.0, 870.0, 2240.0), "ae": (660.0, 1720.0, 2410.0),
}
SAMPLE_RATE = 16000


def _syllable(vowel: tuple[float, float, float], burst: float, f0: float, scale: float, dur: float,
              rng: np.random.Generator) -> np.ndarray:
    n = int(dur * SAMPLE_RATE)
    t = np.arange(n) / SAMPLE_RATE
    f0_t = f0 * (1 + 0.03 * np.sin(2 * np.pi * 3 * t))  # a little intonation
    phase = np.cumsum(f0_t) / SAMPLE_RATE
    source = (np.diff(np.floor(phase), prepend=0) > 0).astype(float)  # one pulse per period
    y = np.zeros(n)
    for k, fk in enumerate(vowel):  # the vowel's resonances, in cascade
        b, a = signal.iirpeak(min(fk * scale, 0.45 * SAMPLE_RATE), Q=5.0 + 3 * k, fs=SAMPLE_RATE)
        y += signal.lfilter(b, a, source) / (k + 1)
    n_burst = int(0.03 * SAMPLE_RATE)
    b, a = signal.butter(2, [burst * 0.8, min(burst * 1.25, 7900.0)], btype="band", fs=SAMPLE_RATE)
    noise = signal.lfilter(b, a, rng.standard_normal(n_burst)) * np.hanning(n_burst)
    envelope = np.minimum(1.0, np.minimum(t, t[::-1]) / 0.02)
    out = np.concatenate([0.5 * noise / (np.abs(noise).max() + 1e-12), y * envelope / (np.abs(y).max() + 1e-12)])
    return out


def make_syllable_words(
    folder: str | os.PathLike[str],
    *,
    n_words: int = 8,
    n_per_word: int = 20,
    n_speakers: int = 2,
    random_state=0,
) -> Path:
    """Write made-up spoken words in the generic audio layout and return the folder.

    Parameters
    ----------
    folder : path-like
        Where to write ``labels.csv`` and the WAV files (16 kHz); created, replaced whole if
        it exists.
    n_words : int, default=8
        Words (concepts), labelled ``"word0"``, ``"word1"``, ...; at most 60.
    n_per_word : int, default=20
        Utterances of each word, spread over the speakers.
    n_speakers : int, default=2
        Speakers (``"s0"``, ``"s1"``, ...), each with its own pitch and vocal-tract length.
    random_state : int, Generator or None
        Seeds the words' syllables and every utterance.

    Returns
    -------
    Path
        The folder, ready for :func:`~mmconcepts.sound.load_generic_audio`.

    Examples
    --------
    >>> from mmconcepts.sound import load_generic_audio, make_syllable_words   # doctest: +SKIP
    >>> words = load_generic_audio(make_syllable_words("words/", n_words=4))  # doctest: +SKIP
    """
    n_words = check_positive_int(n_words, "n_words")
    n_per_word = check_positive_int(n_per_word, "n_per_word")
    n_speakers = check_positive_int(n_speakers, "n_speakers")
    if n_words > 60:
        raise ParameterError(f"make_syllable_words: expected n_words <= 60 (distinct syllable sequences of an "
                             f"inventory of {len(VOWEL_FORMANTS)} vowels and 5 consonants); got {n_words}.")
    rng = check_random_state(random_state)
    vowels = list(VOWEL_FORMANTS.values())
    bursts = [1500.0, 2500.0, 3500.0, 4500.0, 6000.0]  # consonant noise centres (Hz)
    words: list[tuple[tuple[int, int], ...]] = []
    while len(words) < n_words:  # distinct syllable sequences of 2 or 3 (vowel, consonant) pairs
        candidate = tuple((int(rng.integers(len(vowels))), int(rng.integers(len(bursts))))
                          for _ in range(int(rng.integers(2, 4))))
        if candidate not in words:
            words.append(candidate)
    speakers = [(float(rng.uniform(95, 230)), float(rng.uniform(0.9, 1.25))) for _ in range(n_speakers)]
    folder = Path(folder)
    with atomic_dir(folder) as tmp:
        utts = []
        for w, syllables in enumerate(words):
            for k in range(n_per_word):
                s = k % n_speakers
                f0, scale = speakers[s]
                rate = rng.uniform(0.8, 1.2)
                parts = [_syllable(vowels[v], bursts[c], f0 * rng.uniform(0.95, 1.05), scale, 0.16 / rate, rng)
                         for v, c in syllables]
                y = np.concatenate([np.zeros(800), *parts, np.zeros(800)]) * rng.uniform(0.3, 0.8)
                y = y + 0.005 * rng.standard_normal(y.size)
                name = f"word{w}_s{s}_{k}.wav"
                write_audio(tmp / name, y.astype(np.float32), SAMPLE_RATE)
                utts.append(Utterance(tmp / name, f"s{s}", (f"word{w}",)))
        save_generic_audio(utts, tmp)
    return folder
