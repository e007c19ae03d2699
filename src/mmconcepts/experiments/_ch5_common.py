"""Shared machinery of the chapter-5 experiments: the speech corpus and cached MFCCs.

- :func:`load_corpus` reads real speech, in this order of preference: ``acorns``
  (ACORNS Caregiver layout, the thesis' corpus), ``fsdd`` (Free Spoken Digit Dataset,
  :func:`mmconcepts.sound.data.load_fsdd`), ``audio`` (generic layout); else it generates
  (once, cached) the synthetic Caregiver-like corpus of
  :func:`mmconcepts.sound.synthetic.fetch_caregiver`. The generated corpus' seed is fixed
  (``CORPUS_SEED``) so every experiment, and chapter 6, share one cached corpus; the
  experiment's own seed drives compositions, splits and learners through
  :func:`streams`.
- :func:`streams` spawns the independent random streams of an experiment (data
  composition, learner initialisation, splits, reference draws) from its seed.
- :func:`corpus_mfcc` computes the MFCC sequence of every utterance once per data set
  and MFCC configuration and caches it under ``ctx.cache_dir/ch5-mfcc``, keyed on the
  files, the configuration and the code fingerprint.
- :func:`composed_corpus` builds (once, cached) utterances of several words by
  concatenating recordings of one speaker (:func:`mmconcepts.sound.data.compose_utterances`).
- :func:`keyword_targets` gives the keyword of each utterance (the thesis' tasks have one
  keyword per utterance).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np


from .._fingerprint import code_fingerprint
from ..errors import DataError
from ..sound.features import MFCCConfig, mfcc
from .base import RunContext, Streams, cached_call, streams

__all__ = ["CORPUS_SEED", "Streams", "streams", "load_corpus", "data_source", "data_source_note", "corpus_mfcc",
           "composed_corpus", "keyword_targets", "speaker_ids"]

#: Seed of the generated corpus, shared by all experiments (chapters 5 and 6).
CORPUS_SEED = 0


def sub_seed(seed: int, *key: int) -> int:
    """An independent int seed for item ``key`` of a stream (a fold, a speaker)."""
    return int(np.random.SeedSequence([int(seed), *map(int, key)]).generate_state(1)[0] % (2**31 - 1))


#: Real speech sets, in the order load_corpus prefers them.
REAL_SETS = ("acorns", "fsdd", "audio")


def data_source(ctx: RunContext) -> str:
    """Name of the speech set the chapter 5 experiments use: ``acorns``, ``fsdd``, ``audio`` or ``synthetic``."""
    return next((name for name in REAL_SETS if name in ctx.data), "synthetic")


def load_corpus(ctx: RunContext, *, n_per_speaker: int, n_speakers: int = 4):
    """The speech corpus: real (``acorns`` > ``fsdd`` > ``audio`` in ``ctx.data``) or synthetic (generated once,
    cached; ``n_per_speaker`` and ``n_speakers`` size it and are ignored for real sets)."""
    from ..sound.data import load_acorns, load_fsdd, load_generic_audio

    source = data_source(ctx)
    if source == "acorns":
        return load_acorns(ctx.data["acorns"], on_error="skip")
    if source == "fsdd":
        return load_fsdd(ctx.data["fsdd"], on_error="skip")
    if source == "audio":
        return load_generic_audio(ctx.data["audio"], on_error="skip")
    from ..sound.synthetic import fetch_caregiver

    return fetch_caregiver(
        ctx.cache_dir,
        n_utterances_per_speaker=n_per_speaker,
        n_speakers=n_speakers,
        random_state=CORPUS_SEED,
        n_jobs=ctx.workers,
    )


def _sizes(corpus) -> str:
    if corpus is None:
        return ""
    spk = speaker_ids(corpus)
    n_spk = len(set(spk))
    return (f" ({len(corpus)} utterances, {n_spk} speaker{'s' if n_spk != 1 else ''}, "
            f"{len(corpus.keywords)} keywords{', %d files skipped' % len(corpus.skipped) if corpus.skipped else ''})")


#: The thesis' ambiguity on the number of keywords, and the reading taken (issue 12, section 3).
KEYWORDS_READING = (
    "Reading of the thesis: Caregiver has 13 keywords in section 5.2.4 and appendix B.1, but 10 in section 6.5.2 "
    "(speaker 1, 1000 utterances), which names them only through Table 5.1's examples. The generated corpus uses "
    "the 10 keywords of section 6.5.2 (Angus, bath, book, bottle, car, daddy, mummy, nappy, shoe, telephone) for "
    "both chapters; chance is then 0.1 (the thesis' footnote to Table 6.2). FSDD has its own 10 words, the digits."
)


def data_source_note(ctx: RunContext, corpus=None) -> str:
    """Which speech data the experiment ran on, with its sizes when ``corpus`` (the one used) is given."""
    source, size = data_source(ctx), _sizes(corpus)
    if source == "acorns":
        return f"Data: ACORNS Caregiver recordings{size} from {ctx.data['acorns']}."
    if source == "fsdd":
        return (f"Data: real voices, the Free Spoken Digit Dataset{size} from {ctx.data['fsdd']} (English digit words "
                "said alone, 8 kHz WAV resampled to 16 kHz, so the mel bands above 4 kHz hold only the -80 dB floor of the "
                "MFCC; Z. Jackson et al., CC BY-SA 4.0).")
    if source == "audio":
        return f"Data: recordings in the generic audio layout{size} from {ctx.data['audio']}."
    return (
        f"Data: the synthetic Caregiver-like corpus{size} (mmconcepts.sound.synthetic: offline text-to-speech with "
        "piper and eSpeak NG voices, keyword sentences in the style of Table 5.1, speaker-level rate, pitch, "
        "noise and room filtering); real speech is used when the data root holds fsdd or acorns "
        "(or --data audio=DIR)."
    )


def composed_corpus(ctx: RunContext, corpus, *, n_utterances: int, seed: int, n_words=(2, 4), pause_s=(0.1, 0.3)):
    """Utterances of ``n_words`` recordings of one speaker in a row, built once under ``ctx.cache_dir``.

    The folder is named from the sources and the parameters, so two protocols never
    overwrite each other's compositions; :func:`~mmconcepts.sound.data.compose_utterances`
    checks the rest (sources, code fingerprint) and rebuilds when they differ.
    """
    from ..sound.data import compose_utterances

    h = hashlib.sha1()
    for f in corpus.paths:
        h.update(f"{Path(f).resolve()}\n".encode())
    h.update(json.dumps([n_utterances, seed, list(n_words), list(pause_s)]).encode())
    root = Path(ctx.cache_dir) / "ch5-composed" / f"{corpus.name or 'corpus'}-{h.hexdigest()[:16]}"
    return compose_utterances(corpus, root, n_utterances=n_utterances, n_words=tuple(n_words),
                              pause_s=tuple(pause_s), random_state=seed)


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
    from ..sound.audio import load_audio

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

    The cache (the disk cache of :meth:`RunContext.memory <mmconcepts.experiments.base.RunContext.memory>` under ``ctx.cache_dir/ch5-mfcc``) is keyed on the
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
    from ..sound.features import sliding_windows, window_frames

    width = window_frames(window_ms, config.hop_ms)
    step = max(1, int(round(width * shift)))
    return [sliding_windows(s, width, step) for s in corpus_mfcc(ctx, corpus, config)]


def voting_params(window_ms: float = 80.0, *, metric: str = "dtw", search: str = "restart",
                  backtrack: int = 4, r_quantile: float = 0.5, events: str = "leaves") -> dict:
    """Parameters of the section 5.2 recogniser used by the chapter 5 experiments."""
    return {"window_ms": window_ms, "metric": metric, "search": search, "backtrack": backtrack,
            "r_quantile": r_quantile, "events": events}


def choose_r_max(windows: list[np.ndarray], *, metric: str, quantile: float, seed: int,
                 n_sample: int = 600) -> float:
    """Radius of the primitive clusters, set a priori from the training windows.

    The thesis chooses r_max a priori and does not give its value. Here: ``n_sample``
    windows are drawn from the training utterances, each one's distance to its nearest
    neighbour *in another utterance* is computed (windows of one utterance overlap by two
    thirds, so their mutual distances say nothing about the spread of the sounds), and
    r_max is the ``quantile`` of those distances (the median by default): about half of
    the windows then fall within r_max of some window of another utterance.
    """
    from ..sound.dtw import dtw_distance_matrix

    rng = np.random.default_rng(seed)
    owner = np.concatenate([np.full(len(w), i) for i, w in enumerate(windows)])
    flat = np.concatenate([w for w in windows if len(w)])
    take = rng.choice(len(flat), size=min(n_sample, len(flat)), replace=False)
    sample, who = flat[take], owner[take]
    if metric == "dtw":
        D = dtw_distance_matrix(sample)
    else:
        f = sample.reshape(len(sample), -1)
        sq = (f * f).sum(1)
        D = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2 * f @ f.T, 0.0))
    D[who[:, None] == who[None, :]] = np.inf
    nn = D.min(axis=1)
    return float(np.quantile(nn[np.isfinite(nn)], quantile))


def make_voter(params: dict, train_windows: list[np.ndarray], *, seed: int):
    """A :class:`~mmconcepts.sound.voting.TreeVotingClassifier` with r_max chosen from ``train_windows``."""
    from ..sound.tree import ClusterTree
    from ..sound.voting import TreeVotingClassifier

    r_max = choose_r_max(train_windows, metric=params["metric"], quantile=params["r_quantile"], seed=seed)
    tree = ClusterTree(r_max, metric=params["metric"], search=params["search"], backtrack=params["backtrack"],
                       random_state=seed)
    return TreeVotingClassifier(tree, events=params["events"])


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
