"""Named data sets and the data root.

A *data root* is one folder holding the real data sets under their names::

    DATA_ROOT/
        fsdd/            Free Spoken Digit Dataset (WAVs + labels.csv, generic audio layout)
        msr-action3d/    MSR Action3D skeletons (aAA_sSS_eEE_skeleton3D.txt)
        eth80/           ETH-80 PNGs (the folder may also be named eth80-96px)
        coil20/          COIL20.mat
        choreo1/ choreo2/ acorns/    the thesis' own formats
        audio/ motion/ images/   a user's own data in the generic layouts

The data root is given explicitly (``--data-root DIR``), else by the environment variable
``MMCONCEPTS_DATA_ROOT``; nothing else is ever searched. :data:`DATASETS` describes each
set (layout, source, licence, citation, how to obtain it); :func:`find_datasets` returns
the sets present with a sound layout, :func:`dataset_status` what ``mmconcepts data list``
shows, and :func:`fetch_dataset` downloads, verifies (sha256) and unpacks a set that has
a stable public download.

Checks here are cheap (file names, headers, sizes): they say whether a folder *looks*
like the set. Reading every file is the loaders' job (``DatasetInfo.load``).
"""

from __future__ import annotations

import contextlib
import csv
import functools
import importlib
import json
import logging
import lzma
import os
import re
import shutil
import tarfile
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import IO, Any

from ._io import LABELS_HEADER, OLD_LABEL_COLUMNS
from ._validation import Interval, validate_params
from .errors import DataError, ParameterError

__all__ = [
    "DATA_ROOT_ENV",
    "DatasetInfo",
    "DATASETS",
    "data_root",
    "find_dataset",
    "find_datasets",
    "dataset_status",
    "fetch_dataset",
]

_LOG = logging.getLogger(__name__)

#: Environment variable naming the data root when no explicit one is given.
DATA_ROOT_ENV = "MMCONCEPTS_DATA_ROOT"

PathLike = str | os.PathLike[str]

_AUDIO_EXT = {".wav", ".flac"}
_CHOREO1_SUBSETS = ("primitive", "mixed_partial", "mixed_full")


# --------------------------------------------------------------------------- layout checks
# Each check returns None when the folder looks right, else one sentence saying what is wrong.
# Each counter returns the number of recordings (files or records) found; both are cheap. A set's file
# names are recognised by its loader's own parser (parse_fsdd_name, parse_msr_name, parse_eth80_name).


def _iter_files(path: Path, parse: Callable[[str], object], *, recursive: bool = True) -> Iterable[Path]:
    it = path.rglob("*") if recursive else path.iterdir()
    for p in it:
        if parse(p.name) is not None and p.is_file():
            yield p


def _fsdd_name(name: str) -> object:
    from .sound.data import parse_fsdd_name

    return parse_fsdd_name(name)


def _msr_name(name: str) -> object:
    from .motion.data import parse_msr_name

    return parse_msr_name(name)


def _eth80_name(name: str) -> object:
    from .vision.data import parse_eth80_name

    return parse_eth80_name(name)


def _csv_header(path: Path) -> list[str] | None:
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            row = next(csv.reader(fh), None)
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    return None if row is None else [c.strip().lower() for c in row]


def _csv_rows(path: Path) -> int:
    with open(path, newline="", encoding="utf-8-sig") as fh:
        return max(sum(1 for row in csv.reader(fh) if any(c.strip() for c in row)) - 1, 0)


def _check_labels_csv(path: Path, columns: tuple[str, ...], layout: str) -> str | None:
    labels = path / "labels.csv"
    if not labels.is_file():
        return f"no labels.csv (the {layout} layout needs one with columns {','.join(columns)})"
    header = _csv_header(labels)
    if header is None:
        return f"{labels} is empty or unreadable"
    have = set(header) | ({"labels"} if set(OLD_LABEL_COLUMNS) & set(header) else set())  # read with a warning
    missing = [c for c in columns if c not in have]
    if missing:
        return f"{labels} lacks column(s) {missing}; its header is {header}, expected {','.join(columns)}"
    return None


def _check_fsdd(path: Path) -> str | None:
    problem = _check_audio(path)
    if problem:
        if not (path / "labels.csv").exists() and next(iter(_iter_files(path, _fsdd_name)), None) is not None:
            problem += "; it holds FSDD WAVs: move them aside and run `mmconcepts data fetch fsdd`, or write labels.csv"
        return problem
    if next(iter(_iter_files(path, _fsdd_name)), None) is None:
        return "no {digit}_{speaker}_{index}.wav file"
    return None


def _count_fsdd(path: Path) -> int:
    return sum(1 for _ in _iter_files(path, _fsdd_name))


def _check_msr(path: Path) -> str | None:
    if next(iter(_iter_files(path, _msr_name, recursive=False)), None) is None:
        return "no aAA_sSS_eEE_skeleton3D.txt file at its top level"
    return None


def _count_msr(path: Path) -> int:
    return sum(1 for _ in _iter_files(path, _msr_name, recursive=False))


def _check_eth80(path: Path) -> str | None:
    if next(iter(_iter_files(path, _eth80_name)), None) is None:
        return "no <category><instance>-<tilt>-<pan>.png image (in it or its sub-folders)"
    return None


def _count_eth80(path: Path) -> int:
    return sum(1 for _ in _iter_files(path, _eth80_name))


def _coil20_shape(path: Path) -> tuple[int, int] | str:
    mat = path / "COIL20.mat"
    if not mat.is_file():
        return "no COIL20.mat"
    import scipy.io

    try:
        info = {name: shape for name, shape, _ in scipy.io.whosmat(mat)}
    except Exception as exc:  # scipy raises several types on a bad file
        return f"{mat} is not a readable MATLAB file ({type(exc).__name__}: {exc})"
    if "fea" not in info or "gnd" not in info:
        return f"{mat} lacks 'fea' or 'gnd' (holds {sorted(info)})"
    fea = info["fea"]
    if len(fea) != 2:
        return f"{mat}: 'fea' has shape {fea}, expected (n_images, n_pixels)"
    return fea


def _check_coil20(path: Path) -> str | None:
    shape = _coil20_shape(path)
    return shape if isinstance(shape, str) else None


def _count_coil20(path: Path) -> int:
    shape = _coil20_shape(path)
    return 0 if isinstance(shape, str) else int(shape[0])


def _read_records(json_path: Path) -> list | str:
    try:
        meta = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return f"{json_path} is not readable JSON ({exc})"
    recs = meta.get("records") if isinstance(meta, dict) else None
    if not isinstance(recs, list):
        return f"{json_path} has no 'records' list"
    return recs


def _choreo1_jsons(path: Path) -> list[Path]:
    return [path / f"{s}.json" for s in _CHOREO1_SUBSETS if (path / f"{s}.json").is_file()]


def _check_choreo1(path: Path) -> str | None:
    jsons = _choreo1_jsons(path)
    if not jsons:
        return f"none of {', '.join(s + '.json' for s in _CHOREO1_SUBSETS)}"
    for j in jsons:
        recs = _read_records(j)
        if isinstance(recs, str):
            return recs
    return None


def _count_choreo1(path: Path) -> int:
    return sum(len(r) for r in map(_read_records, _choreo1_jsons(path)) if not isinstance(r, str))


def _check_choreo2(path: Path) -> str | None:
    j = path / "choreo2.json"
    if not j.is_file():
        return "no choreo2.json"
    recs = _read_records(j)
    return recs if isinstance(recs, str) else None


def _count_choreo2(path: Path) -> int:
    recs = _read_records(path / "choreo2.json")
    return 0 if isinstance(recs, str) else len(recs)


def _child_dir(parent: Path, name: str) -> Path | None:
    for c in parent.iterdir():
        if c.is_dir() and c.name.lower() == name.lower():
            return c
    return None


def _check_acorns(path: Path) -> str | None:
    missing = [n for n in ("XML", "WAV") if _child_dir(path, n) is None]
    if missing:
        return f"no {' and '.join(m + '/' for m in missing)} folder (the layout is XML/Speaker-NN/*.xml, WAV/Speaker-NN/*.wav)"
    return None


def _count_acorns(path: Path) -> int:
    wav = _child_dir(path, "WAV")
    if wav is None:
        return 0
    return sum(1 for p in wav.rglob("*") if p.suffix.lower() in _AUDIO_EXT and p.is_file())


def _check_audio(path: Path) -> str | None:
    return _check_labels_csv(path, (*LABELS_HEADER, "speaker"), "generic audio")


def _check_images(path: Path) -> str | None:
    return _check_labels_csv(path, LABELS_HEADER, "generic image")


def _check_motion(path: Path) -> str | None:
    return _check_labels_csv(path, LABELS_HEADER, "generic motion")


def _count_labels_csv(path: Path) -> int:
    return _csv_rows(path / "labels.csv")


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class DatasetInfo:
    """A data set known by name: where it lives under a data root, its layout and provenance.

    ``real`` is False for the generic layouts (``audio``, ``motion``, ``images``): they are formats for a
    user's own data, not published data sets. ``max_unpacked_bytes`` and ``max_files`` bound what
    :func:`fetch_dataset` unpacks for the set (bytes of content, archive entries), set well above what the
    set holds; None: the defaults of :func:`fetch_dataset`.
    """

    name: str
    title: str
    modality: str  # "speech" | "motion" | "images"
    folders: tuple[str, ...]
    layout: str
    source: str
    licence: str
    citation: str
    obtain: str
    url: str | None = None
    sha256: str | None = None
    real: bool = True
    loader: str = ""  # "module:function" reading the set's folder ("module:f|g": the first that exists)
    max_unpacked_bytes: int | None = None
    max_files: int | None = None
    _check: Callable[[Path], str | None] | None = field(default=None, repr=False, compare=False)
    _count: Callable[[Path], int] | None = field(default=None, repr=False, compare=False)

    def check(self, path: PathLike) -> str | None:
        """None when ``path`` looks like this set's layout, else a sentence saying what is wrong."""
        path = Path(path)
        if not path.is_dir():
            return f"{path} is not a folder"
        try:
            return self._check(path) if self._check is not None else None
        except OSError as exc:
            return f"cannot read {path}: {exc}"

    def is_valid(self, path: PathLike) -> bool:
        """True when ``path`` looks like this set's layout (:meth:`check` finds nothing wrong)."""
        return self.check(path) is None

    def count(self, path: PathLike) -> int:
        """Number of recordings found in ``path`` (files or records, counted by name; cheap)."""
        path = Path(path)
        if not path.is_dir() or self._count is None:
            return 0
        try:
            return int(self._count(path))
        except OSError:
            return 0

    def load(self, path: PathLike, **kwargs):
        """Load the set from ``path`` with its loader (``kwargs`` go to the loader)."""
        module, _, funcs = self.loader.partition(":")
        try:
            mod = importlib.import_module(module)
        except ImportError as exc:
            raise DataError(f"data set {self.name!r}: its loader {self.loader!r} is not available ({exc}).") from exc
        for func in funcs.split("|"):  # the first that exists
            fn = getattr(mod, func, None)
            if fn is not None:
                return fn(path, **kwargs)
        raise DataError(f"data set {self.name!r}: its loader {self.loader!r} is not available.")


_FSDD_URL = "https://github.com/Jakobovski/free-spoken-digit-dataset/archive/v1.0.9.tar.gz"
# sha256 of the v1.0.9 tag archive (11,975,353 bytes) as published by TensorFlow Datasets in
# tensorflow_datasets/audio/spoken_digit/checksums.tsv (github.com/tensorflow/datasets), whose
# `spoken_digit` builder downloads this exact URL. Not computed here (no network). v1.0.9 holds
# 2500 recordings of 5 speakers (george, jackson, nicolas, theo, yweweler).
_FSDD_SHA256 = "8bc44cde129d505cbbb6b365c09f80c663f2aa77578afc634e6141a2f87100c0"

_LIST: tuple[DatasetInfo, ...] = (
    DatasetInfo(
        name="fsdd",
        title="Free Spoken Digit Dataset (real speech: English digit words)",
        modality="speech",
        folders=("fsdd",),
        layout=(
            "Mono 8 kHz WAV files named {digit}_{speaker}_{index}.wav (one digit word said alone, "
            "'zero'..'nine') and labels.csv in the generic audio layout (file,labels,speaker,"
            "transcription; labels is the digit's word). `data fetch fsdd` writes this layout from "
            "the v1.0.9 archive (5 speakers, 2500 recordings; upstream's recordings/ folder "
            "flattened, its README.md and metadata.py kept as upstream-*)."
        ),
        source="https://github.com/Jakobovski/free-spoken-digit-dataset",
        licence="CC BY-SA 4.0",
        citation=(
            "Z. Jackson et al. Free Spoken Digit Dataset (FSDD). "
            "https://github.com/Jakobovski/free-spoken-digit-dataset, doi:10.5281/zenodo.1342401"
        ),
        obtain="mmconcepts data fetch fsdd (v1.0.9 tag archive, 12 MB, sha256-verified)",
        url=_FSDD_URL,
        sha256=_FSDD_SHA256,
        loader="mmconcepts.sound.data:load_fsdd|load_generic_audio",
        # v1.0.9 unpacks to about 2530 entries and 20 MB (2500 WAVs of about 7 kB, as a copy of 1500 of
        # them measures); room for later releases (3000 recordings) and a tenfold error in that estimate.
        max_unpacked_bytes=200_000_000,
        max_files=10_000,
        _check=_check_fsdd,
        _count=_count_fsdd,
    ),
    DatasetInfo(
        name="msr-action3d",
        title="MSR Action3D (real Kinect v1 skeletons, 20 actions x 10 subjects x 2-3 repetitions)",
        modality="motion",
        folders=("msr-action3d",),
        layout=(
            "One text file per sequence, aAA_sSS_eEE_skeleton3D.txt (action 01..20, subject 01..10, "
            "repetition 01..03), at the folder's top level; each line 'x y z confidence' for one "
            "joint, 20 lines per frame (real-world coordinates)."
        ),
        source="https://sites.google.com/view/wanqingli/data-sets/msr-action3d",
        licence="research use (see the data set's page); cite the paper",
        citation=(
            "W. Li, Z. Zhang, Z. Liu. Action recognition based on a bag of 3D points. "
            "CVPR Workshops (CVPR4HB), 2010."
        ),
        obtain=(
            "request/download the skeleton files (real-world coordinates) as the MSR Action3D page "
            "says (https://sites.google.com/view/wanqingli/data-sets/msr-action3d) and unpack the "
            "*_skeleton3D.txt files into DATA_ROOT/msr-action3d"
        ),
        loader="mmconcepts.motion.data:load_msr_action3d",
        _check=_check_msr,
        _count=_count_msr,
    ),
    DatasetInfo(
        name="eth80",
        title="ETH-80 (real object photos, 8 categories x 10 objects x 41 views)",
        modality="images",
        folders=("eth80", "eth80-96px"),
        layout=(
            "PNG images named <category><instance>-<tilt>-<pan>.png (e.g. cow3-045-090.png), in the "
            "folder or its sub-folders (the original cropped-close128 archive's <category>/<object>/ "
            "tree works as is); any image size."
        ),
        source="http://datasets.d2.mpi-inf.mpg.de/eth80/ (MPI Informatics)",
        licence="research use (see the data set's page); cite the paper",
        citation=(
            "B. Leibe, B. Schiele. Analyzing appearance and contour based methods for object "
            "categorization. CVPR 2003."
        ),
        obtain=(
            "download http://datasets.d2.mpi-inf.mpg.de/eth80/eth80-cropped-close128.tgz (all 80 "
            "objects, 128x128; no published checksum) and unpack it into DATA_ROOT/eth80, or run "
            "`mmconcepts data fetch eth80 --url URL --sha256 HASH` with a hash you trust"
        ),
        loader="mmconcepts.vision.data:load_eth80",
        # The cropped-close128 archive: 3280 PNGs of 128x128 (and a mask each in some archives), some
        # 6600 entries and, at the 14 kB of a 96x96 copy's images scaled to 128x128, about 160 MB.
        max_unpacked_bytes=2_000_000_000,
        max_files=20_000,
        _check=_check_eth80,
        _count=_count_eth80,
    ),
    DatasetInfo(
        name="coil20",
        title="COIL-20 (real object photos, 20 objects x 72 views, grayscale 32x32)",
        modality="images",
        folders=("coil20",),
        layout=(
            "COIL20.mat: 'fea' n_images x 1024 (32x32 grayscale, one image per row, stored column by "
            "column, values in [0, 1]) and 'gnd' n_images x 1 (object ids 1..20)."
        ),
        source="https://www.cs.columbia.edu/CAVE/software/softlib/coil-20.php",
        licence="non-commercial research use (Columbia CAVE); cite the technical report",
        citation=(
            "S. A. Nene, S. K. Nayar, H. Murase. Columbia Object Image Library (COIL-20). "
            "Technical Report CUCS-005-96, Columbia University, 1996."
        ),
        obtain=(
            "download COIL20.mat (the 32x32 MATLAB version distributed with D. Cai's data sets, "
            "http://www.cad.zju.edu.cn/home/dengcai/Data/MLData.html; no published checksum) into "
            "DATA_ROOT/coil20/ (the CAVE page's coil-20-proc.zip holds 128x128 PNGs, not this file)"
        ),
        loader="mmconcepts.vision.data:load_coil20",
        _check=_check_coil20,
        _count=_count_coil20,
    ),
    DatasetInfo(
        name="choreo1",
        title="Choreo1, the choreography database (Kinect, 48 primitive gestures and their combinations)",
        modality="motion",
        folders=("choreo1",),
        layout=(
            "<subset>.json for subset primitive, mixed_partial or mixed_full ({'marker-names', "
            "'data-file', 'records': [{'data-id', 'labels'}]}) and the NPZ it names, one (T, 24, 3) "
            "array of marker positions per record under key str(data-id)."
        ),
        source="http://flowers.inria.fr/choreo/doc/index.html",
        licence="research use (see the data set's page); cite the paper",
        citation=(
            "O. Mangin, P.-Y. Oudeyer. Learning to recognize parallel combinations of human motion "
            "primitives with linguistic descriptions using non-negative matrix factorization. "
            "IEEE/RSJ IROS 2012."
        ),
        obtain=(
            "download the numpy format from http://flowers.inria.fr/choreography_database.html and "
            "put primitive.json, mixed_partial.json, mixed_full.json and their NPZ files in DATA_ROOT/choreo1"
        ),
        loader="mmconcepts.motion.data:load_choreo1",
        _check=_check_choreo1,
        _count=_count_choreo1,
    ),
    DatasetInfo(
        name="choreo2",
        title="Choreo2 (Kinect, 1100 demonstrations of 10 gestures, positions and orientations)",
        modality="motion",
        folders=("choreo2",),
        layout=(
            "choreo2.json ({'marker_names', 'label_descriptions', 'data_file', 'records': "
            "[{'data_id', 'labels'}]}) and choreo2.npz, one (T, 15, 7) array per record (x, y, z, "
            "qx, qy, qz, qw) under key str(data_id)."
        ),
        source="https://zenodo.org/record/29551",
        licence="see the Zenodo record (doi:10.5281/zenodo.29551); cite it",
        citation=(
            "O. Mangin, P.-Y. Oudeyer. Choreography 2 dataset, doi:10.5281/zenodo.29551; and Learning "
            "semantic components from subsymbolic multimodal perception, ICDL-EpiRob 2013."
        ),
        obtain=(
            "download the numpy format from https://zenodo.org/record/29551 and put choreo2.json and "
            "choreo2.npz in DATA_ROOT/choreo2"
        ),
        loader="mmconcepts.motion.data:load_choreo2",
        _check=_check_choreo2,
        _count=_count_choreo2,
    ),
    DatasetInfo(
        name="acorns",
        title="ACORNS Caregiver corpus (real infant- and adult-directed speech, English)",
        modality="speech",
        folders=("acorns",),
        layout=(
            "XML/Speaker-NN/<utterance>.xml (audio-file, vistag(s), trans) and "
            "WAV/Speaker-NN/<audio-file>.wav."
        ),
        source="ACORNS project (Acquisition of Communication and Recognition Skills, EU FP6), distributed via ELRA",
        licence="ELRA licence (not freely redistributable)",
        citation=(
            "T. Altosaar, L. ten Bosch, G. Aimetti, C. Koniaris, K. Demuynck, H. van den Heuvel. "
            "A speech corpus for modeling language acquisition: CAREGIVER. LREC 2010."
        ),
        obtain=(
            "obtain the CAREGIVER corpus under licence (ELRA / the ACORNS consortium) and unpack its "
            "XML/ and WAV/ folders into DATA_ROOT/acorns"
        ),
        loader="mmconcepts.sound.data:load_acorns",
        _check=_check_acorns,
        _count=_count_acorns,
    ),
    DatasetInfo(
        name="audio",
        title="Your own recordings (generic audio layout)",
        modality="speech",
        folders=("audio",),
        layout=(
            "WAV or FLAC files (in the folder or sub-folders) and labels.csv with columns "
            "file,labels,speaker,transcription (labels separated by ';'; transcription optional; "
            "file relative to the folder); optional word_timings.csv (file,word,start,end)."
        ),
        source="your own data",
        licence="yours",
        citation="",
        obtain="put your recordings and labels.csv in DATA_ROOT/audio",
        real=False,
        loader="mmconcepts.sound.data:load_generic_audio",
        _check=_check_audio,
        _count=_count_labels_csv,
    ),
    DatasetInfo(
        name="motion",
        title="Your own motion recordings (generic motion layout)",
        modality="motion",
        folders=("motion",),
        layout=(
            "One CSV file per recording (in the folder or sub-folders): a header naming the columns "
            "<joint>_x,<joint>_y,<joint>_z of every joint, then one row per frame; and labels.csv with "
            "columns file,labels (labels separated by ';'; file relative to the folder)."
        ),
        source="your own data",
        licence="yours",
        citation="",
        obtain="put your recordings and labels.csv in DATA_ROOT/motion",
        real=False,
        loader="mmconcepts.motion.data:load_motion_folder",
        _check=_check_motion,
        _count=_count_labels_csv,
    ),
    DatasetInfo(
        name="images",
        title="Your own images (generic image layout)",
        modality="images",
        folders=("images",),
        layout=(
            "Image files (in the folder or sub-folders) and labels.csv with columns file,labels "
            "(one label per image; optionally view and category; file relative to the folder)."
        ),
        source="your own data",
        licence="yours",
        citation="",
        obtain="put your images and labels.csv in DATA_ROOT/images",
        real=False,
        loader="mmconcepts.vision.data:load_image_folder",
        _check=_check_images,
        _count=_count_labels_csv,
    ),
)

#: Every known set by name, in display order (real sets first, then the generic layouts).
DATASETS: Mapping[str, DatasetInfo] = MappingProxyType({d.name: d for d in _LIST})


def _info(name: str) -> DatasetInfo:
    try:
        return DATASETS[name]
    except (KeyError, TypeError):
        raise ParameterError(f"Unknown data set {name!r}; known sets: {', '.join(DATASETS)}.") from None


# --------------------------------------------------------------------------- finding sets


def data_root(path: PathLike | None = None) -> Path | None:
    """The data root: ``path`` if given, else ``$MMCONCEPTS_DATA_ROOT``, else None.

    Never looks anywhere else. The path is made absolute (not resolved through links); the
    folder is not required to exist (``fetch`` creates it).
    """
    if path is not None and str(path) != "":
        return Path(path).expanduser().absolute()
    env = os.environ.get(DATA_ROOT_ENV, "").strip()
    return Path(env).expanduser().absolute() if env else None


def _locate(info: DatasetInfo, root: Path) -> tuple[Path | None, str | None]:
    """(first present folder with a sound layout or None, what is wrong with the folders tried before it)."""
    problems: list[str] = []
    for folder in info.folders:
        path = root / folder
        if not path.exists():
            continue
        problem = info.check(path)
        if problem is None:
            return path, ("; ".join(problems) or None)
        problems.append(f"{path}: {problem}")
    return None, ("; ".join(problems) or None)


def find_dataset(name: str, root: PathLike | None = None) -> Path | None:
    """The folder of set ``name`` under the data root, or None.

    Folders are tried in the order of ``DATASETS[name].folders``; the first one present with a
    sound layout wins. A folder present with a wrong layout is logged (a warning naming the
    folder and what is wrong) and not used.
    """
    info = _info(name)
    root = data_root(root)
    if root is None or not root.is_dir():
        return None
    path, problem = _locate(info, root)
    if problem:
        _LOG.warning("data set %r: folder with a wrong layout ignored: %s", name, problem)
    return path


def find_datasets(root: PathLike | None = None, names: Iterable[str] | None = None) -> dict[str, Path]:
    """``{name: folder}`` for the sets (all, or ``names``) present under the data root with a sound layout."""
    names = list(DATASETS) if names is None else list(names)
    for n in names:
        _info(n)
    root = data_root(root)
    if root is None:
        return {}
    if not root.is_dir():
        _LOG.warning("data root %s is not a folder; no data set found.", root)
        return {}
    found = {}
    for n in names:
        path = find_dataset(n, root)
        if path is not None:
            found[n] = path
    return found


def dataset_status(root: PathLike | None = None) -> list[dict]:
    """One dict per known set, for ``mmconcepts data list``.

    Keys: ``name``, ``title``, ``modality``, ``real``, ``found`` (folder or None), ``n``
    (recordings, or None when not found), ``problem`` (why a present folder is not used, or
    None), ``obtain``, ``licence``, ``source``, ``citation``.
    """
    root = data_root(root)
    rows = []
    for info in DATASETS.values():
        path = problem = None
        if root is not None and root.is_dir():
            path, problem = _locate(info, root)
        rows.append({
            "name": info.name,
            "title": info.title,
            "modality": info.modality,
            "real": info.real,
            "found": path,
            "n": info.count(path) if path is not None else None,
            "problem": problem if path is None else None,
            "obtain": info.obtain,
            "licence": info.licence,
            "source": info.source,
            "citation": info.citation,
        })
    return rows


# --------------------------------------------------------------------------- fetching

#: What :func:`fetch_dataset` unpacks at most for a set whose entry declares no bound: 10 GB of content in
#: 100 000 entries (files and folders). Over ten times the largest set of the registry (ETH-80's archive, some
#: 6600 entries) and far above its sizes, yet below what fills the disk of a machine that holds the sets:
#: an archive that unpacks beyond them (a decompression bomb, the wrong file) is refused unless raised.
_MAX_UNPACKED_BYTES = 10_000_000_000
_MAX_FILES = 100_000
#: Space left free on the disk beyond what a download or an unpacked archive needs.
_FREE_MARGIN = 16 * 2**20
#: What a file or folder takes on disk beyond its content, at most (one block of a common file system).
_ENTRY_OVERHEAD = 4096
#: What an archive holds per entry beyond its content, at most (a tar header, its padding and a long-name
#: header; zip's headers are smaller), and once (a tar's end blocks in 10 kB records, a zip's end records).
_ARCHIVE_ENTRY_OVERHEAD = 2048
_ARCHIVE_OVERHEAD = 2**20
#: What reading a damaged archive raises: zipfile, tarfile and their decompressors (a gzip or bz2 stream
#: that is not one raises OSError, an encrypted zip member RuntimeError, an unknown zip method
#: NotImplementedError).
_READ_ERRORS = (OSError, EOFError, ValueError, RuntimeError, NotImplementedError, zlib.error, lzma.LZMAError,
                zipfile.BadZipFile, tarfile.TarError)


@dataclass(frozen=True)
class _Bounds:
    """What an archive may unpack to, and where each bound comes from (said in messages)."""

    max_bytes: int
    max_files: int
    bytes_from: str = "the bound given"
    files_from: str = "the bound given"

    @property
    def download(self) -> int:
        """Bytes an archive within the bounds can take at most."""
        return self.max_bytes + _ARCHIVE_ENTRY_OVERHEAD * self.max_files + _ARCHIVE_OVERHEAD

    def describe(self) -> str:
        return (f"{self.max_bytes:,} bytes of content ({self.bytes_from}), "
                f"{self.max_files:,} entries ({self.files_from})")


_RAISE_BYTES = "raise the bound with max_unpacked_bytes=N (--max-size SIZE on the command line)"
_RAISE_FILES = "raise the bound with max_files=N (--max-files N on the command line)"


def _one_line(exc: BaseException) -> str:
    """``exc``'s message on one line (tarfile's and some network errors' span several)."""
    return " ".join(str(exc).split())


def _cannot_write(path: PathLike, exc: OSError) -> str:
    return (
        f"Cannot write {path}: {exc.strerror or _one_line(exc)}. Nothing was kept. Fix: make room on that disk, "
        f"or fetch into a data root on a disk you can write to (--data-root DIR, data_root=...)."
    )


def _check_free_space(folder: Path, needed: int, what: str) -> None:
    """Raise DataError when the disk of ``folder`` has less than ``needed`` bytes free plus the margin."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # cannot tell (some network file systems): the writes themselves will say
        return
    if free < needed + _FREE_MARGIN:
        raise DataError(
            f"Not enough free space in {folder} to {what}: it needs {needed:,} bytes and {_FREE_MARGIN:,} kept free; "
            f"the disk has {free:,} bytes free. Nothing was written. Fix: make room on that disk, or fetch into a "
            f"data root on another disk (--data-root DIR, data_root=...)."
        )


class _Sink:
    """A binary file that takes at most ``limit`` bytes (more: ``DataError(too_much())``, nothing past the
    limit written) and names its path in the DataError an OS error while writing becomes."""

    def __init__(self, fh: IO[bytes], path: Path, limit: int, too_much: Callable[[], str]):
        self.fh, self.path, self.limit, self.too_much = fh, path, limit, too_much
        self.written = 0

    def write(self, data: bytes) -> int:
        self.written += len(data)
        if self.written > self.limit:
            raise DataError(self.too_much())
        try:
            return self.fh.write(data)
        except OSError as exc:
            raise DataError(_cannot_write(self.path, exc)) from exc

    def flush(self) -> None:
        try:
            self.fh.flush()
        except OSError as exc:
            raise DataError(_cannot_write(self.path, exc)) from exc


@contextlib.contextmanager
def _writing(path: Path, limit: int, too_much: Callable[[], str]) -> Iterator[_Sink]:
    """Open ``path`` for writing as a :class:`_Sink`; an OS error opening or closing it is a DataError naming it."""
    try:
        fh = open(path, "wb")
    except OSError as exc:
        raise DataError(_cannot_write(path, exc)) from exc
    try:
        yield _Sink(fh, path, limit, too_much)
    finally:
        try:
            fh.close()
        except OSError as exc:  # the last buffered write
            raise DataError(_cannot_write(path, exc)) from exc


@dataclass(frozen=True)
class _Member:
    """An archive entry: its name, its declared size (0 for a folder), and how to read its content."""

    name: str
    size: int
    is_dir: bool
    open: Callable[[], IO[bytes]]


def _entries(archive: Path, stack: contextlib.ExitStack) -> Iterator[tuple[str, int, bool, Callable[[], IO[bytes]]]]:
    """(name, declared size, is a folder, opener) of each entry of a zip or tar archive, read lazily.

    Raises DataError for an entry that is a link, a device or a pipe, or for a file that is no archive.
    """
    if zipfile.is_zipfile(archive):
        zf = stack.enter_context(zipfile.ZipFile(archive))
        for info in zf.infolist():  # a zip member that is a link is unpacked as a file holding its target
            yield info.filename, info.file_size, info.is_dir(), functools.partial(zf.open, info)
        return
    try:
        tf = stack.enter_context(tarfile.open(archive))
    except tarfile.TarError as exc:
        raise DataError(f"{archive.name} is neither a tar nor a zip archive ({_one_line(exc)}).") from exc
    for t in tf:  # reads one header at a time: the listing stops at the first entry past a bound
        if not (t.isreg() or t.isdir()):
            raise DataError(f"{archive.name}: member {t.name!r} is a link, a device or a pipe, not a file or a folder; "
                            f"refused.")
        yield t.name, t.size if t.isreg() else 0, t.isdir(), functools.partial(_tar_member, tf, t)


def _tar_member(tf: tarfile.TarFile, t: tarfile.TarInfo) -> IO[bytes]:
    fh = tf.extractfile(t)
    if fh is None:  # only for entries that are not regular files, which _entries refuses
        raise tarfile.ReadError(f"{t.name!r} has no content")
    return fh


def _list_members(archive: Path, stack: contextlib.ExitStack, bounds: _Bounds, base: Path) -> list[_Member]:
    """The archive's entries, checked against ``bounds`` from their declared sizes before anything is written."""

    def inside(name: str) -> bool:
        target = (base / name).resolve()
        return target == base or base in target.parents

    members: list[_Member] = []
    total = 0
    for name, size, is_dir, opener in _entries(archive, stack):
        if len(members) == bounds.max_files:
            raise DataError(
                f"{archive.name} holds more than {bounds.max_files:,} entries (files and folders), "
                f"{bounds.files_from}; nothing was unpacked. Fix: if it is the archive you meant, {_RAISE_FILES}."
            )
        if not inside(name):
            raise DataError(f"{archive.name}: member {name!r} would be written outside the folder; refused.")
        total += size
        if total > bounds.max_bytes:
            raise DataError(
                f"{archive.name} unpacks to {total:,} bytes or more (as its entries declare), more than "
                f"{bounds.max_bytes:,} bytes, {bounds.bytes_from}; nothing was unpacked (an archive that unpacks to "
                f"far more than it weighs may be a decompression bomb). Fix: if it is the archive you meant, "
                f"{_RAISE_BYTES}."
            )
        members.append(_Member(name, size, is_dir, opener))
    return members


def _safe_extract(archive: Path, dest: Path, bounds: _Bounds) -> None:
    """Unpack a tar or zip archive into ``dest``, within bounds.

    Refused before anything is written: members outside ``dest``, links, devices and pipes; more than
    ``bounds.max_files`` entries or ``bounds.max_bytes`` bytes of content as the archive declares them; less free
    space than that content needs. While writing, a member is stopped at its declared size (the bound
    holds for what is written, not only for what is declared). Every error is a DataError: a damaged
    member (naming it), an OS error (naming the file).
    """
    base = dest.resolve()
    with contextlib.ExitStack() as stack:
        try:
            members = _list_members(archive, stack, bounds, base)
        except DataError:
            raise
        except _READ_ERRORS as exc:
            raise DataError(f"The archive {archive.name} is corrupt: {type(exc).__name__}: {_one_line(exc)}.") from exc
        try:
            dest.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataError(_cannot_write(dest, exc)) from exc
        total = sum(m.size for m in members)
        _check_free_space(dest, total + _ENTRY_OVERHEAD * len(members),
                          f"unpack {archive.name} ({total:,} bytes in {len(members):,} entries)")
        for m in members:
            _write_member(archive, m, base / m.name)


def _write_member(archive: Path, m: _Member, target: Path) -> None:
    try:
        (target if m.is_dir else target.parent).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(_cannot_write(target, exc)) from exc
    if m.is_dir:
        return

    def too_much() -> str:
        return (f"The archive {archive.name} is corrupt: member {m.name!r} holds more than the {m.size:,} bytes "
                f"it declares; stopped there, nothing was kept.")

    with _writing(target, m.size, too_much) as sink:
        try:
            with m.open() as src:
                shutil.copyfileobj(src, sink)
        except DataError:
            raise
        except _READ_ERRORS as exc:
            raise DataError(
                f"The archive {archive.name} is corrupt: member {m.name!r} cannot be read ({type(exc).__name__}: "
                f"{_one_line(exc)}); nothing was kept. Its download matched its sha256: the archive itself is damaged."
            ) from exc


def _single_top(folder: Path) -> Path:
    """The archive's single top-level folder if it has one (GitHub archives do), else ``folder``."""
    entries = [p for p in folder.iterdir() if p.name not in ("__MACOSX",)]
    if len(entries) == 1 and entries[0].is_dir():
        return entries[0]
    return folder


def _arrange_fsdd(unpacked: Path, out: Path) -> None:
    """FSDD archive -> WAVs at the top level + labels.csv (generic audio layout)."""
    from .sound.data import AUDIO_LABELS_HEADER, FSDD_WORDS, parse_fsdd_name

    wavs = sorted(_iter_files(unpacked, _fsdd_name), key=lambda p: p.name)
    if not wavs:
        raise DataError(f"the archive holds no {{digit}}_{{speaker}}_{{index}}.wav file (unpacked in {unpacked}).")
    out.mkdir()
    rows = []
    seen = set()
    for p in wavs:
        if p.name in seen:
            raise DataError(f"the archive holds two files named {p.name}.")
        seen.add(p.name)
        parsed = parse_fsdd_name(p.name)
        assert parsed is not None  # _iter_files yields only names that parse
        digit, speaker, _ = parsed
        word = FSDD_WORDS[digit]
        shutil.move(str(p), out / p.name)
        rows.append((p.name, word, speaker, word))
    with open(out / "labels.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(AUDIO_LABELS_HEADER)
        w.writerows(rows)
    top = _single_top(unpacked)
    for extra in ("README.md", "metadata.py"):
        if (top / extra).is_file():
            shutil.move(str(top / extra), out / f"upstream-{extra}")


def _arrange_default(unpacked: Path, out: Path) -> None:
    shutil.move(str(_single_top(unpacked)), out)


_ARRANGE: dict[str, Callable[[Path, Path], None]] = {"fsdd": _arrange_fsdd}


def _hash_mismatch(exc: Exception, expected: str) -> str | None:
    """The hash pooch computed, when ``exc`` is pooch's hash-mismatch error; else None."""
    msg = str(exc)
    if "hash" not in msg.lower():
        return None
    got = [h for h in re.findall(r"\b[0-9a-fA-F]{64}\b", msg) if h.lower() != expected.lower()]
    return got[0] if got else "unknown"


def _content_length(url: str) -> int | None:
    """The size a web server announces for ``url`` (a HEAD request), or None when it does not say."""
    if not url.lower().startswith(("http://", "https://")):
        return None
    import requests

    try:
        response = requests.head(url, allow_redirects=True, timeout=30)
        length = int(response.headers["content-length"]) if response.status_code == 200 else -1
    except Exception:  # noqa: BLE001 - only a hint: whatever fails here, the download itself reports
        return None
    return length if length >= 0 else None


class _BoundedDownloader:
    """A pooch downloader that writes at most ``bounds.download`` bytes, checked against the size the server
    announces (and the free space for it) before writing; an OS error while writing names the file."""

    def __init__(self, url: str, *, what: str, bounds: _Bounds, progressbar: bool):
        import pooch

        self.inner = pooch.downloaders.choose_downloader(url, progressbar=progressbar)  # what retrieve would use
        self.what, self.bounds = what, bounds

    def _too_large(self, size: str) -> str:
        return (
            f"{self.what} is {size}, more than an archive within the bounds ({self.bounds.describe()}) can be; "
            f"nothing was kept. Fix: if it is the file you meant, {_RAISE_BYTES}, or max_files=N (--max-files N)."
        )

    def __call__(self, url: str, output_file: str, pooch: Any) -> None:
        path = Path(output_file)
        length = _content_length(url)
        if length is not None:
            if length > self.bounds.download:
                raise DataError(self._too_large(f"{length:,} bytes (as the server says)"))
            _check_free_space(path.parent, length, f"download {url} ({length:,} bytes)")
        with _writing(path, self.bounds.download,
                      lambda: self._too_large(f"larger than {self.bounds.download:,} bytes")) as sink:
            self.inner(url, sink, pooch)


def _download(url: str, folder: Path, *, name: str, known: str, bounds: _Bounds, progressbar: bool) -> Path:
    """Download ``url`` into ``folder`` with pooch, checked against its sha256, ``bounds`` and the free space."""
    import pooch
    import requests

    try:
        downloader = _BoundedDownloader(url, what=f"the download of {name!r} from {url}", bounds=bounds,
                                        progressbar=progressbar)
        return Path(pooch.retrieve(url, known_hash=f"sha256:{known}", fname=Path(url.split("?")[0]).name or
                                   f"{name}.archive", path=folder, downloader=downloader))
    except DataError:
        raise
    except ValueError as exc:
        got = _hash_mismatch(exc, known)
        if got is None:
            raise DataError(f"Cannot fetch {name!r} from {url}: {_one_line(exc)}") from exc
        raise DataError(
            f"Download of {name!r} from {url} is corrupt or not the expected file: expected sha256 "
            f"{known}, got {got}. Nothing was unpacked. Fix: fetch again (a transfer may have been cut); "
            f"if the hash still differs the archive changed upstream: check it with the data set's "
            f"provider and pass its published hash with --sha256."
        ) from exc
    except requests.RequestException as exc:  # an OSError too: network and HTTP status errors
        raise DataError(f"Cannot download {name!r} from {url}: {type(exc).__name__}: {_one_line(exc)}") from exc
    except OSError as exc:
        if exc.filename:  # a file of the download folder (the file written is named by its _Sink)
            raise DataError(_cannot_write(exc.filename, exc)) from exc
        raise DataError(f"Cannot download {name!r} from {url}: {type(exc).__name__}: {_one_line(exc)}") from exc
    except Exception as exc:  # other protocols' errors (ftplib, paramiko)
        raise DataError(f"Cannot download {name!r} from {url}: {type(exc).__name__}: {_one_line(exc)}") from exc


def _bounds(info: DatasetInfo, max_unpacked_bytes: int | None, max_files: int | None) -> _Bounds:
    """The bounds of a fetch: those given, else the set's own, else the defaults."""

    def pick(given: int | None, own: int | None, default: int, option: str) -> tuple[int, str]:
        if given is not None:
            return given, f"the bound given ({option})"
        if own is not None:
            return own, f"the bound of {info.name!r} in the registry"
        return default, "the default bound"

    n_bytes, bytes_from = pick(max_unpacked_bytes, info.max_unpacked_bytes, _MAX_UNPACKED_BYTES, "max_unpacked_bytes")
    n_files, files_from = pick(max_files, info.max_files, _MAX_FILES, "max_files")
    return _Bounds(n_bytes, n_files, bytes_from, files_from)


_FETCH_CONSTRAINTS = {
    "max_unpacked_bytes": [Interval("int", 1, None), None],
    "max_files": [Interval("int", 1, None), None],
}


def fetch_dataset(
    name: str,
    root: PathLike | None = None,
    *,
    url: str | None = None,
    sha256: str | None = None,
    progressbar: bool = False,
    max_unpacked_bytes: int | None = None,
    max_files: int | None = None,
) -> Path:
    """Download, verify (sha256) and unpack set ``name`` into ``root/<folders[0]>``.

    Parameters
    ----------
    name : str
        A key of :data:`DATASETS`.
    root : path-like, optional
        The data root (default: ``$MMCONCEPTS_DATA_ROOT``); created if missing.
    url, sha256 : str, optional
        Override the set's download and its hash. A download is only ever unpacked after its
        sha256 matched: with no known hash (the set's own, or ``sha256``) nothing is fetched.
    progressbar : bool
        Show pooch's progress bar (needs tqdm).
    max_unpacked_bytes, max_files : int, optional
        Bounds on what the archive unpacks to: bytes of content and entries (files and folders).
        Default: the set's own (``DATASETS[name].max_unpacked_bytes``, ``.max_files``), else 10 GB
        and 100 000. An archive beyond them is refused from the sizes it declares, before anything
        is written; a member that holds more than it declares is stopped there. A download larger
        than an archive within the bounds can be is refused too.

    Returns
    -------
    Path
        The set's folder. If the set is already present with a sound layout, it is returned
        untouched (nothing is downloaded).

    Raises
    ------
    ParameterError
        A bound that is not an int >= 1; a malformed sha256.
    DataError
        No data root; the set has no public download (the message says how to obtain it);
        no known hash; the download failed or is corrupt (expected and got hashes); the
        archive is damaged, goes past a bound, or does not hold the set's layout; the disk has
        not enough free space for the download (when the server gives its size) or for the
        unpacked content (checked before writing); an OS error while writing (full disk, no
        permission: the message names the file); the target folder exists with something else
        in it. Nothing half-written is left behind: the set is assembled in a temporary
        folder beside the target and moved in place only once complete and checked.
    """
    info = _info(name)
    validate_params({"max_unpacked_bytes": max_unpacked_bytes, "max_files": max_files}, _FETCH_CONSTRAINTS,
                    owner="fetch_dataset")
    root = data_root(root)
    if root is None:
        raise DataError(
            f"No data root to fetch {name!r} into: give --data-root DIR (data_root=...) or set {DATA_ROOT_ENV}."
        )
    url = url or info.url
    if url is None:
        raise DataError(f"Data set {name!r} has no public download to fetch. To obtain it: {info.obtain}.")
    known = sha256 or (info.sha256 if url == info.url else None)
    if not known:
        raise DataError(
            f"No known sha256 for {url}: a download that cannot be verified is not unpacked "
            f"(it could be truncated, changed or not the data set). Give the hash published by the "
            f"data set's provider with --sha256 HASH (sha256=...)."
        )
    known = known.lower().removeprefix("sha256:")
    if not re.fullmatch(r"[0-9a-f]{64}", known):
        raise ParameterError(f"sha256 must be 64 hexadecimal digits; got {known!r}.")
    bounds = _bounds(info, max_unpacked_bytes, max_files)

    target = root / info.folders[0]
    present, _ = _locate(info, root) if root.is_dir() else (None, None)
    if present is not None:
        _LOG.info("data set %r already present in %s; nothing fetched.", name, present)
        return present
    if target.exists():
        raise DataError(
            f"{target} exists but does not hold {name!r} in its layout ({info.check(target)}); "
            f"move or remove it, then fetch again."
        )

    if progressbar:
        try:
            import tqdm  # noqa: F401  (pooch needs it for its progress bar)
        except ImportError:
            progressbar = False
    try:
        root.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".fetch-{info.folders[0]}-", dir=root))
    except OSError as exc:
        raise DataError(_cannot_write(root, exc)) from exc
    try:
        archive = _download(url, stage / "download", name=name, known=known, bounds=bounds, progressbar=progressbar)
        unpacked = stage / "unpacked"
        _safe_extract(archive, unpacked, bounds)
        out = stage / info.folders[0]
        _ARRANGE.get(name, _arrange_default)(unpacked, out)
        problem = info.check(out)
        if problem:
            raise DataError(f"The archive from {url} does not hold {name!r} in its layout: {problem}.")
        (out / "SOURCE.txt").write_text(
            f"{info.title}\nfetched from {url}\nsha256 {known}\nlicence: {info.licence}\n"
            f"cite: {info.citation}\n",
            encoding="utf-8",
        )
        os.replace(out, target)
    except OSError as exc:  # arranging the set, writing SOURCE.txt, moving it in place
        raise DataError(_cannot_write(exc.filename or stage, exc)) from exc
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    _LOG.info("data set %r fetched into %s (%d recordings).", name, target, info.count(target))
    return target
