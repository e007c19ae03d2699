"""Known answers for the dense SIFT descriptor.

On an intensity ramp ``I(y, x) = a (cos(phi) x + sin(phi) y)`` the gradient is the same
vector ``a (cos phi, sin phi)`` at every pixel (``np.gradient`` is exact on a linear
image, borders included), so each descriptor can be written down from Lowe's (2004)
definition as :func:`~mmconcepts.vision.features.dense_sift` documents it: 4 x 4 cells,
8 orientation bins with linear interpolation between the two nearest bins, a Gaussian
window of standard deviation ``patch_size / 2``, L2 normalisation, clipping at 0.2 and
renormalisation.
"""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts.vision.features import dense_sift

P, CS, STEP = 16, 4, 8


def _ramp(phi: float, a: float = 0.01, size: int = 32) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    return a * (np.cos(phi) * x + np.sin(phi) * y) + 0.5  # offset: values in [0, 1], as every float image's


def _normalize_clip(v: np.ndarray, clip: float = 0.2) -> np.ndarray:
    v = v / np.linalg.norm(v)
    v = np.minimum(v, clip)
    return v / np.linalg.norm(v)


def _expected_upright(phi: float, a: float = 0.01, clip: float = 0.2) -> np.ndarray:
    """Upright descriptor: each cell holds CS*CS samples of magnitude a, split between the
    two bins around phi, weighted by the Gaussian window at the cell centre."""
    b = phi * 8 / (2 * np.pi)
    lo, w_hi = int(np.floor(b)) % 8, b - np.floor(b)
    hist = np.zeros(8)
    hist[lo] += 1 - w_hi
    hist[(lo + 1) % 8] += w_hi
    centre = (np.arange(4) - 1.5) * CS  # cell centres relative to the patch centre
    sigma = P / 2
    g = np.exp(-(centre[:, None] ** 2 + centre[None, :] ** 2) / (2 * sigma**2))
    v = (CS * CS * a) * g[:, :, None] * hist[None, None, :]  # (4, 4, 8): cell row, cell column, bin
    return _normalize_clip(v.ravel(), clip)


def _expected_rotated(a: float = 0.01, clip: float = 0.2) -> np.ndarray:
    """Rotation-invariant descriptor of a ramp whose direction is a 36-bin centre: the
    dominant orientation is the gradient's, so every sample falls in bin 0 of the turned
    frame, weighted by the per-sample Gaussian window; cells sum their samples."""
    off = np.arange(P) - (P - 1) / 2
    sigma = P / 2
    gw = np.exp(-(off[:, None] ** 2 + off[None, :] ** 2) / (2 * sigma**2))  # (row, column) in the patch
    cells = a * gw.reshape(4, CS, 4, CS).sum(axis=(1, 3))
    v = np.zeros((4, 4, 8))
    v[:, :, 0] = cells
    return _normalize_clip(v.ravel(), clip)


@pytest.mark.parametrize("phi_deg", [0.0, 30.0, 100.0, 250.0])
@pytest.mark.parametrize("step", [STEP, 6])  # 8: cells summed on a regular grid; 6: through the integral image
def test_upright_descriptor_of_a_ramp_is_the_hand_computed_one(phi_deg, step):
    phi = np.deg2rad(phi_deg)
    feats = dense_sift(_ramp(phi), patch_size=P, step=step, contrast_threshold=0.0, rotation_invariant=False)
    expected = _expected_upright(phi)
    assert len(feats.vectors) > 1
    np.testing.assert_allclose(feats.vectors, np.broadcast_to(expected, feats.vectors.shape), atol=1e-9)


def test_the_ramp_descriptor_is_clipped():
    """The known answer tests the clip: at 100 degrees some unclipped values exceed 0.2."""
    phi = np.deg2rad(100.0)
    b = phi * 8 / (2 * np.pi)
    assert not np.allclose(_expected_upright(phi), _expected_upright(phi, clip=1.0), atol=1e-3)
    assert 0 < b - np.floor(b) < 1  # and the orientation is split between two bins
    assert not np.allclose(_expected_rotated(), _expected_rotated(clip=1.0), atol=1e-3)


@pytest.mark.parametrize("phi_deg", [35.0, 125.0, 305.0])
def test_rotation_invariant_descriptor_of_a_ramp_is_the_hand_computed_one(phi_deg):
    phi = np.deg2rad(phi_deg)  # a 36-bin centre (5 + 10 k degrees): no parabola shift
    feats = dense_sift(_ramp(phi), patch_size=P, step=STEP, contrast_threshold=0.0, rotation_invariant=True)
    assert len(feats.vectors) > 1
    np.testing.assert_allclose(feats.vectors, np.broadcast_to(_expected_rotated(), feats.vectors.shape),
                               atol=1e-9)


def test_rotation_invariant_descriptor_does_not_depend_on_the_ramp_direction():
    a = dense_sift(_ramp(np.deg2rad(35.0)), patch_size=P, step=STEP, contrast_threshold=0.0,
                   rotation_invariant=True).vectors
    b = dense_sift(_ramp(np.deg2rad(215.0)), patch_size=P, step=STEP, contrast_threshold=0.0,
                   rotation_invariant=True).vectors
    np.testing.assert_allclose(a, b, atol=1e-9)
