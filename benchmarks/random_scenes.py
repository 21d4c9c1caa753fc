"""Scene exploration on tables no part of the project was tuned on: the scene targets on unseen objects.

Each scene is a table (``pybullet_data``'s ``table.urdf``, as in ``tabletop``) with five objects
drawn from ``random_urdfs`` with a fixed seed per scene index, leaving out the 54 ``random_urdfs``
objects that a shipped world, a benchmark or a test named when this benchmark was written (a fixed
list, so that a scene stays the same from commit to commit; a drawn object that one of those files
names since is reported). The first two are known (in the database at the start),
the other three unknown; each gets a size of 6-11 cm, a random yaw and one of five cells on the
table. The free-flying Kinect-profile camera of ``tabletop`` explores it with the ``scene_exploration``
tree (as ``explore run``) and a fresh database. ``--like WORLD`` keeps a shipped world (its table,
region, robot and sensor) and puts an unseen shape at the place of each of its objects, known where
the world's object is known: the same tables under a mobile base or an arm.

Per scene: status, objects explained, known objects recognised, within 5 mm / 2 degrees, on their
surface within 5 mm (a symmetric object turned about its axis), objects taken for another object's
model (and among them those of a near-duplicate shape: the two surfaces within 5 mm of each other on
average, both ways), views and time.

    .venv/bin/python benchmarks/random_scenes.py --scenes 0-7            # a table, then totals
    .venv/bin/python benchmarks/random_scenes.py --scenes 3 --keep worlds_out/   # also write the worlds
    .venv/bin/python benchmarks/random_scenes.py --scenes 0-3 --like scene_small_mobile   # a noisy mobile base
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from reproduce_kriegel import parse_seeds

ROOT = Path(__file__).resolve().parents[1]
NAMED = frozenset("""017 025 026 028 077 079 096 099 116 127 132 145 156 172 177 226 277 278 292 321 337 344 352 358
    364 370 455 466 497 510 578 585 588 596 600 623 626 637 638 651 685 703 711 715 743 768 789 793 838 845 928 941
    949 990""".split())
CELLS = ((-0.27, -0.15), (0.0, -0.17), (0.27, -0.13), (-0.15, 0.15), (0.15, 0.16))
KNOWN = 2


def named_elsewhere() -> set[str]:
    """The ``random_urdfs`` objects that a world, benchmark or test of the project names."""
    names = set()
    for folder in ("worlds", "benchmarks", "tests"):
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in (".yaml", ".py", ".json", ".txt") and path.is_file():
                names |= set(re.findall(r"random_urdfs/(\d{3})", path.read_text(errors="ignore")))
    return names


def scene_world(index: int, like: str | None = None) -> dict[str, Any]:
    """The world of scene ``index``: a table with five unseen ``random_urdfs`` objects, two of them known;
    with ``like``, that shipped world with each of its objects replaced by an unseen shape at its place
    (known where the world's object is known), its table, region, robot and sensor kept."""
    rng = np.random.default_rng(1000 + index)
    pool = [f"{i:03d}" for i in range(1000) if f"{i:03d}" not in NAMED]
    template = yaml.safe_load((ROOT / "worlds" / f"{like}.yaml").read_text()) if like else None
    places = ([(o["position"], o["on_top_of"], bool(o.get("known"))) for o in template["objects"]] if template
              else [(list(cell), "table", k < KNOWN) for k, cell in enumerate(CELLS)])
    objects = []
    for number, (position, support, known) in zip(rng.choice(pool, len(places), replace=False), places, strict=True):
        size, yaw = float(rng.uniform(0.06, 0.11)), float(rng.uniform(0.0, 360.0))
        objects.append({"name": f"r{number}", "source": f"random_urdfs/{number}/{number}.urdf", "size": round(size, 3),
                        "rpy_deg": [0, 0, round(yaw)], "position": position, "on_top_of": support,
                        **({"known": True} if known else {})})
    if template:
        return {**template, "name": f"random_{like}_{index}", "objects": objects,
                "description": f"{like} with unseen random_urdfs objects (benchmarks/random_scenes.py, scene {index})."}
    return {
        "name": f"random_scene_{index}",
        "description": f"Five unseen random_urdfs objects (benchmarks/random_scenes.py, scene {index}).",
        "environment": [{"name": "table", "source": "table/table.urdf", "position": [0.0, 0.0, 0.3125]}],
        "objects": objects,
        "region": {"min": [-0.45, -0.32, 0.625], "max": [0.45, 0.32, 0.90]},
        "robot": {"plugin": "free_flyer"},
        "sensor": {"plugin": "depth_camera", "params": {"profile": "kinect", "width": 320, "height": 240,
                                                         "min_range": 0.3, "max_range": 2.0}},
        "overview": {"eye": [0.0, -0.9, 1.35], "target": [0.0, 0.0, 0.65]},
    }


def run_scene(world_path: Path, seed: int, registry: Any) -> dict[str, Any]:
    """Run ``scene_exploration`` on one scene with a fresh database; the row of the table."""
    from explore.runtime import RunConfig, execute

    started = time.perf_counter()
    folder = Path(tempfile.mkdtemp(prefix="explore-random-scene-"))
    run = execute(RunConfig(tree="scene_exploration", world=str(world_path), seed=seed, out=folder / "run",
                            settings={"start_scene.db": str(folder / "objects.db")}), registry)
    metrics = run.metrics
    known = [o for o in metrics["objects"] if o["known"]]
    recognised = [o for o in known if o["result"] == "recognised" and o.get("correct_model")]
    wrong = [o for o in metrics["objects"] if o["result"] == "recognised" and not o.get("correct_model")]
    return {
        "scene": world_path.stem, "status": run.status,
        "explained": f"{metrics['objects_explained']}/{metrics['objects_total']}",
        "known_recognised": f"{len(recognised)}/{len(known)}",
        "known_within_5mm_2deg": sum(o["pose_error_mm"] <= 5.0 and o["pose_error_deg"] <= 2.0 for o in recognised),
        "up_to_symmetry": sum(o.get("symmetric_error_mm", 99.0) <= 5.0 and o.get("symmetric_error_deg", 99.0) <= 2.0
                              for o in recognised),
        "known_on_surface_5mm": sum(o.get("surface_error_mm", 99.0) <= 5.0 for o in recognised),
        "wrong_accepted": len(wrong),
        "wrong_same_shape": sum(o.get("wrong_model_fit_mm", 99.0) <= 5.0 for o in wrong),
        "views": metrics["views"], "collisions": metrics.get("collisions", 0),
        "time_s": round(time.perf_counter() - started, 1),
        "objects": [{k: o.get(k) for k in ("name", "known", "result", "model", "pose_error_mm", "pose_error_deg",
                                           "symmetric_error_mm", "symmetric_error_deg", "surface_error_mm",
                                           "wrong_model_fit_mm", "coverage")}
                    for o in metrics["objects"]],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="0-3", help="scene indices, e.g. 0-7 or 1,4")
    parser.add_argument("--seed", type=int, default=0, help="the runs' seed")
    parser.add_argument("--like", help="a shipped world whose objects are replaced (its robot and table kept)")
    parser.add_argument("--keep", type=Path, help="write the worlds into this folder")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args(argv)
    try:
        indices = parse_seeds(args.scenes)
    except ValueError:
        parser.error(f"--scenes: {args.scenes!r} is not a list of indices or ranges such as 0-7 or 1,4")
    if args.like and not (ROOT / "worlds" / f"{args.like}.yaml").is_file():
        parser.error(f"--like: no shipped world {args.like!r} (see worlds/)")
    from explore.runtime import Registry

    registry = Registry.load()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="explore-random-worlds-"))
    folder.mkdir(parents=True, exist_ok=True)
    named = named_elsewhere()
    rows = []
    for index in indices:
        world = scene_world(index, args.like)
        if seen := [o["name"] for o in world["objects"] if o["name"][1:] in named]:
            print(f"scene {index}: {', '.join(seen)} named by the project since: no longer unseen", file=sys.stderr)
        path = folder / f"{world['name']}.yaml"
        path.write_text(yaml.safe_dump(world, sort_keys=False, default_flow_style=None))
        names = [o["name"] + (" (known)" if o.get("known") else "") for o in world["objects"]]
        print(f"scene {index}: {', '.join(names)}", file=sys.stderr, flush=True)
        rows.append(run_scene(path, args.seed, registry))
        print(f"  {rows[-1]['status']}, {rows[-1]['views']} views, {rows[-1]['time_s']} s", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    columns = ("scene", "status", "explained", "known_recognised", "known_within_5mm_2deg", "up_to_symmetry",
               "known_on_surface_5mm", "wrong_accepted", "wrong_same_shape", "views", "collisions", "time_s")
    print("| " + " | ".join(columns) + " |")
    print("|" + " --- |" * len(columns))
    for row in rows:
        print("| " + " | ".join(str(row[c]) for c in columns) + " |")
        for obj in row["objects"]:
            if obj["result"] not in ("recognised", "modelled") or (obj["known"] and obj["result"] != "recognised"):
                print(f"|   {obj['name']} ({'known' if obj['known'] else 'unknown'}): {obj['result']} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
