"""Pure functions on any triangle mesh: edges, border edges and boundary loops, holes and their fans, and
Kriegel's completeness estimates: c_m = 1 - n_border/n_total (IROS Eq. 3) and c_m = A_filled/(A_filled + A_empty)
with hole fans (thesis Eq. 4.35-4.37)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explore.core import Array, Points3
from explore.sim import TriMesh

#: a hole lying wholly this close above the support plane is where the object stands (m), as
#: hole rescan's ``contact_band``: a flat-bottomed dish's contact loop lies within 2.4 mm of the
#: support, while the loop along a cylinder lying on its side rises to 11 mm, and the band of
#: its side below that is observable (benchmarks/heldout_set.yaml)
SUPPORT_MARGIN = 0.006

# ---------------------------------------------------------------------------------------
# pure mesh functions (any TriMesh)
# ---------------------------------------------------------------------------------------
def half_edges(triangles: np.ndarray) -> np.ndarray:
    """Directed half-edges (3m, 2) in triangle order: (a,b), (b,c), (c,a) per triangle."""
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    return np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1).reshape(-1, 2)


def edge_table(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges of a mesh.

    Returns
    -------
    edges : (e, 2) int64, sorted vertex pairs (lower index first)
    counts : (e,) int64, number of triangles adjacent to each edge
    half_to_edge : (3m,) int64, edge index of every half-edge of :func:`half_edges`
    """
    half = half_edges(triangles)
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
    half = half_edges(triangles)
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


def coverage_area(vertices: Points3, triangles: np.ndarray, max_perimeter: float | None = None,
                  support_z: float | None = None) -> float:
    """ĉ_m = A_filled / (A_filled + A_empty) with A_empty = Σ hole fans (Eq. 4.35–4.37).

    Every closed border loop counts as a hole, as in the thesis: the opening where the object
    stands on its support too, so 100 % is out of reach for an object on a table and the
    estimate's bias grows with the contact area (38 points on a shallow dish). With
    ``support_z`` the contact is left out (see :func:`coverage_areas`). ``max_perimeter``
    ignores larger loops.
    """
    return coverage_areas(vertices, triangles, support_z, max_perimeter)[0 if support_z is None else 1]


def coverage_areas(vertices: Points3, triangles: np.ndarray, support_z: float | None,
                   max_perimeter: float | None = None, support_margin: float = SUPPORT_MARGIN) -> tuple[float, float]:
    """ĉ_m with every hole, and ĉ_m without the holes lying wholly within ``support_margin`` above
    ``support_z`` (where the object stands: no sensor sees it), from one search for holes."""
    vertices = np.asarray(vertices, dtype=float)
    filled = TriMesh(vertices, np.asarray(triangles).reshape(-1, 3)).area()
    if filled <= 0.0:
        return 0.0, 0.0
    holes = holes_of(vertices, triangles, max_perimeter=max_perimeter)
    empty = sum(h.area for h in holes)
    if support_z is not None:
        holes = [h for h in holes if vertices[h.loop, 2].max() > support_z + support_margin]
    off_support = sum(h.area for h in holes)
    return filled / (filled + empty), filled / (filled + off_support)
