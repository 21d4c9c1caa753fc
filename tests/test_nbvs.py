"""Vasquez-Gomez view/state planning: expected utility (Algorithm 1), the k bound, the pipeline."""

from __future__ import annotations

import math

import numpy as np
import pytest

from explore.motion import MotionPlan, MotionProblem, follow_plan, plan_controls
from explore.nbv import (
    STAGES,
    NBVSSession,
    ObstacleField,
    StateSamples,
    colliding_rollouts,
    expected_utility,
    samples_needed,
)


def _ones(samples: StateSamples) -> np.ndarray:
    return np.ones(len(samples.configs))


def _drive_past_chair(robot, side: float) -> np.ndarray:
    """The base drives 0.65 m along -x with its flank ``side`` m from chair_1's face (y = 0.025)."""
    a = robot.q.copy()
    a[:3] = (1.6, 0.025 - 0.25 - side, math.pi)  # base half width 0.25 m
    b = a.copy()
    b[0] = 0.95
    return np.vstack([a, b])


def test_samples_needed_matches_the_paper() -> None:
    """Eq. 18: alpha 0.01, eta 1/0.997, gamma 0.05 -> k >= 90 (ln 0.01 / ln(1 - 0.05015) = 89.5)."""
    assert samples_needed(0.01, 1 / 0.997, 0.05) == 90
    assert samples_needed(0.05, 1.0, 0.1) == math.ceil(math.log(0.05) / math.log(0.9)) == 29
    assert samples_needed(0.001, 1 / 0.997, 0.05) > samples_needed(0.01, 1 / 0.997, 0.05)
    assert samples_needed(0.01, 1 / 0.997, 0.2) < 90
    assert samples_needed(0.01, 2.0, 0.6) == 1  # eta gamma >= 1: one sample always hits
    with pytest.raises(ValueError):
        samples_needed(0.01, 1.0, 0.0)


def test_expected_utility_rejects_a_candidate_whose_noisy_reach_hits_an_obstacle(cluttered) -> None:
    """3.5 cm past chair_1: the nominal motion is valid (DU accepts), noisy rollouts hit the chair."""
    robot = cluttered.robot
    path = _drive_past_chair(robot, 0.035)
    problem = MotionProblem(robot)
    assert problem.is_valid_motion(path[0], path[1])  # deterministic: pos = 1
    field = ObstacleField.from_sim(cluttered)
    plan = MotionPlan(path)
    # DU (no noise, k = 1 at the nominal final state) accepts the candidate
    controls, nominal = robot.controls_from_path(path)
    assert all(field.clearance(robot.link_points(q)).min() >= 0.0 for q in nominal)
    eu = expected_utility(None, _ones, robot, plan, np.random.default_rng(0), k=100, obstacles=field)
    assert not eu.feasible and eu.value == 0.0 and eu.collided_sample is not None
    # the rejection is real: noisy executions in the true world do hit the chair
    hits = [robot.execute(plan, np.random.default_rng(s), noise=True).collisions for s in range(20)]
    assert any(any("chair_1" in e.bodies for e in events) for events in hits)
    # the same test over every rollout: open loop about a quarter touch the chair, re-localising fewer
    start, controls = plan_controls(robot, plan)
    open_loop = colliding_rollouts(robot, follow_plan(robot, start, controls, np.random.default_rng(0), 100, False),
                                   field)
    relocalised = colliding_rollouts(robot, follow_plan(robot, start, controls, np.random.default_rng(0), 100, True,
                                                        0.25), field)
    assert open_loop.mean() > 0.2 and relocalised.mean() < 0.75 * open_loop.mean()
    first = colliding_rollouts(robot, follow_plan(robot, start, controls, np.random.default_rng(0), 100, False),
                               field, stop_at_first=True)
    assert first.sum() == 1 and open_loop[np.flatnonzero(first)[0]]
    # far from the chair (1 m) every rollout is clear and E(G) is the utility's value
    far = expected_utility(None, _ones, robot, MotionPlan(_drive_past_chair(robot, 1.0)),
                           np.random.default_rng(0), k=100, obstacles=field)
    assert far.feasible and far.value == pytest.approx(1.0)
    assert far.weights.sum() == pytest.approx(1.0) and len(far.utilities) == 100


def test_rollout_collisions_match_a_test_of_every_sample_at_every_step(cluttered) -> None:
    """The rigid test moves its reference robot only now and then along the nominal base (and keeps it
    across calls); it must still flag exactly the rollouts that a point-by-point test of every
    sample's own robot at every step flags (open loop, 1.5 cm past chair_1: some hit, some do not)."""
    robot = cluttered.robot
    start, controls = plan_controls(robot, MotionPlan(_drive_past_chair(robot, 0.015)))
    rollouts = follow_plan(robot, start, controls, np.random.default_rng(3), 12, False)
    field = ObstacleField.from_sim(cluttered)
    brute = np.array([any(field.clearance(robot.link_points(q)).min() < 0.0 for q in sample[1:])
                      for sample in rollouts.configs])
    assert 0 < brute.sum() < len(brute)
    for _ in range(2):  # the second time with the references kept from the first
        assert np.array_equal(colliding_rollouts(robot, rollouts, field), brute)
    # 30 cm from the chair the reference follows the 0.65 m drive in a few moves, not one per step
    start, controls = plan_controls(robot, MotionPlan(_drive_past_chair(robot, 0.3)))
    nominal = follow_plan(robot, start, controls, None).nominal
    moves = len({field.rigid_reference(robot, q).pose for q in nominal})
    assert len(nominal) > 40 and moves <= 6


def test_rollouts_keep_the_robot_margin_from_the_pvs(cluttered) -> None:
    """A PVS wall 6 cm beside the base's flank: its 3 cm surface samples alone would pass every open-loop
    rollout, the robot's ``space_margin`` (clearance + sample gap) rejects most; the rigid kernel and the
    point-by-point test agree with and without it."""
    from explore.mapping import PVS

    robot = cluttered.robot
    path = _drive_past_chair(robot, 0.3)
    flank = float(robot.link_points(path[0])[:, 1].min())
    pvs = PVS(np.array([0.8, flank - 0.12, 0.0]), np.array([1.8, flank + 0.08, 0.6]), 0.01)
    pvs.log_odds[:] = -5.0
    ijk = np.argwhere(np.ones(pvs.shape, dtype=bool))
    pvs.log_odds[tuple(ijk[pvs.centers(ijk)[:, 1] < flank - 0.06].T)] = 5.0
    pvs.version += 1
    start, controls = plan_controls(robot, MotionPlan(path))
    rollouts = follow_plan(robot, start, controls, np.random.default_rng(3), 12, False)
    flagged = {}
    for margin in (robot.space_margin, 0.0):
        field = ObstacleField.from_sim(cluttered, pvs)
        field.space_margin = margin
        brute = np.array([any(field.clearance(robot.link_points(q)).min() < 0.0 for q in sample[1:])
                          for sample in rollouts.configs])
        assert np.array_equal(colliding_rollouts(robot, rollouts, field), brute)
        flagged[margin] = int(brute.sum())
    assert flagged[0.0] == 0 and flagged[robot.space_margin] >= 6


def test_expected_utility_weights_by_probability(cluttered) -> None:
    robot = cluttered.robot
    plan = MotionPlan(_drive_past_chair(robot, 1.0))
    field = ObstacleField.from_sim(cluttered)

    def utility(samples: StateSamples) -> np.ndarray:
        return samples.configs[:, 1]  # final y: varies with the noise

    eu = expected_utility(None, utility, robot, plan, np.random.default_rng(1), k=50, obstacles=field,
                          weighting="probability")
    assert eu.feasible
    assert eu.value == pytest.approx(float(np.sum(eu.utilities * eu.weights)))
    assert np.ptp(eu.utilities) > 0  # the samples really differ
    again = expected_utility(None, utility, robot, plan, np.random.default_rng(1), k=50, obstacles=field,
                             weighting="probability")
    assert again.value == eu.value  # deterministic for a seed


def test_filter_pipeline_counts_are_monotone(open_world, registry) -> None:
    with open_world("cluttered") as sim:
        session = NBVSSession(sim, registry, expected=True, k=10, n_samples=2000, seed=0, top=5)
        session.initial()
        sampled = session.sample()
        # n_samples states whose director ray hits the region, drawn uniformly (~1 % of the draws)
        assert session.stages["ray_hits"] == len(sampled) == 2000 and session.stages["sampled"] > 50 * 2000
        for state in sampled[::97]:  # the grouped FK (base pose @ arm FK) is the robot's FK
            assert np.allclose(state.pose, sim.robot.fk(state.q), atol=1e-6)  # pybullet works in float32
            axis = state.pose[:3, 2]
            t = np.linspace(0.0, sim.sensor.max_range, 3000)[:, None]
            along = state.pose[:3, 3] + t * axis
            assert np.any(np.all((along >= session.region_min - 1e-3) & (along <= session.region_max + 1e-3), axis=1))
        states = session.score(session.plan(session.filter(sampled)))
        counts = [session.stages[name] for name in STAGES]
        assert all(a >= b for a, b in zip(counts[1:-1], counts[2:], strict=True)), counts
        assert len(states) == session.stages["planned"] <= 5
        for state in states:
            assert state.plan is not None and state.plan.controls is not None
            assert state.reg == 1.0 and state.occ / (state.occ + state.unk) > 0.5  # Eq. 5, h = 0.5
            assert state.unk >= session.min_unknown


# cluttered turned about: the robot starts beside the table, where the best-aimed arm pose is level with its top
TEDDY_ROOM = """name: teddy_room
environment:
  - {name: floor, box: [4.0, 4.0, 0.02], position: [0.0, 0.0, -0.01]}
  - {name: table, box: [0.5, 0.7, 0.70], position: [0.0, 0.0, 0.35]}
  - {name: chair_1, box: [0.45, 0.45, 0.9], position: [0.6, -0.4, 0.45]}
  - {name: shelf, box: [0.3, 1.0, 1.4], position: [0.0, 1.0, 0.7]}
objects:
  - {name: teddy, source: teddy_vhacd.urdf, size: 0.14, rpy_deg: [90, 0, 30], position: [0.0, 0.0], on_top_of: table}
region: {min: [-0.2, -0.2, 0.70], max: [0.2, 0.2, 0.92]}
robot: {plugin: mobile_manipulator, base: [-1.2, 0.6, 0.0, -30.0]}
sensor: {plugin: depth_camera, params: {width: 160, height: 120, min_range: 0.2, max_range: 1.5}}
"""


def test_the_first_view_looks_from_above_so_that_later_views_can_overlap_it(open_world, registry, tmp_path) -> None:
    """The arm pose aimed best at the region put the camera 5 cm above the table top: it saw the
    teddy's lower side (10 % of it, 310 occupied voxels) and no sampled state overlapped that by
    h = 0.5, so the run ended after its first view. From above the region's top the table is seen
    too, and hundreds of states pass the registration overlap."""
    path = tmp_path / "teddy_room.yaml"
    path.write_text(TEDDY_ROOM)
    with open_world(path) as sim:
        session = NBVSSession(sim, registry, expected=False, n_samples=2000, seed=0, top=5)
        session.initial()
        assert session.scan_poses[0][2, 3] >= session.region_max[2]
        session.filter(session.sample())
    assert session.stages["registration"] >= 50, session.stages


def test_view_state_planning_refuses_a_line_sensor(open_world, registry) -> None:
    """A laser striper takes one stripe per view: the run ended `no_candidates` at coverage 0."""
    from explore.core import BadInput

    with open_world("bunny_pedestal") as sim, pytest.raises(BadInput, match="sensor: view/state planning takes single"):
        NBVSSession(sim, registry)


def test_two_view_nbvs_run_increases_coverage(open_world, registry) -> None:
    with open_world("cluttered") as sim:
        # the paper's DU row (no noise): the views land where they were chosen
        session = NBVSSession(sim, registry, expected=False, n_samples=2000, seed=0, max_views=2, top=8,
                              noise=False)
        summary = session.run()
        coverage = summary["coverage"]
        assert summary["views"] == 3, summary["reason"]  # the initial scan + 2 planned views
        assert coverage[-1] > coverage[0] > 0.0
        assert summary["collisions"] == 0


def test_log_probability_is_the_truncated_normal_density() -> None:
    """log P (Eq. 2-3) = sum of scipy's truncated-normal log densities over the sampled errors."""
    from scipy.stats import truncnorm

    from explore.motion import truncated_normal, truncated_normal_logpdf

    sigma = np.array([1.65e-3, 0.28, 0.0])
    eps = truncated_normal(np.random.default_rng(3), sigma, 40)
    eps[:, 2] = 0.0
    active = np.ones_like(eps, dtype=bool)
    active[:10] = False  # e.g. the base stands still while the arm moves
    expected = sum(truncnorm.logpdf(eps[10:, j], -3, 3, scale=sigma[j]).sum() for j in range(2))
    assert truncated_normal_logpdf(eps, sigma, 3.0, active) == pytest.approx(expected, rel=1e-9)
    assert truncated_normal_logpdf(eps, sigma) == pytest.approx(
        sum(truncnorm.logpdf(eps[:, j], -3, 3, scale=sigma[j]).sum() for j in range(2)), rel=1e-9)


def test_expected_utility_weights_and_effective_sample_size(cluttered) -> None:
    """Algorithm 1's weights are eta P_i (ESS below k); the default ``mean`` weights give ESS = k."""
    robot = cluttered.robot
    plan = MotionPlan(_drive_past_chair(robot, 1.0))
    field = ObstacleField.from_sim(cluttered)

    def utility(samples: StateSamples) -> np.ndarray:
        return samples.configs[:, 1]

    paper = expected_utility(None, utility, robot, plan, np.random.default_rng(2), k=40, obstacles=field,
                             weighting="probability")
    flat = expected_utility(None, utility, robot, plan, np.random.default_rng(2), k=40, obstacles=field)
    assert flat.ess == pytest.approx(40.0) and flat.value == pytest.approx(float(flat.utilities.mean()))
    assert 1.0 <= paper.ess < 40.0
    assert paper.ess == pytest.approx(1.0 / np.sum(paper.weights**2))
    assert np.array_equal(paper.utilities, flat.utilities)


def _free_flyer_context(sim, registry):
    from explore.mapping import PVS, VoxelGrid
    from explore.nbv import PlanningContext

    pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.01)
    prob = (1.0 / (1.0 + np.exp(-pvs.log_odds.astype(np.float64)))).astype(np.float32)
    grid = VoxelGrid(prob, np.asarray(pvs.origin, dtype=float), float(pvs.resolution))
    return PlanningContext(pvs=pvs, surface=None, grid=grid, sensor=sim.sensor, robot=sim.robot,
                           region_min=np.asarray(sim.spec.region_min), region_max=np.asarray(sim.spec.region_max),
                           environment_boxes=[tuple(b.mesh.bounds) for b in sim.bodies if not b.is_object],
                           rng=np.random.default_rng(0), registry=registry)


def test_expected_utility_plugin_wraps_any_utility(open_world, registry) -> None:
    """Without noise EU equals the wrapped utility; with noise a path 5 mm from the pedestal scores 0."""
    from explore.core import look_at
    from explore.nbv import Candidate

    with open_world("bunny_pedestal") as sim:
        robot = sim.robot
        ctx = _free_flyer_context(sim, registry)
        base = registry.create("utility", "unknown_count", {}, "<test>")
        eu = registry.create("utility", "expected_utility", {"base": "unknown_count", "k": 30}, "<test>")
        bunny = np.array([0.0, 0.0, 0.6])

        def view(x: float, y: float) -> np.ndarray:
            return look_at([x, y, 0.3], bunny)

        robot.q = robot.ik(view(0.085, -0.3))  # sphere (r 3 cm) 3.5 cm from the pedestal face x = 0.05
        near, far = Candidate(view(0.085, 0.3), "test"), Candidate(view(0.4, 0.3), "test")
        plain = base.score([near, far], ctx)
        assert np.all(plain > 0)
        assert np.allclose(eu.score([near, far], ctx), plain, rtol=1e-12)  # no noise: every sample is nominal
        robot.sigma_position = 0.02  # m/s per axis: ~1 cm spread after the 6 s drive
        scored = eu.score([near, far], ctx)
        assert scored[0] == 0.0 and near.diagnostics["eu_feasible"] == 0.0
        assert scored[1] > 0.0 and far.diagnostics["eu_feasible"] == 1.0
        assert scored[1] == pytest.approx(plain[1], rel=0.5)  # the samples see about what the nominal sees


@pytest.mark.slow
def test_nbvs_mobile_tree_runs_a_short_mission(registry, tmp_path) -> None:
    """trees/nbvs_mobile.yaml with vasquez/eu: the first scan and two planned views, executed
    without noise (EU still scores with the noise model), with the metrics and pictures."""
    import json

    from explore.runtime import RunConfig, execute, load_tree

    tree = load_tree("nbvs_mobile", registry)
    assert {n.behaviour for n in tree.root.walk() if n.behaviour} >= {
        "start_nbvs", "nbvs_sample_states", "nbvs_filter", "nbvs_plan", "nbvs_score", "nbvs_select",
        "nbvs_execute", "nbvs_acquire", "nbvs_integrate", "nbvs_check_termination"}
    settings = {"start_nbvs.n_samples": 800, "start_nbvs.top": 6, "start_nbvs.noise": False, "strategy.k": 10}
    config = RunConfig(tree="nbvs_mobile", world="cluttered", strategy="vasquez/eu", seed=0, max_scans=2,
                       settings=settings, out=tmp_path / "run")
    result = execute(config, registry)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert result.status == "budget_exhausted" and result.reason == "max_views = 1 reached", result.reason
    assert metrics["expected_utility"] and metrics["k"] == 10 and metrics["strategy"] == "vasquez/eu"
    assert 2 <= metrics["scans"] <= 3 and metrics["trajectories"] == metrics["scans"] - 1
    assert metrics["collisions"] == 0
    coverage = metrics["coverage_per_scan"]
    assert len(coverage) == metrics["scans"] and coverage[-1] > coverage[0] > 0.0
    assert all(b >= a for a, b in zip(coverage, coverage[1:], strict=False))
    assert metrics["planning"]["queries"] >= 6 and metrics["planning"]["success_rate"] > 0.0
    assert metrics["path_length"] > 0.0 and metrics["path_length_m"] > 0.0
    assert len(metrics["ess_per_move"]) == metrics["trajectories"]
    assert metrics["relocalise"] and metrics["leg_length"] == 0.25 and metrics["weighting"] == "mean"
    stages = metrics["stage_s_per_move"]
    assert len(stages) == metrics["trajectories"] and {"sample", "filter", "plan", "score", "execute"} <= set(stages[0])
    assert metrics["selection_s_median"] > 0.0
    for name in ("trajectories.png", "coverage.png", "pvs.npz", "pvs.bt", "points.ply", "trace.jsonl"):
        assert (tmp_path / "run" / name).stat().st_size > 0


def test_a_start_within_the_clearance_is_left_by_a_short_motion_first(cluttered, registry) -> None:
    """Noise can leave the base nearer chair_1 than the planning clearance without touching it; no motion
    starts from there, so the view/state plan first backs out (valid at zero clearance) and every
    candidate's plan begins with that motion."""
    from explore.nbv.view_states import ViewState

    robot = cluttered.robot
    saved = robot.q.copy()
    try:
        session = NBVSSession(cluttered, registry, expected=False, seed=0, max_views=1)
        goal = session.q.copy()
        near = goal.copy()
        near[:3] = (0.65, -0.308, math.pi / 2)  # facing chair_1, nearer than the planning clearance (1 cm)
        assert not robot.in_collision(near, "known", margin=0.0) and not session.problem.is_valid(near)
        assert session.planner.plan(session.problem, near, goal, seed=1) is None  # no plan from there
        session.q = near
        planned = session.plan([ViewState(q=goal, pose=robot.fk(goal))])
        assert len(planned) == 1
        nominal = planned[0].nominal
        assert np.allclose(nominal[0], near) and np.allclose(nominal[-1][:2], goal[:2], atol=0.02)
        assert not any(robot.in_collision(q, "known", margin=0.0) for q in nominal)
    finally:
        robot.q = saved
        robot.set_config(saved)


def test_rollouts_call_free_the_space_the_robot_stands_in() -> None:
    """An eye-in-hand camera never sees the space its arm fills: as unknown voxels they made every
    rollout from there collide; once the robot has stood in them they are free for the rollouts too."""
    from explore.mapping import PVS
    from explore.motion import BodyFreeSpace

    pvs = PVS(np.zeros(3), np.full(3, 0.3), 0.01)  # all unknown
    space = BodyFreeSpace(pvs)
    field = ObstacleField([], space)
    probe = np.array([[0.155, 0.155, 0.155]])
    assert field.clearance(probe)[0] < 0.0
    axis = np.arange(0.105, 0.21, 0.01)
    space.stand(np.stack(np.meshgrid(axis, axis, axis), axis=-1).reshape(-1, 3))  # an 11 cm cube of body
    half_diagonal = 0.5 * math.sqrt(3.0) * 0.01
    assert field.clearance(probe)[0] == pytest.approx(0.06 - half_diagonal, abs=1e-9)  # 6 voxels to the unknown
    assert ObstacleField([], pvs).clearance(probe)[0] < 0.0  # the PVS itself is unchanged
