"""Surface normals of point clouds: one estimator for segmentation, recognition and registration."""

from __future__ import annotations

import numpy as np

from explore.core import Points3


def estimate_normals(points: Points3, radius: float, viewpoints: Points3 | None = None, max_nn: int = 30) -> Points3:
    """Unit normals by PCA over a ball of ``radius`` (Open3D), oriented towards ``viewpoints``.

    ``viewpoints`` is (n, 3) (per-point sensor origins) or (3,); without it the normals keep
    Open3D's arbitrary sign.
    """
    import open3d as o3d

    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros((0, 3))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn))
    normals = np.asarray(cloud.normals).copy()
    if viewpoints is not None:
        to_view = np.broadcast_to(np.asarray(viewpoints, dtype=float), pts.shape) - pts
        flip = np.einsum("ij,ij->i", normals, to_view) < 0.0
        normals[flip] *= -1.0
    return normals
