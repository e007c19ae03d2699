"""Primitive sounds: audio, MFCC, DTW, the incremental cluster tree, TF-IDF voting, HAC,
and speech data (thesis chapter 5 and Appendix B.1).

Audio and data
    load_audio, write_audio, resample, audio_info; SpeechCorpus, Utterance, WordTiming,
    load_generic_audio (folder + labels.csv), load_acorns (ACORNS Caregiver layout),
    load_fsdd (Free Spoken Digit Dataset, generic or upstream layout), save_generic_audio,
    compose_utterances (several recordings of one speaker in a row, exact word timings).
Features (sections 5.2.3, 5.3)
    MFCCConfig, log_mel_spectrogram, mfcc, delta (the thesis' operator), add_deltas,
    sliding_windows, mfcc_windows; HAC (histograms of acoustic co-occurrences, sparse).
Sequences and events (section 5.2.3)
    dtw, dtw_distance_matrix, dtw_one_to_many; ClusterTree (Algorithm 1 and the two
    backtracking searches); EventVoting (TF-IDF votes, eq. 5.1); TreeVotingClassifier
    (the whole recogniser).
Synthetic speech (loaded lazily: needs the ``speech`` extra)
    EspeakEngine, PiperEngine, get_engine, available_engines, MissingEngineError;
    CAREGIVER_KEYWORDS, SPEAKERS, make_caregiver_corpus, fetch_caregiver.
Made-up words without text-to-speech (a stand-in for examples)
    make_syllable_words: two- and three-syllable words from vowel-like sounds, several
    speakers, in the generic audio layout.
"""

from __future__ import annotations

import importlib
from typing import Any

from .audio import audio_info, load_audio, resample, write_audio
from .data import (
    FSDD_WORDS,
    SkippedFile,
    SpeechCorpus,
    Utterance,
    WordTiming,
    compose_utterances,
    load_acorns,
    load_fsdd,
    load_generic_audio,
    save_generic_audio,
)
from .features import (
    MFCCConfig,
    add_deltas,
    delta,
    log_mel_spectrogram,
    mfcc,
    mfcc_windows,
    sliding_windows,
    window_frames,
)
from .hac import HAC, cooccurrence_counts
from .voting import EventVoting, TreeVotingClassifier

_LAZY = {
    "EspeakEngine": "tts",
    "PiperEngine": "tts",
    "get_engine": "tts",
    "available_engines": "tts",
    "MissingEngineError": "tts",
    "CAREGIVER_KEYWORDS": "synthetic",
    "SPEAKERS": "synthetic",
    "make_caregiver_corpus": "synthetic",
    "fetch_caregiver": "synthetic",
    "dtw": "dtw",
    "dtw_distance_matrix": "dtw",
    "dtw_one_to_many": "dtw",
    "ClusterTree": "tree",
    "make_syllable_words": "syllables",
    "VOWEL_FORMANTS": "syllables",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module = importlib.import_module(f".{_LAZY[name]}", __name__)
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "FSDD_WORDS",
    "VOWEL_FORMANTS",
    "HAC",
    "EventVoting",
    "MFCCConfig",
    "SkippedFile",
    "SpeechCorpus",
    "TreeVotingClassifier",
    "Utterance",
    "WordTiming",
    "add_deltas",
    "audio_info",
    "compose_utterances",
    "cooccurrence_counts",
    "delta",
    "load_acorns",
    "make_syllable_words",
    "load_audio",
    "load_fsdd",
    "load_generic_audio",
    "log_mel_spectrogram",
    "mfcc",
    "mfcc_windows",
    "resample",
    "save_generic_audio",
    "sliding_windows",
    "window_frames",
    "write_audio",
    *_LAZY,
]
