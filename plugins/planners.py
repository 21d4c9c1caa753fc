"""Motion planner plugins (kind ``motion_planner``): OMPL geometric planners by name, a
kinodynamic base planner (``ompl.control``) and the straight line for the free flyer.

Every plugin has ``plan(problem, start, goal, seed=None) -> MotionPlan | None`` where
``problem`` is an :class:`explore.motion.MotionProblem` (validity = known environment +
optional PVS free-space test).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.errors import BadInput
from explore.motion import (
    OPTIONAL_GEOMETRIC,
    MotionPlan,
    MotionProblem,
    plan,
    plan_kinodynamic,
    planner_class,
    straight_line,
)
from explore.params import Param
from explore.typed import Array

_GEOMETRIC = (
    Param("time_limit", float, 1.0, "s", "planning time limit", low=0.001),
    Param("range", float, 0.0, "rad", "maximum step of tree extension (0 = OMPL default)", low=0.0),
    Param("simplify", bool, True, "", "shortcut the path between its vertices (PathSimplifier.reduceVertices)"),
    Param("try_direct", bool, True, "", "return the straight segment when it is valid, without OMPL"),
    Param("check_factor", float, 3.0, "", "search checks motions every factor x resolution (result re-checked "
          "at the resolution)", low=1.0),
)


class GeometricPlanner:
    """An OMPL geometric planner in the robot's configuration space."""

    kind = "motion_planner"
    name = "ompl"
    ompl_name = "RRTConnect"
    params: tuple = _GEOMETRIC

    def __init__(self, **values: Any) -> None:
        for key, value in values.items():
            setattr(self, key, value)

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


class Kinodynamic:
    """Kinodynamic base planner (ompl.control, unicycle/omni model) returning velocity controls."""

    kind = "motion_planner"
    name = "kinodynamic"
    params = (
        Param("time_limit", float, 5.0, "s", "planning time limit", low=0.001),
        Param("planner", str, "rrt", "", "ompl.control planner", choices=("rrt", "kpiece", "sst", "est", "pdst")),
        Param("goal_tolerance", float, 0.05, "", "goal distance in configuration space (m, rad)", low=1e-4),
        Param("max_steps", int, 20, "", "max control duration in dt steps", low=1),
    )

    def __init__(self, **values: Any) -> None:
        for key, value in values.items():
            setattr(self, key, value)

    def plan(self, problem: MotionProblem, start: Array, goal: Array, seed: int | None = None) -> MotionPlan | None:
        """Controls for the base (then the other joints) from ``start`` to near ``goal``."""
        return plan_kinodynamic(
            problem, start, goal, self.planner, self.time_limit, self.goal_tolerance, seed, self.max_steps
        )


class StraightLine:
    """The straight segment in configuration space if valid (the free flyer's planner)."""

    kind = "motion_planner"
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


PLUGINS = [RRTConnect, RRT, RRTStar, PRM, KPIECE, BITStar, OmplByName, Kinodynamic, StraightLine,
           *_optional_planners()]
