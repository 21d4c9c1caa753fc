"""Kriegel thesis Table 4.5 / IROS 2012 Table II-III on our pedestal objects via ``explore compare``.

Quick (default, a few minutes on 2 cores): IG/Quality, Quality and Random selection over
Boundary Search + Hole Rescan, plus IG/Quality over the sphere, on the bunny, 3 seeds,
10 scans. ``--full``: all 12 selection x search-space strategies of Table 4.5 on the bunny,
duck and teddy pedestals, 10 seeds, 30 scans (the thesis: 100 runs, Munkelt object).
``--iros``: the IROS 2012 Table II strategies (B, S, S/IG, B/IG, BH/IG) instead.

The results folder gets results.csv, summary.md (Table 4.5 layout), plots and report.html;
re-running the same command resumes. Extra arguments after ``--`` go to ``explore compare``::

    .venv/bin/python benchmarks/compare_kriegel.py --out runs/kriegel_quick
    .venv/bin/python benchmarks/compare_kriegel.py --full --jobs 2 --out runs/kriegel_full
"""

from __future__ import annotations

import argparse
import sys

QUICK = ["ig_quality/bs_hr", "quality/bs_hr", "random/bs_hr", "ig_quality/sphere"]
FULL = [f"{sel}/{search}" for sel in ("random", "ig", "quality", "ig_quality") for search in ("sphere", "bs", "bs_hr")]
IROS = ["iros/B", "iros/S", "iros/S_IG", "iros/B_IG", "iros/BH_IG"]


def arguments(argv: list[str] | None = None) -> list[str]:
    """The ``explore compare`` arguments of the chosen grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="all strategies, 3 worlds, 10 seeds, 30 scans")
    parser.add_argument("--iros", action="store_true", help="IROS 2012 Table II strategies")
    parser.add_argument("--seeds", type=int, help="override the number of seeds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local")
    parser.add_argument("--ray-address")
    parser.add_argument("--out", default=None)
    parser.add_argument("--dry-run", action="store_true", help="only print the command")
    args, extra = parser.parse_known_args(argv)
    strategies = IROS if args.iros else (FULL if args.full else QUICK)
    worlds = "bunny_pedestal,duck_pedestal,teddy_pedestal" if args.full else "bunny_pedestal"
    seeds = args.seeds or (10 if args.full else 3)
    scans = 30 if args.full else 10
    out = args.out or f"runs/compare_kriegel_{'full' if args.full else 'quick'}{'_iros' if args.iros else ''}"
    command = [
        "compare", "--tree", "model_object", "--worlds", worlds, "--strategies", ",".join(strategies),
        "--seeds", str(seeds), "--max-scans", str(scans), "--jobs", str(args.jobs), "--executor", args.executor,
        "--timeout", "3600", "--out", out,
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
