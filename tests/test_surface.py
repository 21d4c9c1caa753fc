"""Surface model: border edges, boundary loops, holes, completeness ĉ_m, features, bunny scans."""

from __future__ import annotations

import numpy as np
import pytest

from explore.core import fibonacci_sphere
from explore.mapping import (
    SurfaceModel,
    border_edges,
    boundary_loops,
    coverage_area,
    coverage_border,
    edge_table,
    hole_fan_area,
    holes_of,
)
from explore.sim import TriMesh, box_mesh, sphere_mesh


def _polar(mesh: TriMesh) -> np.ndarray:
    """Polar angle of every triangle centroid of a sphere centred at the origin."""
    c = mesh.vertices[mesh.triangles].mean(axis=1)
    return np.arccos(np.clip(c[:, 2] / np.linalg.norm(c, axis=1), -1.0, 1.0))


# -- pure mesh functions ---------------------------------------------------------------
def test_closed_sphere_is_complete() -> None:
    mesh = sphere_mesh(0.1, 24)
    assert len(border_edges(mesh.triangles)) == 0
    assert boundary_loops(mesh.triangles) == []
    assert coverage_border(mesh.triangles) == 1.0
    assert coverage_area(mesh.vertices, mesh.triangles) == 1.0


def test_box_without_top_face() -> None:
    box = box_mesh(np.ones(3))
    top = np.all(box.vertices[box.triangles][:, :, 2] > 0.49, axis=1)
    assert top.sum() == 2
    tris = box.triangles[~top]
    assert len(border_edges(tris)) == 4
    # 18 edges of the closed box minus the top diagonal; 4 of the 17 are border edges
    assert coverage_border(tris) == pytest.approx(1.0 - 4.0 / 17.0, abs=1e-12)
    # Eq. 4.35-4.37: five faces filled, the fan over the open face is exactly one face
    assert coverage_area(box.vertices, tris) == pytest.approx(5.0 / 6.0, abs=1e-12)
    (hole,) = holes_of(box.vertices, tris)
    assert hole.size == 4
    assert hole.area == pytest.approx(1.0)
    assert hole.perimeter == pytest.approx(4.0)
    np.testing.assert_allclose(hole.centre, [0.0, 0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(hole.normal, [0.0, 0.0, 1.0], atol=1e-12)  # out of the box
    assert hole.radius == pytest.approx(np.sqrt(0.5))


def test_the_opening_on_the_support_is_not_a_hole_off_support() -> None:
    """A box standing on z = -0.5 without its bottom face: the bottom is where it stands, so
    without the support opening ĉ_m is 1; an opening higher up still counts."""
    box = box_mesh(np.ones(3))
    face_z = box.vertices[box.triangles][:, :, 2]
    bottom = np.all(face_z < -0.49, axis=1)
    tris = box.triangles[~bottom]
    assert coverage_area(box.vertices, tris) == pytest.approx(5.0 / 6.0, abs=1e-12)
    assert coverage_area(box.vertices, tris, support_z=-0.5) == 1.0
    # within the margin (a sensor does not see the last millimetres) it is; 2 cm above it is not
    assert coverage_area(box.vertices, tris, support_z=-0.505) == 1.0
    assert coverage_area(box.vertices, tris, support_z=-0.52) == pytest.approx(5.0 / 6.0, abs=1e-12)
    top = np.all(face_z > 0.49, axis=1)
    assert coverage_area(box.vertices, box.triangles[~top], support_z=-0.5) == pytest.approx(5.0 / 6.0, abs=1e-12)


def test_hole_fan_area_of_a_planar_polygon() -> None:
    angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(12)])
    expected = 0.5 * 12 * np.sin(2 * np.pi / 12)  # regular 12-gon of circumradius 1
    assert hole_fan_area(ring, np.arange(12)) == pytest.approx(expected)
    assert hole_fan_area(ring, np.arange(2)) == 0.0


@pytest.mark.parametrize("ring", [4, 9, 15])
def test_area_coverage_of_sphere_with_cap_cut_out(ring: int) -> None:
    resolution, radius = 40, 0.05
    mesh = sphere_mesh(radius, resolution)
    theta = ring * np.pi / resolution  # the cut follows a latitude ring of the UV sphere
    keep = _polar(mesh) > theta
    tris = mesh.triangles[keep]
    loops = boundary_loops(tris)
    assert len(loops) == 1 and len(loops[0]) == 2 * resolution
    remaining = 2 * np.pi * radius**2 * (1 + np.cos(theta))
    disc = np.pi * (radius * np.sin(theta)) ** 2
    analytic = remaining / (remaining + disc)
    assert coverage_area(mesh.vertices, tris) == pytest.approx(analytic, rel=0.01)
    (hole,) = holes_of(mesh.vertices, tris)
    assert hole.area == pytest.approx(disc, rel=0.01)
    np.testing.assert_allclose(hole.normal, [0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(hole.centre, [0.0, 0.0, radius * np.cos(theta)], atol=1e-9)


def test_hole_finder_finds_exactly_the_punched_holes() -> None:
    mesh = sphere_mesh(0.1, 30)
    centres = fibonacci_sphere(7) * 0.1
    dist = np.linalg.norm(mesh.vertices[:, None, :] - centres[None], axis=2)  # (n, 7)
    tri_near = dist[mesh.triangles].min(axis=1)  # (m, 7): closest triangle vertex per centre
    radii = np.array([0.012, 0.016, 0.02, 0.024, 0.014, 0.018, 0.022])
    punched = tri_near < radii
    assert not np.any(punched.sum(axis=1) > 1)  # the holes do not touch
    tris = mesh.triangles[~punched.any(axis=1)]
    found = holes_of(mesh.vertices, tris)
    assert len(found) == len(centres)
    border = border_edges(tris)
    assert sum(h.size for h in found) == len(border)
    for hole in found:
        nearest = int(np.argmin(np.linalg.norm(centres - hole.centre, axis=1)))
        # the loop has as many edges as border edges around that punch
        mid = mesh.vertices[border].mean(axis=1)
        own = np.linalg.norm(mid - centres[nearest], axis=1) < radii[nearest] + 0.02
        assert hole.size == int(own.sum())
        assert np.dot(hole.normal, centres[nearest] / 0.1) > 0.98  # points out of the sphere
    assert len(holes_of(mesh.vertices, tris, max_perimeter=2 * np.pi * 0.016)) < len(found)


def test_pinch_vertex_splits_into_two_loops() -> None:
    mesh = sphere_mesh(0.1, 16)
    tris = mesh.triangles
    # two triangles that share exactly one vertex
    first = 200
    shares = np.array([len(set(t) & set(tris[first])) for t in tris])
    second = int(np.flatnonzero(shares == 1)[0])
    cut = np.delete(tris, [first, second], axis=0)
    loops = boundary_loops(cut)
    assert sorted(len(loop) for loop in loops) == [3, 3]
    assert len(border_edges(cut)) == 6


def test_edge_table_counts() -> None:
    box = box_mesh(np.ones(3))
    edges, counts, half_to_edge = edge_table(box.triangles)
    assert len(edges) == 18 and np.all(counts == 2)
    assert len(half_to_edge) == 36


# -- the incremental model on synthetic data ---------------------------------------------
def _sphere_points(centre: np.ndarray, radius: float, n: int) -> np.ndarray:
    return centre + radius * fibonacci_sphere(n)


def test_fully_observed_sphere_gives_a_closed_mesh() -> None:
    centre = np.array([0.0, 0.0, 0.1])
    model = SurfaceModel(centre - 0.08, centre + 0.08)
    points = _sphere_points(centre, 0.04, 40000)
    info = model.integrate_points(points, centre + 3.0 * (points - centre))  # seen from outside
    assert info["points_in"] == 40000
    mesh = model.mesh
    assert len(model.border_edges()) == 0
    assert model.coverage_border() == 1.0 and model.coverage_area() == 1.0
    assert mesh.area() == pytest.approx(4 * np.pi * 0.04**2, rel=0.03)
    radial = np.linalg.norm(mesh.vertices - centre, axis=1)
    assert np.sqrt(np.mean((radial - 0.04) ** 2)) < 3e-4
    outward = np.einsum("ij,ij->i", model.vertex_normals, (mesh.vertices - centre) / radial[:, None])
    assert np.all(outward > 0.8)
    assert 0.0025 < model.mean_edge_length() < 0.004
    assert model.mean_density() > 0.5


def _seen_from_above(centre: np.ndarray, radius: float, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Sphere samples a sensor 30 cm above the centre sees below 80° incidence, and the rim height."""
    points = _sphere_points(centre, radius, n)
    eye = centre + np.array([0.0, 0.0, 0.3])
    normal = (points - centre) / radius
    view = (eye - points) / np.linalg.norm(eye - points, axis=1, keepdims=True)
    seen = np.einsum("ij,ij->i", normal, view) > np.cos(np.deg2rad(80.0))
    return points[seen], eye, float(points[seen, 2].min() - centre[2])


def test_border_edges_only_where_the_sphere_was_not_observed() -> None:
    centre, radius = np.array([0.0, 0.0, 0.1]), 0.04
    model = SurfaceModel(centre - 0.08, centre + 0.08)
    points, eye, rim = _seen_from_above(centre, radius, 40000)
    model.integrate_points(points, eye)
    mesh = model.mesh
    border = model.border_edges()
    assert len(border) > 20
    z = mesh.vertices[np.unique(border), 2] - centre[2]
    assert np.all(np.abs(z - rim) < 0.006)  # at the rim of the observed cap, nowhere else
    assert len(model.boundary_loops()) == 1
    (hole,) = model.holes()
    assert hole.normal[2] < -0.99  # the open side faces down
    # observed cap + fan over the rim disc
    cap = 2 * np.pi * radius * (radius - rim)
    disc = np.pi * (radius**2 - rim**2)
    assert model.coverage_area() == pytest.approx(cap / (cap + disc), abs=0.03)


def test_features_and_voxel_features() -> None:
    centre = np.array([0.0, 0.0, 0.1])
    model = SurfaceModel(centre - 0.08, centre + 0.08)
    points, eye, rim = _seen_from_above(centre, 0.04, 40000)
    model.integrate_points(points, eye)
    feats = model.vertex_features()
    n = len(model.mesh.vertices)
    assert feats["density"].shape == (n,) and feats["border"].shape == (n,) and feats["normal"].shape == (n, 3)
    assert np.all((feats["density"] >= 0) & (feats["density"] <= 1))
    on_border = np.zeros(n, dtype=bool)
    on_border[np.unique(model.border_edges())] = True
    assert np.all(feats["border"][on_border] > 0) and np.all(feats["border"][~on_border] == 0)
    index, density, normal, border = model.voxel_features(0.01, origin=np.zeros(3))
    k = len(index)
    assert index.shape == (k, 3) and density.shape == (k,) and normal.shape == (k, 3) and border.shape == (k,)
    assert len(np.unique(index, axis=0)) == k
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-9)
    assert np.all((border >= 0) & (border <= 1)) and border.max() > 0
    assert np.all(border[index[:, 2] * 0.01 > centre[2] + rim + 0.01] == 0)  # no border above the rim


def test_region_filter_and_empty_model(tmp_path) -> None:
    model = SurfaceModel([0, 0, 0], [0.1, 0.1, 0.1])
    assert len(model.mesh.triangles) == 0
    assert model.coverage_border() == 0.0 and model.coverage_area() == 0.0 and model.mean_density() == 0.0
    assert model.holes() == [] and len(model.voxel_features(0.01)[0]) == 0
    info = model.integrate_points(np.array([[0.5, 0.5, 0.5], [0.05, 0.05, 0.0005], [np.nan, 0, 0]]), np.zeros(3))
    assert info["points_in"] == 0  # outside, below the floor clearance, not finite
    with pytest.raises(ValueError):
        SurfaceModel([0, 0, 0], [0.1, -0.1, 0.1])


def test_save_ply_and_png(tmp_path) -> None:
    centre = np.array([0.0, 0.0, 0.1])
    model = SurfaceModel(centre - 0.06, centre + 0.06)
    points = _sphere_points(centre, 0.03, 20000)
    model.integrate_points(points, centre + 3.0 * (points - centre))
    model.save_ply(tmp_path / "m.ply")
    model.save_png(tmp_path / "m.png")
    assert (tmp_path / "m.ply").stat().st_size > 1000 and (tmp_path / "m.png").stat().st_size > 1000


# -- real simulated scans of the bunny ------------------------------------------------------
VIEW_DIRECTIONS = [(1, 0, 0.3), (-1, 0, 0.3), (0, 1, 0.3), (0, -1, 0.3), (0, 0, 1), (0.7, 0.7, -0.2)]


def test_bunny_scans_raise_completeness(bunny_sim) -> None:
    from explore.mapping import GroundTruthMetrics
    from explore.sim import target_for

    sim = bunny_sim
    sensor = sim.sensor
    metrics = GroundTruthMetrics(sim)
    lo, hi = sim.object_mesh().bounds
    centre = 0.5 * (lo + hi)
    model = SurfaceModel(sim.spec.region_min, sim.spec.region_max)
    rng = np.random.default_rng(0)
    area, border, reach = [], [], []
    for direction in VIEW_DIRECTIONS:
        d = np.asarray(direction, float) / np.linalg.norm(direction)
        scan = sensor.acquire(sim, target_for(sensor, centre + sensor.optimal_distance * d, centre, 0.3), rng)
        model.integrate(scan)
        mesh = model.mesh
        area.append(model.coverage_area())
        border.append(model.coverage_border())
        reach.append(metrics.coverage(mesh.vertices))
    # monotone up to the re-meshing jitter of already covered parts (the top view adds little)
    assert np.all(np.diff(reach) > -2e-3), reach
    assert reach[3] > reach[0] + 0.4
    assert np.all(np.diff(area) > -5e-3), area  # same jitter on the estimate
    assert border[-1] > border[0] + 0.03 and area[-1] > 0.8, (border, area)
    assert reach[-1] > 0.93
    assert 0.0028 < model.mean_edge_length() < 0.004
    assert metrics.rms_error(model.mesh.vertices) < 0.0015  # with the striper's range noise
    # the per-scan mesh part M_cur is a non-empty subset of the mesh
    assert 0 < model.current_vertices().sum() < len(model.mesh.vertices)


def test_border_edge_faces() -> None:
    box = box_mesh(np.ones(3))
    top = np.all(box.vertices[box.triangles][:, :, 2] > 0.49, axis=1)
    tris = box.triangles[~top]
    edges, faces = border_edges(tris, return_faces=True)
    assert len(edges) == len(faces) == 4
    for (a, b), face in zip(edges, faces, strict=True):
        t = list(tris[face])
        assert a in t and b in t and t[(t.index(a) + 1) % 3] == b  # directed as in its triangle
