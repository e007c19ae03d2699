"""Where data, caches and results live (internal).

Resolution order for the data/cache folder: an explicit argument, else the
``MMCONCEPTS_DATA`` environment variable, else ``$XDG_CACHE_HOME/mmconcepts`` when
``XDG_CACHE_HOME`` is set (an absolute path, as the XDG base directory specification asks),
else ``~/.cache/mmconcepts``.
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
    elif os.path.isabs(os.environ.get("XDG_CACHE_HOME", "")):
        home = Path(os.environ["XDG_CACHE_HOME"]) / "mmconcepts"
    else:
        home = Path.home() / ".cache" / "mmconcepts"
    home = home.expanduser()
    if create:
        home.mkdir(parents=True, exist_ok=True)
    return home
