"""Motion planners per world, and the Vasquez-Gomez DU vs EU experiment (their Table 5).

Part 1, for each world x planner: success rate, median planning time (wall time of every
query, failures included), median path length (Eq. 8), and the collision rate of the
executed paths (with the robot's positioning noise, checked against the TRUE world). The
planner knows the environment and treats the region of interest as unknown (an obstacle);
queries join two valid configurations that look at the region (IK for the arm and the free
flyer, uniform states for the mobile robots); ``try_direct`` is off, so OMPL always plans.
The time limits are wall time here (the planners are compared in real time).

Part 2, bunny on a table among obstacles (``worlds/cluttered.yaml``), mobile manipulator with
noise (sigma_v 1.65 mm/s, sigma_omega 0.28 rad/s): deterministic utility without noise (DU)
and with it (DU-MU) vs expected utility (EU-MU) for several k, several seeds, 12 views;
mean / max ground-truth coverage, collision rate (collisions / executed trajectories), the
share of runs with a collision (a run ends at its first collision, as in the paper) and the
median effective sample size of the EU weights. Its planning limits are on the work clock
(``explore.motion.planning_clock``), as in ``explore run``: a seed gives the same row under any load.

    .venv/bin/python benchmarks/planners.py --part planners            # planners (~20 min)
    .venv/bin/python benchmarks/planners.py --part nbvs --runs-file runs/table5.jsonl   # hours, resumable
    .venv/bin/python benchmarks/planners.py --full     # paper-size grid
    .venv/bin/python benchmarks/planners.py --json     # rows as JSON only
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import time
from typing import Any

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")

PLANNERS_QUICK = ("rrt_connect", "rrt", "prm", "kpiece", "bit_star", "rrt_star")
PLANNERS_FULL = PLANNERS_QUICK + ("bkpiece", "fmt", "informed_rrt_star")  # lazy_prm: not in ompl 2.0.1's wheel
WORLDS = ("workcell", "cluttered", "two_tables", "bunny_pedestal", "tabletop")


def view_poses(sim: Any, count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Views 0.3 m from points in the region, 20-50 deg off vertical, from the robot's side.

    The reachable viewpoints an NBV planner asks an arm for (as ``tests/test_robots.py``):
    uniformly oriented views around a table are mostly out of an arm's reach, and each failed
    IK costs every restart.
    """
    from explore.core import look_at

    base = sim.spec.robot.base
    poses = []
    for target in rng.uniform(sim.spec.region_min, sim.spec.region_max, size=(count, 3)):
        toward = rng.uniform(-np.pi, np.pi) if base is None else \
            float(np.arctan2(base[1] - target[1], base[0] - target[0])) + rng.uniform(-1.0, 1.0)
        elevation = rng.uniform(np.radians(20), np.radians(50))
        d = np.array([np.sin(elevation) * np.cos(toward), np.sin(elevation) * np.sin(toward), np.cos(elevation)])
        poses.append(look_at(target + 0.3 * d, target))
    return poses


def _queries(sim: Any, problem: Any, count: int, rng: np.random.Generator,
             ik_attempts: int = 6) -> tuple[list[tuple[np.ndarray, np.ndarray]], dict[str, float]]:
    """Pairs of valid configurations whose sensor looks at the region, and IK statistics.

    Mobile robots: uniform states (the NBVS way). Arm and free flyer: IK to reachable views
    (:func:`view_poses`) with ``ik_attempts`` restarts (capped: the robot's default is 30).
    """
    robot = sim.robot
    configs: list[np.ndarray] = []
    tries, solved, ik_s = 0, 0, 0.0
    saved = getattr(robot, "ik_attempts", None)
    if saved is not None:
        robot.ik_attempts = min(int(saved), ik_attempts)
    try:
        while len(configs) < 2 * count and tries < 50 * count:
            tries += 1
            if robot.base_dofs:
                q = robot.sample_config(rng)
                q[robot.base_dofs[2]] = rng.uniform(-np.pi, np.pi)
            else:
                t0 = time.perf_counter()
                q = robot.ik(view_poses(sim, 1, rng)[0], rng)
                ik_s += time.perf_counter() - t0
                if q is None:
                    continue
                solved += 1
            if problem.is_valid(q):
                configs.append(np.asarray(q, dtype=float))
    finally:
        if saved is not None:
            robot.ik_attempts = saved
    stats = {"ik_tries": tries, "ik_success": solved / tries if not robot.base_dofs else float("nan"),
             "ik_s_per_try": ik_s / tries if not robot.base_dofs else float("nan")}
    return [(configs[2 * i], configs[2 * i + 1]) for i in range(len(configs) // 2)], stats


def planner_rows(full: bool, log: Any, worlds: tuple[str, ...] = (), planners: tuple[str, ...] = (),
                 count: int | None = None) -> list[dict[str, Any]]:
    """One row per world x planner (queries shared by the planners of a world)."""
    from explore.mapping import PVS
    from explore.motion import MotionProblem
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    rows = []
    count = count or (30 if full else 15)
    for world in WORLDS:
        if worlds and world not in worlds:
            continue
        with Simulation(world, registry) as sim:
            robot = sim.robot
            pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.02)  # all unknown
            problem = MotionProblem(robot, space_free=pvs.is_free)
            if not problem.is_valid(robot.q):  # the region is the whole room (two_tables): known world only
                problem = MotionProblem(robot)
            t0 = time.perf_counter()
            queries, ik = _queries(sim, problem, count, np.random.default_rng(0))
            log(f"{world}: {len(queries)} queries in {time.perf_counter() - t0:.1f} s "
                f"(IK success {ik['ik_success']:.0%}, {ik['ik_s_per_try']:.2f} s per IK)")
            names: tuple[str, ...] = PLANNERS_FULL if full else PLANNERS_QUICK
            if robot.name == "free_flyer":
                names = ("straight_line", "rrt_connect")
            elif robot.base_dofs:
                names = names + ("tuck_and_drive", "kinodynamic_rrt", "kinodynamic_kpiece", "kinodynamic_est")
            for name in names:
                if planners and name not in planners:
                    continue
                label = name
                limit = 1.0
                params: dict[str, Any] = {"time_limit": limit, "try_direct": False}
                if name == "straight_line":
                    params = {}
                elif name.startswith("kinodynamic") or name == "tuck_and_drive":
                    limit = 5.0
                    params = {"time_limit": limit}
                    if name.startswith("kinodynamic_"):
                        name, params["planner"] = "kinodynamic", name.split("_", 1)[1]
                if name not in registry.names("motion_planner"):  # any other OMPL planner by name
                    params["planner"] = name
                    planner = registry.create("motion_planner", "ompl", params, "<bench>")
                else:
                    planner = registry.create("motion_planner", name, params, "<bench>")
                times, lengths, ok, collided, executed = [], [], 0, 0, 0
                for index, (a, b) in enumerate(queries):
                    t1 = time.perf_counter()
                    plan = planner.plan(problem, a, b, seed=index + 1)
                    times.append(time.perf_counter() - t1)
                    if plan is None:
                        continue
                    ok += 1
                    lengths.append(plan.length)
                    run = robot.execute(plan, np.random.default_rng(index), noise=True, world="true")
                    executed += 1
                    collided += int(run.collided)
                row = {
                    "part": "planners", "world": world, "robot": robot.name, "planner": label,
                    "queries": len(queries), "time_limit_s": limit if name != "straight_line" else None,
                    "success": ok / max(1, len(queries)),
                    "median_time_s": float(np.median(times)) if times else float("nan"),
                    "max_time_s": float(np.max(times)) if times else float("nan"),
                    "median_length": float(np.median(lengths)) if lengths else float("nan"),
                    "collision_rate": collided / max(1, executed), "ik_success": ik["ik_success"],
                }
                rows.append(row)
                log(f"{world:15s} {label:18s} success {row['success']:5.0%}  median {row['median_time_s']:6.3f} s  "
                    f"max {row['max_time_s']:6.3f} s  length {row['median_length']:7.2f}  "
                    f"collisions {row['collision_rate']:5.0%}")
    return rows


NBVS_WORLD = "cluttered"


def nbvs_rows(full: bool, log: Any, seeds: list[int] | None = None, ks: tuple[int, ...] = (), views: int | None = None,
              runs_file: str | None = None, approaches: tuple[str, ...] = (), world: str = NBVS_WORLD,
              session_params: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Vasquez-Gomez Table 5: DU (no noise), DU-MU and EU-MU for each k, one row per approach.

    Every finished run is appended to ``runs_file`` (JSON lines) and found there again on a
    re-run with the same settings, so a long grid can be stopped and resumed.
    """
    from explore.motion import wall_guard_stops, work_clock
    from explore.nbv import NBVSSession
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    seed_list = seeds or range(10 if full else 5)
    ks = ks or ((1, 10, 100, 500) if full else (1, 100, 500))
    views = views or 12
    configs = [("DU", False, 1, False), ("DU-MU", False, 1, True)] + [("EU-MU", True, k, True) for k in ks]
    if approaches:
        configs = [c for c in configs if c[0] in approaches]
    defaults = inspect.signature(NBVSSession).parameters
    params = {name: defaults[name].default for name in ("relocalise", "weighting", "leg_length", "min_unknown")}
    done: dict[tuple, dict[str, Any]] = {}
    if runs_file and os.path.exists(runs_file):
        with open(runs_file, encoding="utf-8") as handle:
            for line in handle:
                try:
                    run = json.loads(line)
                except json.JSONDecodeError:  # a line cut short by an interrupt: that run is repeated
                    continue
                done[(run.get("world", NBVS_WORLD), run["approach"], run["k"], run["seed"], run["max_views"],
                      run.get("relocalise", False), run.get("weighting", "probability"),
                      run.get("leg_length", 0.25 if run.get("relocalise") else 0.0),
                      run.get("min_unknown", params["min_unknown"]))] = run  # older records: the session default
    params.update(session_params or {})
    if not params["relocalise"]:
        params["leg_length"] = 0.0
    rows = []
    for approach, expected, k, noise in configs:
        runs = []
        for seed in seed_list:
            key = (world, approach, k, seed, views, params["relocalise"], params["weighting"], params["leg_length"],
                   params["min_unknown"])
            if key not in done:
                t0 = time.perf_counter()
                # each run's limits in work done from 0, as `explore run`: the same seed gives the same record
                # under any load and after any other run
                with work_clock(), Simulation(world, registry) as sim:
                    session = NBVSSession(sim, registry, expected=expected, k=k, seed=seed, max_views=views,
                                          noise=noise, **params)
                    summary = session.run(lambda r, a=approach, s=seed, kk=k: log(
                        f"  {a} k={kk} seed {s} view {r.index}: coverage {r.coverage:.3f}  collided {r.collided}  "
                        f"ess {r.ess if r.ess is None else round(r.ess, 1)}  stages {r.stages}"))
                    guard_stops = wall_guard_stops()
                summary.update({"world": world, **params, "approach": approach, "k": k, "seed": seed,
                                "max_views": views, "wall_guard_stops": guard_stops,
                                "seconds": time.perf_counter() - t0, "travelled_m": session.travelled_m()})
                summary = json.loads(json.dumps(summary, default=float))
                done[key] = summary
                if runs_file:
                    with open(runs_file, "a", encoding="utf-8") as handle:
                        handle.write(json.dumps(summary) + "\n")
            run = done[key]
            runs.append(run)
            log(f"{approach} k={k:<3d} seed {seed}: views {run['views']:2d}  coverage {run['final_coverage']:.3f}  "
                f"collisions {run['collisions']}/{run['trajectories']}  ({run['reason']}, {run['seconds']:.0f} s)")
        trajectories = sum(r["trajectories"] for r in runs)
        collisions = sum(r["collisions"] for r in runs)
        cov = [r["final_coverage"] for r in runs]
        ess = [e for r in runs for e in r["ess"] if e is not None]
        rows.append({
            "part": "nbvs", "world": world, "approach": approach, "k": k if expected else None,
            "runs": len(runs), "max_views": views, "mean_coverage": float(np.mean(cov)),
            "max_coverage": float(np.max(cov)), "collision_rate": collisions / max(1, trajectories),
            "runs_with_collision": float(np.mean([r["collided"] for r in runs])), "trajectories": trajectories,
            "mean_views": float(np.mean([r["views"] for r in runs])),
            "median_ess": float(np.median(ess)) if ess else None,
            "plan_success_rate": float(np.mean([r["plan_success_rate"] for r in runs])),
            "seconds_per_run": float(np.mean([r["seconds"] for r in runs])),
            "median_s_per_view": float(np.median([t for r in runs for t in r.get("seconds_per_view", [])] or [np.nan])),
            "travelled_m_per_run": float(np.mean([r["travelled_m"] for r in runs])),
            "wall_guard_stops": sum(r.get("wall_guard_stops", 0) for r in runs),  # older records: not counted
        })
    return rows


def print_tables(rows: list[dict[str, Any]]) -> None:
    planner = [r for r in rows if r["part"] == "planners"]
    if planner:
        print("\nworld            robot               planner             limit s  success  median s   max s  "
              "length  exec. collisions")
        for r in planner:
            limit = "-" if r["time_limit_s"] is None else f"{r['time_limit_s']:.1f}"
            print(f"{r['world']:16s} {r['robot']:19s} {r['planner']:18s} {limit:>7s} {r['success']:8.0%} "
                  f"{r['median_time_s']:9.3f} {r['max_time_s']:7.3f} {r['median_length']:7.2f} "
                  f"{r['collision_rate']:10.0%}")
    nbvs = [r for r in rows if r["part"] == "nbvs"]
    if nbvs:
        print(f"\nVasquez-Gomez Table 5 ({nbvs[0]['world']}, mobile manipulator, sigma_v 1.65 mm/s, "
              f"sigma_w 0.28 rad/s)")
        print("approach    k  runs  mean cov  max cov  collision rate  runs w/ collision  mean views  median ESS  "
              "s/run  s/view")
        for r in nbvs:
            k = "-" if r["k"] is None else str(r["k"])
            ess = "-" if r["median_ess"] is None else f"{r['median_ess']:.1f}"
            print(f"{r['approach']:8s} {k:>4s} {r['runs']:5d} {r['mean_coverage']:9.1%} {r['max_coverage']:8.1%} "
                  f"{r['collision_rate']:15.0%} {r['runs_with_collision']:18.0%} {r['mean_views']:11.1f} "
                  f"{ess:>11s} {r['seconds_per_run']:6.0f} {r['median_s_per_view']:7.1f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="paper-size grid (slow)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON only")
    parser.add_argument("--part", choices=("all", "planners", "nbvs"), default="all")
    parser.add_argument("--worlds", default="", help="comma-separated subset of the planner worlds")
    parser.add_argument("--planners", default="", help="comma-separated subset of the planners")
    parser.add_argument("--queries", type=int, default=None, help="queries per world (15; --full 30)")
    parser.add_argument("--seeds", default=None,
                        help="NBVS seeds per approach: N (0..N-1), a range A-B or a list a,b,c (5; --full 10)")
    parser.add_argument("--ks", default="", help="comma-separated k of EU-MU (1,100,500; --full 1,10,100,500)")
    parser.add_argument("--views", type=int, default=None, help="planned views per NBVS run (12, as the paper)")
    parser.add_argument("--approaches", default="", help="subset of DU,DU-MU,EU-MU")
    parser.add_argument("--runs-file", default=None, help="JSON lines of finished NBVS runs (resume)")
    parser.add_argument("--nbvs-world", default=NBVS_WORLD, help="world of the NBVS runs (cluttered)")
    parser.add_argument("--open-loop", action="store_true",
                        help="NBVS motions executed open loop, as in the paper (default: re-localising)")
    parser.add_argument("--weighting", choices=("mean", "probability"), default="mean", help="EU weights")
    parser.add_argument("--min-unknown", type=int, default=None,
                        help="unknown voxels a candidate must see (default: the session's 30, the paper's stop with "
                             "the real robot's parameters, Table 7, which its Table 6 used; 0: the 12-view budget ends "
                             "a run, as in the paper's simulations of Table 5 and Fig. 12)")
    parser.add_argument("--leg-length", type=float, default=None,
                        help="re-localising, also re-aim drives every this many metres (default: the session's)")
    args = parser.parse_args(argv)
    worlds = tuple(w for w in args.worlds.split(",") if w)
    if set(worlds) - set(WORLDS):
        parser.error(f"--worlds: unknown {sorted(set(worlds) - set(WORLDS))} (valid: {', '.join(WORLDS)})")
    try:
        ks = tuple(int(k) for k in args.ks.split(",") if k)
    except ValueError:
        parser.error(f"--ks: comma-separated integers expected, got {args.ks!r}")
    if args.min_unknown is not None and args.min_unknown < 0:
        parser.error(f"--min-unknown: must be >= 0, got {args.min_unknown}")
    if args.leg_length is not None and args.leg_length < 0.0:
        parser.error(f"--leg-length: must be >= 0, got {args.leg_length}")
    from explore_cli.compare_cmd import parse_seeds

    from explore.core import BadInput
    from explore.sim import find_world

    try:
        find_world(args.nbvs_world)
    except BadInput as error:
        parser.error(f"--nbvs-world: {error}")
    try:
        seeds = None if args.seeds is None else parse_seeds(args.seeds)
    except BadInput as error:
        parser.error(str(error))

    def log(line: str) -> None:
        if not args.json:
            print(line, file=sys.stderr, flush=True)

    rows: list[dict[str, Any]] = []
    if args.part in ("all", "planners"):
        rows += planner_rows(args.full, log, worlds,
                             tuple(p for p in args.planners.split(",") if p), args.queries)
    if args.part in ("all", "nbvs"):
        rows += nbvs_rows(args.full, log, seeds, ks, args.views,
                          args.runs_file, tuple(a for a in args.approaches.split(",") if a), args.nbvs_world,
                          {"relocalise": not args.open_loop, "weighting": args.weighting,
                           **{name: value for name, value in (("leg_length", args.leg_length),
                                                              ("min_unknown", args.min_unknown))
                              if value is not None}})
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print_tables(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
