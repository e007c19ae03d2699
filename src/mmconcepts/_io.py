"""Small file helpers shared by the package (internal): the one atomic writer (:func:`atomic_path` for a file,
:func:`atomic_dir` for a folder), folder locks, CSV tables."""

from __future__ import annotations

import contextlib
import csv
import io
import logging
import os
import re
import shutil
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path

from .errors import DataFormatError, DataWarning, ParameterError

__all__ = ["check_output_dir", "atomic_dir", "atomic_path", "atomic_write", "folder_lock", "leftover_dirs",
           "read_csv_rows", "read_labels_csv", "split_labels", "LABELS_HEADER", "LABEL_SEPARATOR", "OLD_LABEL_COLUMNS",
           "replace_dir"]


def read_csv_rows(path: Path, *, on_error: str = "raise") -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    """Header and ``(line number, row)`` pairs of a CSV file, cells stripped.

    A table that ends early, cut short while it was written or copied, is never read in part
    silently. It ends early when a quoted cell is still open at the end of the file, or when
    its last row has fewer cells than the header and no line break after it (a complete last
    row without a line break is read). A row cut after a whole cell cannot be told from a
    complete one.

    Parameters
    ----------
    path : Path
    on_error : {"raise", "skip"}, default="raise"
        What a table that ends early does: ``"raise"`` a :class:`DataFormatError`;
        ``"skip"`` leaves its last row out, with a :class:`~mmconcepts.errors.DataWarning`
        saying how many rows were read.

    Raises
    ------
    DataFormatError
        If the file cannot be read or decoded, or ends early (``on_error="raise"``), naming it.
    """
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            text = f.read()
        reader = csv.DictReader(io.StringIO(text, newline=""))
        header = [h.strip() for h in (reader.fieldnames or [])]
        reader.fieldnames = header
        rows, last_cells = [], 0
        for row in reader:
            last_cells = sum(v is not None for k, v in row.items() if k is not None)  # missing cells are None
            rows.append((reader.line_num, {k: (v or "").strip() for k, v in row.items() if k is not None}))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFormatError(f"Cannot read {path}: {exc}.") from exc
    if rows:
        why = _cut_short(text, last_cells, len(header))
        if why:
            line = rows[-1][0]
            if on_error == "raise":
                raise DataFormatError(
                    f"{path} ends early: its last row, line {line}, {why}, as a file cut short while written or "
                    f"copied; {len(rows) - 1} complete row(s) before it. Write or copy the file again (or load with "
                    f"on_error='skip' to keep the complete rows)."
                )
            warnings.warn(f"{path} ended early: its last row, line {line}, {why}; it is left out; "
                          f"{len(rows) - 1} row(s) read.", DataWarning, stacklevel=4)
            rows = rows[:-1]
    return header, rows


def _cut_short(text: str, last_cells: int, n_columns: int) -> str:
    """How the end of a CSV text shows it was cut short ("" when it does not)."""
    try:  # the strict reader stops where the lenient one reads an open quoted cell to the end of the file
        for _ in csv.reader(io.StringIO(text, newline=""), strict=True):
            pass
    except csv.Error as exc:
        if "unexpected end of data" in str(exc):
            return "has a quoted cell still open at the end of the file"
    if not text.endswith(("\n", "\r")) and last_cells < n_columns:
        return f"has {last_cells} of the {n_columns} cells of the header and no line break after it"
    return ""


#: The columns every generic layout's ``labels.csv`` starts with: the file (relative to the folder) and its labels.
LABELS_HEADER = ("file", "labels")

#: What separates several labels in a ``labels`` cell.
LABEL_SEPARATOR = ";"

#: Old spellings of the ``labels`` column, still read (with a :class:`FutureWarning`).
OLD_LABEL_COLUMNS = ("label",)


def read_labels_csv(path: Path, *, layout: str, required: tuple[str, ...] = (),
                    optional: tuple[str, ...] = (),
                    on_error: str = "raise") -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    """Header and ``(line number, row)`` pairs of a generic layout's ``labels.csv``.

    The header is ``file,labels`` (:data:`LABELS_HEADER`; several labels in a cell separated by
    ``;``, :func:`split_labels`), then the layout's own columns. A table written with an old
    spelling of ``labels`` (:data:`OLD_LABEL_COLUMNS`: ``label``) is read as if it had the new
    one, with one :class:`FutureWarning` per table read, naming the file and the new header.

    Parameters
    ----------
    path : Path
        The ``labels.csv`` file.
    layout : str
        The layout's name, for messages (``"generic image"``).
    required, optional : tuple of str
        The layout's columns after ``file,labels`` that must be there, and those it also reads;
        named in messages.
    on_error : {"raise", "skip"}, default="raise"
        What a table that ends early does (:func:`read_csv_rows`).

    Returns
    -------
    header : list of str
        The columns, ``labels`` under its new spelling.
    rows : list of (int, dict of str to str)
        Line number and cells of each row, cells stripped; the labels under ``"labels"``.

    Raises
    ------
    DataFormatError
        If the file cannot be read or ends early (``on_error="raise"``), or a column of
        ``file``, ``labels`` and ``required`` is missing (the message names the file, the
        header found and the one expected).
    """
    header, rows = read_csv_rows(path, on_error=on_error)
    columns = [*LABELS_HEADER, *required]
    expected = ",".join(columns) + "".join(f"[,{c}]" for c in optional)
    old = next((c for c in OLD_LABEL_COLUMNS if c in header), None)
    if "labels" not in header and old is not None:
        import warnings

        warnings.warn(f"{path}: the column {old!r} is the old spelling of 'labels'; it is read for now, but a "
                      f"future version will not read it. Write the header {expected} (several labels in a cell "
                      f"separated by '{LABEL_SEPARATOR}').", FutureWarning, stacklevel=3)
        header = ["labels" if h == old else h for h in header]
        rows = [(line, {("labels" if k == old else k): v for k, v in row.items()}) for line, row in rows]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataFormatError(f"{path}: missing column(s) {missing}; the {layout} layout's labels.csv has the header "
                              f"{expected} (labels separated by '{LABEL_SEPARATOR}'); found {header}.")
    return header, rows


def split_labels(cell: str) -> tuple[str, ...]:
    """The labels of a ``labels`` cell: split at ``;`` (:data:`LABEL_SEPARATOR`), stripped, empty ones dropped."""
    return tuple(part.strip() for part in cell.split(LABEL_SEPARATOR) if part.strip())


def replace_dir(tmp: Path, root: Path) -> None:
    """Move the finished folder ``tmp`` to ``root``, replacing any old ``root`` as late as possible.

    The old folder is first renamed aside, so ``root`` is never a half-written mix.
    """
    if root.exists():
        trash = Path(tempfile.mkdtemp(prefix=f".{root.name}.old-", dir=root.parent))
        os.replace(root, trash / "old")
        os.replace(tmp, root)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(tmp, root)


#: How the temporary folders of :func:`atomic_dir` end.
BUILDING = ".building"


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary empty folder beside ``path`` to fill; it replaces ``path`` when the block ends well.

    The folder counterpart of :func:`atomic_path`: the folder ``.<name>.<random>.building``
    is made beside ``path`` and, when the block ends without an exception, moved to ``path``
    by :func:`replace_dir` (an old ``path`` is renamed aside first, then removed), so
    ``path`` is never a half-written mix. A failure (any exception, ``KeyboardInterrupt``
    included) removes the temporary folder and leaves any old ``path`` as it was. A process
    killed meanwhile leaves the temporary folder behind; :func:`leftover_dirs` finds it. The
    folder gets the usual permissions (``0o777`` less the umask).

    Examples
    --------
    >>> with atomic_dir(folder / "corpus") as tmp:   # doctest: +SKIP
    ...     (tmp / "labels.csv").write_text(table)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=BUILDING, dir=path.parent))
    try:
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes 0700
        yield tmp
        replace_dir(tmp, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)  # nothing left after a rename


def leftover_dirs(path: str | os.PathLike[str]) -> list[Path]:
    """The temporary folders :func:`atomic_dir` made for ``path`` and never moved into place.

    Only those of ``path`` itself (not of a sibling whose name starts the same). A caller
    that holds the lock under which ``path`` is built knows they belong to dead processes.
    """
    path = Path(path)
    pattern = re.compile(rf"\.{re.escape(path.name)}\.[a-z0-9_]{{8}}{re.escape(BUILDING)}")
    try:
        with os.scandir(path.parent) as it:
            return sorted(Path(e.path) for e in it if pattern.fullmatch(e.name) and e.is_dir(follow_symlinks=False))
    except OSError:  # no parent folder yet
        return []


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; it replaces ``path`` when the block ends well.

    The one way the package writes a file atomically: a reader never sees a half-written
    ``path``, and a failure (any exception, ``KeyboardInterrupt`` included) removes the
    temporary file and leaves any old ``path`` as it was. The file gets the usual
    permissions (``0o666`` less the umask). ``suffix`` ends the temporary name (give the
    real extension when the writer chooses the format from it, e.g. ``".tmp.wav"``).

    Examples
    --------
    >>> with atomic_path(folder / "x.npz", suffix=".tmp.npz") as tmp:   # doctest: +SKIP
    ...     np.savez(tmp, a=a)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write(path: str | os.PathLike[str], data: bytes | str) -> None:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically, flushed to disk."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike[str], name: str = ".lock") -> Iterator[None]:
    """Hold an exclusive lock on the file ``folder/name`` for the block (made, with ``folder``, if absent).

    For work on a folder that several processes may do at once and that must not
    interleave, such as reading a results folder's records and writing its report: a
    second process waits at the start of its block until the first leaves its own. The
    lock is advisory (``fcntl.flock``; ``msvcrt.locking`` on Windows; none on a file system
    that does not support it), is released when the block ends or the process dies, and
    the lock file is left in place (empty; its modification time is when it was last
    taken). A process that has to wait logs it (logger ``mmconcepts``, level INFO).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / name, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows
            import msvcrt

            while True:
                try:
                    msvcrt.locking(fd, msvcrt.LK_LOCK, 1)  # type: ignore[attr-defined,unused-ignore]
                    break
                except OSError:  # gave up after 10 s: keep waiting
                    continue
        else:
            try:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:  # held by another process: say so, then wait for it
                    logging.getLogger("mmconcepts").info("waiting for %s (held by another process)", folder / name)
                    fcntl.flock(fd, fcntl.LOCK_EX)
            except OSError:  # pragma: no cover - a file system without locks: go on unlocked
                pass
        if os.utime in os.supports_fd:  # held from now: a clean-up by age (cache clear --older-than) spares it
            with contextlib.suppress(OSError):
                os.utime(fd)
        yield
    finally:
        os.close(fd)  # releases the lock


def check_output_dir(output: str | os.PathLike[str], *, room: int = 0) -> Path:
    """Check, before any work, that results can be written to the folder ``output``.

    The folder need not exist yet (it is created when the first result is written), but the
    nearest existing folder on its path must be a folder in which a file can be created, on a
    disk with at least ``room`` bytes free (not checked where the free space cannot be told).

    Raises
    ------
    ParameterError
        If ``output`` is empty, names a file (or a path through a file), cannot be written, or
        its disk has less than ``room`` bytes free.
    """
    if not str(output).strip():
        raise ParameterError("output must name a results folder; got an empty name. Pass e.g. --output results.")
    path = Path(output)
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        where = "is" if probe == path else f"cannot be made: {probe} is"
        raise ParameterError(f"output folder {path} {where} a file, not a folder. Pass --output a folder.")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as exc:
        raise ParameterError(
            f"output folder {path} cannot be written ({exc.strerror or exc} in {probe}). "
            "Pass --output a folder you can write to."
        ) from exc
    try:
        free = shutil.disk_usage(probe).free if room > 0 else None
    except OSError:  # cannot tell (some network file systems): the writes themselves will say
        free = None
    if free is not None and free < room:
        raise ParameterError(
            f"output folder {path} has not enough free space to write results: {free:,} bytes free on its disk, at "
            f"least {room:,} needed. Fix: make room on that disk, or pass --output a folder on another disk."
        )
    return path
