"""What the figures of :mod:`mmconcepts.plot` share (internal): where they draw, and the grid of a dictionary.

Figures are :class:`matplotlib.figure.Figure` objects made directly, never through
``pyplot``'s global state, so drawing is safe in threads and leaves no window open.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure, FigureBase

from .._validation import InstanceOf, Interval, check_nonnegative_matrix
from ..errors import DataError, ParameterError
from ..multimodal import atom_label_association, top_examples

__all__ = ["AXES", "FIGURE", "N_EXAMPLES", "dictionary_grid", "figure_of", "check_figsize", "check_length",
           "single_axes"]

#: The constraint of an ``ax`` parameter: an Axes to draw on, or None for a new figure.
AXES: list[Any] = [InstanceOf(Axes, description="a matplotlib Axes"), None]
#: The constraint of a ``fig`` parameter: a Figure or SubFigure to draw in, or None for a new figure.
FIGURE: list[Any] = [InstanceOf(FigureBase, description="a matplotlib Figure or SubFigure"), None]
#: The constraint of the number of examples shown per atom.
N_EXAMPLES: list[Any] = [Interval("int", 1)]


def figure_of(artist: Axes | FigureBase) -> Figure:
    """The top-level :class:`~matplotlib.figure.Figure` that holds an Axes or a SubFigure."""
    fig: Any = artist
    while not isinstance(fig, Figure):
        fig = fig.figure
    return fig


def check_figsize(figsize: Any, owner: str) -> tuple[float, float] | None:
    """``figsize`` as two positive finite inches (width, height), or None."""
    if figsize is None:
        return None
    try:
        w, h = (float(v) for v in figsize)
    except (TypeError, ValueError):
        w = h = float("nan")
    if isinstance(figsize, (str, bytes)) or not (np.isfinite([w, h]).all() and w > 0 and h > 0):
        raise ParameterError(f"{owner}: figsize must be two positive numbers (width, height) in inches; got "
                             f"{figsize!r}. Fix: e.g. figsize=(8, 6).")
    return w, h


def single_axes(ax: Axes | None, figsize: tuple[float, float] | None, default: tuple[float, float]) -> Axes:
    """``ax``, or the one Axes of a new constrained-layout figure of ``figsize`` (else ``default``)."""
    if ax is not None:
        return ax
    return Figure(figsize=figsize or default, layout="constrained").subplots()


def check_length(items: Any, n_samples: int, name: str, owner: str) -> Sequence[Any]:
    """``items`` as a sequence with one item per row of ``W``."""
    if isinstance(items, (str, bytes)) or not hasattr(items, "__len__") or not hasattr(items, "__getitem__"):
        raise DataError(f"{owner}: {name} must be a sequence with one item per example (row of W); got "
                        f"{type(items).__name__}.")
    if len(items) != n_samples:
        raise DataError(f"{owner}: expected one item of {name} per row of W ({n_samples}); got {len(items)}. "
                        f"Fix: pass the {name} of the examples W was computed from, in the same order.")
    return items


def _atoms(atoms: Any, n_components: int, owner: str) -> list[int]:
    if atoms is None:
        return list(range(n_components))
    a = np.asarray(atoms)
    if a.ndim != 1 or a.size == 0 or not (np.issubdtype(a.dtype, np.integer) or a.dtype == object and all(
            isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in a)):
        raise ParameterError(f"{owner}: atoms must be a non-empty sequence of atom indices (ints); got {atoms!r}.")
    out = [int(v) for v in a]
    bad = [v for v in out if not 0 <= v < n_components]
    if bad:
        raise ParameterError(f"{owner}: atoms must be in [0, {n_components}) (W has {n_components} columns); got "
                             f"{bad}.")
    return out


def _atom_titles(W: np.ndarray, y: Any, atoms: list[int]) -> list[str]:
    """"atom j", and with labels the label the atom aligns with most and its share of the atom's activation."""
    if y is None:
        return [f"atom {j}" for j in atoms]
    A, labels = atom_label_association(W, y)
    return [f"atom {j}\n{labels[A[j].argmax()]} ({A[j].max():.0%})" for j in atoms]


def dictionary_grid(W: Any, items: Any, *, n: int, atoms: Any, y: Any, fig: FigureBase | None,
                    figsize: tuple[float, float] | None, cell: tuple[float, float], owner: str,
                    draw: Callable[[Axes, int], None]) -> Figure:
    """One row per atom, its ``n`` top examples (:func:`~mmconcepts.multimodal.top_examples`) left to right.

    ``draw(ax, i)`` draws example ``i`` (an index into ``items``) on ``ax``. Each panel is titled with the
    example's index, its label when ``y`` is given, and the share of its representation the atom holds; each
    row with the atom's index and, when ``y`` is given, the label it aligns with most
    (:func:`~mmconcepts.multimodal.atom_label_association`).
    """
    W = np.asarray(check_nonnegative_matrix(W, "W", accept_sparse=False), dtype=np.float64)
    items = check_length(items, W.shape[0], "the examples", owner)
    if y is not None:
        y = np.asarray(check_length(y, W.shape[0], "y", owner))
    shown = _atoms(atoms, W.shape[1], owner)
    top = top_examples(W, n)
    share = W / np.maximum(W.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    if fig is None:
        fig = Figure(figsize=figsize or (cell[0] * n + 1.0, cell[1] * len(shown) + 0.3), layout="constrained")
    axes = fig.subplots(len(shown), n, squeeze=False)
    for row, (j, title) in enumerate(zip(shown, _atom_titles(W, y, shown))):
        for k in range(n):
            i = int(top[j, k])
            ax = axes[row, k]
            draw(ax, i)
            what = f"#{i}" if y is None else f"#{i} {y[i]}"
            ax.set_title(f"{what} ({share[i, j]:.0%})", fontsize=7)
            ax.tick_params(labelsize=6)
        axes[row, 0].set_ylabel(title, fontsize=8)
    return figure_of(fig)
