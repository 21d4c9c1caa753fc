"""Executing a plan with positioning noise: open loop against re-localising at its waypoints
(:func:`explore.motion.follow_plan`, the executor of the NBVS runs, of their rollouts and of
modelling with a mobile base)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from explore.motion import MotionPlan, control_pieces, execute_following, follow_plan

TRUNCATED_STD = 0.9866  # std of a normal truncated at +-3 sigma, in sigmas


@pytest.fixture
def drive(cluttered):
    """A turn-drive-turn of the mobile manipulator's base: 1.08 m, the heading +1 rad at the end."""
    robot = cluttered.robot
    start = robot.q.copy()
    goal = start.copy()
    goal[:3] += (-1.0, 0.4, 1.0)
    controls, nominal = robot.controls_from_path(np.vstack([start, goal]))
    return robot, start, controls, nominal


def test_the_plan_is_cut_where_its_control_changes(drive) -> None:
    robot, _, controls, _ = drive
    pieces = control_pieces(controls)
    assert len(pieces) == 3 and pieces[0][0] == 0 and pieces[-1][1] == len(controls)
    kinds = [("drive" if abs(controls[a, 0]) > 0 else "turn") for a, _ in pieces]
    assert kinds == ["turn", "drive", "turn"]
    assert control_pieces(np.zeros((0, 9))) == []


@pytest.mark.parametrize("feedback", [False, True])
def test_without_noise_both_controllers_follow_the_plan(drive, feedback: bool) -> None:
    robot, start, controls, nominal = drive
    rollouts = follow_plan(robot, start, controls, None, k=3, feedback=feedback)
    assert rollouts.configs.shape == (3, len(controls) + 1, robot.dof)
    assert np.allclose(rollouts.configs, nominal[None], atol=1e-9)
    assert np.allclose(rollouts.nominal, nominal, atol=1e-9) and not rollouts.log_prob.any()


def test_open_loop_heading_spreads_as_the_noise_model_says(drive) -> None:
    """Open loop the heading error is a sum of per-step errors: sd = 0.9866 sigma_w dt sqrt(steps)."""
    robot, start, controls, nominal = drive
    rollouts = follow_plan(robot, start, controls, np.random.default_rng(3), k=2000, feedback=False)
    spread = (rollouts.configs[:, -1, 2] - nominal[-1, 2]).std()
    expected = TRUNCATED_STD * robot.sigma_w * robot.dt * math.sqrt(len(controls))
    assert spread == pytest.approx(expected, rel=0.08)  # 0.28 rad/s over 9.9 s: about 0.2 rad
    assert np.isfinite(rollouts.log_prob).all() and rollouts.log_prob.std() > 0


def test_relocalising_keeps_the_errors_of_one_leg_only(drive) -> None:
    """Re-aimed every 0.25 m and turned back within 0.02 rad, the robot ends millimetres and
    about a hundredth of a radian from the plan's end; open loop it ends centimetres and a
    tenth of a radian away (re-localising only at the waypoints fixes the heading, not the drift)."""
    robot, start, controls, nominal = drive
    rng = np.random.default_rng(4)
    open_loop = follow_plan(robot, start, controls, rng, k=500, feedback=False)
    waypoints = follow_plan(robot, start, controls, rng, k=500, feedback=True, leg_length=0.0)
    legs = follow_plan(robot, start, controls, rng, k=500, feedback=True, leg_length=0.25)

    def position_error(r) -> np.ndarray:
        return np.hypot(*(r.configs[:, -1, :2] - nominal[-1, :2]).T)

    assert np.median(position_error(open_loop)) > 0.03
    assert np.median(position_error(legs)) < 0.2 * np.median(position_error(waypoints))
    assert np.median(position_error(legs)) < 0.01
    heading = np.abs(legs.configs[:, -1, 2] - nominal[-1, 2])
    assert np.quantile(heading, 0.99) < 0.05 and np.median(np.abs(open_loop.configs[:, -1, 2] - nominal[-1, 2])) > 0.05
    # all samples stay aligned in time with the noise-free run of the same controller
    assert legs.configs.shape[1] == len(legs.nominal) >= len(nominal)
    assert np.allclose(legs.nominal[-1], nominal[-1], atol=1e-9)


def test_the_executed_motion_is_a_rollout(drive) -> None:
    """The motion a robot executes is one sample of the same controller: its applied controls,
    executed without noise, reach exactly that sample's states."""
    robot, start, controls, _ = drive
    sample = follow_plan(robot, start, controls, np.random.default_rng(5), k=1, feedback=True, leg_length=0.25,
                         keep_controls=True)
    assert sample.applied is not None and sample.commands is not None
    run = robot.execute(MotionPlan(sample.configs[0], controls=sample.applied[0], dt=robot.dt), None, noise=False,
                        world="none")
    assert np.allclose(run.configs, sample.configs[0], atol=1e-9)
    errors = sample.applied[0] - sample.commands[0]
    assert np.abs(errors[:, :2]).max() <= 3 * np.array([robot.sigma_v, robot.sigma_w]).max() + 1e-12
    assert not errors[:, 2:].any()  # the arm is exact (sigma 0)


def test_execute_following_runs_the_relocalising_controller_in_the_true_world(cluttered) -> None:
    """The executor of modelling with a mobile base: the same states as the controller's sample
    from the same random numbers, ending within 1 cm of the plan (open loop: centimetres to
    decimetres, see above), with the errors recorded as the execution's noise."""
    robot = cluttered.robot
    start = robot.q.copy()
    x, y, _, yaw_deg = cluttered.spec.robot.base  # the world's start (other tests move the robot)
    start[:3] = (x, y, math.radians(yaw_deg))
    goal = start.copy()
    goal[:3] += (0.8, 0.0, 0.5)  # away from the table, past no chair
    controls, nominal = robot.controls_from_path(np.vstack([start, goal]))
    try:
        run = execute_following(robot, MotionPlan(nominal, controls=controls, dt=robot.dt), np.random.default_rng(6),
                                feedback=True, leg_length=0.25)
    finally:
        robot.q = start.copy()
        robot.set_config(start)
    sample = follow_plan(robot, start, controls, np.random.default_rng(6), k=1, feedback=True, leg_length=0.25,
                         keep_controls=True)
    assert run.completed and not run.collisions
    assert np.allclose(run.final, sample.configs[0, -1], atol=1e-9)
    assert np.hypot(*(run.final[:2] - nominal[-1, :2])) < 0.01
    assert np.allclose(run.noise, sample.applied[0] - sample.commands[0])
    assert np.abs(run.noise[:, :2]).max() > 0
