"""The motion planner contract: a collision-free motion from one configuration to another."""

from __future__ import annotations

from abc import ABC, abstractmethod

from explore.core import Array
from explore.core.plugin import Plugin
from explore.motion.problem import MotionProblem
from explore.motion.records import MotionPlan


class MotionPlanner(Plugin, ABC):
    """Contract of kind ``motion_planner``.

    :meth:`plan` gets a :class:`~explore.motion.problem.MotionProblem` (the robot, validity =
    the known environment + the PVS's free space where ``space_free`` is given, with the
    robot's ``clearance``), start and goal configurations ((dof,) arrays in the robot's joint
    units: metres and radians) and a seed for the planner's randomness. It returns a
    :class:`~explore.motion.records.MotionPlan` whose ``path`` (m, dof) starts at ``start``,
    ends at ``goal`` and is valid when re-checked at the problem's resolution, or None when
    no such motion was found in the planner's time budget. A plan may carry velocity
    ``controls`` held ``dt`` seconds each (non-holonomic bases); otherwise the robot derives
    them (``Robot.controls_from_path``). The same seed must give the same plan.
    """

    kind = "motion_planner"

    @abstractmethod
    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        """A valid motion from ``start`` to ``goal``, or None."""
