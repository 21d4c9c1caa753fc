"""Vasquez-Gomez expected utility as a utility plugin wrapping any other utility.

``expected_utility`` (kind ``utility``) scores each candidate view or scan path by
Algorithm 1 of Vasquez-Gomez et al. (:func:`explore.nbv.nbvs.expected_utility`): the robot's
configuration for the candidate comes from IK, the motion from the current configuration is
the straight segment in configuration space turned into per-``dt`` velocity controls, k noisy
rollouts are checked against the known environment and the PVS (unknown is an obstacle),
and the wrapped utility (``base``) is evaluated at the sampled final sensor poses, weighted
by their probabilities (Eq. 2-3, 10). A candidate whose straight motion is invalid, that IK
cannot reach, or that any sampled rollout drives into an obstacle scores 0. For the full
view/state pipeline with planned motions use :class:`explore.nbv.nbvs.NBVSSession`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.api import BadInput, Utility
from explore.core import Param
from explore.motion import MotionPlan, MotionProblem
from explore.nbv import Candidate, ObstacleField, PlanningContext, StateSamples, expected_utility
from explore.sim import ScanPath


class ExpectedUtility(Utility):
    """Expected utility (Vasquez-Gomez Alg. 1, k noisy rollouts) around any utility plugin."""

    name = "expected_utility"
    params = (
        Param("base", str, "area_factor", "", "the wrapped utility plugin"),
        Param("k", int, 100, "", "rollouts per candidate (Eq. 18: k >= 90 for alpha 0.01, gamma 0.05)", low=1),
        Param("seed", int, 0, "", "seed of the rollout noise", low=0),
    )

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self._base: Utility | None = None
        self._rng = np.random.default_rng(int(self.seed))

    def base_utility(self, ctx: PlanningContext) -> Utility:
        """The wrapped utility plugin, built on first use from the session's registry."""
        if self._base is None:
            if ctx.registry is None:
                raise BadInput("<expected_utility>", "base", "the planning context has no plugin registry")
            self._base = ctx.registry.create("utility", self.base, {}, "<expected_utility>", "base")
        return self._base

    def score(self, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        robot = ctx.robot
        base = self.base_utility(ctx)
        if robot is None or robot.sim is None:
            return np.asarray(base.score(candidates, ctx), dtype=float)
        obstacles = ObstacleField(ctx.environment_boxes, ctx.pvs, float(robot.clearance))
        problem = MotionProblem(robot, space_free=ctx.pvs.is_free)
        start = np.asarray(robot.q, dtype=float)
        out = np.zeros(len(candidates))
        for index, cand in enumerate(candidates):
            goal = robot.ik(cand.pose, ctx.rng)
            if goal is None or not problem.is_valid_motion(start, goal):
                cand.diagnostics.update({"eu_feasible": 0.0, "utility": 0.0})
                continue
            path = np.vstack([start, goal])
            nominal_pose = robot.fk(goal)

            def at_samples(samples: StateSamples, cand: Candidate = cand, nominal_pose: Any = nominal_pose) -> Any:
                moved = []
                for pose in samples.poses:
                    shift = pose @ np.linalg.inv(nominal_pose)
                    target = cand.target
                    if isinstance(target, ScanPath):
                        target = ScanPath(shift @ target.start, shift @ target.end, target.speed)
                    else:
                        target = shift @ np.asarray(target)
                    moved.append(Candidate(target, cand.source, dict(cand.info), cand.focus, cand.created))
                return base.score(moved, ctx)

            result = expected_utility(cand, at_samples, robot, MotionPlan(path), self._rng, self.k, obstacles)
            out[index] = result.value if result.feasible else 0.0
            cand.diagnostics.update({"eu_feasible": float(result.feasible), "eu_mean": result.mean,
                                     "utility": float(out[index])})
        return out


PLUGINS = [ExpectedUtility]
