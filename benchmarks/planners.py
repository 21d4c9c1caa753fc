"""Motion planners per world, and the Vasquez-Gomez DU vs EU experiment (their Table 5).

Part 1, for each world x planner: success rate, median planning time (wall time of every
query, failures included), median path length (Eq. 8), and the collision rate of the
executed paths (with the robot's positioning noise, checked against the TRUE world). The
planner knows the environment and treats the region of interest as unknown (an obstacle);
queries join two valid configurations that look at the region (IK for the arm and the free
flyer, uniform states for the mobile robots); ``try_direct`` is off, so OMPL always plans.

Part 2, bunny on a table among obstacles (``worlds/cluttered.yaml``), mobile manipulator with
noise (sigma_v 1.65 mm/s, sigma_omega 0.28 rad/s): deterministic utility (DU-MU) vs expected
utility (EU-MU) for several k, several seeds; mean / max ground-truth coverage, collision rate
(collisions / executed trajectories) and the share of runs with a collision (a run ends at
its first collision, as in the paper).

    .venv/bin/python benchmarks/planners.py            # quick (a few minutes)
    .venv/bin/python benchmarks/planners.py --full     # paper-size grid (hours)
    .venv/bin/python benchmarks/planners.py --json     # rows as JSON only
    .venv/bin/python benchmarks/planners.py --part planners|nbvs
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")

PLANNERS_QUICK = ("rrt_connect", "rrt", "prm", "kpiece", "bit_star", "rrt_star")
PLANNERS_FULL = PLANNERS_QUICK + ("lazy_prm",)
WORLDS = (("workcell", False), ("cluttered", True), ("two_tables", True), ("bunny_pedestal", False),
          ("tabletop", False))


def _queries(sim: Any, problem: Any, count: int, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pairs of valid configurations whose sensor looks at the region."""
    from explore.geometry import look_at

    robot = sim.robot
    lo, hi = np.asarray(sim.spec.region_min), np.asarray(sim.spec.region_max)
    centre = 0.5 * (lo + hi)
    configs: list[np.ndarray] = []
    tries = 0
    while len(configs) < 2 * count and tries < 400 * count:
        tries += 1
        if robot.base_dofs:  # mobile: uniform states (the NBVS way)
            q = robot.sample_config(rng)
            q[robot.base_dofs[2]] = rng.uniform(-np.pi, np.pi)
        else:  # IK to a view of the region from outside it
            direction = rng.normal(size=3)
            direction[2] = abs(direction[2]) + 0.3
            direction /= np.linalg.norm(direction)
            eye = centre + direction * (np.linalg.norm(hi - lo) / 2 + rng.uniform(0.1, 0.3))
            q = robot.ik(look_at(eye, centre + rng.uniform(-0.05, 0.05, 3)), rng)
            if q is None:
                continue
        if problem.is_valid(q):
            configs.append(np.asarray(q, dtype=float))
    return [(configs[2 * i], configs[2 * i + 1]) for i in range(len(configs) // 2)]


def planner_rows(full: bool, log: Any, worlds: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    from explore.motion import MotionProblem
    from explore.pvs import PVS
    from explore.registry import Registry
    from explore.simulation import Simulation

    registry = Registry.load()
    rows = []
    count = 30 if full else 6
    for world, _mobile in WORLDS:
        if worlds and world not in worlds:
            continue
        with Simulation(world, registry) as sim:
            robot = sim.robot
            pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.02)  # all unknown
            problem = MotionProblem(robot, space_free=pvs.is_free)
            if not problem.is_valid(robot.q):  # the region is the whole room (two_tables): known world only
                problem = MotionProblem(robot)
            queries = _queries(sim, problem, count, np.random.default_rng(0))
            names: tuple[str, ...] = PLANNERS_FULL if full else PLANNERS_QUICK
            if robot.name == "free_flyer":
                names = ("straight_line", "rrt_connect")
            elif robot.base_dofs:
                names = names + ("kinodynamic",)
            for name in names:
                params = {} if name in ("straight_line", "kinodynamic") else {"time_limit": 1.0, "try_direct": False}
                if name == "kinodynamic":
                    params = {"time_limit": 5.0 if full else 2.0, "goal_tolerance": 0.1}
                planner = registry.create("motion_planner", name, params, "<bench>")
                times, lengths, ok, collided, executed = [], [], 0, 0, 0
                for index, (a, b) in enumerate(queries):
                    t0 = time.perf_counter()
                    plan = planner.plan(problem, a, b, seed=index + 1)
                    times.append(time.perf_counter() - t0)
                    if plan is None:
                        continue
                    ok += 1
                    lengths.append(plan.length)
                    run = robot.execute(plan, np.random.default_rng(index), noise=True, world="true")
                    executed += 1
                    collided += int(run.collided)
                row = {
                    "part": "planners", "world": world, "robot": robot.name, "planner": name,
                    "queries": len(queries), "success": ok / max(1, len(queries)),
                    "median_time_s": float(np.median(times)) if times else float("nan"),
                    "median_length": float(np.median(lengths)) if lengths else float("nan"),
                    "collision_rate": collided / max(1, executed),
                }
                rows.append(row)
                log(f"{world:15s} {name:14s} success {row['success']:5.0%}  median {row['median_time_s']:6.3f} s  "
                    f"length {row['median_length']:7.2f}  collisions {row['collision_rate']:5.0%}")
    return rows


def nbvs_rows(full: bool, log: Any) -> list[dict[str, Any]]:
    from explore.nbvs import NBVSSession
    from explore.registry import Registry
    from explore.simulation import Simulation

    registry = Registry.load()
    seeds = range(10 if full else 5)
    ks = (1, 10, 100, 500) if full else (10, 100)
    views = 12 if full else 3
    options = {"n_samples": 40000, "top": 25} if full else {"n_samples": 30000, "top": 10}
    options["planner_params"] = {"time_limit": 1.0 if full else 0.5}
    configs = [("DU-MU", False, 0)] + [("EU-MU", True, k) for k in ks]
    rows = []
    for approach, expected, k in configs:
        runs = []
        t0 = time.perf_counter()
        for seed in seeds:
            with Simulation("cluttered", registry) as sim:
                session = NBVSSession(sim, registry, expected=expected, k=max(k, 1), seed=seed, max_views=views,
                                      **options)
                summary = session.run()
                runs.append(summary)
                log(f"  {approach} k={k:<3d} seed {seed}: views {summary['views']:2d}  coverage "
                    f"{summary['final_coverage']:.3f}  collisions {summary['collisions']}/{summary['trajectories']}"
                    f"  ({summary['reason']})")
        trajectories = sum(r["trajectories"] for r in runs)
        collisions = sum(r["collisions"] for r in runs)
        cov = [r["final_coverage"] for r in runs]
        row = {
            "part": "nbvs", "world": "cluttered", "approach": approach, "k": k, "runs": len(runs),
            "max_views": views, "mean_coverage": float(np.mean(cov)), "max_coverage": float(np.max(cov)),
            "collision_rate": collisions / max(1, trajectories), "runs_with_collision": float(
                np.mean([r["collided"] for r in runs])),
            "trajectories": trajectories, "mean_views": float(np.mean([r["views"] for r in runs])),
            "seconds_per_run": (time.perf_counter() - t0) / len(runs),
        }
        rows.append(row)
    return rows


def print_tables(rows: list[dict[str, Any]]) -> None:
    planner = [r for r in rows if r["part"] == "planners"]
    if planner:
        print("\nworld            planner         success  median s   length  exec. collisions")
        for r in planner:
            print(f"{r['world']:16s} {r['planner']:14s} {r['success']:8.0%} {r['median_time_s']:9.3f} "
                  f"{r['median_length']:8.2f} {r['collision_rate']:10.0%}")
    nbvs = [r for r in rows if r["part"] == "nbvs"]
    if nbvs:
        print("\nVasquez-Gomez Table 5 (cluttered bunny, noisy mobile manipulator)")
        print("approach  k     runs  mean cov  max cov  collision rate  runs w/ collision  mean views  s/run")
        for r in nbvs:
            print(f"{r['approach']:8s} {r['k']:4d} {r['runs']:6d} {r['mean_coverage']:9.1%} {r['max_coverage']:8.1%} "
                  f"{r['collision_rate']:15.0%} {r['runs_with_collision']:18.0%} {r['mean_views']:11.1f} "
                  f"{r['seconds_per_run']:6.0f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="paper-size grid (slow)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON only")
    parser.add_argument("--part", choices=("all", "planners", "nbvs"), default="all")
    parser.add_argument("--worlds", default="", help="comma-separated subset of the planner worlds")
    args = parser.parse_args(argv)

    def log(line: str) -> None:
        if not args.json:
            print(line, file=sys.stderr, flush=True)

    rows: list[dict[str, Any]] = []
    if args.part in ("all", "planners"):
        rows += planner_rows(args.full, log, tuple(w for w in args.worlds.split(",") if w))
    if args.part in ("all", "nbvs"):
        rows += nbvs_rows(args.full, log)
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print_tables(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
