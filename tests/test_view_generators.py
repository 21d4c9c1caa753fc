"""View generators on synthetic meshes: boundary types, sharp corners, holes, the sphere."""

from __future__ import annotations

import numpy as np
import pytest

from explore.mapping import VoxelGrid, border_edges, boundary_loops, holes_of, vertex_normals_of
from explore.nbv import (
    BETAS_DEG,
    Candidate,
    CandidateStack,
    PlanningContext,
    RepairSettings,
    above_support,
    clip_above,
    frame_from,
    make_target,
    modelling_standoff,
    repair,
    rotation,
    segments_hit_boxes,
)
from explore.sim import ScanPath, TriMesh


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
    gen = registry.create("view_generator", "hole",
                          {"repair": False, "contact_band": 0.0, "pick": 0.0, "h_max": 40, "max_rescans": 1})
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
    assert gen.generate(ctx) == []  # max_rescans = 1: each real hole is scanned once (thesis)


def test_unchanged_hole_is_rescanned_only_from_new_directions(registry, striper) -> None:  # noqa: ANN001
    ctx = context(MeshSurface(grid_mesh(punch=True)), striper)
    gen = registry.create("view_generator", "hole", {"repair": False, "contact_band": 0.0, "h_max": 40,
                                                     "max_rescans": 3, "rescan_angle_deg": 45.0})
    views = []
    for _ in range(4):
        cands = gen.generate(ctx)
        if not cands:
            break
        views.append(-cands[0].pose[:3, 2])
        gen.remember(cands[0])
    assert len(views) == 3  # then the unchanged hole is exhausted
    for a in range(3):
        for b in range(a):
            assert np.degrees(np.arccos(np.clip(views[a] @ views[b], -1, 1))) > 45.0
    # a hole whose rim changed (the scans closed part of it) is a new hole
    moved = grid_mesh(punch=True)
    moved.vertices[:, 0] += 0.01
    ctx.surface = MeshSurface(moved)
    assert len(gen.generate(ctx)) == 1


def test_hole_in_the_support_contact_band_is_skipped(registry, striper) -> None:  # noqa: ANN001
    flat = MeshSurface(grid_mesh(punch=True, z=0.503))  # a hole 3 mm above the support: its contact footprint
    ctx = context(flat, striper)
    gen = registry.create("view_generator", "hole", {"repair": False, "h_max": 40, "contact_band": 0.006})
    assert gen.generate(ctx) == []
    raised = grid_mesh(punch=True, z=0.503)
    raised.vertices[:, 2] += 0.3 * (raised.vertices[:, 0] - raised.vertices[:, 0].min())  # rises above the band
    ctx.surface = MeshSurface(raised)
    cands = gen.generate(ctx)
    assert len(cands) == 1
    assert all(p[2] >= ctx.lowest_sensor_z for p in (cands[0].target.start[:3, 3], cands[0].target.end[:3, 3]))


def test_boundary_hole_switches_when_coverage_stalls(registry, striper) -> None:  # noqa: ANN001
    ctx = context(MeshSurface(grid_mesh(punch=True)), striper)
    gen = registry.create("view_generator", "boundary_hole", {"repair": False, "contact_band": 0.0, "h_max": 40,
                                                              "min_scans": 3, "switch_delta": 0.01})
    ctx.iteration, ctx.coverage_history = 3, [0.40, 0.55, 0.62]  # grows by 7 %: keep searching boundaries
    assert not gen.should_switch(ctx)
    boundary = gen.generate(ctx)
    assert boundary and all(c.source == "boundary" for c in boundary) and ctx.mode == "boundary"
    ctx.stack.push(boundary)
    ctx.iteration, ctx.coverage_history = 4, [0.40, 0.55, 0.62, 0.625]  # Eq. 4.38: 0.5 % < 1 %
    assert gen.should_switch(ctx)
    cands = gen.generate(ctx)
    assert ctx.mode == "hole" and gen.switched_at == 4
    assert not any(c.source == "boundary" for c in ctx.stack)  # the remaining boundary candidates are dropped
    assert [c.source for c in cands].count("hole") == 1
    ctx.coverage_history.append(0.70)  # once switched, it stays in hole mode
    assert gen.should_switch(ctx)


def test_random_view_generator(registry, striper) -> None:  # noqa: ANN001
    ctx = context(MeshSurface(grid_mesh()), striper)
    gen = registry.create("view_generator", "random", {"count": 30, "min_elevation_deg": -10.0})
    cands = gen.generate(ctx)
    assert len(cands) == 30
    radius = striper.optimal_distance + 0.25 * 0.26
    centre = ctx.region_centre
    for cand in cands:
        mid = cand.pose[:3, 3]
        assert np.linalg.norm(mid - centre) == pytest.approx(radius, abs=0.16)  # path of 30 cm through the view
        to_centre = (centre - mid) / np.linalg.norm(centre - mid)
        assert cand.pose[:3, 2] @ to_centre > 0.8  # looks at the region
        assert cand.target.length <= 0.3 + 1e-9
        assert min(cand.target.start[2, 3], cand.target.end[2, 3]) >= ctx.lowest_sensor_z - 1e-9
    elevation = [np.degrees(np.arcsin(-c.pose[2, 2])) for c in cands]
    assert max(elevation) - min(elevation) > 30.0  # spread over the sphere
    again = registry.create("view_generator", "random", {"count": 30, "min_elevation_deg": -10.0})
    ctx.rng = np.random.default_rng(0)
    first = [c.pose[:3, 3] for c in again.generate(ctx)]
    ctx.rng = np.random.default_rng(0)
    assert np.allclose(first, [c.pose[:3, 3] for c in again.generate(ctx)])  # the session's rng decides


def test_sphere_generator_sizes(registry, striper) -> None:  # noqa: ANN001
    ctx = context(MeshSurface(grid_mesh()), striper)
    gen = registry.create("view_generator", "sphere")
    cands = gen.generate(ctx)
    assert len(cands) == 81
    # 30 cm paths, the lowest ones cut where they would go below the support (thesis Sec. 4.1)
    lengths = np.array([c.target.length for c in cands])
    assert np.all(lengths <= 0.3 + 1e-9) and np.mean(lengths > 0.3 - 1e-9) > 0.6
    low = [min(c.target.start[2, 3], c.target.end[2, 3]) for c in cands]
    assert min(low) == pytest.approx(ctx.lowest_sensor_z)
    assert gen.generate(ctx) == []  # the search space is fixed before the first scan
    camera = registry.create("sensor", "depth_camera")
    ctx.sensor = camera
    gen = registry.create("view_generator", "sphere")
    assert len(gen.generate(ctx)) == 121


def test_the_sphere_offers_a_triangulating_striper_each_path_with_its_camera_on_four_sides(registry) -> None:  # noqa: ANN001
    striper = registry.create("sensor", "laser_striper", {"profile": "triangulation"})
    ctx = context(MeshSurface(grid_mesh()), striper)
    cands = registry.create("view_generator", "sphere").generate(ctx)
    by_view: dict[int, list] = {}
    for cand in cands:
        by_view.setdefault(cand.info["index"], []).append(cand)
    full = [group for group in by_view.values() if len(group) == 4]
    assert len(full) > 40  # the lowest paths lose a turn or two below the support
    for group in full:
        views = np.array([c.target.start[:3, 2] for c in group])
        assert np.allclose(views, views[0])  # the same view ...
        cameras = np.array([c.target.start[:3, :3] @ striper.shadow_offset for c in group]) / striper.baseline
        assert sorted(c.info["turn_deg"] for c in group) == [0, 90, 180, 270]
        assert cameras[0] @ cameras[2] == pytest.approx(-1.0)  # ... with the camera above and below
        assert cameras[1] @ cameras[3] == pytest.approx(-1.0)  # and on either side of the laser
        assert abs(cameras[0] @ cameras[1]) < 1e-9


def test_rotation_matches_rodrigues() -> None:
    r = rotation(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    assert r @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0])
    assert np.linalg.det(r) == pytest.approx(1.0)


def repair_setup(striper, bar_half_width: float):  # noqa: ANN001, ANN201
    """Free space over a focus patch at z = 0.6 with an occupied bar (along y) 5 cm above it."""
    ctx = context(MeshSurface(grid_mesh()), striper)
    ctx.grid.prob[:] = 0.02
    res, origin = ctx.grid.resolution, ctx.grid.origin
    lo = np.floor((np.array([-bar_half_width, -0.1, 0.65]) - origin) / res + 1e-9).astype(int)
    hi = np.floor((np.array([bar_half_width, 0.1, 0.66]) - origin) / res + 1e-9).astype(int)
    ctx.grid.prob[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = 0.98
    focus = np.array([[x, y, 0.6] for x in (-0.01, 0.0, 0.01) for y in (-0.02, 0.0, 0.02)])
    anchor = np.array([0.0, 0.0, 0.6])
    pose = frame_from(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), anchor + np.array([0, 0, 0.325]))
    cand = Candidate(make_target(striper, pose, focus, 0.325), "boundary", {"id": 0}, focus, 1)
    return ctx, cand, anchor, focus


def test_repair_rotates_around_an_occluder_in_10_degree_steps(striper) -> None:  # noqa: ANN001
    assert BETAS_DEG == (0, 10, -10, 20, -20, 30, -30, 40, -40)  # Algorithm 3: smallest first, + before -
    ctx, cand, anchor, focus = repair_setup(striper, 0.0)  # no bar: the candidate itself is fine
    assert repair(cand, ctx, anchor, 0.325, focus) is cand
    # a 6 cm wide bar 5 cm above the patch: the points x = -1, 0, 1 cm are seen past it only when the
    # view is tilted about s_y by atan(4 cm / 5 cm) = 39 deg or more, i.e. by 40 deg (30 deg: 1 of 3)
    ctx, cand, anchor, focus = repair_setup(striper, 0.03)
    fixed = repair(cand, ctx, anchor, 0.325, focus)
    assert fixed is not None and fixed.info["repaired_deg"] == (0, 40)
    view = fixed.pose[:3, 2]
    assert np.degrees(np.arccos(-view[2])) == pytest.approx(40.0, abs=0.5)
    # the path still passes over the anchor at the stand-off distance (Eq. 4.18)
    mid = fixed.pose[:3, 3]
    assert np.linalg.norm(np.cross(anchor - mid, view)) == pytest.approx(0.0, abs=0.02)
    # a bar too wide for +-40 deg: the candidate is removed
    ctx, cand, anchor, focus = repair_setup(striper, 0.09)
    assert repair(cand, ctx, anchor, 0.325, focus) is None
    # stricter acceptance: 100 % un-occluded points needed; 40 deg still sees all of them
    strict = RepairSettings(min_visible=1.0)
    ctx, cand, anchor, focus = repair_setup(striper, 0.03)
    assert repair(cand, ctx, anchor, 0.325, focus, strict).info["repaired_deg"] == (0, 40)


def test_repair_never_takes_the_sensor_below_the_support(striper) -> None:  # noqa: ANN001
    ctx, _, anchor, focus = repair_setup(striper, 0.0)
    up = frame_from(np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), anchor - np.array([0, 0, 0.325]))
    below = Candidate(make_target(striper, up, focus, 0.325), "boundary", {"id": 0}, focus, 1)
    assert not above_support(below.target, ctx.lowest_sensor_z)
    assert repair(below, ctx, anchor, 0.325, focus) is None  # +-40 deg cannot lift it above the support


def test_clip_above_and_segments_through_boxes() -> None:
    pose = frame_from(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([-0.3, 0.0, 0.5]))
    path = make_target_path(pose, 0.3)
    clipped = clip_above(path, 0.45)
    assert clipped.start[2, 3] == pytest.approx(0.45) and clipped.end[2, 3] == pytest.approx(0.65)
    assert clip_above(path, 0.7) is None and clip_above(path, 0.3) is path
    assert clip_above(path, 0.63, min_length=0.03) is None  # 2 cm left: too short
    box = [(np.array([-0.05, -0.05, 0.0]), np.array([0.05, 0.05, 0.5]))]
    starts = np.array([[0.0, 0, 0.6], [0.0, 0, 0.6], [0.2, 0, 0.4], [0.2, 0, 0.4], [0.2, 0, 0.6]])
    ends = np.array([[0.0, 0, 0.55], [0.0, 0, 0.4], [-0.2, 0, 0.4], [0.1, 0, 0.4], [-0.2, 0, 0.6]])
    assert segments_hit_boxes(starts, ends, box).tolist() == [False, True, True, False, False]


def make_target_path(pose: np.ndarray, length: float) -> ScanPath:
    start, end = pose.copy(), pose.copy()
    start[:3, 3] -= 0.5 * length * pose[:3, 1]
    end[:3, 3] += 0.5 * length * pose[:3, 1]
    return ScanPath(start, end)


def test_reachable_views_are_poses_the_arm_takes_looking_into_the_region(registry, workcell) -> None:  # noqa: ANN001
    """The arm's own configurations give the candidates: each scan path's middle is a pose the arm reaches
    (IK within 1 mm / 0.5 deg from its configuration's neighbourhood), its optical axis meets the region at
    the sensor's optimal distance, and the candidates spread (no two the same); a boundary candidate along a
    surface normal is reached about one time in seven in this cell (benchmarks/reach_limit.py)."""
    from explore.nbv import CandidateStack

    robot, sensor = workcell.robot, workcell.sensor
    ctx = PlanningContext(pvs=None, surface=None, grid=None, sensor=sensor, robot=robot,
                          region_min=np.asarray(workcell.spec.region_min, float),
                          region_max=np.asarray(workcell.spec.region_max, float), stack=CandidateStack(),
                          rng=np.random.default_rng(0))
    gen = registry.create("view_generator", "reachable", {"samples": 4000, "count": 12})
    found = gen.generate(ctx)
    assert 8 <= len(found) <= 12 and gen.generate(ctx) == []  # once per run, as the sphere
    middles = np.array([c.target.mid for c in found])
    aim = middles[:, :3, 3] + sensor.optimal_distance * middles[:, :3, 2]
    assert np.all((aim >= ctx.region_min - 1e-9) & (aim <= ctx.region_max + 1e-9))
    assert min(np.linalg.norm(a[:3, 3] - b[:3, 3]) for i, a in enumerate(middles) for b in middles[i + 1:]) > 0.02
    reached = sum(robot.ik(pose, np.random.default_rng(1)) is not None for pose in middles)
    assert reached >= 0.75 * len(found)


def test_a_coarse_camera_comes_closer_than_its_optimal_distance(registry, striper) -> None:  # noqa: ANN001
    """Views stand where the central beams fall R_r = 2 mm apart, if that is nearer than the
    sensor's optimal distance: a 160 x 120 camera over 58 degrees (5.9 mm pixels at 0.85 m) comes to
    about 0.3 m; the striper and a 640 x 480 camera keep theirs; never nearer than 1.25 x min range."""
    coarse = registry.create("sensor", "depth_camera", {"width": 160, "height": 120, "min_range": 0.2,
                                                          "max_range": 1.5})
    pixel = np.arctan(1.0 / coarse.intrinsics[0, 0])  # the central pixel's angle
    assert modelling_standoff(coarse, 0.002) == pytest.approx(0.002 / np.tan(pixel), rel=1e-3)
    assert 0.25 < modelling_standoff(coarse, 0.002) < 0.35 < coarse.optimal_distance
    fine = registry.create("sensor", "depth_camera", {"width": 640, "height": 480, "min_range": 0.3,
                                                        "max_range": 1.0})
    assert modelling_standoff(fine, 0.002) == fine.optimal_distance
    assert modelling_standoff(striper, 0.002) == striper.optimal_distance
    assert modelling_standoff(coarse, 0.0001) == pytest.approx(1.25 * coarse.min_range)
