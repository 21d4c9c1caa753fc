"""Mesh extraction from a signed distance grid with surface nets (one vertex per sign-changing cube, one quad
per sign-changing grid edge), keeping the manifold part and closing loops of a few edges (sub-voxel artifacts)."""

from __future__ import annotations

import numpy as np

from explore.core import Points3
from explore.mapping.mesh_holes import (
    boundary_loops,
    edge_table,
    half_edges,
)

# ---------------------------------------------------------------------------------------
# surface nets on a signed distance grid
# ---------------------------------------------------------------------------------------
CUBE_CORNERS = np.array([[(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])

_CUBE_EDGES = np.array(
    [(a, b) for a in range(8) for b in range(a + 1, 8) if np.abs(CUBE_CORNERS[a] - CUBE_CORNERS[b]).sum() == 1]
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
    for dx, dy, dz in CUBE_CORNERS:
        sl = (slice(dx, dx + cs[0]), slice(dy, dy + cs[1]), slice(dz, dz + cs[2]))
        all_valid &= valid[sl]
        any_in |= inside[sl]
        all_in &= inside[sl]
    active = all_valid & any_in & ~all_in
    cubes = np.argwhere(active)
    if len(cubes) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    corner_idx = cubes[:, None, :] + CUBE_CORNERS[None]  # (n, 8, 3)
    values = sdf[corner_idx[..., 0], corner_idx[..., 1], corner_idx[..., 2]].astype(np.float64)
    va, vb = values[:, _CUBE_EDGES[:, 0]], values[:, _CUBE_EDGES[:, 1]]  # (n, 12)
    crossing = (va < 0) != (vb < 0)
    t = np.where(crossing, va / np.where(crossing, va - vb, 1.0), 0.0)
    pa = CUBE_CORNERS[_CUBE_EDGES[:, 0]].astype(float)  # (12, 3)
    pb = CUBE_CORNERS[_CUBE_EDGES[:, 1]].astype(float)
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
    half = half_edges(triangles)
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


def drop_small_components(vertices: Points3, triangles: np.ndarray, min_triangles: int) -> tuple[Points3, np.ndarray]:
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
