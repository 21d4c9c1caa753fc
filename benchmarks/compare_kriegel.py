"""Kriegel thesis Table 4.5 / IROS 2012 Table II-III on our pedestal objects via ``explore compare``.

Quick (default, a few minutes on 2 cores): IG/Quality, Quality and Random selection over
Boundary Search + Hole Rescan, plus IG/Quality over the sphere, on the bunny, 3 seeds,
10 scans. ``--full``: all 12 selection x search-space strategies of Table 4.5 on the bunny,
duck and teddy pedestals, 10 seeds, 30 scans (the thesis: 100 runs, Munkelt object).
``--iros``: the IROS 2012 Table II strategies (B, S, S/IG, B/IG, BH/IG) instead.

As in the thesis, every run goes on scanning after its termination said stop (n_s is where it
first did) until the scan budget or until its strategy has no candidate left, without a
fallback generator. The results folder gets results.csv, summary.md (Table 4.5 layout), plots and report.html;
re-running the same command resumes. Extra arguments after ``--`` go to ``explore compare``::

    .venv/bin/python benchmarks/compare_kriegel.py --out runs/kriegel_quick
    .venv/bin/python benchmarks/compare_kriegel.py --full --jobs 2 --out runs/kriegel_full
"""

from __future__ import annotations

import sys

import compare_grid

QUICK = ["ig_quality/bs_hr", "quality/bs_hr", "random/bs_hr", "ig_quality/sphere"]
FULL = [f"{sel}/{search}" for sel in ("random", "ig", "quality", "ig_quality") for search in ("sphere", "bs", "bs_hr")]
THESIS_SETTINGS = ["--set", "start_modelling.continue_after_stop=true", "--set", "start_modelling.fallback=none"]
IROS = ["iros/B", "iros/S", "iros/S_IG", "iros/B_IG", "iros/BH_IG"]


def main(argv: list[str] | None = None) -> int:
    parser = compare_grid.parser(__doc__, "all strategies, 3 worlds, 10 seeds, 30 scans")
    parser.add_argument("--iros", action="store_true", help="IROS 2012 Table II strategies")
    args, extra = parser.parse_known_args(argv)
    command = compare_grid.compare_command(
        args, [*THESIS_SETTINGS, *extra], tree="model_object",
        worlds=["bunny_pedestal", "duck_pedestal", "teddy_pedestal"] if args.full else ["bunny_pedestal"],
        strategies=IROS if args.iros else (FULL if args.full else QUICK),
        seeds=10 if args.full else 3, max_scans=30 if args.full else 10,
        out=f"runs/compare_kriegel_{'full' if args.full else 'quick'}{'_iros' if args.iros else ''}",
    )
    return compare_grid.run(command, args.dry_run)


if __name__ == "__main__":
    sys.exit(main())
