"""OMPL geometric planning in the robot's configuration space: every planner of the installed bindings by
name, within a time limit on the planning clock (explore.motion.planning_clock), with dense re-checks, bounded
simplification, the PRM family driven in the calling thread, and the straight line."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from explore.core import Array
from explore.motion.planning_clock import Budget
from explore.motion.problem import MotionProblem, check_path_until, path_length
from explore.motion.records import MotionPlan

# OMPL geometric planners by plugin name (any other og.* class is also accepted by its name)
GEOMETRIC_PLANNERS: dict[str, str] = {
    "rrt_connect": "RRTConnect",
    "rrt": "RRT",
    "rrt_star": "RRTstar",
    "informed_rrt_star": "InformedRRTstar",
    "prm": "PRM",
    "prm_star": "PRMstar",
    "kpiece": "KPIECE1",
    "bkpiece": "BKPIECE1",
    "lbkpiece": "LBKPIECE1",
    "bit_star": "BITstar",
    "fmt": "FMT",
    "bfmt": "BFMT",
    "aorrtc": "AORRTC",
    "sorrt_star": "SORRTstar",
}

# Planners of OMPL's C++ library that a Python wheel may lack (ompl 2.0.1 binds neither):
# they are offered only when ``ompl.geometric`` has the class, never replaced by another one.
OPTIONAL_GEOMETRIC: dict[str, str] = {"lazy_prm": "LazyPRM", "lazy_prm_star": "LazyPRMstar"}


# -- OMPL ------------------------------------------------------------------------------------
def ompl_modules() -> tuple[Any, Any, Any]:
    """OMPL's base, geometric and util modules, with OMPL's own console output off: it writes
    straight to stderr (through a live view), and every failure it reports there (e.g. "Unable to
    sample any valid states for goal tree") reaches the caller as a missing plan, which the
    planners and sessions report in their own words."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    return ob, og, ou


def seed_ompl(seed: int | None) -> None:
    """Seed OMPL's global seed generator (deterministic planning for a given seed)."""
    if seed is None:
        return
    _, _, ou = ompl_modules()  # quiet: OMPL complains when RNGs exist already; reseeding still works
    ou.RNG.setSeed(max(1, int(seed)))


def real_vector_space(ob: Any, lower: Array, upper: Array) -> Any:
    space = ob.RealVectorStateSpace(len(lower))
    bounds = ob.RealVectorBounds(len(lower))
    for i, (lo, hi) in enumerate(zip(lower, upper, strict=True)):
        bounds.setLow(i, float(lo))
        bounds.setHigh(i, float(hi) if hi > lo else float(lo) + 1e-9)
    space.setBounds(bounds)
    return space


def ompl_state(space: Any, q: Array) -> Any:
    state = space.allocState()
    for i, v in enumerate(q):
        state[i] = float(v)
    return state


def geometric_planner_names() -> list[str]:
    """The ``ompl.geometric`` planner classes this OMPL build offers (for lookups by name)."""
    ob, og, _ = ompl_modules()
    return sorted(n for n in dir(og) if isinstance(getattr(og, n), type) and issubclass(getattr(og, n), ob.Planner))


def planner_class(name: str) -> Any:
    """The OMPL geometric planner class for a plugin name or an ``og`` class name.

    No substitution: a planner this OMPL build lacks (e.g. LazyPRM in the ompl 2.0.1 wheel)
    is an error that lists the planners that exist.
    """
    _, og, _ = ompl_modules()
    cls_name = GEOMETRIC_PLANNERS.get(name) or OPTIONAL_GEOMETRIC.get(name) or name
    available = geometric_planner_names()
    if cls_name not in available:
        aliases = [k for k, v in GEOMETRIC_PLANNERS.items() if v in available]
        raise ValueError(f"unknown OMPL planner {name!r} (this OMPL offers: {', '.join(aliases + available)})")
    return getattr(og, cls_name)

SOLVE_SHARE = 0.5  # share of the remaining time a coarse search may use (the rest re-checks or retries)


def plan(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str = "rrt_connect",
    time_limit: float = 1.0,
    simplify: bool = True,
    range: float = 0.0,  # noqa: A002 - the OMPL parameter name
    seed: int | None = None,
    goal_threshold: float = 1e-6,
    try_direct: bool = False,
    check_factor: float = 3.0,
) -> MotionPlan | None:
    """A collision-free joint path from ``start`` to ``goal`` with an OMPL geometric planner.

    Only exact solutions are returned, and every returned segment has been checked every
    ``problem.resolution`` (L2) with the clearance margin, as the robot executes it (a
    differential base turns, drives and turns: OMPL checks motions with that local planner,
    :func:`_executed_motion_validator`). ``time_limit`` bounds the whole call: the search,
    the simplification, the re-check and the retry (seconds on the planning clock from
    entry, :mod:`explore.motion.planning_clock`; one validity check may run past it).

    Speed (``benchmarks/planners.py``): the first search checks motions every
    ``check_factor * problem.resolution`` with at most ``SOLVE_SHARE`` of the time, its result
    is re-checked densely; if that fails, the search is repeated at the fine resolution
    (whose result OMPL has checked densely already) with the time left. Simplification is
    bounded: ``reduceVertices`` and ``collapseCloseVertices`` (shortcuts between path
    vertices, cf. the thesis' RRT-Connect + Berchtold-Glavina smoothing) instead of
    ``ss.simplifySolution``, whose B-spline smoothing and perturbation ran 0.3-0.4 s past a
    0.1 s budget on an iiwa query whose answer is one straight segment.
    """
    t0 = time.perf_counter()
    budget = Budget(time_limit)
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if not problem.is_valid(start) or not problem.is_valid(goal):
        return None
    if try_direct:  # the straight segment first (what simplification would return anyway)
        direct = straight_line(problem, start, goal, budget=budget)
        if direct is not None:
            direct.planner = planner
            direct.planning_time = time.perf_counter() - t0
            return direct
    factors = [max(1.0, float(check_factor))] + ([1.0] if check_factor > 1.0 else [])
    for attempt, factor in enumerate(factors):
        if budget.remaining() <= 0.0:
            break
        coarse = factor > 1.0
        seed_ompl(None if seed is None else seed + attempt)
        search = budget.share(SOLVE_SHARE) if coarse else budget
        path = ompl_search(problem, start, goal, planner, search, simplify, range, goal_threshold, factor, budget)
        if path is None:
            continue  # coarse search gave up (e.g. only an approximate solution): try fine
        if coarse:  # OMPL checked every factor x resolution: check the rest now, within the limit
            verdict = check_path_until(problem, problem.motion_path(path), budget, margin=None)
            if verdict is None:
                break
            if not verdict:
                continue
        return MotionPlan(path, planner=planner, planning_time=time.perf_counter() - t0,
                          length=path_length(problem.robot, problem.motion_path(path)))
    return None


def _executed_motion_validator(si: Any, problem: Any, resolution: float, n: int, budget: Budget | None) -> Any:
    """OMPL motion validator that checks the motion the robot executes (turn-drive-turn).

    A subclass of ``ompl.base.MotionValidator`` (the nanobind bindings call the Python
    ``checkMotion``), for robots whose ``execution_path`` differs from the straight segment
    (a differential base). Once ``budget`` expires every motion is invalid (the search winds down).
    """
    ob, _, _ = ompl_modules()

    class Validator(ob.MotionValidator):
        def checkMotion(self, a: Any, b: Any, *last_valid: Any) -> bool:  # noqa: N802 - OMPL's name
            qa = [a[i] for i in range(n)]
            qb = [b[i] for i in range(n)]
            path = problem.motion_path(np.array([qa, qb]))
            return bool(check_path_until(problem, path, budget, resolution, margin=None))

    return Validator(si)


def ompl_search(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str,
    search: Budget,
    simplify: bool,
    step: float,
    goal_threshold: float,
    check_factor: float,
    budget: Budget | None = None,
) -> np.ndarray | None:
    """One OMPL solve within ``search``, motions checked every ``check_factor * problem.resolution``.

    Simplification runs in rounds of 10 shortcut attempts until one round changes nothing or
    ``budget`` (the whole call's) expires (the path is valid after every round).
    """
    ob, og, _ = ompl_modules()
    n = len(start)
    space = real_vector_space(ob, problem.lower, problem.upper)
    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(lambda s: problem.is_valid([s[i] for i in range(n)]))
    si = ss.getSpaceInformation()
    resolution = check_factor * problem.resolution
    si.setStateValidityCheckingResolution(min(1.0, resolution / max(space.getMaximumExtent(), 1e-9)))
    probe = np.vstack([start, goal])
    if problem.motion_path(probe).shape != probe.shape:  # the robot does not drive straight segments
        si.setMotionValidator(_executed_motion_validator(si, problem, resolution, n, budget))
    instance = planner_class(planner)(si)
    if step > 0 and hasattr(instance, "setRange"):
        instance.setRange(step)
    ss.setPlanner(instance)
    ss.setStartAndGoalStates(ompl_state(space, start), ompl_state(space, goal), goal_threshold)
    if isinstance(instance, og.PRM):
        if not _solve_roadmap(ss, instance, search):
            return None
    else:
        status = ss.solve(search.ompl_condition())
        if not status or not ss.haveExactSolutionPath():
            return None
    solution = ss.getSolutionPath()
    if simplify and solution.getStateCount() > 2:
        simplifier = og.PathSimplifier(si)
        for shortcut in (simplifier.reduceVertices, simplifier.collapseCloseVertices, simplifier.reduceVertices):
            # rounds of 10 shortcut attempts (each checks one motion) while time remains
            while solution.getStateCount() > 2 and (budget is None or not budget.expired()):
                if not shortcut(solution, 10, 10):
                    break
    path = np.array(
        [[solution.getState(i)[k] for k in range(n)] for i in range(solution.getStateCount())]
    )
    path[0], path[-1] = start, goal
    return path

ROADMAP_ROUND = 0.02  # planning-clock seconds of roadmap growth between two solution checks (expansion: half)


def _solve_roadmap(ss: Any, prm: Any, search: Budget) -> bool:
    """PRM / PRM* without OMPL's second thread: True when the roadmap joins start and goal.

    OMPL's ``PRM::solve`` grows the roadmap while a second thread looks for a solution. That
    thread evaluates the termination condition, a Python callable here, while the main
    thread waits for it in ``join`` holding the GIL: a deadlock about one run in three. Which
    roadmap the answer comes from also depends on the two threads' timing (and OMPL's
    grow/expand rounds on wall time). Here everything runs in this thread: the roadmap grows
    in rounds on the planning clock (2:1 growth to expansion, as OMPL's ``constructRoadmap``),
    and after each round ``solve`` runs with an always-terminating C++ condition, so its
    thread returns at once and no Python is called off this thread. That ``solve`` adds start
    and goal as milestones and returns the roadmap's shortest path to the vertex nearest the
    goal (as an approximate solution); it reaches the goal when that vertex is the goal.
    """
    ob, _, _ = ompl_modules()
    pdef = ss.getProblemDefinition()
    done = ob.plannerAlwaysTerminatingCondition()
    grow = True
    while True:
        pdef.clearSolutionPaths()
        ss.solve(done)
        if pdef.hasSolution() and pdef.getSolutionDifference() <= 1e-12:
            return True
        if search.expired():
            return False
        round_ = search.slice(ROADMAP_ROUND if grow else 0.5 * ROADMAP_ROUND)
        (prm.growRoadmapPtc if grow else prm.expandRoadmapPtc)(round_.ompl_condition())
        grow = not grow


def straight_line(
    problem: MotionProblem, start: Array, goal: Array, budget: Budget | None = None
) -> MotionPlan | None:
    """The straight segment in configuration space if it is valid (the free flyer's planner).

    Checked as the robot executes it (``problem.motion_path``); None when invalid or when
    ``budget`` expires before the check ends.
    """
    t0 = time.perf_counter()
    path = np.vstack([start, goal]).astype(float)
    if not check_path_until(problem, problem.motion_path(path), budget, margin=None):
        return None
    return MotionPlan(path, planner="straight_line", planning_time=time.perf_counter() - t0,
                      length=path_length(problem.robot, problem.motion_path(path)))
