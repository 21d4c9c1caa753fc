"""Motion planning and execution: validity checking, OMPL planners, noisy execution records.

* :class:`BulletCollider` checks robot parts against pybullet bodies (AABB pre-filter,
  ``getClosestPoints`` with a margin) and precomputed self-collision link pairs, in the style
  of pybullet-planning's ``get_collision_fn``.
* :class:`MotionProblem` is a robot plus a validity checker: robot vs the KNOWN static
  environment (``sim.environment_ids()``) and, optionally, a ``space_free(points) -> bool``
  callable (the PVS distance field: everything not confidently free, p >= 0.05, is an
  obstacle; Kriegel thesis Sec. 3.2.2) evaluated on points sampled on the robot's links.
* :func:`plan` wraps every OMPL geometric planner by name; :func:`plan_kinodynamic` plans
  base motions with ``ompl.control`` (unicycle or omnidirectional model) and returns per-step
  velocity controls; :func:`validate_path` re-checks a path densely.
* :func:`linear_scan_path_ik` validates a linear Cartesian scan path in 10 mm portions with
  IK and continuity (Kriegel thesis Sec. 2 motion planning); :func:`classify_blocked`
  applies the NBS rule (through occupied -> discard, through unknown -> keep for later).
* :class:`Execution` is what ``robot.execute(plan, rng)`` returns; :func:`truncated_normal`
  and :func:`truncated_normal_logpdf` implement the Vasquez-Gomez noise model (Sec. A6:
  noisy velocity controls truncated at beta = 3 sigma, Eq. 2 transition density).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .typed import Array, Points3, Pose

if TYPE_CHECKING:
    from .robot import Robot
    from .scan import ScanPath

SpaceFree = Callable[[np.ndarray], np.ndarray]  # points (n, 3) -> bool (n,) free
Probability = Callable[[np.ndarray], np.ndarray]  # points (n, 3) -> occupancy (n,)

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
CONTROL_PLANNERS: dict[str, str] = {"rrt": "RRT", "kpiece": "KPIECE1", "sst": "SST", "est": "EST", "pdst": "PDST"}


# -- noise model (Vasquez-Gomez Sec. A6) -----------------------------------------------------
def truncated_normal(rng: np.random.Generator, sigma: Array, size: int, beta: float = 3.0) -> np.ndarray:
    """(size, len(sigma)) zero-mean normal samples truncated to |e| <= beta * sigma (rejection)."""
    sigma = np.asarray(sigma, dtype=float)
    out = rng.normal(size=(size, len(sigma))) * sigma
    bad = np.abs(out) > beta * sigma
    while bad.any():
        out[bad] = rng.normal(size=int(bad.sum())) * np.broadcast_to(sigma, out.shape)[bad]
        bad = np.abs(out) > beta * sigma
    return out


def truncated_normal_logpdf(eps: np.ndarray, sigma: Array, beta: float = 3.0) -> float:
    """Sum of log densities of the truncated normal errors (log of Eq. 2 / Eq. 3 products).

    Dimensions with sigma = 0 (noise-free) contribute nothing.
    """
    sigma = np.asarray(sigma, dtype=float)
    use = sigma > 0
    if not use.any() or len(eps) == 0:
        return 0.0
    e, s = np.asarray(eps)[:, use], sigma[use]
    mass = math.erf(beta / math.sqrt(2.0))  # P(-beta sigma <= e <= beta sigma) = 0.997 for beta 3
    logpdf = -0.5 * (e / s) ** 2 - np.log(s * math.sqrt(2.0 * math.pi)) - math.log(mass)
    return float(logpdf.sum())


# -- records ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class CollisionEvent:
    """A collision of the executed motion with the true world (environment + objects)."""

    step: int
    time: float
    config: Array
    bodies: tuple[str, ...]


@dataclass
class MotionPlan:
    """A planned motion: configurations (m, dof) and optionally per-step velocity controls.

    ``controls`` (k, nc) are held for ``dt`` seconds each; ``controls`` is None for a purely
    geometric path (the robot derives controls with ``controls_from_path``).
    """

    path: np.ndarray
    controls: np.ndarray | None = None
    dt: float = 0.0
    planner: str = ""
    planning_time: float = 0.0
    exact: bool = True
    length: float = 0.0  # weighted configuration distance (Vasquez-Gomez Eq. 8)

    @property
    def start(self) -> Array:
        return self.path[0]

    @property
    def goal(self) -> Array:
        return self.path[-1]


@dataclass
class Execution:
    """What happened when a plan was executed (noisy, checked against the true world)."""

    configs: np.ndarray  # (m, dof) executed configurations, the first is the start
    times: Array  # (m,)
    controls: np.ndarray  # (k, nc) nominal controls
    noise: np.ndarray  # (k, nc) sampled control errors (zeros without noise)
    sigma: Array  # (nc,) noise standard deviations
    log_prob: float  # sum of log p(eps) (Eq. 2/3), for expected utility
    final: Array  # final configuration
    sensor_pose: Pose  # world_T_sensor at ``final``
    collisions: list[CollisionEvent] = field(default_factory=list)
    completed: bool = True  # False if the run stopped at a collision

    @property
    def collided(self) -> bool:
        return bool(self.collisions)


# -- pybullet collision checking ---------------------------------------------------------------
@dataclass(frozen=True)
class Part:
    """One movable collision part: a pybullet body and link (-1 for the base)."""

    body: int
    link: int
    name: str = ""


class BulletCollider:
    """Collision tests of robot parts vs obstacle bodies and of self-collision link pairs.

    Set the robot's pybullet state first; then :meth:`collides` returns the names of the
    obstacle bodies hit (AABB pre-filter, ``getClosestPoints`` with distance < ``margin``).
    """

    def __init__(
        self,
        client: int,
        parts: Sequence[Part],
        self_pairs: Sequence[tuple[Part, Part]] = (),
        ignore: Sequence[tuple[Part, int]] = (),
    ) -> None:
        from .bullet import p

        self.p = p
        self.client = client
        self.parts = list(parts)
        self.self_pairs = list(self_pairs)
        self.ignore = set(ignore)
        self._aabb: dict[int, tuple[tuple, tuple]] = {}
        # integer indices of the parts (a frozen dataclass hashes slowly in the inner loop)
        index = {part: i for i, part in enumerate(self.parts)}
        self._pair_index = [(index.get(a, -1), index.get(b, -1)) for a, b in self.self_pairs]
        self._ignore_index = {(index[part], body) for part, body in self.ignore if part in index}

    def obstacle_aabbs(self, bodies: Sequence[int]) -> list[tuple[int, tuple, tuple]]:
        """Cached AABBs (lo, hi tuples) of static bodies (obstacles do not move)."""
        out = []
        for body in bodies:
            if body not in self._aabb:
                lo, hi = self.p.getAABB(body, physicsClientId=self.client)
                self._aabb[body] = (tuple(lo), tuple(hi))
            out.append((body, *self._aabb[body]))
        return out

    def collides(self, obstacles: Sequence[int], margin: float = 0.0, self_check: bool = True) -> list[int]:
        """Obstacle body ids (and -1 for self-collision) within ``margin`` of the robot.

        Plain-Python AABB overlap tests (numpy calls on 3-vectors cost more than the test)
        prune both the obstacle and the self-collision pairs before ``getClosestPoints``.
        """
        p, c = self.p, self.client
        hits: list[int] = []
        boxes = self.obstacle_aabbs(obstacles)
        ignore = self._ignore_index
        part_boxes: list[tuple] = []
        for i, part in enumerate(self.parts):
            lo, hi = p.getAABB(part.body, part.link, physicsClientId=c)
            part_boxes.append((lo, hi))
            for body, blo, bhi in boxes:
                if body in hits or (ignore and (i, body) in ignore):
                    continue
                if not _overlap(lo, hi, blo, bhi, margin):
                    continue
                points = p.getClosestPoints(part.body, body, margin, linkIndexA=part.link, physicsClientId=c)
                if points and min(pt[8] for pt in points) < margin:
                    hits.append(body)
        if self_check:
            for (a, b), (ia, ib) in zip(self.self_pairs, self._pair_index, strict=True):
                if ia >= 0 and ib >= 0 and not _overlap(*part_boxes[ia], *part_boxes[ib], 0.0):
                    continue  # disjoint boxes cannot penetrate
                points = p.getClosestPoints(
                    a.body, b.body, 0.0, linkIndexA=a.link, linkIndexB=b.link, physicsClientId=c
                )
                if points and min(pt[8] for pt in points) < 0.0:
                    hits.append(-1)
                    break
        return hits


def _overlap(lo: Sequence[float], hi: Sequence[float], blo: Sequence[float], bhi: Sequence[float],
             margin: float) -> bool:
    """True if box [lo, hi] grown by ``margin`` overlaps box [blo, bhi]."""
    return not (
        lo[0] - margin > bhi[0] or lo[1] - margin > bhi[1] or lo[2] - margin > bhi[2]
        or hi[0] + margin < blo[0] or hi[1] + margin < blo[1] or hi[2] + margin < blo[2]
    )


def self_collision_pairs(
    client: int, parts: Sequence[Part], adjacent: Callable[[Part, Part], bool], tolerance: float = 0.0
) -> list[tuple[Part, Part]]:
    """Non-adjacent part pairs that do not touch in the current (home) state."""
    from .bullet import p

    pairs = []
    for i, a in enumerate(parts):
        for b in parts[i + 1 :]:
            if adjacent(a, b):
                continue
            points = p.getClosestPoints(
                a.body, b.body, tolerance, linkIndexA=a.link, linkIndexB=b.link, physicsClientId=client
            )
            if points and min(pt[8] for pt in points) < tolerance:
                continue  # touching at home: treated as permanently in contact
            pairs.append((a, b))
    return pairs


# -- the planning problem ----------------------------------------------------------------------
class MotionProblem:
    """A robot, its validity checker (known environment + optional free-space test), bounds.

    A configuration is valid if it is within the joint limits, the robot is at least
    ``margin`` away from every known environment body, does not collide with itself, and
    (with ``space_free``) every point sampled on its links is free in the PVS.
    """

    def __init__(
        self,
        robot: Robot,
        space_free: SpaceFree | None = None,
        margin: float | None = None,
        resolution: float = 0.01,
    ) -> None:
        self.robot = robot
        self.space_free = space_free
        self.margin = float(getattr(robot, "clearance", 0.0) if margin is None else margin)
        self.resolution = float(resolution)  # max configuration step (L2) between checks
        self.checks = 0

    @property
    def lower(self) -> Array:
        return np.asarray(self.robot.lower, dtype=float)

    @property
    def upper(self) -> Array:
        return np.asarray(self.robot.upper, dtype=float)

    def is_valid(self, q: Array, margin: float | None = None) -> bool:
        """Validity of one configuration (limits, known environment, self, free space)."""
        self.checks += 1
        q = np.asarray(q, dtype=float)
        if np.any(q < self.lower - 1e-9) or np.any(q > self.upper + 1e-9):
            return False
        robot = self.robot
        if robot.in_collision(q, world="known", margin=self.margin if margin is None else margin):
            return False
        if self.space_free is not None:
            points = robot.link_points(q)
            if len(points) and not bool(np.all(self.space_free(points))):
                return False
        return True

    def is_valid_motion(self, a: Array, b: Array, resolution: float | None = None) -> bool:
        """The motion from ``a`` to ``b`` as the robot executes it, checked every ``resolution`` (L2).

        A straight line in configuration space, except for a differential base, which turns,
        drives and turns (``robot.execution_path``).
        """
        return path_is_valid(self, self.motion_path(np.vstack([a, b])), resolution, margin=0.0)

    def motion_path(self, path: np.ndarray) -> np.ndarray:
        """The piecewise-linear path the robot really follows for ``path`` (see ``execution_path``)."""
        expand = getattr(self.robot, "execution_path", None)
        return np.asarray(path, dtype=float) if expand is None else np.asarray(expand(path), dtype=float)


def _interpolate(path: np.ndarray, resolution: float) -> np.ndarray:
    """Dense configurations along a piecewise-linear path, at most ``resolution`` apart."""
    path = np.asarray(path, dtype=float)
    pieces = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / resolution)))
        s = np.linspace(0.0, 1.0, n + 1)[1:, None]
        pieces.append(a + s * (b - a))
    return np.vstack(pieces)


def validate_path(
    problem: MotionProblem, path: np.ndarray, resolution: float | None = None, margin: float | None = 0.0
) -> int | None:
    """Dense re-check; the index (into the interpolated path) of the first invalid state, or None.

    The default ``margin`` of 0 checks true contact, while planning uses the robot's clearance.
    The path is checked as given (use ``problem.motion_path`` for what a differential base
    really drives).
    """
    dense = _interpolate(path, resolution or problem.resolution)
    for index, q in enumerate(dense):
        if not problem.is_valid(q, margin=margin):
            return index
    return None


def _bisection_order(n: int) -> list[int]:
    """Indices 0..n-1, ends first, then midpoints (van der Corput, as OMPL's DiscreteMotionValidator)."""
    if n == 0:
        return []
    order = [0, n - 1] if n > 1 else [0]
    seen = set(order)
    step = n - 1
    while step > 1:
        half = step // 2
        for index in builtins_range(half, n - 1, step):
            if index not in seen:
                seen.add(index)
                order.append(index)
        step = half
    order.extend(i for i in builtins_range(n) if i not in seen)
    return order


def path_is_valid(
    problem: MotionProblem, path: np.ndarray, resolution: float | None = None, margin: float | None = 0.0
) -> bool:
    """Same test as ``validate_path(...) is None`` but in bisection order: an invalid path is
    usually rejected after a few checks."""
    return bool(check_path_until(problem, path, None, resolution, margin))


def check_path_until(
    problem: MotionProblem,
    path: np.ndarray,
    deadline: float | None,
    resolution: float | None = None,
    margin: float | None = 0.0,
) -> bool | None:
    """Dense check in bisection order that gives up at ``deadline`` (``time.perf_counter``).

    True: every state valid; False: an invalid state; None: the deadline passed first.
    """
    dense = _interpolate(path, resolution or problem.resolution)
    for count, i in enumerate(_bisection_order(len(dense))):
        if deadline is not None and count % 8 == 0 and time.perf_counter() > deadline:
            return None
        if not problem.is_valid(dense[i], margin=margin):
            return False
    return True


def path_length(robot: Robot, path: np.ndarray) -> float:
    """Weighted path length rho (Vasquez-Gomez Eq. 8)."""
    return float(sum(robot.distance(a, b) for a, b in zip(path[:-1], path[1:], strict=True)))


# -- OMPL ------------------------------------------------------------------------------------
def _ompl() -> tuple[Any, Any, Any]:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_ERROR)
    return ob, og, ou


def seed_ompl(seed: int | None) -> None:
    """Seed OMPL's global seed generator (deterministic planning for a given seed)."""
    if seed is None:
        return
    _, _, ou = _ompl()
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)  # OMPL complains when RNGs exist already; reseeding still works
    ou.RNG.setSeed(max(1, int(seed)))
    ou.setLogLevel(level)


def _space(ob: Any, lower: Array, upper: Array) -> Any:
    space = ob.RealVectorStateSpace(len(lower))
    bounds = ob.RealVectorBounds(len(lower))
    for i, (lo, hi) in enumerate(zip(lower, upper, strict=True)):
        bounds.setLow(i, float(lo))
        bounds.setHigh(i, float(hi) if hi > lo else float(lo) + 1e-9)
    space.setBounds(bounds)
    return space


def _state(space: Any, q: Array) -> Any:
    state = space.allocState()
    for i, v in enumerate(q):
        state[i] = float(v)
    return state


def geometric_planner_names() -> list[str]:
    """The ``ompl.geometric`` planner classes this OMPL build offers (for lookups by name)."""
    ob, og, _ = _ompl()
    return sorted(n for n in dir(og) if isinstance(getattr(og, n), type) and issubclass(getattr(og, n), ob.Planner))


def planner_class(name: str) -> Any:
    """The OMPL geometric planner class for a plugin name or an ``og`` class name.

    No substitution: a planner this OMPL build lacks (e.g. LazyPRM in the ompl 2.0.1 wheel)
    is an error that lists the planners that exist.
    """
    _, og, _ = _ompl()
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
    :class:`_ExecutedMotionValidator`). ``time_limit`` bounds the whole call: the search,
    the simplification, the re-check and the retry (wall time from entry; one validity
    check may run past it).

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
    deadline = t0 + float(time_limit)
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if not problem.is_valid(start) or not problem.is_valid(goal):
        return None
    if try_direct:  # the straight segment first (what simplification would return anyway)
        direct = straight_line(problem, start, goal, deadline=deadline)
        if direct is not None:
            direct.planner = planner
            direct.planning_time = time.perf_counter() - t0
            return direct
    factors = [max(1.0, float(check_factor))] + ([1.0] if check_factor > 1.0 else [])
    for attempt, factor in enumerate(factors):
        remaining = deadline - time.perf_counter()
        if remaining <= 0.0:
            break
        coarse = factor > 1.0
        seed_ompl(None if seed is None else seed + attempt)
        budget = remaining * SOLVE_SHARE if coarse else remaining
        path = _ompl_search(problem, start, goal, planner, budget, simplify, range, goal_threshold, factor, deadline)
        if path is None:
            continue  # coarse search gave up (e.g. only an approximate solution): try fine
        if coarse:  # OMPL checked every factor x resolution: check the rest now, within the limit
            verdict = check_path_until(problem, problem.motion_path(path), deadline, margin=None)
            if verdict is None:
                break
            if not verdict:
                continue
        return MotionPlan(path, planner=planner, planning_time=time.perf_counter() - t0,
                          length=path_length(problem.robot, problem.motion_path(path)))
    return None


class _ExecutedMotionValidator:
    """OMPL motion validator that checks the motion the robot executes (turn-drive-turn).

    Built lazily as a subclass of ``ompl.base.MotionValidator`` (the nanobind bindings call
    the Python ``checkMotion``); used for robots whose ``execution_path`` differs from the
    straight segment (a differential base).
    """

    @staticmethod
    def create(si: Any, problem: MotionProblem, resolution: float, n: int, deadline: float | None) -> Any:
        """A validator instance; past ``deadline`` every motion is invalid (the search winds down)."""
        ob, _, _ = _ompl()

        class Validator(ob.MotionValidator):
            def checkMotion(self, a: Any, b: Any, *last_valid: Any) -> bool:  # noqa: N802 - OMPL's name
                qa = [a[i] for i in builtins_range(n)]
                qb = [b[i] for i in builtins_range(n)]
                path = problem.motion_path(np.array([qa, qb]))
                return bool(check_path_until(problem, path, deadline, resolution, margin=None))

        return Validator(si)


def _ompl_search(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str,
    time_limit: float,
    simplify: bool,
    step: float,
    goal_threshold: float,
    check_factor: float,
    deadline: float | None = None,
) -> np.ndarray | None:
    """One OMPL solve with motions checked every ``check_factor * problem.resolution``.

    Simplification is skipped once ``deadline`` has passed (the unsimplified path is valid).
    """
    ob, og, _ = _ompl()
    n = len(start)
    space = _space(ob, problem.lower, problem.upper)
    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(lambda s: problem.is_valid([s[i] for i in builtins_range(n)]))
    si = ss.getSpaceInformation()
    resolution = check_factor * problem.resolution
    si.setStateValidityCheckingResolution(min(1.0, resolution / max(space.getMaximumExtent(), 1e-9)))
    probe = np.vstack([start, goal])
    if problem.motion_path(probe).shape != probe.shape:  # the robot does not drive straight segments
        si.setMotionValidator(_ExecutedMotionValidator.create(si, problem, resolution, n, deadline))
    instance = planner_class(planner)(si)
    if step > 0 and hasattr(instance, "setRange"):
        instance.setRange(step)
    ss.setPlanner(instance)
    ss.setStartAndGoalStates(_state(space, start), _state(space, goal), goal_threshold)
    status = ss.solve(max(1e-3, float(time_limit)))
    if not status or not ss.haveExactSolutionPath():
        return None
    solution = ss.getSolutionPath()
    if simplify and solution.getStateCount() > 2 and (deadline is None or time.perf_counter() < deadline):
        simplifier = og.PathSimplifier(si)
        simplifier.reduceVertices(solution)
        simplifier.collapseCloseVertices(solution)
        simplifier.reduceVertices(solution)
    path = np.array(
        [[solution.getState(i)[k] for k in builtins_range(n)] for i in builtins_range(solution.getStateCount())]
    )
    path[0], path[-1] = start, goal
    return path


builtins_range = range  # ``plan`` shadows ``range`` with OMPL's parameter name


def straight_line(
    problem: MotionProblem, start: Array, goal: Array, deadline: float | None = None
) -> MotionPlan | None:
    """The straight segment in configuration space if it is valid (the free flyer's planner).

    Checked as the robot executes it (``problem.motion_path``); None when invalid or when
    ``deadline`` (``time.perf_counter``) passes before the check ends.
    """
    t0 = time.perf_counter()
    path = np.vstack([start, goal]).astype(float)
    if not check_path_until(problem, problem.motion_path(path), deadline, margin=None):
        return None
    return MotionPlan(path, planner="straight_line", planning_time=time.perf_counter() - t0,
                      length=path_length(problem.robot, problem.motion_path(path)))


def plan_kinodynamic(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    planner: str = "rrt",
    time_limit: float = 5.0,
    goal_tolerance: float = 0.05,
    seed: int | None = None,
    max_steps: int = 20,
) -> MotionPlan | None:
    """Base motion with velocity controls (``ompl.control``), then the other joints.

    The base (x, y, theta) is planned with the robot's drive model (``robot.propagate``:
    unicycle for a differential drive, omnidirectional otherwise) while the other joints
    keep their start values; at the base goal the remaining joints move to the goal along a
    checked straight line (or an RRT-Connect path). OMPL 2.0.1's Python bindings offer no
    bidirectional control planner, so ``planner`` is one of rrt, kpiece, sst, est, pdst.
    Returns per-step controls (``MotionPlan.controls``, held ``robot.dt`` each).
    """
    ob, _, _ = _ompl()
    from ompl import control as oc

    robot = problem.robot
    base = list(robot.base_dofs)
    if not base:
        raise ValueError(f"{robot.name} has no base to plan kinodynamically")
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if not problem.is_valid(start) or not problem.is_valid(goal):
        return None
    seed_ompl(seed)
    t0 = time.perf_counter()
    dt = float(robot.dt)
    space = _space(ob, problem.lower[base], problem.upper[base])
    limits = robot.base_control_limits()  # (nb,) max |u| of the base controls
    cspace = oc.RealVectorControlSpace(space, len(limits))
    cbounds = ob.RealVectorBounds(len(limits))
    for i, u in enumerate(limits):
        cbounds.setLow(i, -float(u))
        cbounds.setHigh(i, float(u))
    cspace.setBounds(cbounds)
    ss = oc.SimpleSetup(cspace)
    nb, nc = len(base), len(limits)

    def full(s: Any) -> Array:
        q = start.copy()
        q[base] = [s[i] for i in builtins_range(nb)]
        return q

    ss.setStateValidityChecker(lambda s: problem.is_valid(full(s)))

    def propagate(s: Any, u: Any, duration: float, result: Any) -> None:
        q = np.array([s[i] for i in builtins_range(nb)])
        q = robot.propagate_base(q, np.array([u[i] for i in builtins_range(nc)]), duration)
        for i in builtins_range(nb):
            result[i] = float(q[i])

    ss.setStatePropagator(propagate)
    si = ss.getSpaceInformation()
    si.setPropagationStepSize(dt)
    si.setMinMaxControlDuration(1, max_steps)
    si.setStateValidityCheckingResolution(problem.resolution / max(space.getMaximumExtent(), 1e-9))
    cls = getattr(oc, CONTROL_PLANNERS.get(planner, planner), None)
    if cls is None:
        raise ValueError(f"unknown control planner {planner!r} (valid: {', '.join(CONTROL_PLANNERS)})")
    ss.setPlanner(cls(si))
    ss.setStartAndGoalStates(_state(space, start[base]), _state(space, goal[base]), goal_tolerance)
    status = ss.solve(float(time_limit))
    if not status or not ss.haveExactSolutionPath():
        return None
    solution = ss.getSolutionPath()
    controls = []
    for i in builtins_range(solution.getControlCount()):
        u = [solution.getControl(i)[k] for k in builtins_range(nc)]
        steps = max(1, int(round(solution.getControlDuration(i) / dt)))
        controls.extend([u] * steps)
    base_controls = np.asarray(controls, dtype=float)
    # roll the controls out (this is the nominal trajectory the executor will follow)
    configs = [start.copy()]
    for u in base_controls:
        q = configs[-1].copy()
        q[base] = robot.propagate_base(q[base], u, dt)
        configs.append(q)
    reached = configs[-1]
    others = [i for i in builtins_range(len(start)) if i not in base]
    tail = np.vstack([reached, np.concatenate([reached[base], goal[others]])[np.argsort(base + others)]])
    if others and np.any(np.abs(tail[1] - tail[0]) > 1e-12):
        if validate_path(problem, tail, margin=None) is not None:
            sub = plan(problem, tail[0], tail[1], "rrt_connect", time_limit=max(0.5, time_limit / 2), seed=seed)
            if sub is None:
                return None
            tail = sub.path
        joint_controls, joint_path = robot.controls_from_path(tail)
        full_controls = np.vstack([robot.base_to_full_controls(base_controls), joint_controls])
        path = np.vstack([np.asarray(configs), joint_path[1:]])
    else:
        full_controls = robot.base_to_full_controls(base_controls)
        path = np.asarray(configs)
    if validate_path(problem, path, margin=None) is not None:
        return None
    return MotionPlan(
        path,
        controls=full_controls,
        dt=dt,
        planner=f"kinodynamic_{planner}",
        planning_time=time.perf_counter() - t0,
        exact=True,
        length=path_length(robot, path),
    )


# -- scan paths and the NBS rule ---------------------------------------------------------------
@dataclass
class ScanPathIK:
    """Configurations along a linear scan path in ``step`` portions (Kriegel thesis Sec. 2)."""

    configs: np.ndarray  # (r, dof) configurations of the reachable prefix
    poses: np.ndarray  # (m, 4, 4) all portion poses along the path
    reachable: int  # number of leading portion poses reached with continuity

    @property
    def complete(self) -> bool:
        return self.reachable == len(self.poses)

    @property
    def fraction(self) -> float:
        return self.reachable / max(1, len(self.poses))


def scan_path_poses(path: ScanPath, step: float = 0.01) -> np.ndarray:
    """Sensor poses every ``step`` metres along the path (orientation of the start kept)."""
    count = max(2, int(math.ceil(path.length / step)) + 1)
    s = np.linspace(0.0, 1.0, count)
    poses = np.repeat(path.start[None], count, axis=0)
    poses[:, :3, 3] = path.start[:3, 3] + s[:, None] * (path.end[:3, 3] - path.start[:3, 3])
    return poses


def linear_scan_path_ik(
    robot: Robot,
    path: ScanPath,
    step: float = 0.01,
    rng: np.random.Generator | None = None,
    q_start: Array | None = None,
    problem: MotionProblem | None = None,
    max_joint_step: float = 0.2,
    deviation: float = 0.002,
) -> ScanPathIK:
    """IK for every 10 mm portion of a linear scan path, each seeded by the previous one.

    A portion is reachable if IK succeeds from the previous configuration, no joint moves by
    more than ``max_joint_step`` rad (a PTP motion without an extra waypoint), the sensor's
    midpoint between the two configurations stays within ``deviation`` of the line, and the
    configuration is valid for ``problem`` (if given).
    """
    rng = rng or np.random.default_rng(0)
    poses = scan_path_poses(path, step)
    configs: list[Array] = []
    q_prev = q_start
    if q_prev is None:
        q_prev = robot.ik(poses[0], rng)
        if q_prev is None:
            return ScanPathIK(np.zeros((0, robot.dof)), poses, 0)
    for index, pose in enumerate(poses):
        q = robot.ik(pose, rng, seed=q_prev) if index or q_start is not None else q_prev
        if q is None:
            break
        if configs:
            if np.max(np.abs(q - configs[-1])) > max_joint_step:
                break
            mid = robot.fk(0.5 * (q + configs[-1]))[:3, 3]
            a, b = poses[index - 1][:3, 3], pose[:3, 3]
            if _point_segment_distance(mid, a, b) > deviation:
                break
        if problem is not None and not problem.is_valid(q):
            break
        configs.append(q)
        q_prev = q
    stacked = np.asarray(configs) if configs else np.zeros((0, robot.dof))
    return ScanPathIK(stacked, poses, len(configs))


def _point_segment_distance(x: Array, a: Array, b: Array) -> float:
    ab = b - a
    t = 0.0 if float(ab @ ab) < 1e-18 else float(np.clip((x - a) @ ab / (ab @ ab), 0.0, 1.0))
    return float(np.linalg.norm(x - (a + t * ab)))


BLOCK_FREE, BLOCK_UNKNOWN, BLOCK_OCCUPIED = "free", "unknown", "occupied"


def classify_blocked(
    robot: Robot,
    configs: np.ndarray,
    probability: Probability,
    free_below: float = 0.05,
    occupied_above: float = 0.75,
    extra_points: Points3 | None = None,
    space_free: SpaceFree | None = None,
) -> str:
    """NBS rule for a blocked candidate (Kriegel et al. IROS 2012 Sec. B6).

    The robot's link points at every configuration of the candidate (and ``extra_points``)
    are looked up in the PVS: any point with occupancy above ``occupied_above`` (0.75, the
    thesis' "occupied" class for pose validation) means the candidate runs through occupied
    space -> ``"occupied"`` (discard it); otherwise any point not confidently free
    (p >= ``free_below`` = 0.05) -> ``"unknown"`` (keep it on the stack for later);
    else ``"free"`` (it is not blocked by the PVS). With ``space_free`` (e.g. ``pvs.is_free``)
    only the points it reports blocked are classified (points outside the PVS grid are free).
    """
    points = [robot.link_points(q) for q in np.atleast_2d(configs)]
    if extra_points is not None:
        points.append(np.asarray(extra_points, dtype=float).reshape(-1, 3))
    stacked = np.vstack(points) if points else np.zeros((0, 3))
    if space_free is not None and len(stacked):
        stacked = stacked[~np.asarray(space_free(stacked), dtype=bool)]
    if len(stacked) == 0:
        return BLOCK_FREE
    prob = np.asarray(probability(stacked), dtype=float)
    if np.any(prob > occupied_above):
        return BLOCK_OCCUPIED
    if np.any(prob >= free_below):
        return BLOCK_UNKNOWN
    return BLOCK_FREE
