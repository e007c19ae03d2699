"""Your own recordings as a paired multimodal data set (thesis sections 6.5-6.6).

The thesis learns concepts from examples in which a word is heard while an object is shown
or a gesture is seen. :func:`paired_dataset` builds such examples from recordings of each
modality that were made apart (the thesis' situation too: its sounds, gestures and images
come from three corpora), then gives the features the multimodal learner takes:

1. **Load** each modality from a folder in its generic layout (``labels.csv`` + files:
   :func:`~mmconcepts.sound.load_generic_audio`, :func:`~mmconcepts.vision.load_image_folder`,
   :func:`~mmconcepts.motion.load_motion_folder`) or take a set already loaded (a
   ``SpeechCorpus``, ``ImageSet`` or ``MotionDataset``, e.g. from ``load_fsdd`` or
   ``load_eth80``).
2. **Pair by concept.** When the modalities share label names (``"dog"`` said and ``"dog"``
   shown), a concept is a shared label. When their vocabularies differ (digit words and
   object photos), each other modality's labels are put in a random one-to-one
   correspondence with the first modality's (the thesis' Table 6.1 is one such
   correspondence). Or give the pairs yourself: a CSV with one ``<modality>_file`` column per
   modality (file names as in the modalities' ``labels.csv``) and an optional ``concept``
   column.
3. **Split by recording.** Each modality's recordings are split by concept into the parts
   (default: 60 % training, 20 % test, 20 % reference, as the thesis' Fig. 6.5-6.7), then
   paired within each part: every recording of a part is used, the modality with fewer
   recordings of a concept reusing its recordings in turn. So no recording behind a test or
   reference example is behind a training example. With an explicit pairing, examples that
   share a recording stay in one part.
4. **Features** (:meth:`PairedDataset.features`), fitted on the training recordings only:
   HAC for sound (22 MFCC, thesis section 5.3), superpixel colour histograms for images
   (section 6.5.3), joint angle-velocity histograms for motion (section 3.2).

A recording that cannot take part (no label, several labels, a label with no counterpart,
a file the pairing CSV does not name) is left out with a :class:`~mmconcepts.errors.DataWarning`
that counts it: nothing is dropped silently.
"""

from __future__ import annotations

import csv
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import check_random_state
from ..errors import DataError, DataFormatError, DataWarning, ParameterError

__all__ = ["DEFAULT_PARTS", "PairedDataset", "paired_dataset"]

#: The parts of the thesis' evaluation (Fig. 6.5-6.7): training, test and reference recordings.
DEFAULT_PARTS: dict[str, float] = {"train": 0.6, "test": 0.2, "reference": 0.2}

_KINDS = {"sound": "sound", "audio": "sound", "speech": "sound", "image": "image", "images": "image",
          "motion": "motion", "gesture": "motion", "gestures": "motion"}


def _kind_of(name: str, collection: Any) -> str:
    from ..motion import MotionDataset
    from ..sound.data import SpeechCorpus
    from ..vision import ImageSet

    for cls, kind in ((SpeechCorpus, "sound"), (ImageSet, "image"), (MotionDataset, "motion")):
        if isinstance(collection, cls):
            return kind
    if name in _KINDS:
        return _KINDS[name]
    raise ParameterError(
        f"paired_dataset: cannot tell what modality {name!r} is. Expected a folder under one of the names "
        f"{sorted(_KINDS)} or a loaded SpeechCorpus, ImageSet or MotionDataset; got {type(collection).__name__}. "
        "Fix: name the modality 'sound', 'image' or 'motion', or load it first.")


def _load(kind: str, path: Path, on_error: str) -> Any:
    if not path.is_dir():
        raise DataError(f"paired_dataset: expected a folder for the {kind} recordings; got {path}, which is not one. "
                        "Fix: give the folder that holds labels.csv.")
    if kind == "sound":
        from ..sound.data import load_generic_audio

        return load_generic_audio(path, on_error=on_error)
    if kind == "image":
        from ..vision import load_image_folder

        return load_image_folder(path, on_error=on_error)
    from ..motion import load_motion_folder

    return load_motion_folder(path, on_error=on_error)


def _labels_and_ids(kind: str, collection: Any) -> tuple[list[tuple[str, ...]], list[str]]:
    """Each recording's labels (as names) and its id (its file, else its position)."""
    if kind == "sound":
        return [tuple(str(x) for x in labs) for labs in collection.labels], [str(p) for p in collection.paths]
    if kind == "image":
        paths = collection.paths or [None] * len(collection)
        return ([(str(x),) for x in collection.labels],
                [str(p) if p is not None else f"image {i}" for i, p in enumerate(paths)])
    names = collection.label_names
    labels = [tuple(str(names.get(x, x)) for x in rec.labels) for rec in collection]
    ids = [f"{rec.source}#{rec.record_id}" if rec.record_id else (rec.source or f"record {i}")
           for i, rec in enumerate(collection)]
    return labels, ids


def _warn(counts: Mapping[str, Mapping[str, int]]) -> None:
    lines = [f"{modality}: {n} recording{'s' if n != 1 else ''} {why}"
             for modality, reasons in counts.items() for why, n in reasons.items() if n]
    if lines:
        warnings.warn("paired_dataset left recordings out: " + "; ".join(lines) + ".", DataWarning, stacklevel=4)


@dataclass
class PairedDataset:
    """Examples that pair one recording of each modality, with their concepts and parts.

    Built by :func:`paired_dataset`; read the examples of a part with :meth:`indices` and
    their features with :meth:`features`.

    Attributes
    ----------
    modalities : tuple of str
        The modalities' names, in the order given.
    collections : dict of str to SpeechCorpus, ImageSet or MotionDataset
        The recordings of each modality, as loaded (every one, used or not).
    kinds : dict of str to {"sound", "image", "motion"}
    concepts : tuple of str
        The concepts' names: the first modality's labels.
    labels : dict of str to tuple of str
        Each modality's label for each concept (``labels[m][c]`` goes with ``concepts[c]``):
        the correspondence the examples were paired by.
    y : ndarray of int, shape (n_examples,)
        Concept of each example (index into ``concepts``).
    part : ndarray of str, shape (n_examples,)
        Part of each example (``"train"``, ``"test"``, ``"reference"`` by default).
    items : dict of str to ndarray of int, shape (n_examples,)
        Recording of each example in each modality (index into ``collections[m]``).
    recording_ids : dict of str to list of str
        Id (file) of each recording of each modality.
    excluded : dict of str to dict of str to int
        Recordings left out, per modality and reason (also said by a warning).
    """

    modalities: tuple[str, ...]
    collections: dict[str, Any]
    kinds: dict[str, str]
    concepts: tuple[str, ...]
    labels: dict[str, tuple[str, ...]]
    y: np.ndarray
    part: np.ndarray
    items: dict[str, np.ndarray]
    recording_ids: dict[str, list[str]]
    excluded: dict[str, dict[str, int]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.y.size)

    def __repr__(self) -> str:
        parts = {p: int((self.part == p).sum()) for p in dict.fromkeys(self.part.tolist())}
        return (f"PairedDataset(modalities={self.modalities}, n_examples={len(self)}, "
                f"n_concepts={len(self.concepts)}, parts={parts})")

    @property
    def parts(self) -> tuple[str, ...]:
        """The parts' names, in order of first appearance."""
        return tuple(dict.fromkeys(self.part.tolist()))

    def indices(self, part: str) -> np.ndarray:
        """Examples of ``part``, shape (n_part,), int."""
        if part not in self.parts:
            raise ParameterError(f"PairedDataset.indices: expected one of the parts {self.parts}; got {part!r}.")
        return np.flatnonzero(self.part == part)

    def sources(self) -> list[frozenset[tuple[str, str]]]:
        """The recordings behind each example: ``(modality, recording id)`` pairs."""
        return [frozenset((m, self.recording_ids[m][int(self.items[m][i])]) for m in self.modalities)
                for i in range(len(self))]

    def shared_recordings(self) -> set[tuple[str, str]]:
        """Recordings behind examples of two different parts (empty for a sound split)."""
        seen: dict[tuple[str, str], str] = {}
        shared = set()
        for src, p in zip(self.sources(), self.part.tolist()):
            for r in src:
                if seen.setdefault(r, p) != p:
                    shared.add(r)
        return shared

    def features(self, *, fit_on: str = "train", random_state: Any = None, sound: Any = None, image: Any = None,
                 motion: Any = None) -> dict[str, dict[str, Any]]:
        """The feature matrix of every modality for every part, the extractors fitted on ``fit_on``'s recordings.

        Parameters
        ----------
        fit_on : str, default="train"
            The part whose recordings fit the codebooks.
        random_state : int, Generator or None
            Seeds the extractors' codebooks (use a stream apart from the pairing's).
        sound, image, motion : transformer, optional
            The extractor of that kind of modality, fitted on a list of recordings' sequences
            (sound: MFCC sequences; motion: joint-angle sequences) or images. Defaults:
            ``HAC()`` (the thesis' codebooks 150/150/100, lags 2 and 5), ``ImageFeatures(("color",),
            stack=True)``, ``MotionHistograms(data="joint", method="vq", n_bins=25, delay=3)``.

        Returns
        -------
        dict of str to dict of str to matrix
            ``X[part][modality]``: shape (n_part, n_features_of_modality), one row per example of
            the part (in the order of :meth:`indices`); nonnegative, dense or CSR.
        """
        from sklearn.base import clone

        rng = check_random_state(random_state)
        train_examples = self.indices(fit_on)
        out: dict[str, dict[str, Any]] = {p: {} for p in self.parts}
        for m in self.modalities:
            kind = self.kinds[m]
            used = np.unique(self.items[m])
            raw = _raw(kind, self.collections[m], used)
            est = {"sound": sound, "image": image, "motion": motion}[kind]
            est = clone(est) if est is not None else _default_extractor(kind)
            if "random_state" in est.get_params():
                est.set_params(random_state=int(rng.integers(2**31 - 1)))
            train_rec = np.unique(self.items[m][train_examples])
            est.fit([raw[int(r)] for r in train_rec])
            F = est.transform([raw[int(r)] for r in used])
            row_of = {int(r): j for j, r in enumerate(used)}
            for p in self.parts:
                rows = [row_of[int(r)] for r in self.items[m][self.indices(p)]]
                out[p][m] = F[rows]
        return out


def _raw(kind: str, collection: Any, used: np.ndarray) -> dict[int, Any]:
    """What each used recording's extractor takes: MFCC sequences, images, joint-angle sequences."""
    if kind == "sound":
        from ..sound.features import MFCCConfig, mfcc

        config = MFCCConfig(n_mfcc=22)
        return {int(i): mfcc(collection.load(int(i), sr=config.sr), config) for i in used}
    if kind == "image":
        return {int(i): collection[int(i)] for i in used}
    from ..motion import joint_angles

    return {int(i): joint_angles(collection[int(i)]) for i in used}


def _default_extractor(kind: str) -> Any:
    if kind == "sound":
        from ..sound.hac import HAC

        return HAC()
    if kind == "image":
        from ..vision import ImageFeatures

        return ImageFeatures(("color",), stack=True)
    from ..motion import MotionHistograms

    return MotionHistograms(data="joint", method="vq", n_bins=25, delay=3)


def _check_parts(parts: Mapping[str, float]) -> dict[str, float]:
    parts = dict(parts)
    if len(parts) < 2 or any(not isinstance(v, (int, float)) or not v > 0 for v in parts.values()):
        raise ParameterError(f"paired_dataset: expected parts as at least two names with positive shares, e.g. "
                             f"{DEFAULT_PARTS}; got {parts}.")
    total = sum(parts.values())
    return {k: v / total for k, v in parts.items()}


def _split_counts(n: int, shares: Sequence[float]) -> np.ndarray:
    """How many of ``n`` recordings go to each part: largest remainders, at least one each when n allows."""
    raw = np.asarray(shares) * n
    counts = np.floor(raw).astype(int)
    for j in np.argsort(-(raw - counts), kind="stable")[: n - counts.sum()]:
        counts[j] += 1
    for j in range(len(counts)):  # every part gets a recording of the concept when there are enough
        if counts[j] == 0 and n >= len(counts):
            donor = int(np.argmax(counts))
            counts[donor] -= 1
            counts[j] += 1
    return counts


def paired_dataset(
    sources: Mapping[str, str | os.PathLike[str] | Any],
    *,
    pairing: str | os.PathLike[str] | None = None,
    parts: Mapping[str, float] = DEFAULT_PARTS,
    random_state: Any = None,
    on_error: str = "skip",
) -> PairedDataset:
    """Pair recordings of several modalities by concept, split by recording into training, test and reference.

    Parameters
    ----------
    sources : mapping of str to path or loaded set
        One entry per modality, at least two. A folder in the generic layout of its kind
        (the name says the kind: ``"sound"``/``"audio"``, ``"image"``/``"images"``,
        ``"motion"``) or a loaded ``SpeechCorpus``, ``ImageSet`` or ``MotionDataset`` (any
        name). The first modality's labels name the concepts.
    pairing : path, optional
        A CSV with one ``<name>_file`` column per modality (the file as written in that
        modality's ``labels.csv``, or its path) and optionally ``concept``; one row per
        example. Without ``concept`` an example's concept is its first modality's label.
        Without ``pairing``, recordings are paired by their labels (see the module's text).
    parts : mapping of str to float, default=DEFAULT_PARTS
        The parts and their shares of each concept's recordings (normalised to sum to one).
    random_state : int, Generator or None
        Seeds the label correspondence, the split and the pairing (one stream; give the
        feature extractors and the learner their own).
    on_error : {"skip", "raise"}
        Passed to the folder loaders: ``"skip"`` leaves unreadable files out with a warning.

    Returns
    -------
    PairedDataset

    Raises
    ------
    DataError
        Fewer than two modalities, no concept common to all modalities, a pairing CSV that
        names no known file.

    Warns
    -----
    DataWarning
        When recordings are left out, with their count per modality and reason.

    Examples
    --------
    >>> from mmconcepts.multimodal import paired_dataset  # doctest: +SKIP
    >>> data = paired_dataset({"sound": "my_words/", "image": "my_objects/"}, random_state=0)  # doctest: +SKIP
    >>> X = data.features(random_state=1)                   # X["train"]["sound"], ...  # doctest: +SKIP
    """
    if not isinstance(sources, Mapping) or len(sources) < 2:
        raise DataError("paired_dataset: expected a mapping of at least two modalities to their folders or loaded "
                        f"sets, e.g. {{'sound': 'words/', 'image': 'objects/'}}; got {sources!r}.")
    if on_error not in ("skip", "raise"):
        raise ParameterError(f"paired_dataset: on_error must be 'skip' or 'raise'; got {on_error!r}.")
    shares = _check_parts(parts)
    rng = check_random_state(random_state)
    names = tuple(str(m) for m in sources)
    kinds, collections, labels, ids = {}, {}, {}, {}
    for m, src in sources.items():
        m = str(m)
        loaded = isinstance(src, (str, os.PathLike))
        kinds[m] = _kind_of(m, None if loaded else src)
        collections[m] = _load(kinds[m], Path(src), on_error) if loaded else src
        labels[m], ids[m] = _labels_and_ids(kinds[m], collections[m])
    if pairing is not None:
        return _explicit(Path(pairing), names, kinds, collections, labels, ids, shares, rng)
    return _by_labels(names, kinds, collections, labels, ids, shares, rng)


def _by_labels(names, kinds, collections, labels, ids, shares, rng) -> PairedDataset:
    excluded: dict[str, dict[str, int]] = {m: {} for m in names}
    single: dict[str, dict[int, str]] = {}
    for m in names:
        single[m] = {i: labs[0] for i, labs in enumerate(labels[m]) if len(labs) == 1}
        n_multi = sum(len(labs) > 1 for labs in labels[m])
        n_none = sum(len(labs) == 0 for labs in labels[m])
        excluded[m].update({"with several labels (one concept per recording is needed)": n_multi,
                            "without a label": n_none})
    vocab = {m: sorted(set(single[m].values())) for m in names}
    first = names[0]
    shared = set(vocab[first]).intersection(*(vocab[m] for m in names[1:]))
    labels_of: dict[str, list[str]] = {}
    if shared:  # the modalities name their concepts alike
        concepts = sorted(shared)
        labels_of = {m: list(concepts) for m in names}
        how = "not shared by every modality"
    else:  # a random one-to-one correspondence, as the thesis' Table 6.1
        n = min(len(vocab[m]) for m in names)
        if n == 0:
            raise DataError("paired_dataset: a modality has no recording with exactly one label; expected labels in "
                            "each modality's labels.csv. Fix: label the recordings (one concept each).")
        concepts = sorted(rng.choice(vocab[first], size=n, replace=False).tolist())
        labels_of[first] = list(concepts)
        for m in names[1:]:
            labels_of[m] = [str(x) for x in rng.choice(vocab[m], size=n, replace=False)]
        how = "left without a counterpart (the modalities have different numbers of labels)"
    for m in names:
        keep = set(labels_of[m])
        excluded[m][f"with a label {how}"] = sum(lab not in keep for lab in single[m].values())
    _warn(excluded)
    # split each modality's recordings of each concept into the parts, then pair within each part
    part_names = list(shares)
    y: list[int] = []
    part: list[str] = []
    items: dict[str, list[np.ndarray]] = {m: [] for m in names}
    for c in range(len(concepts)):
        per_part: dict[str, list[np.ndarray]] = {}
        for m in names:
            recs = np.array(sorted(i for i, lab in single[m].items() if lab == labels_of[m][c]), dtype=np.intp)
            recs = rng.permutation(recs)
            cuts = np.cumsum(_split_counts(len(recs), list(shares.values())))[:-1]
            per_part[m] = np.split(recs, cuts)
        for j, p in enumerate(part_names):
            n_ex = max(len(per_part[m][j]) for m in names)
            if n_ex == 0 or any(len(per_part[m][j]) == 0 for m in names):
                continue  # a concept with too few recordings in some modality for this part
            for m in names:
                recs = per_part[m][j]
                reps = np.concatenate([rng.permutation(recs) for _ in range(-(-n_ex // len(recs)))])[:n_ex]
                items[m].append(reps)
            y += [c] * n_ex
            part += [p] * n_ex
    if not y:
        raise DataError("paired_dataset: no example could be made; expected each concept to have recordings in every "
                        "modality. Fix: check the labels.")
    return PairedDataset(names, dict(collections), dict(kinds), tuple(concepts),
                         {m: tuple(labels_of[m]) for m in names}, np.asarray(y, dtype=np.intp), np.asarray(part),
                         {m: np.concatenate(items[m]).astype(np.intp) for m in names}, dict(ids), excluded)


def _explicit(path: Path, names, kinds, collections, labels, ids, shares, rng) -> PairedDataset:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise DataError(f"paired_dataset: cannot read the pairing CSV {path}: {exc}.") from exc
    columns = {f"{m}_file": m for m in names}
    header = set(rows[0]) if rows else set()
    if not rows or not set(columns) <= header:
        raise DataFormatError(f"paired_dataset: expected a pairing CSV with the columns {sorted(columns)} (and "
                              f"optionally concept); got {sorted(header)} in {path}.")
    lookup = {}
    for m in names:  # a recording is found by its full id, its file name or its path relative to its folder
        table: dict[str, int] = {}
        for i, rid in enumerate(ids[m]):
            table.setdefault(rid, i)
            table.setdefault(Path(rid).name, i)
        lookup[m] = table
    examples: list[dict[str, int]] = []
    concept_names: list[str] = []
    unknown = 0
    for row in rows:
        idx = {m: lookup[m].get((row[f"{m}_file"] or "").strip()) for m in names}
        if None not in idx.values():
            concept = (row.get("concept") or "").strip()
            if not concept:
                labs = labels[names[0]][idx[names[0]]]
                concept = labs[0] if len(labs) == 1 else ""
            if concept:
                examples.append({m: int(v) for m, v in idx.items() if v is not None})
                concept_names.append(concept)
                continue
        unknown += 1
    if not examples:
        raise DataError(f"paired_dataset: no row of {path} names known files of every modality with a concept; "
                        "expected file names as written in each modality's labels.csv.")
    used = {m: {e[m] for e in examples} for m in names}
    excluded = {m: {"not named by the pairing CSV": len(ids[m]) - len(used[m])} for m in names}
    excluded[names[0]]["rows of the pairing CSV naming an unknown file or no concept"] = unknown
    _warn(excluded)
    # examples that share a recording form one group; groups are dealt to the parts by concept
    parent = list(range(len(examples)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    first_of: dict[tuple[str, int], int] = {}
    for e, ex in enumerate(examples):
        for m in names:
            other = first_of.setdefault((m, ex[m]), e)
            parent[root(e)] = root(other)
    groups = np.array([root(e) for e in range(len(examples))])
    concepts = sorted(set(concept_names))
    y = np.searchsorted(concepts, concept_names)
    part = np.empty(len(examples), dtype=object)
    part_names = list(shares)
    for c in range(len(concepts)):
        g = rng.permutation(np.unique(groups[y == c]))
        cuts = np.cumsum(_split_counts(len(g), list(shares.values())))[:-1]
        for p, chunk in zip(part_names, np.split(g, cuts)):
            part[np.isin(groups, chunk) & (y == c)] = p
    # a group spanning two concepts goes where its first concept put it
    for gid in np.unique(groups):
        members = np.flatnonzero(groups == gid)
        part[members] = part[members[0]]
    return PairedDataset(names, dict(collections), dict(kinds), tuple(concepts), {m: tuple(concepts) for m in names},
                         y.astype(np.intp), part.astype(str),
                         {m: np.array([e[m] for e in examples], dtype=np.intp) for m in names}, dict(ids), excluded)
