"""Loading triangle meshes (OBJ with polygons, STL, PLY) as plain vertex/triangle arrays."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from explore.core import Points3, Pose, captured_output


@dataclass(frozen=True)
class TriMesh:
    """A triangle mesh: vertices (n, 3) float64 and triangles (m, 3) int32."""

    vertices: Points3
    triangles: np.ndarray

    def transformed(self, pose: Pose, scale: np.ndarray | float = 1.0) -> TriMesh:
        scaled = self.vertices * np.asarray(scale, dtype=float)
        return TriMesh(scaled @ pose[:3, :3].T + pose[:3, 3], self.triangles)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def to_open3d(self):  # -> open3d.geometry.TriangleMesh
        import open3d as o3d

        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices), o3d.utility.Vector3iVector(self.triangles)
        )
        mesh.compute_vertex_normals()
        return mesh

    def within(self, max_vertices: int, max_triangles: int) -> TriMesh:
        """This mesh, or one within these sizes: duplicate vertices merged (an STL is a triangle soup), then
        Garland-Heckbert quadric decimation (Open3D) until it fits."""
        if len(self.vertices) <= max_vertices and len(self.triangles) <= max_triangles:
            return self
        mesh = self.to_open3d().remove_duplicated_vertices()
        target = int(max_triangles)
        while len(mesh.vertices) > max_vertices or len(mesh.triangles) > max_triangles:
            mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=target)
            target = max(4, target // 2)
        return TriMesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.triangles, dtype=np.int32))

    def triangle_areas(self) -> np.ndarray:
        """(m,) area of every triangle."""
        a, b, c = (self.vertices[self.triangles[:, i]] for i in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def area(self) -> float:
        return float(self.triangle_areas().sum())

    @staticmethod
    def concatenate(meshes: list[TriMesh]) -> TriMesh:
        vertices, triangles, offset = [], [], 0
        for mesh in meshes:
            vertices.append(mesh.vertices)
            triangles.append(mesh.triangles + offset)
            offset += len(mesh.vertices)
        if not vertices:
            return TriMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32))
        return TriMesh(np.vstack(vertices), np.vstack(triangles).astype(np.int32))


def box_mesh(size: np.ndarray) -> TriMesh:
    """Axis-aligned box centred at the origin with full extents ``size``."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_box(*size)
    vertices = np.asarray(mesh.vertices) - np.asarray(size) / 2.0
    return TriMesh(vertices, np.asarray(mesh.triangles, dtype=np.int32))


def cylinder_mesh(radius: float, length: float, resolution: int = 48) -> TriMesh:
    """Closed cylinder along z centred at the origin."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_cylinder(radius, length, resolution)
    return TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles, dtype=np.int32))


def sphere_mesh(radius: float, resolution: int = 24) -> TriMesh:
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_sphere(radius, resolution)
    return TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles, dtype=np.int32))


def read_obj(path: Path) -> TriMesh:
    """Read an OBJ file, fan-triangulating polygons (Open3D drops quads); negative references count back from
    the vertices read so far. Parsed by numpy a block at a time; a line it cannot read is named in the error."""
    with open(path, encoding="utf-8", errors="replace") as handle:
        lines = handle.read().splitlines()
    vertex_rows = [i for i, line in enumerate(lines) if line.startswith("v ")]
    face_rows = [i for i, line in enumerate(lines) if line.startswith("f ")]
    if not vertex_rows or not face_rows:
        raise ValueError(f"{path}: no triangles")
    try:
        vertices = np.loadtxt([lines[i] for i in vertex_rows], usecols=(1, 2, 3), dtype=float, comments=None, ndmin=2)
        tokens = np.array(_OBJ_REF_TAIL.sub("", "\n".join(lines[i] for i in face_rows)).split())
        is_marker = tokens == "f"
        refs = tokens[~is_marker].astype(np.int64)
    except ValueError:
        raise ValueError(_first_bad_obj_line(path, lines)) from None
    starts = np.flatnonzero(is_marker)
    corners = np.diff(np.append(starts, len(tokens))) - 1  # references per face
    first = starts - np.arange(len(starts))  # index of each face's first reference in refs
    # a negative reference counts back from the vertices defined above its face line
    defined = np.searchsorted(np.asarray(vertex_rows), np.asarray(face_rows))
    refs = np.where(refs > 0, refs - 1, np.repeat(defined, corners) + refs)
    fans = np.maximum(corners - 2, 0)  # triangles (0, i, i + 1) of each face's fan
    face = np.repeat(np.arange(len(fans)), fans)
    step = np.arange(len(face)) - np.repeat(np.cumsum(fans) - fans, fans) + 1
    triangles = np.stack([refs[first[face]], refs[first[face] + step], refs[first[face] + step + 1]], axis=1)
    if not len(triangles):
        raise ValueError(f"{path}: no triangles")
    return _checked(TriMesh(vertices, triangles), path)


_OBJ_REF_TAIL = re.compile(r"/\S*")  # the /texture/normal part of a face reference


def _first_bad_obj_line(path: Path, lines: list[str]) -> str:
    """The error of the first vertex or face line that is not numbers (only when numpy's block parse failed)."""
    for number, line in enumerate(lines, 1):
        try:
            if line.startswith("v ") and len([float(x) for x in line.split()[1:4]]) != 3:
                raise ValueError("a vertex needs x, y, z")
            if line.startswith("f "):
                [int(token.split("/")[0]) for token in line.split()[1:]]
        except ValueError as error:
            return f"{path.name} line {number}: {error}"
    return f"{path.name}: not a readable OBJ file"


def _checked(mesh: TriMesh, path: Path) -> TriMesh:
    """A mesh whose vertices are finite, whose faces index existing vertices and which has some area, else
    ValueError."""
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValueError(f"{path.name}: a vertex is not a finite number")
    if mesh.triangles.size and (mesh.triangles.min() < 0 or mesh.triangles.max() >= len(mesh.vertices)):
        raise ValueError(f"{path.name}: a face refers to a vertex that does not exist")
    corners = mesh.vertices[mesh.triangles]
    if not np.any(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])):
        raise ValueError(f"{path.name}: every triangle has zero area (no surface a sensor could see)")
    return TriMesh(mesh.vertices, mesh.triangles.astype(np.int32))


def read_mesh(path: str | Path) -> TriMesh:
    """Read OBJ, STL or PLY into a :class:`TriMesh`."""
    path = Path(path)
    if path.suffix.lower() == ".obj":
        return read_obj(path)
    if path.suffix.lower() not in (".stl", ".ply"):
        raise ValueError(f"{path.name}: unsupported file type {path.suffix!r} (use .obj, .stl or .ply)")
    import open3d as o3d

    with captured_output(stdout=True):  # Open3D's "[Open3D WARNING] Read ... failed" would come before our line
        mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        raise ValueError(f"{path.name}: no triangles (not a readable mesh)")
    return _checked(TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles, dtype=np.int64)), path)
