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

import csv
import importlib
import json
import logging
import os
import re
import shutil
import tarfile
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from ._io import LABELS_HEADER, OLD_LABEL_COLUMNS
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
    user's own data, not published data sets.
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


def _safe_extract(archive: Path, dest: Path) -> None:
    """Unpack a tar or zip archive into ``dest``; refuse members outside it or links."""
    dest.mkdir(parents=True, exist_ok=True)
    base = dest.resolve()

    def inside(name: str) -> bool:
        target = (base / name).resolve()
        return target == base or base in target.parents

    if zipfile.is_zipfile(archive):
        with zipfile.ZipFile(archive) as zf:
            for m in zf.infolist():
                if not inside(m.filename):
                    raise DataError(f"{archive}: member {m.filename!r} would be written outside the folder; refused.")
            zf.extractall(dest)
        return
    try:
        tf = tarfile.open(archive)
    except tarfile.TarError as exc:
        raise DataError(f"{archive} is neither a tar nor a zip archive ({exc}).") from exc
    with tf:
        members = tf.getmembers()
        for t in members:
            if not inside(t.name) or t.issym() or t.islnk() or t.isdev():
                raise DataError(f"{archive}: member {t.name!r} is a link, a device or outside the folder; refused.")
        tf.extractall(dest, members=members, filter="data")


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


def fetch_dataset(
    name: str,
    root: PathLike | None = None,
    *,
    url: str | None = None,
    sha256: str | None = None,
    progressbar: bool = False,
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

    Returns
    -------
    Path
        The set's folder. If the set is already present with a sound layout, it is returned
        untouched (nothing is downloaded).

    Raises
    ------
    DataError
        No data root; the set has no public download (the message says how to obtain it);
        no known hash; the download failed or is corrupt (expected and got hashes); the
        archive does not hold the set's layout; the target folder exists with something else
        in it. Nothing half-written is left behind: the set is assembled in a temporary
        folder beside the target and moved in place only once complete and checked.
    """
    import pooch

    info = _info(name)
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
    root.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".fetch-{info.folders[0]}-", dir=root))
    try:
        try:
            archive = pooch.retrieve(
                url,
                known_hash=f"sha256:{known}",
                fname=Path(url.split("?")[0]).name or f"{name}.archive",
                path=stage / "download",
                progressbar=progressbar,
            )
        except ValueError as exc:
            got = _hash_mismatch(exc, known)
            if got is None:
                raise DataError(f"Cannot fetch {name!r} from {url}: {exc}") from exc
            raise DataError(
                f"Download of {name!r} from {url} is corrupt or not the expected file: expected sha256 "
                f"{known}, got {got}. Nothing was unpacked. Fix: fetch again (a transfer may have been cut); "
                f"if the hash still differs the archive changed upstream: check it with the data set's "
                f"provider and pass its published hash with --sha256."
            ) from exc
        except Exception as exc:  # requests/urllib/OS errors: network, HTTP status, disk
            raise DataError(f"Cannot download {name!r} from {url}: {type(exc).__name__}: {exc}") from exc
        unpacked = stage / "unpacked"
        _safe_extract(Path(archive), unpacked)
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
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    _LOG.info("data set %r fetched into %s (%d recordings).", name, target, info.count(target))
    return target
