"""What a structured-light depth camera does to a depth image besides white noise.

A Kinect-like camera triangulates a projected pattern seen by a camera ``baseline`` metres away
(Khoshelham & Elberink 2012). That gives four artefacts an exact ray caster lacks, each a
function of the organised depth image (frames x rows x columns of depth z along the optical
axis, NaN where there is no return):

- **disparity quantisation**: the disparity f b / z is measured in steps of ``step`` pixels
  (1/8 px on the Kinect), so depth comes in levels whose spacing grows with z^2:
  dz = z^2 step / (f b);
- **projector shadows**: a surface the camera sees but the projector does not light (beside a
  step edge, on the far side from the projector) returns nothing. Like a real camera's zero
  pixel, it cannot be told from a beam that met nothing: with ``no_return_clears`` the PVS then
  frees that beam's working range, so a map built with shadows on should not clear on misses;

- **flying pixels** (edge fattening): a pixel on a depth discontinuity mixes the two surfaces
  and returns a depth between them;
- **correlated noise**: a low-frequency bias per frame (calibration drift, temperature),
  smooth across the image, on top of the independent per-pixel noise.
"""

from __future__ import annotations

import numpy as np

from explore.core import Array


def quantise_disparity(z: Array, focal_px: float, baseline: float, step: float) -> Array:
    """Depth z (m) after its disparity f b / z is rounded to a multiple of ``step`` pixels."""
    scale = focal_px * baseline
    disparity = np.round(scale / z / step) * step
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(disparity > 0, scale / disparity, np.nan)


def depth_level_spacing(z: Array, focal_px: float, baseline: float, step: float) -> Array:
    """Spacing (m) of the quantised depth levels near z: z^2 step / (f b)."""
    return np.square(z) * step / (focal_px * baseline)


def discontinuity_mask(z: np.ndarray, jump: float, relative: bool = False, missing_is_far: bool = True) -> np.ndarray:
    """Pixels with a return (same shape as ``z``, images along the last two axes) that have a
    4-neighbour whose depth differs by more than ``jump`` metres (``relative``: ``jump`` times the
    nearer of the two depths). A neighbour without a return counts as a jump to the far end when
    ``missing_is_far``, and as no neighbour otherwise."""
    far = np.where(np.isfinite(z), z, np.inf if missing_is_far else np.nan)
    edge = np.zeros(z.shape, dtype=bool)
    for axis in (-2, -1):
        n = z.shape[axis]
        a, b = np.take(far, range(n - 1), axis=axis), np.take(far, range(1, n), axis=axis)
        with np.errstate(invalid="ignore"):
            step = np.abs(a - b) > (jump * np.fmin(a, b) if relative else jump)
        lo = [slice(None)] * z.ndim
        hi = [slice(None)] * z.ndim
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        edge[tuple(lo)] |= step
        edge[tuple(hi)] |= step
    return edge & np.isfinite(z)


def flying_pixels(z: np.ndarray, jump: float, probability: float, rng: np.random.Generator) -> np.ndarray:
    """Pixels on a discontinuity replaced, with ``probability``, by a depth between their own and
    their farthest finite 4-neighbour's (a uniform mix, as the two surfaces share the pixel)."""
    edge = discontinuity_mask(z, jump)
    padded = np.pad(np.where(np.isfinite(z), z, -np.inf), ((0, 0), (1, 1), (1, 1)), constant_values=-np.inf)
    far = np.max([padded[:, 1:-1, :-2], padded[:, 1:-1, 2:], padded[:, :-2, 1:-1], padded[:, 2:, 1:-1]], axis=0)
    other = np.where(np.isfinite(far), far, z)
    fly = edge & (rng.random(z.shape) < probability) & (np.abs(other - z) > jump)
    mix = rng.random(z.shape)
    return np.where(fly, mix * z + (1.0 - mix) * other, z)


def smooth_field(frames: int, rows: int, cols: int, rng: np.random.Generator, cells: int = 4) -> np.ndarray:
    """A random field (frames, rows, cols), mean about 0 and unit standard deviation per frame,
    that varies over about 1/``cells`` of the image: Gaussian values on a coarse grid, resized
    bilinearly (``cv2.resize``)."""
    import cv2

    grid = rng.normal(size=(frames, cells + 1, cells + 1)).astype(np.float32)
    field = np.array([cv2.resize(g, (cols, rows), interpolation=cv2.INTER_LINEAR) for g in grid], dtype=float)
    return field / field.std(axis=(1, 2), keepdims=True)
