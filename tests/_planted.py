"""A planted pickle: a file whose unpickling runs code, for the tests that a reader of the package never unpickles."""

from __future__ import annotations

import pickle
from pathlib import Path


class Plant:
    """An object whose unpickling touches ``marker`` (what a planted file could do: run any code)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (Path(self.marker),))


def planted_pickle(marker: Path) -> bytes:
    """A pickled :class:`Plant` of ``marker``, checked to work: loading it touches ``marker`` (removed again)."""
    planted = pickle.dumps(Plant(marker))
    pickle.loads(planted)
    assert Path(marker).exists(), "the plant does not run code"
    Path(marker).unlink()
    return planted
