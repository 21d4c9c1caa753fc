"""The gtsam pose graph over a scene's views: one Pose3 node per scan, odometry / kinematics factors
(noisy), BetweenFactorPose3 from pairwise ICP (consecutive views and loop closures with enough overlap), Huber or
Cauchy kernels, Levenberg-Marquardt; rebase_scan re-expresses a scan at its corrected pose so the PVS and the surface
can be re-integrated."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import (
    Array,
    Points3,
    Pose,
    invert,
    transform_points,
)
from explore.perception.arrays import as_points, as_pose
from explore.perception.scene_registration import overlap, pyramid, register_pair
from explore.sim import Scan


def _noise(sigmas: Any | None = None, information: Array | None = None, robust: str = "huber", k: float = 1.345):
    import gtsam

    if information is not None:
        base = gtsam.noiseModel.Gaussian.Information(np.asarray(information, dtype=float))
    else:
        base = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float).reshape(6))
    if robust == "none":
        return base
    estimator = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
    if robust not in estimator:
        raise ValueError(f"unknown robust kernel {robust!r} (valid: huber, cauchy, none)")
    return gtsam.noiseModel.Robust.Create(estimator[robust].Create(k), base)


def sigmas6(rotation_rad: float, translation_m: float) -> Array:
    """Diagonal sigmas in gtsam ``Pose3`` tangent order [rx, ry, rz, tx, ty, tz]."""
    return np.array([rotation_rad] * 3 + [translation_m] * 3, dtype=float)


@dataclass
class Edge:
    """A relative-pose measurement ``T = inv(P_target) @ P_source`` between two nodes."""

    target: int
    source: int
    transform: Pose
    kind: str  # "odometry" | "icp" | "loop"
    fitness: float = 1.0


@dataclass
class PoseGraph:
    """Scan poses as a gtsam factor graph, optimised with Levenberg-Marquardt.

    One ``Pose3`` node per scan, initialised from odometry / kinematics. ``add_prior``
    attaches absolute (kinematic) priors, ``add_odometry`` relative odometry factors,
    ``add_registration`` a ``BetweenFactorPose3(X(tgt), X(src), T_icp)`` from pairwise ICP with
    a robust kernel (``robust`` = huber / cauchy / none, threshold ``robust_k`` in whitened
    units).
    """

    robust: str = "huber"
    robust_k: float = 1.345
    initial: list[Pose] = field(default_factory=list)
    edges: list[Edge] = field(default_factory=list)
    error: tuple[float, float] = (math.nan, math.nan)  # graph error before / after the last optimize()
    _factors: list[Any] = field(default_factory=list, repr=False)
    _solution: Any = field(default=None, repr=False)  # (graph, values) of the last optimize()

    def __len__(self) -> int:
        return len(self.initial)

    def add_node(self, pose: Pose, prior_sigmas: Any | None = None) -> int:
        """A node initialised at ``pose``; with ``prior_sigmas`` (6,) also an absolute prior."""
        self.initial.append(as_pose(pose).copy())
        index = len(self.initial) - 1
        if prior_sigmas is not None:
            self.add_prior(index, pose, prior_sigmas)
        return index

    def add_prior(self, index: int, pose: Pose, sigmas: Any) -> None:
        """Absolute pose prior (e.g. from the arm's forward kinematics), Gaussian."""
        import gtsam

        self._check(index)
        key = gtsam.symbol_shorthand.X(index)
        self._factors.append(gtsam.PriorFactorPose3(key, gtsam.Pose3(as_pose(pose)), _noise(sigmas, robust="none")))

    def add_odometry(self, i: int, j: int, relative: Pose, sigmas: Any) -> None:
        """Odometry factor with ``relative = inv(P_i) @ P_j`` (Gaussian: odometry has no outliers)."""
        self._add_between(i, j, relative, _noise(sigmas, robust="none"), "odometry", 1.0)

    def add_registration(
        self, target: int, source: int, transform: Pose, information: Array | None = None,
        sigmas: Any | None = None, kind: str = "icp", fitness: float = 1.0,
    ) -> None:
        """ICP factor ``BetweenFactorPose3(X(target), X(source), T_icp)`` with a robust kernel."""
        if information is None and sigmas is None:
            raise ValueError("a registration edge needs an information matrix or sigmas")
        noise = _noise(sigmas, information, self.robust, self.robust_k)
        self._add_between(target, source, transform, noise, kind, fitness)

    def _check(self, index: int) -> None:
        if not 0 <= index < len(self.initial):
            raise IndexError(f"pose graph has no node {index}")

    def _add_between(self, i: int, j: int, relative: Pose, noise: Any, kind: str, fitness: float) -> None:
        import gtsam

        self._check(i)
        self._check(j)
        x = gtsam.symbol_shorthand.X
        self._factors.append(gtsam.BetweenFactorPose3(x(i), x(j), gtsam.Pose3(as_pose(relative)), noise))
        self.edges.append(Edge(i, j, as_pose(relative).copy(), kind, fitness))

    def optimize(self, max_iterations: int = 100) -> np.ndarray:
        """Corrected world_T_sensor poses (n, 4, 4) after Levenberg-Marquardt.

        LM starts from the odometry and, when the graph was solved before, also from that
        solution (new nodes chained on by odometry, as an incremental solver would); the warm
        start wins if its final error is lower by more than 1 %. From odometry alone LM can
        stall: with a base a metre off no step lowers the error, and the odometry comes back.
        """
        import gtsam

        if not self.initial:
            return np.zeros((0, 4, 4))
        graph = gtsam.NonlinearFactorGraph()
        for factor in self._factors:
            graph.add(factor)
        x = gtsam.symbol_shorthand.X
        starts = [self.initial]
        if self._solution is not None:
            solved = self._solution[1]
            warm = [solved.atPose3(x(i)).matrix() for i in range(len(self.initial)) if solved.exists(x(i))]
            for pose in self.initial[len(warm):]:
                warm.append(warm[-1] @ invert(self.initial[len(warm) - 1]) @ pose)
            starts.append(warm)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(int(max_iterations))
        best = None
        for start in starts:
            values = gtsam.Values()
            for i, pose in enumerate(start):
                values.insert(x(i), gtsam.Pose3(pose))
            result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
            if best is None or graph.error(result) < 0.99 * graph.error(best[1]):
                best = (values, result)
        self.error = (graph.error(best[0]), graph.error(best[1]))
        self._solution = (graph, best[1])
        return np.stack([best[1].atPose3(x(i)).matrix() for i in range(len(self.initial))])

    def sigmas(self, index: int) -> Array:
        """Marginal standard deviations (gtsam ``Pose3`` tangent order, body frame) of node
        ``index`` at the last :meth:`optimize` solution (the graph linearised there)."""
        import gtsam

        self._check(index)
        if self._solution is None:
            raise RuntimeError("optimize() first")
        graph, result = self._solution
        covariance = gtsam.Marginals(graph, result).marginalCovariance(gtsam.symbol_shorthand.X(index))
        return np.sqrt(np.maximum(np.diag(covariance), 0.0))


def rebase_scan(scan: Scan, corrected_pose: Pose) -> Scan:
    """The scan as if taken from ``corrected_pose`` instead of ``scan.sensor_poses[0]``.

    The same rigid correction ``corrected @ inv(sensor_poses[0])`` moves every beam and every
    frame (a scan path keeps its shape), so the PVS and surface can be re-integrated. The inverse is
    the exact one, not the transpose: a scan is re-based after every correction of a run, and with the
    transpose the rounding of its pose's rotation doubled each time (``S' = C Sᵀ S``) until, after some
    50 corrections of a long mobile-base run, its beams overflowed to NaN.
    """
    delta = as_pose(corrected_pose) @ np.linalg.inv(scan.sensor_poses[0])
    r, t = delta[:3, :3], delta[:3, 3]
    return dataclasses.replace(
        scan,
        origins=scan.origins @ r.T + t,
        directions=scan.directions @ r.T,
        sensor_poses=np.einsum("ij,mjk->mik", delta, scan.sensor_poses),
        meta=dict(scan.meta),
        normals=None if scan.normals is None else scan.normals @ r.T,
    )


@dataclass(frozen=True)
class PoseGraphResult:
    """Corrected poses and the edges that produced them."""

    poses: np.ndarray  # (n, 4, 4) world_T_sensor
    initial: np.ndarray  # (n, 4, 4) odometry / kinematics
    edges: list[Edge]
    error_before: float
    error_after: float


def pose_graph_from_scans(
    scans: Sequence[Scan] | Sequence[Points3],
    poses: Sequence[Pose] | np.ndarray | None = None,
    odometry_sigmas: Any = sigmas6(math.radians(2.0), 0.02),
    prior_sigmas: Any | None = None,
    voxel: float = 0.01,
    edge_sigma: float = 0.005,
    min_overlap: float = 0.3,
    loop_closures: bool = True,
    max_loop_closures: int = 50,
    robust: str = "huber",
    robust_k: float = 1.345,
    max_iterations: int = 100,
) -> PoseGraphResult:
    """Correct the poses of a run's scans with a gtsam pose graph.

    ``scans`` are :class:`Scan` objects (points in world coordinates at the believed pose
    ``sensor_poses[0]``) or point arrays already in each sensor frame, with ``poses`` the
    believed world_T_sensor (odometry / kinematics; default: the scans' own poses).
    Consecutive scans are linked by odometry factors (``odometry_sigmas`` per step, node 0
    anchored), or, if ``prior_sigmas`` is given, every node gets an absolute kinematic prior
    instead (an arm's forward kinematics) and by ICP factors (:func:`register_pair`, seeded by odometry); a
    first optimisation then seeds loop-closure ICP between non-consecutive scans whose
    predicted overlap is at least ``min_overlap``. An ICP edge's information is Open3D's
    per-correspondence information over ``edge_sigma**2`` (so unconstrained directions stay
    weak), wrapped in a Huber / Cauchy kernel; edges with fitness below ``min_overlap`` are
    dropped.
    """
    if poses is None:
        if not all(isinstance(s, Scan) for s in scans):
            raise ValueError("poses are required when scans are given as point arrays")
        poses = [s.sensor_poses[0] for s in scans]  # type: ignore[union-attr]
    believed = np.stack([as_pose(p) for p in poses])
    if len(believed) != len(scans):
        raise ValueError("need one pose per scan")
    local: list[Points3] = []
    for scan, pose in zip(scans, believed, strict=True):
        if isinstance(scan, Scan):
            local.append(transform_points(invert(pose), scan.points()))
        else:
            local.append(as_points(scan, "scan points"))
    graph = PoseGraph(robust=robust, robust_k=robust_k)
    anchor = sigmas6(1e-6, 1e-6)
    for i, pose in enumerate(believed):
        graph.add_node(pose, prior_sigmas if prior_sigmas is not None else (anchor if i == 0 else None))
        if i > 0 and prior_sigmas is None:
            graph.add_odometry(i - 1, i, invert(believed[i - 1]) @ pose, odometry_sigmas)
    scale = 1.0 / edge_sigma**2
    scales = (4.0, 2.0, 1.0)
    pyramids = [pyramid(pts, voxel, scales) for pts in local]

    def link(tgt: int, src: int, estimate: np.ndarray, kind: str) -> bool:
        init = invert(estimate[tgt]) @ estimate[src]
        result = register_pair(pyramids[src], pyramids[tgt], init, voxel, scales)
        if result.fitness < min_overlap or result.information is None:
            return False
        graph.add_registration(tgt, src, result.transformation, result.information * scale,
                               kind=kind, fitness=result.fitness)
        return True

    for i in range(1, len(local)):
        link(i - 1, i, believed, "icp")
    poses_out = graph.optimize(max_iterations)
    if loop_closures and len(local) > 2:
        down = [np.asarray(pyr[1].points) for pyr in pyramids]
        candidates = []
        for j in range(len(local)):
            for i in range(j + 2, len(local)):
                rel = invert(poses_out[j]) @ poses_out[i]
                share = overlap(down[i], down[j], rel, 4.0 * voxel)
                if share >= min_overlap:
                    candidates.append((share, j, i))
        for _, j, i in sorted(candidates, reverse=True)[:max_loop_closures]:
            link(j, i, poses_out, "loop")
        poses_out = graph.optimize(max_iterations)
    before, after = graph.error
    return PoseGraphResult(poses_out, believed, list(graph.edges), float(before), float(after))
