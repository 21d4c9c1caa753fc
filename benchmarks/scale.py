"""How a scene run's cost grows with the number of objects and the room (issue 23, item 3).

Each room of :mod:`scale_worlds` (1 table / 5 objects, 2 / 10, 4 / 20, 4 / 40 by default:
objects and room volume grow together) is explored with ``explore run table_patrol`` at 5 mm
in the sparse PVS over the whole room, by each robot of ``--robots``, one child process per
run with a fresh object database. Per run: wall time, peak memory (the child's maximum
resident set), views, the scene outcome (objects explained, known objects recognised and
their map pose errors, wrong matches accepted) and the time split of the scene session
(motion, registration and re-integration, recognition, ...). The growth exponent is the
slope of log(wall time) over log(objects); ``scale.png`` plots both on log-log axes.

    .venv/bin/python benchmarks/scale.py                                   # mobile base, 4 rooms
    .venv/bin/python benchmarks/scale.py --robots mobile_base mobile_manipulator --rooms 1x5 2x10
    .venv/bin/python benchmarks/scale.py --json                            # rows as JSON only
    .venv/bin/python benchmarks/scale.py --replot runs/scale/scale.json    # the plot again
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("MPLBACKEND", "Agg")

from scale_worlds import GROWTH, ROBOTS, room_problem, room_size, write_world  # noqa: E402

SPLIT = ("motion_s", "scan_s", "integrate_s", "registration_s", "segment_s", "recognise_s", "validate_s", "database_s")
PARTS = (*(k.removesuffix("_s") for k in SPLIT), "other")  # other: learning the unknown objects, ticks


def _run(world: Path, out: Path, seed: int, timeout: float) -> tuple[float, float, int]:
    """(wall s, peak MB, exit code) of one ``explore run table_patrol`` in a child process."""
    explore = Path(sys.executable).with_name("explore")
    command = [str(explore), "run", "table_patrol", "--world", str(world), "--seed", str(seed), "-q",
               "--out", str(out / "run"), "--set", f"start_scene.db={out / 'objects.db'}"]
    started = time.perf_counter()
    with open(out / "run.log", "w") as log:
        child = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = started + timeout
        while True:
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                os.killpg(child.pid, signal.SIGKILL)
                pid, status, usage = os.wait4(child.pid, 0)
                break
            time.sleep(0.5)
    return time.perf_counter() - started, usage.ru_maxrss / 1024.0, os.waitstatus_to_exitcode(status)


def _row(tables: int, objects: int, robot: str, wall: float, peak: float, code: int, run: Path) -> dict[str, Any]:
    width, depth = room_size(tables)
    row: dict[str, Any] = {"tables": tables, "objects": objects, "robot": robot,
                           "room_m3": round(width * depth * 1.1, 1), "wall_s": round(wall, 1), "peak_mb": round(peak),
                           "exit": code}
    try:
        metrics = json.loads((run / "metrics.json").read_text())
    except (OSError, ValueError):
        return {**row, "status": "no metrics"}
    known = [o for o in metrics["objects"] if o["known"]]
    good = [o for o in known if o.get("correct_model") and o.get("map_error_mm") is not None
            and o["map_error_mm"] <= 5.0 and o["map_error_deg"] <= 2.0]
    errors = [(o["map_error_mm"], o["map_error_deg"]) for o in known if o.get("map_error_mm") is not None]
    symmetric = [o for o in known if o.get("correct_model")  # within 5 mm / 2 deg up to the model's symmetries
                 and o.get("symmetric_map_error_mm", math.inf) <= 5.0
                 and o.get("symmetric_map_error_deg", math.inf) <= 2.0]
    row.update(
        status=metrics["status"], views=metrics["views"], travel_m=round(metrics["travel_m"], 1),
        collisions=metrics["collisions"],
        explained=f"{metrics['objects_explained']}/{metrics['objects_total']}",
        missed=sum(o["result"] == "missed" for o in metrics["objects"]),
        known_recognised=f"{sum(o['result'] == 'recognised' for o in known)}/{len(known)}",
        known_within_5mm_2deg=f"{len(good)}/{len(known)}",
        up_to_symmetry=f"{len(symmetric)}/{len(known)}",
        worst_map_error=None if not errors else [round(max(e[0] for e in errors), 1),
                                                 round(max(e[1] for e in errors), 2)],
        wrong_accepted=metrics["wrong_matches"]["accepted"],
        wrong_rejected_colour=metrics["wrong_matches"].get("rejected_colour", 0),
        # objects recognised as another object's model, and of those the ones taken for a model of the
        # same shape: the wrong model lies within 5 mm of the object's surface (no geometric recogniser
        # can tell them apart)
        wrong_models=sum(o.get("correct_model") is False for o in metrics["objects"]),
        wrong_same_shape=sum(o.get("correct_model") is False and o.get("wrong_model_fit_mm", math.inf) <= 5.0
                             for o in metrics["objects"]),
        # known objects whose surface the model puts within 5 mm (a symmetric one may be turned)
        known_surface_within_5mm=f"{sum(o.get('surface_error_mm', math.inf) <= 5.0 for o in known)}/{len(known)}",
        scene_s=round(metrics["scene_elapsed_s"], 1),
        **{k.removesuffix("_s"): round(metrics["timings_s"].get(k, 0.0), 1) for k in SPLIT},
    )
    row["other"] = round(_other(row), 1)
    return row


def _other(row: dict[str, Any]) -> float:
    """Scene seconds outside the timed parts (learning the unknown objects, ticks); rows saved before
    a part was timed count it here."""
    return row["scene_s"] - sum(row.get(k, 0.0) for k in PARTS[:-1])


def _slope(rows: list[dict[str, Any]], key: str) -> float | None:
    pts = [(r["objects"], r[key]) for r in rows if r.get(key)]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def _plot(rows: list[dict[str, Any]], path: Path, commit: str) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), dpi=100)
    for robot in dict.fromkeys(r["robot"] for r in rows):
        mine = [r for r in rows if r["robot"] == robot and "views" in r]
        n = [r["objects"] for r in mine]
        for ax, key, label in ((axes[0], "wall_s", "wall time / s"), (axes[1], "peak_mb", "peak memory / MB")):
            slope = _slope(mine, key)
            ax.loglog(n, [r[key] for r in mine], "o-", label=f"{robot} (slope {slope:.2f})" if slope else robot)
            ax.set_xlabel("objects (rooms of 1, 2, 4, 4 tables)")
            ax.set_ylabel(label)
    for ax in axes[:2]:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    last = [r for r in rows if "views" in r and r["robot"] == rows[0]["robot"]]
    bottom = np.zeros(len(last))
    labels = [f"{r['tables']}t/{r['objects']}o" for r in last]
    for key in PARTS:
        part = np.array([_other(r) if key == "other" else r.get(key, 0.0) for r in last])
        if part.any():
            axes[2].bar(labels, part, bottom=bottom, label=key)
            bottom += part
    axes[2].set_ylabel("seconds")
    axes[2].set_title(f"time split ({rows[0]['robot']})", fontsize=10)
    axes[2].legend(fontsize=8)
    fig.suptitle(f"table_patrol at 5 mm, sparse PVS, whole room (commit {commit})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", choices=tuple(ROBOTS), default=["mobile_base"])
    parser.add_argument("--rooms", nargs="+", default=[f"{t}x{o}" for t, o in GROWTH],
                        help="tables x objects, e.g. 1x5 4x40")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds per run")
    parser.add_argument("--out", type=Path, default=Path("runs/scale"))
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--replot", type=Path, help="draw scale.png again from a scale.json, run nothing")
    args = parser.parse_args()
    if args.replot is not None:
        try:
            saved = json.loads(args.replot.read_text())
            saved["rows"], saved["commit"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            print(f"error: --replot: {args.replot}: not a scale.json ({error})", file=sys.stderr)
            return 2
        _plot(saved["rows"], args.replot.with_name("scale.png"), saved["commit"])
        print(args.replot.with_name("scale.png"))
        return 0
    rooms = []
    for text in args.rooms:
        try:
            tables, objects = (int(v) for v in text.lower().split("x"))
        except ValueError:
            print(f"error: --rooms: {text!r} is not TABLESxOBJECTS (e.g. 4x40)", file=sys.stderr)
            return 2
        problem = room_problem(tables, objects)
        if problem:
            print(f"error: --rooms: {text!r}: {problem}", file=sys.stderr)
            return 2
        rooms.append((tables, objects))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    rows = []
    for robot in args.robots:
        for tables, objects in rooms:
            out = args.out / f"{tables}t_{objects}o_{robot}"
            out.mkdir(parents=True, exist_ok=True)
            (out / "objects.db").unlink(missing_ok=True)
            world = write_world(out, tables, objects, robot)
            wall, peak, code = _run(world, out, args.seed, args.timeout)
            rows.append(_row(tables, objects, robot, wall, peak, code, out / "run"))
            if not args.json:
                print(json.dumps(rows[-1]), flush=True)
    (args.out / "scale.json").write_text(json.dumps({"commit": commit, "rows": rows}, indent=1))
    _plot(rows, args.out / "scale.png", commit)
    if args.json:
        print(json.dumps(rows))
        return 0
    for robot in args.robots:
        mine = [r for r in rows if r["robot"] == robot]
        slope = _slope(mine, "wall_s")
        memory = _slope(mine, "peak_mb")
        print(f"{robot}: wall time ~ objects^{slope:.2f}, peak memory ~ objects^{memory:.2f}"
              if slope is not None and memory is not None else f"{robot}: too few runs for a slope")
    print(f"plot: {args.out / 'scale.png'}   rows: {args.out / 'scale.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
