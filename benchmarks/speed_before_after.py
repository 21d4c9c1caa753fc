"""Speed before and after a change, in one run: the speed benchmarks of two checkouts, interleaved.

    python benchmarks/speed_before_after.py --before ../before/.venv/bin/python [--rounds 2] [--json]

``--before`` is the Python of a virtual environment with the earlier checkout installed
(``git worktree add ../before <commit>`` then ``EXPLORE_VENV=../before/.venv ../before/run.sh setup``).
Each round runs, for the earlier and for this checkout in turn (A B, then B A, ...), that
checkout's own ``benchmarks/pvs_vs_octomap.py --json`` and ``benchmarks/reproduce_kriegel.py
--speed``. The best of the rounds is kept per quantity (throughputs; selection times as
selections per second), and the table gives after / before with the verdict against a 10 %
tolerance. A selection time is printed to the millisecond, so there the verdict allows one
printed digit on either side (5 vs 6 ms is "the same"). OctoMap's own throughput is measured in
both and shows how much the machine drifted.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

TOLERANCE = 0.10
PRINTED_S = 1e-3  # resolution of the selection times reproduce_kriegel.py --speed prints
PVS_KEYS = (
    "octomap_points_per_s", "pvs_octomap_mode_points_per_s", "pvs_sensor_model_points_per_s",
    "pvs_roi_sensor_model_points_per_s", "ig_visited_visits_per_s", "ig_plain_visits_per_s",
    "ig_parallel_visits_per_s",
)
SPEED_ROW = re.compile(r"^\s*(\d+)\s+(\d+)\s+([\d.]+)\s+([\d.]+)\s+[\d.]+x\s+\w+\s+([\d.]+)\s")


def checkout_of(python: str) -> Path:
    """The source checkout the interpreter imports ``explore`` from."""
    code = "import explore, pathlib; print(pathlib.Path(explore.__file__).resolve().parents[1])"
    found = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True, cwd="/")  # not this folder
    return Path(found.stdout.strip())


def measure(python: str) -> dict[str, float]:
    """Throughputs (higher is better) of one checkout's speed benchmarks, by name."""
    root = checkout_of(python)
    out: dict[str, float] = {}
    pvs = subprocess.run([python, str(root / "benchmarks" / "pvs_vs_octomap.py"), "--json"],
                         capture_output=True, text=True, check=True, cwd=root)
    for scene in json.loads(pvs.stdout)["scenes"]:
        label = f"{scene['world']} {scene['sensor']} {scene['resolution'] * 1000:.0f} mm"
        for key in PVS_KEYS:
            out[f"{label}: {key}"] = scene[key]
    speed = subprocess.run([python, str(root / "benchmarks" / "reproduce_kriegel.py"), "--speed"],
                           capture_output=True, text=True, check=True, cwd=root)
    for line in speed.stdout.splitlines():
        match = SPEED_ROW.match(line)
        if match:
            count, _, uniform, hrt1, hrt2 = match.groups()
            for name, seconds in (("uniform", uniform), ("HRT a=1", hrt1), ("HRT a=2", hrt2)):
                out[f"selection of {count} candidates, {name}: selections_per_s"] = 1.0 / max(float(seconds), 1e-9)
    return out


def within(row: dict) -> bool:
    """After is at most TOLERANCE slower than before (selection times: give or take a printed digit)."""
    if row["quantity"].endswith("selections_per_s"):
        before_s, after_s = 1.0 / row["before"], 1.0 / row["after"]
        return after_s <= before_s * (1.0 + TOLERANCE) + 2 * PRINTED_S
    return row["ratio"] >= 1.0 - TOLERANCE


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="Python of the earlier checkout's virtual environment")
    parser.add_argument("--after", default=sys.executable, help="Python of the later checkout (default: this one)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds, alternating which side goes first")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    best: dict[str, dict[str, float]] = {"before": {}, "after": {}}
    for r in range(args.rounds):
        order = ("before", "after") if r % 2 == 0 else ("after", "before")
        for side in order:
            print(f"round {r + 1}: {side}", file=sys.stderr)
            for key, value in measure(getattr(args, side)).items():
                best[side][key] = max(best[side].get(key, 0.0), value)
    rows = [
        {"quantity": key, "before": best["before"][key], "after": best["after"][key],
         "ratio": best["after"][key] / best["before"][key]}
        for key in best["before"] if key in best["after"]
    ]
    for row in rows:
        row["reference"] = row["quantity"].endswith(": octomap_points_per_s")  # OctoMap itself: the machine's drift
        row["within"] = row["reference"] or within(row)
    ok = all(r["within"] for r in rows)
    if args.json:
        print(json.dumps({"rows": rows, "tolerance": TOLERANCE, "within_tolerance": ok}))
    else:
        width = max(len(r["quantity"]) for r in rows)
        print(f"{'quantity':<{width}} {'before':>10} {'after':>10} {'after/before':>12}")
        for r in rows:
            note = "  (reference: OctoMap)" if r["reference"] else ("" if r["within"] else "  SLOWER")
            print(f"{r['quantity']:<{width}} {r['before']:>10.4g} {r['after']:>10.4g} {r['ratio']:>11.3f}{note}")
        print(f"every quantity within {TOLERANCE:.0%} of before (or faster): {'yes' if ok else 'no'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
