"""What the learnt concepts mean and how well they match: label association, confusion, activation over time.

- :func:`plot_atom_labels`: which labels each atom aligns with
  (:func:`~mmconcepts.multimodal.atom_label_association`), the learner having never seen them
  (Thesis section 6.6.3 reads the atoms through the concepts in the same spirit, Fig. 6.10);
- :func:`plot_confusion`: the confusion matrix of a cross-modal recognition (Thesis section
  6.6.1: the concept of a test example in one modality taken from its nearest reference
  examples in another, :func:`~mmconcepts.multimodal.crossmodal_distances`);
- :func:`plot_activation_timeline`: the activation of each concept along a stream cut into
  sliding windows, with the moments each concept is actually present (Thesis section 6.6.2,
  Fig. 6.9).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from .._validation import Options, validate_params
from ..errors import DataError, ParameterError
from ..multimodal import atom_label_association
from ._layout import AXES, check_figsize, check_length, figure_of, single_axes

__all__ = ["plot_activation_timeline", "plot_atom_labels", "plot_confusion"]

_ATOM_LABELS_CONSTRAINTS: dict[str, list] = {"order": [Options("label", "atom")], "annotate": ["boolean"],
                                             "ax": AXES}


def plot_atom_labels(W: Any, y: Any, *, labels: Any = None, order: str = "label", annotate: bool = False,
                     ax: Axes | None = None, figsize: tuple[float, float] | None = None) -> Figure:
    """The atom x label association as a heat map: the labels each atom aligns with.

    Cell ``(j, c)`` is the share of atom ``j``'s activation that falls on the examples of
    label ``c`` (:func:`~mmconcepts.multimodal.atom_label_association`; each row sums to
    one). An atom learnt without labels that carries one concept has one bright cell.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients of the examples (``model.transform(X)``).
    y : array-like of shape (n_samples,)
        The label of each example.
    labels : array-like of shape (n_labels,), optional
        The labels, in the order of the columns (default: the sorted unique values of ``y``).
    order : {"label", "atom"}, default="label"
        Row order: ``"label"`` groups the atoms by the label of their largest share (then
        by that share, largest first), so a one-concept-per-atom dictionary shows a
        staircase; ``"atom"`` keeps the atoms' own order.
    annotate : bool, default=False
        Write each share in its cell.
    ax : Axes, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Its first image is the ``(n_components, n_labels)`` association, rows in the chosen
        order; the y tick labels name the atoms, the x tick labels the labels.

    Raises
    ------
    DataError
        If ``W`` is not a nonnegative matrix or ``y`` does not have one label per row of ``W``.
    ParameterError
        If an option has a value that is not allowed.
    """
    validate_params({"order": order, "annotate": annotate, "ax": ax}, _ATOM_LABELS_CONSTRAINTS,
                    owner="plot_atom_labels")
    A, labels = atom_label_association(W, y, labels=labels)
    rows = np.arange(A.shape[0])
    if order == "label":
        rows = np.lexsort((rows, -A.max(axis=1), A.argmax(axis=1)))
    ax = single_axes(ax, check_figsize(figsize, "plot_atom_labels"),
                     (1.2 + 0.4 * A.shape[1], 1.0 + 0.28 * A.shape[0]))
    image = ax.imshow(A[rows], vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto", interpolation="nearest")
    ax.set_xticks(np.arange(A.shape[1]), [str(v) for v in labels], rotation=45 if A.shape[1] > 6 else 0,
                  ha="right" if A.shape[1] > 6 else "center", fontsize=7)
    ax.set_yticks(np.arange(A.shape[0]), [f"atom {j}" for j in rows], fontsize=7)
    ax.set_xlabel("label")
    if annotate:
        for r, j in enumerate(rows):
            for c in range(A.shape[1]):
                ax.text(c, r, f"{A[j, c]:.2f}", ha="center", va="center", fontsize=6,
                        color="black" if A[j, c] > 0.5 else "white")
    figure_of(ax).colorbar(image, ax=ax, label="share of the atom's activation")
    return figure_of(ax)


_CONFUSION_CONSTRAINTS: dict[str, list] = {"normalize": [Options("true", "pred", "all"), None],
                                           "colorbar": ["boolean"], "ax": AXES}


def plot_confusion(y_true: Any, y_pred: Any, *, labels: Any = None, normalize: str | None = None,
                   colorbar: bool = True, title: str | None = None, ax: Axes | None = None,
                   figsize: tuple[float, float] | None = None) -> Figure:
    """The confusion matrix of a recognition, for instance of one modality from another.

    Counts (or shares, with ``normalize``) of the examples of each true label (rows) given
    each predicted label (columns), from :func:`sklearn.metrics.confusion_matrix`, drawn by
    :class:`sklearn.metrics.ConfusionMatrixDisplay`. For cross-modal recognition (Thesis
    section 6.6.1), the prediction of a test example is the label of its nearest reference
    example in the other modality: ``y_pred = y_ref[D.argmin(axis=1)]`` with ``D`` from
    :func:`~mmconcepts.multimodal.crossmodal_distances`.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,)
        True labels.
    y_pred : array-like of shape (n_samples,)
        Predicted labels.
    labels : array-like of shape (n_labels,), optional
        The labels, in the order of the rows and columns (default: the sorted labels found
        in ``y_true`` and ``y_pred``).
    normalize : {"true", "pred", "all"}, optional
        Divide by the row sums (each true label's recall on the diagonal), the column sums,
        or the total (default: counts).
    colorbar : bool, default=True
        Draw a colour bar.
    title : str, optional
        The title (default: the accuracy and the number of examples).
    ax : Axes, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Its first image is the ``(n_labels, n_labels)`` matrix ``sklearn.metrics.confusion_matrix(
        y_true, y_pred, labels=labels, normalize=normalize)``.

    Raises
    ------
    DataError
        If ``y_true`` and ``y_pred`` are not 1-D with one label per example each, or none of
        ``labels`` occurs in ``y_true``.
    ParameterError
        If an option has a value that is not allowed.
    """
    validate_params({"normalize": normalize, "colorbar": colorbar, "ax": ax}, _CONFUSION_CONSTRAINTS,
                    owner="plot_confusion")
    from sklearn.metrics import ConfusionMatrixDisplay, confusion_matrix

    y_true, y_pred = np.asarray(y_true), np.asarray(y_pred)
    if y_true.ndim != 1 or y_true.shape != y_pred.shape or y_true.size == 0:
        raise DataError(f"plot_confusion: expected y_true and y_pred of one shape (n_samples,), n_samples >= 1; "
                        f"got {y_true.shape} and {y_pred.shape}. Fix: pass one true and one predicted label per "
                        "example.")
    if labels is None:
        labels = np.unique(np.concatenate([y_true, y_pred]))
    try:
        C = confusion_matrix(y_true, y_pred, labels=labels, normalize=normalize)
    except ValueError as exc:  # no label of ``labels`` in y_true, mixed label types
        raise DataError(f"plot_confusion: {exc}. Fix: give labels that occur in y_true.") from exc
    ax = single_axes(ax, check_figsize(figsize, "plot_confusion"), (1.6 + 0.45 * len(labels), 1.2 + 0.4 * len(labels)))
    ConfusionMatrixDisplay(C, display_labels=[str(v) for v in labels]).plot(
        ax=ax, cmap="Blues", colorbar=colorbar, values_format=".2f" if normalize else "d",
        xticks_rotation=45 if len(labels) > 6 else "horizontal", text_kw={"fontsize": 7})
    if title is None:
        title = f"accuracy {np.mean(y_true == y_pred):.2f} (n = {y_true.size})"
    ax.set_title(title, fontsize=9)
    return figure_of(ax)


_TIMELINE_CONSTRAINTS: dict[str, list] = {"ylabel": [str], "ax": AXES}


def _check_activations(activations: Any) -> np.ndarray:
    try:
        A = np.asarray(activations, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"plot_activation_timeline: activations must be numbers ({exc}).") from exc
    if A.ndim != 2 or 0 in A.shape:
        raise DataError(f"plot_activation_timeline: expected activations of shape (n_windows, n_concepts), "
                        f"non-empty; got {A.shape}. Fix: one row per window, e.g. model.transform(windows).")
    if not np.isfinite(A).all():
        raise DataError("plot_activation_timeline: activations hold NaN or infinite values.")
    return A


def _check_segments(segments: Any, owner: str) -> list[tuple[float, float, Any]]:
    out = []
    for seg in segments:
        try:
            start, end, label = seg
            start, end = float(start), float(end)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{owner}: each segment must be (start, end, label); got {seg!r}.") from exc
        if not (np.isfinite([start, end]).all() and start <= end):
            raise DataError(f"{owner}: a segment needs finite start <= end; got {seg!r}.")
        out.append((start, end, label))
    return out


def plot_activation_timeline(activations: Any, *, times: Any = None, labels: Sequence[Any] | None = None,
                             segments: Any = None, ylabel: str = "activation", ax: Axes | None = None,
                             figsize: tuple[float, float] | None = None) -> Figure:
    """The activation of each concept along a stream cut into sliding windows (Thesis Fig. 6.9).

    One line per concept (a column of ``activations``: the coefficients of an atom, or a
    similarity to each concept's reference example, as the thesis draws it) against the
    windows' times, and a band of the concept's colour where the concept is actually present
    (the keyword being said), so one sees whether the right concept rises at the right moment.

    Parameters
    ----------
    activations : array-like of shape (n_windows, n_concepts)
        Row ``t``: the window's activation of each concept, e.g. ``model.transform(windows)``
        of a :class:`~mmconcepts.multimodal.MultimodalNMF`.
    times : array-like of shape (n_windows,), optional
        Where each window is, in seconds (its start, as Fig. 6.9, or its centre); default: the
        window numbers.
    labels : sequence of n_concepts, optional
        The concept of each column, for the legend and to colour the segments
        (default: ``"atom 0"``, ``"atom 1"``...).
    segments : sequence of (start, end, label), optional
        Where each concept is present, in the units of ``times``; a band in the colour of
        the column whose label is ``label`` (grey when no column has it).
    ylabel : str, default="activation"
        What the values are (e.g. "cosine similarity to the concept's image").
    ax : Axes, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Its axes hold ``n_concepts`` lines, line ``j`` being ``(times, activations[:, j])``, and
        one band (a polygon patch) per segment.

    Raises
    ------
    DataError
        If ``activations`` is not a finite 2-D array, ``times`` does not give one finite time
        per window, or a segment is not ``(start, end, label)`` with ``start <= end``.
    ParameterError
        If ``labels`` does not name every column, or another option is not allowed.
    """
    validate_params({"ylabel": ylabel, "ax": ax}, _TIMELINE_CONSTRAINTS, owner="plot_activation_timeline")
    owner = "plot_activation_timeline"
    A = _check_activations(activations)
    if times is None:
        t = np.arange(A.shape[0], dtype=np.float64)
    else:
        t = np.asarray(check_length(times, A.shape[0], "times", owner), dtype=np.float64)
        if t.ndim != 1 or not np.isfinite(t).all():
            raise DataError(f"{owner}: times must be {A.shape[0]} finite numbers; got shape {t.shape}.")
    if labels is None:
        names: list[Any] = [f"atom {j}" for j in range(A.shape[1])]
    else:
        names = list(labels)
        if len(names) != A.shape[1]:
            raise ParameterError(f"{owner}: labels must name the {A.shape[1]} columns of activations; got "
                                 f"{len(names)}.")
    segs = [] if segments is None else _check_segments(segments, owner)
    ax = single_axes(ax, check_figsize(figsize, owner), (9.0, 3.2))
    colours: dict[Any, Any] = {}
    for j, name in enumerate(names):
        (line,) = ax.plot(t, A[:, j], lw=1.2, label=str(name))
        colours.setdefault(name, line.get_color())
    for start, end, label in segs:
        ax.axvspan(start, end, color=colours.get(label, "0.6"), alpha=0.2, lw=0)
        ax.text((start + end) / 2, 1.0, str(label), transform=ax.get_xaxis_transform(), ha="center", va="bottom",
                fontsize=7, color=colours.get(label, "0.3"))
    ax.set_xlabel("window number" if times is None else "time (s)")
    ax.set_ylabel(ylabel)
    ax.set_xlim(t.min(), t.max() if t.max() > t.min() else t.min() + 1.0)
    ax.legend(fontsize=7, ncols=max(1, min(len(names), 8)), loc="upper left", bbox_to_anchor=(0.0, -0.18),
              frameon=False)
    return figure_of(ax)
