"""Kriegel's local registration (thesis Sec. 3.2.3): point-to-point / point-to-plane ICP with correspondences
within a 3 mm radius, 2-3 iterations, pairs whose normals differ by more than 60 deg rejected (keeps thin walls apart);
the bottom-scan match uses 20 mm / 40 iterations."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from explore.core import (
    Array,
    Points3,
    Pose,
    kabsch,
    transform_points,
)
from explore.perception.arrays import as_points, as_pose
from explore.perception.depth_filters import organised_normals
from explore.perception.normals import estimate_normals
from explore.sim import Scan


def scan_points_and_normals(scan: Scan, radius: float = 0.01) -> tuple[Points3, Points3]:
    """World points of a scan and their normals oriented towards the beam origins: the scan's own
    (depth processing), else those of its organised image
    (:func:`organised_normals`; under Kinect artefacts 4.7 deg
    median error against 11 deg, ``benchmarks/depth_processing.py``), a neighbour search of
    ``radius`` where neither gives one."""
    pts = scan.points()
    if scan.normals is not None:
        given = scan.normals[scan.hits]
    elif scan.image_shape is not None:
        given = organised_normals(scan)
    else:
        return pts, estimate_normals(pts, radius, scan.origins[scan.hits])
    missing = ~np.isfinite(given[:, 0])
    if missing.any():
        given = given.copy()
        given[missing] = estimate_normals(pts, radius, scan.origins[scan.hits])[missing]
    return pts, given


@dataclass(frozen=True)
class IcpResult:
    """Outcome of a registration: ``transformation`` maps source points into the target frame.

    ``fitness`` is the fraction of source points with an accepted correspondence in the last
    iteration, ``rmse`` their RMS distance (m), ``iterations`` the number of updates done.
    """

    transformation: Pose
    fitness: float
    rmse: float
    correspondences: int
    iterations: int
    information: Array | None = None  # 6x6, [rot, trans] order (gtsam Pose3 tangent)


def _correspond(
    tree: cKDTree,
    src: Points3,
    src_n: Points3 | None,
    tgt_n: Points3 | None,
    radius: float,
    cos_gate: float,
    k: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest *normal-compatible* target point within ``radius`` for each source point.

    Returns (source indices, target indices, distances). Of the ``k`` nearest neighbours
    inside the radius, the closest one whose normal differs by at most the gate is taken
    (Kriegel: reject correspondences with normals more than 60 deg apart, after Pulli).
    """
    dist, idx = tree.query(src, k=k, distance_upper_bound=radius)
    if k == 1:
        dist, idx = dist[:, None], idx[:, None]
    ok = np.isfinite(dist)
    if src_n is not None and tgt_n is not None and cos_gate > -1.0:
        safe = np.where(ok, idx, 0)
        cos = np.einsum("nkj,nj->nk", tgt_n[safe], src_n)
        ok &= cos >= cos_gate
    has = ok.any(axis=1)
    first = np.argmax(ok, axis=1)
    rows = np.nonzero(has)[0]
    return rows, idx[rows, first[rows]], dist[rows, first[rows]]


def _point_to_plane_step(src: Points3, tgt: Points3, tgt_n: Points3) -> Pose:
    """One linearised point-to-plane update (Chen & Medioni; small-angle solve)."""
    a = np.hstack([np.cross(src, tgt_n), tgt_n])
    b = np.einsum("ij,ij->i", tgt - src, tgt_n)
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
    out[:3, 3] = x[3:]
    return out


def icp_local(
    source_points: Points3,
    source_normals: Points3 | None,
    target_points: Points3,
    target_normals: Points3 | None,
    init: Pose | None = None,
    radius: float = 0.003,
    iterations: int = 3,
    normal_gate_deg: float = 60.0,
    method: str = "point_to_point",
    tolerance: float = 1e-7,
    neighbours: int = 8,
    target_tree: cKDTree | None = None,
) -> IcpResult:
    """Local ICP of a scan to a model (Kriegel thesis Sec. 3.2.3).

    Each iteration pairs every transformed source point with the nearest target point within
    ``radius`` whose normal lies within ``normal_gate_deg`` of the source normal, then solves the
    least-squares rigid transform (``"point_to_point"``: SVD, as the thesis; ``"point_to_plane"``:
    linearised Chen-Medioni with the target normals). The thesis stops after 2-3 iterations
    (3 mm, 60 deg) because running to convergence shrank a model by ~4 mm; the bottom-scan
    match uses ``radius=0.02, iterations=40``. Stops early when an update is below
    ``tolerance`` (m and rad). Normals may be None, which disables the gate.

    Returns
    -------
    IcpResult whose ``transformation`` maps the source into the target frame (includes ``init``).
    """
    src0 = as_points(source_points, "source_points")
    tgt = as_points(target_points, "target_points")
    src_n0 = None if source_normals is None else as_points(source_normals, "source_normals")
    tgt_n = None if target_normals is None else as_points(target_normals, "target_normals")
    if method not in ("point_to_point", "point_to_plane"):
        raise ValueError(f"unknown ICP method {method!r} (valid: point_to_point, point_to_plane)")
    if method == "point_to_plane" and tgt_n is None:
        raise ValueError("point_to_plane ICP needs target normals")
    if not radius > 0.0 or iterations < 0:
        raise ValueError("need radius > 0 and iterations >= 0")
    transform = as_pose(init).copy()
    if len(src0) == 0 or len(tgt) == 0:
        return IcpResult(transform, 0.0, math.inf, 0, 0)
    tree = target_tree if target_tree is not None else cKDTree(tgt)
    cos_gate = math.cos(math.radians(normal_gate_deg)) if normal_gate_deg < 180.0 else -2.0
    k = max(1, min(int(neighbours), len(tgt)))
    done = 0
    rows = np.zeros(0, dtype=np.int64)
    dist = np.zeros(0)
    for _ in range(iterations):
        src = transform_points(transform, src0)
        src_n = None if src_n0 is None else src_n0 @ transform[:3, :3].T
        rows, cols, dist = _correspond(tree, src, src_n, tgt_n, radius, cos_gate, k)
        if len(rows) < 6:
            break
        if method == "point_to_point":
            step = kabsch(src[rows], tgt[cols])
        else:
            step = _point_to_plane_step(src[rows], tgt[cols], tgt_n[cols])
        transform = step @ transform
        done += 1
        angle = np.linalg.norm(Rotation.from_matrix(step[:3, :3]).as_rotvec())
        if np.linalg.norm(step[:3, 3]) < tolerance and angle < tolerance:
            break
    # final correspondence statistics at the returned transform
    src = transform_points(transform, src0)
    src_n = None if src_n0 is None else src_n0 @ transform[:3, :3].T
    rows, cols, dist = _correspond(tree, src, src_n, tgt_n, radius, cos_gate, k)
    rmse = float(np.sqrt(np.mean(dist**2))) if len(rows) else math.inf
    return IcpResult(transform, len(rows) / len(src0), rmse, len(rows), done)
