"""A motion problem: a robot plus a validity checker (the KNOWN static environment and, optionally, the PVS
free-space test on points of the robot's links: everything not confidently free is an obstacle, Kriegel thesis
Sec. 3.2.2), and the dense re-checks of paths."""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Array, Points3
from explore.mapping import obstacle_distance
from explore.motion.planning_clock import Budget, charge

if TYPE_CHECKING:
    from explore.motion.robot import Robot


SpaceFree = Callable[..., np.ndarray]  # points (n, 3)[, clearance] -> bool (n,) free

Probability = Callable[[np.ndarray], np.ndarray]  # points (n, 3) -> occupancy (n,)


# -- the planning problem ----------------------------------------------------------------------
class MotionProblem:
    """A robot, its validity checker (known environment + optional free-space test), bounds.

    A configuration is valid if it is within the joint limits, the robot is at least
    ``margin`` away from every known environment body, does not collide with itself, and
    (with ``space_free``) every point sampled on its links is free in the PVS.
    ``space_bounds`` (lo, hi): ``space_free`` calls everything outside this box free, so only
    the robot parts near it are sampled (derived automatically for ``pvs.is_free``).
    ``drive_margin``: how far a mobile base keeps from the known environment while it drives,
    away from the drive's ends (:class:`explore.motion.PlanarChecker`); None: the robot's
    ``drive_clearance``. ``space_margin``: the clearance each link point keeps from non-free voxels,
    passed to a ``space_free`` that takes one (``pvs.is_free(points, clearance)``); None: the
    robot's ``space_margin`` (its clearance plus the gaps between its points).
    """

    def __init__(
        self,
        robot: Robot,
        space_free: SpaceFree | None = None,
        margin: float | None = None,
        resolution: float = 0.01,
        space_bounds: tuple[Array, Array] | None = None,
        drive_margin: float | None = None,
        space_margin: float | None = None,
    ) -> None:
        self.robot = robot
        self.space_margin = float(robot.space_margin if space_margin is None else space_margin)
        self.drive_margin = float(robot.drive_clearance if drive_margin is None else drive_margin)
        self.space_free = space_free
        self.margin = float(robot.clearance if margin is None else margin)
        self.resolution = float(resolution)  # max configuration step (L2) between checks
        self.checks = 0
        self.space_bounds = space_bounds if space_bounds is not None else _free_outside_box(space_free)
        self.pins: dict[int, float] = {}
        self.motions: dict[tuple, np.ndarray] = {}  # joint motions found (see cache_key)
        self._takes_clearance = space_free is not None and "clearance" in inspect.signature(space_free).parameters

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
        out = MotionProblem(self.robot, self.space_free, self.margin, self.resolution, self.space_bounds,
                            self.drive_margin, self.space_margin)
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
            if len(points) and not bool(np.all(self.points_free(points))):
                return False
        return True

    def points_free(self, points: Points3) -> np.ndarray:
        """``space_free`` of robot points, with ``space_margin`` when the test takes a clearance."""
        assert self.space_free is not None
        if self._takes_clearance:
            return self.space_free(points, clearance=self.space_margin)
        return self.space_free(points)

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


class BodyFreeSpace:
    """A PVS's free-space test that also calls free the voxels the robot's body has stood in.

    The robot was there, so that space is free although no beam may have observed it (the arm
    behind an eye-in-hand camera; a base a centimetre off its plan after noisy driving). Without
    this a configuration the robot stands in can be invalid, and no motion can leave it.
    Usable as ``space_free`` (:meth:`is_free`, with the PVS's box and a ``version`` for caching).
    """

    def __init__(self, pvs: Any) -> None:
        self.pvs = pvs
        self._keys = np.zeros(0, dtype=np.int64)
        self._stamp = 0
        self._field: tuple[tuple[int, int], np.ndarray] | None = None

    @property
    def min_corner(self) -> Array:
        return self.pvs.min_corner

    @property
    def max_corner(self) -> Array:
        return self.pvs.max_corner

    @property
    def version(self) -> tuple[int, int]:
        return int(self.pvs.version), self._stamp

    def _keys_of(self, points: Points3) -> tuple[np.ndarray, np.ndarray]:
        ijk, inside = self.pvs.index(points)
        return np.ravel_multi_index(ijk[inside].T, self.pvs.shape).astype(np.int64), inside

    def stand(self, points: Points3) -> None:
        """The robot's body (points on its links) stands here: their voxels are free from now on."""
        keys, _ = self._keys_of(np.asarray(points, dtype=float).reshape(-1, 3))
        merged = np.union1d(self._keys, keys)
        if len(merged) != len(self._keys):
            self._keys, self._stamp = merged, self._stamp + 1

    @property
    def resolution(self) -> float:
        return float(self.pvs.resolution)

    @property
    def lattice(self) -> np.ndarray:
        return self.pvs.lattice

    def index(self, points: Points3) -> tuple[np.ndarray, np.ndarray]:
        return self.pvs.index(points)

    def distance_field(self) -> np.ndarray:
        """``pvs.distance_field`` with the voxels the body has stood in free (for the clearance of
        rollouts, :class:`explore.nbv.ObstacleField`, which takes this in place of the PVS)."""
        if not len(self._keys):
            return self.pvs.distance_field()
        if self._field is not None and self._field[0] == self.version:
            return self._field[1]
        obstacle = self.pvs.obstacle_grid().copy()
        obstacle.reshape(-1)[self._keys] = False
        field = obstacle_distance(obstacle, self.resolution)
        self._field = (self.version, field)
        return field

    def is_free(self, points: Points3, clearance: float = 0.0, outside_free: bool = True) -> np.ndarray:
        """``pvs.is_free``, and True in the voxels the body has stood in."""
        free = np.asarray(self.pvs.is_free(points, clearance, outside_free), dtype=bool)
        if len(self._keys) and len(free):
            keys, inside = self._keys_of(np.asarray(points, dtype=float).reshape(-1, 3))
            free[inside] |= np.isin(keys, self._keys)
        return free


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
