"""Speech corpora and their loaders (thesis chapter 5, section 6.5.2, Appendix B.1).

Layouts (as the thesis' data formats describe them):

Generic audio layout
    A folder holding audio files (WAV or FLAC, in it or in sub-folders) and
    ``labels.csv`` with the header ``file,labels,speaker,transcription`` (the
    ``file,labels`` of every generic layout, then this layout's columns, in any order):
    ``file`` is the path relative to the folder, ``labels`` the utterance's labels
    separated by ``;`` (may be empty), ``speaker`` its speaker, ``transcription`` optional
    (the column may be missing or the cell empty). Extra columns are ignored. A column
    ``label`` (the old spelling of ``labels``) is still read, with a :class:`FutureWarning`.

    Word timings, optional, live in a sidecar file of this package,
    ``word_timings.csv``, with the header ``file,word,start,end``: one row per word,
    ``file`` as in ``labels.csv``, ``start`` and ``end`` in seconds from the start of
    the file (``0 <= start <= end <= duration``), rows of one file in spoken order. A
    file with no row has no timings (``Utterance.word_timings is None``). This is the
    layout :func:`~mmconcepts.sound.synthetic.make_caregiver_corpus` writes; forced
    aligners' word tables (Montreal Forced Aligner, WebMAUS) convert to it one row per
    word.

ACORNS Caregiver
    ``<root>/XML/Speaker-NN/<utterance>.xml`` and ``<root>/WAV/Speaker-NN/<audio>.wav``.
    Each XML file describes one utterance: ``<audio-file value="...">`` (file name,
    usually without ``.wav``), the keyword tag(s) (``<vistag>`` in year 1, ``<vistags>``
    in year 2), the transcription ``<trans>`` and the speaking style ``<style>``. The
    exact spellings beyond these are not documented here, so the loader is lenient: tag
    names are matched without regard to case, namespace, ``-`` or ``_`` (``audio-file``,
    ``audio_file``, ``AudioFile``); a value is read from a ``value`` attribute (any case),
    else from the element's only attribute, else from its text; a ``vistags`` value holding
    several tags is split at commas, semicolons, ``|`` and white space. A file without an
    audio-file or a tag element gets a :class:`~mmconcepts.errors.DataFormatError` that
    names it and lists the elements it does have.

Free Spoken Digit Dataset (FSDD)
    Mono WAV files named ``{digit}_{speaker}_{index}.wav``, either in the generic layout
    above (a folder with ``labels.csv``) or in the upstream layout (a ``recordings/``
    sub-folder and no ``labels.csv``): see :func:`load_fsdd`.

All loaders take ``on_error="raise"`` (the first bad file raises a
:class:`~mmconcepts.errors.DataFormatError` naming it) or ``"skip"`` (bad files are left
out, listed as ``(file, reason)`` in ``corpus.skipped``, and a :class:`RuntimeWarning`
says how many).
"""

from __future__ import annotations

import csv
import logging
import os
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._io import LABEL_SEPARATOR, atomic_path, read_csv_rows, read_labels_csv, split_labels
from .._validation import check_subset_indices
from ..errors import DataError, DataFormatError, ParameterError
from .audio import DEFAULT_SR, audio_info, load_audio

__all__ = [
    "LABELS_FILE",
    "AUDIO_LABELS_HEADER",
    "TIMINGS_FILE",
    "SkippedFile",
    "SpeechCorpus",
    "Utterance",
    "WordTiming",
    "FSDD_WORDS",
    "compose_utterances",
    "composed_sources",
    "load_acorns",
    "load_fsdd",
    "parse_fsdd_name",
    "load_generic_audio",
    "normalize_word",
    "save_generic_audio",
]

_LOG = logging.getLogger(__name__)

#: Name of the label table of the generic audio layout.
LABELS_FILE = "labels.csv"

#: The header of the generic audio layout's ``labels.csv`` (``file,labels`` as every generic layout, then the
#: speaker and the optional transcription), as the writers write it.
AUDIO_LABELS_HEADER = ("file", "labels", "speaker", "transcription")

#: Name of the word-timing sidecar of the generic audio layout (this package's own).
TIMINGS_FILE = "word_timings.csv"

_AUDIO_EXTENSIONS = (".wav", ".flac")
_TIME_TOL = 0.02  # s: timings may overrun the file by this much (frame rounding of aligners)


class WordTiming(NamedTuple):
    """One word of an utterance and when it is spoken (seconds from the file's start)."""

    word: str
    start: float
    end: float


class SkippedFile(NamedTuple):
    """A file that ``on_error="skip"`` left out, and why."""

    file: str
    reason: str


def normalize_word(word: str) -> str:
    """Lower-case a word and strip the punctuation around it (``"Mummy,"`` -> ``"mummy"``)."""
    return re.sub(r"^[^\w']+|[^\w']+$", "", word.strip().lower()).strip("'")


@dataclass(frozen=True)
class Utterance:
    """One recorded utterance.

    Parameters
    ----------
    path : Path
        Audio file.
    speaker : str
        Speaker id (``"01"`` for ACORNS ``Speaker-01``).
    labels : tuple of str
        Semantic tags (the keyword(s) for Caregiver).
    transcription : str
        What is said ("" when unknown).
    word_timings : tuple of WordTiming, optional
        ``(word, start_s, end_s)`` of each word, None when unknown.
    duration : float, optional
        Length in seconds, from the file header (None if not read).
    source : str
        File the record came from (``labels.csv`` row or XML file; used in messages).
    meta : dict
        Anything else the format holds (ACORNS ``style``, ...).
    """

    path: Path
    speaker: str
    labels: tuple[str, ...] = ()
    transcription: str = ""
    word_timings: tuple[WordTiming, ...] | None = None
    duration: float | None = None
    source: str = ""
    meta: dict = field(default_factory=dict, compare=False, hash=False)

    def keyword_span(self, keyword: str | None = None) -> tuple[float, float] | None:
        """Start and end (s) of the first word equal to ``keyword`` (default: the first label).

        Words and keywords are compared with :func:`normalize_word`. None if there are no
        timings or the word is not found.
        """
        if keyword is None:
            if not self.labels:
                return None
            keyword = self.labels[0]
        if not self.word_timings:
            return None
        key = normalize_word(keyword)
        for w in self.word_timings:
            if normalize_word(w.word) == key:
                return (w.start, w.end)
        return None


@dataclass(eq=False)
class SpeechCorpus:
    """A list of :class:`Utterance` (audio paths, speakers, labels, transcriptions, timings).

    Parameters
    ----------
    utterances : list of Utterance
    name : str
    root : Path, optional
        Folder the corpus was read from.
    skipped : list of SkippedFile
        Files ``on_error="skip"`` left out (empty otherwise).

    Examples
    --------
    >>> corpus = load_generic_audio("my_corpus")                     # doctest: +SKIP
    >>> y = corpus.load(0)                                           # doctest: +SKIP
    >>> Y = corpus.label_matrix()           # (n_utterances, n_keywords), 0/1  # doctest: +SKIP
    >>> first = corpus.subset(corpus.speaker_ids == corpus.speakers[0])  # doctest: +SKIP
    """

    utterances: list[Utterance]
    name: str = ""
    root: Path | None = None
    skipped: list[SkippedFile] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.utterances)

    def __getitem__(self, i: int) -> Utterance:
        return self.utterances[i]

    def __iter__(self) -> Iterator[Utterance]:
        return iter(self.utterances)

    def __repr__(self) -> str:
        return (f"SpeechCorpus(name={self.name!r}, n_utterances={len(self)}, speakers={list(self.speakers)}, "
                f"keywords={list(self.keywords)}, skipped={len(self.skipped)})")

    # ----------------------------------------------------------------- views
    @property
    def keywords(self) -> tuple[str, ...]:
        """Sorted set of all labels."""
        return tuple(sorted({l for u in self.utterances for l in u.labels}))

    @property
    def speakers(self) -> tuple[str, ...]:
        """Sorted set of speaker ids."""
        return tuple(sorted({u.speaker for u in self.utterances}))

    @property
    def speaker_ids(self) -> np.ndarray:
        """Speaker of each utterance, shape (n_utterances,), for masks (``ids == "01"``)."""
        return np.array([u.speaker for u in self.utterances], dtype=object)

    @property
    def labels(self) -> list[tuple[str, ...]]:
        """Labels of each utterance."""
        return [u.labels for u in self.utterances]

    @property
    def transcriptions(self) -> list[str]:
        """Transcription of each utterance."""
        return [u.transcription for u in self.utterances]

    @property
    def paths(self) -> list[Path]:
        """Audio file of each utterance."""
        return [u.path for u in self.utterances]

    def label_matrix(self, keywords: Sequence[str] | None = None) -> np.ndarray:
        """Binary label matrix, shape (n_utterances, n_keywords).

        Column j is ``keywords[j]`` (default :attr:`keywords`). Labels not among
        ``keywords`` are ignored (so a subset of the keywords can be asked for).
        """
        kw = list(self.keywords if keywords is None else keywords)
        if len(set(kw)) != len(kw):
            raise ParameterError(f"keywords must not repeat; got {kw}.")
        col = {k: j for j, k in enumerate(kw)}
        Y = np.zeros((len(self.utterances), len(kw)))
        for i, u in enumerate(self.utterances):
            for l in u.labels:
                j = col.get(l)
                if j is not None:
                    Y[i, j] = 1.0
        return Y

    def keyword_spans(self, keyword: str | None = None) -> np.ndarray:
        """Start and end (s) of each utterance's keyword, shape (n_utterances, 2).

        ``keyword=None`` takes each utterance's first label; NaN where the utterance has no
        timings or does not contain the word (see :meth:`Utterance.keyword_span`). Chapter
        6's sliding windows (Thesis section 6.6.2) use it to place the keyword in time.
        """
        out = np.full((len(self.utterances), 2), np.nan)
        for i, u in enumerate(self.utterances):
            span = u.keyword_span(keyword)
            if span is not None:
                out[i] = span
        return out

    # ----------------------------------------------------------------- access
    def load(self, i: int, *, sr: int | None = DEFAULT_SR) -> np.ndarray:
        """Samples of utterance ``i`` (float32, mono, resampled to ``sr``; see :func:`load_audio`)."""
        u = self.utterances[i]
        return load_audio(u.path, sr=sr, min_duration=0.0)

    def subset(self, indices_or_mask: Iterable[int] | np.ndarray) -> SpeechCorpus:
        """A corpus holding the utterances at the given indices, or where a boolean mask is True."""
        idx = check_subset_indices(indices_or_mask, len(self.utterances))
        return SpeechCorpus([self.utterances[int(i)] for i in idx], self.name, self.root, [])

    def by_speaker(self, speaker: str) -> SpeechCorpus:
        """The utterances of one speaker."""
        if speaker not in self.speakers:
            raise ParameterError(f"Unknown speaker {speaker!r}; the corpus has {list(self.speakers)}.")
        return self.subset(self.speaker_ids == speaker)


# --------------------------------------------------------------------------- helpers


def _check_on_error(on_error: str) -> None:
    if on_error not in ("raise", "skip"):
        raise ParameterError(f"on_error must be 'raise' or 'skip'; got {on_error!r}.")


def _report_skipped(skipped: list[SkippedFile], what: str) -> None:
    if not skipped:
        return
    for s in skipped:
        _LOG.warning("skipped %s: %s", s.file, s.reason)
    msg = (f"{len(skipped)} file(s) of {what} could not be read and were skipped (see corpus.skipped); "
           f"first: {skipped[0].reason}")
    _LOG.warning(msg)
    warnings.warn(msg, RuntimeWarning, stacklevel=3)


def _audio_duration(path: Path) -> float:
    """Duration from the header; DataFormatError for missing/corrupt/empty files."""
    try:
        sr, n, _ = audio_info(path)
    except FileNotFoundError as exc:
        raise DataFormatError(f"Audio file {path} not found.") from exc
    if n == 0:
        raise DataFormatError(f"Audio file {path} is empty: it holds no samples.")
    return n / sr




# --------------------------------------------------------------------------- generic layout


def load_generic_audio(
    root: str | os.PathLike[str],
    *,
    on_error: str = "raise",
    check_audio: bool = True,
    name: str | None = None,
) -> SpeechCorpus:
    """Load a folder in the generic audio layout (``labels.csv`` + audio + optional timings).

    See the module docstring for the layout, including the ``word_timings.csv`` sidecar.

    Parameters
    ----------
    root : path-like
        The folder holding ``labels.csv``.
    on_error : {"raise", "skip"}
        ``"raise"``: a bad row, a missing or unreadable audio file, or bad timings raise
        :class:`DataFormatError` naming the file. ``"skip"``: those utterances are left
        out and listed in ``corpus.skipped``; a :class:`RuntimeWarning` says how many. A
        ``labels.csv`` that ends early (its last row cut short) raises, or loses that row
        with a :class:`~mmconcepts.errors.DataWarning` counting the rows read.
    check_audio : bool, default=True
        Open each audio file's header (finds missing, empty and corrupt files at load
        time, and gives ``Utterance.duration``). False only checks that the file exists.
    name : str, optional
        Corpus name (default: the folder's name).

    Returns
    -------
    SpeechCorpus
        Utterances in the order of ``labels.csv``.
    """
    _check_on_error(on_error)
    root = Path(root)
    labels_path = root / LABELS_FILE
    if not root.is_dir():
        raise FileNotFoundError(f"Corpus folder not found: {root}")
    if not labels_path.exists():
        raise DataFormatError(
            f"{root} has no {LABELS_FILE}; the generic audio layout needs one with columns "
            "file,labels,speaker[,transcription]."
        )
    header, rows = read_labels_csv(labels_path, layout="generic audio", required=("speaker",),
                                   optional=("transcription",), on_error=on_error)
    timings, timing_errors = _read_timings(root)
    skipped: list[SkippedFile] = []
    utts: list[Utterance] = []
    seen: set[str] = set()
    for line, row in rows:
        where = f"{labels_path}, line {line}"
        try:
            rel = row.get("file", "")
            if not rel:
                raise DataFormatError(f"{where}: empty 'file' cell.")
            path = root / rel
            if path.suffix.lower() not in _AUDIO_EXTENSIONS:
                raise DataFormatError(f"{where}: {rel!r} is not a .wav or .flac file.")
            if check_audio:
                duration = _audio_duration(path)
            else:
                if not path.is_file():
                    raise DataFormatError(f"Audio file {path} not found ({where}).")
                duration = None
            labels = split_labels(row.get("labels", ""))
            key = Path(rel).as_posix()
            if key in timing_errors:
                raise DataFormatError(timing_errors[key])
            wt = timings.get(key)
            if wt is not None and duration is not None and wt[-1].end > duration + _TIME_TOL:
                raise DataFormatError(
                    f"{root / TIMINGS_FILE}: timings of {rel!r} end at {wt[-1].end:.3f} s, after the end of the "
                    f"audio ({duration:.3f} s)."
                )
            seen.add(key)
            utts.append(Utterance(path=path, speaker=row.get("speaker", ""), labels=labels,
                                  transcription=row.get("transcription", ""), word_timings=wt,
                                  duration=duration, source=where))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedFile(str(root / row.get("file", "")), str(exc)))
    listed = {Path(r.get("file", "")).as_posix() for _, r in rows}
    orphans = sorted(set(timings) - listed)
    if orphans:
        msg = (f"{root / TIMINGS_FILE}: timings for {len(orphans)} file(s) not listed in {LABELS_FILE} "
               f"(first: {orphans[0]!r}).")
        if on_error == "raise":
            raise DataFormatError(msg)
        skipped.append(SkippedFile(str(root / TIMINGS_FILE), msg))
    _report_skipped(skipped, str(root))
    return SpeechCorpus(utts, name if name is not None else root.name, root, skipped)


def _read_timings(root: Path) -> tuple[dict[str, tuple[WordTiming, ...]], dict[str, str]]:
    """Parse ``word_timings.csv``: per-file timings, and per-file error messages."""
    path = root / TIMINGS_FILE
    if not path.exists():
        return {}, {}
    header, rows = read_csv_rows(path)
    missing = [c for c in ("file", "word", "start", "end") if c not in header]
    if missing:
        raise DataFormatError(f"{path}: missing column(s) {missing}; the header must be file,word,start,end.")
    out: dict[str, list[WordTiming]] = {}
    errors: dict[str, str] = {}
    for line, row in rows:
        key = Path(row["file"]).as_posix()
        try:
            start, end = float(row["start"]), float(row["end"])
        except ValueError:
            errors.setdefault(key, f"{path}, line {line}: start/end must be numbers; got {row['start']!r}, "
                                   f"{row['end']!r}.")
            continue
        if not (np.isfinite(start) and np.isfinite(end)) or start < 0 or end < start:
            errors.setdefault(key, f"{path}, line {line}: need 0 <= start <= end; got start={start}, end={end}.")
            continue
        prev = out.get(key)
        if prev and start < prev[-1].start:
            errors.setdefault(key, f"{path}, line {line}: words of {row['file']!r} are not in time order.")
            continue
        out.setdefault(key, []).append(WordTiming(row["word"], start, end))
    return {k: tuple(v) for k, v in out.items()}, errors


def save_generic_audio(corpus: SpeechCorpus | Sequence[Utterance], root: str | os.PathLike[str]) -> Path:
    """Write ``labels.csv`` (and ``word_timings.csv`` when any utterance has timings) for utterances
    whose audio files already lie under ``root``.

    File names are written relative to ``root``. Each table is written atomically.
    Returns the path of ``labels.csv``.

    Raises
    ------
    DataError
        If an audio file is not inside ``root``, or a label holds ``;``.
    """
    root = Path(root)
    utts = list(corpus)
    rows, trows = [], []
    for u in utts:
        try:
            rel = Path(u.path).resolve().relative_to(root.resolve()).as_posix()
        except ValueError as exc:
            raise DataError(f"Audio file {u.path} is not inside {root}; copy it there first.") from exc
        if any(LABEL_SEPARATOR in l for l in u.labels):
            raise DataError(f"Labels of {u.path} contain {LABEL_SEPARATOR!r}, the label separator: {u.labels}.")
        rows.append([rel, LABEL_SEPARATOR.join(u.labels), u.speaker, u.transcription])
        for w in u.word_timings or ():
            trows.append([rel, w.word, f"{w.start:.4f}", f"{w.end:.4f}"])
    _write_csv(root / LABELS_FILE, list(AUDIO_LABELS_HEADER), rows)
    if trows:
        _write_csv(root / TIMINGS_FILE, ["file", "word", "start", "end"], trows)
    return root / LABELS_FILE


def _write_csv(path: Path, header: list[str], rows: list[list[str]]) -> None:
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


# --------------------------------------------------------------------------- FSDD

#: The word said in the recordings of each digit of the Free Spoken Digit Dataset.
FSDD_WORDS = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")

_FSDD_NAME = re.compile(r"^(\d)_(.+)_(\d+)\.wav$", re.IGNORECASE)


def parse_fsdd_name(name: str) -> tuple[int, str, int] | None:
    """``(digit, speaker, index)`` of an FSDD file name ``{digit}_{speaker}_{index}.wav``, else None.

    The one definition of an FSDD recording's name: the loader orders by it, and the data-set
    registry (:mod:`mmconcepts.datasets`) recognises and arranges FSDD folders by it.

    Examples
    --------
    >>> parse_fsdd_name("7_jackson_12.wav")
    (7, 'jackson', 12)
    >>> parse_fsdd_name("notes.txt") is None
    True
    """
    m = _FSDD_NAME.match(name)
    return None if m is None else (int(m.group(1)), m.group(2), int(m.group(3)))


def _fsdd_order(u: Utterance) -> tuple:
    parsed = parse_fsdd_name(u.path.name)
    return (u.speaker, 0, parsed[0], parsed[2], "") if parsed else (u.speaker, 1, 0, 0, u.path.name)


def load_fsdd(
    root: str | os.PathLike[str],
    *,
    speakers: Iterable[str] | None = None,
    on_error: str = "raise",
    check_audio: bool = True,
) -> SpeechCorpus:
    """Load the Free Spoken Digit Dataset (FSDD): English digit words, each said alone.

    Layout. Mono WAV files (8 kHz, 16-bit PCM upstream) named
    ``{digit}_{speaker}_{index}.wav`` (``0_jackson_12.wav``: the 13th "zero" of speaker
    ``jackson``), in either of two layouts:

    - *generic* (what :func:`load_generic_audio` reads): the folder holds the WAV files
      and ``labels.csv`` (``file,labels,speaker,transcription``; ``labels`` is the digit's
      word, ``"zero"`` .. ``"nine"``). The table is authoritative: labels and speakers come
      from it.
    - *upstream* (a clone or archive of the repository): a ``recordings/`` sub-folder of
      WAV files and no ``labels.csv`` (``root`` may also be that folder itself). The label
      is the English word of the digit in the file name (:data:`FSDD_WORDS`) and the
      speaker the name's middle part; a WAV whose name does not follow the pattern is a
      bad file (see ``on_error``).

    Utterances are ordered by speaker, digit and index in both layouts, so a protocol
    gives the same result whichever layout the set came in. Each utterance has one label
    and its transcription is that word; there are no word timings (each file is the one
    word, trimmed to near minimal silence). The audio is 8 kHz: load it with
    :meth:`SpeechCorpus.load` / :func:`~mmconcepts.sound.load_audio`, which resample it
    explicitly to the pipeline's 16 kHz (``sr=16000``, the default).

    Source: Z. Jackson, C. Souza, J. Flaks, Y. Pan, H. Nicolas and A. Thite, *Free Spoken
    Digit Dataset*, https://github.com/Jakobovski/free-spoken-digit-dataset (6 speakers
    and 3000 recordings in its 2024 version; any subset of speakers loads). Licence:
    Creative Commons Attribution-ShareAlike 4.0 (CC BY-SA 4.0). Cite as::

        @misc{fsdd,
          author = {Jackson, Zohar and Souza, C{\'e}sar and Flaks, Jason and Pan, Yuxin and
                    Nicolas, Hereman and Thite, Adhish},
          title = {Jakobovski/free-spoken-digit-dataset},
          publisher = {Zenodo}, doi = {10.5281/zenodo.1342401}, year = {2018}}

    Parameters
    ----------
    root : path-like
        The folder holding ``labels.csv`` and the WAVs, or the repository's folder (with
        ``recordings/``), or the ``recordings/`` folder itself.
    speakers : iterable of str, optional
        Keep only these speakers (default: all). An unknown speaker is an error.
    on_error : {"raise", "skip"}
        ``"raise"``: the first unreadable, empty or truncated WAV (or, in the upstream
        layout, a WAV named otherwise) raises :class:`DataFormatError` naming the file.
        ``"skip"``: such files are left out, listed in ``corpus.skipped``, each logged as a
        warning naming the file, and a :class:`RuntimeWarning` says how many; the rest
        loads.
    check_audio : bool, default=True
        Open each WAV header (finds corrupt files at load time; gives ``duration``).

    Returns
    -------
    SpeechCorpus
        Named ``"fsdd"``; ``meta`` holds ``digit`` and ``index`` where the file name has
        them.

    Raises
    ------
    FileNotFoundError
        If ``root`` does not exist.
    DataFormatError
        If the folder holds neither ``labels.csv`` nor FSDD recordings, or a bad file with
        ``on_error="raise"``.
    ParameterError
        If ``speakers`` names a speaker the set does not have.

    Examples
    --------
    >>> corpus = load_fsdd("data/fsdd", speakers=["jackson"])   # doctest: +SKIP
    >>> corpus.keywords                                        # doctest: +SKIP
    ('eight', 'five', 'four', 'nine', 'one', 'seven', 'six', 'three', 'two', 'zero')
    >>> y = corpus.load(0)       # float32 at 16 kHz (resampled from 8 kHz)   # doctest: +SKIP
    """
    _check_on_error(on_error)
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"FSDD folder not found: {root}")
    want = None if speakers is None else {str(s) for s in speakers}
    if (root / LABELS_FILE).exists():
        corpus = load_generic_audio(root, on_error=on_error, check_audio=check_audio, name="fsdd")
        utts, skipped = list(corpus.utterances), list(corpus.skipped)
        utts = [_with_fsdd_meta(u) for u in utts]
    else:
        rec = _child_dir(root, "recordings") or root
        files = sorted(p for p in rec.iterdir() if p.suffix.lower() in _AUDIO_EXTENSIONS and p.is_file())
        if not files:
            raise DataFormatError(
                f"{root} is not an FSDD folder: it has no {LABELS_FILE} (generic layout) and no recordings/ "
                "folder of {digit}_{speaker}_{index}.wav files (upstream layout)."
            )
        utts, skipped = [], []
        for path in files:
            try:
                parsed = parse_fsdd_name(path.name)
                if parsed is None:
                    raise DataFormatError(
                        f"{path}: not an FSDD file name; expected {{digit}}_{{speaker}}_{{index}}.wav "
                        "(e.g. 0_jackson_12.wav)."
                    )
                digit, speaker, index = parsed
                if want is not None and speaker not in want:
                    continue
                duration = _audio_duration(path) if check_audio else None
                word = FSDD_WORDS[digit]
                utts.append(Utterance(path=path, speaker=speaker, labels=(word,), transcription=word,
                                      duration=duration, source=str(path), meta={"digit": digit, "index": index}))
            except DataFormatError as exc:
                if on_error == "raise":
                    raise
                skipped.append(SkippedFile(str(path), str(exc)))
        _report_skipped(skipped, str(root))
    if want is not None:
        have = {u.speaker for u in utts}
        unknown = sorted(want - have)
        if unknown:
            raise ParameterError(f"FSDD at {root} has no speaker {unknown}; it has {sorted(have)}.")
        utts = [u for u in utts if u.speaker in want]
    if not utts:
        raise DataFormatError(f"No FSDD recording could be read from {root}.")
    utts.sort(key=_fsdd_order)
    return SpeechCorpus(utts, "fsdd", root, skipped)


def _with_fsdd_meta(u: Utterance) -> Utterance:
    """``u`` with ``meta`` holding ``digit`` and ``index`` parsed from its FSDD file name (if it has one)."""
    parsed = parse_fsdd_name(u.path.name)
    if parsed is None:
        return u
    return Utterance(u.path, u.speaker, u.labels, u.transcription or " ".join(u.labels), u.word_timings,
                     u.duration, u.source, {**u.meta, "digit": parsed[0], "index": parsed[2]})


# --------------------------------------------------------------------------- composed utterances

#: Version of the composed-utterance format; a cache of another version is rebuilt.
COMPOSE_VERSION = 1


def _seed_identity(random_state) -> tuple[np.random.SeedSequence, dict]:
    if isinstance(random_state, np.random.SeedSequence):
        ss = random_state
    elif isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool) and random_state >= 0:
        ss = np.random.SeedSequence(int(random_state))
    else:
        raise ParameterError(
            "random_state must be a non-negative int or a numpy.random.SeedSequence (it names the cached "
            f"composition); got {random_state!r}."
        )
    return ss, {"entropy": str(ss.entropy), "spawn_key": [int(k) for k in ss.spawn_key]}


def _check_range(value, name: str, *, integer: bool, low: float) -> tuple:
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a pair (low, high); got {value!r}.") from None
    kinds = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if any(isinstance(v, bool) or not isinstance(v, kinds) or not np.isfinite(v) for v in (lo, hi)) or not (
            low <= lo <= hi):
        what = "ints" if integer else "numbers"
        raise ParameterError(f"{name} must be {what} with {low} <= low <= high; got {value!r}.")
    return (int(lo), int(hi)) if integer else (float(lo), float(hi))


def _sources_digest(corpus: SpeechCorpus) -> str:
    import hashlib

    h = hashlib.sha1()
    for u in corpus:
        p = Path(u.path).resolve()
        st = p.stat()
        h.update(f"{p}|{st.st_size}|{st.st_mtime_ns}|{u.speaker}|{';'.join(u.labels)}|{u.transcription}|"
                 f"{u.word_timings}\n".encode())
    return h.hexdigest()


def compose_utterances(
    corpus: SpeechCorpus,
    root: str | os.PathLike[str],
    *,
    n_utterances: int,
    n_words: tuple[int, int] = (2, 4),
    pause_s: tuple[float, float] = (0.1, 0.3),
    sr: int = DEFAULT_SR,
    random_state: int | np.random.SeedSequence,
    name: str | None = None,
    data_home: str | os.PathLike[str] | None = None,
) -> SpeechCorpus:
    """Longer utterances made by concatenating recordings of one speaker with short pauses.

    Each composed utterance takes one speaker (in turn, over the sorted speakers), a
    number of words ``n`` uniform in ``n_words`` (bounds included; at most the number of
    distinct labels the speaker has), ``n`` *distinct* labels of that speaker uniformly,
    and for each label one of the speaker's recordings that has it, uniformly; the
    recordings are resampled to ``sr``, put end to end in that order with a silence
    uniform in ``pause_s`` (seconds) between two of them, and written to ``root`` in the
    generic audio layout: ``NNNNN_<speaker>.wav`` (16-bit PCM), ``labels.csv`` (the
    labels of the recordings, in spoken order) and ``word_timings.csv``, whose times are
    exact (sample counts divided by ``sr``, written with 9 significant digits): a
    recording with word timings contributes its words shifted by its offset, one
    without contributes one word (its transcription, else its label) spanning the whole
    recording. This is how the FSDD digits (one word per file) give utterances with
    several keywords, the setting of thesis section 5.4 ("simple sentences containing one
    or several keywords").

    ``root`` is a cache (:func:`mmconcepts._store.generated_folder`): when it holds a
    composition made with the same sources (paths, sizes, modification times, labels),
    parameters and seed by the same code (the package's code fingerprint), it is loaded
    instead of rebuilt. The composition is built in a temporary sibling folder and
    renamed, so an interrupted build leaves nothing half-written behind, and processes
    sharing the folder build it once.

    Parameters
    ----------
    corpus : SpeechCorpus
        Source recordings, each with exactly one label.
    root : path-like
        Folder to write (created; replaced if it holds another composition).
    n_utterances : int
        Number of utterances to compose.
    n_words : (int, int), default=(2, 4)
        Fewest and most recordings per utterance.
    pause_s : (float, float), default=(0.1, 0.3)
        Shortest and longest pause between two recordings, seconds.
    sr : int, default=16000
        Sample rate of the written audio (sources are resampled to it).
    random_state : int or numpy.random.SeedSequence
        Seeds every draw; the same seed gives the same files.
    name : str, optional
        Corpus name (default ``"<corpus.name>-composed"``).
    data_home : path-like, optional
        The cache folder ``root`` is in, whose ``.locks`` folder holds the lock of the build
        (default: the parent of ``root``).

    Returns
    -------
    SpeechCorpus
        The composed utterances, loaded from ``root`` (``labels``: the words said,
        ``word_timings``: when).

    Raises
    ------
    DataError
        If the corpus is empty or a source recording has no label or several.
    ParameterError
        If a parameter is out of range.

    Notes
    -----
    Samples are clipped to [-1, 1] before 16-bit writing (resampling can overshoot a
    full-scale recording by a hair); the clipped samples are the only difference between
    the file and the concatenation of the resampled sources, besides 16-bit rounding.
    """
    from .._store import generated_folder
    from .._validation import check_positive_int

    n_utt = check_positive_int(n_utterances, "n_utterances")
    lo_w, hi_w = _check_range(n_words, "n_words", integer=True, low=1)
    lo_p, hi_p = _check_range(pause_s, "pause_s", integer=False, low=0.0)
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0:
        raise ParameterError(f"sr must be a positive int (Hz); got {sr!r}.")
    ss, seed_id = _seed_identity(random_state)
    utts = list(corpus)
    if not utts:
        raise DataError("compose_utterances needs a non-empty corpus.")
    for u in utts:
        if len(u.labels) != 1:
            raise DataError(f"{u.path}: compose_utterances needs exactly one label per source recording; got {u.labels}.")
    root = Path(root)
    manifest = {"format": COMPOSE_VERSION, "sources": _sources_digest(corpus), "n_utterances": n_utt,
                "n_words": [lo_w, hi_w], "pause_s": [lo_p, hi_p], "sr": int(sr), "seed": seed_id}

    def build(folder: Path) -> None:
        _write_composition(folder, utts, n_utt, (lo_w, hi_w), (lo_p, hi_p), int(sr), np.random.default_rng(ss))

    generated_folder(root, manifest, build, home=data_home)
    return load_generic_audio(root, name=name if name is not None else f"{corpus.name or 'corpus'}-composed")


def _write_composition(folder: Path, utts: list[Utterance], n_utt: int, n_words: tuple[int, int],
                       pause_s: tuple[float, float], sr: int, rng: np.random.Generator) -> None:
    """Draw and write the composition of :func:`compose_utterances` into the empty ``folder``."""
    import json

    from .audio import write_audio

    (lo_w, hi_w), (lo_p, hi_p) = n_words, pause_s
    speakers = sorted({u.speaker for u in utts})
    by_label: dict[str, dict[str, list[int]]] = {s: {} for s in speakers}
    for i, u in enumerate(utts):
        by_label[u.speaker].setdefault(u.labels[0], []).append(i)
    plan = []  # (speaker, [source indices], [pause samples])
    for j in range(n_utt):
        spk = speakers[j % len(speakers)]
        labels = sorted(by_label[spk])
        n = min(int(rng.integers(lo_w, hi_w + 1)), len(labels))
        chosen = rng.choice(len(labels), size=n, replace=False)
        srcs = [int(rng.choice(by_label[spk][labels[c]])) for c in chosen]
        pauses = [int(round(rng.uniform(lo_p, hi_p) * sr)) for _ in range(n - 1)]
        plan.append((spk, srcs, pauses))

    audio: dict[int, np.ndarray] = {}
    label_rows, timing_rows = [], []
    for j, (spk, srcs, pauses) in enumerate(plan):
        pieces, offset = [], 0
        words: list[WordTiming] = []
        for k, i in enumerate(srcs):
            if i not in audio:
                audio[i] = load_audio(utts[i].path, sr=sr, min_duration=0.0)
            y = audio[i]
            u = utts[i]
            t0 = offset / sr
            if u.word_timings:
                words += [WordTiming(w.word, t0 + w.start, t0 + w.end) for w in u.word_timings]
            else:
                words.append(WordTiming(u.transcription.strip() or u.labels[0], t0, (offset + len(y)) / sr))
            pieces.append(y)
            offset += len(y)
            if k < len(pauses):
                pieces.append(np.zeros(pauses[k], dtype=np.float32))
                offset += pauses[k]
        rel = f"{j:05d}_{spk}.wav"
        write_audio(folder / rel, np.clip(np.concatenate(pieces), -1.0, 1.0), sr)
        label_rows.append([rel, LABEL_SEPARATOR.join(utts[i].labels[0] for i in srcs), spk,
                           " ".join(utts[i].transcription.strip() or utts[i].labels[0] for i in srcs)])
        timing_rows += [[rel, w.word, format(w.start, ".9g"), format(w.end, ".9g")] for w in words]
    _write_csv(folder / LABELS_FILE, list(AUDIO_LABELS_HEADER), label_rows)
    _write_csv(folder / TIMINGS_FILE, ["file", "word", "start", "end"], timing_rows)
    sources = [[str(utts[i].path) for i in srcs] for _, srcs, _ in plan]
    (folder / "sources.json").write_text(json.dumps(sources))


def composed_sources(corpus: SpeechCorpus) -> list[list[str]]:
    """The source recordings of each utterance of a corpus made by :func:`compose_utterances`."""
    import json

    if corpus.root is None:
        raise DataError("The corpus has no root folder; it was not made by compose_utterances.")
    table = json.loads((Path(corpus.root) / "sources.json").read_text())
    index = {f"{j:05d}": s for j, s in enumerate(table)}
    return [index[Path(u.path).stem.split("_", 1)[0]] for u in corpus]


# --------------------------------------------------------------------------- ACORNS


def _local(tag: object) -> str:
    """Canonical element name: no namespace, lower case, no '-'/'_'."""
    if not isinstance(tag, str):  # comments, processing instructions
        return ""
    return re.sub(r"[-_\s]", "", tag.rsplit("}", 1)[-1].lower())


def _value(el: ET.Element) -> str:
    attrs = {_local(k): v for k, v in el.attrib.items()}
    for k in ("value", "val", "name"):
        if k in attrs:
            return attrs[k].strip()
    if len(el.attrib) == 1:
        return next(iter(el.attrib.values())).strip()
    return "".join(el.itertext()).strip()


_SPEAKER_RE = re.compile(r"speaker[-_ ]?(\w+)$", re.IGNORECASE)


def load_acorns(
    root: str | os.PathLike[str],
    *,
    speakers: Iterable[str] | None = None,
    on_error: str = "raise",
    check_audio: bool = True,
) -> SpeechCorpus:
    """Load the ACORNS Caregiver corpus (Thesis Appendix B.1; years 1 and 2).

    Parameters
    ----------
    root : path-like
        The folder holding ``XML/`` and ``WAV/``.
    speakers : iterable of str, optional
        Keep only these speaker ids (``"01"`` is ``Speaker-01``; ``"1"`` matches it too).
    on_error : {"raise", "skip"}
        ``"raise"``: an unreadable or unknown XML file, or a missing/corrupt audio file,
        raises :class:`DataFormatError` naming the file. ``"skip"``: such utterances are
        left out and listed in ``corpus.skipped``; a :class:`RuntimeWarning` says how many.
    check_audio : bool, default=True
        Open each audio file's header (see :func:`load_generic_audio`).

    Returns
    -------
    SpeechCorpus
        One utterance per XML file (or per ``<utterance>`` element), in speaker then file
        name order; labels are the ``vistag``/``vistags`` values, ``meta`` holds ``style``
        and the XML file. ACORNS has no word timings.
    """
    _check_on_error(on_error)
    root = Path(root)
    xml_root, wav_root = _child_dir(root, "XML"), _child_dir(root, "WAV")
    if xml_root is None:
        raise DataFormatError(f"{root} has no XML/ folder; the ACORNS layout is <root>/XML/Speaker-NN/*.xml.")
    if wav_root is None:
        raise DataFormatError(f"{root} has no WAV/ folder; the ACORNS layout is <root>/WAV/Speaker-NN/*.wav.")
    want = None if speakers is None else {str(s).lstrip("0") or "0" for s in speakers}
    spk_dirs = []
    for d in sorted(p for p in xml_root.iterdir() if p.is_dir()):
        m = _SPEAKER_RE.search(d.name)
        sid = m.group(1) if m else d.name
        if want is not None and (sid.lstrip("0") or "0") not in want:
            continue
        spk_dirs.append((sid, d))
    if not spk_dirs:
        raise DataFormatError(f"{xml_root} holds no Speaker-NN folder" + ("" if want is None else f" for {sorted(want)}")
                              + ".")
    wav_index = _index_audio(wav_root)
    utts: list[Utterance] = []
    skipped: list[SkippedFile] = []
    for sid, d in spk_dirs:
        wav_dir = _child_dir(wav_root, d.name)
        for xml_path in sorted(p for p in d.iterdir() if p.suffix.lower() == ".xml"):
            try:
                for rec in _parse_acorns_xml(xml_path):
                    path = _find_wav(rec["audio"], wav_dir, wav_index, xml_path)
                    duration = _audio_duration(path) if check_audio else None
                    utts.append(Utterance(path=path, speaker=sid, labels=rec["labels"],
                                          transcription=rec["trans"], duration=duration, source=str(xml_path),
                                          meta={"style": rec["style"], "xml": str(xml_path)}))
            except DataFormatError as exc:
                if on_error == "raise":
                    raise
                skipped.append(SkippedFile(str(xml_path), str(exc)))
    _report_skipped(skipped, str(root))
    return SpeechCorpus(utts, "acorns-caregiver", root, skipped)


def _child_dir(parent: Path, name: str) -> Path | None:
    p = parent / name
    if p.is_dir():
        return p
    if parent.is_dir():
        for c in parent.iterdir():
            if c.is_dir() and c.name.lower() == name.lower():
                return c
    return None


def _index_audio(wav_root: Path) -> dict[str, list[Path]]:
    index: dict[str, list[Path]] = {}
    for p in sorted(wav_root.rglob("*")):
        if p.suffix.lower() in _AUDIO_EXTENSIONS and p.is_file():
            index.setdefault(p.stem.lower(), []).append(p)
    return index


def _find_wav(name: str, wav_dir: Path | None, index: dict[str, list[Path]], xml_path: Path) -> Path:
    base = Path(name.replace("\\", "/")).name
    stem = Path(base).stem if Path(base).suffix.lower() in _AUDIO_EXTENSIONS else base
    if wav_dir is not None:
        for cand in (wav_dir / base, wav_dir / f"{stem}.wav", wav_dir / f"{stem}.WAV"):
            if cand.is_file():
                return cand
    hits = index.get(stem.lower(), [])
    if wav_dir is not None:  # prefer the speaker's own folder
        own = [h for h in hits if h.parent == wav_dir]
        hits = own or hits
    if len(hits) == 1:
        return hits[0]
    if len(hits) > 1:
        raise DataFormatError(f"{xml_path}: audio file {name!r} is ambiguous: {[str(h) for h in hits]}.")
    raise DataFormatError(
        f"{xml_path}: audio file {name!r} not found (looked in {wav_dir or 'WAV/'} and below the WAV folder)."
    )


def _parse_acorns_xml(path: Path) -> list[dict]:
    try:
        tree = ET.parse(path)
    except (ET.ParseError, OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(f"Cannot parse {path}: not well-formed XML ({exc}).") from exc
    doc = tree.getroot()
    units = [e for e in doc.iter() if _local(e.tag) == "utterance"] or [doc]
    records = []
    for unit in units:
        found: dict[str, list[ET.Element]] = {}
        for e in unit.iter():
            found.setdefault(_local(e.tag), []).append(e)
        audio = found.get("audiofile") or found.get("audio") or found.get("wav") or found.get("wavfile")
        tags = (found.get("vistag") or []) + (found.get("vistags") or [])
        if not audio or not tags:
            what = [w for w, ok in (("<audio-file>", bool(audio)), ("<vistag>/<vistags>", bool(tags))) if not ok]
            elements = sorted({e.tag for e in unit.iter() if isinstance(e.tag, str)})
            raise DataFormatError(
                f"{path}: unknown ACORNS structure: no {' and no '.join(what)} element; the file has elements "
                f"{elements}."
            )
        if len(audio) > 1:
            raise DataFormatError(f"{path}: {len(audio)} <audio-file> elements in one utterance.")
        audio_name = _value(audio[0])
        if not audio_name:
            raise DataFormatError(f"{path}: empty <audio-file> value.")
        labels: list[str] = []
        for t in tags:
            for l in re.split(r"[,;|\s]+", _value(t)):
                if l and l not in labels:
                    labels.append(l)
        if not labels:
            raise DataFormatError(f"{path}: empty keyword tag (<vistag>/<vistags>).")
        trans = " ".join(_value(t) for t in found.get("trans", []) + found.get("transcription", [])).strip()
        style = " ".join(_value(t) for t in found.get("style", [])).strip()
        records.append({"audio": audio_name, "labels": tuple(labels), "trans": trans, "style": style})
    return records
