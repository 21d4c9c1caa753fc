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

import sys

import compare_grid

QUICK_PLANNERS = ["rrt_connect", "straight_line"]
FULL_PLANNERS = ["rrt_connect", "rrt_star", "prm", "bit_star", "straight_line"]
STRATEGY = "ig_quality/bs_hr"


def shipped_worlds() -> list[str]:
    from explore.sim import list_worlds

    return [p.stem for p in list_worlds()]


def main(argv: list[str] | None = None) -> int:
    parser = compare_grid.parser(__doc__, "all shipped worlds, 5 planners, 5 seeds, 10 scans")
    args, extra = parser.parse_known_args(argv)
    command = compare_grid.compare_command(
        args, extra, tree="model_object",
        worlds=shipped_worlds() if args.full else ["bunny_pedestal", "duck_pedestal"],
        strategies=[STRATEGY], planners=FULL_PLANNERS if args.full else QUICK_PLANNERS,
        seeds=5 if args.full else 2, max_scans=10 if args.full else 4,
        out=f"runs/compare_planners_{'full' if args.full else 'quick'}",
    )
    return compare_grid.run(command, args.dry_run)


if __name__ == "__main__":
    sys.exit(main())
