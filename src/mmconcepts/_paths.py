"""Where data, caches and results live (internal).

Resolution order for the data/cache folder: an explicit argument, else the
``MMCONCEPTS_DATA`` environment variable, else ``~/.cache/mmconcepts``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_home", "DEFAULT_RESULTS_DIR"]

#: Folder where ``mmconcepts run`` and ``mmconcepts reproduce`` write results by default.
DEFAULT_RESULTS_DIR = Path("results")


def data_home(path: str | os.PathLike[str] | None = None, *, create: bool = True) -> Path:
    """Return the folder for generated data and caches.

    Parameters
    ----------
    path : str or path-like, optional
        An explicit folder; wins over everything else.
    create : bool, default=True
        Create the folder if it does not exist.
    """
    if path is not None:
        home = Path(path)
    elif os.environ.get("MMCONCEPTS_DATA"):
        home = Path(os.environ["MMCONCEPTS_DATA"])
    else:
        home = Path.home() / ".cache" / "mmconcepts"
    home = home.expanduser()
    if create:
        home.mkdir(parents=True, exist_ok=True)
    return home
