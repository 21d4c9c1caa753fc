"""Active scene exploration: segment, recognise, validate, model the unknown, remember.

Kriegel thesis Fig. 3.1 (Sec. 3.1, 3.4, 5.6) with Görner's tabletop segmentation (ch. 3)::

    from explore.perception import ObjectDatabase
    from explore.runtime import Registry
    from explore.scene.session import SceneSession
    from explore.sim import Simulation

    registry = Registry.load()
    with Simulation("tabletop", registry) as sim, ObjectDatabase.open("objects.db") as db:
        db.seed_from_world(sim)                   # the objects marked ``known: true``
        scene = SceneSession(sim, registry, db, seed=0)
        result = scene.run()                      # or call the steps one by one
        print(result["all_explained"], [o["result"] for o in result["objects"]])

The steps, each a method a behaviour can call: :meth:`SceneSession.overview` (first views,
PVS initialisation), :meth:`~SceneSession.segment` (support plane, clusters of every new
view, associated to the scene's objects), :meth:`~SceneSession.recognise` (each cluster
against the database; a hypothesis needs q_h >= the recogniser's ``min_q_h``, Eq. 3.10),
:meth:`~SceneSession.validate` (PVS votes, Eq. 3.11; competing hypotheses make the object
*ambiguous*), :meth:`~SceneSession.multi_view_step` (one more view of an ambiguous object;
per-view hypotheses fused on SE(3), Sec. 5.6.2), :meth:`~SceneSession.model_step` (one NBS
iteration of :class:`~explore.nbv.modelling.ModellingSession` restricted to the object's box,
the other objects as obstacles, recognition re-tried during the first scans) and
:meth:`~SceneSession.add_to_database` (mesh, PPF/VFH descriptors, provenance, location:
iterative recognition). :meth:`~SceneSession.correct_poses` runs the gtsam pose graph over
the views and re-integrates the PVS and the clusters at the corrected poses.

The session never reads the ground truth; :meth:`SceneSession.metrics` does, through
:mod:`explore.scene.metrics`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Points3, Pose, invert, pose_error, transform_points
from explore.mapping import boundary_loops
from explore.perception import (
    ACCEPT_FROM,
    Q_H_MIN,
    Cluster,
    FusedPose,
    Hypothesis,
    Model,
    PoseGraphResult,
    Table,
    fuse_poses,
    rebase_scan,
    rivals,
)
from explore.scene.motion import Mover, Target, target_start
from explore.scene.views import as_target, order_by_novelty, overview_targets, viewing_distance, views_around
from explore.sim import Scan, TriMesh

UNEXPLAINED, RECOGNISED, AMBIGUOUS, UNKNOWN, MODELLING, MODELLED = (
    "unexplained", "recognised", "ambiguous", "unknown", "modelling", "modelled")
EXPLAINED = (RECOGNISED, MODELLED)
FLOOR = (0.0, 0.0, 1.0, 0.0)  # the plane robot bases drive on (world z = 0)


@dataclass
class View:
    """One acquisition: the scan at the believed pose, and why it was taken.

    ``true_pose`` is where the sensor really was (metrics only); ``believed`` the pose the
    scan is recorded at (odometry), ``corrected`` the pose graph's estimate (if run).
    """

    index: int
    scan: Scan
    believed: Pose
    true_pose: Pose
    purpose: str
    object_id: int | None = None
    corrected: Pose | None = None

    @property
    def recorded(self) -> Pose:
        """The pose the scan is recorded at now: the pose graph's estimate, else odometry."""
        return self.corrected if self.corrected is not None else self.believed


@dataclass
class SceneObject:
    """A cluster of the scene and how it is explained."""

    id: int
    cluster: Cluster
    status: str = UNEXPLAINED
    model: str | None = None
    pose: Pose | None = None
    q_h: float = math.nan
    v_h: float = math.nan
    hypotheses: list[Hypothesis] = field(default_factory=list)
    rivals: list[Hypothesis] = field(default_factory=list)
    rejected: list[dict[str, Any]] = field(default_factory=list)
    view_hypotheses: list[tuple[int, Hypothesis]] = field(default_factory=list)
    checked_views: set[tuple[int, str]] = field(default_factory=set)
    fused: FusedPose | None = None
    multi_views: int = 0
    modelling_scans: int = 0
    coverage_estimate: float = math.nan
    surface_points: Points3 | None = None
    recognised_after_views: int | None = None
    events: list[str] = field(default_factory=list)
    _sample: Points3 | None = field(default=None, repr=False)

    @property
    def explained(self) -> bool:
        return self.status in EXPLAINED

    def box(self, margin: float = 0.0, top: float = 0.0) -> tuple[Array, Array]:
        """Axis-aligned box of the points, grown by ``margin`` (and by ``top`` upwards)."""
        lo, hi = self.cluster.aabb
        return lo - [margin, margin, 0.0], hi + [margin, margin, margin + top]

    def sample(self, voxel: float = 0.005) -> Points3:
        """The points thinned to one per ``voxel`` (for association tests)."""
        if self._sample is None:
            keys = np.floor(self.cluster.points / voxel).astype(np.int64)
            _, first = np.unique(keys, axis=0, return_index=True)
            self._sample = self.cluster.points[np.sort(first)]
        return self._sample

    def extend(self, part: Cluster) -> None:
        c = self.cluster
        self.cluster = Cluster(c.id, np.vstack([c.points, part.points]), np.vstack([c.normals, part.normals]),
                               np.concatenate([c.views, part.views]), np.concatenate([c.beams, part.beams]), c.up)
        self._sample = None

    def note(self, text: str) -> None:
        self.events.append(text)


def close_holes(mesh: TriMesh) -> TriMesh:
    """Fill every boundary loop with a fan from its centroid (the open bottom becomes a cap).

    Each fan triangle runs against the direction of its border half-edge, so the filled mesh
    keeps the orientation of the surface it closes.
    """
    loops = boundary_loops(mesh.triangles, closed_only=True)
    if not loops:
        return mesh
    vertices = [mesh.vertices]
    triangles = [mesh.triangles]
    next_index = len(mesh.vertices)
    for loop in loops:
        centre = mesh.vertices[loop].mean(axis=0)
        a, b = loop, np.roll(loop, -1)
        triangles.append(np.column_stack([b, a, np.full(len(loop), next_index)]))
        vertices.append(centre[None])
        next_index += 1
    return TriMesh(np.vstack(vertices), np.vstack(triangles).astype(np.int32))


class SceneSession:
    """Scene exploration on a simulation with a robot, a sensor and an object database.

    Parameters
    ----------
    sim : Simulation with robot and sensor attached
    registry : the plugin registry
    database : an open :class:`~explore.perception.database.ObjectDatabase`
    segmenter, recognizer, validator, registrar : plugin names or (name, params)
    strategy : NBV strategy for modelling unknown objects (name, (name, params) or Strategy)
    seed : seeds the sensor noise, the execution noise and random choices
    resolution : scene PVS voxel edge (default: 5 mm, coarser for large regions: at most 4 M voxels)
    max_views : view budget of the whole exploration
    recognition_views : recognise an object from the points of at most this many of its views
        (those with the most points; render-and-compare costs one ray cast per view)
    model_scans : scan budget per modelled object; ``model_coverage`` stops earlier at ĉ_m
    retry_scans : re-try recognition after each of the first ``retry_scans`` modelling scans
    multi_view_views : view budget per ambiguous object; ``multi_view_agree`` per-view
        hypotheses must agree (fused cluster) before an object counts as recognised
    noise : execute motions with the robot's positioning noise
    planner : motion planner plugin name (robots other than the free flyer)
    run_name : recorded as the provenance of modelled objects
    associate_tolerance : a new view's cluster joins an object when its points come this close
    box_margin : the modelling box around an object's points (and ``box_top`` above them)
    min_points : clusters with fewer points (over all views) are noise, not objects
    reach_tries : NBS candidates tried for reachability (IK) per modelling step before the most
        novel reachable view of the object is taken instead
    split_distance, split_share : points of a recognised object farther than ``split_distance``
        from the model, if at least ``split_share`` of them, are another object touching it
    register : grow a pose graph with every view when the robot has a noisy base (and correct
        the views, the clusters and the PVS with it)
    progress : called with a line of text after every step (long work shows progress)
    """

    def __init__(
        self,
        sim: Any,
        registry: Any,
        database: Any,
        *,
        segmenter: Any = ("plane_clusters", {"scale": "table"}),
        recognizer: Any = "ppf",
        validator: Any = "pvs_votes",
        registrar: Any = "pose_graph",
        strategy: Any = ("ig_quality/bs_hr", {}),
        seed: int = 0,
        resolution: float | None = None,
        max_views: int = 80,
        recognition_views: int = 6,
        model_scans: int = 12,
        model_coverage: float = 0.75,
        retry_scans: int = 3,
        multi_view_views: int = 10,
        multi_view_agree: int = 2,
        noise: bool = True,
        planner: str | None = None,
        run_name: str = "run",
        associate_tolerance: float = 0.01,
        box_margin: float = 0.03,
        box_top: float = 0.04,
        min_points: int = 60,
        reach_tries: int = 4,
        split_distance: float = 0.015,
        split_share: float = 0.1,
        register: bool = True,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        from explore.mapping import PVS

        self.sim = sim
        self.registry = registry
        self.db = database
        self.segmenter = _plugin(registry, "segmenter", segmenter)
        self.recognizer = _plugin(registry, "recognizer", recognizer)
        self.validator = _plugin(registry, "pose_validator", validator)
        self.registrar = _plugin(registry, "registrar", registrar)
        self.strategy = strategy
        self.seed = int(seed)
        self.max_views = int(max_views)
        self.recognition_views = int(recognition_views)
        self.model_scans = int(model_scans)
        self.model_coverage = float(model_coverage)
        self.retry_scans = int(retry_scans)
        self.multi_view_views = int(multi_view_views)
        self.multi_view_agree = int(multi_view_agree)
        self.run_name = run_name
        self.associate_tolerance = float(associate_tolerance)
        self.box_margin = float(box_margin)
        self.box_top = float(box_top)
        self.min_points = int(min_points)
        self.split_distance = float(split_distance)
        self.reach_tries = int(reach_tries)
        self.split_share = float(split_share)
        self.progress = progress
        lo = np.asarray(sim.spec.region_min, dtype=float)
        hi = np.asarray(sim.spec.region_max, dtype=float)
        if resolution is None:
            resolution = max(0.005, float(np.prod(hi - lo) / 4e6) ** (1.0 / 3.0))
        self.resolution = float(resolution)
        self.pvs = PVS.for_region(lo, hi, self.resolution)
        rng = np.random.default_rng(self.seed)
        self.rng_sensor = np.random.default_rng(rng.integers(2**63))
        self.mover = Mover(sim, registry, planner, noise, seed=int(rng.integers(2**31)))
        self.mover.pvs = self.pvs
        self.graph = None  # incremental pose graph, for a robot whose base odometry drifts
        if register and self.mover.base_dofs and noise and hasattr(self.registrar, "incremental"):
            # a base on the floor: Plane ICP between views, each view localised in the known environment
            self.graph = self.registrar.incremental(plane=FLOOR, reference=environment_reference(sim))
        self.views: list[View] = []
        self.objects: list[SceneObject] = []
        self.table: Table | None = None
        self._pending: list[int] = []
        self._models: list[Model] | None = None
        self._vertices: dict[str, Points3] = {}
        self._modelling: dict[int, Any] = {}
        self.added: list[str] = []
        self.known_at_start = list(database.names())
        self.registered = False
        self.started = time.perf_counter()
        self.timings: dict[str, float] = {}

    # -- bookkeeping -------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _timed(self, key: str, start: float) -> None:
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - start

    @property
    def models(self) -> list[Model]:
        """The database objects (meshes + stored descriptors), reloaded after an update."""
        if self._models is None:
            self._models = self.db.models()
            self._vertices = {m.name: m.mesh.vertices for m in self._models}
        return self._models

    def object(self, object_id: int) -> SceneObject:
        return next(o for o in self.objects if o.id == object_id)

    def by_status(self, *statuses: str) -> list[SceneObject]:
        return [o for o in self.objects if o.status in statuses]

    @property
    def all_explained(self) -> bool:
        """True when every object is recognised or modelled (and there is at least one view)."""
        return bool(self.views) and all(o.explained for o in self.candidates())

    @property
    def budget_left(self) -> int:
        return self.max_views - len(self.views)

    # -- views -------------------------------------------------------------------------------
    def add_view(self, target: Target, purpose: str, object_id: int | None = None,
                 configs: list | None = None) -> View | None:
        """Move there, scan, record the scan at the believed pose, integrate it into the PVS.

        None if the view budget is spent or the robot cannot reach the target.
        """
        if self.budget_left <= 0:
            return None
        start = time.perf_counter()
        move = self.mover.move(target, configs)
        self._timed("motion_s", start)
        if move is None:
            return None
        start = time.perf_counter()
        scan = self.sim.sensor.acquire(self.sim, move.target, self.rng_sensor)
        true_pose = target_start(move.target)
        if not np.allclose(move.believed, true_pose, atol=1e-9):
            scan = rebase_scan(scan, move.believed)
        view = View(len(self.views), scan, move.believed.copy(), true_pose.copy(), purpose, object_id)
        self.views.append(view)
        self._pending.append(view.index)
        self._timed("scan_s", start)
        if self.graph is not None:
            start = time.perf_counter()
            self._apply(self.graph.add(scan, view.believed, self.mover.odometry_sigmas(),
                                       self.mover.laser_points(true_pose, self.rng_sensor)))
            self._timed("registration_s", start)
        else:
            self.pvs.integrate(scan)
        self._say(f"view {view.index + 1}: {purpose} ({int(scan.hits.sum())} returns)")
        return view

    def scans(self, view_ids: Sequence[int] | None = None) -> dict[int, Scan]:
        ids = range(len(self.views)) if view_ids is None else view_ids
        return {int(i): self.views[int(i)].scan for i in ids}

    def overview(self) -> list[View]:
        """The first views of the scene (world ``overview`` or views of the region); PVS initialised."""
        taken = []
        for target in overview_targets(self.sim.spec, self.sim.sensor, self.sim.robot):
            view = self.add_view(target, "overview")
            if view is not None:
                taken.append(view)
                if self.sim.sensor.geometry != "line" and self.sim.spec.overview is not None:
                    break
        return taken

    # -- segmentation and association ------------------------------------------------------------
    def segment(self) -> list[SceneObject]:
        """Segment the views taken since the last call and attach their clusters to objects."""
        start = time.perf_counter()
        lo, hi = np.asarray(self.sim.spec.region_min), np.asarray(self.sim.spec.region_max)
        for index in self._pending:
            result = self.segmenter.segment(self.views[index].scan, view_ids=[index], table=self.table)
            if result.table is not None:
                self.table = result.table
            for cluster in result.clusters:
                centre = cluster.centroid
                if np.all(centre >= lo) and np.all(centre <= hi):
                    self._associate(cluster)
        self._pending = []
        self._merge_fragments()
        self._timed("segment_s", start)
        return self.candidates()

    def candidates(self) -> list[SceneObject]:
        """The objects large enough to be explained (smaller clusters are noise)."""
        return [o for o in self.objects if len(o.cluster.points) >= self.min_points]

    def _near_share(self, cluster: Cluster, obj: SceneObject) -> np.ndarray:
        from scipy.spatial import cKDTree

        lo, hi = obj.cluster.aabb
        tol = self.associate_tolerance
        if np.any(cluster.points.min(axis=0) > hi + tol) or np.any(cluster.points.max(axis=0) < lo - tol):
            return np.full(len(cluster.points), np.inf)
        dist, _ = cKDTree(obj.sample()).query(cluster.points, distance_upper_bound=tol)
        return dist

    def _associate(self, cluster: Cluster) -> None:
        """Join a view's cluster to the objects it overlaps (split among several), else a new object."""
        candidates = [o for o in self.objects]
        distances = [self._near_share(cluster, o) for o in candidates]
        near = [(o, d) for o, d in zip(candidates, distances, strict=True) if np.mean(np.isfinite(d)) >= 0.1]
        if not near:
            new_id = max((o.id for o in self.objects), default=-1) + 1
            self.objects.append(SceneObject(new_id, dataclasses.replace(cluster, id=new_id)))
            return
        if len(near) == 1:
            near[0][0].extend(cluster)
            return
        stacked = np.stack([d for _, d in near])
        owner = np.argmin(stacked, axis=0)
        for k, (obj, _) in enumerate(near):
            mask = owner == k
            if mask.any():
                obj.extend(cluster.subset(mask))

    def _merge_fragments(self) -> None:
        """Merge objects not yet explained whose points touch (one object seen in pieces)."""
        from scipy.spatial import cKDTree

        tolerance = float(getattr(self.segmenter, "cluster_tolerance", 0.02))
        merged = True
        while merged:
            merged = False
            open_objects = [o for o in self.objects if not o.explained and o.status != MODELLING]
            for i, a in enumerate(open_objects):
                for b in open_objects[i + 1 :]:
                    dist, _ = cKDTree(a.sample()).query(b.sample(), distance_upper_bound=tolerance)
                    if np.any(np.isfinite(dist)):
                        a.extend(b.cluster)
                        a.status = UNEXPLAINED
                        a.note(f"merged with object {b.id}")
                        self.objects.remove(b)
                        merged = True
                        break
                if merged:
                    break

    # -- recognition and validation -------------------------------------------------------------
    def recognition_cluster(self, obj: SceneObject) -> Cluster:
        """The object's points from its ``recognition_views`` views with the most points."""
        ids, counts = np.unique(obj.cluster.views, return_counts=True)
        if len(ids) <= self.recognition_views:
            return obj.cluster
        keep = ids[np.argsort(-counts, kind="stable")[: self.recognition_views]]
        return obj.cluster.subset(np.isin(obj.cluster.views, keep))

    def recognise(self, obj: SceneObject) -> list[Hypothesis]:
        """Hypotheses for the object's cluster (its best-covered views) from every database model."""
        start = time.perf_counter()
        models = self.models
        cluster = self.recognition_cluster(obj)
        scans = self.scans(cluster.view_ids)
        obj.hypotheses = self.recognizer.recognize(cluster, models, scans) if models else []
        self._timed("recognise_s", start)
        return obj.hypotheses

    @property
    def min_q_h(self) -> float:
        """The recogniser's q_h threshold (Eq. 3.10)."""
        return float(getattr(self.recognizer, "min_q_h", Q_H_MIN))

    @property
    def validator_threshold(self) -> float:
        """The pose validator's v_h threshold (Eq. 3.11)."""
        return float(getattr(self.validator, "threshold", ACCEPT_FROM))

    def _validate_one(self, hypothesis: Hypothesis) -> Hypothesis:
        result = self.validator.validate(self.pvs, self._vertices[hypothesis.model], hypothesis.pose)
        return dataclasses.replace(hypothesis, diagnostics={**hypothesis.diagnostics, "v_h": result.score,
                                                              "v_accepted": result.accepted, "v_margin": result.margin})

    def validate(self, obj: SceneObject) -> str:
        """Apply the q_h threshold (Eq. 3.10) and the PVS votes (Eq. 3.11); set the object's status.

        recognised: the best surviving hypothesis has no rival and the per-view hypotheses of at
        least ``multi_view_agree`` views agree with it (fused on SE(3)); ambiguous: another
        model or pose survives nearly as well, or no second view confirms it yet (one view of a
        mug whose handle is hidden fits any rotation); unknown: nothing survives (a wrong match
        is rejected here).
        """
        start = time.perf_counter()
        obj.rejected = []
        survivors = []
        passed = {id(h) for h in self.recognizer.accept(obj.hypotheses)}
        min_q_h = self.min_q_h
        # best q_h first; equal q_h keep the recogniser's order (a stable sort)
        for h in sorted(obj.hypotheses, key=lambda h: -(h.q_h if math.isfinite(h.q_h) else -1.0)):
            if id(h) not in passed:
                obj.rejected.append({"model": h.model, "q_h": h.q_h, "by": "q_h", "margin": h.q_h - min_q_h})
                continue
            checked = self._validate_one(h)
            if checked.diagnostics["v_accepted"]:
                survivors.append(checked)
            else:
                obj.rejected.append({"model": h.model, "q_h": h.q_h, "v_h": checked.diagnostics["v_h"], "by": "pvs",
                                     "margin": checked.diagnostics["v_margin"]})
        self._timed("validate_s", start)
        if not survivors:
            obj.status, obj.model, obj.pose, obj.rivals = UNKNOWN, None, None, []
            self._recognise_from_views(obj)
            return obj.status
        best = survivors[0]
        obj.model, obj.pose, obj.q_h, obj.v_h = best.model, best.pose, best.q_h, best.diagnostics["v_h"]
        obj.rivals = rivals(survivors, meshes={m.name: m.mesh for m in self.models})
        if obj.rivals:
            obj.status = AMBIGUOUS
            return obj.status
        if self._split_residual(obj) is not None:  # the rest was another object: recognise what is left
            self.recognise(obj)
            return self.validate(obj)
        self.collect_view_hypotheses(obj)
        self.fuse(obj)
        if self._fusion_agrees(obj):
            obj.status = RECOGNISED
            if obj.recognised_after_views is None:
                obj.recognised_after_views = len(self.views)
        else:  # not yet confirmed by a second view (Kriegel Sec. 5.6.2): take more views
            obj.status = AMBIGUOUS
        return obj.status

    def _recognise_from_views(self, obj: SceneObject) -> bool:
        """Multi-view recognition (Kriegel Sec. 5.6.2) when the merged views fail q_h.

        The views of a noisy base are registered to a few millimetres, and at 1-1.5 m that
        residual breaks the merged render-and-compare (Eq. 3.10) though each view alone fits.
        Every model the merged views proposed is recognised in each recognition view alone
        (q_h and the PVS votes per view); if at least
        ``multi_view_agree`` of these poses agree (:func:`fuse_poses`) and the PVS accepts the
        fused pose, the object is recognised there.
        """
        best: tuple[str, FusedPose, list[Hypothesis]] | None = None
        for name in sorted({h.model for h in obj.hypotheses}):
            for view in self.recognition_cluster(obj).view_ids:
                self._check_view(obj, int(view), [name])
            mine = [h for _, h in obj.view_hypotheses if h.model == name]
            if len(mine) < self.multi_view_agree:
                continue
            fused = fuse_poses([h.pose for h in mine], [h.q_h for h in mine])
            if len(fused.members) >= self.multi_view_agree and (best is None or fused.weight > best[1].weight):
                best = (name, fused, mine)
        if best is None:
            return False
        name, fused, mine = best
        check = self.validator.validate(self.pvs, self._vertices[name], fused.pose)
        if not check.accepted:
            obj.note(f"{len(fused.members)} views agree on {name}, but the PVS rejects the fused pose")
            return False
        obj.model, obj.pose, obj.fused, obj.status = name, fused.pose, fused, RECOGNISED
        obj.q_h = float(np.mean([mine[i].q_h for i in fused.members]))
        obj.v_h = float(check.score)
        obj.note(f"recognised as {name} by {len(fused.members)} agreeing views (no merged hypothesis survived)")
        if obj.recognised_after_views is None:
            obj.recognised_after_views = len(self.views)
        return True

    def _split_residual(self, obj: SceneObject) -> SceneObject | None:
        """Points the recognised model does not explain (an object touching it) become a new object.

        A share of at least ``split_share`` of the cluster (and ``min_points`` points) farther
        than ``split_distance`` from the model surface at the pose is split off.
        """
        import open3d as o3d

        mesh = next(m.mesh for m in self.models if m.name == obj.model)
        scene = o3d.t.geometry.RaycastingScene()
        tmesh = o3d.t.geometry.TriangleMesh()
        tmesh.vertex.positions = o3d.core.Tensor(mesh.vertices.astype(np.float32))
        tmesh.triangle.indices = o3d.core.Tensor(mesh.triangles.astype(np.int32))
        scene.add_triangles(tmesh)
        local = transform_points(invert(obj.pose), obj.cluster.points).astype(np.float32)
        far = scene.compute_distance(o3d.core.Tensor(local)).numpy() > self.split_distance
        if far.sum() < self.min_points or far.mean() < self.split_share:
            return None
        new_id = max(o.id for o in self.objects) + 1
        rest = SceneObject(new_id, dataclasses.replace(obj.cluster.subset(far), id=new_id))
        obj.cluster = obj.cluster.subset(~far)
        obj._sample = None
        obj.view_hypotheses, obj.checked_views = [], set()
        obj.note(f"{int(far.sum())} points not explained by {obj.model}: split off as object {new_id}")
        rest.note(f"split off object {obj.id}")
        self.objects.append(rest)
        return rest

    def recognise_all(self) -> dict[int, str]:
        """Recognise and validate every object that is not explained or being modelled."""
        out = {}
        for obj in self.candidates():
            if obj.status in (UNEXPLAINED, UNKNOWN, AMBIGUOUS):
                self.recognise(obj)
                out[obj.id] = self.validate(obj)
                self._say(f"object {obj.id}: {obj.status}" + (f" as {obj.model} (q_h {obj.q_h:.2f}, v_h "
                                                              f"{obj.v_h:.2f})" if obj.model else ""))
        return out

    # -- multi-view recognition (Kriegel Sec. 5.6.2) ---------------------------------------------
    def view_hypothesis(self, obj: SceneObject, view: int, names: Sequence[str] | None = None) -> Hypothesis | None:
        """Recognise the object from the points of one view only; validated, or None."""
        part = obj.cluster.only_view(view)
        if len(part.points) < 10:
            return None
        models = [m for m in self.models if names is None or m.name in names]
        hypotheses = self.recognizer.recognize(part, models, {view: self.views[view].scan})
        for h in self.recognizer.accept(hypotheses):
            checked = self._validate_one(h)
            if checked.diagnostics["v_accepted"]:
                return checked
        return None

    def _fusion_agrees(self, obj: SceneObject) -> bool:
        """The fused per-view poses have enough members and agree with the merged recognition."""
        fused = obj.fused
        if fused is None or obj.pose is None or len(fused.members) < self.multi_view_agree:
            return False
        t_err, r_err = pose_error(fused.pose, obj.pose)
        return t_err <= 0.01 and math.degrees(r_err) <= 5.0

    def fuse(self, obj: SceneObject) -> FusedPose | None:
        """Fuse the per-view hypotheses of the object's current model (weights q_h)."""
        poses = [h.pose for _, h in obj.view_hypotheses if h.model == obj.model]
        weights = [h.q_h for _, h in obj.view_hypotheses if h.model == obj.model]
        obj.fused = fuse_poses(poses, weights) if poses else None
        return obj.fused

    def next_view(self, obj: SceneObject, purpose: str) -> View | None:
        """Take the reachable view of ``obj`` farthest (in angle) from the views that saw it.

        A direction the robot cannot reach at the viewing distance is tried nearer (3/4, 1/2 of
        it, not below the sensor's near limit): an arm reaches a steep view from closer. A view
        that fails to plan gives way to the next one; ``2 * reach_tries`` directions are tried.
        """
        centre = obj.cluster.centroid
        lo, hi = obj.cluster.aabb
        extent = float(np.linalg.norm(hi - lo))
        distance = viewing_distance(self.sim.sensor, extent)
        near = viewing_distance(self.sim.sensor, extent, far=0.0)
        ladder = [d for d in (distance, 0.75 * distance, 0.5 * distance) if d >= near] or [distance]
        height = getattr(self.sim.robot, "camera_height", None)
        rings = [views_around(centre, d, camera_height=height)[0] for d in ladder]
        seen = np.array([self.views[v].believed[:3, 3] for v in obj.cluster.view_ids])
        directions = 0
        for index in order_by_novelty(rings[0], seen, centre):
            if not self.mover.plausible(rings[0][index][:3, 3], centre):
                continue
            directions += 1
            for d, ring in zip(ladder, rings, strict=True):
                reached = self.mover.reach(as_target(self.sim.sensor, ring[index], obj.cluster.points, d))
                if reached is not None:
                    view = self.add_view(reached[0], purpose, obj.id, reached[1])
                    if view is not None or self.budget_left <= 0:
                        return view
                    break
            if directions >= 2 * self.reach_tries:
                break
        return None

    def collect_view_hypotheses(self, obj: SceneObject) -> int:
        """Per-view hypotheses (for the object's model and its rivals) of its best-covered and newest views.

        Each view is recognised once per model; hypotheses of another model are dropped when
        the object's model changes.
        """
        names = [obj.model, *[r.model for r in obj.rivals]]
        obj.view_hypotheses = [(v, h) for v, h in obj.view_hypotheses if h.model in names]
        used = {view for view, _ in obj.view_hypotheses}
        views = set(self.recognition_cluster(obj).view_ids) | set(obj.cluster.view_ids[-2:])
        for view in sorted(views):
            if view not in used:
                self._check_view(obj, view, names)
        return len(obj.view_hypotheses)

    def _check_view(self, obj: SceneObject, view: int, names: list[str]) -> None:
        """Recognise the object in one view (once per view and first model name); keep the
        validated hypothesis."""
        key = (int(view), names[0])
        if key in obj.checked_views:
            return
        obj.checked_views.add(key)
        found = self.view_hypothesis(obj, int(view), names)
        if found is not None:
            obj.view_hypotheses.append((int(view), found))

    def settle_from_views(self, obj: SceneObject) -> str:
        """Resolve an ambiguous object with the views already taken (no new ones): fuse and decide."""
        if obj.status != AMBIGUOUS:
            return obj.status
        self.collect_view_hypotheses(obj)
        self.fuse(obj)
        self.validate(obj)
        self._settle_ambiguous(obj)
        return obj.status

    def multi_view_step(self, obj: SceneObject) -> bool:
        """One more view of an ambiguous object; True when it is resolved or out of views."""
        view = self.next_view(obj, f"multi-view {obj.id}") if obj.multi_views < self.multi_view_views else None
        if view is None:
            obj.note("no further view for multi-view recognition")
            self._settle_ambiguous(obj)
            return True
        obj.multi_views += 1
        self.segment()
        self.recognise(obj)
        self.validate(obj)  # collects the new view's hypothesis and fuses
        self._say(f"object {obj.id}: multi-view {obj.multi_views}, {obj.status}"
                  + (f", fused {len(obj.fused.members)} of {len(obj.view_hypotheses)}" if obj.fused else ""))
        if obj.status == RECOGNISED:
            return True
        if obj.status != AMBIGUOUS:
            return True
        if obj.multi_views >= self.multi_view_views:
            self._settle_ambiguous(obj)
            return True
        return False

    def _settle_ambiguous(self, obj: SceneObject) -> None:
        """Out of views: keep the fused pose if enough views agree, or if the robot could not reach a
        confirming view and the validated hypothesis has no rival (Kriegel's single-view
        recognition: q_h and the PVS votes passed); else the object is unknown."""
        if obj.status != AMBIGUOUS:
            return
        agreed = obj.fused is not None and len(obj.fused.members) >= self.multi_view_agree
        unconfirmed = obj.fused is not None and not obj.rivals
        if agreed or unconfirmed:
            obj.pose = obj.fused.pose
            obj.status = RECOGNISED
            obj.note("recognised by the fused per-view poses" if agreed else
                     f"recognised from {len(obj.fused.members)} view(s): no confirming view was reachable")
            if obj.recognised_after_views is None:
                obj.recognised_after_views = len(self.views)
        else:
            obj.status = UNKNOWN
            obj.note("ambiguity not resolved: treated as unknown")

    def resolve_ambiguous(self) -> None:
        """Multi-view recognition of every ambiguous object until it is resolved."""
        for obj in self.by_status(AMBIGUOUS):
            resolved = False
            while not resolved:
                resolved = self.multi_view_step(obj)

    # -- modelling unknown objects -------------------------------------------------------------
    def start_modelling(self, obj: SceneObject) -> Any:
        """A ModellingSession over the object's box (the other objects are obstacles)."""
        from explore.nbv import ModellingSession, resolve_strategy

        lo, hi = self._model_box(obj)
        others = [o.box(0.005) for o in self.objects if o.id != obj.id and len(o.cluster.points) >= self.min_points]
        seen = len(obj.cluster.view_ids)  # scene views integrated first count towards the session's scans
        strategy = resolve_strategy(self.strategy, self.registry)
        strategy = dataclasses.replace(strategy, termination_params={
            **strategy.termination_params, "coverage": self.model_coverage, "n_abort": self.model_scans + seen})
        session = ModellingSession(self.sim, strategy, self.registry, seed=self.seed + 7919 * (obj.id + 1),
                                   max_scans=self.model_scans + seen, region=(lo, hi), obstacles=others,
                                   fallback_generator=None)
        self._modelling[obj.id] = session
        obj.status = MODELLING
        obj.note(f"modelling in box {np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()}")
        for index in obj.cluster.view_ids:  # what the scene already saw of it
            session.integrate_view(self.views[index].scan, self.views[index].believed, "scene")
        session.ctx.sensor_pose = self.mover.believed_pose()
        return session

    def _model_box(self, obj: SceneObject) -> tuple[Array, Array]:
        """The object's box grown by the margins, clipped to the region, resting on the table."""
        lo, hi = obj.box(self.box_margin, self.box_top)
        lo = np.maximum(lo, self.pvs.min_corner)
        hi = np.minimum(hi, self.pvs.max_corner)
        lo[2] = obj.cluster.points[:, 2].min() - 0.004
        if self.table is not None:  # the box rests on the support plane
            lo[2] = max(lo[2] - 0.02, float(self.table.world_T_table[2, 3]) + 0.002)
        return lo, hi

    def model_step(self, obj: SceneObject) -> bool:
        """One NBS iteration for an unknown object; True when its modelling is finished.

        Recognition is re-tried after each of the first ``retry_scans`` scans (the new views
        may show a known object that was hidden); a success ends the modelling.
        """
        session = self._modelling.get(obj.id) or self.start_modelling(obj)
        own_scans = obj.modelling_scans
        if own_scans > 0:
            decision = session.terminate()
            if decision.stop or own_scans >= self.model_scans:
                obj.note(f"modelling stopped: {decision.reason or 'scan budget'}")
                return True
        session.generate()
        target, configs, candidate = None, None, None
        centre = obj.cluster.centroid
        tries = 0
        while tries < self.reach_tries:
            candidate = session.select()
            if candidate is None:
                break
            if not self.mover.plausible(target_start(candidate.target)[:3, 3], centre) or self._taken(candidate.target):
                continue
            tries += 1
            reached = self.mover.reach(candidate.target)
            if reached is not None:
                target, configs = reached
                break
        view = None
        if target is not None:
            view = self.add_view(target, f"model {obj.id}", obj.id, configs)
        if view is None:  # no reachable NBS candidate: the most novel reachable view of the object
            candidate = None
            view = self.next_view(obj, f"model {obj.id}")
        if view is None:
            obj.note("modelling stopped: no reachable view left")
            return True
        obj.modelling_scans += 1
        session.integrate_view(view.scan, view.believed, None if candidate is not None else "scene_view")
        session.ctx.sensor_pose = view.believed.copy()
        self.segment()
        obj.coverage_estimate = float(session.ctx.coverage_history[-1])
        self._say(f"object {obj.id}: modelling scan {obj.modelling_scans}, ĉ_m {obj.coverage_estimate:.2f}")
        if obj.modelling_scans <= self.retry_scans and self.models:
            self.recognise(obj)
            if self.validate(obj) in (RECOGNISED, AMBIGUOUS):
                obj.note(f"recognised as {obj.model} during modelling (scan {obj.modelling_scans})")
                self._modelling.pop(obj.id, None)
                return True
            obj.status = MODELLING
        if self.budget_left <= 0:
            return True
        return False

    def _taken(self, target: Target, eye_tol: float = 0.02, angle_tol_deg: float = 5.0) -> bool:
        """A view was already taken from (about) ``target``'s pose: in a static scene it would
        show the same surface again (an NBS utility that cannot see why its gain never comes
        would otherwise pick it over and over)."""
        if not self.views:
            return False
        pose = target_start(target)
        taken = np.array([v.recorded for v in self.views])
        near = np.linalg.norm(taken[:, :3, 3] - pose[:3, 3], axis=1) <= eye_tol
        aligned = taken[:, :3, 2] @ pose[:3, 2] >= math.cos(math.radians(angle_tol_deg))
        return bool(np.any(near & aligned))

    def finish_modelling(self, obj: SceneObject) -> str | None:
        """Turn the modelled surface into a database object (iterative recognition); its name."""
        session = self._modelling.pop(obj.id, None)
        if session is None or obj.status != MODELLING:
            return None
        mesh = session.surface.mesh
        obj.surface_points = np.asarray(session.surface.points).copy()
        obj.coverage_estimate = float(session.surface.coverage_area()) if len(mesh.triangles) else 0.0
        if len(mesh.triangles) < 20:
            obj.status = UNKNOWN
            obj.note("modelling gave no mesh")
            return None
        name = self.add_to_database(obj, close_holes(mesh), session.n_scans)
        obj.status, obj.model = MODELLED, name
        return name

    def learn_from_views(self, obj: SceneObject) -> str | None:
        """Model an unknown object from the views already taken (Görner's multi-view object
        representation, here fused into a mesh); add it to the database; its name."""
        from scipy.spatial import cKDTree

        from explore.mapping import SurfaceModel

        lo, hi = self._model_box(obj)
        points = obj.sample(0.001)
        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1])) if len(points) > 2 else 0.002
        f = float(np.clip(spacing / 0.002, 1.0, 5.0))  # sparse room-scale views need a coarser surface
        surface = SurfaceModel(lo, hi, point_spacing=0.002 * f, normal_radius=0.006 * f, mesh_radius=0.008 * f,
                               voxel_size=0.0035 * f)
        for index in obj.cluster.view_ids:
            surface.integrate(self.views[index].scan)
        mesh = surface.mesh
        obj.surface_points = np.asarray(surface.points).copy()
        obj.coverage_estimate = float(surface.coverage_area()) if len(mesh.triangles) else 0.0
        if len(mesh.triangles) < 20:
            obj.note("too few points for a mesh")
            return None
        name = self.add_to_database(obj, close_holes(mesh), len(obj.cluster.view_ids))
        obj.status, obj.model = MODELLED, name
        return name

    def model_unknown(self) -> None:
        """Model every unknown object, one after the other."""
        for obj in self.by_status(UNKNOWN):
            finished = False
            while not finished:
                finished = self.model_step(obj)
            if obj.status == MODELLING:
                self.finish_modelling(obj)

    # -- the object database -------------------------------------------------------------------
    def add_to_database(self, obj: SceneObject, world_mesh: TriMesh, scans: int) -> str:
        """Add a modelled mesh (world frame) with descriptors, provenance and location."""
        from explore.perception import model_descriptors, object_frame

        start = time.perf_counter()
        world_T_model, mesh = object_frame(world_mesh)
        name = self._new_name()
        from explore.perception import PPFRecognizer, VFHRecognizer

        chosen = [self.recognizer] if hasattr(self.recognizer, "describe") else []  # the configured one's own
        kinds = {r.descriptor_kind for r in chosen}
        chosen += [r for r in (PPFRecognizer(), VFHRecognizer()) if r.descriptor_kind not in kinds]
        descriptors = model_descriptors(Model(name, mesh), chosen)
        self.db.add(name, mesh, provenance="modelled", world=self.sim.spec.name, run=self.run_name, scans=int(scans),
                    coverage=float(np.clip(obj.coverage_estimate, 0.0, 1.0)), descriptors=descriptors)
        self.db.set_location(name, self.sim.spec.name, world_T_model, np.vstack(world_mesh.bounds))
        obj.pose = world_T_model
        self.added.append(name)
        self._models = None
        self._timed("database_s", start)
        self._say(f"object {obj.id}: added to the database as {name}")
        return name

    def _new_name(self) -> str:
        """A short, stable name for a modelled object: ``<world>-<n>``, the first n free in the database
        (the run that made it is recorded beside it, not in its name)."""
        stem = "".join(ch if ch.isalnum() or ch in "_.-" else "_" for ch in self.sim.spec.name)
        k = 1
        while f"{stem}-{k}" in self.db:
            k += 1
        return f"{stem}-{k}"

    def remember_locations(self) -> None:
        """Record where each recognised object was seen (the database's last known location)."""
        for obj in self.by_status(RECOGNISED):
            if obj.model is not None and obj.pose is not None and obj.model in self.db:
                self.db.set_location(obj.model, self.sim.spec.name, obj.pose, np.vstack(obj.cluster.aabb))

    # -- pose graph and re-integration ---------------------------------------------------------
    def correct_poses(self) -> Any:
        """gtsam pose graph over every view (odometry + ICP factors); re-integrate at the result.

        A session with an incremental graph (a noisy mobile base) has registered and
        localised every view as it came; that graph's solution is the result (a batch graph
        over the same views would lack its multi-start search and its map factors).
        """
        start = time.perf_counter()
        if self.graph is not None:
            poses = self.graph.graph.optimize(self.graph.max_iterations)
            self.graph.poses = poses
            self.reintegrate(list(poses))
            self._timed("registration_s", start)
            error = self.graph.graph.error
            return PoseGraphResult(poses, np.stack(self.graph.believed), list(self.graph.graph.edges), *error)
        believed = [v.believed for v in self.views]
        result = self.registrar.register([rebase_scan(v.scan, v.believed) if v.corrected is not None else v.scan
                                          for v in self.views], believed)
        self.reintegrate(list(result.poses))
        self._timed("registration_s", start)
        return result

    def _apply(self, poses: np.ndarray, tolerance: tuple[float, float] = (0.002, math.radians(0.2))) -> None:
        """Take the incremental graph's poses: the new view is integrated at its corrected pose;
        if an earlier view moved by more than ``tolerance`` (m, rad) everything is re-integrated."""
        moved = any(
            max(err[0] / tolerance[0], err[1] / tolerance[1]) > 1.0
            for err in (pose_error(p, v.recorded)
                        for v, p in zip(self.views[:-1], poses[:-1], strict=True))
        )
        if moved:
            self.reintegrate(list(poses))
            return
        view = self.views[-1]
        view.scan = rebase_scan(view.scan, poses[-1])
        view.corrected = np.asarray(poses[-1]).copy()
        self.pvs.integrate(view.scan)
        self.registered = True

    def reintegrate(self, poses: Sequence[Pose]) -> None:
        """Move every view (scan and cluster points) to ``poses`` and rebuild the PVS from scratch."""
        from explore.mapping import PVS

        deltas = []
        for view, pose in zip(self.views, poses, strict=True):
            current = view.recorded
            deltas.append(np.asarray(pose) @ invert(current))
            view.scan = rebase_scan(view.scan, pose)
            view.corrected = np.asarray(pose).copy()
        for obj in self.objects:
            c = obj.cluster
            points, normals = c.points.copy(), c.normals.copy()
            for index in np.unique(c.views):
                mask = c.views == index
                delta = deltas[int(index)]
                points[mask] = transform_points(delta, c.points[mask])
                normals[mask] = c.normals[mask] @ delta[:3, :3].T
            obj.cluster = Cluster(c.id, points, normals, c.views, c.beams, c.up)
            obj._sample = None
        self.pvs = PVS.for_region(self.sim.spec.region_min, self.sim.spec.region_max, self.resolution)
        for view in self.views:
            self.pvs.integrate(view.scan)
        self.mover.pvs = self.pvs
        self.registered = True

    # -- the whole loop --------------------------------------------------------------------------
    def step(self) -> bool:
        """One round of Fig. 3.1; True when the scene is explained or the budget is spent."""
        if not self.views:
            self.overview()
            self.segment()
            self.recognise_all()
            return self.all_explained
        self.resolve_ambiguous()
        self.model_unknown()
        self.recognise_all()
        self.remember_locations()
        return self.all_explained or self.budget_left <= 0 or not self.by_status(UNEXPLAINED, UNKNOWN, AMBIGUOUS)

    def run(self, max_rounds: int = 10) -> dict[str, Any]:
        """Explore until every object is explained (or the view budget is spent); the metrics."""
        for _ in range(max_rounds):
            if self.step():
                break
        return self.metrics()

    # -- results -----------------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """What the session knows (no ground truth): objects, views, time."""
        return {
            "views": len(self.views),
            "all_explained": self.all_explained,
            "elapsed_s": time.perf_counter() - self.started,
            "travel_m": self.mover.travel_m,
            "collisions": self.mover.collisions,
            "added_to_database": list(self.added),
            "timings_s": dict(self.timings),
            "objects_found": [
                {"id": o.id, "status": o.status, "model": o.model, "points": int(len(o.cluster.points)),
                 "views": len(o.cluster.view_ids), "q_h": o.q_h, "v_h": o.v_h, "multi_views": o.multi_views,
                 "modelling_scans": o.modelling_scans, "coverage_estimate": o.coverage_estimate,
                 "rejected": o.rejected, "events": o.events}
                for o in self.candidates()
            ],
        }

    def metrics(self) -> dict[str, Any]:
        """Ground-truth evaluation (the only place that reads it): see :mod:`explore.scene.metrics`."""
        from explore.scene.metrics import evaluate

        return evaluate(self)


def environment_reference(sim: Any, spacing: float = 0.02, min_height: float = 0.05) -> Points3:
    """Points on the upright surfaces of the known environment (walls, table edges and legs):
    the map a mobile base localises in (a planner may know the environment; objects are left out)."""
    from explore.mapping import sample_surface

    parts = []
    for body in sim.bodies:
        if body.is_object:
            continue
        points, normals = sample_surface(body.mesh, spacing * spacing, seed=0)
        upright = (np.abs(normals[:, 2]) < math.cos(math.radians(45.0))) & (points[:, 2] > min_height)
        parts.append(points[upright])
    out = np.vstack(parts) if parts else np.zeros((0, 3))
    keys = np.floor(out / spacing).astype(np.int64)
    return out[np.sort(np.unique(keys, axis=0, return_index=True)[1])] if len(out) else out


def _plugin(registry: Any, kind: str, spec: Any) -> Any:
    if isinstance(spec, str):
        return registry.create(kind, spec, {}, "<scene>", kind)
    if isinstance(spec, tuple):
        return registry.create(kind, spec[0], spec[1], "<scene>", kind)
    return spec


__all__ = ["SceneObject", "SceneSession", "View", "close_holes", "environment_reference"]
