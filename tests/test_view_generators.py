"""View generators on synthetic meshes: boundary types, sharp corners, holes, the sphere."""

from __future__ import annotations

import numpy as np
import pytest

from explore.candidates import CandidateStack, PlanningContext, frame_from, rotation
from explore.meshes import TriMesh
from explore.scan import ScanPath
from explore.surface import border_edges, boundary_loops, holes_of, vertex_normals_of
from explore.visibility import VoxelGrid


class MeshSurface:
    """The parts of SurfaceModel the generators read, over a fixed mesh."""

    def __init__(self, mesh: TriMesh) -> None:
        self.mesh = mesh
        self.vertex_normals = vertex_normals_of(mesh.vertices, mesh.triangles)

    def current_vertices(self) -> np.ndarray:
        return np.ones(len(self.mesh.vertices), dtype=bool)

    def border_edges(self) -> np.ndarray:
        return border_edges(self.mesh.triangles)

    def boundary_loops(self) -> list[np.ndarray]:
        return boundary_loops(self.mesh.triangles)

    def holes(self, max_perimeter=None, min_edges=3, max_edges=None):  # noqa: ANN001, ANN201
        return holes_of(self.mesh.vertices, self.mesh.triangles, max_perimeter, min_edges, max_edges,
                        self.vertex_normals)


def grid_mesh(n: int = 20, spacing: float = 0.0035, z: float = 0.6, punch: bool = False) -> TriMesh:
    """A square n x n vertex grid in the plane z, normals +z; optionally with a square hole."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    half = (n - 1) * spacing / 2
    verts = np.column_stack([ii.ravel() * spacing - half, jj.ravel() * spacing - half, np.full(n * n, z)])
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            if punch and 8 <= i < 11 and 8 <= j < 11:
                continue
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            tris += [[a, b, c], [a, c, d]]
    return TriMesh(verts, np.asarray(tris, dtype=np.int32))


class Scanned:
    """The parts of a Scan the boundary search reads (the sensor poses of the latest scan)."""

    def __init__(self, poses: np.ndarray) -> None:
        self.sensor_poses = poses


@pytest.fixture
def striper(registry):  # noqa: ANN001, ANN201
    return registry.create("sensor", "laser_striper")


def context(surface: MeshSurface, sensor, with_scan: bool = True) -> PlanningContext:  # noqa: ANN001
    res = 0.005
    origin = np.array([-0.1, -0.1, 0.5])
    grid = VoxelGrid(np.full((40, 40, 40), 0.5, dtype=np.float32), origin, res)
    grid.ensure_features()
    # sensor straight above the square, scanning along world y (sensor y)
    pose = frame_from(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.925]))
    path = ScanPath(pose.copy(), pose.copy())
    poses = np.stack([pose.copy() for _ in range(3)])
    poses[0, 1, 3], poses[2, 1, 3] = -0.15, 0.15
    ctx = PlanningContext(pvs=None, surface=surface, grid=grid, sensor=sensor, robot=None,
                          region_min=np.array([-0.13, -0.13, 0.5]), region_max=np.array([0.13, 0.13, 0.72]),
                          stack=CandidateStack())
    ctx.last_scan = Scanned(poses) if with_scan else None
    ctx.iteration = 1
    del path
    return ctx


def test_boundary_types_of_a_half_scanned_box(registry, striper) -> None:  # noqa: ANN001
    surface = MeshSurface(grid_mesh())
    ctx = context(surface, striper)
    gen = registry.create("view_generator", "boundary", {"repair": False, "floor_margin": 0.0})
    found = gen.boundaries(ctx)
    assert sorted(b["type"] for b in found) == ["bottom", "left", "right", "top"]
    pose = ctx.last_scan.sensor_poses[1]
    for b in found:
        assert len(b["vertices"]) - 1 >= 15  # b_min edges
        # the outward direction points away from the square's centre, in the plane
        centre = surface.mesh.vertices[b["vertices"]].mean(axis=0)
        assert np.dot(b["outward"], centre[:2].tolist() + [0.0]) > 0
        assert abs(b["outward"][2]) < 1e-6
        # Table 4.1: left/right boundaries run along the scan direction (sensor y)
        along_y = abs(np.dot(b["direction"], pose[:3, 1])) > 0.9
        assert along_y == (b["type"] in ("left", "right"))
    by_type = {b["type"]: b for b in found}
    assert np.dot(by_type["left"]["outward"], pose[:3, 0]) < 0  # unknown area to the image left
    assert np.dot(by_type["bottom"]["outward"], pose[:3, 1]) > 0  # OpenCV y points down in the image


def test_boundary_candidates_sharp_corner_and_path(registry, striper) -> None:  # noqa: ANN001
    surface = MeshSurface(grid_mesh())
    ctx = context(surface, striper)
    gen = registry.create("view_generator", "boundary", {"repair": False, "floor_margin": 0.0})
    cands = gen.generate(ctx)
    assert len(cands) == 4
    for cand in cands:
        # planar region, boundary inside the FOV: a sharp corner, rotated 45 deg about the boundary
        assert cand.info["corner"]
        view = cand.pose[:3, 2]
        assert np.degrees(np.arccos(np.clip(-view[2], -1, 1))) == pytest.approx(45.0, abs=1.0)
        # the path runs along the boundary, at the optimal distance from its centre
        assert isinstance(cand.target, ScanPath)
        assert abs(np.dot(cand.pose[:3, 1], view)) < 1e-9
        focus = cand.pose[:3, 3] + striper.optimal_distance * view
        assert focus[2] == pytest.approx(0.6, abs=1e-3)


def test_boundary_trend_without_corner_looks_perpendicular(registry, striper) -> None:  # noqa: ANN001
    surface = MeshSurface(grid_mesh())
    ctx = context(surface, striper)
    gen = registry.create("view_generator", "boundary", {"repair": False, "floor_margin": 0.0, "corner_deg": 0.0,
                                                         "overlap": 0.3})
    cands = gen.generate(ctx)
    assert len(cands) == 4
    width = 2 * striper.optimal_distance * np.tan(np.deg2rad(striper.fan_deg / 2))
    for cand in cands:
        view = cand.pose[:3, 2]
        assert view == pytest.approx([0, 0, -1], abs=1e-6)  # perpendicular to the plane (Eq. 4.13)
        focus = cand.pose[:3, 3] + striper.optimal_distance * view
        # the new view is centred beyond the boundary by (0.5 - o) of the stripe width (Eq. 4.14), +- one step
        edge = (surface.mesh.vertices[:, :2].max())
        beyond = np.max(np.abs(focus[:2])) - edge
        assert beyond == pytest.approx(width * 0.2, abs=0.003)


def test_hole_rescan_finds_the_punched_hole(registry, striper) -> None:  # noqa: ANN001
    surface = MeshSurface(grid_mesh(punch=True))
    ctx = context(surface, striper)
    gen = registry.create("view_generator", "hole", {"repair": False, "floor_margin": 0.0, "pick": 0.0, "h_max": 40})
    cands = gen.generate(ctx)
    assert len(cands) == 1
    cand = cands[0]
    assert cand.info["holes"] == 1 and cand.info["edges"] == 12
    assert np.asarray(cand.info["centre"]) == pytest.approx([0.0, 0.0, 0.6], abs=1e-6)
    # pick = 0: the free direction closest to the PCA normal; looks down the hole normal
    assert abs(cand.pose[:3, 2][2]) > 0.98
    # Eq. 4.22-4.23: the path spans 2 x 1.1 x hole radius (3 cm at least)
    radius = np.sqrt(2) * 1.5 * 0.0035
    assert cand.target.length == pytest.approx(max(2.2 * radius, 0.03), rel=0.05)
    gen.remember(cand)
    assert gen.generate(ctx) == []  # each real hole is scanned once


def test_sphere_generator_sizes(registry, striper) -> None:  # noqa: ANN001
    ctx = context(MeshSurface(grid_mesh()), striper)
    gen = registry.create("view_generator", "sphere")
    cands = gen.generate(ctx)
    assert len(cands) == 81
    assert all(c.target.length == pytest.approx(0.3) for c in cands)
    assert gen.generate(ctx) == []  # the search space is fixed before the first scan
    camera = registry.create("sensor", "depth_camera")
    ctx.sensor = camera
    gen = registry.create("view_generator", "sphere")
    assert len(gen.generate(ctx)) == 121


def test_rotation_matches_rodrigues() -> None:
    r = rotation(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    assert r @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0])
    assert np.linalg.det(r) == pytest.approx(1.0)
