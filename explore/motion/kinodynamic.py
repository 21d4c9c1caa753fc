"""Kinodynamic planning of a mobile robot's base with ompl.control (unicycle or omnidirectional model):
velocity controls held for dt, propagated by the robot's own model."""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import Array
from explore.motion.geometric import ompl_modules, ompl_state, real_vector_space, seed_ompl
from explore.motion.mobile import BaseProblem, mobile_plan
from explore.motion.planning_clock import Budget
from explore.motion.problem import MotionProblem, check_path_until
from explore.motion.records import MotionPlan

CONTROL_PLANNERS: dict[str, str] = {"rrt": "RRT", "kpiece": "KPIECE1", "sst": "SST", "est": "EST", "pdst": "PDST"}


def plan_kinodynamic(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str = "rrt",
    time_limit: float = 5.0,
    goal_tolerance: float = 0.4,
    seed: int | None = None,
    max_duration: float = 4.0,
    tuck: bool = True,
    goal_bias: float = 0.05,
    propagation_step: float = 0.2,
    min_duration: float = 0.8,
    connect: bool = True,
) -> MotionPlan | None:
    """Base motion with velocity controls (``ompl.control``) between joint motions.

    1. With ``tuck`` (and a robot with ``travel_joints``, the mobile manipulator's ``home``)
       the arm first moves to its travel configuration at the start base pose (else the
       start's or the goal's joints are carried, whichever is valid at both ends);
    2. the base (x, y, theta) is planned with the robot's drive model (``robot.propagate_base``:
       unicycle for a differential drive, omnidirectional otherwise), every other joint fixed,
       until it is within ``goal_tolerance`` (L2 in m and rad) of the goal base pose; with
       ``connect`` the robot's own steering (turn-drive-turn, or a straight omnidirectional
       move) then closes the gap to the goal when that motion is valid;
    3. the other joints move to their goal values at the reached base pose.

    States are checked by :class:`PlanarChecker` (rigid planar motion of surface points
    against boxes and the PVS; pybullet near obstacles) every ``propagation_step`` seconds
    (rounded to multiples of ``robot.dt``), and the nominal rollout between them at
    ``problem.resolution``; a control is held ``min_duration``..``max_duration`` seconds and
    integrated at dt (the executor's Euler step); RRT extends toward the goal with probability
    ``goal_bias`` (the other control planners of the ompl 2.0.1 bindings expose no goal bias;
    SST and PDST have no constructor there); KPIECE and EST project states on (x, y).
    ``time_limit`` bounds the whole call. The defaults were tuned on ``benchmarks/planners.py``
    (cluttered, mobile manipulator): long controls and steps and a 0.4 goal region, closed by
    the steering, beat short ones (few states per second with a Python propagator).
    Returns per-step controls (``MotionPlan.controls``, held dt each) and their nominal
    rollout; if the gap could not be closed, the final configuration is the reached one
    (within the tolerance of ``goal``, ``MotionPlan.exact`` False): Vasquez-Gomez's RRT
    Ext-Ext leaves such a gap too.
    """
    ob, _, _ = ompl_modules()
    from ompl import control as oc

    cls = control_planner_class(planner)
    robot = problem.robot
    dt = float(robot.dt)

    def drive(sub: BaseProblem, a: Array, b: Array, budget: Budget) -> tuple[np.ndarray, np.ndarray] | None:
        seed_ompl(seed)
        space = real_vector_space(ob, sub.lower, sub.upper)
        limits = robot.base_control_limits()  # (nb,) max |u| of the base controls
        cspace = oc.RealVectorControlSpace(space, len(limits))
        cbounds = ob.RealVectorBounds(len(limits))
        for i, u in enumerate(limits):
            cbounds.setLow(i, -float(u))
            cbounds.setHigh(i, float(u))
        cspace.setBounds(cbounds)
        ss = oc.SimpleSetup(cspace)
        nc = len(limits)
        ss.setStateValidityChecker(lambda s: sub.checker([s[0], s[1], s[2]]))

        def propagate(s: Any, u: Any, duration: float, result: Any) -> None:
            q = np.array([s[0], s[1], s[2]])
            control = np.array([u[i] for i in range(nc)])
            steps = max(1, int(round(duration / dt)))
            for _ in range(steps):  # Euler at the executor's dt
                q = robot.propagate_base(q, control, duration / steps)
            result[0], result[1], result[2] = float(q[0]), float(q[1]), float(q[2])

        ss.setStatePropagator(propagate)
        space.registerDefaultProjection(ob.RealVectorOrthogonalProjectionEvaluator(space, [0, 1]))  # KPIECE, EST
        si = ss.getSpaceInformation()
        step = dt * max(1, int(round(propagation_step / dt)))
        si.setPropagationStepSize(step)
        shortest = max(1, int(round(min_duration / step)))
        si.setMinMaxControlDuration(shortest, max(shortest, int(round(max_duration / step))))
        instance = cls(si)
        if hasattr(instance, "setGoalBias"):
            instance.setGoalBias(float(goal_bias))
        ss.setPlanner(instance)
        ss.setStartAndGoalStates(ompl_state(space, a), ompl_state(space, b), goal_tolerance)
        if budget.remaining() <= 0.0:
            return None
        status = ss.solve(budget.share(0.8).ompl_condition())  # the rest: the final joint motion and its check
        if not status or not ss.haveExactSolutionPath():
            return None
        solution = ss.getSolutionPath()
        controls = []
        for i in range(solution.getControlCount()):
            u = [solution.getControl(i)[k] for k in range(nc)]
            controls.extend([u] * max(1, int(round(solution.getControlDuration(i) / dt))))
        base_controls = np.asarray(controls, dtype=float).reshape(-1, nc)
        rollout = [np.asarray(a, dtype=float)]  # the nominal rollout at dt (what the executor runs)
        for u in base_controls:
            rollout.append(robot.propagate_base(rollout[-1], u, dt))
        rollout = np.asarray(rollout)
        if not check_path_until(sub, rollout, budget):  # between the propagation steps too
            return None
        if connect and np.linalg.norm(rollout[-1] - b) > 1e-9:  # close the gap with the robot's steering
            steer_controls, steered = robot.controls_from_path(sub.full_path(np.vstack([rollout[-1], b])))
            steered = steered[:, sub.base]
            if len(steer_controls) and check_path_until(sub, sub.motion_path(steered), budget):
                rollout = np.vstack([rollout, steered[1:]])
                base_controls = np.vstack([base_controls, steer_controls[:, :nc]])
        return rollout, base_controls

    return mobile_plan(problem, start, goal, drive, time_limit, seed, tuck, f"kinodynamic_{planner}")


def control_planner_class(name: str) -> Any:
    """The ``ompl.control`` planner class for a plugin name (only classes the bindings can build)."""
    available = control_planner_names()
    cls_name = CONTROL_PLANNERS.get(name, name)
    if cls_name not in available.values():
        raise ValueError(f"unknown or unavailable control planner {name!r} (this OMPL offers: "
                         f"{', '.join(available)}; ompl 2.0.1's bindings cannot construct SST or PDST)")
    from ompl import control as oc

    return getattr(oc, cls_name)


def control_planner_names() -> dict[str, str]:
    """Plugin name -> ``ompl.control`` class of the control planners this OMPL can construct."""
    ob, _, _ = ompl_modules()
    from ompl import control as oc

    space = ob.RealVectorStateSpace(1)
    bounds = ob.RealVectorBounds(1)
    bounds.setLow(0.0)
    bounds.setHigh(1.0)
    space.setBounds(bounds)
    si = oc.SimpleSetup(oc.RealVectorControlSpace(space, 1)).getSpaceInformation()
    out = {}
    for name, cls_name in CONTROL_PLANNERS.items():
        try:
            getattr(oc, cls_name)(si)
        except (AttributeError, TypeError):  # missing, or "no constructor defined" in the bindings
            continue
        out[name] = cls_name
    return out
