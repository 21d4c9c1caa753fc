"""Shared command line of the ``explore compare`` reproduction scripts (compare_*.py).

Each script picks a grid (tree, worlds, strategies, planners, seeds, scans); the options
common to all of them (seeds override, jobs, executor, Ray address, output folder, dry run)
and the hand-over to ``explore compare`` live here. Arguments after ``--`` go to
``explore compare`` unchanged.
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence


def parser(doc: str, full_help: str) -> argparse.ArgumentParser:
    """Options every reproduction script has; ``full_help`` says what ``--full`` runs."""
    out = argparse.ArgumentParser(description=doc.splitlines()[0])
    out.add_argument("--full", action="store_true", help=full_help)
    out.add_argument("--seeds", type=int, help="override the number of seeds")
    out.add_argument("--jobs", type=int, default=2)
    out.add_argument("--executor", default="local")
    out.add_argument("--ray-address")
    out.add_argument("--out", default=None)
    out.add_argument("--dry-run", action="store_true", help="only print the command")
    return out


def compare_command(args: argparse.Namespace, extra: Sequence[str], *, tree: str, worlds: Sequence[str],
                    strategies: Sequence[str], seeds: int, max_scans: int, out: str,
                    planners: Sequence[str] = (), timeout: int = 3600, variants: Sequence[str] = ()) -> list[str]:
    """The ``explore compare`` arguments of a grid (``args.seeds`` overrides ``seeds``); ``variants`` are
    ``--variant`` values (``NAME: key=value; ...``)."""
    command = [
        "compare", "--tree", tree, "--worlds", ",".join(worlds),
        "--seeds", str(args.seeds or seeds), "--max-scans", str(max_scans), "--jobs", str(args.jobs),
        "--executor", args.executor, "--timeout", str(timeout), "--out", args.out or out,
    ]
    if strategies:
        command += ["--strategies", ",".join(strategies)]
    if planners:
        command += ["--planners", ",".join(planners)]
    for variant in variants:
        command += ["--variant", variant]
    if args.ray_address:
        command += ["--ray-address", args.ray_address]
    return command + [a for a in extra if a != "--"]


def run(command: list[str], dry_run: bool = False) -> int:
    """Print the command, then run it in this process (unless ``dry_run``); its exit code."""
    print("explore " + shlex.join(command))
    if dry_run:
        return 0
    from explore_cli.main import main as explore

    return explore(command)
