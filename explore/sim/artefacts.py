"""What real range sensors do to a depth image besides white noise.

Each artefact is a function of the organised depth image (frames x rows x columns of depth z
along the optical axis, NaN where there is no return) or of the beams' geometry:

- **disparity quantisation** (structured light, Khoshelham & Elberink 2012): the disparity
  f b / z is measured in steps of ``step`` pixels (1/8 px on the Kinect), so depth comes in
  levels whose spacing grows with z^2: dz = z^2 step / (f b);
- **shadows of the second viewpoint**: a triangulating sensor needs its projector (or, for a
  laser striper, its camera) ``baseline`` away to see the surface too; beside a step edge it
  returns nothing. Like a real camera's zero pixel, a shadow cannot be told from a beam that met
  nothing: with ``no_return_clears`` the PVS then frees that beam's working range, so a map
  built with shadows on should not clear on misses;
- **flying pixels** (edge fattening): a pixel on a depth discontinuity mixes the two surfaces
  and returns a depth between them;
- **missing returns** at grazing incidence (the return probability falls linearly in cos from
  ``grazing_from`` to the sensor's largest incidence angle) and on dark surfaces (the grey level
  of the surface's colour in pybullet's render times cos(incidence), as a Lambertian surface
  sends the emitter's light back);
- **glossy surfaces**: a surface that reflects the share ``specular`` of the light as a mirror sends
  only the rest, (1 - specular), back diffusely (the dark-surface model sees that share of its
  colour), and where the mirror reflection of the emitter's light falls within ``highlight_deg`` of
  the receiver the highlight saturates the sensor: no return there, with probability ``specular``;
- **correlated noise**: a low-frequency bias per frame (calibration drift, temperature), smooth
  across the image, and correlated patches (the correlation window of the pattern matcher; a
  laser stripe's speckle along the stripe), on top of the independent per-pixel noise.
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


def correlated_field(shape: tuple[int, ...], length: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of unit variance (``shape``: frames x rows x columns) whose correlation
    between pixels a lag L apart along an axis is exp(-L^2 / (4 s^2)), s the axis's ``length``
    (rows, columns; 0: independent along that axis): white noise blurred by a Gaussian kernel of
    standard deviation s (``cv2.GaussianBlur``, separable), divided by the kernel's L2 norm."""
    import cv2

    frames, rows, cols = shape[0], int(np.prod(shape[1:-1])), shape[-1]
    s_rows, s_cols = length
    half_rows, half_cols = (int(np.ceil(3.0 * s)) if s > 0 else 0 for s in (s_rows, s_cols))
    kernel_cols = cv2.getGaussianKernel(2 * half_cols + 1, s_cols) if s_cols > 0 else np.ones((1, 1))
    kernel_rows = cv2.getGaussianKernel(2 * half_rows + 1, s_rows) if s_rows > 0 else np.ones((1, 1))
    # white noise on a margin of the kernel's half-width, blurred and cropped: no border effect
    white = rng.normal(size=(frames, rows + 2 * half_rows, cols + 2 * half_cols))
    blurred = np.array([cv2.sepFilter2D(frame, cv2.CV_64F, kernel_cols, kernel_rows) for frame in white])
    field = blurred[:, half_rows : half_rows + rows, half_cols : half_cols + cols]
    return field.reshape(shape) / (np.linalg.norm(kernel_cols) * np.linalg.norm(kernel_rows))


def grazing_return_probability(cos_incidence: Array, from_deg: float, max_deg: float) -> Array:
    """Probability of a return at incidence angle arccos(``cos_incidence``): 1 up to ``from_deg``,
    falling linearly in cos to 0 at ``max_deg`` (a sensor's signal goes with the cosine)."""
    lo, hi = np.cos(np.deg2rad(max_deg)), np.cos(np.deg2rad(from_deg))
    if hi <= lo:
        return (np.asarray(cos_incidence) >= lo).astype(float)
    return np.clip((np.asarray(cos_incidence) - lo) / (hi - lo), 0.0, 1.0)


def dark_return_probability(intensity: Array, dark_level: float) -> Array:
    """Probability of a return for a surface sending back ``intensity`` = grey level of its own
    colour (0-255) times cos(incidence), as a Lambertian surface lit by the sensor's own emitter
    does: intensity / ``dark_level`` below that level, 1 above it."""
    return np.clip(np.asarray(intensity, dtype=float) / dark_level, 0.0, 1.0)


def mirror_deviation(directions: Array, normals: Array, points: Array, receivers: Array) -> Array:
    """Angle (rad, (n,)) between the mirror reflection of each beam (unit ``directions`` meeting surfaces of
    unit ``normals`` at ``points``) and the direction from its point to its receiver (``receivers``, (n, 3)):
    0 where a mirror would send the emitter's light straight into the receiver. The angle is the same with
    emitter and receiver swapped (a reflection is its own inverse), so the beams may be either's."""
    reflected = directions - 2.0 * np.einsum("ij,ij->i", directions, normals)[:, None] * normals
    back = receivers - points
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    return np.arccos(np.clip(np.einsum("ij,ij->i", reflected, back), -1.0, 1.0))


def highlight_return_probability(specular: Array, deviation: Array, highlight_deg: float) -> Array:
    """Probability of a return on a glossy surface (``specular``: the share of the light it reflects as a
    mirror) where the mirror reflection deviates by ``deviation`` (rad) from the receiver: within
    ``highlight_deg`` the highlight saturates the sensor and the return is lost with probability
    ``specular``; elsewhere 1."""
    return np.where(np.asarray(deviation) < np.deg2rad(highlight_deg), 1.0 - np.asarray(specular), 1.0)


def smooth_field(frames: int, rows: int, cols: int, rng: np.random.Generator, cells: int = 4) -> np.ndarray:
    """A random field (frames, rows, cols), mean about 0 and unit standard deviation per frame,
    that varies over about 1/``cells`` of the image: Gaussian values on a coarse grid, resized
    bilinearly (``cv2.resize``)."""
    import cv2

    grid = rng.normal(size=(frames, cells + 1, cells + 1)).astype(np.float32)
    field = np.array([cv2.resize(g, (cols, rows), interpolation=cv2.INTER_LINEAR) for g in grid], dtype=float)
    spread = field.std(axis=(1, 2), keepdims=True)
    # a one-pixel image has no spread: its value is one draw of the grid's unit normal already
    return field / np.where(spread > 0.0, spread, 1.0)
