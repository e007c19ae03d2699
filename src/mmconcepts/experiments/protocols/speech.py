"""The speech corpus the chapters share: one speaker's utterances, real or generated, and their cached MFCCs.

Chapter 5 learns words from it; chapters 6 and 7 pair its utterances with gestures and objects.

- :func:`load_corpus` reads real speech, in this order of preference: ``acorns``
  (ACORNS Caregiver layout, the thesis' corpus), ``fsdd`` (Free Spoken Digit Dataset,
  :func:`mmconcepts.sound.data.load_fsdd`), ``audio`` (generic layout); else it generates
  (once, cached) the synthetic Caregiver-like corpus of
  :func:`mmconcepts.sound.synthetic.fetch_caregiver`. The generated corpus' seed is fixed
  (:data:`CORPUS_SEED`) so that every experiment shares one cached corpus; an experiment's
  own seed drives compositions, splits and learners.
- :func:`first_speaker` gives the utterances of the first speaker by name (the thesis'
  chapter 6 uses speaker 1), with the keyword of each (:func:`keyword_targets`);
  :func:`chapter6_utterances` gives them for the thesis' corpora and every utterance of
  the user's own recordings (``audio``).
- :func:`corpus_mfcc` computes the MFCC sequence of every utterance once per data set
  and MFCC configuration and caches it under ``ctx.cache_dir/ch5-mfcc``, keyed on the
  files, the configuration and the code fingerprint; :func:`corpus_windows` cuts them into
  the windows of section 5.2.3.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..._fingerprint import code_fingerprint
from ...engine import RunContext, cached_call
from ...errors import DataError
from ...sound.features import MFCCConfig, mfcc

__all__ = ["CORPUS_SEED", "REAL_SETS", "data_source", "load_corpus", "corpus_sizes", "data_source_note", "speaker_ids",
           "keyword_targets", "corpus_mfcc", "corpus_windows", "first_speaker",
           "chapter6_utterances", "speakers_name"]

#: Seed of the generated corpus, shared by all experiments (chapters 5 and 6).
CORPUS_SEED = 0


#: Real speech sets, in the order load_corpus prefers them.
REAL_SETS = ("acorns", "fsdd", "audio")


def data_source(ctx: RunContext) -> str:
    """Name of the speech set the chapter 5 experiments use: ``acorns``, ``fsdd``, ``audio`` or ``synthetic``."""
    return next((name for name in REAL_SETS if ctx.has_dataset(name)), "synthetic")


def load_corpus(ctx: RunContext, *, n_per_speaker: int, n_speakers: int = 4):
    """The speech corpus: real (``acorns`` > ``fsdd`` > ``audio`` in ``ctx.data``) or synthetic (generated once,
    cached; ``n_per_speaker`` and ``n_speakers`` size it and are ignored for real sets)."""
    from ...sound.data import load_acorns, load_fsdd, load_generic_audio

    source = data_source(ctx)
    if source == "acorns":
        return load_acorns(ctx.dataset("acorns"), on_error="skip")
    if source == "fsdd":
        return load_fsdd(ctx.dataset("fsdd"), on_error="skip")
    if source == "audio":
        return load_generic_audio(ctx.dataset("audio"), on_error="skip")
    from ...sound.synthetic import fetch_caregiver

    return fetch_caregiver(
        ctx.cache_dir,
        n_utterances_per_speaker=n_per_speaker,
        n_speakers=n_speakers,
        random_state=CORPUS_SEED,
        n_jobs=ctx.workers,
        verbose=ctx.verbose,
    )


def corpus_sizes(corpus) -> str:
    if corpus is None:
        return ""
    spk = speaker_ids(corpus)
    n_spk = len(set(spk))
    return (f" ({len(corpus)} utterances, {n_spk} speaker{'s' if n_spk != 1 else ''}, "
            f"{len(corpus.keywords)} keywords{', %d files skipped' % len(corpus.skipped) if corpus.skipped else ''})")


def data_source_note(ctx: RunContext, corpus=None) -> str:
    """Which speech data the experiment ran on, with its sizes when ``corpus`` (the one used) is given."""
    source, size = data_source(ctx), corpus_sizes(corpus)
    if source == "acorns":
        return f"Data: ACORNS Caregiver recordings{size} from {ctx.dataset('acorns')}."
    if source == "fsdd":
        return (f"Data: real voices, the Free Spoken Digit Dataset{size} from {ctx.dataset('fsdd')} (English digit words "
                "said alone, 8 kHz WAV resampled to 16 kHz, so the mel bands above 4 kHz hold only the -80 dB floor of the "
                "MFCC; Z. Jackson et al., CC BY-SA 4.0).")
    if source == "audio":
        return f"Data: recordings in the generic audio layout{size} from {ctx.dataset('audio')}."
    return (
        f"Data: the synthetic Caregiver-like corpus{size} (mmconcepts.sound.synthetic: offline text-to-speech with "
        "piper and eSpeak NG voices, keyword sentences in the style of Table 5.1, speaker-level rate, pitch, "
        "noise and room filtering); real speech is used when the data root holds fsdd or acorns "
        "(or --data audio=DIR)."
    )


def speaker_ids(corpus) -> np.ndarray:
    """Speaker of each utterance, as an array of strings."""
    return np.asarray([str(s) for s in corpus.speaker_ids])


def keyword_targets(corpus) -> np.ndarray:
    """The keyword of each utterance (array of str).

    Raises
    ------
    DataError
        If an utterance has no keyword or several (these experiments classify utterances
        into exactly one of the keywords, as in thesis Fig. 5.3).
    """
    out = []
    for i, labels in enumerate(corpus.labels):
        labels = tuple(labels)
        if len(labels) != 1:
            raise DataError(
                f"utterance {i} ({corpus.paths[i]}) has {len(labels)} keywords {labels}; the chapter 5 "
                "experiments need exactly one keyword per utterance."
            )
        out.append(str(labels[0]))
    return np.asarray(out)


def _mfcc_one(task: tuple[str, dict]) -> np.ndarray:
    path, cfg = task
    from ...sound.audio import load_audio

    config = MFCCConfig(**cfg)
    return mfcc(load_audio(path, sr=config.sr), config)


def _cached_mfcc(ctx: RunContext, files: list[str], config: dict, stamps: list[tuple[int, int]],
                 code: str) -> list[np.ndarray]:
    """MFCC of ``files`` computed over ``ctx.parallel``; cached by :func:`corpus_mfcc` (``ctx`` is not hashed).

    ``stamps`` are the files' (size, modification time in s), ``code`` the package's
    :func:`~mmconcepts._fingerprint.code_fingerprint`.
    """
    return ctx.parallel(_mfcc_one, [(f, config) for f in files], desc="MFCC")


def corpus_mfcc(ctx: RunContext, corpus, config: MFCCConfig) -> list[np.ndarray]:
    """MFCC sequence of every utterance of ``corpus`` (computed in parallel, cached on disk).

    The cache (the disk cache of :meth:`RunContext.memory <mmconcepts.engine.context.RunContext.memory>` under ``ctx.cache_dir/ch5-mfcc``) is keyed on the
    files (path, size, modification time), the MFCC configuration and
    :func:`~mmconcepts._fingerprint.code_fingerprint`.
    """
    files = [str(Path(f).resolve()) for f in corpus.paths]
    stamps = [(st.st_size, int(st.st_mtime)) for st in map(os.stat, files)]
    memo = ctx.memory("ch5-mfcc").cache(_cached_mfcc, ignore=["ctx"])
    return cached_call(memo, ctx, files, config.to_dict(), stamps, code_fingerprint())


def corpus_windows(ctx: RunContext, corpus, config: MFCCConfig, *, window_ms: float = 80.0,
                   shift: float = 1 / 3) -> list[np.ndarray]:
    """MFCC windows (n_windows, width, n_mfcc) of every utterance (thesis section 5.2.3)."""
    from ...sound.features import sliding_windows, window_frames

    width = window_frames(window_ms, config.hop_ms)
    step = max(1, int(round(width * shift)))
    return [sliding_windows(s, width, step) for s in corpus_mfcc(ctx, corpus, config)]


def first_speaker(ctx: RunContext, *, n_per_speaker: int):
    """The utterances of the first speaker (the thesis' chapter 6 uses speaker 1).

    Returns
    -------
    sub : SpeechCorpus
    speaker : str
    keywords : list of str (sorted)
    y : ndarray of int, the index of each utterance's keyword in ``keywords``
    """
    corpus = load_corpus(ctx, n_per_speaker=n_per_speaker)
    spk = speaker_ids(corpus)
    speaker = sorted(set(spk))[0]
    sub = corpus.subset(np.flatnonzero(spk == speaker))
    kw = keyword_targets(sub)
    keywords = sorted(set(kw))
    return sub, speaker, keywords, np.searchsorted(keywords, kw)


def speakers_name(speakers) -> str:
    """The speakers of a set of utterances, for the notes: ``"s1"``, ``"s1 and s2"``, ``"s1, ..., s9 (9 speakers)"``."""
    speakers = sorted(set(speakers))
    if len(speakers) <= 3:
        return " and ".join([", ".join(speakers[:-1]), speakers[-1]] if len(speakers) > 1 else speakers)
    return f"{speakers[0]}, ..., {speakers[-1]} ({len(speakers)} speakers)"


def chapter6_utterances(ctx: RunContext, *, n_per_speaker: int):
    """The utterances chapter 6 learns from: the first speaker's of a corpus, every one of the user's own recordings.

    The thesis' corpora (ACORNS, and FSDD read the same way) give the first speaker by name,
    as the thesis uses speaker 1 (:func:`first_speaker`). The user's own recordings (the
    ``audio`` set, generic layout) are used whole, every speaker: what a person gives is
    what is learnt from.

    Returns
    -------
    The values of :func:`first_speaker`; ``speaker`` names every speaker used
    (:func:`speakers_name`).
    """
    if data_source(ctx) != "audio":
        return first_speaker(ctx, n_per_speaker=n_per_speaker)
    corpus = load_corpus(ctx, n_per_speaker=n_per_speaker)
    kw = keyword_targets(corpus)
    keywords = sorted(set(kw))
    return corpus, speakers_name(speaker_ids(corpus)), keywords, np.searchsorted(keywords, kw)
