"""Figures of learnt concepts (matplotlib): what each atom is, what it means, when it is active.

A dictionary learnt by :class:`~mmconcepts.multimodal.MultimodalNMF` holds atoms that no one
reads directly; these functions show them through the examples and labels they go with.
Each returns a :class:`matplotlib.figure.Figure` and takes its options by keyword. A figure
a function makes is made directly, not through ``pyplot`` (safe in threads, no window left
open): save it with ``fig.savefig``, show it in a notebook as a cell's value, or hand it to
pyplot with ``plt.figure(fig)`` (matplotlib >= 3.11). To draw into a figure of your own
(made by ``pyplot``, or a panel of a larger figure), pass ``ax=`` to the functions that draw
one panel and ``fig=`` (a Figure or SubFigure) to the grids; the figure returned is then the
one that holds it.

A learnt dictionary, modality by modality
    plot_dictionary_images (each atom's top images), plot_dictionary_sounds (the
    spectrograms of its top utterances), plot_dictionary_motion (the joint-angle curves of
    its top motions), plot_dictionary_skeletons (stick figures of them, with the bones of
    :func:`mmconcepts.motion.skeleton_bones`).
What the atoms mean and how well they match
    plot_atom_labels (the atom x label association), plot_confusion (the confusion matrix of
    a cross-modal recognition, section 6.6.1), plot_activation_timeline (each concept's
    activation along sliding windows, section 6.6.2, Fig. 6.9).

``W`` is always the internal coefficients of the examples, ``(n_samples, n_components)``
(``model.transform(X)``; the thesis' H, transposed): an example "expresses" an atom by the
share of its coefficients the atom holds (:func:`~mmconcepts.multimodal.top_examples`).
"""

from __future__ import annotations

from .analysis import plot_activation_timeline, plot_atom_labels, plot_confusion
from .dictionary import (
    plot_dictionary_images,
    plot_dictionary_motion,
    plot_dictionary_skeletons,
    plot_dictionary_sounds,
)

__all__ = [
    "plot_activation_timeline",
    "plot_atom_labels",
    "plot_confusion",
    "plot_dictionary_images",
    "plot_dictionary_motion",
    "plot_dictionary_skeletons",
    "plot_dictionary_sounds",
]
