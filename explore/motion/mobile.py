"""Mobile robots: base poses checked fast as a rigid body in the plane (PlanarChecker), and motions that tuck
the arm, drive the base along a geometric path (turn-drive-turn for a differential base) and untuck."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from explore.core import Array, Points3, wrap_angle
from explore.motion.geometric import ompl_search, plan, seed_ompl
from explore.motion.kernels import planar_points_clearance, point_clusters
from explore.motion.planning_clock import Budget, charge
from explore.motion.problem import MotionProblem, check_path_until, path_length
from explore.motion.records import MotionPlan
from explore.sim import body_aabb


def box_distance(points: Points3, lo: np.ndarray, hi: np.ndarray) -> Array:
    """Signed distance (n,) from points to the nearest of the boxes [lo_b, hi_b].

    Outside a box the Euclidean distance, inside minus the depth below its nearest face.
    """
    if len(lo) == 0:
        return np.full(len(points), np.inf)
    below, above = lo[None] - points[:, None], points[:, None] - hi[None]  # (n, b, 3)
    gap = np.maximum(np.maximum(below, 0.0), above)
    outside = np.sqrt(np.einsum("nbk,nbk->nb", gap, gap))
    depth = np.minimum(-below, -above).min(axis=2)  # > 0 inside
    return np.where(outside > 0.0, outside, -np.maximum(depth, 0.0)).min(axis=1)


class PlanarChecker:
    """Validity of base poses (x, y, theta) with every other joint fixed at ``q_ref``.

    The robot then moves as a rigid body in the plane, so points sampled on its surface
    every ``spacing`` (``robot.link_points``) are moved instead of re-posing pybullet. The
    PVS test (``problem.space_free`` on those points) is the one :meth:`MotionProblem.is_valid`
    makes; the known environment is tested against the bodies' bounding boxes: a pose whose
    points keep ``margin`` + ``slack`` from every box is valid (``slack`` covers the gaps
    between the surface samples, sqrt(3) x spacing, and convex collision hulls, 2 cm); closer
    poses get the full pybullet test (``fast`` / ``exact`` count both). Self-collision
    cannot change (the joints are fixed; ``q_ref`` must be valid). Boxes below (or above) the
    robot by at least ``margin`` never come closer in a planar motion and are left out (the
    floor).

    ``drive_margin`` with ``ends`` (base poses): a pose d metres (xy) from the nearer end must
    keep min(``drive_margin``, margin + d) from the bounding boxes of the known environment: a
    funnel that lets the base start and stop near the table but keeps it ``drive_margin`` away
    while it drives, room for the heading drift of a noisy base (Vasquez-Gomez's sigma_omega).
    """

    def __init__(self, problem: MotionProblem, q_ref: Array, spacing: float = 0.015, drive_margin: float = 0.0,
                 ends: Sequence[Array] = ()) -> None:
        robot = problem.robot
        self.problem, self.q_ref = problem, np.asarray(q_ref, dtype=float).copy()
        self.base = list(robot.base_dofs)
        x, y, th = self.q_ref[self.base]
        points = robot.link_points(self.q_ref, spacing=spacing)
        c, s = math.cos(th), math.sin(th)
        rel = points[:, :2] - (x, y)
        self.local = np.ascontiguousarray(np.column_stack([c * rel[:, 0] + s * rel[:, 1],
                                                           -s * rel[:, 0] + c * rel[:, 1]]))
        self.radius = float(np.sqrt((self.local**2).sum(axis=1)).max(initial=0.0))
        self.z = np.ascontiguousarray(points[:, 2])
        self._clusters = point_clusters(self.local, self.z)
        self.margin = problem.margin
        self.drive_margin = max(float(drive_margin), self.margin)
        self.ends = np.array([np.asarray(e, dtype=float)[:2] for e in ends]).reshape(-1, 2)
        self.slack = math.sqrt(3.0) * float(spacing) + 0.02
        boxes = []
        sim = getattr(robot, "sim", None)
        if sim is not None and len(points):
            zmin, zmax = float(self.z.min()), float(self.z.max())
            for body in sim.environment_ids():
                lo, hi = body_aabb(body, sim.client)
                if hi[2] <= zmin - self.margin or lo[2] >= zmax + self.margin:
                    continue
                boxes.append((lo, hi))
        self.lo = np.array([b[0] for b in boxes], dtype=float).reshape(-1, 3)
        self.hi = np.array([b[1] for b in boxes], dtype=float).reshape(-1, 3)
        self.lower, self.upper = problem.lower[self.base], problem.upper[self.base]
        self._points = np.empty((len(self.local), 3))
        if problem.space_free is None:
            self._box = (np.full(3, np.inf), np.full(3, -np.inf))
        elif problem.space_bounds is None:  # an unknown free-space test: every point goes to it
            self._box = (np.full(3, -np.inf), np.full(3, np.inf))
        else:
            self._box = tuple(np.asarray(b, dtype=float) for b in problem.space_bounds)

    def full(self, qb: Array) -> Array:
        """The whole configuration at base pose ``qb``."""
        q = self.q_ref.copy()
        q[self.base] = qb
        return q

    def __call__(self, qb: Array) -> bool:
        charge("planar")
        qb = np.asarray(qb, dtype=float)
        if np.any(qb < self.lower - 1e-9) or np.any(qb > self.upper + 1e-9):
            return False
        drive = self.margin
        if self.drive_margin > self.margin:
            to_end = float(np.sqrt(((self.ends - qb[:2]) ** 2).sum(axis=1)).min(initial=np.inf))
            drive = min(self.drive_margin, self.margin + to_end)
        clearance, inside = planar_points_clearance(
            *self._clusters, self.radius, float(qb[0]), float(qb[1]), float(qb[2]), self.lo, self.hi,
            max(drive, self.margin + self.slack), self._box[0], self._box[1], self._points)
        if clearance < drive - 1e-12 and drive > self.margin:  # the funnel, measured to the bounding boxes
            return False
        space_free = self.problem.space_free
        if space_free is not None and inside:
            if not bool(np.all(self.problem.points_free(self._points[:inside]))):
                return False
        if clearance >= self.margin + self.slack:
            return True
        return self.problem.is_valid(self.full(qb))


class BaseProblem:
    """The base (x, y, theta) part of a problem with the other joints carried fixed.

    Duck-types :class:`MotionProblem` for :func:`ompl_search`: validity by a
    :class:`PlanarChecker`, motions as the robot drives them (``problem.motion_path``).
    """

    def __init__(self, problem: MotionProblem, carried: Array, goal: Array, lower: Array, upper: Array) -> None:
        self.problem, self.robot = problem, problem.robot
        ends = [carried[list(problem.robot.base_dofs)], goal]  # the drive's start and goal base poses
        self.checker = PlanarChecker(problem, carried, drive_margin=problem.drive_margin, ends=ends)
        self.checker.lower, self.checker.upper = lower, upper
        self.lower, self.upper = lower, upper
        self.resolution = problem.resolution
        self.base = self.checker.base

    def is_valid(self, qb: Array, margin: float | None = None) -> bool:
        return self.checker(qb)

    def full_path(self, path: np.ndarray) -> np.ndarray:
        out = np.tile(self.checker.q_ref, (len(path), 1))
        out[:, self.base] = path
        return out

    def motion_path(self, path: np.ndarray) -> np.ndarray:
        return self.problem.motion_path(self.full_path(np.asarray(path, dtype=float)))[:, self.base]


def _joint_motion(problem: MotionProblem, a: Array, b: Array, budget: Budget, seed: int | None) -> np.ndarray | None:
    """Path moving only the non-base joints from ``a`` to ``b`` (straight if valid, else RRT-Connect).

    Found motions are remembered by the problem while its free space is unchanged (the tuck
    from the current state is the same for every candidate of an NBV iteration).
    """
    if not np.any(np.abs(np.asarray(b) - np.asarray(a)) > 1e-12):
        return np.vstack([a]).astype(float)
    key = problem.cache_key(a, b)
    if key is not None and key in problem.motions:
        return problem.motions[key]
    path = np.vstack([a, b]).astype(float)
    verdict = check_path_until(problem, path, budget, margin=None)
    if verdict is None:
        return None
    if not verdict:
        pinned = problem.pinned(list(problem.robot.base_dofs), a)
        sub = plan(pinned, a, b, "rrt_connect", time_limit=max(0.0, budget.remaining()), seed=seed)
        if sub is None:
            return None
        path = sub.path
    if key is not None:
        if len(problem.motions) > 512:  # older free-space versions
            problem.motions.clear()
        problem.motions[key] = path
    return path


def _carried_joints(problem: MotionProblem, start: Array, goal: Array, tuck: bool) -> list[Array]:
    """Joint values to drive with, best first: the robot's ``travel_joints`` (with ``tuck``),
    the start's, the goal's; each valid at the start and at the goal base pose."""
    robot = problem.robot
    base = list(robot.base_dofs)
    joints = [i for i in range(len(start)) if i not in base]
    options = [start[joints], goal[joints]]
    travel = robot.travel_joints
    if tuck and travel is not None and joints:
        options.insert(0, np.asarray(travel, dtype=float))
    out: list[Array] = []
    for values in options:
        if any(np.allclose(values, o) for o in out):
            continue
        a, b = start.copy(), goal.copy()
        a[joints], b[base] = values, goal[base]
        b[joints] = values
        if problem.is_valid(a) and problem.is_valid(b):
            out.append(values)
    return out


def mobile_plan(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    drive: Callable[[BaseProblem, Array, Array, Budget], tuple[np.ndarray, np.ndarray] | None],
    time_limit: float,
    seed: int | None,
    tuck: bool,
    name: str,
) -> MotionPlan | None:
    """Joints to the carried values, the base by ``drive``, joints to the goal; one MotionPlan
    (only the joint motion when the base stays put).

    ``drive(base_problem, start_base, goal_base, budget)`` returns the base rollout (m + 1, 3)
    at ``robot.dt`` and its base controls (m, nb), or None. The drive is checked by the
    planar checker, the joint motions with pybullet, all within ``time_limit``.
    """
    t0 = time.perf_counter()
    budget = Budget(time_limit)
    robot = problem.robot
    base = list(robot.base_dofs)
    if not base:
        raise ValueError(f"{robot.name} has no base to drive")
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float).copy()
    if not problem.is_valid(start) or not problem.is_valid(goal):
        return None
    th = base[2]
    goal[th] = start[th] + wrap_angle(goal[th] - start[th])  # the same heading, the shorter turn
    joints = [i for i in range(len(start)) if i not in base]
    if np.allclose(start[base], goal[base], atol=1e-9):  # the base stays put: only the joints move
        path = _joint_motion(problem, start, goal, budget, seed)
        if path is None:
            return None
        controls, rolled = robot.controls_from_path(path)
        return MotionPlan(rolled, controls=controls, dt=float(robot.dt), planner=name,
                          planning_time=time.perf_counter() - t0, length=path_length(robot, rolled))
    lower, upper = problem.lower[base].copy(), problem.upper[base].copy()
    lower[2], upper[2] = start[th] - 2 * math.pi, start[th] + 2 * math.pi
    for values in _carried_joints(problem, start, goal, tuck):
        if budget.expired():
            return None
        carried = start.copy()
        carried[joints] = values
        first = _joint_motion(problem, start, carried, budget, seed)
        if first is None:
            continue
        sub = BaseProblem(problem, carried, goal[base], lower, upper)
        if not sub.is_valid(goal[base]):
            # The drive's checker samples the robot every 1.5 cm, is_valid (which chose the carried joints)
            # every 3 cm, so it can refuse the goal pose. No drive ends there, and OMPL's bidirectional
            # planners would wait for a valid goal sample until the limit (PlannerInputStates::nextGoal
            # sleeps 10 ms per try), which then only the wall-time hang guard ends.
            continue
        driven = drive(sub, carried[base], goal[base], budget)
        if driven is None:
            continue
        rollout, base_controls = driven
        reached = carried.copy()
        reached[base] = rollout[-1]
        target = reached.copy()
        target[joints] = goal[joints]
        last = _joint_motion(problem, reached, target, budget, None if seed is None else seed + 1)
        if last is None:
            continue
        pieces, control_pieces = [start[None]], []
        for joint_path in (first, None, last):
            if joint_path is None:
                pieces.append(sub.full_path(rollout[1:]))
                control_pieces.append(robot.base_to_full_controls(base_controls))
            elif len(joint_path) > 1:
                joint_controls, rolled = robot.controls_from_path(joint_path)
                control_pieces.append(joint_controls)
                pieces.append(rolled[1:])
        path = np.vstack(pieces)
        exact = bool(np.linalg.norm(rollout[-1] - goal[base]) < 1e-6)
        return MotionPlan(path, controls=np.vstack(control_pieces), dt=float(robot.dt), planner=name,
                          planning_time=time.perf_counter() - t0, exact=exact, length=path_length(robot, path))
    return None


def plan_mobile(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str = "rrt_connect",
    time_limit: float = 5.0,
    seed: int | None = None,
    tuck: bool = True,
    simplify: bool = True,
) -> MotionPlan | None:
    """Tuck, drive, untuck with an OMPL geometric planner for the base (x, y, theta).

    As :func:`plan_kinodynamic`, but the base path comes from a (bidirectional) geometric
    planner whose local planner is the robot's own steering: a differential base turns,
    drives straight and turns (``robot.execution_path``), so every base segment is
    executable exactly; an omnidirectional base drives the segment. States and motions are
    checked by :class:`PlanarChecker` every ``problem.resolution`` (L2 of m and rad). The
    plan's controls follow the path exactly (``robot.controls_from_path``).
    """
    robot = problem.robot

    def drive(sub: BaseProblem, a: Array, b: Array, budget: Budget) -> tuple[np.ndarray, np.ndarray] | None:
        seed_ompl(seed)
        if budget.remaining() <= 0.0:
            return None
        path = ompl_search(sub, a, b, planner, budget.share(0.8), simplify, 0.0, 1e-6, 1.0, budget)
        if path is None:
            return None
        controls, rolled = robot.controls_from_path(sub.full_path(path))
        base = list(robot.base_dofs)
        return rolled[:, base], controls[:, : robot.n_base_controls]

    return mobile_plan(problem, start, goal, drive, time_limit, seed, tuck, f"mobile_{planner}")
