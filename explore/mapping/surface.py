"""Incremental surface model: a triangle mesh with border edges, holes and quality features.

The model keeps two things, both restricted to the region of interest (a pass-through
filter that also drops the support the object stands on):

* a **density-limited point set** (thesis §3.3.1, stage 1): one running-mean point per cell
  of edge ``point_spacing`` (R_r); it serves the relative point density d(v) (Eq. 4.24–4.26);
* a **truncated signed distance grid** over the region (dense, voxel ``voxel_size``) fused
  from point + sensor-origin pairs: grid nodes around each beam, from ``mesh_radius`` in
  front of the measured point to ``behind`` behind it, get the signed distance to the
  point's PCA tangent plane (normal oriented to the sensor), with fading weight behind the
  surface so thin walls survive. The mesh is extracted with *surface nets* (one vertex per
  sign-changing cube, one quad per sign-changing grid edge): only cubes whose 8 corners were
  observed produce geometry, so the mesh is closed wherever the surface was observed and
  ends in **border edges where it was not**. Triangles at non-manifold edges are dropped and
  loops of ≤ ``fill_max_edges`` edges (sub-voxel artifacts) are closed. Mean edge length is
  ≈ 0.9 × ``voxel_size`` (3.1 mm by default).

Completeness follows Kriegel: ĉ_m = 1 − n_border/n_total (IROS Eq. 3) and
ĉ_m = A_filled/(A_filled + A_empty) with hole fans (thesis Eq. 4.35–4.37). Per-vertex and
per-voxel features d̄_i, n̄_i, b_i (Eq. 4.24–4.28) feed the PVS.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from explore.core import Array, Points3
from explore.sim import TriMesh

if TYPE_CHECKING:
    from explore.sim import Scan

__all__ = [
    "Hole",
    "SurfaceModel",
    "border_edges",
    "boundary_loops",
    "coverage_area",
    "coverage_border",
    "edge_table",
    "hole_fan_area",
    "holes_of",
    "mesh_edge_lengths",
    "vertex_normals_of",
]


# ---------------------------------------------------------------------------------------
# pure mesh functions (any TriMesh)
# ---------------------------------------------------------------------------------------
def _half_edges(triangles: np.ndarray) -> np.ndarray:
    """Directed half-edges (3m, 2) in triangle order: (a,b), (b,c), (c,a) per triangle."""
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    return np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1).reshape(-1, 2)


def edge_table(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges of a mesh.

    Returns
    -------
    edges : (e, 2) int64, sorted vertex pairs (lower index first)
    counts : (e,) int64, number of triangles adjacent to each edge
    half_to_edge : (3m,) int64, edge index of every half-edge of :func:`_half_edges`
    """
    half = _half_edges(triangles)
    if len(half) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    key = np.sort(half, axis=1)
    edges, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return edges, counts, inverse.reshape(-1)


def border_edges(triangles: np.ndarray, return_faces: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Border edges (k, 2): edges with exactly one adjacent triangle (thesis Eq. 4.1).

    Each is directed as in its triangle (a→b), so walking them follows the mesh boundary
    with the surface on the left (seen from the front side). With ``return_faces`` also the
    index (k,) of the one adjacent triangle (the side that is present, Table 4.1).
    """
    half = _half_edges(triangles)
    if len(half) == 0:
        empty = np.zeros((0, 2), np.int64)
        return (empty, np.zeros(0, np.int64)) if return_faces else empty
    _, counts, inverse = edge_table(triangles)
    is_border = counts[inverse] == 1
    if return_faces:
        return half[is_border], np.flatnonzero(is_border) // 3
    return half[is_border]


def coverage_border(triangles: np.ndarray) -> float:
    """ĉ_m = 1 − n_border / n_total over undirected edges (IROS Eq. 3); 0 for no mesh."""
    _, counts, _ = edge_table(triangles)
    if len(counts) == 0:
        return 0.0
    return float(1.0 - np.count_nonzero(counts == 1) / len(counts))


def boundary_loops(triangles: np.ndarray, closed_only: bool = False) -> list[np.ndarray]:
    """Boundary walks along the border edges (thesis §4.2.1/§4.4), as vertex index arrays.

    Each walk follows the border half-edges in triangle direction. A walk that returns to
    its first vertex is a closed loop (a hole; the first vertex is not repeated); a walk that
    gets stuck (non-manifold or inconsistently oriented border) is returned open. At a
    vertex touched by several loops (a pinch vertex) the closed walk is split into simple
    loops. ``closed_only`` drops open walks.
    """
    border = border_edges(triangles)
    if len(border) == 0:
        return []
    order = np.argsort(border[:, 0], kind="stable")
    starts = border[order, 0]
    used = np.zeros(len(border), dtype=bool)
    loops: list[np.ndarray] = []

    def outgoing(vertex: int) -> int:
        lo, hi = np.searchsorted(starts, [vertex, vertex + 1])
        for slot in range(lo, hi):
            if not used[order[slot]]:
                return int(order[slot])
        return -1

    for first in range(len(border)):
        if used[first]:
            continue
        used[first] = True
        walk = [int(border[first, 0])]
        head = int(border[first, 1])
        closed = False
        while True:
            if head == walk[0]:
                closed = True
                break
            walk.append(head)
            nxt = outgoing(head)
            if nxt < 0:
                break
            used[nxt] = True
            head = int(border[nxt, 1])
        if closed:
            loops.extend(_split_at_repeats(walk))
        elif not closed_only:
            loops.append(np.asarray(walk, dtype=np.int64))
    return loops


def _split_at_repeats(walk: list[int]) -> list[np.ndarray]:
    """Split a closed walk that passes a vertex twice (pinch vertex) into simple loops."""
    loops: list[np.ndarray] = []
    stack: list[int] = []
    where: dict[int, int] = {}
    for vertex in walk:
        if vertex in where:
            cut = where[vertex]
            loops.append(np.asarray(stack[cut:], dtype=np.int64))
            for v in stack[cut + 1 :]:
                del where[v]
            del stack[cut + 1 :]
        else:
            where[vertex] = len(stack)
            stack.append(vertex)
    loops.append(np.asarray(stack, dtype=np.int64))
    return [loop for loop in loops if len(loop) >= 3]


def hole_fan_area(vertices: Points3, loop: np.ndarray) -> float:
    """Area of the fan from the loop centre c_h: ½ Σ‖(v_{i−1} − c_h) × (v_i − c_h)‖ (Eq. 4.37)."""
    ring = np.asarray(vertices)[np.asarray(loop)]
    if len(ring) < 3:
        return 0.0
    centre = ring.mean(axis=0)
    a = ring - centre
    b = np.roll(a, -1, axis=0)
    return float(0.5 * np.linalg.norm(np.cross(a, b), axis=1).sum())


def _triangle_areas(vertices: Points3, triangles: np.ndarray) -> Array:
    if len(triangles) == 0:
        return np.zeros(0)
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def vertex_normals_of(vertices: Points3, triangles: np.ndarray) -> Points3:
    """Area-weighted unit vertex normals (zero for unreferenced vertices)."""
    normals = np.zeros((len(vertices), 3))
    if len(triangles):
        a, b, c = (vertices[triangles[:, i]] for i in range(3))
        face = np.cross(b - a, c - a)
        for i in range(3):
            for axis in range(3):
                normals[:, axis] += np.bincount(triangles[:, i], face[:, axis], minlength=len(vertices))
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, norm, out=np.zeros_like(normals), where=norm > 0)


def mesh_edge_lengths(vertices: Points3, triangles: np.ndarray) -> Array:
    """Lengths of the undirected edges of a mesh."""
    edges, _, _ = edge_table(triangles)
    return np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)


@dataclass(frozen=True)
class Hole:
    """A closed boundary loop (thesis §4.4).

    Attributes
    ----------
    loop : (k,) int, vertex indices in walking order
    centre : (3,) c_h, mean of the loop vertices
    normal : (3,) n_h, PCA plane normal of the loop vertices (Eq. 4.19–4.21 applied to
        positions), oriented out of the object (towards where a sensor should look from)
    perimeter : float, loop length (m)
    area : float, fan area A_hole (Eq. 4.37, m²)
    far_vertex : (3,) v_max, loop vertex farthest from c_h (hole direction d_h, Eq. 4.22)
    radius : float, ‖v_max − c_h‖
    """

    loop: np.ndarray
    centre: np.ndarray
    normal: np.ndarray
    perimeter: float
    area: float
    far_vertex: np.ndarray
    radius: float

    @property
    def size(self) -> int:
        """Number of border edges |E_H| of the loop."""
        return len(self.loop)


def _hole(vertices: Points3, loop: np.ndarray, normals: Points3 | None) -> Hole:
    ring = vertices[loop]
    centre = ring.mean(axis=0)
    centred = ring - centre
    _, vectors = np.linalg.eigh(centred.T @ centred / len(ring))
    normal = vectors[:, 0]
    # the loop runs with the surface on its left, so its vector area points into the object
    vector_area = 0.5 * np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)
    sign = -float(normal @ vector_area)
    if abs(sign) < 1e-12 and normals is not None:
        sign = float(normal @ normals[loop].sum(axis=0))
    if sign < 0:
        normal = -normal
    distance = np.linalg.norm(centred, axis=1)
    far = int(np.argmax(distance))
    perimeter = float(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1).sum())
    return Hole(
        loop=loop,
        centre=centre,
        normal=normal,
        perimeter=perimeter,
        area=hole_fan_area(vertices, loop),
        far_vertex=ring[far].copy(),
        radius=float(distance[far]),
    )


def holes_of(
    vertices: Points3,
    triangles: np.ndarray,
    max_perimeter: float | None = None,
    min_edges: int = 3,
    max_edges: int | None = None,
    normals: Points3 | None = None,
) -> list[Hole]:
    """Closed boundary loops of a mesh as :class:`Hole` (h_min ≤ |E_H| ≤ h_max, §4.4)."""
    vertices = np.asarray(vertices, dtype=float)
    out = []
    for loop in boundary_loops(triangles, closed_only=True):
        if len(loop) < min_edges or (max_edges is not None and len(loop) > max_edges):
            continue
        hole = _hole(vertices, loop, normals)
        if max_perimeter is None or hole.perimeter <= max_perimeter:
            out.append(hole)
    return out


def coverage_area(vertices: Points3, triangles: np.ndarray, max_perimeter: float | None = None) -> float:
    """ĉ_m = A_filled / (A_filled + A_empty) with A_empty = Σ hole fans (Eq. 4.35–4.37).

    Every closed border loop counts as a hole (the opening at the support too, so 100 % is
    out of reach for an object on a table); ``max_perimeter`` ignores larger loops.
    """
    vertices = np.asarray(vertices, dtype=float)
    filled = float(_triangle_areas(vertices, np.asarray(triangles)).sum())
    if filled <= 0.0:
        return 0.0
    empty = sum(h.area for h in holes_of(vertices, triangles, max_perimeter=max_perimeter))
    return filled / (filled + empty)


# ---------------------------------------------------------------------------------------
# surface nets on a signed distance grid
# ---------------------------------------------------------------------------------------
_CUBE_CORNERS = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])
_CUBE_EDGES = np.array(
    [(a, b) for a in range(8) for b in range(a + 1, 8) if np.abs(_CUBE_CORNERS[a] - _CUBE_CORNERS[b]).sum() == 1]
)


def surface_nets(sdf: np.ndarray, valid: np.ndarray) -> tuple[Points3, np.ndarray]:
    """Naive surface nets of the zero level of ``sdf`` (negative inside) where ``valid``.

    Returns vertices in grid-index coordinates (float) and triangles oriented with their
    normal towards positive ``sdf``. A cube makes a vertex only if its 8 corners are valid;
    a grid edge with a sign change makes a quad only if its 4 cubes have vertices.
    """
    shape = np.array(sdf.shape)
    if np.any(shape < 2):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    inside = sdf < 0
    cs = tuple(shape - 1)
    all_valid = np.ones(cs, dtype=bool)
    any_in = np.zeros(cs, dtype=bool)
    all_in = np.ones(cs, dtype=bool)
    for dx, dy, dz in _CUBE_CORNERS:
        sl = (slice(dx, dx + cs[0]), slice(dy, dy + cs[1]), slice(dz, dz + cs[2]))
        all_valid &= valid[sl]
        any_in |= inside[sl]
        all_in &= inside[sl]
    active = all_valid & any_in & ~all_in
    cubes = np.argwhere(active)
    if len(cubes) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    corner_idx = cubes[:, None, :] + _CUBE_CORNERS[None]  # (n, 8, 3)
    values = sdf[corner_idx[..., 0], corner_idx[..., 1], corner_idx[..., 2]].astype(np.float64)
    va, vb = values[:, _CUBE_EDGES[:, 0]], values[:, _CUBE_EDGES[:, 1]]  # (n, 12)
    crossing = (va < 0) != (vb < 0)
    t = np.where(crossing, va / np.where(crossing, va - vb, 1.0), 0.0)
    pa = _CUBE_CORNERS[_CUBE_EDGES[:, 0]].astype(float)  # (12, 3)
    pb = _CUBE_CORNERS[_CUBE_EDGES[:, 1]].astype(float)
    points = pa[None] + t[..., None] * (pb - pa)[None]  # (n, 12, 3)
    count = crossing.sum(axis=1)
    local = (points * crossing[..., None]).sum(axis=1) / count[:, None]
    vertices = cubes + local
    cube_id = np.full(cs, -1, dtype=np.int64)
    cube_id[cubes[:, 0], cubes[:, 1], cubes[:, 2]] = np.arange(len(cubes))

    quads = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3  # u × v = axis
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        change = (inside[tuple(lo)] != inside[tuple(hi)]) & valid[tuple(lo)] & valid[tuple(hi)]
        # the four cubes around an edge need u-1 and v-1 >= 0 and u, v < cs
        change[tuple(slice(0, 1) if d == u else slice(None) for d in range(3))] = False
        change[tuple(slice(0, 1) if d == v else slice(None) for d in range(3))] = False
        nodes = np.argwhere(change)
        keep = (nodes[:, u] < cs[u]) & (nodes[:, v] < cs[v])
        nodes = nodes[keep]
        if len(nodes) == 0:
            continue
        corners = []
        for du, dv in ((-1, -1), (0, -1), (0, 0), (-1, 0)):  # counter-clockwise in (u, v)
            c = nodes.copy()
            c[:, u] += du
            c[:, v] += dv
            corners.append(cube_id[c[:, 0], c[:, 1], c[:, 2]])
        quad = np.stack(corners, axis=1)
        complete = np.all(quad >= 0, axis=1)
        quad, nodes = quad[complete], nodes[complete]
        nodes_in = inside[nodes[:, 0], nodes[:, 1], nodes[:, 2]]
        # inside at the lower node -> outward normal along +axis -> keep CCW order
        quad = np.where(nodes_in[:, None], quad, quad[:, ::-1])
        quads.append(quad)
    if not quads:
        return vertices, np.zeros((0, 3), np.int64)
    quad = np.vstack(quads)
    p = vertices[quad]
    d02 = np.sum((p[:, 0] - p[:, 2]) ** 2, axis=1)
    d13 = np.sum((p[:, 1] - p[:, 3]) ** 2, axis=1)
    split02 = d02 <= d13
    tri_a = np.where(split02[:, None], quad[:, [0, 1, 2]], quad[:, [0, 1, 3]])
    tri_b = np.where(split02[:, None], quad[:, [0, 2, 3]], quad[:, [1, 2, 3]])
    return vertices, np.vstack([tri_a, tri_b])


def manifold_part(triangles: np.ndarray) -> np.ndarray:
    """Drop triangles at non-manifold edges (> 2 triangles) or at edges whose two triangles
    disagree in orientation, so every border vertex has as many in- as outgoing border
    edges and boundary walks close."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(triangles) == 0:
        return triangles
    half = _half_edges(triangles)
    _, counts, inverse = edge_table(triangles)
    forward = (half[:, 0] < half[:, 1]).astype(np.int64)
    n_forward = np.bincount(inverse, forward, len(counts))
    bad_edge = (counts > 2) | ((counts == 2) & (n_forward != 1))
    bad_triangle = bad_edge[inverse].reshape(-1, 3).any(axis=1)
    return triangles[~bad_triangle]


def fill_small_holes(triangles: np.ndarray, max_edges: int) -> np.ndarray:
    """Close boundary loops of at most ``max_edges`` edges with a fan (extraction artifacts
    below the grid resolution); fills that would make an edge non-manifold are skipped."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if max_edges < 3 or len(triangles) == 0:
        return triangles
    fills = []
    for loop in boundary_loops(triangles, closed_only=True):
        if 3 <= len(loop) <= max_edges:
            i = np.arange(1, len(loop) - 1)
            fills.append(np.column_stack([np.full(len(i), loop[0]), loop[i + 1], loop[i]]))
    if not fills:
        return triangles
    fill = np.vstack(fills)
    merged = np.vstack([triangles, fill])
    kept = manifold_part(merged)
    if len(kept) == len(merged):
        return merged
    # keep the original triangles and only the fills that stay manifold
    _, counts, inverse = edge_table(merged)
    bad_triangle = (counts[inverse] > 2).reshape(-1, 3).any(axis=1)
    bad_triangle[: len(triangles)] = False
    return manifold_part(merged[~bad_triangle])


def _drop_small_components(vertices: Points3, triangles: np.ndarray, min_triangles: int) -> tuple[Points3, np.ndarray]:
    """Remove connected components with fewer than ``min_triangles`` and unused vertices."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(triangles) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    if min_triangles > 1:
        n = len(vertices)
        rows = np.concatenate([triangles[:, 0], triangles[:, 1]])
        cols = np.concatenate([triangles[:, 1], triangles[:, 2]])
        graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n, n))
        _, label = connected_components(graph, directed=False)
        tri_label = label[triangles[:, 0]]
        size = np.bincount(tri_label, minlength=label.max() + 1)
        triangles = triangles[size[tri_label] >= min_triangles]
    used = np.zeros(len(vertices), dtype=bool)
    used[triangles.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return vertices[used], remap[triangles]


# ---------------------------------------------------------------------------------------
# the incremental model
# ---------------------------------------------------------------------------------------
@dataclass
class _Cache:
    mesh: TriMesh | None = None
    normals: Points3 | None = None
    vertex_scan: np.ndarray | None = None
    features: dict[str, np.ndarray] | None = None
    extra: dict[str, object] = field(default_factory=dict)


class SurfaceModel:
    """Triangle mesh of the region of interest, built incrementally from scans.

    Parameters
    ----------
    region_min, region_max : (3,) corners of the region of interest (world frame, m).
    point_spacing : R_r, cell edge of the density-limited point set (m).
    normal_radius : R_n, neighbourhood radius of the point density d(v) (Eq. 4.24) (m).
    mesh_radius : front truncation band of the signed distance (m); a measurement shapes the
        mesh within this distance, like R_m of the streaming triangulation.
    voxel_size : grid spacing of the signed distance grid; mesh edges are ≈ 0.9 × this (m).
    behind : how far behind a measured point the grid is marked inside (m); short so that
        thin walls scanned from both sides keep both faces. Default 1.75 voxels.
    min_weight : summed sample weight a grid node needs to count as observed.
    behind_weight : weight of a sample at the far end of the behind band (it falls linearly
        from 1 at the surface), so evidence from the other side of a thin wall wins.
    splat : update the 8 grid nodes around every band sample (no gaps between beams).
    sample_step : spacing of the band samples along the normal, in voxels.
    fill_max_edges : boundary loops of at most this many edges are closed (extraction
        artifacts smaller than a voxel); 0 keeps every loop.
    point_to_plane : signed distance to the PCA plane of the measured point (radius R_n)
        instead of the projective distance along the beam (more accurate at oblique incidence).
    merge_scan_points : fuse one mean point per R_r cell of each integration (weighted by its
        count) instead of every return: same result, several times faster for dense scans.
    grid_floor : grid nodes lower than ``region_min[2] + grid_floor`` never carry surface.
    floor_clearance : points lower than ``region_min[2] + floor_clearance`` are dropped, so
        noisy returns from the support's top face stay out (m); :meth:`integrate` also drops
        points closer to the floor than 3 σ of their height noise.
    min_component : connected mesh pieces with fewer triangles are dropped (noise specks).
    max_grid_nodes : the voxel size grows if the region would need more grid nodes
        (13 bytes per node; the bunny region needs 0.4 M at 3.5 mm).
    """

    def __init__(
        self,
        region_min: Array,
        region_max: Array,
        point_spacing: float = 0.002,
        normal_radius: float = 0.006,
        mesh_radius: float = 0.008,
        voxel_size: float = 0.0035,
        behind: float | None = None,
        min_weight: float = 0.05,
        behind_weight: float = 0.1,
        splat: bool = True,
        fill_max_edges: int = 6,
        point_to_plane: bool = True,
        merge_scan_points: bool = True,
        sample_step: float = 1.0,
        floor_clearance: float = 0.0015,
        grid_floor: float = 0.0,
        min_component: int = 30,
        max_grid_nodes: int = 8_000_000,
    ) -> None:
        self.region_min = np.asarray(region_min, dtype=float).copy()
        self.region_max = np.asarray(region_max, dtype=float).copy()
        if self.region_min.shape != (3,) or np.any(self.region_max <= self.region_min):
            raise ValueError("region_max must exceed region_min in every axis")
        self.point_spacing = float(point_spacing)
        self.normal_radius = float(normal_radius)
        self.mesh_radius = float(mesh_radius)
        extent = self.region_max - self.region_min
        voxel = float(voxel_size)
        while np.prod(np.ceil(extent / voxel) + 3) > max_grid_nodes:
            voxel *= 1.25
        self.voxel_size = voxel
        self.behind = float(behind) if behind is not None else 1.75 * voxel
        self.min_weight = float(min_weight)
        self.behind_weight = float(behind_weight)
        self.splat = bool(splat)
        self.fill_max_edges = int(fill_max_edges)
        self.point_to_plane = bool(point_to_plane)
        self.merge_scan_points = bool(merge_scan_points)
        self.sample_step = float(sample_step)
        self.floor_clearance = float(floor_clearance)
        self.grid_floor = float(grid_floor)
        self.min_component = int(min_component)
        # grid nodes at origin + i * voxel, one node of padding around the region
        self.grid_origin = self.region_min - voxel
        self.grid_shape = tuple(int(n) for n in np.ceil(extent / voxel).astype(int) + 3)
        self._sdf_sum = np.zeros(self.grid_shape, dtype=np.float32)
        self._weight = np.zeros(self.grid_shape, dtype=np.float32)
        self._stamp = np.full(self.grid_shape, -1, dtype=np.int32)
        lo = self.region_min + np.array([0.0, 0.0, self.grid_floor])
        axes = [self.grid_origin[a] + np.arange(self.grid_shape[a]) * voxel for a in range(3)]
        inside = [(axes[a] >= lo[a] - 1e-9) & (axes[a] <= self.region_max[a] + 1e-9) for a in range(3)]
        self._region_nodes = inside[0][:, None, None] & inside[1][None, :, None] & inside[2][None, None, :]
        # density-limited point set: sorted cell keys, running sums and counts
        self._cell_origin = self.region_min.copy()
        self._cell_dims = np.ceil(extent / self.point_spacing).astype(np.int64) + 1
        self._keys = np.zeros(0, dtype=np.int64)
        self._psum = np.zeros((0, 3))
        self._vsum = np.zeros((0, 3))
        self._pcount = np.zeros(0, dtype=np.int64)
        self.n_scans = 0
        self._cache = _Cache()

    # -- input ---------------------------------------------------------------------------
    def inside_region(self, points: Points3, clearance: Array | float | None = None) -> np.ndarray:
        """Pass-through filter: mask of points inside the region and higher than
        ``region_min[2] + clearance`` (default ``floor_clearance``) above its floor."""
        clearance = self.floor_clearance if clearance is None else clearance
        inside = np.all((points >= self.region_min) & (points <= self.region_max), axis=1)
        return inside & (points[:, 2] >= self.region_min[2] + clearance)

    def integrate(self, scan: Scan) -> dict:
        """Add the returns of ``scan`` that fall inside the region."""
        hit = scan.hits
        return self.integrate_points(scan.points(), scan.origins[hit], scan.sigmas[hit])

    def integrate_points(self, points: Points3, sensor_origins: Points3, sigmas: Array | None = None) -> dict:
        """Add measured ``points`` (n, 3) seen from ``sensor_origins`` ((n, 3) or (3,)).

        With range ``sigmas`` (n,) a point must clear the floor by 3 σ of its height noise
        (σ · |d_z|) as well, so noisy returns from the support's top stay out.
        """
        start = time.perf_counter()
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        origins = np.broadcast_to(np.asarray(sensor_origins, dtype=float), points.shape)
        finite = np.all(np.isfinite(points), axis=1) & np.all(np.isfinite(origins), axis=1)
        points = np.where(finite[:, None], points, np.inf)
        clearance: Array | float = self.floor_clearance
        if sigmas is not None:
            ray = points - origins
            dz = np.abs(ray[:, 2]) / np.maximum(np.linalg.norm(ray, axis=1), 1e-12)
            sig = np.nan_to_num(np.broadcast_to(np.asarray(sigmas, dtype=float), len(points)))
            clearance = np.maximum(self.floor_clearance, 3.0 * sig * dz)
        keep = finite & self.inside_region(points, clearance)
        points, origins = points[keep], origins[keep]
        before = len(self._keys)
        if len(points):
            self._add_points(points, origins)
            if self.merge_scan_points:
                self._fuse(*self._merge_cells(points, origins))
            else:
                self._fuse(points, origins, np.ones(len(points)))
        self.n_scans += 1
        self._cache = _Cache()
        return {
            "points_in": int(len(points)),
            "points_new": int(len(self._keys) - before),
            "points_total": int(len(self._keys)),
            "integrate_s": time.perf_counter() - start,
        }

    def _add_points(self, points: Points3, origins: Points3) -> None:
        cell = np.floor((points - self._cell_origin) / self.point_spacing).astype(np.int64)
        cell = np.clip(cell, 0, self._cell_dims - 1)
        keys = np.ravel_multi_index(cell.T, tuple(self._cell_dims))
        view = origins - points
        view /= np.linalg.norm(view, axis=1, keepdims=True) + 1e-12
        all_keys = np.concatenate([self._keys, keys])
        uniq, inverse = np.unique(all_keys, return_inverse=True)
        psum = np.zeros((len(uniq), 3))
        vsum = np.zeros((len(uniq), 3))
        for axis in range(3):
            psum[:, axis] = np.bincount(inverse, np.concatenate([self._psum[:, axis], points[:, axis]]), len(uniq))
            vsum[:, axis] = np.bincount(inverse, np.concatenate([self._vsum[:, axis], view[:, axis]]), len(uniq))
        count = np.bincount(inverse, np.concatenate([self._pcount, np.ones(len(keys), np.int64)]), len(uniq))
        self._keys, self._psum, self._vsum, self._pcount = uniq, psum, vsum, count.astype(np.int64)

    def _merge_cells(self, points: Points3, origins: Points3) -> tuple[Points3, Points3, Array]:
        """One mean point, mean origin and count per R_r cell of this integration's points."""
        cell = np.floor((points - self._cell_origin) / self.point_spacing).astype(np.int64)
        cell = np.clip(cell, 0, self._cell_dims - 1)
        keys = np.ravel_multi_index(cell.T, tuple(self._cell_dims))
        _, inverse, count = np.unique(keys, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        k = len(count)
        mean_p = np.column_stack([np.bincount(inverse, points[:, a], k) for a in range(3)]) / count[:, None]
        mean_o = np.column_stack([np.bincount(inverse, origins[:, a], k) for a in range(3)]) / count[:, None]
        return mean_p, mean_o, count.astype(float)

    def _fuse(self, points: Points3, origins: Points3, point_weight: Array) -> None:
        """Truncated signed distance update around every (merged) measurement."""
        ray = points - origins
        rng = np.linalg.norm(ray, axis=1)
        ok = rng > 1e-9
        points, origins, ray, rng, point_weight = points[ok], origins[ok], ray[ok], rng[ok], point_weight[ok]
        direction = ray / rng[:, None]
        step = self.sample_step * self.voxel_size
        offsets = np.arange(-self.behind, self.mesh_radius + step, step)  # >0: towards the sensor
        # march along the surface normal (full band at any incidence) or back along the beam
        normal = self._scan_normals(points, direction) if self.point_to_plane else -direction
        samples = points[:, None, :] + offsets[None, :, None] * normal[:, None, :]
        grid = (samples - self.grid_origin) / self.voxel_size
        if self.splat:  # the 8 nodes around every sample, so no node next to a beam is missed
            base = np.floor(grid).astype(np.int64).reshape(-1, 1, 3)
            node = (base + _CUBE_CORNERS[None]).reshape(-1, 3)
            per_beam = len(offsets) * 8
        else:
            node = np.rint(grid).astype(np.int64).reshape(-1, 3)
            per_beam = len(offsets)
        inside = np.all((node >= 0) & (node < np.array(self.grid_shape)), axis=1)
        beam = np.repeat(np.arange(len(points)), per_beam)
        node, beam = node[inside], beam[inside]
        flat = np.ravel_multi_index(node.T, self.grid_shape)
        # one update per (beam, node)
        pair = np.sort(flat * len(points) + beam)  # sort + diff: faster than np.unique here
        pair = pair[np.concatenate([[True], pair[1:] != pair[:-1]])]
        flat, beam = pair // len(points), pair % len(points)
        centre = self.grid_origin + np.column_stack(np.unravel_index(flat, self.grid_shape)) * self.voxel_size
        if self.point_to_plane:  # exact for locally planar surfaces, also beside the beam
            sdf = np.einsum("ij,ij->i", centre - points[beam], normal[beam])
        else:  # projective distance along the beam
            sdf = rng[beam] - np.einsum("ij,ij->i", centre - origins[beam], direction[beam])
        band = (sdf >= -self.behind) & (sdf <= self.mesh_radius)
        flat, sdf = flat[band], sdf[band]
        # behind the surface the evidence fades, so thin walls seen from both sides survive
        weight = np.where(sdf >= 0.0, 1.0, np.maximum(1.0 + sdf / self.behind, self.behind_weight))
        weight = weight * point_weight[beam[band]]
        total = self._sdf_sum.size
        self._sdf_sum.reshape(-1)[:] += np.bincount(flat, weight * sdf, total).astype(np.float32)
        self._weight.reshape(-1)[:] += np.bincount(flat, weight, total).astype(np.float32)
        self._stamp.reshape(-1)[flat] = self.n_scans

    def _scan_normals(self, points: Points3, direction: Points3) -> Points3:
        """PCA normals of one integration's points (radius R_n), oriented towards the sensor;
        the beam direction where a point has too few neighbours."""
        import open3d as o3d

        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(self.normal_radius, 24))
        normal = np.asarray(cloud.normals)
        if len(normal) != len(points):
            return -direction
        flip = np.einsum("ij,ij->i", normal, direction) > 0
        normal[flip] *= -1.0
        # grazing or unreliable normals: fall back towards the beam
        cos = -np.einsum("ij,ij->i", normal, direction)
        weak = ~np.isfinite(cos) | (cos < 0.05)
        normal[weak] = -direction[weak]
        return normal

    # -- the mesh ------------------------------------------------------------------------
    def _build(self) -> None:
        if self._cache.mesh is not None:
            return
        start = time.perf_counter()
        weight = self._weight
        valid = (weight >= self.min_weight) & self._region_nodes
        sdf = np.divide(self._sdf_sum, weight, out=np.zeros_like(self._sdf_sum), where=weight > 0)
        vertices, triangles = surface_nets(sdf, valid)
        triangles = fill_small_holes(manifold_part(triangles), self.fill_max_edges)
        vertices, triangles = _drop_small_components(vertices, triangles, self.min_component)
        grid_index = np.clip(np.floor(vertices).astype(np.int64), 0, np.array(self.grid_shape) - 2)
        stamp = np.full(len(vertices), -1, dtype=np.int64)
        for dx, dy, dz in _CUBE_CORNERS:
            stamp = np.maximum(stamp, self._stamp[grid_index[:, 0] + dx, grid_index[:, 1] + dy, grid_index[:, 2] + dz])
        world = self.grid_origin + vertices * self.voxel_size
        self._cache.mesh = TriMesh(world, triangles.astype(np.int32))
        self._cache.normals = vertex_normals_of(world, triangles)
        self._cache.vertex_scan = stamp
        self._cache.extra["build_s"] = time.perf_counter() - start

    @property
    def mesh(self) -> TriMesh:
        """Current mesh (rebuilt lazily after an integration)."""
        self._build()
        assert self._cache.mesh is not None
        return self._cache.mesh

    @property
    def vertex_normals(self) -> Points3:
        """Unit vertex normals (n, 3), pointing out of the object (towards the sensors)."""
        self._build()
        assert self._cache.normals is not None
        return self._cache.normals

    @property
    def vertex_scan(self) -> np.ndarray:
        """Index of the last integration that changed each vertex (n,); for M_cur (§4.2.1)."""
        self._build()
        assert self._cache.vertex_scan is not None
        return self._cache.vertex_scan

    def current_vertices(self) -> np.ndarray:
        """Mask of the vertices touched by the latest integration (the mesh part M_cur)."""
        return self.vertex_scan == self.n_scans - 1

    @property
    def build_seconds(self) -> float:
        """Time the last mesh extraction took."""
        self._build()
        return float(self._cache.extra["build_s"])  # type: ignore[arg-type]

    @property
    def points(self) -> Points3:
        """The density-limited point set (n, 3): one running-mean point per R_r cell."""
        if len(self._keys) == 0:
            return np.zeros((0, 3))
        return self._psum / self._pcount[:, None]

    @property
    def point_view_directions(self) -> Points3:
        """Mean unit direction from each point of :attr:`points` towards its sensors (n, 3)."""
        norm = np.linalg.norm(self._vsum, axis=1, keepdims=True)
        return np.divide(self._vsum, norm, out=np.zeros_like(self._vsum), where=norm > 0)

    def __len__(self) -> int:
        return len(self._keys)

    # -- borders, holes, completeness ----------------------------------------------------
    def border_edges(self) -> np.ndarray:
        """Border edges (k, 2) of the current mesh, directed as in their triangle."""
        return border_edges(self.mesh.triangles)

    def boundary_loops(self) -> list[np.ndarray]:
        """Boundary walks (vertex index arrays); closed ones are holes."""
        return boundary_loops(self.mesh.triangles)

    def holes(self, max_perimeter: float | None = None, min_edges: int = 3, max_edges: int | None = None) -> list[Hole]:
        """Closed boundary loops as :class:`Hole`, largest fan area first."""
        mesh = self.mesh
        found = holes_of(mesh.vertices, mesh.triangles, max_perimeter, min_edges, max_edges, self.vertex_normals)
        return sorted(found, key=lambda h: -h.area)

    def coverage_border(self) -> float:
        """ĉ_m = 1 − n_border / n_total (IROS Eq. 3)."""
        return coverage_border(self.mesh.triangles)

    def coverage_area(self, max_perimeter: float | None = None) -> float:
        """ĉ_m = A_filled / (A_filled + A_empty) with hole fans (Eq. 4.35–4.37)."""
        mesh = self.mesh
        return coverage_area(mesh.vertices, mesh.triangles, max_perimeter)

    def mean_edge_length(self) -> float:
        """l̄_e of the current mesh (m)."""
        lengths = mesh_edge_lengths(self.mesh.vertices, self.mesh.triangles)
        return float(lengths.mean()) if len(lengths) else 0.0

    # -- quality features ----------------------------------------------------------------
    @property
    def n_max(self) -> float:
        """N_max = √2 π R_n² / R_r², points of a close-packed R_n disc (Eq. 4.25)."""
        return float(np.sqrt(2.0) * np.pi * self.normal_radius**2 / self.point_spacing**2)

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
        from explore.core import save_mesh_png

        mesh = self.mesh
        text = title or (
            f"{len(mesh.triangles)} triangles, ĉ_m = {self.coverage_area():.3f} (area), "
            f"{self.coverage_border():.3f} (border)"
        )
        save_mesh_png(mesh.vertices, mesh.triangles, path, text)
