"""Processing an organised depth image before it becomes points (OpenCV).

A structured-light or time-of-flight camera returns mixed depths on discontinuities (flying
pixels, :mod:`explore.sim.artefacts`) that land in free space between two surfaces, where
segmentation sees spurious clusters and ICP spurious correspondences. The classic remedies work
on the organised image (:attr:`Scan.image_shape <explore.sim.Scan>`: one image per camera frame,
a laser striper's sweep as one image of stripes):

- the **flying-pixel filter**: drop a pixel that fewer than ``min_support`` of its 8 neighbours
  lie within ``max_ratio`` times its depth of. A pixel on a surface's true edge keeps the about
  five neighbours on its own surface; a mixed pixel floating between two surfaces has none or
  one (two neighbouring flying pixels of nearly the same depth). Unlike the jump-edge filter of
  Fuchs & May (2008), which drops every pixel next to a jump (:func:`jump_edges`), it leaves the
  objects' silhouettes alone, which global descriptors (VFH) and render-and-compare see;
- an edge-preserving **median** (``cv2.medianBlur``, 3 or 5 px) against speckle, taken only over
  pixels with a return;
- **normals from the image** (as PCL's integral-image normals): the point image averaged over a
  window (``cv2.blur``, normalised by the returns in the window), its central differences across
  ``window // 2`` pixels crossed; no neighbour search, and no normal across a depth jump.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from explore.core import Points3
from explore.sim import Scan, discontinuity_mask


def depth_image(scan: Scan) -> tuple[np.ndarray, np.ndarray]:
    """The scan's depth along each frame's optical axis as organised images (images, rows, cols),
    NaN without a return, and the cosine between each beam and its optical axis (to go back to
    ranges: range = depth / cosine)."""
    if scan.image_shape is None:
        raise ValueError("the scan is not organised (beams were dropped from it)")
    optical = np.einsum("ij,ij->i", scan.directions, scan.sensor_poses[scan.frame_of_beam][:, :3, 2])
    return (scan.ranges * optical).reshape(scan.image_shape), optical


def jump_edges(z: np.ndarray, max_ratio: float = 0.02) -> np.ndarray:
    """Pixels with a return (images along the last two axes) that have a 4-neighbour with a return
    whose depth differs by more than ``max_ratio`` times the nearer depth."""
    return discontinuity_mask(z, max_ratio, relative=True, missing_is_far=False)


def flying_pixel_mask(z: np.ndarray, max_ratio: float = 0.02, min_support: int = 3) -> np.ndarray:
    """Pixels with a return (images along the last two axes) that fewer than ``min_support`` of
    their 8 neighbours with a return lie within ``max_ratio`` times their depth of."""
    far = np.where(np.isfinite(z), z, np.nan)
    padded = np.pad(far, [(0, 0)] * (z.ndim - 2) + [(1, 1), (1, 1)], constant_values=np.nan)
    rows, cols = z.shape[-2:]
    support = np.zeros(z.shape, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr or dc:
                    other = padded[..., 1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
                    support += np.abs(other - far) <= max_ratio * far
    return np.isfinite(z) & (support < min_support)


def median_depth(z: np.ndarray, size: int = 3) -> np.ndarray:
    """``cv2.medianBlur`` of the depth image (size 3 or 5) where every pixel of the window has a
    return; other pixels keep their depth (a median over a hole would invent depth)."""
    import cv2

    if size not in (3, 5):
        raise ValueError("median size must be 3 or 5 (cv2.medianBlur on float images)")
    valid = np.isfinite(z)
    blurred = cv2.medianBlur(np.where(valid, z, 0.0).astype(np.float32), size).astype(np.float64)
    whole = cv2.erode(valid.astype(np.uint8), np.ones((size, size), np.uint8), borderValue=0).astype(bool)
    return np.where(whole, blurred, z)


def filter_depth_scan(scan: Scan, max_ratio: float = 0.02, median: int = 0, normals: bool = False) -> Scan:
    """The scan without its flying pixels (:func:`flying_pixel_mask`; and, with ``median``, its
    depth median-filtered), image by image; with ``normals`` its returns carry the normals of
    :func:`organised_normals`, estimated before the beams go. Dropped beams are removed, not
    turned into beams without a return, which would declare the space in front of the sensor
    free."""
    z, optical = depth_image(scan)
    if median:
        z = np.array([median_depth(image, median) for image in z])
        scan = dataclasses.replace(scan, ranges=z.ravel() / optical)
    if normals:
        scan = with_organised_normals(scan)
    keep = ~flying_pixel_mask(z, max_ratio).ravel() if max_ratio < np.inf else np.ones(len(scan), dtype=bool)
    ranges = scan.ranges[keep]
    return dataclasses.replace(
        scan, origins=scan.origins[keep], directions=scan.directions[keep], ranges=ranges,
        sigmas=np.where(np.isfinite(ranges), scan.sigmas[keep], np.nan), frame_of_beam=scan.frame_of_beam[keep],
        colors=None if scan.colors is None else scan.colors[keep], image_shape=None,
        normals=None if scan.normals is None else scan.normals[keep],
    )


@dataclasses.dataclass(frozen=True)
class DepthProcessing:
    """What happens to every organised view before it is used: the flying-pixel filter's
    ``max_ratio`` (0: off), a median over ``median_px`` pixels (0: off) and the image's normals."""

    flying_pixel_filter: float = 0.02
    median_px: int = 0
    organised_normals: bool = True

    def apply(self, scan: Scan) -> Scan:
        """:func:`filter_depth_scan` with these settings; a scan that is not organised stays as it is."""
        if scan.image_shape is None:
            return scan
        return filter_depth_scan(scan, self.flying_pixel_filter or np.inf, self.median_px, self.organised_normals)


def with_organised_normals(scan: Scan, window: int = 5) -> Scan:
    """The scan with per-beam normals (:attr:`Scan.normals <explore.sim.Scan>`) from its
    organised image (:func:`organised_normals`; NaN without a return or a usable window)."""
    per_beam = np.full((len(scan), 3), np.nan)
    per_beam[scan.hits] = organised_normals(scan, window)
    return dataclasses.replace(scan, normals=per_beam)


def organised_normals(scan: Scan, window: int = 5, max_ratio: float = 0.02) -> Points3:
    """Unit normals (n_hits, 3) of the scan's returns, oriented towards the sensor, from its
    organised image: the point image averaged over ``window`` x ``window`` returns, then the
    cross product of its central differences ``window // 2`` pixels apart along the rows and the
    columns. NaN where a difference would cross a depth jump (``max_ratio``, as
    :func:`jump_edges`) or leave the returns."""
    import cv2

    z, _ = depth_image(scan)
    images, rows, cols = z.shape
    valid = np.isfinite(z)
    points = np.where(valid.ravel()[:, None], scan.origins + scan.directions * np.nan_to_num(scan.ranges)[:, None],
                      0.0).reshape(images, rows, cols, 3)
    size = (window, window)
    weight = np.array([cv2.blur(v.astype(np.float64), size, borderType=cv2.BORDER_CONSTANT) for v in valid])
    mean = np.array([cv2.blur(img, size, borderType=cv2.BORDER_CONSTANT) for img in points])
    mean = mean / np.where(weight > 0, weight, np.nan)[..., None]
    broken = np.array([cv2.dilate(e.astype(np.uint8), np.ones(size, np.uint8)) for e in jump_edges(z, max_ratio)])
    usable = valid & ~broken.astype(bool)
    h = max(1, window // 2)
    normals = np.full((images, rows, cols, 3), np.nan)
    both = usable[:, h:-h, h:-h] & usable[:, h:-h, 2 * h:] & usable[:, h:-h, :-2 * h] \
        & usable[:, 2 * h:, h:-h] & usable[:, :-2 * h, h:-h]
    du = mean[:, h:-h, 2 * h:] - mean[:, h:-h, :-2 * h]
    dv = mean[:, 2 * h:, h:-h] - mean[:, :-2 * h, h:-h]
    n = np.cross(du, dv)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals[:, h:-h, h:-h] = np.where(both[..., None] & (length > 0), n / length, np.nan)
    normals = normals.reshape(-1, 3)[scan.hits]
    towards = scan.origins[scan.hits] - scan.points()
    flip = np.einsum("ij,ij->i", normals, towards) < 0
    normals[flip] *= -1.0
    return normals
