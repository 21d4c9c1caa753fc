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


def point_clusters(local: np.ndarray, z: np.ndarray, cell: float = 0.1) -> tuple[np.ndarray, ...]:
    """Group base-frame points (n, 2) + heights (n,) by the ``cell``-sized cube they fall in.

    Returns the points and heights sorted by cluster, the clusters' start offsets (m + 1,),
    their centres (m, 3) and the radii (m,) of the balls about those centres that hold them,
    for :func:`planar_points_clearance` to skip whole clusters.
    """
    if len(local) == 0:
        return local, z, np.zeros(1, dtype=np.int64), np.zeros((0, 3)), np.zeros(0)
    cells = np.floor(np.column_stack([local, z]) / cell).astype(np.int64)
    cells -= cells.min(axis=0)
    _, label = np.unique(np.ravel_multi_index(cells.T, cells.max(axis=0) + 1), return_inverse=True)
    order = np.argsort(label, kind="stable")
    local, z, label = local[order], z[order], label[order]
    starts = np.searchsorted(label, np.arange(label[-1] + 2)).astype(np.int64)
    xyz = np.column_stack([local, z])
    lo = np.minimum.reduceat(xyz, starts[:-1])
    hi = np.maximum.reduceat(xyz, starts[:-1])
    centres = 0.5 * (lo + hi)
    radii = np.sqrt(np.maximum.reduceat(((xyz - np.repeat(centres, np.diff(starts), axis=0)) ** 2).sum(axis=1),
                                        starts[:-1]))
    return (np.ascontiguousarray(local), np.ascontiguousarray(z), starts, np.ascontiguousarray(centres),
            np.ascontiguousarray(radii))


@njit(cache=True)
def planar_points_clearance(
    local: np.ndarray, z: np.ndarray, starts: np.ndarray, centres: np.ndarray, radii: np.ndarray, radius: float,
    x: float, y: float, theta: float, lo: np.ndarray, hi: np.ndarray, reach: float, box_lo: np.ndarray,
    box_hi: np.ndarray, out: np.ndarray,
) -> tuple[float, int]:
    """Move base-frame points (n, 2) + heights (n,), grouped by :func:`point_clusters`, to base pose
    (x, y, theta).

    Returns the smallest distance from a point to the boxes [lo_b, hi_b] if it is below ``reach``
    (inf otherwise) and the number m of points inside the box [box_lo, box_hi] (the PVS grid), which
    ``out[:m]`` (n, 3) receives. Boxes whose xy rectangle is farther than ``radius`` (the points'
    largest distance from the base axis) + ``reach`` from (x, y) are skipped, and so is every cluster
    whose ball keeps ``reach`` from the remaining boxes and lies outside the grid: a base far from
    furniture and from the grid costs one pass over the clusters, not over the points.
    """
    c, s = math.cos(theta), math.sin(theta)
    near = np.empty(lo.shape[0], dtype=np.int64)
    count = 0
    for b in range(lo.shape[0]):
        gx, gy = _gap(x, lo[b, 0], hi[b, 0]), _gap(y, lo[b, 1], hi[b, 1])
        if gx * gx + gy * gy <= (radius + reach) ** 2:
            near[count] = b
            count += 1
    best, inside = reach * reach, 0
    for k in range(centres.shape[0]):
        cx = c * centres[k, 0] - s * centres[k, 1] + x
        cy = s * centres[k, 0] + c * centres[k, 1] + y
        cz = centres[k, 2]
        near_box = False
        for j in range(count):
            if _box_sq_distance(cx, cy, cz, lo, hi, near[j]) <= (reach + radii[k]) ** 2:
                near_box = True
                break
        gx, gy, gz = _gap(cx, box_lo[0], box_hi[0]), _gap(cy, box_lo[1], box_hi[1]), _gap(cz, box_lo[2], box_hi[2])
        in_grid = gx * gx + gy * gy + gz * gz <= radii[k] * radii[k]
        if not near_box and not in_grid:
            continue
        for i in range(starts[k], starts[k + 1]):
            px = c * local[i, 0] - s * local[i, 1] + x
            py = s * local[i, 0] + c * local[i, 1] + y
            pz = z[i]
            if near_box:
                for j in range(count):
                    d = _box_sq_distance(px, py, pz, lo, hi, near[j])
                    if d < best:
                        best = d
            if in_grid and box_lo[0] <= px <= box_hi[0] and box_lo[1] <= py <= box_hi[1] \
                    and box_lo[2] <= pz <= box_hi[2]:
                out[inside, 0], out[inside, 1], out[inside, 2] = px, py, pz
                inside += 1
    return (math.sqrt(best) if best < reach * reach else np.inf), inside


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
