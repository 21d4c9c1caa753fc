"""Ground-truth evaluation of a scene exploration (metrics only; the session never reads this).

Per ground-truth object: was it recognised (which model, pose error in mm and degrees,
Kriegel's rotation error = angle of R_est R_gt^T; for a robot whose views were corrected by a
pose graph also the error in the robot's map, without its remaining localisation error) or
modelled (coverage c_a of the modelled surface against the object's observable surface), and
after how many views. Per scene: all explained, views, time, travel; the recogniser's wrong
matches and where they were rejected (q_h threshold, colour or PVS votes); precision and recall of the
recognitions.

The true pose of a database model in the current world comes from its first recorded
location (the frame it was added in, in world W0): the body it was made from is moved from
W0 into this world by the rigid transform between the two ground-truth meshes of that body
(same source and size give the same vertices), which is exact for given objects and for
modelled ones up to their reconstruction error.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Pose, invert, kabsch, pose_error, transform_points
from explore.mapping import GroundTruthMetrics, sample_surface
from explore.perception import fuse_poses, icp_local, surface_distances
from explore.sim import Simulation

if TYPE_CHECKING:
    from explore.scene.session import SceneSession
    from explore.sim import TriMesh


@lru_cache(maxsize=8)
def _world_bodies(world: str) -> tuple[tuple[str, np.ndarray], ...]:
    """(name, world vertices) of every object body of a world (loaded once)."""
    with Simulation(world) as sim:
        return tuple((b.name, b.mesh.vertices.copy()) for b in sim.objects())


def model_truth(db: Any, name: str, sim: Any) -> tuple[Pose | None, str | None]:
    """True world_T_model of database object ``name`` in ``sim``'s world, and the body it is."""
    locations = db.locations(name) if name in db else []
    if not locations or not locations[0].get("world"):
        return None, None
    first = locations[0]
    world0, pose0 = first["world"], np.asarray(first["pose"], dtype=float)
    try:
        bodies0 = dict(_world_bodies(world0)) if world0 != sim.spec.name else {
            b.name: b.mesh.vertices for b in sim.objects()}
    except Exception:  # noqa: BLE001 - a world that is gone: no truth, no error
        return None, None
    if not bodies0:
        return None, None
    body_name = name if name in bodies0 else min(
        bodies0, key=lambda n: float(np.linalg.norm(0.5 * (bodies0[n].min(0) + bodies0[n].max(0)) - pose0[:3, 3])))
    here = {b.name: b.mesh.vertices for b in sim.objects()}
    if body_name not in here or len(here[body_name]) != len(bodies0[body_name]):
        return None, body_name
    motion = kabsch(bodies0[body_name], here[body_name])
    return motion @ pose0, body_name


def _body_of(points: np.ndarray, sim: Any, tolerance: float = 0.01) -> tuple[str | None, float]:
    """The ground-truth object most of ``points`` lie on (within ``tolerance``), and that share."""
    import open3d as o3d

    best, share = None, 0.0
    query = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
    for body in sim.objects():
        scene = o3d.t.geometry.RaycastingScene()
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(body.mesh.vertices.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(body.mesh.triangles.astype(np.int32))
        scene.add_triangles(mesh)
        near = float(np.mean(scene.compute_distance(query).numpy() <= tolerance))
        if near > share:
            best, share = body.name, near
    return (best, share) if share >= 0.3 else (None, share)


def _true_points(session: SceneSession, cluster: Any) -> np.ndarray:
    """Where the cluster's points really are: each moved by its view's remaining pose error
    (the body an object is must not depend on how well a drifting base was localised)."""
    points = cluster.points.copy()
    for index in np.unique(cluster.views):
        view = session.views[int(index)]
        mask = cluster.views == index
        points[mask] = transform_points(view.true_pose @ invert(view.recorded), cluster.points[mask])
    return points


def _in_map(session: SceneSession, obj: Any, truth: Pose) -> Pose:
    """The true pose as the robot's map has it: moved by the localisation error of the view
    that saw most of the object (so a pose error against it is the recognition's own, not the
    base's remaining drift)."""
    ids, counts = np.unique(obj.cluster.views, return_counts=True)
    view = session.views[int(ids[np.argmax(counts)])]
    return view.recorded @ invert(view.true_pose) @ truth


def _errors(estimate: Pose | None, truth: Pose | None) -> tuple[float | None, float | None]:
    if estimate is None or truth is None:
        return None, None
    t_err, r_err = pose_error(estimate, truth)
    return 1e3 * t_err, math.degrees(r_err)


#: largest surface displacement (m) under which a turn of a model counts as one of its symmetries:
#: below the depth noise of the scene sensors at their working distance, so no view tells the two apart
SYMMETRY_TOLERANCE = 0.001


def symmetry_of(mesh: TriMesh, turn: Pose, tolerance: float = SYMMETRY_TOLERANCE) -> Pose:
    """The symmetry of a model nearest to ``turn`` (model frame), or the identity if it has none there.

    ``turn`` is refined by ICP of the model's surface onto itself (it converges to the nearest
    turn that maps the surface onto itself, if one is near) and kept if no surface point then
    lies more than ``tolerance`` off the surface. The error against the nearest symmetric pose is
    what BOP's maximum symmetry-aware surface distance (MSSD; Hodaň et al., BOP Challenge 2020,
    Sec. 2.2) measures with hand-listed symmetries; here they are found on the model itself.
    """
    points, normals = sample_surface(mesh, max(mesh.area(), 1e-12) / 3000, seed=2)
    refined = icp_local(points, normals, points, normals, init=turn, radius=0.01, iterations=40,
                        method="point_to_plane").transformation
    if float(surface_distances(mesh, refined, np.eye(4)).max()) <= tolerance:
        return refined
    return np.eye(4)


def _symmetric_errors(mesh: TriMesh, estimate: Pose, truth: Pose) -> tuple[float | None, float | None]:
    """Pose error (mm, degrees) against the nearest pose the model's symmetries make equivalent to the truth."""
    return _errors(estimate, truth @ symmetry_of(mesh, invert(truth) @ estimate))


def evaluate(session: SceneSession) -> dict[str, Any]:
    """metrics.json fields of a scene exploration: ``objects`` (per ground-truth object) and scene numbers."""
    sim, db = session.sim, session.db
    truths: dict[str, tuple[Pose | None, str | None]] = {}

    def truth_of(name: str) -> tuple[Pose | None, str | None]:
        if name not in truths:
            truths[name] = model_truth(db, name, sim)
        return truths[name]

    found = session.candidates()
    owner = {o.id: _body_of(_true_points(session, o.cluster), sim) for o in found}
    rows = []
    wrong = {"proposed": 0, "rejected_q_h": 0, "rejected_colour": 0, "rejected_pvs": 0, "accepted": 0,
             "unverifiable": 0}
    correct_recognitions = recognitions = 0
    for body in sim.objects():
        mine = [o for o in found if owner[o.id][0] == body.name]
        row: dict[str, Any] = {"name": body.name, "known": bool(body.known), "result": "missed", "clusters": len(mine)}
        if mine:
            obj = max(mine, key=lambda o: len(o.cluster.points))
            row.update(result=obj.status, model=obj.model, views=len(obj.cluster.view_ids),
                       recognised_after_views=obj.recognised_after_views, q_h=obj.q_h, v_h=obj.v_h,
                       multi_views=obj.multi_views, modelling_scans=obj.modelling_scans)
            if obj.status == "recognised" and obj.model is not None:
                truth, truth_body = truth_of(obj.model)
                right = truth_body == body.name
                known_truth = truth_body is not None  # else the model's first world cannot be loaded
                recognitions += int(known_truth)
                correct_recognitions += int(right)
                row["correct_model"] = right if known_truth else None
                row["pose_error_mm"], row["pose_error_deg"] = _errors(obj.pose, truth if right else None)
                if right and truth is not None and session.registered:
                    row["map_error_mm"], row["map_error_deg"] = _errors(obj.pose, _in_map(session, obj, truth))
                mesh = next((m.mesh for m in session.models if m.name == obj.model), None)
                if mesh is not None and obj.pose is not None:
                    if right and truth is not None:  # symmetric objects: where the surface is, not the frame
                        row["surface_error_mm"] = 1e3 * float(surface_distances(mesh, obj.pose, truth).mean())
                        row["symmetric_error_mm"], row["symmetric_error_deg"] = _symmetric_errors(
                            mesh, obj.pose, truth)
                        if session.registered:
                            row["symmetric_map_error_mm"], row["symmetric_map_error_deg"] = _symmetric_errors(
                                mesh, obj.pose, _in_map(session, obj, truth))
                    elif known_truth and not right:  # a wrong model: how its surface and the object's overlay
                        row["wrong_model_fit_mm"] = 1e3 * float(max(  # (a small model fits a larger object one way)
                            surface_distances(mesh, obj.pose, np.eye(4), onto=body.mesh).mean(),
                            surface_distances(body.mesh, np.eye(4), obj.pose, onto=mesh).mean()))
                if obj.fused is not None and right:
                    row["fused_error_mm"], row["fused_error_deg"] = _errors(obj.fused.pose, truth)
                    row["fused_members"] = int(len(obj.fused.members))
                    curve = []
                    poses = [h.pose for _, h in obj.view_hypotheses if h.model == obj.model]
                    weights = [h.q_h for _, h in obj.view_hypotheses if h.model == obj.model]
                    for k in range(1, len(poses) + 1):
                        curve.append(_errors(fuse_poses(poses[:k], weights[:k]).pose, truth))
                    row["fusion_curve_mm_deg"] = [[round(t, 3), round(r, 3)] for t, r in curve]
            if obj.status == "modelled":
                points = obj.surface_points if obj.surface_points is not None else np.zeros((0, 3))
                metrics = GroundTruthMetrics(sim, gt_mesh=body.mesh)
                row["coverage"] = float(metrics.coverage(points))
                row["coverage_estimate"] = obj.coverage_estimate
                if session.short_of_target(obj):
                    row["result"] = "partial"
            # wrong matches among the last hypotheses and where they were stopped
            stopped = {(r["model"], round(float(r["q_h"]), 9)): r["by"] for r in obj.rejected}
            accepted_before = wrong["accepted"]
            for h in obj.hypotheses:
                _, h_body = truth_of(h.model)
                if h_body is None:  # no way to tell right from wrong
                    wrong["unverifiable"] += 1
                    continue
                if h_body == body.name:
                    continue
                wrong["proposed"] += 1
                by = stopped.get((h.model, round(float(h.q_h), 9)))
                if by == "q_h":
                    wrong["rejected_q_h"] += 1
                elif by == "colour":
                    wrong["rejected_colour"] += 1
                elif by == "pvs":
                    wrong["rejected_pvs"] += 1
                elif obj.status == "recognised" and obj.model == h.model:
                    wrong["accepted"] += 1
            if row.get("correct_model") is False and wrong["accepted"] == accepted_before:
                wrong["accepted"] += 1  # recognised by agreeing single views (no merged hypothesis passed)
        rows.append(row)
    known_bodies = {truth_of(name)[1] for name in session.known_at_start}
    known_present = sum(1 for b in sim.objects() if b.name in known_bodies)
    summary = session.summary()
    spurious = [o.id for o in found if owner[o.id][0] is None]
    out = {
        "objects": rows,
        "all_explained": bool(summary["all_explained"]),
        "objects_explained": sum(1 for r in rows if r["result"] in ("recognised", "modelled")),
        "objects_total": len(rows),
        "views": summary["views"],
        "scene_elapsed_s": summary["elapsed_s"],
        "travel_m": summary["travel_m"],
        "collisions": summary["collisions"],
        "moves_failed": summary["moves_failed"],
        "wrong_matches": wrong,
        "recognition_precision": correct_recognitions / recognitions if recognitions else math.nan,
        "recognition_recall": correct_recognitions / known_present if known_present else math.nan,
        "spurious_clusters": spurious,
        "added_to_database": summary["added_to_database"],
        "timings_s": summary["timings_s"],
        "objects_found": summary["objects_found"],
        # objects seen with too few points to be objects, and the body they lie on
        "too_small": [{**row, "body": _body_of(_true_points(session, session.object(row["id"]).cluster), sim)[0]}
                      for row in summary["too_small"]],
        "unexplained_surface": summary["unexplained_surface"],  # occupied space no object explains
    }
    if session.registered:
        out["pose_graph"] = pose_graph_errors(session)
    return out


def pose_graph_errors(session: SceneSession) -> dict[str, float]:
    """Scan-pose error (mm, deg) of odometry and of the pose graph against the true poses.

    ``*_mm``/``*_deg``: mean absolute error; ``relative_*``: mean error of every pose relative
    to the first view (the map frame a pose graph anchors; the first view's own odometry
    error cancels).
    """
    views = session.views

    def mean_error(poses: list[Pose], truths: list[Pose]) -> tuple[float, float]:
        errors = np.array([pose_error(p, t) for p, t in zip(poses, truths, strict=True)])
        return float(1e3 * errors[:, 0].mean()), float(np.degrees(errors[:, 1]).mean())

    believed = [v.believed for v in views]
    corrected = [v.recorded for v in views]
    truth = [v.true_pose for v in views]
    out: dict[str, float] = {"views": len(views)}
    out["odometry_mm"], out["odometry_deg"] = mean_error(believed, truth)
    out["corrected_mm"], out["corrected_deg"] = mean_error(corrected, truth)
    if len(views) > 1:
        rel_truth = [invert(truth[0]) @ t for t in truth[1:]]
        out["relative_odometry_mm"], out["relative_odometry_deg"] = mean_error(
            [invert(believed[0]) @ b for b in believed[1:]], rel_truth)
        out["relative_corrected_mm"], out["relative_corrected_deg"] = mean_error(
            [invert(corrected[0]) @ c for c in corrected[1:]], rel_truth)
    return out
