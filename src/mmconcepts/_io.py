"""Small file helpers shared by the data modules (internal)."""

from __future__ import annotations

import csv
import os
import shutil
import tempfile
from pathlib import Path

from .errors import DataFormatError

__all__ = ["read_csv_rows", "replace_dir"]


def read_csv_rows(path: Path) -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    """Header and ``(line number, row)`` pairs of a CSV file, cells stripped.

    Raises
    ------
    DataFormatError
        If the file cannot be read or decoded, naming it.
    """
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            reader = csv.DictReader(f)
            header = [h.strip() for h in (reader.fieldnames or [])]
            reader.fieldnames = header
            rows = [(reader.line_num, {k: (v or "").strip() for k, v in row.items() if k is not None})
                    for row in reader]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFormatError(f"Cannot read {path}: {exc}.") from exc
    return header, rows


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
