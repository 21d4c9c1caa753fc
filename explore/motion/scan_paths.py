"""Scan paths for a robot: a linear Cartesian scan path checked in 10 mm portions with IK and continuity
(Kriegel thesis Sec. 2, motion planning), and the NBS rule for a path through the PVS: through occupied space the
candidate is discarded, through unknown space it is kept for later."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from explore.core import Array, Points3
from explore.motion.problem import MotionProblem, Probability, SpaceFree

if TYPE_CHECKING:
    from explore.motion.robot import Robot
    from explore.sim import ScanPath


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


def _near_occupied(points: Points3, probability: Probability, radius: float, occupied_above: float) -> bool:
    """Whether any point has a place with occupancy above ``occupied_above`` within ``radius``
    (probed on a lattice of radius / 4 in the ball)."""
    if not len(points):
        return False
    steps = np.arange(-4, 5) * (radius / 4.0)
    offsets = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= radius + 1e-12]
    probes = (np.asarray(points, dtype=float)[:, None, :] + offsets[None]).reshape(-1, 3)
    return bool(np.any(np.asarray(probability(probes), dtype=float) > occupied_above))


def classify_blocked(
    robot: Robot,
    configs: np.ndarray,
    probability: Probability,
    free_below: float = 0.05,
    occupied_above: float = 0.75,
    extra_points: Points3 | None = None,
    space_free: SpaceFree | None = None,
    space_margin: float = 0.0,
) -> str:
    """NBS rule for a blocked candidate (Kriegel et al. IROS 2012 Sec. B6).

    The robot's link points at every configuration of the candidate (and ``extra_points``)
    are looked up in the PVS: any point with occupancy above ``occupied_above`` (0.75, the
    thesis' "occupied" class for pose validation) means the candidate runs through occupied
    space -> ``"occupied"`` (discard it); otherwise any point not confidently free
    (p >= ``free_below`` = 0.05) -> ``"unknown"`` (keep it on the stack for later);
    else ``"free"`` (it is not blocked by the PVS). With ``space_free`` (e.g. ``pvs.is_free``)
    only the points it reports blocked are classified (points outside the PVS grid are free); a
    point whose own voxel is free but that is within ``space_margin`` of a non-free voxel
    (``space_free(points, clearance=space_margin)``) counts as occupied if an occupied voxel is
    that near, else as unknown.
    """
    points = [robot.link_points(q) for q in np.atleast_2d(configs)]
    if extra_points is not None:
        points.append(np.asarray(extra_points, dtype=float).reshape(-1, 3))
    stacked = np.vstack(points) if points else np.zeros((0, 3))
    near = np.zeros((0, 3))
    if space_free is not None and len(stacked):
        free = np.asarray(space_free(stacked), dtype=bool)
        if space_margin > 0.0:
            near = stacked[free & ~np.asarray(space_free(stacked, clearance=space_margin), dtype=bool)]
        stacked = stacked[~free]
    prob = np.asarray(probability(stacked), dtype=float) if len(stacked) else np.zeros(0)
    if np.any(prob > occupied_above) or _near_occupied(near, probability, space_margin, occupied_above):
        return BLOCK_OCCUPIED
    if len(near) or np.any(prob >= free_below):
        return BLOCK_UNKNOWN
    return BLOCK_FREE
