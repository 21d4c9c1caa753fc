"""How well the work clock's nominal costs track wall time (explore.motion.planning_clock.COSTS).

Plans the queries of ``benchmarks/planners.py`` under the work clock, counts the validity
checks and planner iterations of each plan, and fits seconds per unit to the plans' wall
times (non-negative least squares). Prints, per world and planner, the median ratio of
wall time to nominal work time with the current costs and with the fitted ones. A ratio
near 1 means a time limit on the work clock lasts about as long as on the wall clock.

    .venv/bin/python benchmarks/planning_clock.py            # table (a few minutes)
    .venv/bin/python benchmarks/planning_clock.py --json     # rows as JSON only
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
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

CASES = (("workcell", "rrt_connect"), ("cluttered", "rrt_connect"), ("cluttered", "tuck_and_drive"),
         ("scene_small_mm", "tuck_and_drive"), ("scene_small_mobile", "tuck_and_drive"))


def samples(count: int, log: Any) -> list[dict[str, Any]]:
    """One record per plan: world, planner, wall seconds and the units charged."""
    from planners import _queries

    from explore.mapping import PVS
    from explore.motion import MotionProblem, planning_clock
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    out = []
    for world in dict.fromkeys(w for w, _ in CASES):
        with Simulation(world, registry) as sim:
            pvs = PVS.for_region(sim.spec.region_min, sim.spec.region_max, 0.02)  # all unknown
            problem = MotionProblem(sim.robot, space_free=pvs.is_free)
            if not problem.is_valid(sim.robot.q):
                problem = MotionProblem(sim.robot)
            queries, _ = _queries(sim, problem, count, np.random.default_rng(0))
            for name in (p for w, p in CASES if w == world):
                limit = 1.0 if name == "rrt_connect" else 5.0
                params = {"time_limit": limit} | ({"try_direct": False} if name == "rrt_connect" else {})
                planner = registry.create("motion_planner", name, params, "<bench>")
                for index, (a, b) in enumerate(queries):
                    with planning_clock.work_clock():
                        before = dict(planning_clock.counts)
                        t0 = time.perf_counter()
                        plan = planner.plan(problem, a, b, seed=index + 1)
                        wall = time.perf_counter() - t0
                        units = {k: planning_clock.counts[k] - before[k] for k in planning_clock.COSTS}
                    out.append({"world": world, "planner": name, "wall_s": wall, "solved": plan is not None,
                                **units})
                log(f"{world:20s} {name:16s} {len(queries)} plans")
    return out


def fit(records: list[dict[str, Any]], kinds: list[str]) -> dict[str, float]:
    """Seconds per unit that best explain the wall times (non-negative least squares)."""
    from scipy.optimize import nnls

    units = np.array([[r[k] for k in kinds] for r in records], dtype=float)
    wall = np.array([r["wall_s"] for r in records])
    scale = np.maximum(units.max(axis=0), 1.0)
    costs, _ = nnls(units / scale, wall)
    return dict(zip(kinds, (costs / scale).tolist(), strict=True))


def main() -> None:
    from explore.motion import COSTS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--queries", type=int, default=8, help="query pairs per world")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON only")
    args = parser.parse_args()
    log = (lambda _: None) if args.json else (lambda m: print(m, file=sys.stderr))
    records = samples(args.queries, log)
    kinds = list(COSTS)
    fitted = fit(records, kinds)
    rows = []
    for world, name in CASES:
        group = [r for r in records if r["world"] == world and r["planner"] == name]
        nominal = np.array([sum(COSTS[k] * r[k] for k in kinds) for r in group])
        refit = np.array([sum(fitted[k] * r[k] for k in kinds) for r in group])
        wall = np.array([r["wall_s"] for r in group])
        rows.append({"world": world, "planner": name, "plans": len(group),
                     "solved": sum(r["solved"] for r in group) / max(1, len(group)),
                     "median_wall_s": float(np.median(wall)),
                     "median_wall_per_work": float(np.median(wall / np.maximum(nominal, 1e-9))),
                     "median_wall_per_fitted": float(np.median(wall / np.maximum(refit, 1e-9)))})
    result = {"costs": COSTS, "fitted_costs": fitted, "rows": rows}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print("costs (s per unit): " + ", ".join(f"{k} {COSTS[k]:.2e} (fitted {fitted[k]:.2e})" for k in kinds))
    print(f"{'world':20s} {'planner':16s} {'plans':>5s} {'solved':>6s} {'wall s':>7s} {'wall/work':>9s} "
          f"{'wall/fitted':>11s}")
    for r in rows:
        print(f"{r['world']:20s} {r['planner']:16s} {r['plans']:5d} {r['solved']:6.0%} {r['median_wall_s']:7.3f} "
              f"{r['median_wall_per_work']:9.2f} {r['median_wall_per_fitted']:11.2f}")


if __name__ == "__main__":
    main()
