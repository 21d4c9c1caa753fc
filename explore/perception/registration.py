"""Registration: local ICP, Goerner's Plane ICP, a gtsam pose graph and SE(3) pose fusion.

* :func:`icp_local` -- Kriegel's local registration (thesis Sec. 3.2.3): correspondences within
  a 3 mm radius, 2-3 iterations, reject pairs whose normals differ by more than 60 deg (keeps
  thin walls apart); the bottom-scan match uses 20 mm / 40 iterations.
* :func:`plane_icp` -- Goerner's Plane ICP (Alg. 2, "2.5D-ICP"): snap the source onto the
  table plane (z, roll, pitch), then ICP over (x, y, yaw) only, correspondences found in 3-D.
* :class:`PoseGraph` / :func:`pose_graph_from_scans` -- one gtsam ``Pose3`` node per scan,
  odometry / kinematics factors (noisy), ``BetweenFactorPose3`` from pairwise ICP (consecutive
  views and loop closures with enough overlap), Huber or Cauchy kernels, Levenberg-Marquardt.
  :func:`rebase_scan` re-expresses a scan at its corrected pose so the PVS and the surface can
  be re-integrated. :class:`IncrementalPoseGraph` grows the graph one scan at a time.
* :func:`fuse_poses` -- multi-view fusion of recognition hypotheses (thesis Sec. 5.6.2):
  nearest-neighbour pose clustering with a distance and an angle cut-off, then the weighted
  chordal L2 mean of the largest cluster (rotation by SVD projection, Hartley et al. 2013).

Conventions: poses are 4x4 ``world_T_frame``; a registration result ``T`` maps *source*
points into the *target* frame, so for sensor poses ``T = inv(P_tgt) @ P_src`` (STYLE Sec. 2.6).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from explore.core import (
    Array,
    Points3,
    Pose,
    invert,
    kabsch,
    mean_pose,
    open3d_serial,
    pose_error,
    transform_points,
)
from explore.perception.normals import estimate_normals
from explore.sim import Scan

# -- small SE(3) helpers ---------------------------------------------------------------------


def _as_points(points: Any, name: str) -> Points3:
    out = np.asarray(points, dtype=np.float64)
    if out.ndim != 2 or out.shape[1] != 3:
        raise ValueError(f"{name} must be an (n, 3) array, got shape {out.shape}")
    return out


def _as_pose(pose: Any | None) -> Pose:
    if pose is None:
        return np.eye(4)
    out = np.asarray(pose, dtype=np.float64)
    if out.shape != (4, 4) or not np.all(np.isfinite(out)):
        raise ValueError("a pose must be a finite 4x4 matrix")
    return out


def scan_points_and_normals(scan: Scan, radius: float = 0.01) -> tuple[Points3, Points3]:
    """World points of a scan and their normals oriented towards the beam origins."""
    pts = scan.points()
    return pts, estimate_normals(pts, radius, scan.origins[scan.hits])


# -- local ICP (Kriegel Sec. 3.2.3) ------------------------------------------------------------


@dataclass(frozen=True)
class IcpResult:
    """Outcome of a registration: ``transformation`` maps source points into the target frame.

    ``fitness`` is the fraction of source points with an accepted correspondence in the last
    iteration, ``rmse`` their RMS distance (m), ``iterations`` the number of updates done.
    """

    transformation: Pose
    fitness: float
    rmse: float
    correspondences: int
    iterations: int
    information: Array | None = None  # 6x6, [rot, trans] order (gtsam Pose3 tangent)


def _correspond(
    tree: cKDTree,
    src: Points3,
    src_n: Points3 | None,
    tgt_n: Points3 | None,
    radius: float,
    cos_gate: float,
    k: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest *normal-compatible* target point within ``radius`` for each source point.

    Returns (source indices, target indices, distances). Of the ``k`` nearest neighbours
    inside the radius, the closest one whose normal differs by at most the gate is taken
    (Kriegel: reject correspondences with normals more than 60 deg apart, after Pulli).
    """
    dist, idx = tree.query(src, k=k, distance_upper_bound=radius)
    if k == 1:
        dist, idx = dist[:, None], idx[:, None]
    ok = np.isfinite(dist)
    if src_n is not None and tgt_n is not None and cos_gate > -1.0:
        safe = np.where(ok, idx, 0)
        cos = np.einsum("nkj,nj->nk", tgt_n[safe], src_n)
        ok &= cos >= cos_gate
    has = ok.any(axis=1)
    first = np.argmax(ok, axis=1)
    rows = np.nonzero(has)[0]
    return rows, idx[rows, first[rows]], dist[rows, first[rows]]


def _point_to_plane_step(src: Points3, tgt: Points3, tgt_n: Points3) -> Pose:
    """One linearised point-to-plane update (Chen & Medioni; small-angle solve)."""
    a = np.hstack([np.cross(src, tgt_n), tgt_n])
    b = np.einsum("ij,ij->i", tgt - src, tgt_n)
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
    out[:3, 3] = x[3:]
    return out


def icp_local(
    source_points: Points3,
    source_normals: Points3 | None,
    target_points: Points3,
    target_normals: Points3 | None,
    init: Pose | None = None,
    radius: float = 0.003,
    iterations: int = 3,
    normal_gate_deg: float = 60.0,
    method: str = "point_to_point",
    tolerance: float = 1e-7,
    neighbours: int = 8,
    target_tree: cKDTree | None = None,
) -> IcpResult:
    """Local ICP of a scan to a model (Kriegel thesis Sec. 3.2.3).

    Each iteration pairs every transformed source point with the nearest target point within
    ``radius`` whose normal lies within ``normal_gate_deg`` of the source normal, then solves the
    least-squares rigid transform (``"point_to_point"``: SVD, as the thesis; ``"point_to_plane"``:
    linearised Chen-Medioni with the target normals). The thesis stops after 2-3 iterations
    (3 mm, 60 deg) because running to convergence shrank a model by ~4 mm; the bottom-scan
    match uses ``radius=0.02, iterations=40``. Stops early when an update is below
    ``tolerance`` (m and rad). Normals may be None, which disables the gate.

    Returns
    -------
    IcpResult whose ``transformation`` maps the source into the target frame (includes ``init``).
    """
    src0 = _as_points(source_points, "source_points")
    tgt = _as_points(target_points, "target_points")
    src_n0 = None if source_normals is None else _as_points(source_normals, "source_normals")
    tgt_n = None if target_normals is None else _as_points(target_normals, "target_normals")
    if method not in ("point_to_point", "point_to_plane"):
        raise ValueError(f"unknown ICP method {method!r} (valid: point_to_point, point_to_plane)")
    if method == "point_to_plane" and tgt_n is None:
        raise ValueError("point_to_plane ICP needs target normals")
    if not radius > 0.0 or iterations < 0:
        raise ValueError("need radius > 0 and iterations >= 0")
    transform = _as_pose(init).copy()
    if len(src0) == 0 or len(tgt) == 0:
        return IcpResult(transform, 0.0, math.inf, 0, 0)
    tree = target_tree if target_tree is not None else cKDTree(tgt)
    cos_gate = math.cos(math.radians(normal_gate_deg)) if normal_gate_deg < 180.0 else -2.0
    k = max(1, min(int(neighbours), len(tgt)))
    done = 0
    rows = np.zeros(0, dtype=np.int64)
    dist = np.zeros(0)
    for _ in range(iterations):
        src = transform_points(transform, src0)
        src_n = None if src_n0 is None else src_n0 @ transform[:3, :3].T
        rows, cols, dist = _correspond(tree, src, src_n, tgt_n, radius, cos_gate, k)
        if len(rows) < 6:
            break
        if method == "point_to_point":
            step = kabsch(src[rows], tgt[cols])
        else:
            step = _point_to_plane_step(src[rows], tgt[cols], tgt_n[cols])
        transform = step @ transform
        done += 1
        angle = np.linalg.norm(Rotation.from_matrix(step[:3, :3]).as_rotvec())
        if np.linalg.norm(step[:3, 3]) < tolerance and angle < tolerance:
            break
    # final correspondence statistics at the returned transform
    src = transform_points(transform, src0)
    src_n = None if src_n0 is None else src_n0 @ transform[:3, :3].T
    rows, cols, dist = _correspond(tree, src, src_n, tgt_n, radius, cos_gate, k)
    rmse = float(np.sqrt(np.mean(dist**2))) if len(rows) else math.inf
    return IcpResult(transform, len(rows) / len(src0), rmse, len(rows), done)


# -- Plane ICP (Goerner Alg. 2) ----------------------------------------------------------------


def _plane(plane: Any) -> tuple[Array, float]:
    """Unit normal and offset of a plane ``n . x + d = 0`` given as (4,)."""
    v = np.asarray(plane, dtype=float).reshape(4)
    norm = np.linalg.norm(v[:3])
    if not np.all(np.isfinite(v)) or norm < 1e-12:
        raise ValueError("a plane is (a, b, c, d) with a finite, non-zero normal")
    return v[:3] / norm, float(v[3] / norm)


def _minimal_rotation(a: Array, b: Array) -> Array:
    """Smallest rotation taking unit vector ``a`` onto unit vector ``b``."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def plane_frame(plane: Any, near: Array | None = None) -> Pose:
    """A frame whose x-y plane is ``plane`` (z = its normal), origin the projection of ``near``."""
    n, d = _plane(plane)
    near = np.zeros(3) if near is None else np.asarray(near, dtype=float)
    origin = near - (n @ near + d) * n
    x = np.cross([0.0, 1.0, 0.0], n) if abs(n[1]) < 0.9 else np.cross(n, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[:3, :3] = np.column_stack([x, np.cross(n, x), n])
    out[:3, 3] = origin
    return out


def snap_to_plane(source_plane: Any, target_plane: Any) -> Pose:
    """Smallest rigid motion putting ``source_plane`` onto ``target_plane`` (z, roll, pitch only)."""
    ns, ds = _plane(source_plane)
    nt, dt = _plane(target_plane)
    r = _minimal_rotation(ns, nt)
    out = np.eye(4)
    out[:3, :3] = r
    # a point on the rotated source plane is R(-ds ns) = -ds nt; move it onto the target plane
    out[:3, 3] = (ds - dt) * nt
    return out


def as_2d_transform(transform: Pose, plane: Any) -> Pose:
    """Goerner's AS2DTRANSFORM: keep the in-plane translation and the yaw about the plane normal."""
    frame = plane_frame(plane)
    local = invert(frame) @ _as_pose(transform) @ frame
    yaw = math.atan2(local[1, 0], local[0, 0])
    out = np.eye(4)
    out[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    out[:2, 3] = local[:2, 3]
    return frame @ out @ invert(frame)


def _kabsch_2d(src: Array, tgt: Array) -> Pose:
    """Least-squares 2-D rigid transform (x, y, yaw) on the first two coordinates, as a 4x4."""
    mu_s, mu_t = src.mean(axis=0), tgt.mean(axis=0)
    h = (src - mu_s).T @ (tgt - mu_t)
    yaw = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:2, 3] = mu_t - out[:2, :2] @ mu_s
    return out


def plane_icp(
    source: Points3,
    target: Points3,
    plane: Any,
    source_plane: Any | None = None,
    init: Pose | None = None,
    radius: float | Sequence[float] = (0.05, 0.01),
    iterations: int = 30,
    tolerance: float = 1e-7,
) -> IcpResult:
    """Goerner's Plane ICP (Alg. 2, 2.5D-ICP).

    ``plane`` is the table plane (a, b, c, d) in the target frame. If ``source_plane`` (the
    table as detected in the source, source coordinates) is given, the source (after ``init``)
    is first snapped onto ``plane``, which fixes z, roll and pitch; then ICP with 3-D nearest
    neighbours within ``radius`` solves only for the rigid motion in the plane (x, y, yaw about
    the normal; PCL ``TransformationEstimation2D``). ``radius`` may be a coarse-to-fine
    schedule, up to ``iterations`` per stage: Goerner's 5 cm maximum correspondence distance,
    then 1 cm, which removes most of the bias of partially overlapping views.
    """
    src0 = _as_points(source, "source")
    tgt = _as_points(target, "target")
    radii = [float(radius)] if np.isscalar(radius) else [float(r) for r in radius]  # type: ignore[arg-type]
    if not radii or min(radii) <= 0.0:
        raise ValueError("need positive correspondence radii")
    transform = _as_pose(init).copy()
    if source_plane is not None:
        n_s, d_s = _plane(source_plane)
        # the source plane after init, in target coordinates
        r, t = transform[:3, :3], transform[:3, 3]
        n_w = r @ n_s
        moved = np.append(n_w, d_s - n_w @ t)
        transform = snap_to_plane(moved, plane) @ transform
    if len(src0) == 0 or len(tgt) == 0:
        return IcpResult(transform, 0.0, math.inf, 0, 0)
    frame = plane_frame(plane, tgt.mean(axis=0))
    frame_inv = invert(frame)
    tgt_local = transform_points(frame_inv, tgt)
    tree = cKDTree(tgt_local)
    planar = np.eye(4)  # accumulated 2-D motion in the table frame
    src_local0 = transform_points(frame_inv @ transform, src0)
    done = 0
    for stage_radius in radii:
        for _ in range(iterations):
            src_local = transform_points(planar, src_local0)
            dist, idx = tree.query(src_local, distance_upper_bound=stage_radius)
            ok = np.isfinite(dist)
            if ok.sum() < 3:
                break
            step = _kabsch_2d(src_local[ok, :2], tgt_local[idx[ok], :2])
            planar = step @ planar
            done += 1
            if np.linalg.norm(step[:2, 3]) < tolerance and abs(math.atan2(step[1, 0], step[0, 0])) < tolerance:
                break
    transform = frame @ planar @ frame_inv @ transform
    dist, _ = tree.query(transform_points(planar, src_local0), distance_upper_bound=radii[-1])
    ok = np.isfinite(dist)
    rmse = float(np.sqrt(np.mean(dist[ok] ** 2))) if ok.any() else math.inf
    return IcpResult(transform, float(ok.mean()), rmse, int(ok.sum()), done)


# -- pairwise scene registration (pose-graph edges) --------------------------------------------


def _cloud(points: Points3, voxel: float):  # -> open3d.geometry.PointCloud
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(voxel)
    if len(cloud.points) < 3:  # nothing to register (a view that saw none of the scene's surfaces)
        return cloud
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3.0 * voxel, max_nn=30))
    cloud.orient_normals_towards_camera_location(np.zeros(3))  # clouds are in the sensor frame
    return cloud


def _pyramid(points: Points3, voxel: float, scales: Sequence[float]) -> list:
    """Downsampled clouds with normals, one per scale (coarse to fine)."""
    pts = _as_points(points, "points")
    return [_cloud(pts, voxel * s) for s in scales]


def register_pair(
    source: Points3 | list,
    target: Points3 | list,
    init: Pose | None = None,
    voxel: float = 0.01,
    scales: Sequence[float] = (4.0, 2.0, 1.0),
    max_iterations: int = 30,
) -> IcpResult:
    """Coarse-to-fine point-to-plane ICP (Open3D) between two clouds in their sensor frames.

    Each scale downsamples to ``voxel * s`` and pairs points within ``2.5 * voxel * s``
    (``source`` / ``target`` may also be precomputed pyramids from ``_pyramid``). The result
    carries Open3D's 6x6 information matrix at the finest scale ([rot, trans], the gtsam
    ``Pose3`` tangent order) divided by the number of correspondences.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src_pyr = source if isinstance(source, list) else _pyramid(source, voxel, scales)
    tgt_pyr = target if isinstance(target, list) else _pyramid(target, voxel, scales)
    transform = _as_pose(init).copy()
    result = None
    with open3d_serial():  # its threads sum the normal equations in a varying order
        for s, src_c, tgt_c in zip(scales, src_pyr, tgt_pyr, strict=True):
            result = reg.registration_icp(
                src_c, tgt_c, 2.5 * voxel * s, transform, reg.TransformationEstimationPointToPlane(),
                reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=max_iterations),
            )
            transform = np.asarray(result.transformation).copy()
        assert result is not None
        distance = 2.5 * voxel * scales[-1]
        info = np.asarray(reg.get_information_matrix_from_point_clouds(src_pyr[-1], tgt_pyr[-1], distance,
                                                                       transform))
    count = max(len(result.correspondence_set), 1)
    return IcpResult(
        transform, float(result.fitness), float(result.inlier_rmse), len(result.correspondence_set),
        max_iterations * len(scales), info / count,
    )


def overlap(source: Points3, target: Points3, transform: Pose, distance: float) -> float:
    """Fraction of ``source`` points (moved by ``transform``) within ``distance`` of ``target``."""
    if len(source) == 0 or len(target) == 0:
        return 0.0
    dist, _ = cKDTree(target).query(transform_points(transform, source), distance_upper_bound=distance)
    return float(np.isfinite(dist).mean())


# -- gtsam pose graph --------------------------------------------------------------------------


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
        self.initial.append(_as_pose(pose).copy())
        index = len(self.initial) - 1
        if prior_sigmas is not None:
            self.add_prior(index, pose, prior_sigmas)
        return index

    def add_prior(self, index: int, pose: Pose, sigmas: Any) -> None:
        """Absolute pose prior (e.g. from the arm's forward kinematics), Gaussian."""
        import gtsam

        self._check(index)
        key = gtsam.symbol_shorthand.X(index)
        self._factors.append(gtsam.PriorFactorPose3(key, gtsam.Pose3(_as_pose(pose)), _noise(sigmas, robust="none")))

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
        self._factors.append(gtsam.BetweenFactorPose3(x(i), x(j), gtsam.Pose3(_as_pose(relative)), noise))
        self.edges.append(Edge(i, j, _as_pose(relative).copy(), kind, fitness))

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
    frame (a scan path keeps its shape), so the PVS and surface can be re-integrated.
    """
    delta = _as_pose(corrected_pose) @ invert(scan.sensor_poses[0])
    r, t = delta[:3, :3], delta[:3, 3]
    return dataclasses.replace(
        scan,
        origins=scan.origins @ r.T + t,
        directions=scan.directions @ r.T,
        sensor_poses=np.einsum("ij,mjk->mik", delta, scan.sensor_poses),
        meta=dict(scan.meta),
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
    believed = np.stack([_as_pose(p) for p in poses])
    if len(believed) != len(scans):
        raise ValueError("need one pose per scan")
    local: list[Points3] = []
    for scan, pose in zip(scans, believed, strict=True):
        if isinstance(scan, Scan):
            local.append(transform_points(invert(pose), scan.points()))
        else:
            local.append(_as_points(scan, "scan points"))
    graph = PoseGraph(robust=robust, robust_k=robust_k)
    anchor = sigmas6(1e-6, 1e-6)
    for i, pose in enumerate(believed):
        graph.add_node(pose, prior_sigmas if prior_sigmas is not None else (anchor if i == 0 else None))
        if i > 0 and prior_sigmas is None:
            graph.add_odometry(i - 1, i, invert(believed[i - 1]) @ pose, odometry_sigmas)
    scale = 1.0 / edge_sigma**2
    scales = (4.0, 2.0, 1.0)
    pyramids = [_pyramid(pts, voxel, scales) for pts in local]

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


class LikelihoodField:
    """A likelihood field of map points (Thrun's beam-endpoint model, as AMCL's) for
    correlative scan matching (Olson 2009): brute-force search over x, y and yaw of how well a
    view's points land on the map. The field is 3-D: an object standing on a table must not
    score on the table's edge below it, which a 2-D projection lets it do."""

    def __init__(self, points: Points3, resolution: float = 0.02, sigma: float = 0.03, margin: float = 0.2) -> None:
        from scipy.ndimage import distance_transform_edt

        xyz = _as_points(points, "map points")
        self.resolution = float(resolution)
        self.origin = xyz.min(axis=0) - margin
        shape = np.ceil((xyz.max(axis=0) + margin - self.origin) / self.resolution).astype(int) + 1
        occupied = np.zeros(shape, dtype=bool)
        cells = np.floor((xyz - self.origin) / self.resolution).astype(int)
        occupied[cells[:, 0], cells[:, 1], cells[:, 2]] = True
        distance = distance_transform_edt(~occupied) * self.resolution
        self.field = np.exp(-0.5 * (distance / sigma) ** 2).astype(np.float32)

    def score(self, xyz: Array) -> Array:
        """Mean likelihood of point sets (..., n, 3); points off the map count zero."""
        cells = np.floor((xyz - self.origin) / self.resolution).astype(int)
        shape = np.array(self.field.shape)
        inside = np.all((cells >= 0) & (cells < shape), axis=-1)
        cells = np.clip(cells, 0, shape - 1)
        values = self.field[cells[..., 0], cells[..., 1], cells[..., 2]]
        return np.where(inside, values, 0.0).mean(axis=-1)

    def match(self, xyz: Array, pivot: Array, search: float = 0.15, search_yaw: float = math.radians(4.0),
              points: int = 400) -> tuple[Pose, float]:
        """Best planar motion (x, y, yaw about the vertical through ``pivot``) of the points
        ``xyz`` onto the map, and its score.

        Coarse to fine: steps of an eighth of the window (at least 4 cm / 1 deg), then 1 cm /
        0.25 deg around the best; at most ``points`` points (evenly picked) are scored.
        """
        xyz = np.asarray(xyz, dtype=float)
        xyz = xyz[np.linspace(0, len(xyz) - 1, min(points, len(xyz))).astype(int)]
        pivot = np.asarray(pivot, dtype=float)[:2]
        best = (-1.0, 0.0, np.zeros(2))
        coarse, coarse_yaw = max(0.04, search / 8.0), max(math.radians(1.0), search_yaw / 8.0)
        for half, step, half_yaw, step_yaw in ((search, coarse, search_yaw, coarse_yaw),
                                               (coarse, 0.01, coarse_yaw, math.radians(0.25))):
            offsets = np.arange(-half, half + 1e-9, step)
            shifts = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2) + best[2]
            grid = np.zeros((len(shifts), 1, 3))
            grid[:, 0, :2] = shifts
            centre_yaw = best[1]
            for yaw in centre_yaw + np.arange(-half_yaw, half_yaw + 1e-9, step_yaw):
                c, s = math.cos(yaw), math.sin(yaw)
                turned = xyz.copy()
                turned[:, :2] = (xyz[:, :2] - pivot) @ np.array([[c, s], [-s, c]]) + pivot
                scores = self.score(turned[None] + grid)
                k = int(np.argmax(scores))
                if scores[k] > best[0]:
                    best = (float(scores[k]), float(yaw), shifts[k].copy())
        score, yaw, shift = best
        out = _turn_about(np.array([*pivot, 0.0]), np.array([0.0, 0.0, 1.0]), yaw)
        out[:2, 3] += shift
        return out, score


def _turn_about(point: Array, axis: Array, angle: float) -> Pose:
    """Rotation by ``angle`` about the line through ``point`` along ``axis``."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(np.asarray(axis, dtype=float) * angle).as_matrix()
    out[:3, 3] = point - out[:3, :3] @ point
    return out


def _within(transform: Pose, prediction: Pose, gate: tuple[float, float]) -> bool:
    """True if an ICP result stays within ``gate`` (m, rad) of its prediction: registration that
    slid along a symmetric table or a floor is an outlier the odometry rules out."""
    t_err, r_err = pose_error(transform, prediction)
    return t_err <= gate[0] and r_err <= gate[1]


def _moves_within(correction: Pose, pose: Pose, gate: tuple[float, float]) -> bool:
    """True if a world-frame ``correction`` moves ``pose`` by at most ``gate`` (m, rad).

    Measured at the pose, not at the world origin: a turn of a few degrees about a sensor a
    metre from the origin is a large translation of the world frame but none of the sensor.
    """
    return _within(_as_pose(correction) @ pose, pose, gate)


class IncrementalPoseGraph:
    """The pose graph of :func:`pose_graph_from_scans`, grown one scan at a time.

    Each new scan gets an odometry factor to its predecessor (or an absolute kinematic prior
    with ``prior_sigmas``), an ICP factor to its predecessor seeded by the corrected
    predecessor plus the odometry step, and ICP loop closures to at most ``max_links``
    earlier scans whose predicted overlap is at least ``min_overlap``; an ICP result farther
    than ``gate`` (m, rad) from its prediction is dropped (a symmetric table lets ICP slide).
    Levenberg-Marquardt then re-optimises the whole graph (fast: the ICP edges are computed
    once). Used by the scene exploration after every view of a noisy mobile base.

    With ``plane`` (the floor a mobile base drives on, (a, b, c, d) in world coordinates) the
    edges come from Görner's Plane ICP instead: the views' points higher than ``min_height``
    above that plane on upright surfaces, in world coordinates at the estimated poses, are
    aligned in x, y and yaw only (z, roll and pitch of a base on a floor are known), starting
    first against the points of *all* earlier views at their estimates (scan to local map),
    from ``2 yaw_starts + 1`` turns ``yaw_step`` apart about the view (a base's odometry can be
    off by many degrees: Vasquez-Gomez's sigma_omega = 0.28 rad/s gives ~7 deg per move); the
    best fit wins if it moves the view by no more than the gate, which widens to the searched
    range. That estimate (accurate to about a degree) seeds the sequential edge and the loop
    closures, each one Plane ICP run that must stay within ``loop_gate`` of it: an edge that
    converged elsewhere (a far overview and a close view share few edges) would otherwise
    pull a whole chain. Gates are measured at the sensor, not at the world origin.

    With ``reference`` (points on the upright surfaces of the known environment -- walls,
    table edges and legs -- in world coordinates: the map Görner's robot localises in with
    AMCL) every scan whose points lie near the map is also localised in it: a correlative
    search within ``reference_search`` of the graph's estimate on the map's 3-D likelihood
    field (:class:`LikelihoodField`), then Plane ICP against the map points; a fit of at
    least ``min_reference_fit`` adds an absolute pose factor, so the graph is held in the
    world and not only at its first scan. The search is narrow because a table is symmetric
    (its front edge fits its back edge). The default sigmas trust the map's heading (1 deg)
    more than its position (0.1 m): with one table edge in view the match slides along it.
    A view added with a base laser scan (``add(..., laser=...)``) is localised by that scan,
    with ``laser_sigmas`` (0.5 deg, 2 cm: the legs of a table pin its position too).
    """

    def __init__(
        self,
        odometry_sigmas: Any = sigmas6(math.radians(2.0), 0.02),
        prior_sigmas: Any | None = None,
        voxel: float = 0.01,
        edge_sigma: float = 0.005,
        min_overlap: float = 0.3,
        max_links: int = 3,
        robust: str = "huber",
        robust_k: float = 1.345,
        max_iterations: int = 100,
        gate: tuple[float, float] = (0.1, math.radians(10.0)),
        plane: Any | None = None,
        min_height: float = 0.05,
        yaw_starts: int = 3,
        yaw_step: float = math.radians(6.0),
        loop_gate: tuple[float, float] = (0.05, math.radians(3.0)),
        reference: Points3 | None = None,
        reference_sigmas: Any = sigmas6(math.radians(1.0), 0.1),
        min_reference_fit: float = 0.3,
        reference_search: tuple[float, float] = (0.15, math.radians(4.0)),
        laser_sigmas: Any = sigmas6(math.radians(0.5), 0.02),
    ) -> None:
        self.graph = PoseGraph(robust=robust, robust_k=robust_k)
        self.gate = gate
        self.plane = None if plane is None else np.asarray(plane, dtype=float)
        self.min_height = float(min_height)
        self.yaw_starts = int(yaw_starts)
        self.yaw_step = float(yaw_step)
        if self.plane is not None:  # the multi-start search covers larger odometry errors
            self.gate = (max(gate[0], 0.3), max(gate[1], (self.yaw_starts + 1) * self.yaw_step))
        self.edge_sigma = float(edge_sigma)
        self.points: list[Points3] = []  # per node: local points for planar edges
        self.loop_gate = loop_gate
        self.reference = None if reference is None else _as_points(reference, "reference")
        self.field = None if self.reference is None else LikelihoodField(self.reference)
        self.reference_sigmas = reference_sigmas
        self.min_reference_fit = float(min_reference_fit)
        self.reference_search = (float(reference_search[0]), float(reference_search[1]))
        self.laser_sigmas = laser_sigmas
        self.lasers: list[Points3 | None] = []  # per node: base laser points (sensor frame), if any
        self.mapped = False  # the newest node's estimate came from Plane ICP against the earlier views
        self.localised: list[int] = []  # nodes with an absolute factor from the reference
        self.odometry_sigmas = odometry_sigmas
        self.prior_sigmas = prior_sigmas
        self.voxel = float(voxel)
        self.scale = 1.0 / float(edge_sigma) ** 2
        self.min_overlap = float(min_overlap)
        self.max_links = int(max_links)
        self.max_iterations = int(max_iterations)
        self.scales = (4.0, 2.0, 1.0)
        self.believed: list[Pose] = []
        self.pyramids: list[list] = []
        self.poses = np.zeros((0, 4, 4))

    def __len__(self) -> int:
        return len(self.believed)

    def add(self, scan: Scan | Points3, believed: Pose | None = None, odometry_sigmas: Any | None = None,
            laser: Points3 | None = None) -> np.ndarray:
        """Add a scan (world points at ``believed``, default its own pose); all corrected poses.

        ``odometry_sigmas`` (6,) is the uncertainty of the motion since the previous scan
        (default: the graph's ``odometry_sigmas``). ``laser``: the base's planar localisation
        scan taken with it, in the scan's sensor frame; it joins the upright points the views
        are registered with, and alone localises the view in the map (AMCL-like: it sees the
        table legs and walls, which a camera looking down at a table top does not).
        """
        if believed is None:
            if not isinstance(scan, Scan):
                raise ValueError("a believed pose is required for a point array")
            believed = scan.sensor_poses[0]
        believed = _as_pose(believed)
        points = transform_points(invert(believed), scan.points()) if isinstance(scan, Scan) else _as_points(
            scan, "scan points")
        i = len(self.believed)
        anchor = None
        if i == 0:  # the first scan anchors the graph (by the motion since the known start if the map can
            # localise it)
            anchor = sigmas6(1e-6, 1e-6)
            if self.reference is not None:
                anchor = self.odometry_sigmas if odometry_sigmas is None else odometry_sigmas
        self.graph.add_node(believed, self.prior_sigmas if self.prior_sigmas is not None else anchor)
        if i > 0 and self.prior_sigmas is None:
            sigmas = self.odometry_sigmas if odometry_sigmas is None else odometry_sigmas
            self.graph.add_odometry(i - 1, i, invert(self.believed[-1]) @ believed, sigmas)
        self.believed.append(believed)
        self.pyramids.append(_pyramid(points, self.voxel, self.scales))
        self.lasers.append(None if laser is None else _as_points(laser, "laser points"))
        if self.plane is not None:
            upright = self._upright_points(points, believed)
            self.points.append(upright if laser is None else np.vstack([upright, self.lasers[-1]]))
        if i == 0:
            self.poses = self.graph.optimize(self.max_iterations)
            if self._localise(0, self.poses):
                self.poses = self.graph.optimize(self.max_iterations)
            return self.poses
        predicted = np.concatenate([self.poses, (self.poses[-1] @ invert(self.believed[-2]) @ believed)[None]])
        self.mapped = False
        if self.plane is not None:  # multi-start Plane ICP against all earlier views: a start within a degree
            step = self.odometry_sigmas if odometry_sigmas is None else odometry_sigmas
            predicted[i] = self._to_views(i, predicted, step) @ predicted[i]
        self._link(i - 1, i, predicted, "icp")
        if not self.mapped:  # loop closures start from the graph's estimate with the sequential edge
            predicted = self.graph.optimize(self.max_iterations)
        down_i = np.asarray(self.pyramids[i][1].points)
        candidates = []
        for j in range(i - 1):
            rel = invert(predicted[j]) @ predicted[i]
            share = overlap(down_i, np.asarray(self.pyramids[j][1].points), rel, 4.0 * self.voxel)
            if share >= self.min_overlap:
                candidates.append((share, j))
        for _, j in sorted(candidates, reverse=True)[: self.max_links]:
            self._link(j, i, predicted, "loop")
        self.poses = self.graph.optimize(self.max_iterations)
        if self._localise(i, self.poses):
            self.poses = self.graph.optimize(self.max_iterations)
        return self.poses

    def _link(self, target: int, source: int, estimate: np.ndarray, kind: str) -> None:
        if self.plane is not None:
            self._link_planar(target, source, estimate, kind)
            return
        init = invert(estimate[target]) @ estimate[source]
        result = register_pair(self.pyramids[source], self.pyramids[target], init, self.voxel, self.scales)
        if result.fitness >= self.min_overlap and result.information is not None and _within(
                result.transformation, init, self.loop_gate if kind == "loop" else self.gate):
            self.graph.add_registration(target, source, result.transformation, result.information * self.scale,
                                        kind=kind, fitness=result.fitness)

    def _localise(self, i: int, estimate: np.ndarray) -> bool:
        """An absolute factor for node ``i``: correlative search on the map's 3-D likelihood
        field within ``reference_search`` (m, rad) of the graph's estimate, then Plane ICP
        against the map points; True if the fit is good enough to add.

        The window is narrow on purpose: a table is symmetric, and its front edge seen from
        one side fits its back edge as well; the graph's estimate (views registered to each
        other) is good to a few cm, so only the map's correction of the slow drift is searched.
        A view with a base laser scan is matched by that scan alone (it sees the map, legs and
        walls, and no objects) and the factor gets the tighter ``laser_sigmas``.
        """
        laser = self.lasers[i] is not None and len(self.lasers[i]) >= 20
        local = self.lasers[i] if laser else self.points[i]
        if self.reference is None or self.plane is None or self.field is None or len(local) < 20:
            return False
        src = transform_points(estimate[i], local)
        sigmas = self._sigmas(i)  # 3 sigma of the estimate, at least reference_search, at most 0.8 m, 20 deg
        search = (float(np.clip(3.0 * np.linalg.norm(sigmas[3:5]), self.reference_search[0], 0.8)),
                  float(np.clip(3.0 * sigmas[2], self.reference_search[1], math.radians(20.0))))
        near = cKDTree(self.reference).query(src, distance_upper_bound=search[0])[0]
        if np.mean(np.isfinite(near)) < self.min_reference_fit:  # the view shows too little of the map
            return False
        coarse, _ = self.field.match(src, estimate[i][:2, 3], *search)
        result = plane_icp(src, self.reference, self.plane, init=coarse, radius=(0.05, 2.0 * self.voxel))
        if result.fitness < self.min_reference_fit or not _moves_within(
                result.transformation, estimate[i], (search[0] + 0.05, search[1] + math.radians(1.0))):
            return False
        sigmas = self.laser_sigmas if laser else self.reference_sigmas
        self.graph.add_prior(i, result.transformation @ estimate[i], sigmas)
        self.localised.append(i)
        return True

    def _plane_icp(self, src: Points3, tgt: Points3, view: Pose, starts: int,
                   radius: Sequence[float] | None = None) -> IcpResult:
        """Multi-start Plane ICP: ``2 starts + 1`` turns about the view's position, the best fit wins."""
        result = None
        radius = radius or (0.15, 0.05, 2.0 * self.voxel)
        for yaw in (0.0, *[sign * k * self.yaw_step for k in range(1, starts + 1) for sign in (1, -1)]):
            trial = plane_icp(src, tgt, self.plane, init=_turn_about(view[:3, 3], self.plane[:3], yaw),
                              radius=radius)
            if result is None or (trial.fitness, -trial.rmse) > (result.fitness, -result.rmse):
                result = trial
        assert result is not None
        return result

    def _sigmas(self, i: int) -> Array:
        """Node ``i``'s marginal sigmas; if the linearised graph is singular, the gate's third."""
        try:
            return self.graph.sigmas(i)
        except RuntimeError:  # gtsam's IndeterminantLinearSystemException
            return sigmas6(self.gate[1] / 3.0, self.gate[0] / 3.0)

    def _to_views(self, i: int, estimate: np.ndarray, step_sigmas: Any) -> Pose:
        """Correction (world frame) of node ``i``'s estimate against the points of all earlier
        views at their estimates (scan to local map: more structure than one neighbour, so a
        wrong turn rarely fits better).

        Two kinds of start, the best Plane ICP fit wins: ``2 yaw_starts + 1`` turns about the
        view, and a correlative search (:class:`LikelihoodField` of the earlier views) within
        3 sigma of the predicted pose -- the previous node's marginal sigmas grown by
        ``step_sigmas`` (a bumper stop or a long drive can put odometry off by more than the
        turns cover). Identity if the best fit overlaps less than ``min_overlap`` or moves the
        view farther than the searched range.
        """
        src = transform_points(estimate[i], self.points[i])
        tgt = np.vstack([transform_points(estimate[j], self.points[j]) for j in range(i)])
        if len(src) < 20 or len(tgt) < 20:
            return np.eye(4)
        keys = np.floor(tgt / self.voxel).astype(np.int64)
        tgt = tgt[np.unique(keys, axis=0, return_index=True)[1]]
        result = self._plane_icp(src, tgt, estimate[i], self.yaw_starts)
        sigmas = np.sqrt(self._sigmas(i - 1) ** 2 + np.asarray(step_sigmas, dtype=float) ** 2)
        search = (float(np.clip(3.0 * np.linalg.norm(sigmas[3:5]), self.gate[0], 1.0)),
                  float(np.clip(3.0 * sigmas[2], self.gate[1], math.radians(45.0))))
        coarse, _ = LikelihoodField(tgt, resolution=2.0 * self.voxel, sigma=3.0 * self.voxel).match(
            src, estimate[i][:2, 3], *search)
        trial = plane_icp(src, tgt, self.plane, init=coarse, radius=(0.15, 0.05, 2.0 * self.voxel))
        if (trial.fitness, -trial.rmse) > (result.fitness, -result.rmse):
            result = trial
        gate = (search[0] + 0.1, search[1] + math.radians(2.0))
        if result.fitness < self.min_overlap or not _moves_within(result.transformation, estimate[i], gate):
            return np.eye(4)
        self.mapped = True
        return result.transformation

    def _upright_points(self, points: Points3, believed: Pose) -> Points3:
        """The view's points on surfaces standing up from the floor (sensor frame, one per voxel).

        Floors and table tops constrain nothing in x, y, yaw, and their visible patches change
        from view to view, which drags a 2-D ICP: only points whose normal is within 45 deg
        of the floor plane are kept (table edges and legs, object sides, walls).
        """
        world = transform_points(believed, points)
        keep = world @ self.plane[:3] + self.plane[3] > self.min_height
        local = points[keep]
        if len(local) == 0:
            return local
        keys = np.floor(local / self.voxel).astype(np.int64)
        local = local[np.sort(np.unique(keys, axis=0, return_index=True)[1])]
        if len(local) < 10:
            return local
        normals = estimate_normals(local, 3.0 * self.voxel) @ believed[:3, :3].T
        return local[np.abs(normals @ self.plane[:3]) < math.cos(math.radians(45.0))]

    def _link_planar(self, target: int, source: int, estimate: np.ndarray, kind: str) -> None:
        """Plane ICP (x, y, yaw) of the two views' points above the floor, in world coordinates."""
        src = transform_points(estimate[source], self.points[source])
        tgt = transform_points(estimate[target], self.points[target])
        if len(src) < 20 or len(tgt) < 20:
            return
        # edges start from the scan-to-views estimate (or, without one, from odometry, which may be off
        # by many degrees: then the sequential edge searches yaw itself)
        local = kind == "loop" or self.mapped
        result = self._plane_icp(src, tgt, estimate[source], 0 if local else self.yaw_starts)
        gate = self.loop_gate if local else self.gate
        if result.fitness < self.min_overlap or not _moves_within(result.transformation, estimate[source], gate):
            return
        measured = invert(estimate[target]) @ result.transformation @ estimate[source]
        self.graph.add_registration(target, source, measured, sigmas=sigmas6(self.edge_sigma / 0.5, self.edge_sigma),
                                    kind=kind, fitness=result.fitness)


# -- multi-view pose fusion (Kriegel Sec. 5.6.2) -----------------------------------------------


@dataclass(frozen=True)
class FusedPose:
    """Average of the largest pose cluster: ``pose``, member indices and their total weight."""

    pose: Pose
    members: np.ndarray
    weight: float
    clusters: int


def fuse_poses(
    poses: Sequence[Pose] | np.ndarray,
    weights: Sequence[float] | Array | None = None,
    cluster_radius: tuple[float, float] = (0.01, 5.0),
) -> FusedPose:
    """Fuse per-view pose hypotheses of one object on SE(3) (Kriegel thesis Sec. 5.6.2).

    Nearest-neighbour clustering: two poses are neighbours if their translations differ by at
    most ``cluster_radius[0]`` metres *and* their rotations by at most ``cluster_radius[1]``
    degrees; clusters are the connected components. The cluster with the largest total weight
    is averaged: weighted mean of translations and weighted chordal L2 mean of rotations
    (the thesis uses Pham et al. 2011; the chordal mean is its closed-form counterpart).
    """
    stack = np.stack([_as_pose(p) for p in poses]) if len(poses) else np.zeros((0, 4, 4))
    if len(stack) == 0:
        raise ValueError("fuse_poses needs at least one pose")
    w = np.ones(len(stack)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if len(w) != len(stack) or np.any(~np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("need one finite, non-negative weight per pose (not all zero)")
    t = stack[:, :3, 3]
    r = stack[:, :3, :3]
    dt = np.linalg.norm(t[:, None] - t[None], axis=2)
    cos = (np.einsum("aij,bij->ab", r, r) - 1.0) / 2.0  # trace(Ra^T Rb)
    dr = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    adjacency = (dt <= cluster_radius[0]) & (dr <= cluster_radius[1])
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(adjacency, directed=False)
    totals = np.bincount(labels, weights=w, minlength=count)
    best = int(np.argmax(totals))
    members = np.nonzero(labels == best)[0]
    return FusedPose(mean_pose(stack[members], w[members]), members, float(totals[best]), int(count))
