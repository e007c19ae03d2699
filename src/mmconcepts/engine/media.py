"""The files of a run's concept explorer (:mod:`.explorer`): clips, thumbnails and motions written beside its figures.

:func:`write_explorer` writes them to ``<output>/<id>/explorer/`` (one folder, built beside and
moved into place, so a record never lists half-written files) and returns the record's
``explorer`` entry (:func:`render_explorer` gives the entry and the files' bytes, for the runner,
which writes a run's files all at once): clips as mono 16-bit PCM WAV (the standard library's :mod:`wave`),
thumbnails as PNG (Pillow, which matplotlib needs), motions as animated SVG (SMIL, plain text:
a stick figure frame by frame, or angle curves under a moving cursor), every path relative to
the results folder.
"""

from __future__ import annotations

import io
import wave
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_dir
from .explorer import AudioClip, Explorer, MotionClip, Thumbnail

__all__ = ["EXPLORER_DIR", "render_explorer", "write_explorer", "explorer_files", "wav_bytes", "png_bytes", "svg_text"]

#: The folder beside a record's figures that holds its explorer's files.
EXPLORER_DIR = "explorer"

_SVG = 'xmlns="http://www.w3.org/2000/svg"'


def wav_bytes(clip: AudioClip) -> bytes:
    """The clip as a mono 16-bit PCM WAV file (samples clipped to [-1, 1], times 32768, rounded)."""
    levels = np.clip(np.round(np.clip(clip.samples, -1.0, 1.0) * 32768.0), -32768, 32767).astype("<i2")
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(clip.sample_rate)
        w.writeframes(levels.tobytes())
    return buf.getvalue()


def png_bytes(thumbnail: Thumbnail) -> bytes:
    """The thumbnail as a PNG file."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(thumbnail.pixels).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def _fit(points: np.ndarray, width: float, height: float, margin: float, *,
         uniform: bool) -> tuple[np.ndarray, float, float]:
    """Scale and shift 2-D points (y up) into a ``width`` x ``height`` box (y down), centred; ``uniform``: one
    scale for both axes (a figure keeps its proportions), else each axis fills the box."""
    lo, hi = np.nanmin(points, axis=0), np.nanmax(points, axis=0)
    span = np.maximum(hi - lo, 1e-9)
    scale = np.array([(width - 2 * margin) / span[0], (height - 2 * margin) / span[1]])
    if uniform:
        scale[:] = scale.min()
    x = margin + (points[..., 0] - lo[0]) * scale[0] + (width - 2 * margin - span[0] * scale[0]) / 2
    y = height - margin - (points[..., 1] - lo[1]) * scale[1] - (height - 2 * margin - span[1] * scale[1]) / 2
    return np.stack([x, y], axis=-1), float(width), float(height)


def _n(v: float) -> str:
    return str(int(round(v)))


def svg_text(motion: MotionClip) -> str:
    """The motion as an animated SVG (SMIL): a stick figure frame by frame, or curves under a moving cursor."""
    dur = f"{motion.seconds:.3g}s"
    if motion.positions is not None:
        xy, w, h = _fit(motion.positions[..., :2].reshape(-1, 2), 200.0, 200.0, 10.0, uniform=True)
        xy = xy.reshape(motion.positions.shape[:2] + (2,))

        def path(frame: np.ndarray) -> str:
            parts = [f"M{_n(frame[a, 0])} {_n(frame[a, 1])}L{_n(frame[b, 0])} {_n(frame[b, 1])}"
                     for a, b in motion.bones if np.isfinite(frame[[a, b]]).all()]
            return "".join(parts) or "M0 0"

        frames = [path(f) for f in xy]
        body = (f'<path d="{frames[0]}" fill="none" stroke="#1f5fbf" stroke-width="4" stroke-linecap="round">'
                f'<animate attributeName="d" values="{";".join(frames)}" dur="{dur}" calcMode="discrete" '
                'repeatCount="indefinite"/></path>')
    else:
        assert motion.curves is not None
        n = motion.curves.shape[0]
        t = np.repeat(np.linspace(0.0, 1.0, n)[:, None], motion.curves.shape[1], axis=1)
        pts, w, h = _fit(np.stack([t, motion.curves], axis=-1).reshape(-1, 2), 320.0, 160.0, 8.0, uniform=False)
        pts = pts.reshape(n, -1, 2)
        lines = "".join(f'<polyline points="{" ".join(f"{_n(x)},{_n(y)}" for x, y in pts[:, j])}" fill="none" '
                        f'stroke="hsl({int(360 * j / pts.shape[1])},60%,40%)" stroke-width="1.5"/>'
                        for j in range(pts.shape[1]))
        x0, x1 = _n(pts[0, 0, 0]), _n(pts[-1, 0, 0])
        body = lines + (f'<line x1="{x0}" y1="0" x2="{x0}" y2="{_n(h)}" stroke="#000" stroke-width="2">'
                        f'<animate attributeName="x1" from="{x0}" to="{x1}" dur="{dur}" repeatCount="indefinite"/>'
                        f'<animate attributeName="x2" from="{x0}" to="{x1}" dur="{dur}" repeatCount="indefinite"/>'
                        "</line>")
    return (f'<svg {_SVG} viewBox="0 0 {_n(w)} {_n(h)}" width="{_n(w * 0.6)}" height="{_n(h * 0.6)}">'
            f'<rect width="100%" height="100%" fill="#fff"/>{body}</svg>\n')


def render_explorer(explorer: Explorer | None, fig_dir_name: str) -> tuple[dict[str, Any], dict[str, bytes]]:
    """The explorer's record entry and its files, as :func:`write_explorer` writes them to ``<fig_dir>/explorer/``.

    Returns
    -------
    entry : dict
        As :func:`write_explorer` returns it (``{}`` without an explorer).
    files : dict of str to bytes
        Each file's content by its name in the explorer folder (``card-1-clip-1.wav``).
    """
    if explorer is None:
        return {}, {}
    rel = f"{fig_dir_name}/{EXPLORER_DIR}"
    cards, files = [], {}
    for c, card in enumerate(explorer.cards, start=1):
        entry: dict[str, Any] = {"title": card.title, "note": card.note,
                                 "labels": [{"label": lab, "share": share} for lab, share in card.labels],
                                 "clips": [], "images": [], "motions": []}
        for m, clip in enumerate(card.clips, start=1):
            name = f"card-{c}-clip-{m}.wav"
            files[name] = wav_bytes(clip)
            entry["clips"].append({"path": f"{rel}/{name}", "seconds": round(clip.seconds, 4),
                                   "sample_rate": clip.sample_rate, "caption": clip.caption})
        for m, image in enumerate(card.images, start=1):
            name = f"card-{c}-image-{m}.png"
            files[name] = png_bytes(image)
            entry["images"].append({"path": f"{rel}/{name}", "width": int(image.pixels.shape[1]),
                                    "height": int(image.pixels.shape[0]), "caption": image.caption})
        for m, motion in enumerate(card.motions, start=1):
            name = f"card-{c}-motion-{m}.svg"
            files[name] = svg_text(motion).encode("utf-8")
            entry["motions"].append({"path": f"{rel}/{name}", "frames": motion.n_frames,
                                     "seconds": round(motion.seconds, 4), "caption": motion.caption})
        cards.append(entry)
    return {"note": explorer.note, "cards": cards}, files


def write_explorer(explorer: Explorer | None, fig_dir: Path) -> dict[str, Any]:
    """Write the explorer's files to ``<fig_dir>/explorer/`` (one folder, atomically); return its record entry.

    Returns
    -------
    dict
        ``{}`` without an explorer (nothing written), else ``{"note", "cards"}``: per card its
        ``title``, ``note``, ``labels`` (``[{"label", "share"}]``), ``clips`` (``[{"path",
        "seconds", "sample_rate", "caption"}]``), ``images`` (``[{"path", "width", "height",
        "caption"}]``) and ``motions`` (``[{"path", "frames", "seconds", "caption"}]``), every path
        relative to the results folder (``<id>/explorer/card-1-clip-1.wav``).
    """
    entry, files = render_explorer(explorer, fig_dir.name)
    if explorer is not None:
        with atomic_dir(fig_dir / EXPLORER_DIR) as tmp:
            for name, data in files.items():
                (tmp / name).write_bytes(data)
    return entry


def explorer_files(entry: Any) -> list[str]:
    """The relative paths an explorer entry of a record lists (none for a malformed entry)."""
    out = []
    cards = entry.get("cards") if isinstance(entry, dict) else None
    for card in cards if isinstance(cards, list) else []:
        for kind in ("clips", "images", "motions"):
            items = card.get(kind) if isinstance(card, dict) else None
            out += [str(i["path"]) for i in items or [] if isinstance(i, dict) and isinstance(i.get("path"), str)]
    return out
