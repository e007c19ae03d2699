"""Shared machinery of the chapter-5 experiments: utterances composed by fold, label sets, the voting recogniser.

The speech corpus itself (real or generated, and its cached MFCCs) is
:mod:`mmconcepts.experiments.protocols.speech`, shared with chapters 6 and 7; its names are
importable from here too.

- :func:`streams` gives the independent random streams of an experiment (data, composition,
  learner initialisation, splits, reference draws) from its seed (:class:`~mmconcepts.engine.Streams`).
- :func:`composed_corpus` builds (once, cached) utterances of several words by
  concatenating recordings of one speaker (:func:`mmconcepts.sound.data.compose_utterances`);
  :func:`recording_folds` splits recordings into stratified folds and
  :func:`compose_by_fold` composes each fold's utterances from that fold's recordings only.
- :func:`utterance_sources` gives the source recordings behind each utterance (its own
  file, or the recordings a composed utterance was made of) and :func:`fold_sources` the
  (training, test) sources of each fold, for
  :func:`~mmconcepts.engine.splits.describe_split`.
- :func:`keyword_targets` gives the keyword of each utterance (the thesis' tasks have one
  keyword per utterance).
- :func:`keyword_sets` gives the set of keywords of each utterance as a label matrix
  (section 5.4: "one or several keywords"), :func:`check_label_sets` checks one, and
  :func:`check_words_per_utterance` refuses more distinct keywords per utterance than the
  vocabulary holds.
- :func:`label_set_corpus` gives utterances of one or several keywords of one speaker with
  their label sets and folds: real recordings of one word composed into utterances (or
  real utterances as recorded), or the generated corpus' one- and two-keyword sentences.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..._store import cache_key, versioned
from ...errors import DataError, ParameterError
from ...engine import RunContext, Streams, streams
from ..protocols.speech import (
    CORPUS_SEED,
    corpus_mfcc,
    corpus_windows,
    data_source,
    data_source_note,
    keyword_targets,
    load_corpus,
    speaker_ids,
)

__all__ = ["CORPUS_SEED", "Streams", "streams", "load_corpus", "data_source", "data_source_note", "corpus_mfcc",
           "corpus_windows", "composed_corpus", "recording_folds", "compose_by_fold", "utterance_sources", "fold_sources",
           "keyword_targets", "speaker_ids", "keyword_sets", "check_label_sets", "check_words_per_utterance",
           "label_set_corpus", "LabelSetData"]











#: The thesis' ambiguity on the number of keywords, and the reading taken.
KEYWORDS_READING = (
    "Reading of the thesis: Caregiver has 13 keywords in section 5.2.4 and appendix B.1, but 10 in section 6.5.2 "
    "(speaker 1, 1000 utterances), which names them only through Table 5.1's examples. The generated corpus uses "
    "the 10 keywords of section 6.5.2 (Angus, bath, book, bottle, car, daddy, mummy, nappy, shoe, telephone) for "
    "both chapters; chance is then 0.1 (the thesis' footnote to Table 6.2). FSDD has its own 10 words, the digits."
)




def composed_corpus(ctx: RunContext, corpus, *, n_utterances: int, seed: int, n_words=(2, 4), pause_s=(0.1, 0.3)):
    """Utterances of ``n_words`` recordings of one speaker in a row, built once under ``ctx.cache_dir``.

    The folder, ``ch5-composed/<corpus name>-<key>``, is named by the package's key scheme
    (:func:`mmconcepts._store.cache_key` of the sources' paths and the parameters, under the
    composition format), so two protocols never overwrite each other's compositions;
    :func:`~mmconcepts.sound.data.compose_utterances` checks the rest (the sources' sizes and
    times, the code fingerprint) and rebuilds in place when they differ.
    """
    from ...sound.data import COMPOSE_VERSION, compose_utterances

    paths = [str(Path(f).resolve()) for f in corpus.paths]
    key = cache_key(paths, [n_utterances, seed, list(n_words), list(pause_s)],
                    code=versioned("mmconcepts.sound.data.compose_utterances", COMPOSE_VERSION))
    root = Path(ctx.cache_dir) / "ch5-composed" / f"{corpus.name or 'corpus'}-{key[:16]}"
    return compose_utterances(corpus, root, n_utterances=n_utterances, n_words=tuple(n_words),
                              pause_s=tuple(pause_s), random_state=seed, data_home=ctx.cache_dir)


def recording_folds(y, n_folds: int, seed: int) -> np.ndarray:
    """The test fold of each recording: ``n_folds`` folds stratified by keyword (shuffled by ``seed``).

    Parameters
    ----------
    y : array-like of shape (n_recordings,)
        The keyword of each recording.
    n_folds : int
        Folds wanted; fewer when a keyword has fewer recordings (at least 2).
    seed : int
        The ``splits`` stream.

    Returns
    -------
    ndarray of int, shape (n_recordings,)
        Values ``0 .. k - 1``; every recording is in exactly one fold.

    Raises
    ------
    DataError
        If some keyword has a single recording (no 2-fold split keeps it on both sides).
    """
    from sklearn.model_selection import StratifiedKFold

    y = np.asarray(y)
    counts = np.unique(y, return_counts=True)[1]
    k = min(int(n_folds), int(counts.min()))
    if k < 2:
        raise DataError(f"some keyword has {int(counts.min())} recording(s); expected at least 2 per keyword for "
                        f"{n_folds}-fold cross-validation. Fix: fewer folds or more recordings.")
    fold = np.full(len(y), -1)
    for i, (_, te) in enumerate(StratifiedKFold(k, shuffle=True, random_state=seed).split(np.zeros(len(y)), y)):
        fold[te] = i
    return fold


def compose_by_fold(ctx: RunContext, corpus, fold: np.ndarray, *, n_composed: int, streams: Streams, n_words=(2, 4),
                    pause_s=(0.1, 0.3)) -> list:
    """Utterances composed fold by fold: fold ``i``'s from the recordings whose ``fold`` is ``i`` only.

    So a composed utterance of one fold holds no recording of another fold, and the
    utterances of a test fold share no recording with the training utterances (the other
    folds') nor with the training recordings. Fold ``i`` is composed with seed
    ``streams.seed_for("composition", i)``.

    Returns
    -------
    list of SpeechCorpus
        One per fold, in fold order (:func:`composed_corpus`).
    """
    fold = np.asarray(fold)
    return [composed_corpus(ctx, corpus.subset(np.flatnonzero(fold == i)), n_utterances=n_composed,
                            seed=streams.seed_for("composition", i), n_words=tuple(n_words), pause_s=tuple(pause_s))
            for i in range(int(fold.max()) + 1)]


def utterance_sources(corpus) -> list[list[str]]:
    """The recordings behind each utterance: the files a composed utterance was made of, else its own file.

    Recordings are named by their resolved path, so the sources of a composed utterance
    (:func:`~mmconcepts.sound.data.composed_sources`) and the recordings it was composed
    from compare equal.
    """
    from ...sound.data import composed_sources

    def ids(paths) -> list[str]:
        return [str(Path(p).resolve()) for p in paths]

    if corpus.root is not None and (Path(corpus.root) / "sources.json").is_file():
        return [ids(s) for s in composed_sources(corpus)]
    return [ids([p]) for p in corpus.paths]


def fold_sources(sources, fold, *, extra_train=None) -> list[tuple[list, list]]:
    """Per fold ``i``: the sources of the training examples (fold != i) and of the test examples (fold == i).

    Parameters
    ----------
    sources : sequence of collections of recording ids, one per example
    fold : array-like of int, the test fold of each example (-1: never tested)
    extra_train : sequence of (sources, fold), optional
        Other examples the learner of fold ``i`` trains on (e.g. the single recordings a
        codebook is fitted on), each with its own test fold: those with fold != i join fold
        ``i``'s training side.

    Returns
    -------
    list of (train_sources, test_sources)
        For :func:`~mmconcepts.engine.splits.describe_split`.
    """
    fold = np.asarray(fold)
    out = []
    for i in range(int(fold.max()) + 1):
        train = [sources[j] for j in np.flatnonzero(fold != i)]
        for more, more_fold in (extra_train or ()):
            train += [more[j] for j in np.flatnonzero(np.asarray(more_fold) != i)]
        out.append((train, [sources[j] for j in np.flatnonzero(fold == i)]))
    return out






def keyword_sets(corpus, keywords=None) -> tuple[np.ndarray, list[str]]:
    """The keywords said in each utterance, as a label matrix (thesis sections 3.3.1 and 5.4).

    Parameters
    ----------
    corpus : SpeechCorpus
        Utterances whose ``labels`` are the keywords they say (one or several).
    keywords : sequence of str, optional
        The vocabulary, in column order (default: every label of the corpus, sorted).

    Returns
    -------
    Y : ndarray of float of shape (n_utterances, n_keywords)
        1 where the utterance says the keyword.
    keywords : list of str

    Raises
    ------
    DataError
        If an utterance says no keyword (or none of ``keywords``): a label set is required
        for every utterance of these experiments.
    """
    labels = [tuple(dict.fromkeys(str(l) for l in ls)) for ls in corpus.labels]
    vocab = sorted({l for ls in labels for l in ls}) if keywords is None else [str(k) for k in keywords]
    if len(set(vocab)) != len(vocab):
        raise ParameterError(f"keywords must not repeat; got {vocab!r}. Fix: pass each keyword once.")
    col = {k: j for j, k in enumerate(vocab)}
    Y = np.zeros((len(labels), len(vocab)))
    for i, ls in enumerate(labels):
        cols = [col[l] for l in ls if l in col]
        if not cols:
            got = f"labels {ls}" if ls else "no label"
            raise DataError(
                f"utterance {i} ({corpus.paths[i]}) says no keyword: expected at least one of the {len(vocab)} "
                f"keywords per utterance (its label set); got {got}. Fix: leave that utterance out "
                "(corpus.subset) or give it its keyword(s) in labels.csv."
            )
        Y[i, cols] = 1.0
    return Y, vocab


def check_label_sets(Y, n_utterances: int, n_keywords: int) -> np.ndarray:
    """``Y`` as a float 0/1 label matrix of shape (n_utterances, n_keywords), every row holding a keyword.

    Raises
    ------
    DataError
        If ``Y`` is not 2-D of that shape, not binary, or a row is empty.
    """
    A = np.asarray(Y)
    if A.ndim != 2 or A.shape != (n_utterances, n_keywords):
        raise DataError(
            f"label sets must be a binary matrix of shape (n_utterances, n_keywords) = ({n_utterances}, "
            f"{n_keywords}); got shape {A.shape}. Fix: one row per utterance, one column per keyword "
            "(keyword_sets(corpus) or sklearn.preprocessing.MultiLabelBinarizer builds it from label sets)."
        )
    if not (A.dtype == bool or np.issubdtype(A.dtype, np.number)) or not np.isin(A, (0, 1)).all():
        raise DataError(f"label sets must hold 0/1 values; got dtype {A.dtype} with other values. Fix: a 1 "
                        "where the utterance says the keyword, else 0.")
    empty = np.flatnonzero(A.sum(axis=1) == 0)
    if empty.size:
        raise DataError(f"utterance {int(empty[0])} has an empty label set ({empty.size} such rows): expected at least "
                        "one keyword per utterance; got none. Fix: leave those utterances out.")
    return A.astype(np.float64)


def check_words_per_utterance(n_words, n_keywords: int) -> tuple[int, int]:
    """``n_words = (fewest, most)`` distinct keywords per utterance, checked against the vocabulary.

    Raises
    ------
    ParameterError
        If the bounds are not ints with ``1 <= fewest <= most``, or ``most`` is above the
        number of keywords (the keywords of an utterance are distinct).
    """
    try:
        lo, hi = (int(v) for v in n_words)
        ok = all(float(v) == int(v) for v in n_words)
    except (TypeError, ValueError):
        lo = hi = 0
        ok = False
    if not ok or not 1 <= lo <= hi:
        raise ParameterError(f"words per utterance must be (fewest, most) ints with 1 <= fewest <= most; got "
                             f"{n_words!r}. Fix: e.g. (1, 3).")
    if hi > n_keywords:
        raise ParameterError(
            f"utterances of up to {hi} distinct keywords were asked for, but the vocabulary has {n_keywords} keywords; "
            f"expected at most {n_keywords}. Fix: lower the largest number of words per utterance to {n_keywords} or "
            "use a corpus with more keywords."
        )
    return lo, hi


@dataclass
class LabelSetData:
    """Utterances of one or several keywords of one speaker (see :func:`label_set_corpus`).

    corpus : SpeechCorpus of the utterances; Y : (n, n_keywords) label matrix; keywords : its columns;
    fold : int array (n,), the test fold of each utterance (-1: no folds); kind : "composed",
    "as-recorded" or "generated"; speaker : the speaker id; description : what it is, in words;
    n_source : the number of the speaker's recordings it was built from; sources : the
    recordings behind each utterance (:func:`utterance_sources`).
    """

    corpus: Any
    Y: np.ndarray
    keywords: list[str]
    fold: np.ndarray
    kind: str
    speaker: str
    description: str
    n_source: int = 0
    extra: dict = field(default_factory=dict)
    sources: list = field(default_factory=list)


def _concat(corpora, name: str):
    from ...sound.data import SpeechCorpus

    return SpeechCorpus([u for c in corpora for u in c.utterances], name, None, [])


def label_set_corpus(ctx: RunContext, *, seeds: Streams, speaker_index: int = 0, n_folds: int | None,
                     n_per_speaker: int, n_composed: int, n_words=(1, 3), pause_s=(0.1, 0.3),
                     n_single: int = 0, n_double: int = 0) -> LabelSetData:
    """Utterances of one or several keywords of one speaker, their label sets, test folds and source recordings.

    What the data root holds decides (nothing is named here):

    - a real corpus whose utterances say one keyword each (FSDD: one digit per file): the
      speaker's recordings are split into ``n_folds`` stratified folds (the splits stream)
      and ``n_composed`` utterances of ``n_words`` recordings in a row (pauses
      ``pause_s``) are composed from each fold's recordings (:func:`composed_corpus`,
      the composition stream), so a test fold's utterances hold only that fold's recordings;
      ``n_folds=None``: ``n_composed`` utterances composed from all of them, no folds;
    - a real corpus with several keywords per utterance: its utterances as recorded,
      split into folds stratified by the number of keywords;
    - no real speech: the generated corpus' speaker (one keyword per sentence, cached and
      shared with the other chapter 5 experiments), ``n_single`` of its sentences drawn by
      the data stream, and ``n_double`` sentences of two keywords said by the same voice
      (:func:`~mmconcepts.sound.synthetic.fetch_caregiver` with
      ``keywords_per_utterance=2``, generated once and cached), folds stratified by the
      number of keywords.

    Raises
    ------
    DataError
        Too few recordings, a speaker index beyond the speakers found, an utterance with
        no keyword.
    ParameterError
        ``n_words`` above the vocabulary (see :func:`check_words_per_utterance`).
    """
    from sklearn.model_selection import StratifiedKFold

    source = data_source(ctx)
    corpus = load_corpus(ctx, n_per_speaker=n_per_speaker)
    spk = speaker_ids(corpus)
    order = sorted(set(spk))
    if not 0 <= speaker_index < len(order):
        raise DataError(f"speaker_index {speaker_index} asks for speaker {speaker_index + 1} in sorted order, but the "
                        f"corpus has {len(order)} speaker(s) {order}. Fix: speaker_index in [0, {len(order) - 1}].")
    speaker = order[speaker_index]
    sub = corpus.subset(np.flatnonzero(spk == speaker))
    n_labels = [len(set(ls)) for ls in sub.labels]

    def folds_by_size(Y: np.ndarray) -> np.ndarray:
        fold = np.full(len(Y), -1)
        if n_folds is None:
            return fold
        size = Y.sum(axis=1).astype(int)
        k = min(int(n_folds), int(np.unique(size, return_counts=True)[1].min()))
        if k < 2:
            raise DataError(f"{len(Y)} utterances of speaker {speaker} cannot be split into {n_folds} folds (got {k} "
                            "possible); expected at least 2 utterances of each number of keywords. Fix: fewer folds "
                            "or more data.")
        for i, (_, te) in enumerate(StratifiedKFold(k, shuffle=True, random_state=seeds.seed_for("splits")).split(size, size)):
            fold[te] = i
        return fold

    if source != "synthetic" and all(n == 1 for n in n_labels):
        y = keyword_targets(sub)
        keywords = sorted(set(y))
        lo, hi = check_words_per_utterance(n_words, len(keywords))
        if n_folds is None:
            rec_fold = np.zeros(len(y), dtype=int)
        else:
            counts = np.unique(y, return_counts=True)[1]
            if min(int(n_folds), int(counts.min())) < 2:
                raise DataError(f"speaker {speaker} has {int(counts.min())} recording(s) of some keyword; expected at "
                                f"least 2 per keyword for {n_folds}-fold composition. Fix: fewer folds or more "
                                "recordings.")
            rec_fold = recording_folds(y, n_folds, seeds.seed_for("splits"))
        parts = compose_by_fold(ctx, sub, rec_fold, n_composed=n_composed, streams=seeds, n_words=(lo, hi),
                                pause_s=tuple(pause_s))
        fold = (np.full(sum(len(p) for p in parts), -1) if n_folds is None
                else np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)]))
        sources = [s for p in parts for s in utterance_sources(p)]
        utts = _concat(parts, f"{corpus.name or 'corpus'}-composed")
        Y, _ = keyword_sets(utts, keywords)
        desc = (f"{len(Y)} utterances of {lo}-{hi} real recordings of speaker {speaker} said in a row (pauses "
                f"{pause_s[0]:g}-{pause_s[1]:g} s), composed "
                + ("from all of the speaker's recordings" if n_folds is None else
                   f"fold by fold from {len(parts)} stratified folds of the speaker's {len(sub)} recordings (a test "
                   "fold's utterances hold only that fold's recordings)"))
        return LabelSetData(utts, Y, keywords, fold, "composed", speaker, desc, len(sub), sources=sources)
    if source != "synthetic":
        Y, keywords = keyword_sets(sub)
        desc = f"{len(Y)} utterances of speaker {speaker} as recorded ({int(Y.sum(1).min())}-{int(Y.sum(1).max())} keywords)"
        return LabelSetData(sub, Y, keywords, folds_by_size(Y), "as-recorded", speaker, desc, len(sub),
                            sources=utterance_sources(sub))

    # generated: the speaker's one-keyword sentences and two-keyword sentences of the same voice
    from ...sound.synthetic import fetch_caregiver

    if n_single < 0 or n_double < 0 or n_single + n_double == 0:
        raise ParameterError(f"n_single and n_double must be >= 0 and not both 0; got {n_single}, {n_double}. Fix: "
                             "e.g. n_single=150, n_double=150.")
    rng = seeds.rng("data")
    if n_single > len(sub):
        raise DataError(f"n_single={n_single} one-keyword sentences asked for, but the generated speaker {speaker} "
                        f"has {len(sub)}. Fix: n_single <= {len(sub)} or a larger n_per_speaker.")
    parts = [sub.subset(np.sort(rng.choice(len(sub), n_single, replace=False)))] if n_single else []
    if n_double:
        doubles = fetch_caregiver(ctx.cache_dir, n_utterances_per_speaker=n_double, n_speakers=speaker_index + 1,
                                  keywords_per_utterance=2, random_state=CORPUS_SEED, n_jobs=ctx.workers,
                                  verbose=ctx.verbose)
        parts.append(doubles.subset(np.flatnonzero(speaker_ids(doubles) == speaker)))
    utts = _concat(parts, "caregiver-synth-1+2")
    Y, keywords = keyword_sets(utts, sorted(set(sub.keywords)))
    n_one = int(np.sum(Y.sum(axis=1) == 1))
    desc = (f"{len(Y)} generated sentences of speaker {speaker}: {n_one} with one keyword (drawn from the shared "
            f"generated corpus) and {len(Y) - n_one} with two (generated with keywords_per_utterance=2, same voice)")
    sources = [src for p in parts for src in utterance_sources(p)]
    return LabelSetData(utts, Y, keywords, folds_by_size(Y), "generated", speaker, desc, len(sub), sources=sources)










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
    from ...sound.dtw import dtw_distance_matrix

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
    from ...sound.tree import ClusterTree
    from ...sound.voting import TreeVotingClassifier

    r_max = choose_r_max(train_windows, metric=params["metric"], quantile=params["r_quantile"], seed=seed)
    tree = ClusterTree(r_max, metric=params["metric"], search=params["search"], backtrack=params["backtrack"],
                       random_state=seed)
    return TreeVotingClassifier(tree, events=params["events"])


