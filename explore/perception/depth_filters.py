"""Cleaning an organised depth image before it becomes points (OpenCV).

A structured-light or time-of-flight camera returns mixed depths on discontinuities (flying
pixels, :mod:`explore.sim.structured_light`) that land in free space between two surfaces, where
segmentation sees spurious clusters and ICP spurious correspondences. Two classic remedies on the
organised image:

- the **jump-edge filter** (Fuchs & May 2008): drop a pixel whose depth differs from a 4-neighbour
  by more than ``max_ratio`` times its own depth; it removes the flying pixels (all but the few
  that sit next to another of nearly the same depth) and erodes each true edge by about one pixel;
- an edge-preserving **median** (``cv2.medianBlur``, 3 or 5 px) against speckle, taken only over
  pixels with a return.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from explore.sim import Scan
from explore.sim.structured_light import discontinuity_mask


def jump_edges(z: np.ndarray, max_ratio: float = 0.02) -> np.ndarray:
    """Pixels with a return (images along the last two axes) that have a 4-neighbour with a return
    whose depth differs by more than ``max_ratio`` times the nearer depth."""
    return discontinuity_mask(z, max_ratio, relative=True, missing_is_far=False)


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


def filter_depth_scan(scan: Scan, rows: int, cols: int, max_ratio: float = 0.02, median: int = 0) -> Scan:
    """The scan without its jump-edge beams (and, with ``median``, its depth median-filtered), frame
    by frame; ``rows`` x ``cols`` is the sensor's image. Dropped beams are removed, not turned into
    beams without a return, which would declare the space in front of the sensor free."""
    optical = np.einsum("ij,ij->i", scan.directions, scan.sensor_poses[scan.frame_of_beam][:, :3, 2])
    z = (scan.ranges * optical).reshape(-1, rows, cols)
    if median:
        z = np.array([median_depth(image, median) for image in z])
    keep = ~jump_edges(z, max_ratio).ravel()
    ranges = (z.ravel() / optical)[keep]
    return dataclasses.replace(
        scan, origins=scan.origins[keep], directions=scan.directions[keep], ranges=ranges,
        sigmas=np.where(np.isfinite(ranges), scan.sigmas[keep], np.nan), frame_of_beam=scan.frame_of_beam[keep],
        colors=None if scan.colors is None else scan.colors[keep],
    )
