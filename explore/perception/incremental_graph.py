"""The incremental planar pose graph of a mobile base: the graph grows one scan at a time, each view
localised by its planar laser scan against a likelihood field of the known environment."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from explore.core import (
    Array,
    Points3,
    Pose,
    invert,
    pose_error,
    transform_points,
)
from explore.perception.arrays import as_points, as_pose
from explore.perception.icp import IcpResult
from explore.perception.normals import estimate_normals
from explore.perception.plane_icp import plane_icp
from explore.perception.pose_graph import PoseGraph, sigmas6
from explore.perception.scene_registration import overlap, pyramid, register_pair
from explore.sim import Scan


class LikelihoodField:
    """A likelihood field of map points (Thrun's beam-endpoint model, as AMCL's) for
    correlative scan matching (Olson 2009): brute-force search over x, y and yaw of how well a
    view's points land on the map. The field is 3-D: an object standing on a table must not
    score on the table's edge below it, which a 2-D projection lets it do."""

    def __init__(self, points: Points3, resolution: float = 0.02, sigma: float = 0.03, margin: float = 0.2) -> None:
        from scipy.ndimage import distance_transform_edt

        xyz = as_points(points, "map points")
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
              points: int = 400, recentre: int = 0) -> tuple[Pose, float]:
        """Best planar motion (x, y, yaw about the vertical through ``pivot``) of the points
        ``xyz`` onto the map, and its score.

        Coarse to fine: steps of an eighth of the window (at least 4 cm / 1 deg), then 1 cm /
        0.25 deg around the best; at most ``points`` points (evenly picked) are scored. An
        answer beyond the window (the fine step went past its border) is no peak: the true
        motion may lie farther out, so up to ``recentre`` times the window is moved there and
        searched again, and the best score of all the windows wins.
        """
        xyz = np.asarray(xyz, dtype=float)
        xyz = xyz[np.linspace(0, len(xyz) - 1, min(points, len(xyz))).astype(int)]
        pivot = np.asarray(pivot, dtype=float)[:2]
        best = centre = (-1.0, 0.0, np.zeros(2))
        for _ in range(1 + max(0, int(recentre))):
            found = self._search(xyz, pivot, centre[1], centre[2], search, search_yaw)
            if found[0] > best[0]:
                best = found
            if abs(found[1] - centre[1]) <= search_yaw and np.all(np.abs(found[2] - centre[2]) <= search):
                break
            centre = found
        score, yaw, shift = best
        out = _turn_about(np.array([*pivot, 0.0]), np.array([0.0, 0.0, 1.0]), yaw)
        out[:2, 3] += shift
        return out, score

    def _search(self, xyz: Array, pivot: Array, yaw: float, shift: Array, search: float,
                search_yaw: float) -> tuple[float, float, Array]:
        """(score, yaw, shift) of the best motion in one window centred on (``yaw``, ``shift``)."""
        best = (-1.0, float(yaw), np.asarray(shift, dtype=float))
        coarse, coarse_yaw = max(0.04, search / 8.0), max(math.radians(1.0), search_yaw / 8.0)
        for half, step, half_yaw, step_yaw in ((search, coarse, search_yaw, coarse_yaw),
                                               (coarse, 0.01, coarse_yaw, math.radians(0.25))):
            offsets = np.arange(-half, half + 1e-9, step)
            shifts = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2) + best[2]
            grid = np.zeros((len(shifts), 1, 3))
            grid[:, 0, :2] = shifts
            centre_yaw = best[1]
            for turn in centre_yaw + np.arange(-half_yaw, half_yaw + 1e-9, step_yaw):
                c, s = math.cos(turn), math.sin(turn)
                turned = xyz.copy()
                turned[:, :2] = (xyz[:, :2] - pivot) @ np.array([[c, s], [-s, c]]) + pivot
                scores = self.score(turned[None] + grid)
                k = int(np.argmax(scores))
                if scores[k] > best[0]:
                    best = (float(scores[k]), float(turn), shifts[k].copy())
        return best


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
    return _within(as_pose(correction) @ pose, pose, gate)


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
        self.reference = None if reference is None else as_points(reference, "reference")
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
        believed = as_pose(believed)
        points = transform_points(invert(believed), scan.points()) if isinstance(scan, Scan) else as_points(
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
        self.pyramids.append(pyramid(points, self.voxel, self.scales))
        self.lasers.append(None if laser is None else as_points(laser, "laser points"))
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
        views at their estimates near this view's (scan to local map: more structure than one
        neighbour, so a wrong turn rarely fits better; the map is cropped to this view's points'
        box widened by the search, so that the cost follows the views of the neighbourhood, not
        of the whole room).

        Two kinds of start, the best Plane ICP fit wins: ``2 yaw_starts + 1`` turns about the
        view, and a correlative search (:class:`LikelihoodField` of the earlier views) within
        3 sigma of the predicted pose -- the previous node's marginal sigmas grown by
        ``step_sigmas`` (a bumper stop or a long drive can put odometry off by more than the
        turns cover). Identity if the best fit overlaps less than ``min_overlap`` or moves the
        view farther than the searched range.
        """
        src = transform_points(estimate[i], self.points[i])
        tgt = np.vstack([transform_points(estimate[j], self.points[j]) for j in range(i)])
        if len(src) >= 20:  # the local map: earlier points within reach of a searched motion of this view
            reach = 1.2  # the widest translation search (1 m) and the ICP radius
            near = np.all((tgt >= src.min(axis=0) - reach) & (tgt <= src.max(axis=0) + reach), axis=1)
            tgt = tgt[near]
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
