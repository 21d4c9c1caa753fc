"""Vasquez-Gomez Fig. 11: EU-MU's collision rate against the number of rollouts k, DU and DU-MU beside it.

Reads the NBVS runs that ``benchmarks/planners.py --part nbvs --runs-file FILE`` wrote (one JSON
line per run), groups them by executor (open loop / re-localising), approach and k, prints one
row per group and draws the collision rate per executed move (the paper's definition: collisions
over planned trajectories executed) against k on a log axis, with DU-MU (and DU) as flat lines
since k does not enter them, and the mean coverage in a second panel::

    .venv/bin/python benchmarks/planners.py --part nbvs --open-loop --approaches DU-MU,EU-MU \\
        --ks 1,10,100,500 --seeds 5 --runs-file runs/fig11.jsonl
    .venv/bin/python benchmarks/collision_vs_k.py runs/fig11.jsonl --plot docs/images/collision_vs_k.png
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

REQUIRED = ("approach", "k", "collisions", "trajectories", "final_coverage", "views", "seed")
# settings every run of one figure shares (older records lack some: planners.py's defaults then)
SHARED = {"world": "cluttered", "max_views": 12, "min_unknown": 30, "weighting": "probability"}


def read_runs(paths: list[str]) -> list[dict[str, Any]]:
    """Every run of the given JSON-lines files; a bad file or line raises ValueError naming it."""
    runs = []
    for path in paths:
        try:
            lines = Path(path).read_text(encoding="utf-8").splitlines()
        except OSError as error:
            raise ValueError(f"{path}: cannot read ({error.strerror})") from None
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                run = json.loads(line)
            except json.JSONDecodeError:
                raise ValueError(f"{path}:{number}: not a JSON line") from None
            missing = [key for key in REQUIRED if key not in run]
            if missing:
                raise ValueError(f"{path}:{number}: no {', '.join(missing)} (not a run of planners.py --part nbvs)")
            runs.append(run)
    if not runs:
        raise ValueError(f"{', '.join(paths)}: no runs")
    for key, default in SHARED.items():
        values = sorted({str(run.get(key, default)) for run in runs})
        if len(values) > 1:
            raise ValueError(f"{', '.join(paths)}: runs of different {key} ({', '.join(values)}) in one figure; "
                             "give the runs of one setting")
    return runs


def rows_of(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (world, executor, approach, k): runs, collision rate per move, runs with a collision,
    mean coverage and views."""
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for run in runs:
        executor = "re-localising" if run.get("relocalise") else "open loop"
        k = run["k"] if run["approach"] == "EU-MU" else None
        groups[(run.get("world", "cluttered"), executor, run["approach"], k)].append(run)
    rows = []
    for (world, executor, approach, k), group in sorted(groups.items(), key=lambda item: (
            item[0][0], item[0][1], item[0][2], item[0][3] or 0)):
        moves = sum(r["trajectories"] for r in group)
        rows.append({
            "world": world, "executor": executor, "approach": approach, "k": k, "runs": len(group),
            "moves": moves, "collisions": sum(r["collisions"] for r in group),
            "collision_rate": sum(r["collisions"] for r in group) / max(1, moves),
            "runs_with_collision": sum(1 for r in group if r["collisions"]) / len(group),
            "mean_coverage": sum(r["final_coverage"] for r in group) / len(group),
            "mean_views": sum(r["views"] for r in group) / len(group),
        })
    return rows


def plot(rows: list[dict[str, Any]], path: str) -> None:
    """Collision rate and mean coverage against k, one colour per executor."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for colour, executor in zip(("tab:red", "tab:blue"), ("open loop", "re-localising"), strict=True):
        eu = [r for r in rows if r["executor"] == executor and r["approach"] == "EU-MU"]
        for ax, key in zip(axes, ("collision_rate", "mean_coverage"), strict=True):
            if eu:
                ax.plot([r["k"] for r in eu], [100 * r[key] for r in eu], "o-", color=colour,
                        label=f"EU-MU, {executor}")
            for r in rows:
                if r["executor"] == executor and r["approach"] in ("DU", "DU-MU"):
                    ax.axhline(100 * r[key], color=colour, ls="--" if r["approach"] == "DU-MU" else ":",
                               label=f"{r['approach']}, {executor} ({r['runs']} runs)")
    for ax, label in zip(axes, ("collision rate per move (%)", "mean coverage (%)"), strict=True):
        ax.set_xscale("log")
        ax.set_xlabel("rollouts per candidate k")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylim(bottom=0)
    axes[0].legend(fontsize=8)
    world = rows[0]["world"]
    fig.suptitle(f"Vasquez-Gomez Fig. 11 on {world}: EU-MU against k (mobile manipulator, "
                 "sigma_v 1.65 mm/s, sigma_w 0.28 rad/s)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="JSON-lines files of planners.py --part nbvs --runs-file")
    parser.add_argument("--plot", default=None, help="write the figure to this PNG")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args(argv)
    try:
        rows = rows_of(read_runs(args.runs))
    except ValueError as error:
        print(f"collision_vs_k.py: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print("world        executor       approach    k  runs  moves  collision rate  runs w/ collision  "
              "mean coverage  mean views")
        for r in rows:
            k = "-" if r["k"] is None else str(r["k"])
            print(f"{r['world']:12s} {r['executor']:14s} {r['approach']:8s} {k:>4s} {r['runs']:5d} {r['moves']:6d} "
                  f"{r['collision_rate']:15.1%} {r['runs_with_collision']:18.0%} {r['mean_coverage']:14.1%} "
                  f"{r['mean_views']:11.1f}")
    if args.plot:
        plot(rows, args.plot)
        if not args.json:
            print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
