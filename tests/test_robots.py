"""Robot plugins: every world builds, FK/IK round trips, IK success, noisy execution statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from explore.core import look_at, pose_error
from explore.motion import MotionPlan
from explore.sim import list_worlds


@pytest.mark.parametrize("world", [w.stem for w in list_worlds()])
def test_every_shipped_world_builds_with_a_valid_start(open_world, world: str) -> None:
    with open_world(world) as sim:
        robot = sim.robot
        assert robot.dof >= 3
        if robot.name != "free_flyer":  # the free flyer has no start pose of its own
            assert robot.collisions(robot.q, "true", 0.0) == []
            assert np.allclose(robot.fk(robot.q)[:3, :3].T @ robot.fk(robot.q)[:3, :3], np.eye(3))


def test_arm_fk_ik_round_trip_within_1mm_and_half_degree(workcell) -> None:
    robot = workcell.robot
    rng = np.random.default_rng(1)
    worst = np.zeros(2)
    for _ in range(10):
        pose = robot.fk(robot.sample_config(rng))
        q = robot.ik(pose, rng, check_collision=False)
        assert q is not None
        worst = np.maximum(worst, pose_error(robot.fk(q), pose))
        assert robot.within_limits(q)
    assert worst[0] <= 1e-3 and worst[1] <= math.radians(0.5)


def region_view_poses(sim, count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Views 0.3 m from points in the region, 20-50 deg off vertical, from the robot's side."""
    base = np.asarray(sim.spec.robot.base[:2])
    poses = []
    for target in rng.uniform(sim.spec.region_min, sim.spec.region_max, size=(count, 3)):
        toward = math.atan2(base[1] - target[1], base[0] - target[0]) + rng.uniform(-1.0, 1.0)
        elevation = rng.uniform(math.radians(20), math.radians(50))
        d = np.array(
            [math.sin(elevation) * math.cos(toward), math.sin(elevation) * math.sin(toward), math.cos(elevation)]
        )
        poses.append(look_at(target + 0.3 * d, target))
    return poses


def test_arm_ik_success_over_the_workcell_region(workcell) -> None:
    robot = workcell.robot
    rng = np.random.default_rng(2)
    solved = [robot.ik(pose, rng) for pose in region_view_poses(workcell, 20, rng)]
    assert sum(q is not None for q in solved) >= 18
    for q in solved:
        if q is not None:
            assert not robot.in_collision(q)


def test_mobile_base_ik_round_trip_and_reachability(two_tables) -> None:
    robot = two_tables.robot
    rng = np.random.default_rng(3)
    q = robot.q.copy()
    q[3:] = (0.4, 0.5)
    pose = robot.fk(q)
    q2 = robot.ik(pose, rng)
    assert q2 is not None
    dp, da = pose_error(robot.fk(q2), pose)
    assert dp <= 1e-3 and da <= math.radians(0.5)
    too_high = pose.copy()
    too_high[2, 3] += 0.5
    assert robot.ik(too_high, rng) is None


def test_mobile_manipulator_ik_round_trip(open_world) -> None:
    with open_world("cluttered") as sim:
        robot = sim.robot
        assert robot.dof >= 8
        rng = np.random.default_rng(4)
        pose = look_at([0.45, -0.35, 1.1], [0.0, 0.0, 0.8])
        q = robot.ik(pose, rng)
        assert q is not None
        dp, da = pose_error(robot.fk(q), pose)
        assert dp <= 1e-3 and da <= math.radians(0.5)
        assert not robot.in_collision(q)


def test_mobile_manipulator_ik_keeps_its_base_when_the_arm_reaches(open_world) -> None:
    """With ``keep_base`` (on in scene_small_mm) IK tries the current base first (a base that
    stays put keeps its odometry); a pose beyond the arm's reach moves the base; a plan that
    stays in place executes as a no-op."""
    with open_world("scene_small_mm") as sim:
        robot = sim.robot
        here = robot.q.copy()
        rng = np.random.default_rng(6)
        near = robot.ik(look_at([0.0, -0.75, 1.25], [0.0, 0.0, 0.65]), rng)
        assert near is not None and np.allclose(near[:3], here[:3])
        far = robot.ik(look_at([0.0, 0.75, 1.25], [0.0, 0.0, 0.65]), rng)  # across the table
        assert far is not None and np.linalg.norm(far[:2] - here[:2]) > 1.0
        robot.q = here
        robot.set_config(here)
        run = robot.execute(MotionPlan(here[None, :]), rng)
        assert len(run.controls) == 0 and np.allclose(run.final, here)


def test_noise_statistics_match_the_model(two_tables) -> None:
    """sigma_v = 1.65 mm/s, sigma_w = 0.28 rad/s, truncated at 3 sigma (Vasquez-Gomez Sec. A6)."""
    robot = two_tables.robot
    start = robot.q.copy()
    goal = start.copy()
    goal[0] += 0.6
    controls, nominal = robot.controls_from_path(np.vstack([start, goal]))
    rng = np.random.default_rng(5)
    eps, finals = [], []
    for _ in range(300):
        configs, e, log_prob = robot.rollout(start, controls, rng)
        eps.append(e)
        finals.append(configs[-1])
        assert np.isfinite(log_prob)
    eps = np.vstack(eps)
    sigma = robot.control_sigma()
    assert np.all(np.abs(eps) <= 3 * sigma + 1e-12)
    truncated_std = 0.9866 * sigma  # std of a normal truncated at +-3 sigma
    used = sigma > 0
    assert np.allclose(eps[:, used].std(axis=0), truncated_std[used], rtol=0.05)
    assert np.allclose(eps[:, used].mean(axis=0), 0.0, atol=0.05 * sigma[used].max())
    # heading error after k steps: sum of k independent errors * dt
    k = len(controls)
    theta_err = np.array(finals)[:, 2] - nominal[-1, 2]
    expected = truncated_std[2] * robot.dt * math.sqrt(k)
    assert abs(theta_err.std() / expected - 1.0) < 0.15
    # without noise the rollout is the nominal path
    configs, e, _ = robot.rollout(start, controls, rng, noise=False)
    assert np.allclose(configs[-1], goal, atol=1e-9) and not e.any()


def test_execution_records_collisions_with_the_true_world_only(open_world) -> None:
    with open_world("bunny_pedestal") as sim:
        robot = sim.robot
        a = robot.ik(look_at([-0.3, 0.0, 0.62], [0.0, 0.0, 0.6]))
        b = robot.ik(look_at([0.3, 0.0, 0.62], [0.6, 0.0, 0.6]))
        run = robot.execute(MotionPlan(np.vstack([a, b])), np.random.default_rng(0))
        assert run.collided and "bunny" in run.collisions[0].bodies
        known = robot.execute(MotionPlan(np.vstack([a, b])), np.random.default_rng(0), world="known")
        assert not known.collided and np.allclose(known.final, b)


SQUARE_TABLE = """
name: square_table
description: pybullet_data's table_square, whose top is a link below an empty base link
environment:
  - {name: floor, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01]}
  - {name: table, source: table_square/table_square.urdf, position: [0.0, 0.0, 0.32]}
objects:
  - {name: duck, source: duck.obj, size: 0.10, rpy_deg: [90, 0, 0], position: [0.0, 0.0], on_top_of: table}
region: {min: [-0.3, -0.3, 0.6], max: [0.3, 0.3, 0.8]}
robot: {plugin: mobile_base, base: [0.0, -1.0, 0.0, 90.0]}
sensor: {plugin: depth_camera, params: {width: 160, height: 120, min_range: 0.3, max_range: 2.0}}
"""


def test_a_body_whose_shape_is_in_a_child_link_is_an_obstacle(open_world, tmp_path) -> None:
    """The collision pre-filter took an environment body's box from its base link alone; table_square's
    base link is empty (a point on the floor), so the mast passed through the 0.6 m tabletop unseen.
    With the box around every link, the base 0.2 m inside the top's edge collides with it (known and
    true world, and for the planar checker), and 0.1 m outside it does not."""
    from explore.motion import MotionProblem, PlanarChecker

    world = tmp_path / "square_table.yaml"
    world.write_text(SQUARE_TABLE, encoding="utf-8")
    with open_world(world) as sim:
        robot = sim.robot
        checker = PlanarChecker(MotionProblem(robot), robot.q)
        verdicts = {}
        for y in (-0.4, -0.1):  # the mast at the base's centre; the top spans y -0.3..0.3 at 0.56-0.64 m
            q = np.asarray(robot.q, dtype=float).copy()
            q[1] = y
            verdicts[y] = (robot.in_collision(q, world="known", margin=0.0),
                           "table" in robot.collisions(q, "true", 0.0), not checker(q[:3]))
    assert verdicts == {-0.4: (False, False, False), -0.1: (True, True, True)}, verdicts


def _through_the_bunny(robot) -> MotionPlan:
    a = robot.ik(look_at([-0.3, 0.0, 0.62], [0.0, 0.0, 0.6]))
    b = robot.ik(look_at([0.3, 0.0, 0.62], [0.6, 0.0, 0.6]))
    return MotionPlan(np.vstack([a, b]))


def test_on_collision_stop_ends_the_motion_continue_records_every_step(bunny_sim) -> None:
    robot = bunny_sim.robot
    plan = _through_the_bunny(robot)
    robot.on_collision = "stop"
    stopped = robot.execute(plan, noise=False)
    robot.on_collision = "continue"
    kept = robot.execute(plan, noise=False)
    assert not stopped.completed and len(stopped.collisions) == 1
    first = stopped.collisions[0]
    assert len(stopped.configs) == first.step + 1 and np.allclose(stopped.final, first.config)
    assert kept.completed and np.allclose(kept.final, plan.path[-1])
    steps = [e.step for e in kept.collisions]
    assert steps[0] == first.step and len(steps) > 3 and steps == sorted(set(steps))  # one event per step
    assert all("bunny" in e.bodies for e in kept.collisions)  # the sphere passes through the bunny only


def test_execute_samples_the_noise_model(two_tables) -> None:
    """Through ``execute``: errors within 3 sigma with the truncated std, none while the base
    stands still (the pan-tilt head moves alone first), log P as the model, heading spread."""
    from explore.motion import truncated_normal_logpdf

    robot = two_tables.robot
    start = robot.q.copy()
    turned = start.copy()
    turned[3] = 0.6  # pan only: the base is commanded to stand still
    goal = turned.copy()
    goal[0] += 0.6
    plan = MotionPlan(np.vstack([start, turned, goal]))
    sigma = robot.control_sigma()
    runs = [robot.execute(plan, np.random.default_rng(seed), noise=True, world="none") for seed in range(150)]
    mask = robot.noise_mask(runs[0].controls)
    still = ~mask[:, 0]
    assert still.sum() > 10 and mask[:, 0].sum() > 10
    eps = np.vstack([r.noise for r in runs])
    active = np.vstack([mask] * len(runs))
    assert not np.any(eps[~active]) and np.all(np.abs(eps) <= 3 * sigma + 1e-12)
    used = sigma > 0
    moving = eps[active[:, 0]][:, used]
    assert np.allclose(moving.std(axis=0), 0.9866 * sigma[used], rtol=0.05)  # std of a normal cut at 3 sigma
    for run in runs[:5]:
        assert run.log_prob == pytest.approx(truncated_normal_logpdf(run.noise, sigma, robot.truncation, mask))
    heading = np.array([r.final[2] for r in runs]) - goal[2]
    expected = 0.9866 * sigma[2] * robot.dt * math.sqrt(mask[:, 0].sum())
    assert abs(heading.std() / expected - 1.0) < 0.15
    assert np.allclose(robot.execute(plan, noise=False, world="none").final, goal, atol=1e-9)


def test_differential_base_turns_drives_turns_symmetrically(open_world) -> None:
    """The executed path of a -> b is that of b -> a reversed (OMPL's bidirectional planners need it)."""
    with open_world("cluttered") as sim:
        robot = sim.robot
        a = robot.q.copy()
        b = a.copy()
        b[:3] = (a[0] - 0.5, a[1] + 0.4, a[2] + 2.5)
        b[3:] = a[3:] + 0.3
        forward = robot.execution_path(np.vstack([a, b]))
        backward = robot.execution_path(np.vstack([b, a]))
        assert len(forward) == 4 and np.allclose(forward, backward[::-1])
        heading = forward[1, 2]
        assert np.allclose(forward[1, :2], a[:2]) and np.allclose(forward[2, :2], b[:2])  # turn in place, drive
        assert forward[2, 2] == heading  # the drive keeps the heading ...
        d = b[:2] - a[:2]
        assert abs(abs(math.sin(heading - math.atan2(d[1], d[0])))) < 1e-9  # ... along the segment
        controls, rolled = robot.controls_from_path(np.vstack([a, b]))
        assert np.allclose(rolled[-1], b, atol=1e-9)
        assert np.allclose(controls[:, 1][np.abs(controls[:, 0]) > 1e-9], 0.0)  # no turning while driving


def test_link_points_of_a_degenerate_mesh_are_its_vertices_not_an_error() -> None:
    """A zero-size part (a free flyer of radius 0, a URDF mesh of zero area) samples its
    triangles uniformly instead of failing on probabilities that do not sum to 1."""
    from explore.motion.bullet_robot import _surface_samples

    vertices = np.zeros((3, 3))
    points = _surface_samples(vertices, np.array([[0, 1, 2]]), spacing=0.01)
    assert len(points) >= 1 and np.allclose(points, 0.0)
    tiny = np.array([[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [0.0, 1e-9, 0.0]])
    assert np.abs(_surface_samples(tiny, np.array([[0, 1, 2]]), spacing=0.01)).max() <= 1e-9
