"""Image sets and their loaders (the image modality of thesis chapter 6, section 6.5.3).

Layouts (as the thesis' data formats describe them):

Generic image layout
    A folder holding image files (PNG, JPEG, ... anything ``imageio`` reads; in it or in
    sub-folders) and ``labels.csv`` with the header ``file,labels`` (as every generic
    layout) and optionally ``view``: ``file`` is the path relative to the folder,
    ``labels`` the object (concept) shown, one per image, ``view`` an identifier of the
    viewpoint. This package also reads and writes an optional ``category`` column (the
    object's category, e.g. ``cow`` for ``cow3``); any other column is ignored. A column
    ``label`` (the old spelling of ``labels``) is still read, with a :class:`FutureWarning`.
ETH-80
    Leibe and Schiele (CVPR 2003): one PNG per view, named
    ``<category><instance>-<tilt>-<pan>.png`` (``cow3-045-090.png``), in one folder or in
    the original ``<category>/<category><instance>/`` sub-folders. The label of an image
    is the object (``cow3``), its category is ``cow`` and its view ``045-090``. Other
    files (the original distribution's ``*-map.png`` segmentation masks) are ignored.
COIL-20
    Nene, Nayar and Murase (1996), as the MATLAB file ``COIL20.mat``: ``fea``
    (n_images, side * side) grayscale rows in [0, 1] and ``gnd`` (n_images, 1) object
    ids. Each row stores its image column by column (MATLAB order): reshaped row-major it
    would be transposed. Checked on the data: with column-major order the labels on the
    boxes read left to right ("ANACIN", "TYLENOL"), the cars lie horizontally and the
    lamp-like object 13 has its wide cap at the top in all 72 views.

Images are float RGB arrays of shape (H, W, 3) with values in [0, 1]; grayscale images
are promoted to three equal channels, an alpha channel is dropped.

Loaders take ``on_error="raise"`` (the first unreadable image raises a
:class:`~mmconcepts.errors.DataFormatError` naming the file) or ``"skip"`` (bad images are
left out, listed as ``(file, reason)`` in ``image_set.skipped``, and a
:class:`RuntimeWarning` says how many).
"""

from __future__ import annotations

import logging
import math
import numbers
import os
import re
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .._io import read_labels_csv, split_labels
from .._validation import check_subset_indices
from ..errors import DataError, DataFormatError, ParameterError

__all__ = [
    "ETH80_CATEGORIES",
    "LABELS_FILE",
    "ImageSet",
    "SkippedFile",
    "as_rgb_image",
    "check_images",
    "load_coil20",
    "load_eth80",
    "parse_eth80_name",
    "load_image",
    "load_image_folder",
]

#: Name of the label table of the generic image layout.
LABELS_FILE = "labels.csv"

#: The eight ETH-80 categories (Leibe and Schiele, 2003).
ETH80_CATEGORIES: tuple[str, ...] = ("apple", "car", "cow", "cup", "dog", "horse", "pear", "tomato")

_ETH80_NAME = re.compile(r"^([a-z]+)(\d+)-(\d{3})-(\d{3})\.png$", re.IGNORECASE)


def parse_eth80_name(name: str) -> tuple[str, int, str, str] | None:
    """``(category, instance, tilt, pan)`` of an ETH-80 image ``<category><instance>-<tilt>-<pan>.png``, else None.

    The category is lower-cased, the instance an int, tilt and pan their three digits as
    written. The one definition of an ETH-80 image's name: :func:`load_eth80` reads the files
    it matches, and the data-set registry (:mod:`mmconcepts.datasets`) recognises ETH-80
    folders by it.

    Examples
    --------
    >>> parse_eth80_name("cup3-045-180.png")
    ('cup', 3, '045', '180')
    >>> parse_eth80_name("cup3.png") is None
    True
    """
    m = _ETH80_NAME.match(name)
    return None if m is None else (m.group(1).lower(), int(m.group(2)), m.group(3), m.group(4))


class SkippedFile(NamedTuple):
    """A file that ``on_error="skip"`` left out, and why."""

    file: str
    reason: str


# --------------------------------------------------------------------------- arrays


def as_rgb_image(image: object, *, name: str = "image") -> np.ndarray:
    """Return ``image`` as a float64 RGB array of shape (H, W, 3) with values in [0, 1].

    Parameters
    ----------
    image : array-like of shape (H, W), (H, W, 1), (H, W, 2), (H, W, 3) or (H, W, 4)
        Grayscale (promoted to three equal channels), grayscale + alpha, RGB or RGBA (the
        alpha channel is dropped). Integer images are scaled by their type's maximum
        (255 for uint8, 65535 for uint16); boolean images become 0/1; float images must
        already lie in [0, 1].
    name : str
        How to call the image in error messages.

    Raises
    ------
    DataError
        If the array is not an image of one of these shapes, is smaller than 2 x 2, holds
        NaN or infinite values, or float values outside [0, 1].

    Notes
    -----
    This function is the one meaning of an image array in :mod:`mmconcepts.vision`: the
    loaders and every descriptor (:func:`~mmconcepts.vision.superpixel_colors`,
    :func:`~mmconcepts.vision.dense_sift` and the bags built on them) read their images
    through it. Two channels are gray + alpha, as PNG's "LA" mode and Pillow/imageio give
    them (not two colour channels); the alpha channel is dropped, not composited over a
    background, so a transparent pixel keeps the colour stored under it.
    """
    try:
        a = np.asarray(image)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise DataError(f"{name} is not an array of pixel values ({exc}).") from exc
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise DataError(f"{name} must hold numbers; got dtype {a.dtype}.")
    if np.iscomplexobj(a):
        raise DataError(f"{name} holds complex numbers; give real pixel values.")
    if a.ndim == 3 and a.shape[2] in (1, 2):
        a = a[:, :, 0]
    elif a.ndim == 3 and a.shape[2] == 4:
        a = a[:, :, :3]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
        raise DataError(
            f"{name} must have shape (H, W) (grayscale) or (H, W, 3) (RGB, or RGBA with 4 channels); "
            f"got {a.shape}."
        )
    if a.shape[0] < 2 or a.shape[1] < 2:
        raise DataError(f"{name} is too small: shape {a.shape}; an image needs at least 2 x 2 pixels.")
    if a.dtype == bool:
        a = a.astype(np.float64)
    elif np.issubdtype(a.dtype, np.integer):
        info = np.iinfo(a.dtype)
        if info.min < 0 and a.min() < 0:
            raise DataError(f"{name} holds negative integer pixel values (min {a.min()}).")
        a = a.astype(np.float64) / float(info.max)
    else:
        a = np.asarray(a, dtype=np.float64)
        if not np.isfinite(a).all():
            raise DataError(f"{name} holds {int((~np.isfinite(a)).sum())} NaN or infinite value(s).")
        lo, hi = float(a.min()), float(a.max())
        if lo < 0.0 or hi > 1.0:
            raise DataError(
                f"{name} is a float image with values in [{lo:g}, {hi:g}]; float images must lie in [0, 1] "
                "(divide 8-bit values by 255)."
            )
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    return np.ascontiguousarray(a)


def check_images(images: object, *, min_size: int = 2) -> list[np.ndarray]:
    """Validate a collection of images: an :class:`ImageSet` or a sequence of arrays.

    Returns a list of float64 (H, W, 3) arrays in [0, 1] (see :func:`as_rgb_image`).

    Raises
    ------
    DataError
        If ``images`` is one array (wrap a single image as ``[image]``), is empty, or an
        image is invalid or smaller than ``min_size`` pixels on a side.
    """
    if isinstance(images, ImageSet):
        out = list(images.images)
    else:
        if isinstance(images, np.ndarray) and images.ndim in (2, 3) and images.dtype != object:
            raise DataError(
                f"Expected a sequence of images (an ImageSet or a list of (H, W, 3) arrays); got one array of shape "
                f"{images.shape}. Wrap a single image as [image]."
            )
        if isinstance(images, (str, bytes, os.PathLike)) or not isinstance(images, Iterable):
            raise DataError(
                f"Expected a sequence of images (an ImageSet or a list of arrays); got {type(images).__name__}."
            )
        out = [as_rgb_image(im, name=f"image {i}") for i, im in enumerate(images)]
    if not out:
        raise DataError("No images: give at least one.")
    for i, im in enumerate(out):
        if min(im.shape[:2]) < min_size:
            raise DataError(f"image {i} has shape {im.shape}; these features need at least {min_size} x {min_size} "
                            "pixels.")
    return out


# --------------------------------------------------------------------------- the set


@dataclass(eq=False)
class ImageSet:
    """Images of objects, each with the object's label and optionally its view.

    Parameters
    ----------
    images : list of ndarray of shape (H, W, 3)
        Float RGB in [0, 1]; anything :func:`as_rgb_image` accepts is converted.
    labels : sequence of str
        The object (concept) each image shows; converted to ``str``.
    views : sequence of str, optional
        Viewpoint identifier of each image (``"045-090"`` for ETH-80).
    categories : sequence of str, optional
        Category of each image's object (``"cow"`` for ETH-80's ``cow3``).
    paths : sequence of path or None, optional
        File each image was read from (None for generated images).
    name : str
    skipped : list of SkippedFile
        Files ``on_error="skip"`` left out (empty otherwise).

    Examples
    --------
    >>> import numpy as np
    >>> s = ImageSet([np.zeros((8, 8)), np.ones((8, 8, 3))], ["a", "b"])
    >>> len(s), s.classes, s[0].shape
    (2, ('a', 'b'), (8, 8, 3))
    """

    images: list[np.ndarray]
    labels: list[str]
    views: list[str] | None = None
    categories: list[str] | None = None
    paths: list[Path | None] | None = None
    name: str = ""
    skipped: list[SkippedFile] = field(default_factory=list)

    def __post_init__(self) -> None:
        if isinstance(self.images, np.ndarray) and self.images.ndim == 4:
            self.images = list(self.images)
        self.images = [as_rgb_image(im, name=f"image {i}") for i, im in enumerate(self.images)]
        n = len(self.images)
        self.labels = self._strings(self.labels, "labels", n)
        if self.views is not None:
            self.views = self._strings(self.views, "views", n)
        if self.categories is not None:
            self.categories = self._strings(self.categories, "categories", n)
        if self.paths is not None:
            paths = list(self.paths)
            if len(paths) != n:
                raise DataError(f"{len(paths)} paths for {n} images.")
            self.paths = [None if p is None else Path(p) for p in paths]
        self.skipped = list(self.skipped)

    @staticmethod
    def _strings(values: Any, what: str, n: int) -> list[str]:
        if isinstance(values, str):
            raise DataError(f"{what} must be a sequence of strings, one per image; got a single string {values!r}.")
        vals = list(values)
        if len(vals) != n:
            raise DataError(f"{len(vals)} {what} for {n} images; give one per image.")
        return [str(v) for v in vals]

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, i: int) -> np.ndarray:
        return self.images[i]

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter(self.images)

    def __repr__(self) -> str:
        return (f"ImageSet(name={self.name!r}, n_images={len(self)}, n_classes={len(self.classes)}, "
                f"views={'yes' if self.views is not None else 'no'}, skipped={len(self.skipped)})")

    @property
    def classes(self) -> tuple[str, ...]:
        """Sorted set of labels."""
        return tuple(sorted(set(self.labels)))

    @property
    def label_ids(self) -> np.ndarray:
        """Index of each image's label in :attr:`classes`, shape (n_images,), int."""
        col = {c: j for j, c in enumerate(self.classes)}
        return np.array([col[l] for l in self.labels], dtype=np.int64)

    def label_matrix(self, classes: Sequence[str] | None = None) -> np.ndarray:
        """Binary label matrix, shape (n_images, n_classes); column j is ``classes[j]``.

        Labels not among ``classes`` give an all-zero row (so a subset can be asked for).
        """
        cls = list(self.classes if classes is None else classes)
        if len(set(cls)) != len(cls):
            raise ParameterError(f"classes must not repeat; got {cls}.")
        col = {c: j for j, c in enumerate(cls)}
        Y = np.zeros((len(self), len(cls)))
        for i, l in enumerate(self.labels):
            j = col.get(l)
            if j is not None:
                Y[i, j] = 1.0
        return Y

    def subset(self, indices_or_mask: Iterable[int] | np.ndarray) -> ImageSet:
        """An image set holding the images at the given indices, or where a boolean mask is True."""
        idx = check_subset_indices(indices_or_mask, len(self))
        sel = [int(i) for i in idx]

        def pick(xs):
            return None if xs is None else [xs[i] for i in sel]

        return ImageSet([self.images[i] for i in sel], pick(self.labels), pick(self.views), pick(self.categories),
                        pick(self.paths), self.name, [])


# --------------------------------------------------------------------------- reading


def _check_on_error(on_error: str) -> None:
    if on_error not in ("raise", "skip"):
        raise ParameterError(f"on_error must be 'raise' or 'skip'; got {on_error!r}.")


def _report_skipped(skipped: list[SkippedFile], what: str) -> None:
    for k in skipped:  # each file in the log, as the audio loaders do; one warning for them all
        logging.getLogger(__name__).warning("skipped %s: %s", k.file, k.reason)
    if skipped:
        warnings.warn(
            f"{len(skipped)} file(s) of {what} could not be read and were skipped (see image_set.skipped); "
            f"first: {skipped[0].reason}",
            RuntimeWarning,
            stacklevel=3,
        )


def load_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read one image file as float RGB (H, W, 3) in [0, 1] (``imageio``; see :func:`as_rgb_image`).

    Raises
    ------
    DataFormatError
        If the file is missing (a folder, a link to nothing), empty, corrupt, not an image,
        or not a single still image of a supported shape; the message names the file.
    """
    import imageio.v3 as iio

    path = Path(path)
    if not path.is_file():
        if path.is_dir():
            raise DataFormatError(f"{path} is a folder, not an image file.")
        if path.is_symlink():
            raise DataFormatError(f"{path} links to {os.readlink(path)}, which does not exist.")
        raise DataFormatError(f"Image file {path} not found.")
    if path.stat().st_size == 0:
        raise DataFormatError(f"Image file {path} is empty (0 bytes).")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # imageio's legacy plugins, tried on bad files
            arr = iio.imread(path)
    except Exception as exc:  # imageio/Pillow raise OSError, ValueError, SyntaxError, ... on bad files
        raise DataFormatError(f"Cannot read image file {path}: {type(exc).__name__}: {exc}") from exc
    try:
        return as_rgb_image(arr, name=f"image file {path}")
    except DataError as exc:
        raise DataFormatError(str(exc)) from exc




def load_image_folder(
    root: str | os.PathLike[str],
    *,
    on_error: str = "raise",
    name: str | None = None,
) -> ImageSet:
    """Load a folder in the generic image layout (``labels.csv`` with ``file,labels[,view][,category]``).

    Parameters
    ----------
    root : path-like
        The folder holding ``labels.csv``.
    on_error : {"raise", "skip"}
        ``"raise"``: a bad row or a missing, corrupt or unreadable image raises
        :class:`DataFormatError` naming the file. ``"skip"``: those images are left out
        and listed in ``image_set.skipped``; a :class:`RuntimeWarning` says how many. A
        ``labels.csv`` that ends early (its last row cut short) raises, or loses that row
        with a :class:`~mmconcepts.errors.DataWarning` counting the rows read.
    name : str, optional
        Set name (default: the folder's name).

    Returns
    -------
    ImageSet
        Images in the order of ``labels.csv``; ``views`` (``categories``) is set when the
        table has a ``view`` (``category``) column.
    """
    _check_on_error(on_error)
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Image folder not found: {root}")
    labels_path = root / LABELS_FILE
    if not labels_path.exists():
        raise DataFormatError(
            f"{root} has no {LABELS_FILE}; the generic image layout needs one with columns file,labels (and "
            "optionally view and category)."
        )
    header, rows = read_labels_csv(labels_path, layout="generic image", optional=("view", "category"),
                                   on_error=on_error)
    has_view, has_cat = "view" in header, "category" in header
    images, labels, views, cats = [], [], [], []
    paths: list[Path | None] = []
    skipped: list[SkippedFile] = []
    for line, row in rows:
        where = f"{labels_path}, line {line}"
        rel = row.get("file", "")
        try:
            if not rel:
                raise DataFormatError(f"{where}: empty 'file' cell.")
            label = split_labels(row.get("labels", ""))
            if len(label) != 1:
                raise DataFormatError(f"{where}: {len(label)} labels for {rel!r} ({row.get('labels', '')!r}); the "
                                      "generic image layout takes one label per image.")
            path = root / rel
            if not path.is_file():
                raise DataFormatError(f"Image file {path} not found ({where}).")
            images.append(load_image(path))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedFile(str(root / rel), str(exc)))
            continue
        labels.append(label[0])
        views.append(row.get("view", ""))
        cats.append(row.get("category", ""))
        paths.append(path)
    _report_skipped(skipped, str(root))
    return ImageSet(images, labels, views if has_view else None, cats if has_cat else None, paths,
                    name if name is not None else root.name, skipped)


def load_eth80(
    root: str | os.PathLike[str],
    *,
    categories: Sequence[str] | None = None,
    instances: Sequence[int] | None = None,
    on_error: str = "raise",
) -> ImageSet:
    """Load ETH-80 images (Leibe and Schiele, 2003) named ``<category><instance>-<tilt>-<pan>.png``.

    Parameters
    ----------
    root : path-like
        Folder holding the PNG files, directly or in sub-folders.
    categories : sequence of str, optional
        Keep only these categories (default: all found).
    instances : sequence of int, optional
        Keep only these instance numbers (default: all found).
    on_error : {"raise", "skip"}
        As in :func:`load_image_folder`.

    Returns
    -------
    ImageSet
        Sorted by category, instance, tilt, pan. ``labels`` are objects (``"cow3"``),
        ``categories`` their category (``"cow"``), ``views`` ``"<tilt>-<pan>"``.
    """
    _check_on_error(on_error)
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"ETH-80 folder not found: {root}")
    if categories is not None:
        if isinstance(categories, str):
            categories = [categories]
        categories = [str(c).lower() for c in categories]
    if instances is not None:
        if isinstance(instances, (numbers.Integral, np.integer)):
            instances = [int(instances)]
        bad = [i for i in instances if isinstance(i, bool) or not isinstance(i, (numbers.Integral, np.integer))]
        if bad:
            raise ParameterError(f"instances must be ints; got {bad!r}.")
        instances = [int(i) for i in instances]
    found = []
    for p in root.rglob("*"):
        parsed = parse_eth80_name(p.name)
        if parsed:  # a folder or a link to nothing named like an image is kept: reading it raises (or skips) it
            cat, inst, tilt, pan = parsed
            found.append((cat, inst, int(tilt), int(pan), tilt, pan, p))
    if not found:
        raise DataFormatError(f"No ETH-80 image (<category><instance>-<tilt>-<pan>.png) found in {root}.")
    present = sorted({f[0] for f in found})
    if categories is not None:
        unknown = sorted(set(categories) - set(present))
        if unknown:
            raise ParameterError(f"Unknown ETH-80 categor(y/ies) {unknown}; {root} holds {present}.")
        found = [f for f in found if f[0] in categories]
    if instances is not None:
        have = sorted({f[1] for f in found})
        unknown_ids = sorted(set(instances) - set(have))
        if unknown_ids:
            raise ParameterError(f"Unknown ETH-80 instance number(s) {unknown_ids}; the selection holds {have}.")
        found = [f for f in found if f[1] in instances]
    found.sort(key=lambda f: f[:4] + (str(f[6]),))
    images, labels, views, cats = [], [], [], []
    paths: list[Path | None] = []
    skipped: list[SkippedFile] = []
    for cat, inst, _, _, tilt, pan, p in found:
        try:
            images.append(load_image(p))
        except DataFormatError as exc:
            if on_error == "raise":
                raise
            skipped.append(SkippedFile(str(p), str(exc)))
            continue
        labels.append(f"{cat}{inst}")
        cats.append(cat)
        views.append(f"{tilt}-{pan}")
        paths.append(p)
    _report_skipped(skipped, str(root))
    return ImageSet(images, labels, views, cats, paths, "eth80", skipped)


_MAT5_ITEMSIZE = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8, 16: 1, 17: 2, 18: 4}
_MAT5_NUMERIC_CLASSES = set(range(6, 16))  # mxDOUBLE .. mxUINT64
_MAT5_MAX_INFLATED = 1 << 30  # 1 GiB: COIL-20 at 128 x 128 is 190 MB


def _check_mat5(path: Path) -> None:
    """Check the structure of a MATLAB 5 (``-v6``/``-v7``) file before :func:`scipy.io.loadmat` reads it.

    scipy's compiled reader trusts the sizes a file declares, and a damaged file (a flipped
    byte in a matrix's dimensions) crashes the interpreter with SIGSEGV or SIGBUS instead of
    raising. This walks the data elements (inflating compressed ones up to 1 GiB) and checks
    that every element fits in its container and that the data of every numeric matrix has
    exactly the bytes its dimensions call for; the contents of cells, structs and objects are
    left to scipy. Files in other versions (v4, v7.3/HDF5) are left to scipy.

    Raises
    ------
    DataFormatError
        Naming the file and what does not fit.
    """
    import struct
    import zlib

    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFormatError(f"Cannot read {path}: {exc}.") from exc
    if len(raw) < 128 or raw[126:128] not in (b"IM", b"MI"):
        return  # not a MATLAB 5 file: scipy reads v4 files or says what it is
    e = "<" if raw[126:128] == b"IM" else ">"

    def bad(msg: str) -> DataFormatError:
        return DataFormatError(f"{path}: damaged MATLAB file ({msg}).")

    def elements(buf: bytes, start: int, end: int, depth: int):
        pos = start
        while pos < end:
            if pos + 8 > end:
                raise bad(f"an element tag is cut at byte {pos}")
            u1, u2 = struct.unpack_from(e + "II", buf, pos)
            if u1 >> 16:  # small data element: type and size in one word, 4 bytes of data
                dtype, nbytes, data = u1 & 0xFFFF, u1 >> 16, pos + 4
                if nbytes > 4:
                    raise bad(f"a small element at byte {pos} declares {nbytes} bytes")
                nxt = pos + 8
            else:
                dtype, nbytes, data = u1, u2, pos + 8
                nxt = data + nbytes + ((-nbytes) % 8 if dtype != 15 else 0)
                if data + nbytes > end:
                    raise bad(f"an element at byte {pos} declares {nbytes} bytes, {end - data} are left")
            yield dtype, buf, data, nbytes
            pos = min(nxt, end) if depth == 0 else nxt

    def matrix(buf: bytes, data: int, nbytes: int, depth: int) -> None:
        subs = list(elements(buf, data, data + nbytes, depth + 1))
        if len(subs) < 3 or subs[0][0] != 6 or subs[0][3] < 8 or subs[1][0] != 5:
            raise bad("a matrix without array flags, dimensions and name")
        flags = struct.unpack_from(e + "I", subs[0][1], subs[0][2])[0]
        cls, complex_ = flags & 0xFF, bool(flags & 0x0800)
        if subs[1][3] % 4 or subs[1][3] < 8:
            raise bad("matrix dimensions of a wrong size")
        dims = struct.unpack_from(e + f"{subs[1][3] // 4}i", subs[1][1], subs[1][2])
        if min(dims) < 0:
            raise bad(f"negative matrix dimensions {dims}")
        if cls in _MAT5_NUMERIC_CLASSES:
            parts = subs[3:5] if complex_ else subs[3:4]
            if len(parts) != (2 if complex_ else 1):
                raise bad(f"a numeric matrix of dimensions {dims} without its data")
            n = int(np.prod(dims, dtype=np.float64))
            for dtype, _, _, size in parts:
                if dtype not in _MAT5_ITEMSIZE or size != n * _MAT5_ITEMSIZE[dtype]:
                    raise bad(f"a matrix of dimensions {dims} holds {size} bytes of type {dtype}")

    def walk(buf: bytes, start: int, end: int, depth: int) -> None:
        if depth > 3:
            raise bad("compressed elements nested too deeply")
        for dtype, b, data, nbytes in elements(buf, start, end, depth):
            if dtype == 15:  # miCOMPRESSED: one element, deflated
                z = zlib.decompressobj()
                try:
                    inner = z.decompress(b[data:data + nbytes], _MAT5_MAX_INFLATED)
                except zlib.error as exc:
                    raise bad(f"a compressed element does not inflate: {exc}") from None
                if z.unconsumed_tail:
                    raise bad("a compressed element inflates beyond 1 GiB")
                walk(inner, 0, len(inner), depth + 1)
            elif dtype == 14:
                matrix(b, data, nbytes, depth)

    walk(raw, 128, len(raw), 0)


def load_coil20(path: str | os.PathLike[str]) -> ImageSet:
    """Load COIL-20 (Nene, Nayar and Murase, 1996) from ``COIL20.mat`` (``fea``, ``gnd``).

    Parameters
    ----------
    path : path-like
        The ``.mat`` file, or a folder holding ``COIL20.mat``.

    Returns
    -------
    ImageSet
        Grayscale images promoted to RGB, upright (rows are stored column by column,
        module docstring); ``labels`` are object ids as strings (``"1"`` .. ``"20"``),
        ``views`` the index of the image among its object's images (``"0"`` .. ``"71"``,
        5 degrees of turntable rotation apart).

    Raises
    ------
    DataFormatError
        If the file is not a readable MATLAB file with a square-image ``fea`` matrix and a
        matching ``gnd`` vector.
    """
    import scipy.io

    path = Path(path)
    if path.is_dir():
        path = path / "COIL20.mat"
    if not path.is_file():
        raise FileNotFoundError(f"COIL-20 file not found: {path}")
    _check_mat5(path)  # scipy's reader crashes the process (SIGSEGV/SIGBUS) on some damaged files
    try:
        mat = scipy.io.loadmat(path)
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, MatReadError on bad files
        raise DataFormatError(f"Cannot read {path} as a MATLAB file: {type(exc).__name__}: {exc}") from exc
    for key in ("fea", "gnd"):
        if key not in mat:
            found = sorted(k for k in mat if not k.startswith("__"))
            raise DataFormatError(f"{path} has no {key!r} variable; found {found}.")
    fea = np.asarray(mat["fea"])
    gnd = np.asarray(mat["gnd"]).ravel()
    if fea.ndim != 2 or not np.issubdtype(fea.dtype, np.number):
        raise DataFormatError(f"{path}: 'fea' must be a 2-D numeric matrix; got shape {fea.shape}, dtype {fea.dtype}.")
    side = math.isqrt(fea.shape[1])
    if side * side != fea.shape[1] or side < 2:
        raise DataFormatError(f"{path}: 'fea' rows have {fea.shape[1]} values, not a square image of at least "
                              "2 x 2 pixels.")
    if fea.shape[0] == 0:
        raise DataFormatError(f"{path}: 'fea' holds no image (0 rows).")
    if gnd.shape[0] != fea.shape[0]:
        raise DataFormatError(f"{path}: {gnd.shape[0]} 'gnd' labels for {fea.shape[0]} 'fea' rows.")
    if not (np.issubdtype(gnd.dtype, np.number) and np.isfinite(gnd).all() and np.all(gnd == np.round(gnd))
            and np.abs(gnd).max() < 2**53):
        raise DataFormatError(f"{path}: 'gnd' must hold integer object ids; got dtype {gnd.dtype} "
                              f"(first values {gnd[:3].tolist()!r}).")
    fea = fea.astype(np.float64)
    if not np.isfinite(fea).all():
        raise DataFormatError(f"{path}: 'fea' holds NaN or infinite values.")
    if fea.min() < 0 or fea.max() > 1:
        if fea.min() >= 0 and fea.max() <= 255:
            fea = fea / 255.0  # some distributions store 8-bit values
        else:
            raise DataFormatError(f"{path}: 'fea' values lie in [{fea.min():g}, {fea.max():g}]; expected [0, 1].")
    imgs = fea.reshape(-1, side, side).transpose(0, 2, 1)  # column-major rows: see module docstring
    labels = [str(int(g)) for g in gnd]
    counters: dict[str, int] = {}
    views = []
    for l in labels:
        views.append(str(counters.get(l, 0)))
        counters[l] = counters.get(l, 0) + 1
    return ImageSet(list(imgs), labels, views, None, [path] * len(labels), "coil20")
