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

import argparse
import sys

WORLD = "cluttered"


def strategies() -> list[str]:
    """The registered Vasquez-Gomez strategies (DU first)."""
    from explore.registry import Registry

    names = [n for n in Registry.load().names("strategy") if n.startswith("vasquez/")]
    return sorted(names, key=lambda n: (n != "vasquez/du", n))


def arguments(argv: list[str] | None = None) -> list[str]:
    """The ``explore compare`` arguments of the chosen grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="10 seeds, 12 views")
    parser.add_argument("--seeds", type=int, help="override the number of seeds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local")
    parser.add_argument("--ray-address")
    parser.add_argument("--out", default=None)
    parser.add_argument("--dry-run", action="store_true", help="only print the command")
    args, extra = parser.parse_known_args(argv)
    command = [
        "compare", "--tree", "nbvs_mobile", "--worlds", WORLD, "--strategies", ",".join(strategies()),
        "--seeds", str(args.seeds or (10 if args.full else 3)), "--max-scans", "12" if args.full else "6",
        "--jobs", str(args.jobs), "--executor", args.executor, "--timeout", "7200",
        "--out", args.out or f"runs/compare_vasquez_{'full' if args.full else 'quick'}",
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
