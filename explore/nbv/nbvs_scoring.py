"""Scoring view/states: a motion plan to each survivor, the utility g = pos * reg * sur * dist (Vasquez-Gomez Eq.
4, 7, 8) or its expectation under positioning noise, and the choice (ties broken by sampling order)."""

from __future__ import annotations

import time

import numpy as np

from explore.core import pick_best, wrap_angle
from explore.motion import (
    MotionPlan,
    escape_motion,
    path_length,
)
from explore.nbv.candidates import Candidate
from explore.nbv.expected_utility import StateSamples, expected_utility
from explore.nbv.view_states import ViewState


class Scoring:
    """Part of :class:`NBVSSession`: planning, utility and selection of the candidates."""

    def plan(self, states: list[ViewState]) -> list[ViewState]:
        """Plan from the current state to each candidate; keep those with a motion (pos = 1).

        Every planner checks the motion as the robot executes it (a differential base turns,
        drives and turns; the kinodynamic and tuck-and-drive planners check their control
        rollout), so the noise-free execution of the controls is collision-free. A geometric
        path becomes per-``dt`` velocity controls (``controls_from_path``); planners that
        return controls keep them (their final state may differ from the candidate's: DU and
        EU score the state the controls reach). A start the planner calls invalid (noise left the
        robot within its clearance) is left first by a short motion valid at zero clearance
        (:func:`explore.motion.escape_motion`), which every plan then begins with.
        """
        robot, out = self.robot, []
        start, escape = self.q, None
        if not self.problem.is_valid(start):  # noise left the robot within the clearance: back out first
            rng = np.random.default_rng([self.plan_seed, len(self.plan_log)])
            escape = escape_motion(robot, self.problem, start, rng)
            if escape is not None:
                start = escape.path[-1]
        for i, s in enumerate(states):
            self.progress(f"motion planning: candidate {i + 1} of {len(states)}, {len(out)} planned")
            goal = s.q.copy()
            if robot.base_dofs:
                th = robot.base_dofs[2]
                goal[th] = start[th] + wrap_angle(goal[th] - start[th])
                if not robot.lower[th] <= goal[th] <= robot.upper[th]:
                    continue
            t0 = time.perf_counter()
            plan = self.planner.plan(self.problem, start, goal, seed=self.plan_seed + 2 * len(self.plan_log))
            self.plan_log.append((time.perf_counter() - t0, plan is not None))
            if plan is None:
                continue
            if plan.controls is not None:
                controls, nominal = np.asarray(plan.controls), np.asarray(plan.path)
            else:
                controls, nominal = robot.controls_from_path(plan.path)
            if len(controls) == 0:
                continue
            if escape is not None:
                controls, nominal = np.vstack([escape.controls, controls]), np.vstack([escape.path, nominal[1:]])
            s.plan = MotionPlan(nominal, controls=controls, dt=float(robot.dt), planner=plan.planner,
                                planning_time=plan.planning_time, length=path_length(robot, nominal))
            s.nominal, s.length = nominal, s.plan.length
            out.append(s)
        self.stages["planned"] = self.stages.get("planned", 0) + len(out)
        return out

    def utility_at(self, samples: StateSamples) -> np.ndarray:
        """g(s) = pos * reg * sur * dist (Eq. 4, area_factor) or score * dist (other utilities)."""
        cands = [Candidate(pose, "nbvs") for pose in samples.poses]
        scores = np.asarray(self.utility.score(cands, self.ctx), dtype=float)
        dist = 1.0 / (1.0 + np.asarray(samples.lengths, dtype=float))
        if self.utility is self.visibility:
            view = np.array([c.diagnostics["pos"] * c.diagnostics["reg"] * c.diagnostics["sur"] for c in cands])
        else:
            view = scores
        return view * dist

    def score(self, states: list[ViewState]) -> list[ViewState]:
        """DU at the nominal final state; with ``expected`` also Algorithm 1 (k samples)."""
        robot = self.robot
        for i, s in enumerate(states):
            self.progress(f"{'expected utility, ' + str(self.k) + ' rollouts' if self.expected else 'utility'}: "
                          f"candidate {i + 1} of {len(states)}")
            assert s.nominal is not None and s.plan is not None
            final = s.nominal[-1]
            nominal = StateSamples(final[None], robot.fk(final)[None], np.array([s.length]), np.zeros(1))
            s.deterministic = float(self.utility_at(nominal)[0])
            if self.expected:
                s.expected = expected_utility(s, self.utility_at, robot, s.plan, self.rng_eu, self.k, self.obstacles,
                                              weighting=self.weighting, feedback=self.relocalise,
                                              leg_length=self.leg_length)
                s.score = s.expected.value if s.expected.feasible else 0.0
            else:
                s.score = s.deterministic
        self.stages["feasible"] = self.stages.get("feasible", 0) + sum(1 for s in states if s.score > 0)
        return states

    def select(self, states: list[ViewState]) -> ViewState | None:
        """argmax of the (expected) utility; None if no candidate is feasible."""
        good = [s for s in states if s.score > 0]
        pick = pick_best([s.score for s in good])  # near-ties go to the first in sampling order
        if pick is None:
            return None
        good[pick.index].margin = pick.margin
        return good[pick.index]
