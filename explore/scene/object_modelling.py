"""Modelling the unknown objects of a scene (Kriegel thesis Sec. 3.4): each unknown cluster gets its own box and
an NBS modelling session in it, scanning until the termination rule or the scan budget ends it, retrying recognition
during the first scans (the object may be known after all); objects seen from enough views are learnt from them
without modelling scans (Goerner's patrol)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import BUDGET, SUCCESS, Array
from explore.mapping import SurfaceModel
from explore.nbv import ModellingSession, resolve_strategy
from explore.perception import distance_to_model
from explore.scene.motion import target_start
from explore.scene.scene_objects import (
    AMBIGUOUS,
    ENVIRONMENT_MARGIN,
    MODELLED,
    MODELLING,
    NO_PROGRESS,
    NO_VIEW,
    RECOGNISED,
    RECOGNISED_INSTEAD,
    SCAN_BUDGET,
    TARGET,
    UNKNOWN,
    VIEW_BUDGET,
    SceneObject,
    close_holes,
    without_vertices,
)
from explore.scene.viewing import BEYOND
from explore.sim import TriMesh

# a modelled surface point this near a recognised neighbour's model at its pose is the neighbour's (depth noise
# and the pose's error are a few millimetres; the split of touching objects uses 15 mm)
NEIGHBOUR_SURFACE = 0.005

if TYPE_CHECKING:
    from explore.scene.session import SceneSession


class ObjectModelling:
    """The modelling step: model every unknown cluster with the NBS loop in its own box."""

    def __init__(self, scene: SceneSession) -> None:
        self.scene = scene

    # -- modelling unknown objects -------------------------------------------------------------
    def start_modelling(self, obj: SceneObject) -> Any:
        """A ModellingSession over the object's box (the other objects are obstacles)."""
        scene = self.scene
        lo, hi = self._model_box(obj)
        settings = scene.settings
        others = [o.box(0.005) for o in scene.objects
                  if o.id != obj.id and len(o.cluster.points) >= settings.min_points]
        seen = len(obj.cluster.view_ids)  # scene views integrated first count towards the session's scans
        strategy = resolve_strategy(scene.settings.strategy, scene.registry)
        strategy = dataclasses.replace(strategy, termination_params={
            **strategy.termination_params, "coverage": settings.model_coverage, "n_abort": settings.model_scans + seen})
        support_z = lo[2] + ENVIRONMENT_MARGIN  # the box rests on the support: its band is the floor clearance's

        def environment(points: np.ndarray) -> np.ndarray:  # a shelf's lip or post reaching into the box
            return scene.environment_points(points, support_z)

        session = ModellingSession(scene.sim, strategy, scene.registry, seed=scene.settings.seed + 7919 * (obj.id + 1),
                                   max_scans=scene.settings.model_scans + seen, region=(lo, hi), obstacles=others,
                                   fallback_generator=None, standoff=0.0,  # as the scene's views
                                   surface_params={"exclude": environment})
        scene.modelling_sessions[obj.id] = session
        obj.status, obj.modelling_end = MODELLING, ""
        obj.note(f"modelling in box {np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()}")
        for index in obj.cluster.view_ids:  # what the scene already saw of it
            session.integrate_view(scene.views[index].scan, scene.views[index].believed, "scene")
        session.ctx.sensor_pose = scene.mover.believed_pose()
        return session

    def _model_box(self, obj: SceneObject) -> tuple[Array, Array]:
        """The object's box grown by the margins, clipped to the region, resting on the table."""
        scene = self.scene
        lo, hi = obj.box(scene.settings.box_margin, scene.settings.box_top)
        lo = np.maximum(lo, scene.pvs.min_corner)
        hi = np.minimum(hi, scene.pvs.max_corner)
        lo[2] = obj.cluster.points[:, 2].min() - 0.004
        if scene.table is not None:  # the box rests on the support plane
            lo[2] = max(lo[2] - 0.02, float(scene.table.world_T_table[2, 3]) + 0.002)
        return lo, hi

    def model_step(self, obj: SceneObject) -> bool:
        """One NBS iteration for an unknown object; True when its modelling is finished.

        Recognition is re-tried after each of the first ``retry_scans`` scans (the new views
        may show a known object that was hidden); a success ends the modelling.
        """
        scene = self.scene
        session = scene.modelling_sessions.get(obj.id) or self.start_modelling(obj)
        own_scans = obj.modelling_scans
        if own_scans > 0:
            decision = session.terminate()
            if decision.stop:
                end = {SUCCESS: TARGET, BUDGET: SCAN_BUDGET}.get(decision.outcome, NO_PROGRESS)
                return _stopped(obj, end, decision.reason)
            if own_scans >= scene.settings.model_scans:
                return _stopped(obj, SCAN_BUDGET, f"scan budget of {own_scans} used ({decision.reason})")
        session.generate()
        target, configs, candidate = None, None, None
        centre = obj.cluster.centroid
        tries = 0
        while tries < scene.settings.reach_tries:
            candidate = session.select()
            if candidate is None:
                break
            start = target_start(candidate.target)[:3, 3]
            if (not scene.mover.plausible(start, centre) or scene.viewing.already_taken(candidate.target)
                    or not scene.viewing.in_sight(start, obj.cluster.points)):
                continue
            tries += 1
            reached = scene.mover.reach(candidate.target)
            if reached is not None:
                target, configs = reached
                break
        view = None
        if target is not None:
            view = scene.viewing.add_view(target, f"model {obj.id}", obj.id, configs)
        if view is None:  # no reachable NBS candidate: the most novel reachable view of the object, from farther
            candidate = None  # only when no direction is reachable near (a base kept away by the table)
            view = scene.viewing.next_view(obj, f"model {obj.id}") or \
                scene.viewing.next_view(obj, f"model {obj.id}", BEYOND)
        if view is None:
            history = session.ctx.coverage_history
            estimate = f"ĉ_m = {history[-1] if history else 0.0:.3f}"
            if scene.budget_left <= 0:
                return _stopped(obj, VIEW_BUDGET, f"{self._out_of_views()} ({estimate})")
            return _stopped(obj, NO_VIEW, f"no reachable view left ({estimate})")
        obj.modelling_scans += 1
        session.integrate_view(view.scan, view.believed, None if candidate is not None else "scene_view")
        session.ctx.sensor_pose = view.believed.copy()
        scene.segment()
        obj.coverage_estimate = float(session.ctx.coverage_history[-1])
        scene.say(f"object {obj.id}: modelling scan {obj.modelling_scans}, ĉ_m {obj.coverage_estimate:.2f}")
        if obj.modelling_scans <= scene.settings.retry_scans and scene.models:
            scene.recognition.recognise(obj)
            if scene.recognition.validate(obj) in (RECOGNISED, AMBIGUOUS):
                obj.modelling_end = RECOGNISED_INSTEAD
                obj.note(f"recognised as {obj.model} during modelling (scan {obj.modelling_scans})")
                scene.modelling_sessions.pop(obj.id, None)
                return True
            obj.status = MODELLING
        if scene.budget_left <= 0:
            return _stopped(obj, VIEW_BUDGET, self._out_of_views())
        return False

    def _out_of_views(self) -> str:
        return f"the scene's view budget of {self.scene.settings.max_views} is used up"

    def finish_modelling(self, obj: SceneObject) -> str | None:
        """Turn the modelled surface into a database object (iterative recognition); its name."""
        scene = self.scene
        session = scene.modelling_sessions.pop(obj.id, None)
        if session is None or obj.status != MODELLING:
            return None
        mesh = self._without_neighbours(obj, session.surface)
        obj.coverage_estimate = float(session.surface.coverage_area()) if len(mesh.triangles) else 0.0
        if len(mesh.triangles) < 20:
            obj.status = UNKNOWN
            obj.note("modelling gave no mesh")
            return None
        name = scene.database_update.add_to_database(obj, close_holes(mesh), session.n_scans)
        obj.status, obj.model = MODELLED, name
        return name

    def _without_neighbours(self, obj: SceneObject, surface: Any) -> TriMesh:
        """The modelled surface's mesh without what recognised objects beside it explain (a known duck
        touching the box being modelled lies in the box's modelling box); sets ``obj.surface_points``."""
        scene = self.scene
        mesh, points = surface.mesh, np.asarray(surface.points)
        both = np.vstack([mesh.vertices, points])  # one distance query per neighbour for the two
        if len(both) == 0:
            obj.surface_points = points.copy()
            return mesh
        margin = scene.settings.box_margin  # a neighbour is only partly seen: its points near, not on, the surface
        lo, hi = both.min(axis=0) - margin, both.max(axis=0) + margin
        meshes = {m.name: m.mesh for m in scene.models}
        beside = np.zeros(len(both), dtype=bool)
        for other in scene.objects:
            if other is obj or other.status != RECOGNISED or other.model not in meshes or other.pose is None:
                continue
            near_lo, near_hi = other.cluster.aabb
            if np.all(near_hi >= lo) and np.all(near_lo <= hi):
                beside |= distance_to_model(meshes[other.model], other.pose, both) < NEIGHBOUR_SURFACE
        on_mesh, on_points = beside[: len(mesh.vertices)], beside[len(mesh.vertices):]
        obj.surface_points = points[~on_points].copy()
        if not on_mesh.any():
            return mesh
        obj.note(f"{int(on_points.sum())} surface points of recognised objects beside it left out")
        return without_vertices(mesh, on_mesh)

    def learn_from_views(self, obj: SceneObject) -> str | None:
        """Model an unknown object from the views already taken (Görner's multi-view object
        representation, here fused into a mesh); add it to the database; its name."""
        scene = self.scene
        from scipy.spatial import cKDTree

        lo, hi = self._model_box(obj)
        points = obj.sample(0.001)
        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1])) if len(points) > 2 else 0.002
        f = float(np.clip(spacing / 0.002, 1.0, 5.0))  # sparse room-scale views need a coarser surface
        surface = SurfaceModel(lo, hi, point_spacing=0.002 * f, normal_radius=0.006 * f, mesh_radius=0.008 * f,
                               voxel_size=0.0035 * f)
        for index in obj.cluster.view_ids:
            surface.integrate(scene.views[index].scan)
        mesh = self._without_neighbours(obj, surface)
        obj.coverage_estimate = float(surface.coverage_area()) if len(mesh.triangles) else 0.0
        if len(mesh.triangles) < 20:
            obj.note("too few points for a mesh")
            return None
        name = scene.database_update.add_to_database(obj, close_holes(mesh), len(obj.cluster.view_ids))
        obj.status, obj.model = MODELLED, name
        return name

    def model_unknown(self) -> None:
        """Model every unknown object, one after the other."""
        for obj in self.scene.by_status(UNKNOWN):
            finished = False
            while not finished:
                finished = self.model_step(obj)
            if obj.status == MODELLING:
                self.finish_modelling(obj)


def _stopped(obj: SceneObject, end: str, reason: str) -> bool:
    """End the object's modelling: record why (``modelling_end``) and say so; True (finished)."""
    obj.modelling_end = end
    obj.note(f"modelling stopped: {reason}")
    return True
