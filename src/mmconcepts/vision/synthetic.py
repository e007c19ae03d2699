"""Synthetic object images: many views of a few objects (the image modality of Thesis 6.5.3).

The thesis' robot images (frames from an iCub's RGB-D camera, segmented into
proto-objects) cannot be reached from here. This module draws objects and photographs
them from several viewpoints so that a fresh machine can run every image experiment; its
output goes through the generic image layout (:func:`write_image_folder`,
:func:`~mmconcepts.vision.load_image_folder`) like a user's own photos.

Objects. Each object has a shape from one of six parametric families (:data:`FAMILIES`,
the object's ``category``): ellipse, polygon (3-7 jittered sides), star (5-8 points),
blob (a circle with random low-frequency radial harmonics, fruit-like), box (a
superellipse) and composite (a body with one or two attached parts of another colour, like
a head, a handle or a stem). Every part has a colour and a texture (:data:`TEXTURES`:
plain, stripes, dots, checker, mottled) drawn in the object's own frame, so it turns with
the object. Objects are drawn independently: two objects may share a family, a colour or a
texture, as ETH-80's five apples do.

Views. A view turns the object in the image plane (uniform angle), foreshortens it along
a random axis (an out-of-plane tilt of up to 60 degrees), changes its scale and position
a little, swings its attached parts around the body (a crude parallax), and lights it
from a random direction (dome shading). All views of one object share a "session"
lighting (brightness gain, contrast, colour temperature), as ETH-80's views of one object
were photographed together; each photo adds its own small lighting change, a background
with a linear gradient, a few small distractor shapes behind the object, sensor noise,
and 8-bit quantisation.

How the values were chosen: measured on the 1640 ETH-80 images of
the ``eth80`` data set at 96x96 pixels (object = not the blue background), percentiles 5/50/95
(noise, gradient: 10/50/90); the generator's column gives its parameters and, in
brackets, the same statistics of its output (:func:`image_statistics`, 300 images):

==========================  ================================  =================================
quantity                    ETH-80 (96 x 96)                  generator
==========================  ================================  =================================
object area / image         8 % / 19 % / 44 %                 [10 % / 18 % / 39 %]
object bounding box side    47 / 67 / 76 px                   half-extent U(24, 40) px,
                                                              x lognormal(0, 0.1) per view
                                                              [43 / 58 / 79 px]
object centre               44-52 px (image centre 48)        N(0, 3 px) per axis [43-54 px]
object mean HSV S           0.03 / 0.30 / 0.55                S U(0.05, 0.6) [0.09 / 0.33 / 0.58]
object mean HSV V           0.48 / 0.68 / 0.84                V U(0.6, 1.0), dome shading
                                                              0.6-1.0 [0.43 / 0.64 / 0.88]
object mean RGB sd          0.11 / 0.13 / 0.15 (R / G / B)    uniform hue [0.17 / 0.14 / 0.17]
background V                0.51 / 0.64 / 0.78 (plain blue)   V U(0.45, 0.75), S U(0.1, 0.6),
                                                              one hue per data set
background V range          0.03 / 0.18 / 0.27 (corners)      linear gradient U(0.03, 0.27)
log brightness sd           0.049 within an object's views,   per view N(0, 0.05), per object
                            0.144 between objects             (session) N(0, 0.14)
log(R/B) sd (background)    0.067 within, 0.091 between       temperature t (R x (1+t),
                                                              B x (1-t)): N(0, 0.03) per view,
                                                              N(0, 0.045) per object
sensor noise sd             0.003 / 0.006 / 0.012             U(0.003, 0.012) per photo
==========================  ================================  =================================

Not measurable on ETH-80 and chosen by hand (assumptions): uniform in-plane rotation
(ETH-80 turns objects by pan and tilt, which a 2-D drawing can only imitate; a robot
sees objects handled in any orientation), tilt up to 60 degrees (ETH-80's goes to 90),
contrast U(0.85, 1.15) per object, distractors (Poisson, mean 1.5, radius 4-12 px;
ETH-80 has none, the thesis' robot images had segmentation leftovers), part swing
N(0, 20 deg), textures (40 % plain). Nothing here was tuned on a recognition result.
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io import LABELS_HEADER, replace_dir
from .._optional import optional_import
from .._validation import check_random_state
from ..errors import DataError, ParameterError
from .data import LABELS_FILE, ImageSet

__all__ = [
    "FAMILIES",
    "GENERATOR_VERSION",
    "TEXTURES",
    "ViewParams",
    "image_statistics",
    "make_objects",
    "write_image_folder",
]

#: Bumped whenever the generator's output changes.
GENERATOR_VERSION = 1

#: Shape families (the ``category`` of a generated object).
FAMILIES: tuple[str, ...] = ("ellipse", "polygon", "star", "blob", "box", "composite")

#: Textures of object parts.
TEXTURES: tuple[str, ...] = ("plain", "stripes", "dots", "checker", "mottled")

_SS = 2  # supersampling factor of the renderer
_TEXTURE_P = (0.4, 0.15, 0.15, 0.15, 0.15)  # plain, stripes, dots, checker, mottled
_SATURATION = (0.05, 0.6)  # HSV saturation and value of object colours (before shading)
_VALUE = (0.6, 1.0)
_AMBIENT = 0.6  # shading: ambient + (1 - ambient) * max(0, n . l)


@dataclass(frozen=True)
class ViewParams:
    """Variation of objects, views and photos (values: module docstring; sizes at 96 px)."""

    radius_px: tuple[float, float] = (24.0, 40.0)
    scale_sd: float = 0.10
    shift_sd_px: float = 3.0
    tilt_max_deg: float = 60.0
    part_swing_deg: float = 20.0
    session_gain_sd: float = 0.14  # per object (all its views)
    gain_sd: float = 0.05  # per view
    contrast: tuple[float, float] = (0.85, 1.15)
    session_temperature_sd: float = 0.045
    temperature_sd: float = 0.03
    noise_sd: tuple[float, float] = (0.003, 0.012)
    background_v: tuple[float, float] = (0.45, 0.75)
    background_s: tuple[float, float] = (0.10, 0.60)
    gradient: tuple[float, float] = (0.03, 0.27)
    distractors_mean: float = 1.5
    distractor_radius_px: tuple[float, float] = (4.0, 12.0)


# --------------------------------------------------------------------------- colours and shapes


def _hsv(h: float, s: float, v: float) -> np.ndarray:
    hsv2rgb = optional_import("skimage.color", "vision", "generating images").hsv2rgb

    return hsv2rgb(np.array([[[h % 1.0, s, v]]]))[0, 0]


def _outline(family: str, rng: np.random.Generator) -> np.ndarray:
    """Closed outline (n, 2) of a primitive in object units (max radius 1), x right, y down."""
    if family == "ellipse":
        t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
        pts = np.stack([np.cos(t), rng.uniform(0.5, 1.0) * np.sin(t)], 1)
    elif family == "polygon":
        n = int(rng.integers(3, 8))
        t = np.arange(n) * 2 * np.pi / n + rng.normal(0, 0.1, n)
        r = rng.uniform(0.85, 1.0, n)
        pts = np.stack([r * np.cos(t), r * np.sin(t)], 1)
    elif family == "star":
        n = int(rng.integers(5, 9))
        inner = rng.uniform(0.4, 0.7)
        t = np.arange(2 * n) * np.pi / n
        r = np.where(np.arange(2 * n) % 2 == 0, 1.0, inner)
        pts = np.stack([r * np.cos(t), r * np.sin(t)], 1)
    elif family == "blob":
        t = np.linspace(0, 2 * np.pi, 96, endpoint=False)
        r = np.ones_like(t)
        for k in (2, 3, 4):
            r += rng.uniform(0, 0.15) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
        pts = np.stack([r * np.cos(t), r * np.sin(t)], 1)
    elif family == "box":
        t = np.linspace(0, 2 * np.pi, 96, endpoint=False)
        p = rng.uniform(3.0, 6.0)
        b = rng.uniform(0.4, 1.0)
        c, s = np.cos(t), np.sin(t)
        pts = np.stack([np.sign(c) * np.abs(c) ** (2 / p), b * np.sign(s) * np.abs(s) ** (2 / p)], 1)
    else:  # pragma: no cover - internal
        raise ParameterError(f"unknown shape family {family!r}")
    return pts / np.abs(pts).max() if family != "polygon" else pts / np.linalg.norm(pts, axis=1).max()


@dataclass
class _Part:
    outline: np.ndarray  # (n, 2) object units, relative to the part's centre
    centre: np.ndarray  # (2,) in object units (0 for the body)
    anchor: float  # angle of the attachment around the body (radians), attached parts only
    colour_a: np.ndarray
    colour_b: np.ndarray
    texture: str
    period: float
    angle: float
    phases: np.ndarray
    dot_radius: float
    strength: float
    behind: bool


@dataclass
class _Object:
    family: str
    radius_px: float
    parts: list  # the body first


def _texture_colours(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float, float]:
    h, s, v = rng.uniform(0, 1), rng.uniform(*_SATURATION), rng.uniform(*_VALUE)
    if rng.uniform() < 0.5:
        h2, s2, v2 = h + rng.uniform(0.25, 0.75), rng.uniform(*_SATURATION), rng.uniform(*_VALUE)
    else:
        h2, s2, v2 = h, s, v * rng.uniform(0.35, 0.7)
    return _hsv(h, s, v), _hsv(h2, s2, v2), h, s


def _part(outline, centre, anchor, rng, behind=False) -> _Part:
    a, b, _, _ = _texture_colours(rng)
    texture = str(rng.choice(TEXTURES, p=_TEXTURE_P))
    return _Part(outline=outline, centre=np.asarray(centre, float), anchor=anchor, colour_a=a, colour_b=b,
                 texture=texture, period=rng.uniform(0.2, 0.5), angle=rng.uniform(0, np.pi),
                 phases=rng.uniform(0, 2 * np.pi, 8), dot_radius=rng.uniform(0.2, 0.35),
                 strength=rng.uniform(0.3, 1.0), behind=behind)


def _make_object(family: str, rng: np.random.Generator, p: ViewParams) -> _Object:
    radius = rng.uniform(*p.radius_px)
    if family != "composite":
        return _Object(family, radius, [_part(_outline(family, rng), (0, 0), 0.0, rng)])
    body_family = str(rng.choice(["ellipse", "blob", "box"]))
    body = _outline(body_family, rng) * 0.75
    parts = [_part(body, (0, 0), 0.0, rng)]
    for _ in range(int(rng.integers(1, 3))):
        r = rng.uniform(0.3, 0.5)
        shape = _outline(str(rng.choice(["ellipse", "box", "polygon"])), rng) * r
        anchor = rng.uniform(0, 2 * np.pi)
        parts.append(_part(shape, (0, 0), anchor, rng, behind=bool(rng.uniform() < 0.5)))
    return _Object(family, radius, parts)


def _body_radius(body: np.ndarray, angle: float) -> float:
    """Distance from the centre to the body outline in direction ``angle``."""
    ang = np.arctan2(body[:, 1], body[:, 0])
    d = np.abs((ang - angle + np.pi) % (2 * np.pi) - np.pi)
    return float(np.linalg.norm(body[np.argmin(d)]))


# --------------------------------------------------------------------------- rendering


def _texture(part: _Part, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mixing weight of colour_b in [0, 1] at object coordinates (u, v) of the part."""
    c, s = np.cos(part.angle), np.sin(part.angle)
    x, y = (c * u + s * v) / part.period, (-s * u + c * v) / part.period
    ph = part.phases
    if part.texture == "plain":
        return np.zeros_like(u)
    if part.texture == "stripes":
        return 0.5 + 0.5 * np.tanh(3 * np.sin(2 * np.pi * x + ph[0]))
    if part.texture == "dots":
        fx, fy = (x + ph[0]) % 1.0 - 0.5, (y + ph[1]) % 1.0 - 0.5
        return (np.hypot(fx, fy) < part.dot_radius).astype(float)
    if part.texture == "checker":
        return ((np.floor(x + ph[0] / 6) + np.floor(y + ph[1] / 6)) % 2).astype(float)
    # mottled: smooth random field from a few oriented sinusoids
    f = np.zeros_like(u)
    for k in range(3):
        a = ph[2 + k]
        f += np.sin(2 * np.pi * (np.cos(a) * x + np.sin(a) * y) * (0.5 + 0.3 * k) + ph[5 + k % 3])
    return 0.5 + 0.5 * np.tanh(1.5 * f)


def _polygon_mask(shape: tuple[int, int], pts_xy: np.ndarray) -> np.ndarray:
    polygon = optional_import("skimage.draw", "vision", "generating images").polygon

    m = np.zeros(shape, dtype=bool)
    rr, cc = polygon(pts_xy[:, 1], pts_xy[:, 0], shape=shape)
    m[rr, cc] = True
    return m


def _render_view(obj: _Object, bg: dict, session: dict, size: int, rng: np.random.Generator, p: ViewParams,
                 clutter: bool) -> tuple[np.ndarray, np.ndarray]:
    """One photo of ``obj``: (image (size, size, 3) in [0, 1], 8-bit levels; object mask)."""
    S = size * _SS
    k = size / 96.0  # sizes in ViewParams are for 96 x 96 images
    yy, xx = (np.indices((S, S)) + 0.5) / _SS  # pixel centres in output pixels

    # background: scene colour with a linear gradient of value
    g_amp = rng.uniform(*p.gradient)
    g_dir = rng.uniform(0, 2 * np.pi)
    ramp = ((xx - size / 2) * np.cos(g_dir) + (yy - size / 2) * np.sin(g_dir)) / (size / np.sqrt(2))
    bg_v = np.clip(bg["v"] * (1 + 0.05 * rng.normal()) + 0.5 * g_amp * ramp, 0, 1)
    base = _hsv(bg["h"] + rng.normal(0, 0.01), bg["s"], 1.0)
    img = bg_v[:, :, None] * base[None, None, :]

    # distractors, behind the object
    if clutter:
        for _ in range(int(rng.poisson(p.distractors_mean))):
            fam = str(rng.choice(["ellipse", "polygon", "blob", "box"]))
            r = rng.uniform(*p.distractor_radius_px) * k
            th = rng.uniform(0, 2 * np.pi)
            R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            pts = (_outline(fam, rng) @ R.T) * r + rng.uniform(0, size, 2)
            m = _polygon_mask((S, S), pts * _SS)
            col = _hsv(rng.uniform(), rng.uniform(0, 0.7), rng.uniform(0.2, 0.9))
            img[m] = col

    # view geometry: x_img = centre + s * Rot(theta) @ F @ x_obj
    theta = rng.uniform(0, 2 * np.pi)
    beta = rng.uniform(0, np.pi)
    ct = np.cos(np.deg2rad(rng.uniform(0, p.tilt_max_deg)))
    Rb = np.array([[np.cos(beta), -np.sin(beta)], [np.sin(beta), np.cos(beta)]])
    F = Rb @ np.diag([1.0, ct]) @ Rb.T
    Rt = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    scale = obj.radius_px * k * np.exp(rng.normal(0, p.scale_sd))
    A = scale * Rt @ F
    centre = size / 2 + rng.normal(0, p.shift_sd_px * k, 2)
    Ainv = np.linalg.inv(A)
    rel = np.stack([xx - centre[0], yy - centre[1]], -1)  # (S, S, 2), image frame
    obj_uv = rel @ Ainv.T  # object frame

    # lighting direction (image frame) and dome shading
    phi, el = rng.uniform(0, 2 * np.pi), np.deg2rad(rng.uniform(20, 60))
    light = np.array([np.cos(phi) * np.sin(el), np.sin(phi) * np.sin(el), np.cos(el)])
    body = obj.parts[0].outline
    mask_all = np.zeros((S, S), bool)
    order = [pt for pt in obj.parts[1:] if pt.behind] + [obj.parts[0]] + [pt for pt in obj.parts[1:] if not pt.behind]
    for part in order:
        if part is obj.parts[0]:
            pc = np.zeros(2)
        else:
            a = part.anchor + np.deg2rad(rng.normal(0, p.part_swing_deg))
            d = _body_radius(body, a) + 0.6 * np.abs(part.outline).max()
            pc = d * np.array([np.cos(a), np.sin(a)])
        pts = (part.outline + pc) @ A.T + centre
        m = _polygon_mask((S, S), pts * _SS)
        if not m.any():
            continue
        uv = obj_uv[m] - pc
        t = part.strength * _texture(part, uv[:, 0], uv[:, 1])[:, None]
        col = (1 - t) * part.colour_a[None, :] + t * part.colour_b[None, :]
        rxy = rel[m] / (scale * max(1.0, float(np.abs(pc).max() + np.abs(part.outline).max())))
        rho2 = np.minimum((rxy**2).sum(1), 1.0)
        normal = np.concatenate([rxy, np.sqrt(1 - rho2)[:, None]], 1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        shade = _AMBIENT + (1 - _AMBIENT) * np.clip(normal @ light, 0, 1)
        img[m] = col * shade[:, None]
        mask_all |= m

    # photo: downsample, lighting, noise, 8 bits
    img = img.reshape(size, _SS, size, _SS, 3).mean(axis=(1, 3))
    mask = mask_all.reshape(size, _SS, size, _SS).mean(axis=(1, 3)) >= 0.5
    gain = session["gain"] * np.exp(rng.normal(0, p.gain_sd))
    temp = session["temperature"] + rng.normal(0, p.temperature_sd)
    img = img * gain * np.array([1 + temp, 1.0, 1 - temp])
    mu = img.mean()
    img = (img - mu) * session["contrast"] + mu
    img = img + rng.normal(0, rng.uniform(*p.noise_sd), img.shape)
    img = np.round(np.clip(img, 0, 1) * 255) / 255
    return img, mask


def _views(n_objects: int, n_views: int, size: int, random_state, clutter: bool, params: ViewParams):
    rng = check_random_state(random_state)
    base = int(rng.integers(2**63 - 1))
    scene = np.random.default_rng([base, 0])
    bg = {"h": scene.uniform(), "s": scene.uniform(*params.background_s), "v": scene.uniform(*params.background_v)}
    offset = int(scene.integers(len(FAMILIES)))
    images, masks, labels, views, cats = [], [], [], [], []
    for i in range(n_objects):
        family = FAMILIES[(i + offset) % len(FAMILIES)]
        orng = np.random.default_rng([base, 1, i])
        obj = _make_object(family, orng, params)
        session = {"gain": np.exp(orng.normal(0, params.session_gain_sd)),
                   "temperature": orng.normal(0, params.session_temperature_sd),
                   "contrast": orng.uniform(*params.contrast)}
        for v in range(n_views):
            img, m = _render_view(obj, bg, session, size, np.random.default_rng([base, 2, i, v]), params, clutter)
            images.append(img)
            masks.append(m)
            labels.append(f"obj{i:02d}")
            views.append(f"{v:02d}")
            cats.append(family)
    return images, masks, labels, views, cats


def make_objects(
    n_objects: int = 10,
    n_views: int = 24,
    *,
    size: int = 96,
    clutter: bool = True,
    params: ViewParams | None = None,
    random_state=0,
) -> ImageSet:
    """Photos of ``n_objects`` synthetic objects from ``n_views`` viewpoints each.

    Parameters
    ----------
    n_objects : int, default=10
        Objects (concepts). Object ``i`` is labelled ``"obj{i:02d}"``; its shape family
        (``categories``) cycles through :data:`FAMILIES`.
    n_views : int, default=24
        Views per object (``views`` ``"00"``, ``"01"``, ...).
    size : int, default=96
        Image side in pixels (as the ETH-80 images here); sizes scale with it.
    clutter : bool, default=True
        Draw distractor shapes in the background.
    params : ViewParams, optional
        Variation parameters (defaults: module docstring).
    random_state : int, Generator or None, default=0
        Resolved once. Object ``i`` and its view ``v`` depend only on the seed, ``i`` and
        ``v``: asking for more objects or views keeps the first ones unchanged.

    Returns
    -------
    ImageSet
        ``n_objects * n_views`` float RGB images (size, size, 3) in [0, 1] on 8-bit levels
        (``k / 255``), object by object.
    """
    from .._validation import check_positive_int

    n_objects = check_positive_int(n_objects, "n_objects")
    n_views = check_positive_int(n_views, "n_views")
    size = check_positive_int(size, "size", minimum=16)
    params = ViewParams() if params is None else params
    if not isinstance(params, ViewParams):
        raise ParameterError(f"params must be a ViewParams; got {type(params).__name__}.")
    images, _, labels, views, cats = _views(n_objects, n_views, size, random_state, bool(clutter), params)
    return ImageSet(images, labels, views, cats, None, "synthetic-objects")


def image_statistics(image_set: ImageSet | None = None, *, n_objects: int = 10, n_views: int = 24,
                     random_state=0) -> dict[str, np.ndarray]:
    """Statistics of generated photos to compare with real ones (module docstring's table).

    Renders ``make_objects(n_objects, n_views, random_state=random_state)`` with the object
    masks and returns per-image arrays: ``area`` (object fraction of the image),
    ``bbox`` (larger side of the object's bounding box, px), ``centre`` (row, col),
    ``object_hsv`` and ``object_rgb`` (mean colour of the object), ``background_v``.
    ``image_set`` is ignored unless None (kept for symmetry with measured sets).
    """
    rgb2hsv = optional_import("skimage.color", "vision", "generating images").rgb2hsv

    images, masks, *_ = _views(n_objects, n_views, 96, random_state, True, ViewParams())
    out: dict[str, list] = {k: [] for k in ("area", "bbox", "centre", "object_hsv", "object_rgb", "background_v")}
    for im, m in zip(images, masks):
        rr, cc = np.nonzero(m)
        out["area"].append(m.mean())
        out["bbox"].append(max(rr.max() - rr.min() + 1, cc.max() - cc.min() + 1) if len(rr) else 0)
        out["centre"].append([rr.mean(), cc.mean()] if len(rr) else [np.nan, np.nan])
        out["object_hsv"].append(rgb2hsv(im)[m].mean(0))
        out["object_rgb"].append(im[m].mean(0))
        out["background_v"].append(rgb2hsv(im)[~m][:, 2].mean())
    return {k: np.asarray(v) for k, v in out.items()}


# --------------------------------------------------------------------------- writing


def _safe(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name).strip("._") or "image"


def write_image_folder(
    image_set: ImageSet,
    root: str | os.PathLike[str],
    *,
    overwrite: bool = False,
) -> Path:
    """Write an image set in the generic image layout: PNG files and ``labels.csv``.

    Files are named ``<label>_<view>.png`` (``<label>_<index>.png`` when the set has no
    views or these names repeat); ``labels.csv`` has the columns ``file,labels``, then
    ``view`` and ``category`` when the set has them. Pixels are written as 8-bit
    (``round(255 x)``). The folder is built next to ``root`` and renamed into place, so
    ``root`` is either complete or absent.

    Parameters
    ----------
    image_set : ImageSet
    root : path-like
        Folder to create.
    overwrite : bool, default=False
        Replace an existing non-empty ``root``.

    Returns
    -------
    Path
        The path of ``labels.csv``.
    """
    import imageio.v3 as iio

    if not isinstance(image_set, ImageSet):
        raise DataError(f"write_image_folder takes an ImageSet; got {type(image_set).__name__}.")
    if len(image_set) == 0:
        raise DataError("Nothing to write: the image set is empty.")
    root = Path(root)
    if root.exists() and (not root.is_dir() or any(root.iterdir())) and not overwrite:
        raise ParameterError(f"{root} already exists and is not empty; remove it or pass overwrite=True.")
    n = len(image_set)
    width = max(4, len(str(n - 1)))
    names = None
    if image_set.views is not None:
        names = [f"{_safe(l)}_{_safe(v)}.png" for l, v in zip(image_set.labels, image_set.views)]
        if len({n_.lower() for n_ in names}) != n:
            names = None
    if names is None:
        names = [f"{_safe(l)}_{i:0{width}d}.png" for i, l in enumerate(image_set.labels)]
    header = [*LABELS_HEADER] + (["view"] if image_set.views is not None else []) + \
        (["category"] if image_set.categories is not None else [])
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{root.name}.building-", dir=root.parent))
    try:
        rows = []
        for i, (name, im) in enumerate(zip(names, image_set.images)):
            iio.imwrite(tmp / name, np.round(np.clip(im, 0, 1) * 255).astype(np.uint8))
            row = [name, image_set.labels[i]]
            if image_set.views is not None:
                row.append(image_set.views[i])
            if image_set.categories is not None:
                row.append(image_set.categories[i])
            rows.append(row)
        with open(tmp / LABELS_FILE, "w", encoding="utf-8", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            w.writerows(rows)
        replace_dir(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return root / LABELS_FILE
