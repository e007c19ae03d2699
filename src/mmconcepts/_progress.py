"""Progress bars of the package's long loops (internal): what ``verbose=`` turns on.

The feature extractors and data generators take ``verbose`` (a bool, or an int level as in
scikit-learn: any value above 0 shows the bar) and draw a tqdm bar on stderr while it is
true, whatever stderr is: a library call shows what it was asked to show. The experiments
ask only when their run is interactive (:attr:`mmconcepts.engine.RunContext.verbose`), and
draw their own loops through :meth:`~mmconcepts.engine.RunContext.progress`, which ends here.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import Any, TypeVar

__all__ = ["QUIET_ENV", "progress", "progress_chunks"]

#: Environment variable that, set to ``1``, silences the one-line notice a process prints when it
#: compiles the package's numerical kernels (:mod:`mmconcepts._jit`). ``mmconcepts -q`` sets it, so
#: that the worker processes it starts inherit it.
QUIET_ENV = "MMCONCEPTS_QUIET"

_T = TypeVar("_T")


def progress(iterable: Iterable[_T], *, verbose: bool | int, total: int | None = None, desc: str | None = None,
             unit: str = "it") -> Iterable[_T]:
    """``iterable`` in a tqdm bar on stderr when ``verbose``; the bar is removed when the loop ends.

    Parameters
    ----------
    iterable : iterable
    verbose : bool or int
        Draw the bar (any value above 0); otherwise ``iterable`` is returned as it is.
    total : int, optional
        Number of items, when ``len(iterable)`` is not available.
    desc : str, optional
        Label shown before the bar.
    unit : str, default="it"
        What an item is ("image", "utterance", ...).
    """
    if not verbose:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=False)


def progress_chunks(results: Iterable[_T], sizes: Sequence[int], *, verbose: bool | int, desc: str | None = None,
                    unit: str = "it") -> Iterator[_T]:
    """Yield ``results``, one per chunk of work, advancing a bar over the chunks' items (``sizes``).

    For work done in chunks (one joblib task per chunk of images or utterances): the bar
    counts items, ``sum(sizes)`` in all, and moves by ``sizes[i]`` when the result of chunk
    ``i`` comes.
    """
    if not verbose:
        yield from results
        return
    from tqdm.auto import tqdm

    bar: Any = tqdm(total=int(sum(sizes)), desc=desc, unit=unit, leave=False)
    try:
        for size, result in zip(sizes, results):
            bar.update(size)
            yield result
    finally:
        bar.close()
