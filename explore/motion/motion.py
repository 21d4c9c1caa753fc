"""Motion planning and execution: validity checking, OMPL planners, noisy execution records.

* :class:`BulletCollider` checks robot parts against pybullet bodies (AABB pre-filter,
  ``getClosestPoints`` with a margin) and precomputed self-collision link pairs, in the style
  of pybullet-planning's ``get_collision_fn``.
* :class:`MotionProblem` is a robot plus a validity checker: robot vs the KNOWN static
  environment (``sim.environment_ids()``) and, optionally, a ``space_free(points) -> bool``
  callable (the PVS distance field: everything not confidently free, p >= 0.05, is an
  obstacle; Kriegel thesis Sec. 3.2.2) evaluated on points sampled on the robot's links.
* :func:`plan` wraps every OMPL geometric planner the installed bindings offer, by name, within
  its time limit (search, re-check and retry included); a differential base is checked as it
  drives (turn-drive-turn). :func:`plan_kinodynamic` (``ompl.control``, unicycle or
  omnidirectional model) and :func:`plan_mobile` (geometric base path) move a mobile robot:
  arm to its travel configuration, base, arm to the goal, with per-step velocity controls;
  :class:`PlanarChecker` tests base poses of the rigid robot fast; :func:`validate_path`
  re-checks a path densely.
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

from explore.core import Array, Points3, Pose, wrap_angle
from explore.motion.planning_clock import Budget, charge

if TYPE_CHECKING:
    from explore.motion.robot import Robot
    from explore.sim import ScanPath

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


def truncated_normal_logpdf(eps: np.ndarray, sigma: Array, beta: float = 3.0,
                            active: np.ndarray | None = None) -> float:
    """Sum of log densities of the truncated normal errors (log of Eq. 2 / Eq. 3 products).

    Dimensions with sigma = 0 (noise-free) contribute nothing, nor do the entries that
    ``active`` (same shape as ``eps``) marks as not sampled (a control that commands no motion).
    """
    sigma = np.asarray(sigma, dtype=float)
    use = sigma > 0
    if not use.any() or len(eps) == 0:
        return 0.0
    e, s = np.asarray(eps)[:, use], sigma[use]
    mass = math.erf(beta / math.sqrt(2.0))  # P(-beta sigma <= e <= beta sigma) = 0.997 for beta 3
    logpdf = -0.5 * (e / s) ** 2 - np.log(s * math.sqrt(2.0 * math.pi)) - math.log(mass)
    if active is not None:
        logpdf = np.where(np.asarray(active, dtype=bool)[:, use], logpdf, 0.0)
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
        from explore.sim import p

        self.p = p
        self.client = client
        self.parts = list(parts)
        self.self_pairs = list(self_pairs)
        self.ignore = set(ignore)
        self._aabb: dict[int, tuple[tuple, tuple]] = {}
        # integer indices of the parts (a frozen dataclass hashes slowly in the inner loop)
        index = {part: i for i, part in enumerate(self.parts)}
        self._pair_index = [(index.get(a, -1), index.get(b, -1)) for a, b in self.self_pairs]
        self._pair_a = np.array([i for i, _ in self._pair_index], dtype=np.int64)
        self._pair_b = np.array([j for _, j in self._pair_index], dtype=np.int64)
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

        AABB overlap tests (one numpy comparison of every part box with every obstacle box)
        prune both the obstacle and the self-collision pairs before ``getClosestPoints``.
        """
        p, c = self.p, self.client
        hits: list[int] = []
        boxes = self.obstacle_aabbs(obstacles)
        part_boxes = np.array([[*lo, *hi] for lo, hi in (p.getAABB(part.body, part.link, physicsClientId=c)
                                                         for part in self.parts)]).reshape(-1, 6)
        if boxes:
            ids = [body for body, _, _ in boxes]
            obstacle_boxes = np.array([[*lo, *hi] for _, lo, hi in boxes])
            near = np.all(part_boxes[:, None, :3] - margin <= obstacle_boxes[None, :, 3:], axis=2) & \
                np.all(part_boxes[:, None, 3:] + margin >= obstacle_boxes[None, :, :3], axis=2)
            for i, j in zip(*np.nonzero(near), strict=True):
                body = ids[j]
                if body in hits or (self._ignore_index and (int(i), body) in self._ignore_index):
                    continue
                part = self.parts[i]
                points = p.getClosestPoints(part.body, body, margin, linkIndexA=part.link, physicsClientId=c)
                if points and min(pt[8] for pt in points) < margin:
                    hits.append(body)
        if self_check and self.self_pairs:
            ia, ib = self._pair_a, self._pair_b
            known = (ia >= 0) & (ib >= 0)
            a_box, b_box = part_boxes[np.where(known, ia, 0)], part_boxes[np.where(known, ib, 0)]
            touching = ~known | (np.all(a_box[:, :3] <= b_box[:, 3:], axis=1) & np.all(a_box[:, 3:] >= b_box[:, :3],
                                                                                     axis=1))
            for index in np.flatnonzero(touching):  # disjoint boxes cannot penetrate
                a, b = self.self_pairs[index]
                points = p.getClosestPoints(
                    a.body, b.body, 0.0, linkIndexA=a.link, linkIndexB=b.link, physicsClientId=c
                )
                if points and min(pt[8] for pt in points) < 0.0:
                    hits.append(-1)
                    break
        return hits


def self_collision_pairs(
    client: int, parts: Sequence[Part], adjacent: Callable[[Part, Part], bool], tolerance: float = 0.0
) -> list[tuple[Part, Part]]:
    """Non-adjacent part pairs that do not touch in the current (home) state."""
    from explore.sim import p

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
    ``space_bounds`` (lo, hi): ``space_free`` calls everything outside this box free, so only
    the robot parts near it are sampled (derived automatically for ``pvs.is_free``).
    """

    def __init__(
        self,
        robot: Robot,
        space_free: SpaceFree | None = None,
        margin: float | None = None,
        resolution: float = 0.01,
        space_bounds: tuple[Array, Array] | None = None,
    ) -> None:
        self.robot = robot
        self.space_free = space_free
        self.margin = float(getattr(robot, "clearance", 0.0) if margin is None else margin)
        self.resolution = float(resolution)  # max configuration step (L2) between checks
        self.checks = 0
        self.space_bounds = space_bounds if space_bounds is not None else _free_outside_box(space_free)
        self.pins: dict[int, float] = {}
        self.motions: dict[tuple, np.ndarray] = {}  # joint motions found (see cache_key)

    @property
    def lower(self) -> Array:
        lower = np.asarray(self.robot.lower, dtype=float).copy()
        for index, value in self.pins.items():
            lower[index] = value
        return lower

    @property
    def upper(self) -> Array:
        upper = np.asarray(self.robot.upper, dtype=float).copy()
        for index, value in self.pins.items():
            upper[index] = value
        return upper

    def cache_key(self, a: Array, b: Array) -> tuple | None:
        """Key of a motion a -> b valid while the free space does not change (None: no caching).

        Without ``space_free`` the known environment is static; ``pvs.is_free`` carries the
        PVS version; any other free-space test cannot be cached.
        """
        if self.space_free is None:
            version: Any = "static"
        else:
            version = getattr(getattr(self.space_free, "__self__", None), "version", None)
            if version is None:
                return None
        return (np.asarray(a, dtype=float).tobytes(), np.asarray(b, dtype=float).tobytes(), version,
                tuple(sorted(self.pins.items())))

    def pinned(self, dofs: Sequence[int], q: Array) -> MotionProblem:
        """The same problem with the joints ``dofs`` held at their values in ``q`` (e.g. the base)."""
        out = MotionProblem(self.robot, self.space_free, self.margin, self.resolution, self.space_bounds)
        out.pins = {**self.pins, **{int(i): float(q[i]) for i in dofs}}
        out.motions = self.motions
        return out

    def is_valid(self, q: Array, margin: float | None = None) -> bool:
        """Validity of one configuration (limits, known environment, self, free space)."""
        self.checks += 1
        charge("state")
        q = np.asarray(q, dtype=float)
        if np.any(q < self.lower - 1e-9) or np.any(q > self.upper + 1e-9):
            return False
        robot = self.robot
        if robot.in_collision(q, world="known", margin=self.margin if margin is None else margin):
            return False
        if self.space_free is not None:
            if self.space_bounds is None:
                points = robot.link_points(q)
            else:  # only parts near the box whose outside ``space_free`` calls free
                points = robot.link_points(q, within=self.space_bounds)
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


def _free_outside_box(space_free: SpaceFree | None) -> tuple[Array, Array] | None:
    """The grid box of ``pvs.is_free`` (which calls every point outside its grid free), else None."""
    owner = getattr(space_free, "__self__", None)
    if getattr(space_free, "__name__", "") == "is_free" and hasattr(owner, "min_corner"):
        return np.asarray(owner.min_corner, dtype=float), np.asarray(owner.max_corner, dtype=float)
    return None


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
        for index in range(half, n - 1, step):
            if index not in seen:
                seen.add(index)
                order.append(index)
        step = half
    order.extend(i for i in range(n) if i not in seen)
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
    budget: Budget | None,
    resolution: float | None = None,
    margin: float | None = 0.0,
) -> bool | None:
    """Dense check in bisection order that gives up when ``budget`` expires.

    True: every state valid; False: an invalid state; None: the budget ran out first.
    """
    dense = _interpolate(path, resolution or problem.resolution)
    for count, i in enumerate(_bisection_order(len(dense))):
        if budget is not None and count % 8 == 0 and budget.expired():
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
        path = _ompl_search(problem, start, goal, planner, search, simplify, range, goal_threshold, factor, budget)
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
    ob, _, _ = _ompl()

    class Validator(ob.MotionValidator):
        def checkMotion(self, a: Any, b: Any, *last_valid: Any) -> bool:  # noqa: N802 - OMPL's name
            qa = [a[i] for i in range(n)]
            qb = [b[i] for i in range(n)]
            path = problem.motion_path(np.array([qa, qb]))
            return bool(check_path_until(problem, path, budget, resolution, margin=None))

    return Validator(si)


def _ompl_search(
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
    ob, og, _ = _ompl()
    n = len(start)
    space = _space(ob, problem.lower, problem.upper)
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
    ss.setStartAndGoalStates(_state(space, start), _state(space, goal), goal_threshold)
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
    ob, _, _ = _ompl()
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
        self.margin = problem.margin
        self.drive_margin = max(float(drive_margin), self.margin)
        self.ends = np.array([np.asarray(e, dtype=float)[:2] for e in ends]).reshape(-1, 2)
        self.slack = math.sqrt(3.0) * float(spacing) + 0.02
        boxes = []
        sim = getattr(robot, "sim", None)
        if sim is not None and len(points):
            from explore.sim import p

            zmin, zmax = float(self.z.min()), float(self.z.max())
            for body in sim.environment_ids():
                lo, hi = p.getAABB(body, physicsClientId=sim.client)
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
        from explore.motion.kernels import planar_points_clearance

        charge("planar")
        qb = np.asarray(qb, dtype=float)
        if np.any(qb < self.lower - 1e-9) or np.any(qb > self.upper + 1e-9):
            return False
        drive = self.margin
        if self.drive_margin > self.margin:
            to_end = float(np.sqrt(((self.ends - qb[:2]) ** 2).sum(axis=1)).min(initial=np.inf))
            drive = min(self.drive_margin, self.margin + to_end)
        clearance, inside = planar_points_clearance(
            self.local, self.z, self.radius, float(qb[0]), float(qb[1]), float(qb[2]), self.lo, self.hi,
            max(drive, self.margin + self.slack), self._box[0], self._box[1], self._points)
        if clearance < drive - 1e-12 and drive > self.margin:  # the funnel, measured to the bounding boxes
            return False
        space_free = self.problem.space_free
        if space_free is not None and inside:
            points = self._points
            near = points[np.all((points >= self._box[0]) & (points <= self._box[1]), axis=1)]
            if not bool(np.all(space_free(near))):
                return False
        if clearance >= self.margin + self.slack:
            return True
        return self.problem.is_valid(self.full(qb))


class _BaseProblem:
    """The base (x, y, theta) part of a problem with the other joints carried fixed.

    Duck-types :class:`MotionProblem` for :func:`_ompl_search`: validity by a
    :class:`PlanarChecker`, motions as the robot drives them (``problem.motion_path``).
    """

    def __init__(self, problem: MotionProblem, carried: Array, goal: Array, lower: Array, upper: Array) -> None:
        self.problem, self.robot = problem, problem.robot
        ends = [carried[list(problem.robot.base_dofs)], goal]  # the drive's start and goal base poses
        self.checker = PlanarChecker(problem, carried, drive_margin=float(getattr(self.robot, "drive_clearance", 0.0)),
                                     ends=ends)
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
    travel = getattr(robot, "travel_joints", None)
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


def _mobile_plan(
    problem: MotionProblem,
    start: Array,
    goal: Array,
    drive: Callable[[_BaseProblem, Array, Array, Budget], tuple[np.ndarray, np.ndarray] | None],
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
        sub = _BaseProblem(problem, carried, goal[base], lower, upper)
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
    ob, _, _ = _ompl()
    from ompl import control as oc

    cls = control_planner_class(planner)
    robot = problem.robot
    dt = float(robot.dt)

    def drive(sub: _BaseProblem, a: Array, b: Array, budget: Budget) -> tuple[np.ndarray, np.ndarray] | None:
        seed_ompl(seed)
        space = _space(ob, sub.lower, sub.upper)
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
        ss.setStartAndGoalStates(_state(space, a), _state(space, b), goal_tolerance)
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

    return _mobile_plan(problem, start, goal, drive, time_limit, seed, tuck, f"kinodynamic_{planner}")


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

    def drive(sub: _BaseProblem, a: Array, b: Array, budget: Budget) -> tuple[np.ndarray, np.ndarray] | None:
        seed_ompl(seed)
        if budget.remaining() <= 0.0:
            return None
        path = _ompl_search(sub, a, b, planner, budget.share(0.8), simplify, 0.0, 1e-6, 1.0, budget)
        if path is None:
            return None
        controls, rolled = robot.controls_from_path(sub.full_path(path))
        base = list(robot.base_dofs)
        return rolled[:, base], controls[:, : robot.n_base_controls]

    return _mobile_plan(problem, start, goal, drive, time_limit, seed, tuck, f"mobile_{planner}")


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
    ob, _, _ = _ompl()
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
