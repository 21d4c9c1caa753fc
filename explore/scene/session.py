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

The steps, each a method a behaviour can call on one of the session's collaborators:
``scene.viewing.overview()`` (first views, PVS initialisation), :meth:`SceneSession.segment`
(support plane, clusters of every new view, associated to the scene's objects),
``scene.recognition.recognise(obj)`` (each cluster against the database; a hypothesis needs
q_h >= the recogniser's ``min_q_h``, Eq. 3.10), ``scene.recognition.validate(obj)`` (PVS votes,
Eq. 3.11; competing hypotheses make the object *ambiguous*),
``scene.recognition.multi_view_step(obj)`` (one more view of an ambiguous object; per-view
hypotheses fused on SE(3), Sec. 5.6.2), ``scene.object_modelling.model_step(obj)`` (one NBS
iteration of :class:`~explore.nbv.modelling.ModellingSession` restricted to the object's box,
the other objects as obstacles, recognition re-tried during the first scans) and
``scene.database_update.add_to_database`` (mesh, PPF/VFH descriptors, provenance, location:
iterative recognition). ``scene.viewing.correct_poses()`` runs the gtsam pose graph over the
views and re-integrates the PVS and the clusters at the corrected poses.
:meth:`SceneSession.shortfall` says why a run that ends with every object explained may still
have missed its goal (no reachable view, the view budget).

The session never reads the ground truth; :meth:`SceneSession.metrics` does, through
:mod:`explore.scene.metrics`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from explore.core import BUDGET, FAILURE, NO_CANDIDATES, Points3
from explore.mapping import make_pvs
from explore.perception import (
    Cloud,
    Cluster,
    Model,
    Segmentation,
    Table,
    euclidean_clusters,
    grown_to,
    require_role,
    vote_points,
)
from explore.scene.database_update import DatabaseUpdate
from explore.scene.metrics import evaluate
from explore.scene.motion import Mover
from explore.scene.object_modelling import ObjectModelling
from explore.scene.recognition import Recognition
from explore.scene.scene_objects import (
    AMBIGUOUS,
    ENVIRONMENT_MARGIN,
    FLOOR,
    MODELLED,
    MODELLING,
    NO_PROGRESS,
    NO_VIEW,
    RECOGNISED,
    UNEXPLAINED,
    UNKNOWN,
    UPRIGHT_NORMAL_Z,
    VIEW_BUDGET,
    WALL_MARGIN,
    SceneObject,
    View,
    _plugin,
    environment_reference,
)
from explore.scene.settings import SceneSettings
from explore.scene.viewing import ViewTaking

REGION_SUPPORT_GAP = 0.05  # m: how far above its support a world's region may begin
UNEXPLAINED_AREA = 5e-4  # m²: occupied voxels no object explains, this much together, are an object missed
EXPLAINED_NEAR = 0.015  # m: an occupied voxel this near an object's points is that object's


class SceneSession:
    """Scene exploration on a simulation with a robot, a sensor and an object database.

    Parameters
    ----------
    sim : Simulation with robot and sensor attached
    registry : the plugin registry
    database : an open :class:`~explore.perception.database.ObjectDatabase`
    settings : what the exploration uses and how much it may do (:class:`SceneSettings`);
        keyword ``overrides`` replace single fields (``SceneSession(sim, registry, db, seed=1)``)
    progress : called with a line of text after every step (long work shows progress)
    """

    def __init__(self, sim: Any, registry: Any, database: Any, settings: SceneSettings | None = None, *,
                 progress: Callable[[str], None] | None = None, **overrides: Any) -> None:
        self.sim = sim
        self.registry = registry
        self.db = database
        self.settings = settings = dataclasses.replace(settings or SceneSettings(), **overrides)
        self.segmenter = _plugin(registry, "segmenter", settings.segmenter)
        self.recognizer = _plugin(registry, "recognizer", settings.recognizer)
        self.recognizer.sense_with(sim.sensor, settings.depth_processing)
        self.validator = _plugin(registry, "pose_validator", settings.validator)
        self.registrar = require_role(_plugin(registry, "registrar", settings.registrar, "scans"), "scans", "<scene>")
        self.progress = progress
        self.resolution = 0.005 if settings.resolution is None else float(settings.resolution)
        self.pvs = self.new_pvs()
        rng = np.random.default_rng(int(settings.seed))
        self.rng_sensor = np.random.default_rng(rng.integers(2**63))
        self.mover = Mover(sim, registry, settings.planner, settings.noise, seed=int(rng.integers(2**31)))
        self.mover.pvs = self.pvs
        self.graph = None  # incremental pose graph, for a robot whose base odometry drifts
        if settings.register and self.mover.base_dofs and settings.noise and not self.mover.localises \
                and hasattr(self.registrar, "incremental"):
            # a base on the floor: Plane ICP between views, each view localised in the known environment
            self.graph = self.registrar.incremental(plane=FLOOR, reference=environment_reference(sim))
        self.views: list[View] = []
        self.objects: list[SceneObject] = []
        self.table: Table | None = None
        self.pending_views: list[int] = []
        self.model_cache: list[Model] | None = None
        self.model_vote_points: dict[str, Points3] = {}  # what each model votes with (Eq. 3.11)
        self.modelling_sessions: dict[int, Any] = {}
        self.added: list[str] = []
        self.budget_cuts: list[str] = []  # looks of the scene a step planned and the view budget cut short
        self.looks_closer = False  # a closer-look step aims views at objects seen with too few points
        self.known_at_start = list(database.names())
        self.registered = self.mover.localises  # views recorded in a map frame of their own (not the truth)
        self.started = time.perf_counter()
        self._unexplained: tuple[tuple[int, int, int], list[dict[str, Any]]] | None = None
        self.timings: dict[str, float] = {}
        self.database_update = DatabaseUpdate(self)
        self.object_modelling = ObjectModelling(self)
        self.recognition = Recognition(self)
        self.viewing = ViewTaking(self)

    # -- bookkeeping -------------------------------------------------------------------------

    def new_pvs(self) -> Any:
        """An empty PVS over the world's region at the session's resolution, dense or sparse as the settings
        say (:func:`~explore.mapping.make_pvs`)."""
        return make_pvs(self.sim.spec.region_min, self.sim.spec.region_max, self.resolution,
                        layout=self.settings.pvs_layout)

    def say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def timed(self, key: str, start: float) -> None:
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - start

    @property
    def models(self) -> list[Model]:
        """The database objects (meshes + stored descriptors), reloaded after an update."""
        if self.model_cache is None:
            self.model_cache = self.db.models()
            self.model_vote_points = {m.name: vote_points(m.mesh, self.resolution) for m in self.model_cache}
        return self.model_cache

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
        return self.settings.max_views - len(self.views)

    def open_objects(self) -> list[SceneObject]:
        """The objects still to explain that another round could explain: not those left unknown because
        no view to model them could be reached (tried again only while other objects bring new views)."""
        pending = self.by_status(UNEXPLAINED, UNKNOWN, AMBIGUOUS)
        return pending if any(o.modelling_end != NO_VIEW for o in pending) else []

    def awaiting_closer_look(self) -> list[SceneObject]:
        """Objects seen with too few points after the round's closer look (a recognition or modelling
        view glimpsed them): the next round's closer look is theirs before the scene counts as explained."""
        return [o for o in self.too_small() if not o.closer_look_offered] if self.looks_closer else []

    def shortfall(self) -> tuple[str, str]:
        """(outcome, reason) when the session could not do what its goal needs for want of a reachable
        view (``no_candidates``: an object modelled below the coverage target, or one glimpsed with too
        few points to tell from noise that no closer view could reach) or of the scene's views
        (``budget_exhausted``: modelled below the target, or objects left unexplained); ("", "")
        otherwise. The per-object scan budget is Kriegel's n_abort, the thesis' own end of an object's
        NBS loop, and counts as done. Before all of these, a run in which the robot touched the world is a
        ``failure`` however well it explained the scene (each contact stopped its motion, as a bumper does,
        and the exploration went on)."""
        if self.mover.collisions:
            return FAILURE, (f"the robot touched {', '.join(sorted(self.mover.touched))} "
                             f"({self.mover.collisions} contact(s); each stopped its motion and the run went on)")
        target = self.settings.model_coverage

        def listed(objects: list[SceneObject]) -> str:
            return ", ".join(f"{o.id} (ĉ_m {o.coverage_estimate:.2f}, {o.modelling_scans} scans)" for o in objects)

        missed = self.unexplained_surface()
        if missed:
            places = ", ".join(f"{m['voxels']} voxels around {m['centre']}" for m in missed[:3])
            if self.budget_left <= 0:  # more views might have explained it
                return BUDGET, (f"view budget of {self.settings.max_views} used up with occupied space in the "
                                f"region that no object explains ({places})")
            return FAILURE, (f"occupied space in the region that no object explains ({places}): an object the "
                             "segmentation missed")
        below = [o for o in self.by_status(MODELLED) if self.short_of_target(o)]
        unreached = [o for o in below if o.modelling_end == NO_VIEW]
        stalled = [o for o in below if o.modelling_end == NO_PROGRESS]
        stuck = [str(o.id) for o in self.by_status(UNKNOWN) if o.modelling_end == NO_VIEW]
        glimpsed = [f"{o.id} ({len(o.cluster.points)} points)" for o in self.too_small() if o.closer_look_unreached]
        reasons = []
        if unreached:
            reasons.append(f"object(s) {listed(unreached)} modelled below the coverage target {target}: "
                           "no reachable view was left")
        if stalled:
            reasons.append(f"object(s) {listed(stalled)} modelled below the coverage target {target}: "
                           "the termination rule saw no progress left")
        if stuck:
            reasons.append(f"object(s) {', '.join(stuck)} left unknown: no view to model it could be reached")
        if glimpsed:
            reasons.append(f"object(s) {', '.join(glimpsed)} seen with too few points to tell from noise: "
                           "no closer view")
        if reasons:
            return NO_CANDIDATES, "; ".join(reasons)
        cut = [o for o in below if o.modelling_end == VIEW_BUDGET]
        if cut:
            return BUDGET, f"view budget of {self.settings.max_views} used up modelling object(s) {listed(cut)}"
        if self.budget_cuts:
            return BUDGET, f"view budget of {self.settings.max_views} used up: {'; '.join(self.budget_cuts)}"
        unexplained = [str(o.id) for o in self.candidates() if not o.explained]
        if unexplained and self.budget_left <= 0:
            return BUDGET, (f"view budget of {self.settings.max_views} used up with object(s) "
                            f"{', '.join(unexplained)} unexplained")
        return "", ""

    def short_of_target(self, obj: SceneObject) -> bool:
        """``obj`` was modelled below the coverage target (ĉ_m) for want of a reachable view or of progress, or
        its modelling was cut by the scene's view budget: a partial model. Its own scan budget (Kriegel's
        n_abort) ends the NBS loop as the thesis does, and counts as done."""
        return (obj.status == MODELLED and not obj.coverage_estimate >= self.settings.model_coverage
                and obj.modelling_end in (NO_VIEW, NO_PROGRESS, VIEW_BUDGET))

    def unexplained_surface(self) -> list[dict[str, Any]]:
        """Clusters of occupied PVS voxels (p ≥ 0.75) in the region, at least ``UNEXPLAINED_AREA`` of
        them together, that no object's points or recognised model at its pose (within ``EXPLAINED_NEAR``),
        the known environment, the support (1 cm above its plane) or the floor explains: a surface the
        views saw that the segmentation never made an object of (a bin floor seen as a strip left the
        objects on the rest of it out, and the run said `success`). A recognised object explains its
        model's surface also where its cluster does not reach (a corner of an unseen part that the
        clusters of a laser-localised base's views left out). Largest first: voxels and centre (m)."""
        from scipy.spatial import cKDTree

        recognised = self.by_status(RECOGNISED)
        key = (len(self.views), len(self.objects), sum(len(o.cluster.points) for o in self.objects),
               tuple((o.model, None if o.pose is None else np.asarray(o.pose).tobytes()) for o in recognised))
        if self._unexplained is not None and self._unexplained[0] == key:
            return self._unexplained[1]
        lo, hi = np.asarray(self.sim.spec.region_min), np.asarray(self.sim.spec.region_max)
        voxel = float(self.pvs.resolution)
        points = self.pvs.occupied_points(0.75)
        points = points[np.all((points >= lo) & (points <= hi), axis=1) & (points[:, 2] > 0.01)]
        if self.table is not None and len(points):
            points = points[self.table.heights(points) > 0.01]
        if len(points):
            nearest, _ = self.sim.environment_caster().closest(points)
            points = points[np.linalg.norm(nearest - points, axis=1) > ENVIRONMENT_MARGIN + 0.5 * np.sqrt(3) * voxel]
        objects = [o.cluster.points for o in self.objects if len(o.cluster.points)]
        objects += [self.recognition.model_surface(o) for o in recognised]
        if len(points) and objects:
            distance, _ = cKDTree(np.vstack(objects)).query(points, distance_upper_bound=EXPLAINED_NEAR)
            points = points[~np.isfinite(distance)]
        found = []
        if len(points):
            labels = euclidean_clusters(points, 1.5 * voxel)
            for label in np.unique(labels[labels >= 0]):
                part = points[labels == label]
                if len(part) * voxel * voxel >= UNEXPLAINED_AREA:
                    found.append({"voxels": int(len(part)), "centre": np.round(part.mean(axis=0), 3).tolist()})
        found.sort(key=lambda m: -m["voxels"])
        self._unexplained = (key, found)
        return found

    # -- segmentation and association ------------------------------------------------------------
    def segment(self) -> list[SceneObject]:
        """Segment the views taken since the last call and attach their clusters to objects."""
        start = time.perf_counter()
        lo, hi = np.asarray(self.sim.spec.region_min), np.asarray(self.sim.spec.region_max)
        for index in self.pending_views:
            result = self.segmenter.segment(self.views[index].scan, view_ids=[index], table=self.table)
            if result.table is None or not self._supports_region(result.table, lo, hi):
                result = self._segment_region_band(index, result, lo, hi)
            if result.table is not None:
                self.table = result.table
            for cluster in result.clusters:
                cluster = self._off_environment(cluster, lo, hi)
                if cluster is not None and np.all(cluster.centroid >= lo) and np.all(cluster.centroid <= hi):
                    self._associate(cluster)
        self.pending_views = []
        self._merge_fragments()
        self.timed("segment_s", start)
        return self.candidates()

    def _off_environment(self, cluster: Cluster, lo: np.ndarray, hi: np.ndarray) -> Cluster | None:
        """The cluster without the points that are not an object's: outside the region (the world says
        its objects lie within it) or the known environment's (:meth:`environment_points`); None if none
        is left."""
        points = cluster.points
        keep = np.all((points >= lo - ENVIRONMENT_MARGIN) & (points <= hi + ENVIRONMENT_MARGIN), axis=1)
        if keep.any():
            keep[keep] = ~self.environment_points(points[keep])
        if keep.all():
            return cluster
        return cluster.subset(keep) if keep.any() else None

    def environment_points(self, points: np.ndarray, support_z: float = -np.inf) -> np.ndarray:
        """Mask of the points that are the known environment's: within ``ENVIRONMENT_MARGIN`` of it
        (where its nearest surface lies higher than ``support_z``: below, the support plane, whose band
        the segmenter and the modelling's floor clearance deal with), or within ``WALL_MARGIN`` of its
        upright faces (a shelf's back and sides, seen at a slant through the depth noise)."""
        nearest, normals = self.sim.environment_caster().closest(points)
        distance = np.linalg.norm(nearest - points, axis=1)
        upright = np.abs(normals[:, 2]) < UPRIGHT_NORMAL_Z
        return ((distance <= ENVIRONMENT_MARGIN) & (nearest[:, 2] > support_z)) | (upright & (distance <= WALL_MARGIN))

    @staticmethod
    def _supports_region(table: Table, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Whether ``table`` can be what the objects of the region ``lo``..``hi`` stand on: the region's
        floor lies no more than ``REGION_SUPPORT_GAP`` above the plane, and the plane not above the
        region's top (a room's region may reach down to the floor, below its tables)."""
        floor = np.array([[0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]]])
        gap = float(table.heights(floor)[0])
        return -(hi[2] - lo[2]) <= gap <= REGION_SUPPORT_GAP

    def _segment_region_band(self, index: int, first: Segmentation, lo: np.ndarray, hi: np.ndarray) -> Segmentation:
        """Segment view ``index`` again on its points within the region's footprint, from
        ``REGION_SUPPORT_GAP`` below the region's floor to its top: the view's planes were another level
        (a shelf's lower board, the floor under a table the region sits on) or upright (a shelf's back
        and sides), so the support is searched where the world says the objects are, and it reaches
        over the region's whole footprint (a bin's floor seen from its front, past its lip, shows
        a strip; the objects on the rest would be cut off). Keeps ``first`` if that finds none either."""
        cloud = Cloud.from_scans(self.views[index].scan, [index])
        band_lo = np.array([lo[0], lo[1], lo[2] - REGION_SUPPORT_GAP])
        inside = np.all((cloud.points >= band_lo) & (cloud.points <= hi), axis=1)
        band = cloud.subset(inside)
        again = self.segmenter.segment(band, table=self.table)
        if again.table is None:
            return first
        footprint = np.array([[x, y, lo[2]] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
        if not again.table.inside(footprint, margin=1e-6).all():  # once grown, later views keep it
            again = self.segmenter.segment(band, table=grown_to(again.table, footprint))
        again.diagnostics["support"] = "region band"
        return again

    def candidates(self) -> list[SceneObject]:
        """The objects large enough to be explained (smaller clusters are noise)."""
        return [o for o in self.objects if len(o.cluster.points) >= self.settings.min_points]

    def too_small(self) -> list[SceneObject]:
        """The other objects: seen with too few points to be explained (noise unless a closer look adds more)."""
        return [o for o in self.objects if len(o.cluster.points) < self.settings.min_points]

    def _near_share(self, cluster: Cluster, obj: SceneObject) -> np.ndarray:
        from scipy.spatial import cKDTree

        lo, hi = obj.cluster.aabb
        tol = self.settings.associate_tolerance
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

    @property
    def touch_tolerance(self) -> float:
        """How near two objects' points must come for them to touch: the segmenter's cluster tolerance."""
        return float(getattr(self.segmenter, "cluster_tolerance", 0.02))

    def _merge_fragments(self) -> None:
        """Merge objects not yet explained whose points touch (one object seen in pieces), unless a
        recognised model split one off the other (an object touching a known one)."""
        merged = True
        while merged:
            merged = False
            open_objects = [o for o in self.objects if not o.explained and o.status != MODELLING]
            for i, a in enumerate(open_objects):
                for b in open_objects[i + 1 :]:
                    if b.id in a.apart or a.id in b.apart:
                        continue
                    if a.touches(b.sample(), self.touch_tolerance):
                        a.extend(b.cluster)
                        a.apart |= b.apart
                        a.status = UNEXPLAINED
                        a.note(f"merged with object {b.id}")
                        self.objects.remove(b)
                        merged = True
                        break
                if merged:
                    break

    # -- the whole loop --------------------------------------------------------------------------
    def step(self) -> bool:
        """One round of Fig. 3.1; True when the scene is explained or the budget is spent."""
        if not self.views:
            self.viewing.overview()
            self.segment()
            self.viewing.look_closer()
            self.recognition.recognise_all()
            return self.all_explained
        self.recognition.resolve_ambiguous()
        self.object_modelling.model_unknown()
        self.recognition.recognise_all()
        self.database_update.remember_locations()
        return self.all_explained or self.budget_left <= 0 or not self.open_objects()

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
            "moves_failed": self.mover.failed_moves,
            "added_to_database": list(self.added),
            "timings_s": dict(self.timings),
            "objects_found": [
                {"id": o.id, "status": o.status, "model": o.model, "points": int(len(o.cluster.points)),
                 "views": len(o.cluster.view_ids), "q_h": o.q_h, "v_h": o.v_h, "multi_views": o.multi_views,
                 "modelling_scans": o.modelling_scans, "modelling_end": o.modelling_end,
                 "coverage_estimate": o.coverage_estimate,
                 "rejected": o.rejected, "events": o.events}
                for o in self.candidates()
            ],
            "too_small": [{"id": o.id, "points": int(len(o.cluster.points)), "views": len(o.cluster.view_ids),
                           "closer_looks": o.closer_looks}
                          for o in self.too_small()],
            "unexplained_surface": self.unexplained_surface(),
        }

    def metrics(self) -> dict[str, Any]:
        """Ground-truth evaluation (the only place that reads it): see :mod:`explore.scene.metrics`."""
        return evaluate(self)
