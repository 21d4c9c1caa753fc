"""Out of a start the planner calls invalid: positioning noise can leave a robot nearer the known
environment (or the unknown space around it) than the planning clearance without touching anything,
and no planned motion starts from there (MoveIt's FixStartStateCollision does the same)."""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import Array
from explore.motion.problem import MotionProblem, path_is_valid, path_length
from explore.motion.records import MotionPlan


def escape_motion(robot: Any, problem: MotionProblem, start: Array, rng: np.random.Generator,
                  tries: int = 64) -> MotionPlan | None:
    """A small motion from ``start`` to a valid configuration, valid at zero clearance all along.

    Configurations within 1-4 steps (2 cm / 0.03 rad of a base, 0.02 rad of a joint), nearest
    first, as the robot's velocity controls; None if none will do.
    """
    step = np.full(len(start), 0.02)
    base = list(robot.base_dofs)
    if base:
        step[base] = (0.02, 0.02, 0.03)
    for radius in (1, 2, 3, 4):
        nearby = start + radius * step * rng.uniform(-1.0, 1.0, (tries, len(start)))
        for q in nearby[np.argsort([robot.distance(start, q) for q in nearby], kind="stable")]:
            if not problem.is_valid(q):
                continue
            controls, rolled = robot.controls_from_path(np.vstack([start, q]))
            if path_is_valid(problem, rolled[1:], resolution=np.inf, margin=0.0):
                return MotionPlan(rolled, controls=controls, dt=float(robot.dt), planner="escape",
                                  length=path_length(robot, rolled))
    return None


def joined_plans(first: MotionPlan, second: MotionPlan, robot: Any) -> MotionPlan:
    """One plan: ``first`` then ``second`` (which starts where ``first`` ends)."""
    path = np.vstack([first.path, second.path[1:]])
    controls = None if second.controls is None else np.vstack([first.controls, second.controls])
    return MotionPlan(path, controls=controls, dt=float(robot.dt) if controls is not None else 0.0,
                      planner=f"{first.planner}+{second.planner}", planning_time=second.planning_time,
                      length=first.length + second.length)
