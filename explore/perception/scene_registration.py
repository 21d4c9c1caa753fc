"""Pairwise registration of two views of a scene (pose-graph edges): coarse-to-fine point-to-plane ICP with
Open3D on downsampled pyramids, run on one thread (its parallel sums are not repeatable), and the overlap of
two views.

Conventions: poses are 4x4 world_T_frame; a registration result T maps *source* points into the *target*
frame, so for sensor poses T = inv(P_tgt) @ P_src (STYLE Sec. 2.6).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from explore.core import (
    Points3,
    Pose,
    open3d_serial,
    transform_points,
)
from explore.perception.arrays import as_points, as_pose
from explore.perception.icp import IcpResult


def _cloud(points: Points3, voxel: float):  # -> open3d.geometry.PointCloud
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(voxel)
    if len(cloud.points) < 3:  # nothing to register (a view that saw none of the scene's surfaces)
        return cloud
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3.0 * voxel, max_nn=30))
    cloud.orient_normals_towards_camera_location(np.zeros(3))  # clouds are in the sensor frame
    return cloud


def pyramid(points: Points3, voxel: float, scales: Sequence[float]) -> list:
    """Downsampled clouds with normals, one per scale (coarse to fine)."""
    pts = as_points(points, "points")
    return [_cloud(pts, voxel * s) for s in scales]


def register_pair(
    source: Points3 | list,
    target: Points3 | list,
    init: Pose | None = None,
    voxel: float = 0.01,
    scales: Sequence[float] = (4.0, 2.0, 1.0),
    max_iterations: int = 30,
) -> IcpResult:
    """Coarse-to-fine point-to-plane ICP (Open3D) between two clouds in their sensor frames.

    Each scale downsamples to ``voxel * s`` and pairs points within ``2.5 * voxel * s``
    (``source`` / ``target`` may also be precomputed pyramids from ``pyramid``). The result
    carries Open3D's 6x6 information matrix at the finest scale ([rot, trans], the gtsam
    ``Pose3`` tangent order) divided by the number of correspondences.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src_pyr = source if isinstance(source, list) else pyramid(source, voxel, scales)
    tgt_pyr = target if isinstance(target, list) else pyramid(target, voxel, scales)
    transform = as_pose(init).copy()
    result = None
    with open3d_serial():  # its threads sum the normal equations in a varying order
        for s, src_c, tgt_c in zip(scales, src_pyr, tgt_pyr, strict=True):
            result = reg.registration_icp(
                src_c, tgt_c, 2.5 * voxel * s, transform, reg.TransformationEstimationPointToPlane(),
                reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=max_iterations),
            )
            transform = np.asarray(result.transformation).copy()
        assert result is not None
        distance = 2.5 * voxel * scales[-1]
        info = np.asarray(reg.get_information_matrix_from_point_clouds(src_pyr[-1], tgt_pyr[-1], distance,
                                                                       transform))
    count = max(len(result.correspondence_set), 1)
    return IcpResult(
        transform, float(result.fitness), float(result.inlier_rmse), len(result.correspondence_set),
        max_iterations * len(scales), info / count,
    )


def overlap(source: Points3, target: Points3, transform: Pose, distance: float) -> float:
    """Fraction of ``source`` points (moved by ``transform``) within ``distance`` of ``target``."""
    if len(source) == 0 or len(target) == 0:
        return 0.0
    dist, _ = cKDTree(target).query(transform_points(transform, source), distance_upper_bound=distance)
    return float(np.isfinite(dist).mean())
