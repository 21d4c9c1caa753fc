"""Taking the views of a scene exploration: overview views, views for an object (nearer, or another direction
when the robot cannot reach), each scan recorded with its believed, corrected and true pose, integrated into
the PVS; the pose graph corrects the poses of a moving base and the views are re-integrated (Kriegel Sec.
5.6.1, Goerner Alg. 2).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Pose, invert, transform_points
from explore.perception import (
    Cluster,
    PoseGraphResult,
    rebase_scan,
)
from explore.scene.motion import Target, target_start
from explore.scene.scene_objects import (
    SceneObject,
    View,
)
from explore.scene.views import as_target, order_by_novelty, overview_targets, viewing_distance, views_around
from explore.sim import Scan

if TYPE_CHECKING:
    from explore.scene.session import SceneSession


def _displacement(scan: Any, pose: Pose, recorded: Pose) -> float:
    """The farthest any return of ``scan`` (recorded at ``recorded``) moves when the view moves to
    ``pose``: the largest shift of the corners of the returns' bounding box (a rigid motion moves
    a box's points no farther than its farthest corner)."""
    points = scan.points()
    if len(points) == 0:
        return float(np.linalg.norm(pose[:3, 3] - recorded[:3, 3]))
    lo, hi = points.min(axis=0), points.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return float(np.linalg.norm(transform_points(pose @ invert(recorded), corners) - corners, axis=1).max())


NEARER = (1.0, 0.75, 0.5)  # the viewing distance's scales a view tries first (an arm reaches steep views closer)
BEYOND = (1.5, 2.0)  # and then, for a base that cannot come near (an object in the middle of a table)
FARTHER = NEARER + BEYOND  # the scales a closer look tries, nearer first


class ViewTaking:
    """The viewing step: take, record and correct the views."""

    def __init__(self, scene: SceneSession) -> None:
        self.scene = scene
        self.stale = False  # earlier views moved by the graph and not yet re-integrated (deferred)

    # -- views -------------------------------------------------------------------------------
    def add_view(self, target: Target, purpose: str, object_id: int | None = None,
                 configs: list | None = None, defer: bool = False) -> View | None:
        """Move there, scan, record the scan at the believed pose, integrate it into the PVS.

        None if the view budget is spent or the robot cannot reach the target. With ``defer``
        (a burst of views, such as a table surround) a pose-graph correction of earlier views
        is not re-integrated at once but by :meth:`settle` after the burst: re-integrating
        every view after every view costs the square of their number.
        """
        scene = self.scene
        if scene.budget_left <= 0:
            return None
        start = time.perf_counter()
        move = scene.mover.move(target, configs)
        scene.timed("motion_s", start)
        if move is None:
            return None
        start = time.perf_counter()
        scan = scene.sim.sensor.acquire(scene.sim, move.target, scene.rng_sensor)
        scan = scene.settings.depth_processing.apply(scan)
        true_pose = target_start(move.target)
        if not np.allclose(move.believed, true_pose, atol=1e-9):
            scan = rebase_scan(scan, move.believed)
        view = View(len(scene.views), scan, move.believed.copy(), true_pose.copy(), purpose, object_id)
        scene.views.append(view)
        scene.pending_views.append(view.index)
        scene.timed("scan_s", start)
        if scene.graph is not None:
            start = time.perf_counter()
            self._apply(scene.graph.add(scan, view.believed, scene.mover.odometry_sigmas(),
                                       scene.mover.laser_points(true_pose, scene.rng_sensor)), defer)
            scene.timed("registration_s", start)
        else:
            start = time.perf_counter()
            scene.pvs.integrate(scan)
            scene.timed("integrate_s", start)
        scene.say(f"view {view.index + 1}: {purpose} ({int(scan.hits.sum())} returns)")
        return view

    def scans(self, view_ids: Sequence[int] | None = None) -> dict[int, Scan]:
        scene = self.scene
        ids = range(len(scene.views)) if view_ids is None else view_ids
        return {int(i): scene.views[int(i)].scan for i in ids}

    def overview(self) -> list[View]:
        """The first views of the scene (world ``overview`` or views of the region); PVS initialised."""
        scene = self.scene
        taken = []
        targets = overview_targets(scene.sim.spec, scene.sim.sensor, scene.sim.robot)
        for index, target in enumerate(targets):
            if scene.budget_left <= 0:
                scene.budget_cuts.append(f"the overview took {index} of its {len(targets)} views")
                break
            view = self.add_view(target, "overview")
            if view is not None:
                taken.append(view)
                if scene.sim.sensor.geometry != "line" and scene.sim.spec.overview is not None:
                    break
        return taken

    def next_view(self, obj: SceneObject, purpose: str, scales: Sequence[float] = NEARER) -> View | None:
        """Take the reachable view of ``obj`` farthest (in angle) from the views that saw it.

        A direction the robot cannot reach at the viewing distance is tried at the other
        ``scales`` of it (by default nearer, 3/4 and 1/2, not below the sensor's near limit: an
        arm reaches a steep view from closer). A view that fails to plan gives way to the next
        one; ``2 * reach_tries`` directions are tried.
        """
        scene = self.scene
        centre = obj.cluster.centroid
        lo, hi = obj.cluster.aabb
        extent = float(np.linalg.norm(hi - lo))
        distance = viewing_distance(scene.sim.sensor, extent)
        near = viewing_distance(scene.sim.sensor, extent, far=0.0)
        ladder = [scale * distance for scale in scales if scale * distance >= near] or [distance]
        height = scene.sim.robot.camera_height
        rings = [views_around(centre, d, camera_height=height)[0] for d in ladder]
        seen = np.array([scene.views[v].believed[:3, 3] for v in obj.cluster.view_ids])
        directions = 0
        for index in order_by_novelty(rings[0], seen, centre):
            eye = rings[0][index][:3, 3]
            if not scene.mover.plausible(eye, centre) or not self.in_sight(eye, obj.cluster.points):
                continue
            directions += 1
            for d, ring in zip(ladder, rings, strict=True):
                target = as_target(scene.sim.sensor, ring[index], obj.cluster.points, d)
                if self.already_taken(target):  # it would show the same surface again
                    continue
                reached = scene.mover.reach(target)
                if reached is not None:
                    view = self.add_view(reached[0], purpose, obj.id, reached[1])
                    if view is not None or scene.budget_left <= 0:
                        return view
                    break
            if directions >= 2 * scene.settings.reach_tries:
                break
        return None

    def in_sight(self, eye: np.ndarray, points: np.ndarray, samples: int = 64, tolerance: float = 0.01) -> bool:
        """Whether at least half of ``points`` (up to ``samples`` of them, evenly picked) lie within the
        sensor's range of ``eye`` and the known environment leaves them in sight: a view from behind a
        shelf's back wall, from below its board or from inside a cabinet sees the furniture, not the
        object; one from 4 m away, with a camera that measures to 2 m, sees nothing."""
        if len(points) == 0:
            return True
        chosen = points[np.linspace(0, len(points) - 1, min(samples, len(points))).astype(int)]
        offsets = chosen - eye
        lengths = np.linalg.norm(offsets, axis=1)
        hit, _, _ = self.scene.sim.environment_caster().cast(np.repeat(eye[None], len(chosen), 0),
                                                            offsets / lengths[:, None])
        seen = (hit >= lengths - tolerance) & (lengths <= self.scene.sim.sensor.max_range)
        return bool(np.mean(seen) >= 0.5)

    def look_closer(self, views: int = 2) -> tuple[int, int]:
        """Views aimed at the objects seen with fewer than ``min_points`` points, up to ``views`` per
        object over the run, segmented as they come, until the object has the points of an object (or
        is merged into another): a small part between others (an upright domino in a grid of objects)
        may show its narrow side to every patrol view. A base that cannot come near (the object in
        the middle of a table) looks from up to twice the viewing distance. (glimpsed objects, views
        taken)."""
        scene = self.scene
        scene.looks_closer = views > 0
        glimpsed = scene.too_small()
        taken = 0
        for obj in glimpsed:
            obj.closer_look_offered = True
            while any(o is obj for o in scene.too_small()) and obj.closer_looks < views and scene.budget_left > 0:
                obj.closer_looks += 1
                if self.next_view(obj, "closer look", FARTHER) is None:
                    obj.closer_look_unreached = scene.budget_left > 0
                    obj.note("no closer view reachable" if obj.closer_look_unreached else "no views left")
                    break
                taken += 1
                scene.segment()
        return len(glimpsed), taken

    def already_taken(self, target: Target, eye_tol: float = 0.02, angle_tol_deg: float = 5.0) -> bool:
        """A view was already taken from (about) ``target``'s pose: in a static scene it would
        show the same surface again (an NBS utility that cannot see why its gain never comes
        would otherwise pick it over and over)."""
        scene = self.scene
        if not scene.views:
            return False
        pose = target_start(target)
        taken = np.array([v.recorded for v in scene.views])
        near = np.linalg.norm(taken[:, :3, 3] - pose[:3, 3], axis=1) <= eye_tol
        aligned = taken[:, :3, 2] @ pose[:3, 2] >= math.cos(math.radians(angle_tol_deg))
        return bool(np.any(near & aligned))

    # -- pose graph and re-integration ---------------------------------------------------------
    def correct_poses(self) -> Any:
        """gtsam pose graph over every view (odometry + ICP factors); re-integrate at the result.

        A session with an incremental graph (a noisy mobile base) has registered and
        localised every view as it came; that graph's solution is the result (a batch graph
        over the same views would lack its multi-start search and its map factors), and the
        PVS is rebuilt only if it moves a view's returns by more than a voxel.
        """
        scene = self.scene
        start = time.perf_counter()
        if scene.graph is not None:
            poses = scene.graph.graph.optimize(scene.graph.max_iterations)
            scene.graph.poses = poses
            if self.stale or self._moves_a_voxel(poses):
                self.reintegrate(list(poses))
            else:
                self._move_views(list(poses))
            scene.timed("registration_s", start)
            error = scene.graph.graph.error
            return PoseGraphResult(poses, np.stack(scene.graph.believed), list(scene.graph.graph.edges), *error)
        believed = [v.believed for v in scene.views]
        if scene.mover.localises:  # the base laser localised every view in the known room: nothing to correct
            poses = np.stack([v.recorded for v in scene.views])
            return PoseGraphResult(poses, np.stack(believed), [], 0.0, 0.0)
        result = scene.registrar.register([rebase_scan(v.scan, v.believed) if v.corrected is not None else v.scan
                                          for v in scene.views], believed)
        self.reintegrate(list(result.poses))
        scene.timed("registration_s", start)
        return result

    def _apply(self, poses: np.ndarray, defer: bool = False) -> None:
        """Take the incremental graph's poses: every view's scan and cluster points move to their
        corrected poses and the new view is integrated at its own. If the correction of an earlier
        view moves some of its returns by more than a PVS voxel, the PVS is rebuilt too (at once,
        or with ``defer`` by the next :meth:`settle`); smaller corrections leave its cells as they
        are within a voxel."""
        scene = self.scene
        far = self._moves_a_voxel(poses[:-1])
        if far and not defer:
            self.reintegrate(list(poses))
            return
        self.stale = self.stale or far
        self._move_views(list(poses))
        scene.pvs.integrate(scene.views[-1].scan)
        scene.registered = True

    def _moves_a_voxel(self, poses: Sequence[Pose]) -> bool:
        """Moving the first ``len(poses)`` views to ``poses`` shifts some return by more than a PVS voxel."""
        scene = self.scene
        return any(_displacement(v.scan, p, v.recorded) > scene.resolution
                   for v, p in zip(scene.views[: len(poses)], poses, strict=True))

    def settle(self) -> None:
        """Re-integrate at the graph's poses if corrections were deferred (``add_view(defer=True)``)."""
        if self.stale and self.scene.graph is not None:
            start = time.perf_counter()
            self.reintegrate(list(self.scene.graph.poses))
            self.scene.timed("registration_s", start)

    def _move_views(self, poses: Sequence[Pose]) -> None:
        """Move every view's scan and the cluster points it gave to ``poses``."""
        scene = self.scene
        deltas = []
        for view, pose in zip(scene.views, poses, strict=True):
            current = view.recorded
            deltas.append(np.asarray(pose) @ invert(current))
            view.scan = rebase_scan(view.scan, pose)
            view.corrected = np.asarray(pose).copy()
        for obj in scene.objects:
            c = obj.cluster
            points, normals = c.points.copy(), c.normals.copy()
            for index in np.unique(c.views):
                mask = c.views == index
                delta = deltas[int(index)]
                points[mask] = transform_points(delta, c.points[mask])
                normals[mask] = c.normals[mask] @ delta[:3, :3].T
            obj.cluster = Cluster(c.id, points, normals, c.views, c.beams, c.up)
            obj._sample = None
        scene.registered = True

    def reintegrate(self, poses: Sequence[Pose]) -> None:
        """Move every view (scan and cluster points) to ``poses`` and rebuild the PVS from scratch."""
        scene = self.scene
        self.stale = False
        self._move_views(poses)
        scene.pvs = scene.new_pvs()
        for view in scene.views:
            scene.pvs.integrate(view.scan)
        scene.mover.pvs = scene.pvs
        scene.registered = True
