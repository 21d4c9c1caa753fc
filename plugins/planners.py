"""Motion planner plugins (kind ``motion_planner``): OMPL geometric planners by name, a
kinodynamic base planner (``ompl.control``) and the straight line for the free flyer.

Every plugin has ``plan(problem, start, goal, seed=None) -> MotionPlan | None`` where
``problem`` is an :class:`explore.motion.MotionProblem` (validity = known environment +
optional PVS free-space test).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import Array, BadInput, Param
from explore.motion import (
    OPTIONAL_GEOMETRIC,
    MotionPlan,
    MotionPlanner,
    MotionProblem,
    control_planner_names,
    plan,
    plan_kinodynamic,
    plan_mobile,
    planner_class,
    straight_line,
)


def _control_choices() -> tuple[str, ...]:
    """The ompl.control planners the installed bindings can construct (rrt, kpiece, est with 2.0.1)."""
    try:
        return tuple(control_planner_names())
    except ImportError:
        return ("rrt",)


CONTROL_CHOICES = _control_choices()

_GEOMETRIC = (
    Param("time_limit", float, 1.0, "s", "planning time limit", low=0.001),
    Param("range", float, 0.0, "rad", "maximum step of tree extension (0 = OMPL default)", low=0.0),
    Param("simplify", bool, True, "", "shortcut the path (OMPL reduceVertices, collapseCloseVertices)"),
    Param("try_direct", bool, True, "", "return the straight segment when it is valid, without OMPL"),
    Param("check_factor", float, 3.0, "", "search checks motions every factor x resolution (result re-checked "
          "at the resolution)", low=1.0),
)


class GeometricPlanner(MotionPlanner):
    """An OMPL geometric planner in the robot's configuration space."""

    name = "ompl"
    ompl_name = "RRTConnect"
    params: tuple = _GEOMETRIC

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        """A simplified, densely re-checked collision-free path or None."""
        return plan(
            problem,
            start,
            goal,
            self.ompl_name,
            self.time_limit,
            self.simplify,
            self.range,
            seed,
            try_direct=self.try_direct,
            check_factor=getattr(self, "check_factor", 3.0),
        )


def _geometric(plugin_name: str, ompl_name: str, doc: str) -> type[GeometricPlanner]:
    return type(
        f"Planner_{plugin_name}", (GeometricPlanner,), {"name": plugin_name, "ompl_name": ompl_name, "__doc__": doc}
    )


RRTConnect = _geometric(
    "rrt_connect", "RRTConnect", "Bidirectional RRT-Connect (Kuffner & LaValle 2000), as in Kriegel's thesis."
)
RRT = _geometric("rrt", "RRT", "Single-tree RRT (LaValle 1998).")
RRTStar = _geometric("rrt_star", "RRTstar", "Asymptotically optimal RRT* (uses the whole time limit).")
PRM = _geometric("prm", "PRM", "Probabilistic roadmap (Kavraki 1996), as in Kriegel et al. 2012.")
KPIECE = _geometric("kpiece", "KPIECE1", "KPIECE: projection-based cell exploration.")
BITStar = _geometric("bit_star", "BITstar", "Batch informed trees BIT* (asymptotically optimal).")


class OmplByName(GeometricPlanner):
    """Any OMPL geometric planner by its ompl.geometric class name (the wheel's list; no LazyPRM in ompl 2.0.1)."""

    name = "ompl"
    params = (Param("planner", str, "BKPIECE1", "", "ompl.geometric class name (e.g. FMT, PRMstar)"), *_GEOMETRIC)

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        try:
            planner_class(self.planner)
        except ValueError as error:
            raise BadInput("<motion_planner ompl>", "planner", str(error)) from None

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        return plan(
            problem,
            start,
            goal,
            self.planner,
            self.time_limit,
            self.simplify,
            self.range,
            seed,
            try_direct=self.try_direct,
            check_factor=getattr(self, "check_factor", 3.0),
        )


class Kinodynamic(MotionPlanner):
    """Kinodynamic base planner (ompl.control, unicycle/omni model): tuck, drive, untuck; velocity controls."""

    name = "kinodynamic"
    params = (
        Param("time_limit", float, 5.0, "s", "planning time limit (the whole call)", low=0.001),
        Param("planner", str, "rrt", "", "ompl.control planner (SST and PDST cannot be built with ompl 2.0.1)",
              choices=CONTROL_CHOICES),
        Param("goal_tolerance", float, 0.4, "", "goal region radius around the base goal (L2 of m and rad)",
              low=1e-4),
        Param("connect", bool, True, "", "close the gap to the goal with the robot's steering when valid"),
        Param("propagation_step", float, 0.2, "s", "OMPL propagation step (states checked there)", low=1e-3),
        Param("min_duration", float, 0.8, "s", "shortest control duration", low=1e-3),
        Param("max_duration", float, 4.0, "s", "longest control duration", low=1e-3),
        Param("goal_bias", float, 0.05, "", "probability that RRT extends toward the goal (rrt only)",
              low=0.0, high=1.0),
        Param("tuck", bool, True, "", "move the arm to its travel configuration before driving"),
    )

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        """Controls: joints to travel configuration, the base to near ``goal``, joints to ``goal``."""
        return plan_kinodynamic(
            problem, start, goal, self.planner, self.time_limit, self.goal_tolerance, seed, self.max_duration,
            tuck=self.tuck, goal_bias=self.goal_bias, propagation_step=self.propagation_step,
            min_duration=self.min_duration, connect=self.connect,
        )


class TuckAndDrive(MotionPlanner):
    """Mobile robots: arm to travel configuration, base path by an OMPL geometric planner, arm to goal."""

    name = "tuck_and_drive"
    params = (
        Param("time_limit", float, 5.0, "s", "planning time limit (the whole call)", low=0.001),
        Param("planner", str, "rrt_connect", "", "OMPL geometric planner of the base path (x, y, theta)"),
        Param("tuck", bool, True, "", "move the arm to its travel configuration before driving"),
        Param("simplify", bool, True, "", "shortcut the base path between its vertices"),
    )

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        try:
            planner_class(self.planner)
        except ValueError as error:
            raise BadInput("<motion_planner tuck_and_drive>", "planner", str(error)) from None

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        """Controls along joints -> travel, a turn-drive-turn (or omni) base path, travel -> goal joints."""
        return plan_mobile(problem, start, goal, self.planner, self.time_limit, seed, self.tuck, self.simplify)


class StraightLine(MotionPlanner):
    """The straight segment in configuration space if valid (the free flyer's planner)."""

    name = "straight_line"
    params = ()

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        return straight_line(problem, np.asarray(start, dtype=float), np.asarray(goal, dtype=float))


def _optional_planners() -> list[type[GeometricPlanner]]:
    """Planners registered only if the installed OMPL binds them (ompl 2.0.1's wheel has no
    LazyPRM / LazyPRMstar, so ``lazy_prm`` is then absent: never silently another planner)."""
    try:
        from ompl import geometric as og
    except ImportError:
        return []
    docs = {"lazy_prm": "Lazy PRM (Bohlin & Kavraki 2000): edges checked only on the candidate path.",
            "lazy_prm_star": "Asymptotically optimal Lazy PRM*."}
    return [_geometric(name, cls, docs[name]) for name, cls in OPTIONAL_GEOMETRIC.items() if hasattr(og, cls)]


PLUGINS = [RRTConnect, RRT, RRTStar, PRM, KPIECE, BITStar, OmplByName, Kinodynamic, TuckAndDrive, StraightLine,
           *_optional_planners()]
