"""Motion planning: OMPL planners, dense re-checks, unknown space, scan paths, kinodynamic base."""

from __future__ import annotations

import contextlib
import math
import time

import numpy as np
import pytest

from explore.core import look_at
from explore.motion import BodyFreeSpace, MotionProblem, classify_blocked, linear_scan_path_ik, validate_path
from explore.sim import ScanPath


@pytest.fixture(scope="module")
def endpoints(workcell):
    robot = workcell.robot
    rng = np.random.default_rng(0)
    a = robot.ik(look_at([0.45, -0.25, 0.85], [0.7, -0.2, 0.45]), rng)
    b = robot.ik(look_at([0.45, 0.3, 0.85], [0.75, 0.2, 0.45]), rng)
    assert a is not None and b is not None
    return a, b


@pytest.mark.parametrize("name", ["rrt_connect", "prm", "bit_star"])
def test_planner_paths_are_collision_free_when_densely_rechecked(registry, workcell, endpoints, name) -> None:
    problem = MotionProblem(workcell.robot)
    planner = registry.get("motion_planner", name).create({"time_limit": 3.0, "try_direct": False})
    plan = planner.plan(problem, *endpoints, seed=1)
    assert plan is not None
    assert np.allclose(plan.path[0], endpoints[0]) and np.allclose(plan.path[-1], endpoints[1])
    assert validate_path(problem, plan.path, resolution=problem.resolution / 10, margin=0.0) is None
    assert plan.length > 0


def test_planner_avoids_a_known_obstacle(registry, workcell, endpoints) -> None:
    """A goal below the table top is rejected; every path stays above the table."""
    robot = workcell.robot
    problem = MotionProblem(robot)
    low = robot.ik(look_at([0.75, 0.0, 0.3], [0.75, 0.0, 0.0]), check_collision=False)
    assert low is not None and not problem.is_valid(low)
    assert registry.get("motion_planner", "rrt_connect").create({}).plan(problem, endpoints[0], low) is None


def test_ompl_failures_reach_the_caller_not_the_console(workcell, endpoints, capfd) -> None:
    """OMPL writes its errors straight to stderr (through a live view); a failed search is a None."""
    from explore.motion.geometric import ompl_search
    from explore.motion.planning_clock import Budget

    robot = workcell.robot
    problem = MotionProblem(robot)
    low = robot.ik(look_at([0.75, 0.0, 0.3], [0.75, 0.0, 0.0]), check_collision=False)
    capfd.readouterr()
    assert ompl_search(problem, endpoints[0], low, "rrt_connect", Budget(0.5), True, 0.0, 1e-6, 1.0) is None
    assert capfd.readouterr().err == ""


def _clearing_scan(lo: np.ndarray, hi: np.ndarray):
    """Vertical beams without a return through the box [lo, hi]: they prove it free."""
    from explore.sim import Scan

    g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 30), np.linspace(lo[1], hi[1], 30)), -1).reshape(-1, 2)
    n = len(g)
    origins = np.column_stack([g, np.full(n, hi[2] + 0.3)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    nan = np.full(n, np.nan)
    return Scan(origins, directions, nan, nan, np.eye(4)[None], np.zeros(1), np.zeros(n, int), 0.0, 1.0, True, True)


def test_unknown_space_blocks_a_path_until_observed_free(workcell, endpoints) -> None:
    """With the real PVS: unknown (p = 0.5) blocks the goal; after a clearing scan it is free."""
    from explore.mapping import PVS

    robot = workcell.robot
    a, b = endpoints
    tip = robot.fk(b)[:3, 3]
    pvs = PVS(tip - 0.06, tip + 0.06, 0.02)
    problem = MotionProblem(robot, space_free=pvs.is_free)
    assert not problem.is_valid(b)
    assert classify_blocked(robot, b[None], pvs.probability, space_free=pvs.is_free) == "unknown"  # keep for later
    assert classify_blocked(robot, b[None], lambda x: np.maximum(pvs.probability(x), 0.9)) == "occupied"
    for _ in range(3):
        pvs.integrate(_clearing_scan(tip - 0.07, tip + 0.07))
    assert problem.is_valid(b) and problem.is_valid_motion(a, b)
    assert classify_blocked(robot, b[None], pvs.probability, space_free=pvs.is_free) == "free"


def test_the_robot_surface_between_its_samples_keeps_the_clearance_from_the_pvs(workcell, endpoints) -> None:
    """An occupied voxel where the arm's surface lies between its 3 cm samples: without a margin for
    the gaps the samples' voxels are free and far enough, and the configuration passes although the
    arm touches the voxel; with the robot's ``space_margin`` (clearance + measured sample gap) it fails."""
    from scipy.spatial import cKDTree

    from explore.mapping import PVS

    robot = workcell.robot
    _, b = endpoints
    tip = robot.fk(b)[:3, 3]
    pvs = PVS(tip - 0.15, tip + 0.15, 0.01)
    pvs.log_odds[:] = -5.0  # all observed free
    box = (pvs.min_corner, pvs.max_corner)
    samples = robot.link_points(b, within=box)
    dense = robot.link_points(b, within=box, spacing=0.005)
    dense = dense[np.all((dense > pvs.min_corner + 0.02) & (dense < pvs.max_corner - 0.02), axis=1)]
    gap, _ = cKDTree(samples).query(dense)
    assert robot.point_spacing <= robot.sample_gap <= 1.5 * robot.point_spacing
    assert gap.max() <= robot.sample_gap + 1e-9
    touched = dense[np.argmax(gap)]  # the surface point farthest from every sample (about 2.5 cm)
    ijk, _ = pvs.index(touched[None])
    pvs.log_odds[tuple(ijk[0])] = 5.0
    pvs.version += 1
    assert MotionProblem(robot, space_free=pvs.is_free, space_margin=0.0).is_valid(b)  # the old test misses it
    problem = MotionProblem(robot, space_free=pvs.is_free)
    assert problem.space_margin == pytest.approx(robot.clearance + robot.sample_gap)
    assert not problem.is_valid(b)
    margin = problem.space_margin
    verdict = classify_blocked(robot, b[None], pvs.probability, space_free=pvs.is_free, space_margin=margin)
    assert verdict == "occupied"  # the samples' own voxels are free, the one within the margin is not
    pvs.log_odds[tuple(ijk[0])] = 0.0  # unknown instead: the candidate waits
    pvs.version += 1
    verdict = classify_blocked(robot, b[None], pvs.probability, space_free=pvs.is_free, space_margin=margin)
    assert verdict == "unknown"


def test_scene_motion_passes_unknown_space_but_keeps_the_margin_from_occupied_voxels(workcell, endpoints,
                                                                                     registry) -> None:
    """A scene's robot moves through unknown space (its region is unseen when it starts) but keeps its
    ``space_margin`` from occupied voxels, as modelling does: the voxel where the arm's surface lies
    between its samples blocks the configuration (the old test, each sample's own voxel below p 0.75,
    passed it), a voxel of the known table does not, and a scan sweep ends before the first
    configuration that is blocked (the arm swept its camera through a modelled object in
    ``benchmarks/random_scenes.py --like workcell``, scene 45)."""
    from scipy.spatial import cKDTree

    from explore.mapping import PVS
    from explore.scene.motion import Mover, OccupiedClearance

    robot = workcell.robot
    a, b = endpoints
    tip = robot.fk(b)[:3, 3]
    pvs = PVS(tip - 0.15, tip + 0.15, 0.01)  # all unknown
    mover = Mover(workcell, registry, noise=False)
    mover.pvs = pvs
    sweep = np.linspace(a, b, 10)
    assert all(mover._problem().is_valid(q) for q in sweep)
    box = (pvs.min_corner, pvs.max_corner)
    dense = robot.link_points(b, within=box, spacing=0.005)
    dense = dense[np.all((dense > pvs.min_corner + 0.02) & (dense < pvs.max_corner - 0.02), axis=1)]
    gap, _ = cKDTree(robot.link_points(b, within=box)).query(dense)
    ijk, _ = pvs.index(dense[np.argmax(gap)][None])  # the arm's surface farthest from its samples
    pvs.log_odds[tuple(ijk[0])] = 5.0
    pvs.version += 1
    assert pvs.probability_below(robot.link_points(b, within=box), 0.75).all()  # the old test passes it
    problem = mover._problem()
    assert not problem.is_valid(b)
    valid = [problem.is_valid(q) for q in sweep]
    first = valid.index(False)
    assert 4 <= first < 10 and not any(valid[first:])
    target = ScanPath(robot.fk(a), robot.fk(b), 0.05)
    shortened, kept = mover._valid_sweep(problem, target, sweep)
    assert len(kept) == first and np.allclose(shortened.end[:3, 3], robot.fk(sweep[first - 1])[:3, 3])
    mover.min_path_fraction = 0.95  # less of it than the shortest share still scanned: no scan
    assert mover._valid_sweep(problem, target, sweep) is None
    assert mover.move(target, sweep) is None and mover.failed_moves == 1  # the run's metrics: moves_failed

    # a voxel on the known table's top and a point 2 cm above it
    top = workcell.environment_caster().closest(np.array([[0.75, 0.0, 0.5]]))[0][0]
    near_top = PVS(top - 0.05, top + 0.05, 0.005)
    near_top.log_odds[tuple(near_top.index(top[None])[0][0])] = 5.0
    above = top[None] + [0.0, 0.0, 0.02]
    assert not OccupiedClearance(near_top, 0.75).is_free(above, clearance=0.03)[0]
    assert OccupiedClearance(near_top, 0.75, workcell.environment_caster()).is_free(above, clearance=0.03)[0]


def test_the_space_the_robot_stood_in_is_free_for_planning(workcell, endpoints) -> None:
    """Unknown space around the arm blocks the configuration it stands in until it is recorded as
    the robot's own volume; the PVS itself is unchanged and a cached motion is invalidated."""
    from explore.mapping import PVS

    robot = workcell.robot
    _, b = endpoints
    tip = robot.fk(b)[:3, 3]
    pvs = PVS(tip - 0.06, tip + 0.06, 0.02)
    free_space = BodyFreeSpace(pvs)
    problem = MotionProblem(robot, space_free=free_space.is_free)
    assert problem.space_bounds is not None  # only the links near the PVS box are sampled
    assert not problem.is_valid(b)
    before = problem.cache_key(b, b)
    points = robot.link_points(b, within=(pvs.min_corner, pvs.max_corner))
    free_space.stand(points)
    assert problem.is_valid(b) and problem.cache_key(b, b) != before
    ijk, inside = pvs.index(points)
    assert inside.any() and free_space.is_free(points[inside]).all()
    assert not pvs.is_free(points[inside]).any()  # the map keeps its evidence
    every = np.stack(np.meshgrid(*[np.arange(n) for n in pvs.shape], indexing="ij"), axis=-1).reshape(-1, 3)
    stood = {tuple(v) for v in ijk[inside]}
    others = pvs.centers(np.array([v for v in every if tuple(v) not in stood]))
    assert len(others) and not free_space.is_free(others).any()  # nowhere else


def test_linear_scan_path_in_10mm_portions(workcell) -> None:
    robot = workcell.robot
    start = look_at([0.55, -0.12, 0.8], [0.75, -0.12, 0.45])
    end = start.copy()
    end[:3, 3] += 0.1 * start[:3, 0]  # 10 cm sideways (along the sensor's x)
    result = linear_scan_path_ik(robot, ScanPath(start, end), step=0.01, problem=MotionProblem(robot))
    assert result.complete and len(result.configs) == 11
    assert np.max(np.abs(np.diff(result.configs, axis=0))) < 0.2
    for q, pose in zip(result.configs, result.poses, strict=True):
        assert np.linalg.norm(robot.fk(q)[:3, 3] - pose[:3, 3]) < 1e-3


def test_straight_line_for_the_free_flyer(open_world, registry) -> None:
    with open_world("bunny_pedestal") as sim:
        robot = sim.robot
        problem = MotionProblem(robot)
        planner = registry.get("motion_planner", "straight_line").create({})
        a = robot.ik(look_at([-0.3, 0.0, 0.62], [0.0, 0.0, 0.6]))
        b = robot.ik(look_at([0.0, -0.3, 0.62], [0.0, 0.0, 0.6]))
        assert planner.plan(problem, a, b) is not None
        through_pedestal = robot.ik(look_at([0.3, 0.0, 0.3], [0.0, 0.0, 0.6]))
        assert planner.plan(problem, robot.ik(look_at([-0.3, 0.0, 0.3], [0, 0, 0.6])), through_pedestal) is None


def test_kinodynamic_base_plan_gives_controls_that_reach_the_goal(open_world, registry) -> None:
    with open_world("two_tables") as sim:
        robot = sim.robot
        problem = MotionProblem(robot)
        start = robot.q.copy()
        goal = start.copy()
        goal[:3] = (0.6, 0.3, 0.5)
        goal[3] = 0.3
        planner = registry.get("motion_planner", "kinodynamic").create({"time_limit": 20.0, "goal_tolerance": 0.1})
        plan = planner.plan(problem, start, goal, seed=2)
        assert plan is not None and plan.controls is not None
        assert validate_path(problem, plan.path, resolution=problem.resolution / 10, margin=0.0) is None
        run = robot.execute(plan, np.random.default_rng(0), noise=False)
        assert np.allclose(run.final, plan.path[-1], atol=1e-6)
        assert np.linalg.norm(run.final[:3] - goal[:3]) < 0.1 * np.sqrt(3) and abs(run.final[3] - goal[3]) < 1e-6
        noisy = robot.execute(plan, np.random.default_rng(1))
        assert not np.allclose(noisy.final[:3], plan.path[-1][:3])


def test_only_planners_the_ompl_bindings_have_are_offered(registry) -> None:
    """No silent substitution: lazy_prm exists only if ompl.geometric binds LazyPRM (2.0.1 does not)."""
    from ompl import geometric as og

    from explore.core import BadInput
    from explore.motion import control_planner_names, geometric_planner_names, planner_class

    names = registry.names("motion_planner")
    assert ("lazy_prm" in names) == hasattr(og, "LazyPRM")
    if not hasattr(og, "LazyPRM"):
        with pytest.raises(ValueError, match="LazyPRM"):
            planner_class("LazyPRM")
        with pytest.raises(BadInput):
            registry.create("motion_planner", "ompl", {"planner": "LazyPRM"}, "<test>")
    assert {"RRTConnect", "PRM", "BITstar", "KPIECE1"} <= set(geometric_planner_names())
    assert planner_class("prm") is og.PRM and planner_class("rrt_connect") is og.RRTConnect
    choices = next(p.choices for p in registry.get("motion_planner", "kinodynamic").params if p.name == "planner")
    assert set(choices) == set(control_planner_names()) and "rrt" in choices


def _wrapped(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("name", ["kinodynamic", "tuck_and_drive"])
def test_mobile_manipulator_drives_around_the_furniture(open_world, registry, name) -> None:
    """Cluttered: tuck the arm, drive past chair_1 to the far side, untuck; executed without noise
    the controls reach the goal (the gap closed by the steering) without touching the true world."""
    from explore.mapping import PVS

    with open_world("cluttered") as sim:
        robot = sim.robot
        pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.02)  # the bunny's box: unknown
        problem = MotionProblem(robot, space_free=pvs.is_free)
        start, goal = robot.q.copy(), robot.q.copy()
        goal[:3] = (1.5, 1.2, 3.0)
        goal[3:] += 0.2
        planner = registry.get("motion_planner", name).create({"time_limit": 20.0})
        plan = planner.plan(problem, start, goal, seed=3)
        assert plan is not None and plan.controls is not None and plan.exact
        assert np.allclose(plan.path[-1][3:], goal[3:], atol=1e-9)
        tucked = np.flatnonzero(np.all(np.abs(plan.path[:, 3:] - robot.travel_joints) < 1e-9, axis=1))
        moving = np.flatnonzero(np.any(np.abs(np.diff(plan.path[:, :2], axis=0)) > 1e-12, axis=1))
        assert set(moving) <= set(tucked)  # the base moves only with the arm tucked
        run = robot.execute(plan, noise=False, world="true")
        assert not run.collided
        assert np.allclose(run.final[:2], goal[:2], atol=1e-6) and abs(_wrapped(run.final[2] - goal[2])) < 1e-6


def test_geometric_planner_checks_the_turn_drive_turn_a_differential_base_drives(open_world, registry) -> None:
    """Base-only problem (arm pinned): every returned segment is valid as the base executes it."""
    with open_world("cluttered") as sim:
        robot = sim.robot
        start = robot.q.copy()
        problem = MotionProblem(robot).pinned(robot.joint_dofs, start)
        goal = start.copy()
        goal[:3] = (1.5, 1.2, 3.0)
        plan = registry.get("motion_planner", "rrt_connect").create({"time_limit": 20.0}).plan(
            problem, start, goal, seed=4)
        assert plan is not None
        executed = problem.motion_path(plan.path)
        assert len(executed) > len(plan.path)  # turns inserted
        assert validate_path(problem, executed, resolution=problem.resolution, margin=0.0) is None
        run = robot.execute(plan, noise=False, world="true")
        assert not run.collided and np.allclose(run.final, goal, atol=1e-6)


class _SlowProblem(MotionProblem):
    """Every validity check takes ``delay`` seconds longer (a CPU shared with other work)."""

    delay = 0.0

    def is_valid(self, q: np.ndarray, margin: float | None = None) -> bool:
        time.sleep(self.delay)
        return super().is_valid(q, margin)


def test_the_work_clock_makes_a_plan_independent_of_the_cpu_load(workcell, endpoints) -> None:
    """A 0.3 s limit on the work clock (validity checks at nominal cost) gives the same path
    when every check takes 2 ms longer; on the wall clock the slowdown cuts the search short."""
    from explore.motion import plan, work_clock

    results = {}
    for clock in ("work", "wall"):
        for delay in (0.0, 0.002):
            problem = _SlowProblem(workcell.robot)
            problem.delay = delay
            with work_clock() if clock == "work" else contextlib.nullcontext():
                found = plan(problem, *endpoints, "rrt_connect", time_limit=0.3, seed=1)
            results[clock, delay] = (found, problem.checks)
    (fast, fast_checks), (slow, slow_checks) = results["work", 0.0], results["work", 0.002]
    assert fast is not None and slow is not None
    assert np.array_equal(fast.path, slow.path) and fast_checks == slow_checks
    assert slow.planning_time > 0.3  # the same work took longer than the limit in wall time
    wall, wall_checks = results["wall", 0.002]
    assert wall_checks < fast_checks  # the wall clock stopped the same search earlier
    assert wall is None or not np.array_equal(wall.path, fast.path)


def test_a_work_budget_without_work_still_ends_by_the_wall_guard() -> None:
    """A planner that charges nothing cannot hang a run: the budget ends after
    WALL_FACTOR x limit + 1 s of wall time, and the run counts that wall time decided once
    (metrics.json's ``wall_guard_stops``); a budget ended by its work is not counted."""
    from explore.motion import WALL_FACTOR, Budget, wall_guard_stops, work_clock
    from explore.motion.planning_clock import charge

    with work_clock():
        budget = Budget(0.02)
        t0 = time.perf_counter()
        while not budget.expired():
            time.sleep(0.01)
        waited = time.perf_counter() - t0
        assert budget.expired() and wall_guard_stops() == 1
        worked = Budget(0.02)
        while not worked.expired():
            charge("planar")
        assert wall_guard_stops() == 1
    assert WALL_FACTOR * 0.02 + 1.0 <= waited + 0.011 < WALL_FACTOR * 0.02 + 1.5
    with work_clock():
        assert wall_guard_stops() == 0  # each run counts its own


def test_a_drive_keeps_its_drive_clearance_away_from_its_ends(open_world) -> None:
    """Start and goal 1.2 m apart beside the table, a few cm from it: the straight drive along
    its edge is valid with the 1 cm clearance; with drive_clearance 0.2 m the base may start and
    stop there, but every pose 0.2 m or more from both ends keeps 0.2 m from the table."""
    from explore.motion import PlanarChecker, box_distance, plan_mobile
    from explore.sim import p

    with open_world("scene_small_mm") as sim:
        robot = sim.robot
        table = next(b.body_id for b in sim.bodies if b.name == "table")
        lo, hi = (np.array(v) for v in p.getAABB(table, physicsClientId=sim.client))
        problem = MotionProblem(robot)
        start = robot.q.copy()
        start[:3] = (-0.6, -1.0, 0.0)  # heading along the table's south edge
        while problem.is_valid(start):  # creep up to the table
            start[1] += 0.005
        start[1] -= 0.03
        goal = start.copy()
        goal[0] = 0.6
        line = np.linspace(start[:3], goal[:3], 25)
        near = PlanarChecker(problem, start)
        assert all(near(qb) for qb in line)
        funnel = PlanarChecker(problem, start, drive_margin=0.2, ends=[start[:3], goal[:3]])
        assert funnel(line[0]) and funnel(line[-1]) and not funnel(line[12])
        robot.drive_clearance = 0.2
        found = plan_mobile(problem, start, goal, time_limit=20.0, seed=1)
        assert found is not None
        away = [q for q in found.path
                if min(np.linalg.norm(q[:2] - start[:2]), np.linalg.norm(q[:2] - goal[:2])) >= 0.2]
        assert away  # the drive leaves the funnels at the ends
        gaps = [box_distance(robot.link_points(q), lo[None], hi[None]).min() for q in away]
        assert min(gaps) >= 0.2 - 0.03  # surface samples every 3 cm


def test_a_drive_goal_only_the_denser_drive_check_refuses_fails_at_once(open_world) -> None:
    """An unknown speck on the robot at the goal pose that the 3 cm points of ``is_valid`` miss and the
    1.5 cm points of the drive's checker hit: the goal passes ``is_valid``, no drive can end there, and
    the plan fails on its work budget, not by idling until the wall-time hang guard (OMPL's
    RRT-Connect waits 10 ms per try for a valid goal sample)."""
    from scipy.spatial import cKDTree

    from explore.motion import PlanarChecker, plan_mobile, wall_guard_stops, work_clock

    with open_world("cluttered") as sim:
        robot = sim.robot
        start, goal = robot.q.copy(), robot.q.copy()
        goal[:3] = (1.5, 1.2, 3.0)
        dense, sparse = robot.link_points(goal, spacing=0.015), robot.link_points(goal)
        gaps = cKDTree(sparse).query(dense)[0]
        speck, radius = dense[np.argmax(gaps)], 0.5 * float(gaps.max())
        assert radius > 0.003

        def space_free(points: np.ndarray) -> np.ndarray:
            return np.linalg.norm(points - speck, axis=1) >= radius

        problem = MotionProblem(robot, space_free=space_free)
        assert problem.is_valid(start) and problem.is_valid(goal)
        assert not PlanarChecker(problem, goal)(goal[:3])
        with work_clock():
            found = plan_mobile(problem, start, goal, time_limit=1.0, seed=1, tuck=False)
            assert found is None and wall_guard_stops() == 0


def test_the_clustered_planar_kernel_gives_the_clearance_and_grid_points_of_every_point() -> None:
    """17 000 robot points moved to 500 random base poses among two boxes and beside a grid box: the
    kernel, which skips clusters far from both, returns the brute-force smallest distance whenever it is
    below ``reach`` (inf otherwise) and exactly the moved points inside the grid."""
    from explore.motion.kernels import planar_points_clearance, point_clusters
    from explore.motion.mobile import box_distance

    rng = np.random.default_rng(0)
    local, z = rng.uniform(-0.5, 0.5, (17000, 2)), rng.uniform(0.0, 1.2, 17000)
    clusters = point_clusters(local, z)
    assert len(clusters[3]) < len(local) / 10 and clusters[2][-1] == len(local)
    radius = float(np.sqrt((local**2).sum(axis=1)).max())
    lo, hi = np.array([[0.8, -0.3, 0.0], [-1.5, 1.0, 0.0]]), np.array([[1.2, 0.3, 0.7], [-1.0, 1.5, 1.0]])
    grid_lo, grid_hi = np.array([0.3, -2.0, 0.5]), np.array([2.0, 2.0, 2.0])
    out, near, inside_seen = np.empty((len(local), 3)), 0, 0
    for _ in range(500):
        x, y, theta, reach = rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-3, 3), rng.uniform(0.01, 0.3)
        c, s = math.cos(theta), math.sin(theta)
        moved = np.column_stack([c * local[:, 0] - s * local[:, 1] + x, s * local[:, 0] + c * local[:, 1] + y, z])
        distance = float(box_distance(moved, lo, hi).min())
        inside = moved[np.all((moved >= grid_lo) & (moved <= grid_hi), axis=1)]
        clearance, m = planar_points_clearance(*clusters, radius, x, y, theta, lo, hi, reach, grid_lo, grid_hi, out)
        if distance < reach:
            assert clearance == pytest.approx(max(distance, 0.0), abs=1e-12)
            near += 1
        else:
            assert clearance == np.inf
        assert m == len(inside)
        np.testing.assert_array_equal(np.sort(out[:m], axis=0), np.sort(inside, axis=0))
        inside_seen += m > 0
    assert near > 20 and inside_seen > 100  # both branches were exercised


def test_a_base_pose_is_blocked_by_a_wall_in_the_sparse_pvs_as_the_full_test_finds(open_world) -> None:
    """A wall of occupied voxels in a room-sized sparse PVS, 1.2 m ahead of the mobile manipulator: along a
    drive through it the planar checker (moved surface samples, the PVS's block bitmap) gives the verdict of
    the full test at every base pose, blocked only near the wall."""
    from test_pvs import make_scan

    from explore.mapping import SparsePVS
    from explore.motion import PlanarChecker

    with open_world("scene_small_mm") as sim:
        robot = sim.robot
        x0, y0, heading = robot.q[:3]
        pvs = SparsePVS([-3.0, -3.0, -0.1], [3.0, 3.0, 1.5], 0.01)
        ys, zs = np.meshgrid(np.linspace(y0 - 0.3, y0 + 0.3, 61), np.linspace(0.05, 1.0, 96))
        origins = np.column_stack([np.full(ys.size, x0), ys.ravel(), zs.ravel()])
        for _ in range(3):  # three returns: p > 0.75
            pvs.integrate(make_scan(origins, np.tile([1.0, 0.0, 0.0], (ys.size, 1)), np.full(ys.size, 1.2),
                                    max_range=2.0))
        problem = MotionProblem(robot, space_free=lambda points: pvs.probability_below(points, 0.75),
                                space_bounds=(pvs.min_corner, pvs.max_corner))
        checker, empty = PlanarChecker(problem, robot.q), PlanarChecker(MotionProblem(robot), robot.q)
        drive = [np.array([x, y0, heading]) for x in np.linspace(x0, x0 + 1.6, 60)]
        verdicts = [checker(qb) for qb in drive]
        assert verdicts == [problem.is_valid(checker.full(qb)) for qb in drive]
        assert all(empty(qb) for qb in drive)
        blocked = [float(qb[0] - x0) for qb, ok in zip(drive, verdicts, strict=True) if not ok]
        assert len(blocked) > 10 and 1.2 - checker.radius < blocked[0] and blocked[-1] < 1.2 + checker.radius


_ROADMAP_SOLVES = """
import sys
import numpy as np
from explore.core import look_at
from explore.motion import MotionProblem, plan
from explore.motion import work_clock
from explore.runtime import Registry
from explore.sim import Simulation

with Simulation("workcell", Registry.load()) as sim:
    rng = np.random.default_rng(0)
    a = sim.robot.ik(look_at([0.45, -0.25, 0.85], [0.7, -0.2, 0.45]), rng)
    b = sim.robot.ik(look_at([0.45, 0.3, 0.85], [0.75, 0.2, 0.45]), rng)
    problem = MotionProblem(sim.robot)
    paths = []
    for i in range(int(sys.argv[2])):
        with work_clock():
            found = plan(problem, a, b, sys.argv[1], time_limit=1.0, simplify=False, seed=1)
        paths.append(None if found is None else found.path.round(9).tobytes())
    print(sum(p is not None for p in paths), len(set(paths)))
"""


@pytest.mark.parametrize(("planner", "solves"), [("prm", 50), ("PRMstar", 10)])
def test_roadmap_planners_never_deadlock_and_repeat_their_path(planner, solves) -> None:
    """OMPL's PRM::solve looks for a solution in a second thread that would call Python while the
    main thread holds the GIL in join (a hang about one solve in three): consecutive solves all
    finish, all find a path, and the same seed gives the same path every time."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _ROADMAP_SOLVES, planner, str(solves)], capture_output=True,
                         text=True, timeout=150)
    assert out.returncode == 0, out.stderr[-2000:]
    found, distinct = map(int, out.stdout.split())
    assert found == solves and distinct == 1


def test_a_base_left_within_the_clearance_first_backs_out(registry, cluttered) -> None:
    """Noise can stop the base 5 mm from the table, inside the 1 cm planning clearance though not
    touching it; every motion from there is invalid. The plan then starts with a short motion,
    valid at zero clearance all along, to a configuration that keeps the clearance."""
    from explore.mapping import PVS
    from explore.nbv.scan_planning import ScanMotion, make_planner

    robot = cluttered.robot
    q = robot.q.copy()
    q[:3] = (0.615, -0.35, math.pi)  # facing the table (x <= 0.3), the base's front 5 mm from it
    motion = ScanMotion(robot, PVS(np.array([-0.2, -0.2, 0.72]), np.array([0.2, 0.2, 0.95]), 0.02),
                        make_planner(registry, robot, None), np.random.default_rng(0), 1, noise=True)
    problem = motion.problem
    assert not problem.is_valid(q) and not robot.in_collision(q, "known", 0.0)
    escape = motion._escape(q, problem)
    assert escape is not None and np.allclose(escape.path[0], q)
    assert problem.is_valid(escape.path[-1]) and all(problem.is_valid(x, margin=0.0) for x in escape.path)
    assert np.linalg.norm(escape.path[-1][:2] - q[:2]) <= 4 * 0.02 * math.sqrt(2)
    assert escape.controls is not None and len(escape.controls) == len(escape.path) - 1
