"""numba kernels of the planners' fast validity tests (planar rigid motion of robot points)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def planar_points_clearance(
    local: np.ndarray, z: np.ndarray, radius: float, x: float, y: float, theta: float, lo: np.ndarray,
    hi: np.ndarray, reach: float, box_lo: np.ndarray, box_hi: np.ndarray, out: np.ndarray,
) -> tuple[float, int]:
    """Move base-frame points (n, 2) + heights (n,) to base pose (x, y, theta) into ``out`` (n, 3).

    Returns the smallest distance from a point to the boxes [lo_b, hi_b] (inf when none is
    nearer than ``reach``: boxes whose xy rectangle is farther than ``radius`` + ``reach``
    from (x, y), ``radius`` bounding the points' distance from the base axis, are skipped)
    and the number of points inside the box [box_lo, box_hi] (the PVS grid).
    """
    c, s = math.cos(theta), math.sin(theta)
    near = np.empty(lo.shape[0], dtype=np.int64)
    count = 0
    for b in range(lo.shape[0]):
        gx = lo[b, 0] - x if x < lo[b, 0] else (x - hi[b, 0] if x > hi[b, 0] else 0.0)
        gy = lo[b, 1] - y if y < lo[b, 1] else (y - hi[b, 1] if y > hi[b, 1] else 0.0)
        if gx * gx + gy * gy <= (radius + reach) ** 2:
            near[count] = b
            count += 1
    best = np.inf
    inside = 0
    for i in range(local.shape[0]):
        px = c * local[i, 0] - s * local[i, 1] + x
        py = s * local[i, 0] + c * local[i, 1] + y
        pz = z[i]
        out[i, 0], out[i, 1], out[i, 2] = px, py, pz
        for k in range(count):
            b = near[k]
            g = lo[b, 0] - px if px < lo[b, 0] else (px - hi[b, 0] if px > hi[b, 0] else 0.0)
            d = g * g
            g = lo[b, 1] - py if py < lo[b, 1] else (py - hi[b, 1] if py > hi[b, 1] else 0.0)
            d += g * g
            g = lo[b, 2] - pz if pz < lo[b, 2] else (pz - hi[b, 2] if pz > hi[b, 2] else 0.0)
            d += g * g
            if d < best:
                best = d
        if box_lo[0] <= px <= box_hi[0] and box_lo[1] <= py <= box_hi[1] and box_lo[2] <= pz <= box_hi[2]:
            inside += 1
    return math.sqrt(best), inside
