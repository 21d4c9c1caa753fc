"""Quality features of the surface model (thesis Eq. 4.24-4.28): relative point density, normals and border
flags per vertex and per PVS voxel, the model's summary, and the mesh as PLY and picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from explore.core import Array, Points3, save_mesh_png
from explore.mapping.mesh_holes import (
    edge_table,
)


class SurfaceFeatures:
    """Part of :class:`SurfaceModel`: features, summary and files."""

    def vertex_features(self) -> dict[str, np.ndarray]:
        """Per-vertex features: ``density`` d(v_j) = N_act/N_max ∈ [0, 1] (Eq. 4.24–4.25),
        ``border`` = share of border edges among the vertex's edges (Eq. 4.28 per vertex),
        ``normal`` = unit vertex normal; plus ``n_edges`` and ``n_border`` (edge counts)."""
        if self._cache.features is not None:
            return self._cache.features
        mesh = self.mesh
        n = len(mesh.vertices)
        density = np.zeros(n)
        if n and len(self._keys):
            from scipy.spatial import cKDTree

            tree = cKDTree(self.points)
            count = tree.query_ball_point(mesh.vertices, self.normal_radius, return_length=True)
            density = np.minimum(np.asarray(count, dtype=float) / self.n_max, 1.0)
        edges, counts, _ = edge_table(mesh.triangles)
        n_edges = np.bincount(edges.reshape(-1), minlength=n).astype(float)
        is_border = np.repeat(counts == 1, 2)
        n_border = np.bincount(edges.reshape(-1)[is_border], minlength=n).astype(float)
        border = np.divide(n_border, n_edges, out=np.zeros(n), where=n_edges > 0)
        self._cache.features = {
            "density": density,
            "border": border,
            "normal": self.vertex_normals,
            "n_edges": n_edges,
            "n_border": n_border,
        }
        return self._cache.features

    def mean_density(self) -> float:
        """d̄_m: mean relative point density over all mesh vertices (Eq. 4.24–4.26)."""
        density = self.vertex_features()["density"]
        return float(density.mean()) if len(density) else 0.0

    def voxel_features(
        self, resolution: float, origin: Array | None = None
    ) -> tuple[np.ndarray, Array, Points3, Array]:
        """Features averaged per voxel of edge ``resolution`` (voxel = floor((v − origin)/res)).

        Returns ``voxel_index`` (k, 3) int, ``density`` d̄_i (k,) (Eq. 4.26), ``normal`` n̄_i
        (k, 3) (Eq. 4.27, re-normalised to unit length) and ``border`` b_i =
        N_border/N_total (k,) (Eq. 4.28; each edge counted at both of its end vertices).
        """
        origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)
        mesh = self.mesh
        if len(mesh.vertices) == 0:
            return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros(0)
        feats = self.vertex_features()
        index = np.floor((mesh.vertices - origin) / resolution).astype(np.int64)
        voxels, inverse, count = np.unique(index, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        k = len(voxels)
        density = np.bincount(inverse, feats["density"], k) / count
        normal = np.column_stack([np.bincount(inverse, feats["normal"][:, a], k) for a in range(3)]) / count[:, None]
        norm = np.linalg.norm(normal, axis=1, keepdims=True)
        normal = np.divide(normal, norm, out=np.zeros_like(normal), where=norm > 0)
        n_edges = np.bincount(inverse, feats["n_edges"], k)
        n_border = np.bincount(inverse, feats["n_border"], k)
        border = np.divide(n_border, n_edges, out=np.zeros(k), where=n_edges > 0)
        return voxels, density, normal, border

    # -- export --------------------------------------------------------------------------
    def summary(self) -> dict:
        """Counts and completeness numbers of the current model."""
        mesh = self.mesh
        return {
            "points": len(self),
            "vertices": int(len(mesh.vertices)),
            "triangles": int(len(mesh.triangles)),
            "border_edges": int(len(self.border_edges())),
            "coverage_border": self.coverage_border(),
            "coverage_area": self.coverage_area(),
            "mean_density": self.mean_density(),
            "mean_edge_length": self.mean_edge_length(),
        }

    def save_ply(self, path: str | Path) -> None:
        """Write the mesh with vertex normals as PLY."""
        import open3d as o3d

        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.mesh.vertices), o3d.utility.Vector3iVector(self.mesh.triangles)
        )
        mesh.vertex_normals = o3d.utility.Vector3dVector(self.vertex_normals)
        if not o3d.io.write_triangle_mesh(str(path), mesh):
            raise OSError(f"could not write {path}")

    def save_png(self, path: str | Path, title: str = "") -> None:
        """Shaded snapshot of the mesh."""
        mesh = self.mesh
        text = title or (
            f"{len(mesh.triangles)} triangles, ĉ_m = {self.coverage_area():.3f} (area), "
            f"{self.coverage_border():.3f} (border)"
        )
        save_mesh_png(mesh.vertices, mesh.triangles, path, text)
