"""Vasquez-Gomez et al. Table 5: deterministic (DU) vs expected utility (EU) under positioning noise.

Runs ``explore compare`` with the view/state tree ``trees/nbvs_mobile.yaml`` and the
``vasquez/du`` and ``vasquez/eu`` strategies on the bunny among furniture (``cluttered``, a
mobile manipulator whose velocity controls carry the paper's truncated Gaussian noise,
sigma_v 1.65 mm/s, sigma_omega 0.28 rad/s: the robot's defaults). A collision ends a run (a
failed mission in the report), as in the paper. summary.md then holds coverage and
failures per strategy; ``benchmarks/planners.py --part nbvs`` prints the Table 5 layout
(collision rate per k) from the same library code without the tree.

Quick (default): 3 seeds, 6 views. ``--full``: 10 seeds (as in the paper), 12 views. EU uses
the strategy's k = 100 (``--strategies`` lists the strategies; ``benchmarks/planners.py
--part nbvs --ks 1,100,500`` sweeps k). Extra arguments after ``--`` go to ``explore
compare``; re-running the same command resumes::

    .venv/bin/python benchmarks/compare_vasquez.py --out runs/vasquez_quick
    .venv/bin/python benchmarks/compare_vasquez.py --full
"""

from __future__ import annotations

import sys

import compare_grid

WORLD = "cluttered"


def strategies() -> list[str]:
    """The registered Vasquez-Gomez strategies (DU first)."""
    from explore.runtime import Registry

    names = [n for n in Registry.load().names("strategy") if n.startswith("vasquez/")]
    return sorted(names, key=lambda n: (n != "vasquez/du", n))


def main(argv: list[str] | None = None) -> int:
    parser = compare_grid.parser(__doc__, "10 seeds, 12 views")
    args, extra = parser.parse_known_args(argv)
    command = compare_grid.compare_command(
        args, extra, tree="nbvs_mobile", worlds=[WORLD], strategies=strategies(),
        seeds=10 if args.full else 3, max_scans=12 if args.full else 6, timeout=7200,
        out=f"runs/compare_vasquez_{'full' if args.full else 'quick'}",
    )
    return compare_grid.run(command, args.dry_run)


if __name__ == "__main__":
    sys.exit(main())
