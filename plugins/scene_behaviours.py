"""Behaviour plugins of scene exploration (Kriegel thesis Fig. 3.1) and Görner's table patrol.

Thin adapters over :class:`explore.scene.session.SceneSession`: the session lives in
``context.state["scene"]`` as a :class:`SceneRun`, which gives the live status line and the
``metrics.json`` fields. Blackboard keys (in the run's namespace): ``scene`` (the run),
``unknown`` / ``ambiguous`` (object ids still to explain), ``object`` (the current one in a
``for_each``), ``object_done`` (its loop ends), ``done`` (the exploration ends), ``explained``
(every object explained). Long steps are ``blocking`` (worker thread).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from explore.core import BUDGET, FAILURE, NO_CANDIDATES, SUCCESS, Param
from explore.perception import Q_H_MIN, ObjectDatabase, default_path
from explore.runtime import ExploreBehaviour, Outcome, failure, success
from explore.scene import SceneSession, SceneSettings, known_tables, surround


class SceneRun:
    """The scene session of a tree run: live statistics and the run's outputs."""

    def __init__(self, session: Any, database: Any) -> None:
        self.session = session
        self.database = database
        self.patrol: dict[str, Any] = {}

    @property
    def end_outcome(self) -> str:
        """SUCCESS only when the mission's goal was met (see :meth:`shortfall`)."""
        return self.shortfall()[0]

    @property
    def end_reason(self) -> str:
        return self.shortfall()[1]

    def shortfall(self) -> tuple[str, str]:
        """(outcome, reason): the session's FAILURE (a contact, surface no object explains) first, then
        NO_CANDIDATES when none of a patrolled table's observation poses could be reached, BUDGET when the
        view budget ran out before a table got a view (its objects are not explained, however well the
        others went), then the session's other shortfalls (:meth:`~explore.scene.SceneSession.shortfall`);
        (SUCCESS, "") when the goal was met."""
        outcome, reason = self.session.shortfall()
        if outcome == FAILURE:
            return outcome, reason
        unreached, unseen = self._unseen_tables()
        if unreached:
            return NO_CANDIDATES, f"no observation pose around {', '.join(unreached)} could be reached"
        if unseen:
            max_views = self.session.settings.max_views
            return BUDGET, f"view budget of {max_views} used up before {', '.join(unseen)} got a view"
        return (outcome, reason) if outcome else (SUCCESS, "")

    def _unseen_tables(self) -> tuple[list[str], list[str]]:
        """(tables whose poses were all unreachable, tables the view budget left unseen)."""
        tables = self.patrol.get("tables", [])
        return ([t["table"] for t in tables if not t["views"] and t.get("unreachable")],
                [t["table"] for t in tables if not t["views"] and not t.get("unreachable")])

    def live_stats(self) -> dict[str, Any]:
        s = self.session
        found = s.candidates()
        stats: dict[str, Any] = {"views": len(s.views), "objects": len(found),
                                 "explained": sum(o.explained for o in found)}
        for status in ("ambiguous", "unknown", "modelling"):
            count = sum(o.status == status for o in found)
            if count:
                stats[status] = count
        return stats

    def run_outputs(self, out_dir: Any) -> dict[str, Any]:
        """metrics.json fields (per-object results, scene numbers), the scene picture, PVS and models.

        This is the run's last use of the database: it is closed here.
        """
        out_dir = Path(out_dir)
        s = self.session
        try:
            metrics = s.metrics()
            save_scene_png(s, out_dir / "scene.png")
            s.pvs.save(out_dir / "pvs.npz")
            s.pvs.save_octomap(out_dir / "pvs.bt")
            for name in s.added:
                (out_dir / "models").mkdir(exist_ok=True)
                self.database.export(name, out_dir / "models" / f"{name}.ply")
            metrics["database"] = str(self.database.path)
            metrics["database_objects"] = len(self.database)
            if self.patrol:
                metrics["patrol"] = dict(self.patrol)
        finally:
            self.database.close()
        return metrics


def save_scene_png(session: Any, path: Path) -> None:
    """Top view of the objects' points coloured by how they were explained. Each object carries its
    number just above its points; the key beside the plot names it, so labels never pile up."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"recognised": "tab:green", "modelled": "tab:blue", "ambiguous": "tab:orange",
               "unknown": "tab:red", "modelling": "tab:purple", "unexplained": "tab:gray"}
    fig, ax = plt.subplots(figsize=(9, 5.5), dpi=110)
    if session.table is not None:
        hull = session.table.hull @ session.table.world_T_table[:3, :2].T + session.table.world_T_table[:3, 3]
        ring = np.vstack([hull, hull[:1]])
        ax.plot(ring[:, 0], ring[:, 1], color="0.6", lw=1, label="support hull")
    names = []
    for obj in session.candidates():
        pts = obj.cluster.points[:: max(1, len(obj.cluster.points) // 3000)]
        colour = colours.get(obj.status, "k")
        ax.scatter(pts[:, 0], pts[:, 1], s=0.5, color=colour)
        top = [float(obj.cluster.centroid[0]), float(pts[:, 1].max())]
        ax.annotate(str(obj.id), top, textcoords="offset points", xytext=(0, 4), ha="center", va="bottom",
                    fontsize=8, bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": colour, "alpha": 0.85})
        names.append(plt.Line2D([], [], ls="", label=f"{obj.id}: {obj.model or '-'} ({obj.status})"))
    eyes = np.array([v.believed[:3, 3] for v in session.views]) if session.views else np.zeros((0, 3))
    if len(eyes):
        ax.plot(eyes[:, 0], eyes[:, 1], "k.", ms=3, label=f"{len(eyes)} views")
    handles = [plt.Line2D([], [], marker="o", ls="", color=c, label=k) for k, c in colours.items()]
    ax.legend(handles=handles + ax.get_legend_handles_labels()[0] + names, fontsize=7, loc="upper left",
              bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    explained = sum(o.explained for o in session.candidates())
    ax.set_title(f"{session.sim.spec.name}: {explained} of {len(session.candidates())} objects explained, "
                 f"{len(session.views)} views")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _scene(behaviour: ExploreBehaviour) -> Any:
    return behaviour.need("scene").session


def _to_model(behaviour: ExploreBehaviour, ids: list[int]) -> None:
    """Add objects left unknown after validation to the round's ``unknown`` list (modelled or learned
    in this round; the list is written once, by ``validate_objects``)."""
    listed = behaviour.read("unknown") or []
    new = [i for i in ids if i not in listed]
    if new:
        behaviour.write("unknown", [*listed, *new])


def _current(behaviour: ExploreBehaviour, *statuses: str) -> Any:
    """The object named by the ``object`` key if it still has one of ``statuses``, else None."""
    scene = _scene(behaviour)
    object_id = behaviour.read("object")
    found = [o for o in scene.objects if o.id == object_id]
    return found[0] if found and found[0].status in statuses else None


class StartScene(ExploreBehaviour):
    """Open the object database (seeding the world's known objects) and start a scene session."""

    name = "start_scene"
    writes = ("scene", "done", "explained", "unknown", "ambiguous", "object", "object_done")
    params = (
        Param("db", str, "", "", "object database file ('': $EXPLORE_DB or runs/objects.db, as `explore db`)"),
        Param("seed_known", bool, True, "", "add the world's `known: true` objects to the database first"),
        Param("segmenter", str, "plane_clusters", "", "segmenter plugin"),
        Param("scale", str, "table", "", "segmenter scale preset (room: 0.05 m / 20 points, table: 0.02 m / 30)",
              choices=("room", "table")),
        Param("recognizer", str, "ppf", "", "recogniser plugin (ppf, fpfh_ransac, vfh_mean_distance)"),
        Param("min_q_h", float, Q_H_MIN, "", "q_h acceptance threshold (Kriegel Eq. 3.10)", low=0.0, high=1.0),
        Param("validator", str, "pvs_votes", "", "pose validator plugin (Eq. 3.11)"),
        Param("strategy", str, "ig_quality/bs_hr", "", "NBV strategy for modelling (overridden by --strategy)"),
        Param("resolution", float, 0.0, "m", "scene PVS voxel (0: 5 mm)", low=0.0),
        Param("pvs_layout", str, "auto", "", "scene PVS storage: a dense grid, hashed blocks (sparse), or auto "
              "(dense up to 32 M voxels)", choices=("auto", "dense", "sparse")),
        Param("max_views", int, 80, "", "view budget (overridden by --max-scans)", low=1),
        Param("model_scans", int, 12, "", "scan budget per modelled object", low=1),
        Param("model_coverage", float, 0.75, "", "stop modelling an object at this ĉ_m (Kriegel: 70-75 %)",
              low=0.0, high=1.0),
        Param("retry_scans", int, 3, "", "re-try recognition during the first modelling scans", low=0),
        Param("multi_view_views", int, 10, "", "view budget per ambiguous object", low=0),
        Param("view_render_fit", float, 0.8, "", "share of the model's rendered beams one view must confirm "
              "(N_m/N_r) to confirm a pose in multi-view recognition", low=0.0, high=1.0),
        Param("register", bool, True, "", "pose graph + re-integration after each view (noisy mobile base without "
              "a localisation laser)"),
        Param("noise", bool, True, "", "execute motions with the robot's positioning noise"),
        Param("flying_pixel_filter", float, 0.02, "", "drop beams with under 3 of 8 neighbours within this share of "
              "their depth (flying pixels; 0: off)", low=0.0, high=1.0),
        Param("median_px", int, 0, "px", "median-filter each depth image first (0: off)", choices=(0, 3, 5)),
        Param("organised_normals", bool, True, "", "normals from each depth image (else a neighbour search)"),
    )

    def work(self) -> Outcome:
        ctx, p = self.context, self.p
        config = ctx.config
        database = ObjectDatabase.open(Path(p["db"]).expanduser() if p["db"] else default_path())
        try:
            if p["seed_known"]:
                database.seed_from_world(ctx.sim)
            recognizer = ctx.registry.create("recognizer", p["recognizer"], {"min_q_h": p["min_q_h"]},
                                             self.tree_path or "<tree>", "recognizer")
            settings = SceneSettings(
                segmenter=(p["segmenter"], {"scale": p["scale"]}), recognizer=recognizer,
                validator=p["validator"],
                strategy=(config.strategy or p["strategy"], config.scoped("strategy")),
                seed=config.seed, resolution=p["resolution"] or None, pvs_layout=p["pvs_layout"],
                max_views=config.max_scans or p["max_views"], model_scans=p["model_scans"],
                model_coverage=p["model_coverage"], retry_scans=p["retry_scans"],
                multi_view_views=p["multi_view_views"], view_render_fit=p["view_render_fit"], noise=p["noise"],
                planner=config.planner,
                run_name=ctx.out_dir.name, register=p["register"], flying_pixel_filter=p["flying_pixel_filter"],
                median_px=p["median_px"], organised_normals=p["organised_normals"],
            )
            session = SceneSession(ctx.sim, ctx.registry, database, settings, progress=ctx.progress)
        except BaseException:
            database.close()
            raise
        run = SceneRun(session, database)
        ctx.state["scene"] = run
        self.write("scene", run)
        for key, value in (("done", False), ("explained", False), ("unknown", []), ("ambiguous", []),
                           ("object", None), ("object_done", False)):
            self.write(key, value)
        ctx.trace("decision", what="scene", database=str(database.path), known=database.names())
        return success(f"database {database.path} with {len(database)} objects")


class SceneOverview(ExploreBehaviour):
    """The first look: the world's overview view (line sensors: scan paths over the region); PVS initialised."""

    name = "scene_overview"
    reads = ("scene",)
    blocking = True

    def work(self) -> Outcome:
        views = _scene(self).viewing.overview()
        if not views:
            return failure("no overview view is reachable")
        for view in views:
            self.context.trace("scan", index=view.index + 1, purpose=view.purpose, returns=int(view.scan.hits.sum()))
        return success(f"{len(views)} overview views")


class SegmentScene(ExploreBehaviour):
    """Support plane, object clusters of every new view, associated to the scene's objects (Görner Ch. 3)."""

    name = "segment_scene"
    reads = ("scene",)
    blocking = True

    def work(self) -> Outcome:
        scene = _scene(self)
        if not scene.views:  # e.g. a patrolled table none of whose poses was reachable
            return success("no view to segment")
        objects = scene.segment()
        self.context.status_line = _status(self)
        if scene.table is None:
            return failure("no support plane found (the views show no table top or floor for the objects to stand on)")
        return success(f"{len(objects)} objects")


class LookCloser(ExploreBehaviour):
    """Aim views at the objects seen with too few points to be objects before they are called noise,
    and segment them."""

    name = "look_closer"
    reads = ("scene",)
    blocking = True
    params = (Param("views", int, 2, "", "views per object seen with too few points (0: none)", low=0),)

    def work(self) -> Outcome:
        scene = _scene(self)
        glimpsed, views = scene.viewing.look_closer(self.p["views"])
        self.context.status_line = _status(self)
        return success(f"{glimpsed} seen with too few points, {views} views aimed at them, "
                       f"{len(scene.too_small())} left too small")


class RecogniseObjects(ExploreBehaviour):
    """Recognise every object not yet explained against the database (PPF / FPFH / VFH)."""

    name = "recognise_objects"
    reads = ("scene",)
    blocking = True

    def work(self) -> Outcome:
        scene = _scene(self)
        count = 0
        for obj in scene.candidates():
            if obj.status in ("unexplained", "unknown", "ambiguous"):
                self.context.progress(f"object {obj.id}: matching {len(scene.models)} models")
                hypotheses = scene.recognition.recognise(obj)
                count += 1
                self.context.trace("decision", what="recognise", object=obj.id,
                                   hypotheses=[[h.model, round(h.q_h, 4)] for h in hypotheses[:5]])
        return success(f"{count} objects, {len(scene.models)} models")


class ValidateObjects(ExploreBehaviour):
    """q_h threshold and PVS votes (Eq. 3.10, 3.11): recognised, ambiguous or unknown."""

    name = "validate_objects"
    reads = ("scene",)
    writes = ("unknown", "ambiguous", "object")
    blocking = True  # render-and-compare and the PVS votes take seconds per object

    def work(self) -> Outcome:
        scene = _scene(self)
        for obj in scene.candidates():
            if obj.status in ("unexplained", "unknown", "ambiguous") and obj.hypotheses is not None:
                self.context.progress(f"object {obj.id}: q_h and PVS votes of {len(obj.hypotheses)} hypotheses")
                scene.recognition.validate(obj)
                self.context.trace("decision", what="validate", object=obj.id, status=obj.status, model=obj.model,
                                   q_h=obj.q_h, v_h=obj.v_h, q_h_margin=obj.q_h - scene.recognition.min_q_h,
                                   v_h_margin=obj.v_h - scene.recognition.validator_threshold, rejected=obj.rejected)
        unknown = [o.id for o in scene.by_status("unknown") if o in scene.candidates()]
        ambiguous = [o.id for o in scene.by_status("ambiguous") if o in scene.candidates()]
        self.write("unknown", unknown)
        self.write("ambiguous", ambiguous)
        self.write("object", None)
        self.context.status_line = _status(self)
        return success(f"{len(ambiguous)} ambiguous, {len(unknown)} unknown")


class MultiViewStep(ExploreBehaviour):
    """One more view of the current ambiguous object; per-view hypotheses fused on SE(3) (Sec. 5.6.2).

    An object the views leave unknown joins the ``unknown`` list, to be modelled in the same round
    (the next round would find it ambiguous again, with its view budget spent, and go round in
    circles until the rounds run out)."""

    name = "multi_view_step"
    reads = ("scene", "object", "unknown")
    writes = ("object_done", "unknown")
    blocking = True

    def work(self) -> Outcome:
        obj = _current(self, "ambiguous")
        if obj is None:
            self.write("object_done", True)
            return success("nothing ambiguous")
        done = _scene(self).recognition.multi_view_step(obj)
        self.write("object_done", done)
        if obj.status == "unknown":
            _to_model(self, [obj.id])
        self.context.status_line = _status(self)
        self.context.trace("decision", what="multi_view", object=obj.id, status=obj.status, views=obj.multi_views)
        return success(f"object {obj.id}: {obj.status}")


class ModelCluster(ExploreBehaviour):
    """One NBS iteration for the current unknown object (its box; the rest of the scene as obstacles)."""

    name = "model_cluster"
    reads = ("scene", "object")
    writes = ("object_done",)
    blocking = True

    def work(self) -> Outcome:
        obj = _current(self, "unknown", "modelling")
        if obj is None:
            self.write("object_done", True)
            return success("nothing to model")
        done = _scene(self).object_modelling.model_step(obj)
        self.write("object_done", done)
        self.context.status_line = _status(self)
        self.context.trace("scan", object=obj.id, purpose="model", scans=obj.modelling_scans,
                           coverage_estimate=obj.coverage_estimate)
        return success(f"object {obj.id}: {obj.modelling_scans} scans, ĉ_m {obj.coverage_estimate:.2f}")


class UpdateDatabase(ExploreBehaviour):
    """Add the modelled object (mesh, PPF/VFH descriptors, provenance, location); remember recognised ones."""

    name = "update_database"
    reads = ("scene", "object")
    blocking = True

    def work(self) -> Outcome:
        scene = _scene(self)
        obj = _current(self, "modelling")
        name = scene.object_modelling.finish_modelling(obj) if obj is not None else None
        scene.database_update.remember_locations()
        if name is not None:
            self.context.trace("decision", what="database", object=obj.id, added=name)
            return success(f"added {name}")
        return success("locations recorded")


class LearnObject(ExploreBehaviour):
    """Görner: learn the current unknown object from the views already taken (mesh + database)."""

    name = "learn_object"
    reads = ("scene", "object")
    blocking = True

    def work(self) -> Outcome:
        obj = _current(self, "unknown")
        if obj is None:
            return success("nothing to learn")
        name = _scene(self).object_modelling.learn_from_views(obj)
        if name is None:
            return success(f"object {obj.id}: too few points, left unknown")
        self.context.trace("decision", what="database", object=obj.id, added=name)
        return success(f"added {name}")


class SettleFromViews(ExploreBehaviour):
    """Resolve the current ambiguous object with the views already taken (fused per-view poses),
    and the objects split off it when its model leaves points unexplained; one left unknown joins
    the ``unknown`` list, to be learned."""

    name = "settle_from_views"
    reads = ("scene", "object", "unknown")
    writes = ("unknown",)
    blocking = True

    def work(self) -> Outcome:
        obj = _current(self, "ambiguous")
        if obj is None:
            return success("nothing ambiguous")
        scene = _scene(self)
        before = {o.id for o in scene.objects}
        settled = {obj.id: scene.recognition.settle_from_views(obj)}
        while split := [o for o in scene.candidates() if o.id not in before and o.id not in settled]:
            settled[split[0].id] = scene.recognition.settle_from_views(split[0])
        _to_model(self, [i for i, status in settled.items() if status == "unknown"])
        self.context.status_line = _status(self)
        return success(", ".join(f"object {i}: {status}" for i, status in settled.items()))


class CheckExplained(ExploreBehaviour):
    """Write ``explained`` (every object explained) and ``done`` (explained, out of views or stuck)."""

    name = "check_explained"
    reads = ("scene",)
    writes = ("done", "explained")

    def work(self) -> Outcome:
        scene = _scene(self)
        explained = scene.all_explained
        done = scene.budget_left <= 0 or ((explained or not scene.open_objects()) and not scene.awaiting_closer_look())
        self.write("explained", explained)
        self.write("done", done)
        found = scene.candidates()
        return success(f"{sum(o.explained for o in found)} of {len(found)} explained")


class RegisterViews(ExploreBehaviour):
    """gtsam pose graph over all views (odometry + ICP + loop closures); re-integrate PVS and clusters."""

    name = "register_views"
    reads = ("scene",)
    blocking = True

    def work(self) -> Outcome:
        scene = _scene(self)
        if len(scene.views) < 2:
            return success("fewer than two views")
        result = scene.viewing.correct_poses()
        edges = sum(e.kind != "odometry" for e in result.edges)
        return success(f"{len(scene.views)} poses, {edges} ICP edges")


class SurroundTable(ExploreBehaviour):
    """Görner's exploration step: views from up to 12 observation poses around a table's centre.

    The focus points are the known tables (environment boxes at table height, Görner's
    assumption that table positions are known); ``table`` picks one by index or name.
    """

    name = "surround_table"
    reads = ("scene", "table")
    blocking = True
    params = (
        Param("d_min", float, 0.7, "m", "closest observation distance (Görner 0.7 m)", low=0.1),
        Param("d_max", float, 1.5, "m", "farthest observation distance (Görner 1.5 m)", low=0.1),
        Param("step_deg", float, 30.0, "deg", "angle between observation poses (Görner 0.5 rad)", low=1.0),
    )

    def work(self) -> Outcome:
        run = self.need("scene")
        scene = run.session
        tables = known_tables(scene.sim)
        table = self.read("table")
        if not tables:
            return failure("the world has no table to surround")
        focus = tables[table] if isinstance(table, str) and table in tables else list(tables.values())[0]
        name = next(k for k, v in tables.items() if v is focus)
        views = surround(scene, focus, self.p["d_min"], self.p["d_max"], math.radians(self.p["step_deg"]), repr(name))
        entry: dict[str, Any] = {"table": name, "views": len(views)}
        if not views and scene.budget_left > 0:
            entry["unreachable"] = True
        run.patrol.setdefault("tables", []).append(entry)
        return success(f"{name}: {len(views)} views" + (" (no observation pose reachable)" if not views else ""))


class ListTables(ExploreBehaviour):
    """Write ``tables``: the names of the known tables to patrol (round robin order)."""

    name = "list_tables"
    reads = ("scene",)
    writes = ("tables",)

    def work(self) -> Outcome:
        names = list(known_tables(_scene(self).sim))
        self.write("tables", names)
        return success(", ".join(names) or "no tables") if names else failure("the world has no tables")


def _status(behaviour: ExploreBehaviour) -> str:
    stats = behaviour.need("scene").live_stats()
    return "  ".join(f"{k} {v}" for k, v in stats.items())


PLUGINS = [
    StartScene,
    SceneOverview,
    SegmentScene,
    LookCloser,
    RecogniseObjects,
    ValidateObjects,
    MultiViewStep,
    ModelCluster,
    UpdateDatabase,
    LearnObject,
    SettleFromViews,
    CheckExplained,
    RegisterViews,
    ListTables,
    SurroundTable,
]
