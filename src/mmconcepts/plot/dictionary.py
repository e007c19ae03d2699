"""A learnt dictionary, modality by modality: each atom shown through the examples that express it most.

An atom of a multimodal dictionary is a vector of features (histograms of colours, of
acoustic co-occurrences, of joint angles and velocities) that no one can read directly. What
a person can look at is the examples whose internal representation is most made of the
atom (:func:`~mmconcepts.multimodal.top_examples`): their images, the spectrograms of their
utterances, the angle curves or the stick figures of their motions. Every function here draws
one row per atom and its ``n`` top examples left to right, titles each example with its index
(its label when ``y`` is given) and the share of its representation the atom holds, and titles
each row with the label the atom aligns with most
(:func:`~mmconcepts.multimodal.atom_label_association`) when ``y`` is given.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure, FigureBase

from .._validation import InstanceOf, Interval, validate_params
from ..errors import DataError, ParameterError
from ..motion import SKELETON_CHAINS, MotionDataset, MotionRecording, normalize_marker_name, skeleton_bones
from ..sound import MFCCConfig, log_mel_spectrogram
from ..vision import ImageSet, as_rgb_image
from ._layout import FIGURE, N_EXAMPLES, check_figsize, dictionary_grid

__all__ = [
    "plot_dictionary_images",
    "plot_dictionary_motion",
    "plot_dictionary_skeletons",
    "plot_dictionary_sounds",
]

_GRID_CONSTRAINTS: dict[str, list] = {"n": N_EXAMPLES, "fig": FIGURE}

def plot_dictionary_images(W: Any, images: Any, *, n: int = 4, y: Any = None, atoms: Any = None,
                           fig: FigureBase | None = None, figsize: tuple[float, float] | None = None) -> Figure:
    """Each atom's top images, as thumbnails.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients of the examples (``model.transform(X)``).
    images : ImageSet or sequence of n_samples arrays of shape (H, W), (H, W, 3) or (H, W, 4)
        The image of each example (any size; an array whose first axis indexes the examples
        works too), read by :func:`~mmconcepts.vision.as_rgb_image`: integers scaled by their
        type's maximum, floats in [0, 1].
    n : int, default=4
        Images per atom (at most ``n_samples``).
    y : array-like of shape (n_samples,), optional
        The label of each example, shown in the titles.
    atoms : sequence of int, optional
        The atoms to show, one row each (default: all).
    fig : Figure or SubFigure, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Axes ``(r, k)`` (row-major, ``n`` per row) shows ``images[top_examples(W, n)[atoms[r], k]]``.

    Raises
    ------
    DataError
        If ``W`` is not a nonnegative matrix, ``images`` or ``y`` do not have one item per row of
        ``W``, ``n`` exceeds ``n_samples``, or a shown image is not an image.
    ParameterError
        If an option has a value that is not allowed.
    """
    validate_params({"n": n, "fig": fig}, _GRID_CONSTRAINTS, owner="plot_dictionary_images")
    if isinstance(images, ImageSet):
        images = images.images

    def draw(ax: Axes, i: int) -> None:
        ax.imshow(as_rgb_image(images[i], name=f"image {i}"))
        ax.set_xticks([])
        ax.set_yticks([])

    return dictionary_grid(W, images, n=n, atoms=atoms, y=y, fig=fig,
                           figsize=check_figsize(figsize, "plot_dictionary_images"), cell=(1.4, 1.5),
                           owner="plot_dictionary_images", draw=draw)


_SOUND_CONSTRAINTS: dict[str, list] = {**_GRID_CONSTRAINTS, "sr": [Interval("int", 1), None],
                                       "config": [InstanceOf(MFCCConfig), None]}


def _sound_config(sr: int | None, config: MFCCConfig | None) -> MFCCConfig:
    if config is None:
        return MFCCConfig() if sr is None else MFCCConfig(sr=sr)
    if sr is not None and sr != config.sr:
        raise ParameterError(f"plot_dictionary_sounds: sr={sr} and config.sr={config.sr} disagree. Fix: give one of "
                             "them (config=MFCCConfig(sr=...) sets the rest of the front end too).")
    return config


def plot_dictionary_sounds(W: Any, sounds: Any, *, sr: int | None = None, config: MFCCConfig | None = None,
                           n: int = 3, y: Any = None, atoms: Any = None, fig: FigureBase | None = None,
                           figsize: tuple[float, float] | None = None) -> Figure:
    """The spectrograms of each atom's top utterances.

    A waveform is shown as its log (dB) mel spectrogram, the MFCC front end of the thesis
    before its DCT (:func:`~mmconcepts.sound.log_mel_spectrogram`, Thesis section 5.2.3); a
    2-D array is taken as already computed frame features (a spectrogram, MFCC) and shown as
    it is.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients of the examples (``model.transform(X)``).
    sounds : sequence of n_samples arrays of shape (n_audio_samples,) or (n_frames, n_bands)
        The utterance of each example: mono audio at ``sr``, or frame features, one row per
        frame (``config.hop_ms`` apart).
    sr : int, optional
        Sample rate of the audio (Hz); default 16000, or ``config.sr``.
    config : MFCCConfig, optional
        The front end (window, hop, mel bands, dynamic range); default ``MFCCConfig(sr=sr)``.
    n : int, default=3
        Utterances per atom (at most ``n_samples``).
    y : array-like of shape (n_samples,), optional
        The label of each example, shown in the titles.
    atoms : sequence of int, optional
        The atoms to show, one row each (default: all).
    fig : Figure or SubFigure, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Axes ``(r, k)`` (row-major, ``n`` per row) shows the spectrogram of
        ``sounds[top_examples(W, n)[atoms[r], k]]``: its image array is the ``(n_bands,
        n_frames)`` transpose (frequency up, time in seconds to the right).

    Raises
    ------
    DataError
        If ``W`` is not a nonnegative matrix, ``sounds`` or ``y`` do not have one item per row of
        ``W``, ``n`` exceeds ``n_samples``, or a shown utterance is neither mono audio (longer
        than one analysis frame) nor a finite 2-D array.
    ParameterError
        If an option has a value that is not allowed, or ``sr`` and ``config.sr`` disagree.
    MissingExtraError
        If a waveform is given and librosa (the ``audio`` extra) is not installed.
    """
    validate_params({"n": n, "fig": fig, "sr": sr, "config": config}, _SOUND_CONSTRAINTS,
                    owner="plot_dictionary_sounds")
    config = _sound_config(sr, config)
    hop = config.hop_length / config.sr

    def draw(ax: Axes, i: int) -> None:
        s = np.asarray(sounds[i])
        if s.ndim == 2:
            if not (np.issubdtype(s.dtype, np.number) and np.isfinite(s).all() and s.size):
                raise DataError(f"plot_dictionary_sounds: sound {i} must be finite frame features; got "
                                f"{s.dtype} values of shape {s.shape}.")
            S = s
        else:
            S = log_mel_spectrogram(s, config)
        ax.imshow(S.T, origin="lower", aspect="auto", cmap="magma", interpolation="nearest",
                  extent=(0.0, S.shape[0] * hop, 0, S.shape[1]))
        ax.set_yticks([])

    return dictionary_grid(W, sounds, n=n, atoms=atoms, y=y, fig=fig,
                           figsize=check_figsize(figsize, "plot_dictionary_sounds"), cell=(2.0, 1.3),
                           owner="plot_dictionary_sounds", draw=draw)


_MOTION_CONSTRAINTS: dict[str, list] = {**_GRID_CONSTRAINTS,
                                        "frame_rate": [Interval("real", 0, None, closed="neither"), None]}


def _columns(dofs: Any, n_dof: int, i: int) -> np.ndarray:
    if dofs is None:
        return np.arange(n_dof)
    d = np.asarray(dofs)
    if d.ndim != 1 or d.size == 0 or not np.issubdtype(d.dtype, np.integer):
        raise ParameterError(f"plot_dictionary_motion: dofs must be a non-empty sequence of column indices; got "
                             f"{dofs!r}.")
    if d.min() < 0 or d.max() >= n_dof:
        raise ParameterError(f"plot_dictionary_motion: dofs must be in [0, {n_dof}) (trajectory {i} has {n_dof} "
                             f"columns); got {d.tolist()}.")
    return d


def plot_dictionary_motion(W: Any, trajectories: Any, *, dofs: Sequence[int] | None = None,
                           names: Sequence[str] | None = None, frame_rate: float | None = None, n: int = 3,
                           y: Any = None, atoms: Any = None, fig: FigureBase | None = None,
                           figsize: tuple[float, float] | None = None) -> Figure:
    """The joint-angle curves of each atom's top motions.

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients of the examples (``model.transform(X)``).
    trajectories : sequence of n_samples arrays of shape (n_frames, n_dof)
        The motion of each example, one row per frame: the angles of
        :func:`~mmconcepts.motion.joint_angles` (radians), or any degrees of freedom.
    dofs : sequence of int, optional
        The columns to draw (default: all); e.g. ``mmconcepts.motion.ARM_COLUMNS`` (the arms' angles).
    names : sequence of str, optional
        The name of each column of the trajectories (e.g.
        :data:`~mmconcepts.motion.JOINT_ANGLE_NAMES`), for the figure's legend.
    frame_rate : float, optional
        Frames per second: time in seconds along x (default: frame numbers).
    n : int, default=3
        Motions per atom (at most ``n_samples``).
    y : array-like of shape (n_samples,), optional
        The label of each example, shown in the titles.
    atoms : sequence of int, optional
        The atoms to show, one row each (default: all).
    fig : Figure or SubFigure, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Axes ``(r, k)`` (row-major, ``n`` per row) has one line per column ``d`` of ``dofs``,
        the curve ``trajectories[i][:, d]`` of ``i = top_examples(W, n)[atoms[r], k]``; a column
        has the same colour in every panel.

    Raises
    ------
    DataError
        If ``W`` is not a nonnegative matrix, ``trajectories`` or ``y`` do not have one item per
        row of ``W``, ``n`` exceeds ``n_samples``, or a shown trajectory is not a 2-D array of
        numbers (NaN, a lost frame, leaves a gap).
    ParameterError
        If an option has a value that is not allowed (``dofs`` beyond the columns, ``names``
        of the wrong length).
    """
    validate_params({"n": n, "fig": fig, "frame_rate": frame_rate}, _MOTION_CONSTRAINTS,
                    owner="plot_dictionary_motion")
    from matplotlib import colormaps

    legend: dict[str, Any] = {}

    def draw(ax: Axes, i: int) -> None:
        x = np.asarray(trajectories[i])
        if x.ndim != 2 or x.shape[0] == 0 or not np.issubdtype(x.dtype, np.number):
            raise DataError(f"plot_dictionary_motion: trajectory {i} must be a 2-D array (n_frames, n_dof) of "
                            f"numbers; got {x.dtype} values of shape {x.shape}.")
        cols = _columns(dofs, x.shape[1], i)
        if names is not None and len(names) != x.shape[1]:
            raise ParameterError(f"plot_dictionary_motion: names must name the {x.shape[1]} columns of the "
                                 f"trajectories; got {len(names)} names.")
        t = np.arange(x.shape[0]) / (frame_rate or 1.0)
        cmap = colormaps["tab10" if len(cols) <= 10 else "tab20"]
        for c, d in enumerate(cols):
            (line,) = ax.plot(t, x[:, d], lw=0.9, color=cmap(c % cmap.N))
            legend.setdefault(str(names[d]) if names is not None else f"dof {d}", line)

    fig_out = dictionary_grid(W, trajectories, n=n, atoms=atoms, y=y, fig=fig,
                              figsize=check_figsize(figsize, "plot_dictionary_motion"), cell=(2.0, 1.3),
                              owner="plot_dictionary_motion", draw=draw)
    holder = fig if fig is not None else fig_out
    if names is not None:
        holder.legend(list(legend.values()), list(legend), loc="outside right upper", fontsize=6)
    holder.supxlabel("time (s)" if frame_rate else "frame", fontsize=8)
    return fig_out


_SKELETON_CONSTRAINTS: dict[str, list] = {**_GRID_CONSTRAINTS, "n_poses": [Interval("int", 1)]}


def _bone_indices(bones: Any, recording: MotionRecording, i: int) -> list[tuple[int, int]]:
    if bones is None:
        found = skeleton_bones(recording.marker_names)
        if not found:
            raise DataError(f"plot_dictionary_skeletons: recording {i} has none of the markers of SKELETON_CHAINS "
                            f"({list(recording.marker_names)[:6]}...). Fix: pass bones=[(marker, marker), ...].")
        return found
    try:
        pairs = [(str(a), str(b)) for a, b in bones]
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"plot_dictionary_skeletons: bones must be pairs of marker names; got {bones!r}.") \
            from exc
    return [(recording.marker_index(a), recording.marker_index(b)) for a, b in pairs]


def plot_dictionary_skeletons(W: Any, recordings: Any, *, bones: Sequence[tuple[str, str]] | None = None,
                              plane: tuple[int, int] = (0, 1), n_poses: int = 4, n: int = 3, y: Any = None,
                              atoms: Any = None, fig: FigureBase | None = None,
                              figsize: tuple[float, float] | None = None) -> Figure:
    """Stick figures of each atom's top motions: a few poses of each, from light (early) to dark (late).

    Parameters
    ----------
    W : array-like of shape (n_samples, n_components)
        Nonnegative internal coefficients of the examples (``model.transform(X)``).
    recordings : MotionDataset or sequence of n_samples MotionRecording
        The motion of each example, as marker positions.
    bones : sequence of (str, str), optional
        The bones to draw, as pairs of marker names (default: :func:`skeleton_bones` of
        each recording, which knows the OpenNI and MSR Action3D skeletons).
    plane : (int, int), default=(0, 1)
        The coordinates of the positions drawn along x and y: (0, 1) is a front view of
        data whose second coordinate points up (OpenNI, MSR Action3D as loaded).
    n_poses : int, default=4
        Poses per motion, at frames evenly spaced from the first to the last.
    n : int, default=3
        Motions per atom (at most ``n_samples``).
    y : array-like of shape (n_samples,), optional
        The label of each example, shown in the titles.
    atoms : sequence of int, optional
        The atoms to show, one row each (default: all).
    fig : Figure or SubFigure, optional
        Where to draw (default: a new figure).
    figsize : (float, float), optional
        Size of the new figure (inches).

    Returns
    -------
    Figure
        Axes ``(r, k)`` (row-major, ``n`` per row) has one line collection per pose, for the
        frames ``f = round(linspace(0, n_frames - 1, n_poses))``: its segment for bone ``(a, b)``
        joins ``positions[f, a, plane]`` and ``positions[f, b, plane]``.

    Raises
    ------
    DataError
        If ``W`` is not a nonnegative matrix, ``recordings`` or ``y`` do not have one item per
        row of ``W``, ``n`` exceeds ``n_samples``, an item is not a MotionRecording, or a bone
        names a marker a recording lacks.
    ParameterError
        If an option has a value that is not allowed.
    """
    validate_params({"n": n, "fig": fig, "n_poses": n_poses}, _SKELETON_CONSTRAINTS,
                    owner="plot_dictionary_skeletons")
    if isinstance(recordings, MotionDataset):
        recordings = recordings.recordings
    try:
        h, v = (int(c) for c in plane)
        ok = {h, v} <= {0, 1, 2} and h != v and not isinstance(plane, (str, bytes))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ParameterError(f"plot_dictionary_skeletons: plane must be two different coordinates among 0, 1, 2 "
                             f"(x, y, z); got {plane!r}. Fix: (0, 1) for a front view with y up.")
    from matplotlib import colormaps

    shades = colormaps["Blues"](np.linspace(0.35, 1.0, n_poses))

    def draw(ax: Axes, i: int) -> None:
        rec = recordings[i]
        if not isinstance(rec, MotionRecording):
            raise DataError(f"plot_dictionary_skeletons: recording {i} must be a MotionRecording; got "
                            f"{type(rec).__name__}.")
        pairs = _bone_indices(bones, rec, i)
        P = rec.positions[:, :, [h, v]]
        a, b = np.array(pairs).T
        for shade, f in zip(shades, np.round(np.linspace(0, P.shape[0] - 1, n_poses)).astype(int)):
            segments = list(np.stack([P[f, a], P[f, b]], axis=1))  # one (2, 2) array per bone
            ax.add_collection(LineCollection(segments, colors=[shade], linewidths=1.2, capstyle="round"))
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xticks([])
        ax.set_yticks([])

    return dictionary_grid(W, recordings, n=n, atoms=atoms, y=y, fig=fig,
                           figsize=check_figsize(figsize, "plot_dictionary_skeletons"), cell=(1.4, 1.8),
                           owner="plot_dictionary_skeletons", draw=draw)
