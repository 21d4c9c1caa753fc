"""Goerner's Plane ICP (Alg. 2, "2.5D-ICP"): snap the source onto the table plane (z, roll, pitch), then
ICP over (x, y, yaw) only, correspondences found in 3-D."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from explore.core import (
    Array,
    Points3,
    Pose,
    invert,
    transform_points,
)
from explore.perception.arrays import as_points, as_pose
from explore.perception.icp import IcpResult


def _plane(plane: Any) -> tuple[Array, float]:
    """Unit normal and offset of a plane ``n . x + d = 0`` given as (4,)."""
    v = np.asarray(plane, dtype=float).reshape(4)
    norm = np.linalg.norm(v[:3])
    if not np.all(np.isfinite(v)) or norm < 1e-12:
        raise ValueError("a plane is (a, b, c, d) with a finite, non-zero normal")
    return v[:3] / norm, float(v[3] / norm)


def _minimal_rotation(a: Array, b: Array) -> Array:
    """Smallest rotation taking unit vector ``a`` onto unit vector ``b``."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def plane_frame(plane: Any, near: Array | None = None) -> Pose:
    """A frame whose x-y plane is ``plane`` (z = its normal), origin the projection of ``near``."""
    n, d = _plane(plane)
    near = np.zeros(3) if near is None else np.asarray(near, dtype=float)
    origin = near - (n @ near + d) * n
    x = np.cross([0.0, 1.0, 0.0], n) if abs(n[1]) < 0.9 else np.cross(n, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[:3, :3] = np.column_stack([x, np.cross(n, x), n])
    out[:3, 3] = origin
    return out


def snap_to_plane(source_plane: Any, target_plane: Any) -> Pose:
    """Smallest rigid motion putting ``source_plane`` onto ``target_plane`` (z, roll, pitch only)."""
    ns, ds = _plane(source_plane)
    nt, dt = _plane(target_plane)
    r = _minimal_rotation(ns, nt)
    out = np.eye(4)
    out[:3, :3] = r
    # a point on the rotated source plane is R(-ds ns) = -ds nt; move it onto the target plane
    out[:3, 3] = (ds - dt) * nt
    return out


def as_2d_transform(transform: Pose, plane: Any) -> Pose:
    """Goerner's AS2DTRANSFORM: keep the in-plane translation and the yaw about the plane normal."""
    frame = plane_frame(plane)
    local = invert(frame) @ as_pose(transform) @ frame
    yaw = math.atan2(local[1, 0], local[0, 0])
    out = np.eye(4)
    out[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    out[:2, 3] = local[:2, 3]
    return frame @ out @ invert(frame)


def _kabsch_2d(src: Array, tgt: Array) -> Pose:
    """Least-squares 2-D rigid transform (x, y, yaw) on the first two coordinates, as a 4x4."""
    mu_s, mu_t = src.mean(axis=0), tgt.mean(axis=0)
    h = (src - mu_s).T @ (tgt - mu_t)
    yaw = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:2, 3] = mu_t - out[:2, :2] @ mu_s
    return out


def plane_icp(
    source: Points3,
    target: Points3,
    plane: Any,
    source_plane: Any | None = None,
    init: Pose | None = None,
    radius: float | Sequence[float] = (0.05, 0.01),
    iterations: int = 30,
    tolerance: float = 1e-7,
) -> IcpResult:
    """Goerner's Plane ICP (Alg. 2, 2.5D-ICP).

    ``plane`` is the table plane (a, b, c, d) in the target frame. If ``source_plane`` (the
    table as detected in the source, source coordinates) is given, the source (after ``init``)
    is first snapped onto ``plane``, which fixes z, roll and pitch; then ICP with 3-D nearest
    neighbours within ``radius`` solves only for the rigid motion in the plane (x, y, yaw about
    the normal; PCL ``TransformationEstimation2D``). ``radius`` may be a coarse-to-fine
    schedule, up to ``iterations`` per stage: Goerner's 5 cm maximum correspondence distance,
    then 1 cm, which removes most of the bias of partially overlapping views.
    """
    src0 = as_points(source, "source")
    tgt = as_points(target, "target")
    radii = [float(radius)] if np.isscalar(radius) else [float(r) for r in radius]  # type: ignore[arg-type]
    if not radii or min(radii) <= 0.0:
        raise ValueError("need positive correspondence radii")
    transform = as_pose(init).copy()
    if source_plane is not None:
        n_s, d_s = _plane(source_plane)
        # the source plane after init, in target coordinates
        r, t = transform[:3, :3], transform[:3, 3]
        n_w = r @ n_s
        moved = np.append(n_w, d_s - n_w @ t)
        transform = snap_to_plane(moved, plane) @ transform
    if len(src0) == 0 or len(tgt) == 0:
        return IcpResult(transform, 0.0, math.inf, 0, 0)
    frame = plane_frame(plane, tgt.mean(axis=0))
    frame_inv = invert(frame)
    tgt_local = transform_points(frame_inv, tgt)
    tree = cKDTree(tgt_local)
    planar = np.eye(4)  # accumulated 2-D motion in the table frame
    src_local0 = transform_points(frame_inv @ transform, src0)
    done = 0
    for stage_radius in radii:
        for _ in range(iterations):
            src_local = transform_points(planar, src_local0)
            dist, idx = tree.query(src_local, distance_upper_bound=stage_radius)
            ok = np.isfinite(dist)
            if ok.sum() < 3:
                break
            step = _kabsch_2d(src_local[ok, :2], tgt_local[idx[ok], :2])
            planar = step @ planar
            done += 1
            if np.linalg.norm(step[:2, 3]) < tolerance and abs(math.atan2(step[1, 0], step[0, 0])) < tolerance:
                break
    transform = frame @ planar @ frame_inv @ transform
    dist, _ = tree.query(transform_points(planar, src_local0), distance_upper_bound=radii[-1])
    ok = np.isfinite(dist)
    rmse = float(np.sqrt(np.mean(dist[ok] ** 2))) if ok.any() else math.inf
    return IcpResult(transform, float(ok.mean()), rmse, int(ok.sum()), done)
