"""Why expected utility rejects candidates: the share of colliding rollouts per planned view/state.

For the first planned view of an NBVS run in ``cluttered`` (after the initial scan), every
candidate that survives the filters and gets a motion plan is rolled out k times with the
robot's positioning noise (Vasquez-Gomez Sec. A6, sigma_omega 0.28 rad/s) under three
executors (:func:`explore.motion.follow_plan`): open loop as in the paper, re-localising at the
plan's waypoints only, and re-localising at the waypoints and every 0.25 m of a drive (the NBVS
default). Per executor it prints the share of candidates that EU's "any rollout collides" rule
keeps, the median share of colliding rollouts, and the spread of the final base pose::

    .venv/bin/python benchmarks/eu_rollouts.py --seeds 0,1,2 [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

EXECUTORS = {"open loop": (False, 0.0), "waypoints": (True, 0.0), "waypoints + 0.25 m legs": (True, 0.25)}


def measure(seed: int, k: int, world: str) -> list[dict[str, Any]]:
    from explore.motion import follow_plan, plan_controls
    from explore.nbv import NBVSSession, colliding_rollouts
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    rows = []
    with Simulation(world, registry) as sim:
        session = NBVSSession(sim, registry, expected=False, seed=seed)
        session.step()
        planned = session.plan(session.filter(session.sample()))
        for name, (feedback, leg) in EXECUTORS.items():
            rng = np.random.default_rng(seed)
            shares, position, heading = [], [], []
            for state in planned:
                start, controls = plan_controls(session.robot, state.plan)
                rollouts = follow_plan(session.robot, start, controls, rng, k, feedback, leg)
                shares.append(float(colliding_rollouts(session.robot, rollouts, session.obstacles).mean()))
                final, nominal = rollouts.configs[:, -1], rollouts.nominal[-1]
                position.append(float(np.median(np.hypot(*(final[:, :2] - nominal[:2]).T))))
                heading.append(float(np.std(final[:, 2] - nominal[2])))
            rows.append({"seed": seed, "executor": name, "candidates": len(planned), "k": k,
                         "kept": float(np.mean([s == 0.0 for s in shares])),
                         "median_colliding": float(np.median(shares)),
                         "median_position_error_m": float(np.median(position)),
                         "median_heading_sd_rad": float(np.median(heading))})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated seeds")
    parser.add_argument("--k", type=int, default=100, help="rollouts per candidate")
    parser.add_argument("--world", default="cluttered")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args(argv)
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s]
    except ValueError:
        parser.error(f"--seeds: comma-separated integers expected, got {args.seeds!r}")
    if args.k < 1:
        parser.error(f"--k: must be >= 1, got {args.k}")
    try:
        from explore.core import BadInput
        from explore.sim import find_world

        find_world(args.world)
    except BadInput as error:
        parser.error(f"--world: {error}")
    rows = [row for seed in seeds for row in measure(seed, args.k, args.world)]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"| executor | candidates | kept by EU (no colliding rollout of {args.k}) | median share of colliding "
          "rollouts | median final position error | median final heading sd |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name in EXECUTORS:
        mine = [r for r in rows if r["executor"] == name]
        count = sum(r["candidates"] for r in mine)
        kept = sum(r["kept"] * r["candidates"] for r in mine) / max(1, count)
        print(f"| {name} | {count} | {kept:.0%} | {np.median([r['median_colliding'] for r in mine]):.0%} | "
              f"{100 * np.median([r['median_position_error_m'] for r in mine]):.1f} cm | "
              f"{np.median([r['median_heading_sd_rad'] for r in mine]):.3f} rad |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
