"""The expected utility of a view/state under positioning noise (Vasquez-Gomez et al., Algorithm 1): k noisy
executions of the plan with the robot's noise model (truncated Gaussian velocity errors, Sec. A6; open loop or
re-localising, :func:`explore.motion.follow_plan`); any sampled state in the obstacle region makes the candidate
infeasible; else E(G) is the mean of g(s_i), or Algorithm 1's sum_i g(s_i) eta P_i with P_i = prod_t p(eps_t)
(Eq. 2-3, in log space, eta = 1 / sum_i P_i). samples_needed is the bound k >= log a / log(1 - eta gamma)
(Eq. 11-18)."""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3
from explore.motion import (
    MotionPlan,
    Rollouts,
    box_distance,
    follow_plan,
    plan_controls,
    rigid_clearances,
    rigid_first_hit,
)


# -- the bound on k (Eq. 11-18) --------------------------------------------------------------
def samples_needed(alpha: float, eta: float, gamma: float) -> int:
    """Smallest k with k >= log(alpha) / log(1 - eta gamma) (Vasquez-Gomez Eq. 18).

    ``alpha``: accepted probability of missing a collision (confidence 1 - alpha);
    ``eta`` = 1 / P(R), R the region reached with errors truncated at beta (1 / 0.997 for
    3 sigma); ``gamma`` = P(O n R), the probability that a rollout ends in the obstacle region.
    Example (paper): alpha = 0.01, eta = 1/0.997, gamma = 0.05 -> 90.
    """
    if not 0.0 < alpha < 1.0:
        raise ValueError("alpha must be in (0, 1)")
    if gamma <= 0.0 or eta <= 0.0:
        raise ValueError("eta and gamma must be positive (no obstacle probability: no k detects it)")
    miss = 1.0 - eta * gamma
    if miss <= 0.0:
        return 1
    return max(1, int(math.ceil(math.log(alpha) / math.log(miss) - 1e-12)))


# -- obstacles as seen by the planner -------------------------------------------------------
class ObstacleField:
    """Clearance of points from the planning obstacles O = W_obj u W_unk u O_env (Sec. A1).

    ``boxes`` are the known environment bodies as axis-aligned boxes (every shipped world
    builds its environment from boxes); the clearance from them is the exact signed distance
    (negative inside) minus ``box_margin``
    (the robot's planning clearance, so that a planner-validated state has clearance >= 0).
    The PVS contributes every voxel with p >= 0.05 (unknown is an obstacle): its distance
    field minus half a voxel diagonal and ``space_margin`` inside the grid (the robot's
    ``space_margin``: its clearance plus the gaps between the sampled points), the distance to
    the grid box outside. ``pvs`` may be a :class:`explore.motion.BodyFreeSpace` over the PVS (the
    voxels the robot has stood in are then free).
    A point with clearance < 0 is in collision. Bodies below ``ground`` (the floor) are left
    out: planar base noise never changes heights, so it cannot push the robot into them.
    """

    def __init__(self, boxes: list[tuple[Array, Array]], pvs: Any = None, box_margin: float = 0.0,
                 ground: float = 1e-3, space_margin: float = 0.0) -> None:
        kept = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes if float(hi[2]) > ground]
        self.lo = np.array([b[0] for b in kept]).reshape(-1, 3)
        self.hi = np.array([b[1] for b in kept]).reshape(-1, 3)
        self.box_margin = float(box_margin)
        self.space_margin = float(space_margin)
        self.pvs = pvs
        self._field: np.ndarray | None = None
        self._version = -1
        self._references: OrderedDict[bytes, _RigidReference] = OrderedDict()

    @classmethod
    def from_sim(cls, sim: Any, pvs: Any = None, box_margin: float | None = None) -> ObstacleField:
        """The known environment of ``sim`` (never its objects) plus the PVS, with the robot's margins."""
        boxes = [tuple(b.mesh.bounds) for b in sim.bodies if not b.is_object]
        robot = getattr(sim, "robot", None)
        margin = float(getattr(robot, "clearance", 0.0)) if box_margin is None else box_margin
        return cls(boxes, pvs, margin, space_margin=float(getattr(robot, "space_margin", 0.0)))

    def _pvs_field(self) -> np.ndarray:
        version = getattr(self.pvs, "version", 0)
        if self._field is None or version != self._version:
            self._field = np.asarray(self.pvs.distance_field(), dtype=float)
            self._version = version
            self._references.clear()
        return self._field

    #: rigid references kept (about 0.2 MB each): every candidate of a view starts with the same motion
    #: (e.g. the arm tucking), whose references are then computed once
    REFERENCES_KEPT = 512

    def rigid_reference(self, robot: Any, config: Array) -> _RigidReference:
        """The robot at ``config`` for rigid planar tests of its samples (one per arm configuration,
        moved along with the nominal base, see :class:`_RigidReference`)."""
        if self.pvs is not None:
            self._pvs_field()  # a new PVS version drops the references
        config = np.asarray(config, dtype=float)
        key = config[list(robot.joint_dofs)].tobytes()
        reference = self._references.get(key)
        if reference is None:
            reference = self._references[key] = _RigidReference(robot, config, self)
            if len(self._references) > self.REFERENCES_KEPT:
                self._references.popitem(last=False)
        else:
            self._references.move_to_end(key)
        reference.follow(config)
        return reference

    def kernel_field(self) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
        """PVS distance field, lattice, voxel size and grid box for numba kernels (empty without a PVS)."""
        if self.pvs is None:
            return np.zeros((0, 0, 0)), np.zeros(3, dtype=np.int64), 1.0, np.zeros(3), np.zeros(3)
        return (np.ascontiguousarray(self._pvs_field()), np.asarray(self.pvs.lattice, dtype=np.int64),
                float(self.pvs.resolution), np.asarray(self.pvs.min_corner, dtype=float),
                np.asarray(self.pvs.max_corner, dtype=float))

    def clearance(self, points: Points3) -> Array:
        """(n,) clearance of each point (< 0: collision): to the boxes minus the margin; in the PVS the
        distance between the point's voxel centre and the nearest obstacle voxel centre minus half a
        voxel diagonal and ``space_margin``. A point can be up to half a diagonal nearer than that:
        motion bounds must subtract it."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        out = box_distance(points, self.lo, self.hi) - self.box_margin
        if self.pvs is not None and len(points):
            pvs = self.pvs
            field_ = self._pvs_field()
            ijk, inside = pvs.index(points)
            dist = np.empty(len(points))
            dist[inside] = field_[tuple(ijk[inside].T)] - 0.5 * math.sqrt(3.0) * pvs.resolution - self.space_margin
            outside = ~inside
            if outside.any():  # any obstacle voxel lies inside the grid box
                lo, hi = np.asarray(pvs.min_corner)[None], np.asarray(pvs.max_corner)[None]
                dist[outside] = box_distance(points[outside], lo, hi)
            out = np.minimum(out, dist)
        return out


# -- rollouts and Algorithm 1 ----------------------------------------------------------------
@dataclass
class StateSamples:
    """Sampled final states s_i of Algorithm 1, what a utility needs to score them."""

    configs: np.ndarray  # (k, dof) final configurations
    poses: np.ndarray  # (k, 4, 4) world_T_sensor at the final configurations
    lengths: Array  # (k,) weighted length rho (Eq. 8) of each sampled trajectory
    log_prob: Array  # (k,) log P_i = sum_t log p(eps_t) (Eq. 2-3)

UtilityFn = Callable[[StateSamples], np.ndarray]  # samples -> (k,) utility g(s_i)


@dataclass
class ExpectedUtility:
    """Result of :func:`expected_utility` (Algorithm 1)."""

    value: float  # E(G_x) ~ sum_i g_i eta P_i; 0 when infeasible
    feasible: bool
    k: int
    collided_sample: int | None = None
    utilities: Array = field(default_factory=lambda: np.zeros(0))  # g_i
    weights: Array = field(default_factory=lambda: np.zeros(0))  # eta P_i
    mean: float = 0.0  # plain sample mean of g_i (diagnostic)
    ess: float = 0.0  # effective sample size 1 / sum w_i^2 of the weights (k for equal weights)


def _weighted_lengths(robot: Any, configs: np.ndarray) -> Array:
    """Eq. 8 along each trajectory (k, m + 1, dof) -> (k,)."""
    w = np.asarray(robot.weights, dtype=float)[: configs.shape[2]]
    d = np.diff(configs, axis=1)
    return np.sqrt(np.einsum("kmd,d->km", d * d, w)).sum(axis=1)


def expected_utility(
    candidate: Any,
    utility_fn: UtilityFn,
    robot: Any,
    plan: MotionPlan | np.ndarray,
    rng: np.random.Generator,
    k: int = 100,
    obstacles: ObstacleField | None = None,
    weighting: str = "mean",
    feedback: bool = False,
    leg_length: float = 0.0,
) -> ExpectedUtility:
    """Algorithm 1: expected utility of ``candidate`` reached by executing ``plan`` k times.

    Every sampled execution x_0..x_m (:func:`explore.motion.follow_plan` with the robot's
    truncated noise: open loop as in the paper, or with ``feedback`` re-localising at the
    plan's waypoints and every ``leg_length`` m of a drive, as the robot executes it) is
    checked state by state against the planning obstacles; ANY colliding state of ANY sample
    makes the candidate infeasible (value 0). Otherwise the utility g(s_i) of each sampled final
    state is averaged. ``weighting="mean"`` gives every sample the weight 1/k: the plain Monte
    Carlo estimate of E(G), since the samples are already drawn from the noise model.
    ``weighting="probability"`` is Algorithm 1 as printed, E(G) = sum_i g_i eta P_i with
    P_i = prod_t p(eps_t) (Eq. 2-3) and eta = 1 / sum_i P_i (log-sum-exp), which counts each
    sample's probability twice: log P_i sums one term -e^2 / (2 sigma^2) - log Z per noisy
    control and step, whose spread grows like sqrt(steps x controls / 2) (about 17 for 300
    steps of 2 noisy controls), so the weights collapse onto a few samples. ``ess`` =
    1 / sum w_i^2 says how many samples the estimate rests on.

    The collision test is :func:`colliding_rollouts`; ``obstacles`` defaults to the known
    environment of ``robot.sim``.
    """
    k = int(k)
    if k < 1:
        raise ValueError("k must be >= 1")
    if weighting not in ("probability", "mean"):
        raise ValueError(f"weighting must be 'probability' or 'mean', got {weighting!r}")
    if obstacles is None:
        obstacles = ObstacleField.from_sim(robot.sim) if getattr(robot, "sim", None) is not None else \
            ObstacleField([], None)
    start, controls = plan_controls(robot, plan)
    rollouts = follow_plan(robot, start, controls, rng, k, feedback, leg_length)
    configs, log_prob = rollouts.configs, rollouts.log_prob
    hits = colliding_rollouts(robot, rollouts, obstacles, stop_at_first=True)
    if hits.any():
        return ExpectedUtility(0.0, False, k, int(np.flatnonzero(hits)[0]))
    finals = configs[:, -1]
    poses = np.array([robot.fk(q) for q in finals])
    samples = StateSamples(finals, poses, _weighted_lengths(robot, configs), log_prob)
    g = np.asarray(utility_fn(samples), dtype=float).reshape(k)
    g = np.where(np.isfinite(g), g, 0.0)
    if weighting == "probability":
        weights = np.exp(log_prob - log_prob.max())
        weights /= weights.sum()  # eta P_i
    else:  # "mean": the plain sample mean
        weights = np.full(k, 1.0 / k)
    result = ExpectedUtility(float(np.sum(g * weights)), True, k, utilities=g, weights=weights,
                             mean=float(g.mean()), ess=float(1.0 / np.sum(weights**2)))
    if hasattr(candidate, "expected"):
        candidate.expected = result
    return result


def colliding_rollouts(robot: Any, rollouts: Rollouts, obstacles: ObstacleField,
                       stop_at_first: bool = False) -> np.ndarray:
    """(k,) True for each rollout with a state in the planning obstacles (latest steps first:
    collisions are likeliest where the drift is largest and the goal near the object).

    When the noise moves only the planar base, every sample at a step is a reference robot moved
    rigidly in the plane (:class:`_RigidReference`); with joint noise each sample's own points are
    tested (slow); without noise every sample is the validated nominal.
    ``stop_at_first``: return as soon as one colliding rollout is found (Algorithm 1's test).
    """
    configs, nominal = rollouts.configs, rollouts.nominal
    sigma = np.asarray(robot.control_sigma(), dtype=float)
    base = list(robot.base_dofs)
    rigid = bool(base) and not np.any(sigma[int(robot.n_base_controls):] > 0)
    hits = np.zeros(len(configs), dtype=bool)
    if not np.any(sigma > 0):
        return hits
    for t in range(configs.shape[1] - 1, 0, -1):
        alive = np.flatnonzero(~hits)
        if rigid:
            reference = obstacles.rigid_reference(robot, nominal[t])
            while len(alive):
                first = reference.first_hit(configs[alive, t])
                if first is None:
                    break
                hits[alive[first]] = True
                if stop_at_first:
                    return hits
                alive = np.delete(alive, first)
        else:
            for i in alive:
                if np.any(obstacles.clearance(robot.link_points(configs[i, t])) < 0.0):
                    hits[i] = True
                    if stop_at_first:
                        return hits
    return hits


class _RigidReference:
    """The robot at one arm configuration and a reference base pose, with a lower bound on each of its
    points' clearance (:func:`explore.motion.rigid_clearances`); samples are tested as planar moves
    of it (:func:`explore.motion.rigid_first_hit`).

    Computing the bounds costs a pass over every robot point, so the reference follows the nominal
    base only when the nominal has moved more than half the smallest clearance away from it
    (every point moves at most |dc| + R |dtheta|): the samples' bounds then grow by that move, the
    test stays exact, and a drive far from obstacles needs a handful of passes instead of one per step.
    """

    def __init__(self, robot: Any, config: Array, obstacles: ObstacleField) -> None:
        ref = np.asarray(config, dtype=float).copy()
        self.base = list(robot.base_dofs)
        ref[self.base] = 0.0
        local = np.ascontiguousarray(robot.link_points(ref))
        self.local, self.z = local, np.ascontiguousarray(local[:, 2])
        field, lattice, resolution, grid_lo, grid_hi = obstacles.kernel_field()
        self.grid = (field, lattice, resolution, 0.5 * math.sqrt(3.0) * resolution, grid_lo, grid_hi,
                     obstacles.space_margin)
        self.boxes = (obstacles.lo, obstacles.hi, obstacles.box_margin)
        self.pose: tuple[float, float, float] | None = None

    def follow(self, config: Array) -> None:
        """Move the reference to ``config``'s base pose unless it is still near enough (see the class)."""
        x, y, theta = (float(config[i]) for i in self.base)
        if self.pose is not None:
            moved = math.hypot(x - self.pose[0], y - self.pose[1]) + self.radius * abs(theta - self.pose[2])
            if moved == 0.0 or moved <= 0.5 * self.least:
                return
        self.pose = (x, y, theta)
        self.wx, self.wy, self.clear, self.radius, self.least = rigid_clearances(
            self.local, x, y, theta, *self.boxes, *self.grid)

    def first_hit(self, states: np.ndarray) -> int | None:
        """Index of the first of ``states`` (n, dof) whose robot hits an obstacle, or None."""
        if len(self.local) == 0:
            return None
        hit, _ = rigid_first_hit(self.z, self.wx, self.wy, self.clear, self.radius, self.least, *self.pose,
                                 np.ascontiguousarray(states[:, self.base]), *self.boxes, *self.grid)
        return None if hit < 0 else int(hit)
