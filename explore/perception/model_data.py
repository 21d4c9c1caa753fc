"""What a recogniser keeps of a model: dense points with normals for ICP and a sampled set (ModelCloud),
and the descriptors stored in the object database (model_descriptors)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Points3, fibonacci_sphere
from explore.perception.verification import (
    o3d_cloud,
    render_views,
)
from explore.sim import TriMesh


# -- shared model data ----------------------------------------------------------------------
@dataclass
class ModelCloud:
    """A model's surface as seen from around: dense points/normals (ICP) and a sampled set."""

    dense_points: Points3
    dense_normals: Points3
    points: Points3
    normals: Points3
    _tree: Any = field(default=None, repr=False)

    def tree(self):  # -> scipy.spatial.cKDTree
        """kd-tree over the dense points (built on first use)."""
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.dense_points)
        return self._tree


def model_cloud(mesh: TriMesh, sampling: float, views: int = 24, normal_radius: float = 0.01) -> ModelCloud:
    """Union of rendered views from the whole sphere (outward normals), voxel-sampled at ``sampling``."""
    rendered = render_views(mesh, fibonacci_sphere(views), resolution=96, normal_radius=normal_radius)
    pts = np.vstack([v.points for v in rendered])
    nrm = np.vstack([v.normals for v in rendered])
    dense = oriented(o3d_cloud(pts, nrm).voxel_down_sample(0.003))
    sampled = oriented(o3d_cloud(pts, nrm).voxel_down_sample(sampling))
    return ModelCloud(*dense, *sampled)


def has_normal(normals: Points3) -> np.ndarray:
    """Rows whose normal did not vanish (a voxel average of opposite normals on a thin wall is
    zero): only they have a pair feature (PPF)."""
    length = np.linalg.norm(normals, axis=1)
    return np.isfinite(length) & (length > 1e-6)


def oriented(cloud: Any) -> tuple[Points3, Points3]:
    """Points and unit normals of an Open3D cloud, without the points whose normal vanished."""
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    keep = has_normal(normals)
    return points[keep].copy(), normals[keep] / np.linalg.norm(normals[keep], axis=1, keepdims=True)
