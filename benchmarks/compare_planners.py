"""Motion planners across the shipped worlds: success rate, planning time, path length.

Runs ``explore compare`` over every shipped world (``explore worlds list``) with several
motion planners and one NBV strategy; summary.md holds the per-planner table and
planners.png the success / time plot.

Quick (default): two pedestal worlds, RRT-Connect vs the straight line, 2 seeds, 4 scans.
``--full``: every shipped world, RRT-Connect, RRT*, PRM, BIT* and the straight line,
5 seeds, 10 scans. Extra arguments after ``--`` go to ``explore compare``; re-running the
same command resumes::

    .venv/bin/python benchmarks/compare_planners.py --out runs/planners_quick
    .venv/bin/python benchmarks/compare_planners.py --full --executor ray --ray-address HOST:6379
"""

from __future__ import annotations

import argparse
import sys

QUICK_PLANNERS = ["rrt_connect", "straight_line"]
FULL_PLANNERS = ["rrt_connect", "rrt_star", "prm", "bit_star", "straight_line"]
STRATEGY = "ig_quality/bs_hr"


def shipped_worlds() -> list[str]:
    from explore.world import list_worlds

    return [p.stem for p in list_worlds()]


def arguments(argv: list[str] | None = None) -> list[str]:
    """The ``explore compare`` arguments of the chosen grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="all shipped worlds, 5 planners, 5 seeds, 10 scans")
    parser.add_argument("--seeds", type=int, help="override the number of seeds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local")
    parser.add_argument("--ray-address")
    parser.add_argument("--out", default=None)
    parser.add_argument("--dry-run", action="store_true", help="only print the command")
    args, extra = parser.parse_known_args(argv)
    worlds = shipped_worlds() if args.full else ["bunny_pedestal", "duck_pedestal"]
    planners = FULL_PLANNERS if args.full else QUICK_PLANNERS
    command = [
        "compare", "--tree", "model_object", "--worlds", ",".join(worlds), "--strategies", STRATEGY,
        "--planners", ",".join(planners), "--seeds", str(args.seeds or (5 if args.full else 2)),
        "--max-scans", "10" if args.full else "4", "--jobs", str(args.jobs), "--executor", args.executor,
        "--timeout", "3600", "--out", args.out or f"runs/compare_planners_{'full' if args.full else 'quick'}",
    ]
    if args.ray_address:
        command += ["--ray-address", args.ray_address]
    command += [a for a in extra if a != "--"]
    return ["--dry-run", *command] if args.dry_run else command


def main(argv: list[str] | None = None) -> int:
    command = arguments(argv)
    print("explore " + " ".join(a for a in command if a != "--dry-run"))
    if command[0] == "--dry-run":
        return 0
    from explore_cli.main import main as explore

    return explore(command)


if __name__ == "__main__":
    sys.exit(main())
