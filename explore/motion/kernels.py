"""numba kernels of the planners' fast validity tests (planar rigid motion of robot points)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _gap(v: float, lo: float, hi: float) -> float:
    """Distance from ``v`` to the interval [lo, hi] (0 inside)."""
    return lo - v if v < lo else (v - hi if v > hi else 0.0)


@njit(cache=True, inline="always")
def _box_sq_distance(x: float, y: float, z: float, lo: np.ndarray, hi: np.ndarray, b: int) -> float:
    """Squared distance from a point to box ``b`` of [lo, hi] (0 inside)."""
    gx, gy, gz = _gap(x, lo[b, 0], hi[b, 0]), _gap(y, lo[b, 1], hi[b, 1]), _gap(z, lo[b, 2], hi[b, 2])
    return gx * gx + gy * gy + gz * gz


@njit(cache=True)
def planar_points_clearance(
    local: np.ndarray, z: np.ndarray, radius: float, x: float, y: float, theta: float, lo: np.ndarray,
    hi: np.ndarray, reach: float, box_lo: np.ndarray, box_hi: np.ndarray, out: np.ndarray,
) -> tuple[float, int]:
    """Move base-frame points (n, 2) + heights (n,) to base pose (x, y, theta) into ``out`` (n, 3).

    Returns the smallest distance from a point to the boxes [lo_b, hi_b] (inf when none is
    nearer than ``reach``: boxes whose xy rectangle is farther than ``radius`` + ``reach``
    from (x, y), ``radius`` bounding the points' distance from the base axis, are skipped)
    and the number m of points inside the box [box_lo, box_hi] (the PVS grid): ``out[:m]``
    holds those in their order, ``out[m:]`` the others.
    """
    c, s = math.cos(theta), math.sin(theta)
    near = np.empty(lo.shape[0], dtype=np.int64)
    count = 0
    for b in range(lo.shape[0]):
        gx, gy = _gap(x, lo[b, 0], hi[b, 0]), _gap(y, lo[b, 1], hi[b, 1])
        if gx * gx + gy * gy <= (radius + reach) ** 2:
            near[count] = b
            count += 1
    best = np.inf
    inside, outside = 0, local.shape[0]
    for i in range(local.shape[0]):
        px = c * local[i, 0] - s * local[i, 1] + x
        py = s * local[i, 0] + c * local[i, 1] + y
        pz = z[i]
        for k in range(count):
            d = _box_sq_distance(px, py, pz, lo, hi, near[k])
            if d < best:
                best = d
        if box_lo[0] <= px <= box_hi[0] and box_lo[1] <= py <= box_hi[1] and box_lo[2] <= pz <= box_hi[2]:
            j = inside
            inside += 1
        else:
            outside -= 1
            j = outside
        out[j, 0], out[j, 1], out[j, 2] = px, py, pz
    return math.sqrt(best), inside


@njit(cache=True)
def point_clearance(
    x: float, y: float, z: float, lo: np.ndarray, hi: np.ndarray, margin: float, field: np.ndarray,
    lattice: np.ndarray, resolution: float, half_diagonal: float, grid_lo: np.ndarray, grid_hi: np.ndarray,
    space_margin: float,
) -> float:
    """Clearance of one point as ``explore.nbv.nbvs.ObstacleField.clearance`` (< 0: collision).

    Boxes: the signed distance to the nearest box (negative inside) minus ``margin``. PVS (``field`` not empty): inside
    the grid the distance field minus ``half_diagonal`` and ``space_margin``, outside the distance to the grid box.
    """
    best = np.inf
    for b in range(lo.shape[0]):
        d = _box_sq_distance(x, y, z, lo, hi, b)
        if d > 0.0:
            signed = math.sqrt(d)
        else:  # inside: minus the depth below the nearest face
            signed = -min(x - lo[b, 0], hi[b, 0] - x, y - lo[b, 1], hi[b, 1] - y, z - lo[b, 2], hi[b, 2] - z)
        if signed < best:
            best = signed
    out = best - margin
    if field.shape[0] > 0:
        inv = 1.0 / resolution
        ix = int(math.floor(x * inv)) - lattice[0]
        iy = int(math.floor(y * inv)) - lattice[1]
        iz = int(math.floor(z * inv)) - lattice[2]
        if 0 <= ix < field.shape[0] and 0 <= iy < field.shape[1] and 0 <= iz < field.shape[2]:
            pvs = field[ix, iy, iz] - half_diagonal - space_margin
        else:
            gx, gy = _gap(x, grid_lo[0], grid_hi[0]), _gap(y, grid_lo[1], grid_hi[1])
            gz = _gap(z, grid_lo[2], grid_hi[2])
            pvs = math.sqrt(gx * gx + gy * gy + gz * gz)
        if pvs < out:
            out = pvs
    return out


@njit(cache=True)
def rigid_clearances(
    local: np.ndarray, bx: float, by: float, btheta: float, lo: np.ndarray, hi: np.ndarray, margin: float,
    field: np.ndarray, lattice: np.ndarray, resolution: float, half_diagonal: float, grid_lo: np.ndarray,
    grid_hi: np.ndarray, space_margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Robot points ``local`` (n, 3, base frame) at base pose (bx, by, btheta): their world x, y, a
    lower bound on each point's clearance, the points' largest distance R from the base axis and
    the smallest bound. With a PVS the clearance is measured between voxel centres (minus half a
    diagonal), so a point may lie up to another half diagonal nearer to an obstacle voxel: the
    bound subtracts it."""
    n = local.shape[0]
    wx, wy, clear = np.empty(n), np.empty(n), np.empty(n)
    c0, s0 = math.cos(btheta), math.sin(btheta)
    radius, least = 0.0, np.inf
    for p in range(n):
        wx[p] = c0 * local[p, 0] - s0 * local[p, 1] + bx
        wy[p] = s0 * local[p, 0] + c0 * local[p, 1] + by
        r = math.sqrt(local[p, 0] * local[p, 0] + local[p, 1] * local[p, 1])
        if r > radius:
            radius = r
        clear[p] = point_clearance(wx[p], wy[p], local[p, 2], lo, hi, margin, field, lattice, resolution,
                                   half_diagonal, grid_lo, grid_hi, space_margin)
        if field.shape[0] > 0:
            clear[p] -= half_diagonal
        if clear[p] < least:
            least = clear[p]
    return wx, wy, clear, radius, least


@njit(cache=True)
def rigid_first_hit(
    z: np.ndarray, wx: np.ndarray, wy: np.ndarray, clear: np.ndarray, radius: float, least: float, bx: float,
    by: float, btheta: float, states: np.ndarray, lo: np.ndarray, hi: np.ndarray, margin: float, field: np.ndarray,
    lattice: np.ndarray, resolution: float, half_diagonal: float, grid_lo: np.ndarray, grid_hi: np.ndarray,
    space_margin: float,
) -> tuple[int, int]:
    """First sample whose base pose ``states[i]`` = (x, y, theta) puts the robot into an obstacle.

    The robot's points are given at the reference base pose (bx, by, btheta) by
    :func:`rigid_clearances` (world ``wx``, ``wy``, heights ``z``, clearance bounds ``clear``).
    A sample moves every point by at most |dc| + R |dtheta| from there, so samples whose bound
    stays below the smallest clearance ``least`` are safe; otherwise the points whose clearance
    is below the bound are moved and tested (:func:`point_clearance` < 0). Returns (sample index
    or -1, samples tested).
    """
    tested = 0
    for i in range(states.shape[0]):
        d_theta = states[i, 2] - btheta
        sx, sy = states[i, 0] - bx, states[i, 1] - by
        bound = math.sqrt(sx * sx + sy * sy) + radius * abs(d_theta)
        if bound < least:
            continue
        tested += 1
        c, s = math.cos(d_theta), math.sin(d_theta)
        for p in range(z.shape[0]):
            if clear[p] >= bound:
                continue
            rx, ry = wx[p] - bx, wy[p] - by
            x = c * rx - s * ry + states[i, 0]
            y = s * rx + c * ry + states[i, 1]
            if point_clearance(x, y, z[p], lo, hi, margin, field, lattice, resolution, half_diagonal,
                               grid_lo, grid_hi, space_margin) < 0.0:
                return i, tested
    return -1, tested
