"""Vasquez-Gomez et al. Table 5: deterministic (DU) vs expected utility (EU) under positioning noise.

Runs ``explore compare`` with the ``vasquez/*`` strategies that are registered (``vasquez/du``;
``vasquez/eu`` when present) on a mobile manipulator whose velocity controls carry the paper's
truncated Gaussian noise (sigma_v 1.65 mm/s, sigma_omega 0.28 rad/s: the robot's defaults).
summary.md then holds the Table 5 layout (mean / max coverage, collision rate).

Quick (default): bunny pedestal, 3 seeds, 8 scans. ``--full``: bunny, teddy and duck
pedestals, 10 seeds (as in the paper), 15 scans. Extra arguments after ``--`` go to
``explore compare``; re-running the same command resumes::

    .venv/bin/python benchmarks/compare_vasquez.py --out runs/vasquez_quick
    .venv/bin/python benchmarks/compare_vasquez.py --full -- --set robot.sigma_v=0.00165
"""

from __future__ import annotations

import argparse
import sys

ROBOT = "mobile_manipulator"


def strategies() -> list[str]:
    """The registered Vasquez-Gomez strategies (DU first)."""
    from explore.registry import Registry

    names = [n for n in Registry.load().names("strategy") if n.startswith("vasquez/")]
    return sorted(names, key=lambda n: (n != "vasquez/du", n))


def arguments(argv: list[str] | None = None) -> list[str]:
    """The ``explore compare`` arguments of the chosen grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="3 worlds, 10 seeds, 15 scans")
    parser.add_argument("--seeds", type=int, help="override the number of seeds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--executor", default="local")
    parser.add_argument("--ray-address")
    parser.add_argument("--out", default=None)
    parser.add_argument("--dry-run", action="store_true", help="only print the command")
    args, extra = parser.parse_known_args(argv)
    worlds = "bunny_pedestal,teddy_pedestal,duck_pedestal" if args.full else "bunny_pedestal"
    command = [
        "compare", "--tree", "model_object", "--worlds", worlds, "--strategies", ",".join(strategies()),
        "--robots", ROBOT, "--seeds", str(args.seeds or (10 if args.full else 3)),
        "--max-scans", "15" if args.full else "8", "--jobs", str(args.jobs), "--executor", args.executor,
        "--timeout", "3600", "--out", args.out or f"runs/compare_vasquez_{'full' if args.full else 'quick'}",
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
