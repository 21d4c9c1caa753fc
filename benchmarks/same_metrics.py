"""Same seeds, same results across a code change: a fixed set of runs over every tree and robot.

    python benchmarks/same_metrics.py --save before.json     # on the old code
    python benchmarks/same_metrics.py --check before.json    # on the new code: lists every difference

Each run's metrics.json and trace.jsonl are kept without wall times, tick numbers and paths
(:func:`explore.runtime.rundiff.comparable`); ``--check`` runs the set again and compares run by run.
Runs go one at a time with ``--threads 1`` (the result does not depend on it; it keeps the
two cores for the machine). Exit code 1 if anything differs.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from explore.runtime import comparable, differences, load_run

EXPLORE = Path(sys.executable).parent / "explore"
SMALL_NBVS = ["--set", "start_nbvs.n_samples=800", "--set", "start_nbvs.top=6"]
# name -> (tree, world, arguments): every tree, every robot plugin (free flyer, arm, mobile base,
# mobile manipulator), small budgets
RUNS: dict[str, tuple[str, str, list[str]]] = {
    "model_free_flyer": ("model_object", "bunny_pedestal", ["--max-scans", "5"]),
    "model_free_flyer_iros": ("model_object", "duck_pedestal", ["--max-scans", "4", "--strategy", "iros/BH_IG"]),
    "model_arm": ("model_object", "workcell", ["--max-scans", "3"]),
    "model_mobile_manipulator": ("model_object", "cluttered", ["--max-scans", "2", "--planner", "straight_line"]),
    "nbvs_eu": ("nbvs_mobile", "cluttered", ["--strategy", "vasquez/eu", "--max-scans", "3", *SMALL_NBVS,
                                             "--set", "strategy.k=10"]),
    "nbvs_du": ("nbvs_mobile", "cluttered", ["--strategy", "vasquez/du", "--max-scans", "3", *SMALL_NBVS]),
    "scene_free_flyer": ("scene_exploration", "scene_small", []),
    "scene_arm": ("scene_exploration", "workcell", []),
    "patrol_mobile_base": ("table_patrol", "scene_small_mobile", []),
}
SCENE_TREES = ("scene_exploration", "table_patrol")


def run_all(names: list[str], seed: int) -> dict[str, dict]:
    out: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="same-metrics-") as tmp:
        for name in names:
            tree, world, extra = RUNS[name]
            run_dir = Path(tmp) / name
            scene = ["--set", f"start_scene.db={Path(tmp) / name}.db"] if tree in SCENE_TREES else []
            args = [str(EXPLORE), "run", tree, "--world", world, "--seed", str(seed), "--threads", "1", "-q",
                    "--out", str(run_dir), *extra, *scene]
            done = subprocess.run(args, capture_output=True, text=True, timeout=1800)
            if not (run_dir / "metrics.json").exists():
                raise SystemExit(f"{name}: no metrics ({done.returncode}): {done.stderr[-500:]}")
            metrics, trace = load_run(run_dir)
            out[name] = {"metrics": comparable(metrics), "trace": comparable(trace)}
            print(f"{name}: {metrics['status']} ({metrics.get('reason', '')})", file=sys.stderr)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    action = parser.add_mutually_exclusive_group(required=True)
    action.add_argument("--save", type=Path, help="write the runs' comparable results to this file")
    action.add_argument("--check", type=Path, help="compare with a file written by --save")
    parser.add_argument("--runs", default=",".join(RUNS), help="comma-separated subset of: " + ", ".join(RUNS))
    parser.add_argument("--seed", type=int, default=2)
    args = parser.parse_args()
    names = [n for n in args.runs.split(",") if n]
    unknown = sorted(set(names) - set(RUNS))
    if unknown:
        parser.error(f"unknown runs: {', '.join(unknown)}")
    results = run_all(names, args.seed)
    if args.save:
        args.save.write_text(json.dumps({"seed": args.seed, "runs": results}, indent=1) + "\n", encoding="utf-8")
        print(f"saved {len(results)} runs to {args.save}")
        return 0
    before = json.loads(args.check.read_text(encoding="utf-8"))
    if before["seed"] != args.seed:
        parser.error(f"{args.check} was saved with --seed {before['seed']}")
    failed = 0
    for name in names:
        lines = differences(before["runs"].get(name), results[name])
        failed += bool(lines)
        print(f"{name}: {'same' if not lines else f'{len(lines)} differences'}")
        for line in lines[:10]:
            print(f"    {line}")
    print(f"{len(names) - failed} of {len(names)} runs the same")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
