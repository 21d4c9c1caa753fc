"""Scene exploration: explained objects, pose errors, recognition precision, fusion, pose graph.

Parts (``--part``, default all but ``robots``):

* ``scene``: Kriegel's scene exploration (``SceneSession``) on ``worlds/tabletop.yaml`` with a
  fresh database holding the two known objects (duck, mug), then on
  ``worlds/tabletop_rearranged.yaml`` with the database the first run left behind. Per object:
  recognised (model, pose error mm / deg, surface error for symmetric shapes) or modelled
  (coverage c_a); per scene: all explained, views, time, wrong matches and where they were
  rejected (q_h threshold, PVS votes).
* ``recognition``: single views of both arrangements (several seeds, random viewpoints),
  every cluster against a partial database (duck, mug) and the full one (all six ground-truth
  meshes) with PPF, FPFH + RANSAC and VFH: precision / recall of the accepted matches after
  the q_h threshold and PVS validation, wrong matches proposed / accepted, and Görner's
  pair-counted precision (pairs of observations given the same model that are the same object).
* ``fusion``: multi-view fusion with real per-view recogniser hypotheses: 10 views around the
  duck and the mug of ``scene_small``, the error of the fused pose after each view.
* ``pose_graph``: a mobile base without a localisation laser (robot plugin's noisy execution)
  surrounds every table of ``scene_small_odometry`` (``--graph-worlds``, e.g. also ``two_tables``; several seeds):
  scan-pose error of raw odometry vs the incremental gtsam pose graph, and what
  re-integration at the corrected poses does to the PVS (share of the objects' true surface
  in voxels the PVS calls free).
* ``robots``: the scene exploration with the arm (``workcell``), the mobile manipulator
  (``scene_small_mm``) and the mobile base (``scene_small_mobile``).

    .venv/bin/python benchmarks/scene.py                    # scene, recognition, fusion, pose_graph
    .venv/bin/python benchmarks/scene.py --part robots      # the three robots (slow: tens of minutes)
    .venv/bin/python benchmarks/scene.py --json             # rows as JSON only
    .venv/bin/python benchmarks/scene.py --seeds 3
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")

KNOWN = ("duck", "mug")


def _log(args: argparse.Namespace, text: str) -> None:
    if not args.json:
        print(text, flush=True)


def _world(name: str, args: argparse.Namespace) -> Any:
    """The world ``name`` with the sensor profile of ``--profile`` and the ``--sensor-param`` values
    (none: the world's own)."""
    import dataclasses

    from explore.sim import load_world_spec

    spec = load_world_spec(name)
    params = dict(args.sensor_params)
    if args.profile is not None:
        params["profile"] = args.profile
    if not params:
        return spec
    sensor = dataclasses.replace(spec.sensor, params={**spec.sensor.params, **params})
    return dataclasses.replace(spec, sensor=sensor)


def _processing(args: argparse.Namespace) -> dict[str, Any]:
    """The depth processing of ``--flying-pixel-filter`` and ``--median`` as session settings (none: the
    defaults)."""
    pairs = (("flying_pixel_filter", args.flying_pixel_filter), ("median_px", args.median),
             ("organised_normals", args.organised_normals))
    return {k: v for k, v in pairs if v is not None}


def _depth_processing(args: argparse.Namespace) -> Any:
    from explore.perception import DepthProcessing

    return DepthProcessing(**_processing(args))


def _round(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (round(v, 4) if isinstance(v, float) and math.isfinite(v) else v) for k, v in row.items()}


# -- part 1: the scene ------------------------------------------------------------------------
def part_scene(args: argparse.Namespace, registry: Any) -> list[dict[str, Any]]:
    from explore.perception import ObjectDatabase
    from explore.scene import SceneSession
    from explore.sim import Simulation

    rows = []
    db_path = Path(tempfile.mkdtemp(prefix="explore-scene-")) / "objects.db"
    for run, world in enumerate(("tabletop", "tabletop_rearranged")):
        started = time.perf_counter()
        with Simulation(_world(world, args), registry) as sim, ObjectDatabase.open(db_path) as db:
            db.seed_from_world(sim)
            session = SceneSession(sim, registry, db, seed=args.seed, run_name=f"bench{run + 1}", **_processing(args),
                                   progress=(lambda text: _log(args, f"    {text}")) if args.verbose else None)
            metrics = session.run()
        elapsed = time.perf_counter() - started
        for obj in metrics["objects"]:
            rows.append(_round({"part": "scene", "world": world, "run": run + 1, **{
                k: obj.get(k) for k in ("name", "known", "result", "model", "correct_model", "pose_error_mm",
                                        "pose_error_deg", "surface_error_mm", "fused_error_mm", "fused_error_deg",
                                        "coverage", "coverage_estimate", "recognised_after_views", "multi_views",
                                        "modelling_scans")}}))
        rows.append(_round({"part": "scene", "world": world, "run": run + 1, "name": "(scene)",
                            "all_explained": metrics["all_explained"], "views": metrics["views"],
                            "time_s": elapsed, "wrong_proposed": metrics["wrong_matches"]["proposed"],
                            "wrong_rejected_q_h": metrics["wrong_matches"]["rejected_q_h"],
                            "wrong_rejected_colour": metrics["wrong_matches"]["rejected_colour"],
                            "wrong_rejected_pvs": metrics["wrong_matches"]["rejected_pvs"],
                            "wrong_accepted": metrics["wrong_matches"]["accepted"],
                            "precision": metrics["recognition_precision"], "recall": metrics["recognition_recall"],
                            "added": len(metrics["added_to_database"])}))
        _log(args, f"  {world}: all explained {metrics['all_explained']}, {metrics['views']} views, {elapsed:.0f} s")
    return rows


# -- part 2: recognition precision / recall ----------------------------------------------------
def _views(rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    eyes = []
    for _ in range(count):
        a = rng.uniform(-math.pi, math.pi)
        r = rng.uniform(0.75, 1.05)
        eyes.append((np.array([r * math.cos(a), 0.8 * r * math.sin(a), rng.uniform(1.15, 1.4)]),
                     np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08), 0.65])))
    return eyes


def part_recognition(args: argparse.Namespace, registry: Any) -> list[dict[str, Any]]:
    from explore.core import look_at
    from explore.mapping import PVS
    from explore.perception import Model, object_frame, pvs_votes
    from explore.sim import Simulation

    segmenter = registry.create("segmenter", "plane_clusters", {"scale": "table"})
    methods = {m: registry.create("recognizer", m) for m in ("ppf", "fpfh_ransac", "vfh_mean_distance")}
    records: dict[tuple[str, str], list[tuple[str, str | None, str]]] = {}
    wrong: dict[tuple[str, str], dict[str, int]] = {}
    models_full: list[Model] = []
    processing = _depth_processing(args)
    for world in ("tabletop", "tabletop_rearranged"):
        with Simulation(_world(world, args), registry) as sim:
            if args.sensed_training:  # as the scene session does: training views through the world's sensor
                for recognizer in methods.values():
                    recognizer.sense_with(sim.sensor, processing)
            if not models_full:  # model frames of the first arrangement, as a database holds them
                models_full = [Model(b.name, object_frame(b)[1]) for b in sim.objects()]
            bodies = {b.name: b for b in sim.objects()}
            for seed in range(args.seeds):
                rng = np.random.default_rng(1000 + seed)
                for eye, target in _views(rng, args.views):
                    scan = processing.apply(sim.sensor.acquire(sim, look_at(eye, target), rng))
                    pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.005)
                    pvs.integrate(scan)
                    for cluster in segmenter.segment(scan).clusters:
                        truth = min(bodies, key=lambda n: float(np.linalg.norm(
                            cluster.centroid - 0.5 * np.sum(bodies[n].mesh.bounds, axis=0))))
                        if len(cluster.points) < 60:
                            continue
                        for database in ("partial", "full"):
                            models = [m for m in models_full if database == "full" or m.name in KNOWN]
                            vertices = {m.name: m.mesh.vertices for m in models}
                            for name, recognizer in methods.items():
                                hypotheses = recognizer.recognize(cluster, models, scan)
                                decision = None
                                count = wrong.setdefault((name, database), {"proposed": 0, "rejected_q_h": 0,
                                                                            "rejected_pvs": 0, "accepted": 0})
                                kept = {id(h) for h in recognizer.accept(hypotheses)}
                                for h in hypotheses:
                                    ok = id(h) in kept and pvs_votes(pvs, vertices[h.model], h.pose).accepted
                                    if h.model != truth:
                                        count["proposed"] += 1
                                        if id(h) not in kept:
                                            count["rejected_q_h"] += 1
                                        elif not ok:
                                            count["rejected_pvs"] += 1
                                    if ok and decision is None:
                                        decision = h.model
                                if decision is not None and decision != truth:
                                    count["accepted"] += 1
                                known = truth in {m.name for m in models}
                                records.setdefault((name, database), []).append((truth, decision,
                                                                                 "known" if known else "unknown"))
        _log(args, f"  recognition: {world} done")
    rows = []
    for (name, database), items in sorted(records.items()):
        tp = sum(1 for t, d, _ in items if d == t)
        fp = sum(1 for t, d, _ in items if d is not None and d != t)
        fn = sum(1 for t, d, k in items if k == "known" and d != t)
        tn = sum(1 for _, d, k in items if k == "unknown" and d is None)
        labelled = [(t, d) for t, d, _ in items if d is not None]
        same = [(a[0] == b[0]) for i, a in enumerate(labelled) for b in labelled[i + 1:] if a[1] == b[1]]
        rows.append(_round({
            "part": "recognition", "recognizer": name, "database": database, "observations": len(items),
            "precision": tp / (tp + fp) if tp + fp else math.nan, "recall": tp / (tp + fn) if tp + fn else math.nan,
            "unknown_rejected": (tn / unknown) if (unknown := sum(1 for _, _, k in items if k == "unknown"))
            else math.nan,
            "pair_precision": float(np.mean(same)) if same else math.nan, **{
                f"wrong_{k}": v for k, v in wrong[(name, database)].items()}}))
    return rows


# -- part 3: multi-view fusion ------------------------------------------------------------------
def part_fusion(args: argparse.Namespace, registry: Any) -> list[dict[str, Any]]:
    from explore.core import pose_error
    from explore.perception import ObjectDatabase, fuse_poses
    from explore.scene import SceneSession, model_truth
    from explore.sim import Simulation

    rows = []
    for seed in range(args.seeds):
        with Simulation(_world("scene_small", args), registry) as sim, \
                ObjectDatabase.open(Path(tempfile.mkdtemp(prefix="explore-fusion-")) / "o.db") as db:
            db.seed_from_world(sim)
            session = SceneSession(sim, registry, db, seed=seed, **_processing(args))
            session.viewing.overview()
            session.segment()
            session.recognition.recognise_all()
            for obj in session.candidates():
                if obj.model not in KNOWN:
                    continue
                truth, _ = model_truth(db, obj.model, sim)
                model = obj.model
                hypotheses = []
                for taken in range(1, 11):
                    view = session.viewing.next_view(obj, f"fusion {model}")
                    if view is None:
                        break
                    session.segment()
                    found = session.recognition.view_hypothesis(obj, view.index, [model])
                    if found is not None:
                        hypotheses.append(found)
                    if hypotheses:
                        fused = fuse_poses([h.pose for h in hypotheses], [h.q_h for h in hypotheses])
                        t_err, r_err = pose_error(fused.pose, truth)
                        r_err = math.degrees(r_err)
                        rows.append(_round({"part": "fusion", "seed": seed, "object": model,
                                            "views": taken, "hypotheses": len(hypotheses),
                                            "members": len(fused.members), "error_mm": 1e3 * t_err,
                                            "error_deg": r_err}))
        _log(args, f"  fusion: seed {seed} done")
    return rows


# -- part 4: pose graph of a noisy mobile base ---------------------------------------------------
def _free_share(pvs: Any, sim: Any) -> float:
    """Share of the objects' true surface samples that the PVS calls free (p < 0.25): wrong poses smear it."""
    from explore.mapping import sample_surface

    points = np.vstack([sample_surface(b.mesh, 2e-5, seed=0)[0] for b in sim.objects()])
    return float(np.mean(pvs.probability(points) < 0.25))


def part_pose_graph(args: argparse.Namespace, registry: Any) -> list[dict[str, Any]]:
    from explore.mapping import PVS
    from explore.perception import ObjectDatabase, rebase_scan
    from explore.scene import SceneSession, known_tables, pose_graph_errors, surround
    from explore.sim import Simulation

    rows = []
    for world in args.graph_worlds:
        for seed in range(args.seeds):
            started = time.perf_counter()
            with Simulation(_world(world, args), registry) as sim, \
                    ObjectDatabase.open(Path(tempfile.mkdtemp(prefix="explore-graph-")) / "o.db") as db:
                session = SceneSession(sim, registry, db, seed=seed, **_processing(args))
                if sim.spec.overview is not None:
                    session.viewing.overview()
                for focus in known_tables(sim).values():  # Görner's surround step at every table
                    surround(session, focus, 0.7, 1.5, 0.5)
                errors = pose_graph_errors(session)
                odometry = PVS.for_region(sim.spec.region_min, sim.spec.region_max, session.resolution)
                for view in session.views:
                    odometry.integrate(rebase_scan(view.scan, view.believed))
                row = {"part": "pose_graph", "world": world, "seed": seed, **errors,
                       "ratio_mm": errors["corrected_mm"] / errors["odometry_mm"],
                       "ratio_deg": errors["corrected_deg"] / errors["odometry_deg"],
                       "relative_ratio_mm": errors["relative_corrected_mm"] / errors["relative_odometry_mm"],
                       "relative_ratio_deg": errors["relative_corrected_deg"] / errors["relative_odometry_deg"],
                       "localised": len(session.graph.localised),
                       "surface_free_odometry": _free_share(odometry, sim),
                       "surface_free_corrected": _free_share(session.pvs, sim),
                       "collisions": session.mover.collisions, "time_s": time.perf_counter() - started}
            rows.append(_round(row))
            _log(args, f"  pose graph {world} seed {seed}: {errors['odometry_mm']:.0f} mm / "
                       f"{errors['odometry_deg']:.2f} deg -> {errors['corrected_mm']:.0f} mm / "
                       f"{errors['corrected_deg']:.2f} deg")
    return rows


# -- part 5: the robots ----------------------------------------------------------------------------
def part_robots(args: argparse.Namespace, registry: Any) -> list[dict[str, Any]]:
    from explore.perception import ObjectDatabase
    from explore.scene import SceneSession
    from explore.sim import Simulation

    rows = []
    for world in ("workcell", "scene_small_mm", "scene_small_mobile"):
        started = time.perf_counter()
        with Simulation(_world(world, args), registry) as sim, \
                ObjectDatabase.open(Path(tempfile.mkdtemp(prefix="explore-robot-")) / "o.db") as db:
            db.seed_from_world(sim)
            session = SceneSession(sim, registry, db, seed=args.seed, **_processing(args),
                                   progress=(lambda text: _log(args, f"    {text}")) if args.verbose else None)
            metrics = session.run()
        for obj in metrics["objects"]:
            rows.append(_round({"part": "robots", "world": world, "robot": sim.spec.robot.plugin, **{
                k: obj.get(k) for k in ("name", "result", "model", "pose_error_mm", "pose_error_deg", "coverage")}}))
        rows.append(_round({"part": "robots", "world": world, "robot": sim.spec.robot.plugin, "name": "(scene)",
                            "all_explained": metrics["all_explained"], "views": metrics["views"],
                            "collisions": metrics["collisions"], "time_s": time.perf_counter() - started,
                            **({"pose_graph": metrics["pose_graph"]} if "pose_graph" in metrics else {})}))
        _log(args, f"  {world}: all explained {metrics['all_explained']}, {metrics['views']} views")
    return rows


PARTS = {"scene": part_scene, "recognition": part_recognition, "fusion": part_fusion, "pose_graph": part_pose_graph,
         "robots": part_robots}


def _table(rows: list[dict[str, Any]]) -> None:
    by_part: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_part.setdefault(row["part"], []).append(row)
    for part, items in by_part.items():
        columns = [k for k in dict.fromkeys(k for r in items for k in r) if k != "part"]
        print(f"\n## {part}")
        print(" | ".join(columns))
        for r in items:
            print(" | ".join("" if r.get(c) is None else str(r.get(c)) for c in columns))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", action="append", choices=sorted(PARTS), help="parts to run (repeatable)")
    parser.add_argument("--seeds", type=int, default=2, help="seeds of the recognition, fusion and pose-graph parts")
    parser.add_argument("--views", type=int, default=3, help="views per seed and arrangement (recognition)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scene and robot runs")
    parser.add_argument("--graph-worlds", nargs="+", default=["scene_small_odometry"],
                        help="worlds of the pose-graph part (a mobile base; two_tables takes minutes per seed)")
    parser.add_argument("--profile", choices=("ideal", "kinect", "tof"),
                        help="the depth camera's profile (default: each world's own)")
    parser.add_argument("--sensor-param", action="append", default=[], metavar="KEY=VALUE",
                        help="a sensor parameter over the profile's, e.g. flying_pixels=0 (repeatable)")
    parser.add_argument("--flying-pixel-filter", type=float, help="drop beams with under 3 of 8 neighbours within this "
                        "share of their depth (0: off; default: the session's)")
    parser.add_argument("--organised-normals", action=argparse.BooleanOptionalAction, default=None,
                        help="normals from the depth images (default: the session's)")
    parser.add_argument("--sensed-training", action=argparse.BooleanOptionalAction, default=True,
                        help="render the recognisers' training views through the world's sensor (VFH)")
    parser.add_argument("--median", type=int, choices=(0, 3, 5), help="median filter of the depth images (px)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON only")
    parser.add_argument("--verbose", action="store_true", help="show the sessions' progress")
    args = parser.parse_args(argv)
    from explore.core import BadInput, parse_assignment
    from explore.motion import work_clock
    from explore.runtime import Registry

    try:
        args.sensor_params = [parse_assignment(item, "--sensor-param") for item in args.sensor_param]
    except BadInput as error:
        parser.error(str(error))
    registry = Registry.load()
    try:  # the sensor's parameters as every part's worlds will take them
        spec = _world("tabletop", args).sensor
        registry.create("sensor", spec.plugin, spec.params, "--sensor-param")
    except BadInput as error:
        parser.error(str(error))
    parts = args.part or ["scene", "recognition", "fusion", "pose_graph"]
    rows: list[dict[str, Any]] = []
    for part in parts:
        _log(args, f"# {part}")
        with work_clock():  # planning limits in work done: the same seed gives the same rows under any load
            rows.extend(PARTS[part](args, registry))
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        _table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
