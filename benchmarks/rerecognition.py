"""Re-recognition: every object modelled in a first scene exploration is recognised in a re-arranged scene.

For each seed: ``explore run scene_exploration`` on the first world with a fresh object database
(unknown objects are modelled and stored), then on each re-arranged world with that database.
An object modelled in the first run counts as re-recognised when the second run recognises it
as its own model (``result: recognised``, ``correct_model: true``).

    python benchmarks/rerecognition.py [--seeds 0-9] [--worlds tabletop_rearranged,tabletop_rearranged2]
                                       [--jobs 2] [--json]

Prints a table per re-arranged world (seed, objects modelled, re-recognised, and why not) and the
totals; ``--json`` prints one JSON object instead.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

EXPLORE = Path(sys.executable).parent / "explore"


def _seeds(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",") if s]


def _run(world: str, seed: int, db: Path, out: Path) -> dict:
    args = [str(EXPLORE), "run", "scene_exploration", "--world", world, "--seed", str(seed), "-q", "--threads", "1",
            "--set", f"start_scene.db={db}", "--out", str(out)]
    subprocess.run(args, capture_output=True, text=True, timeout=3600)
    path = out / "metrics.json"
    return json.loads(path.read_text()) if path.exists() else {"status": "crashed", "objects": []}


def one_seed(first: str, second: list[str], seed: int, tmp: Path) -> list[dict]:
    """The first exploration once, then each re-arranged world with its own copy of the database."""
    db = tmp / "first" / "objects.db"
    db.parent.mkdir(parents=True)
    a = _run(first, seed, db, tmp / "first" / "run")
    modelled = {o["name"]: o.get("model") for o in a.get("objects", []) if o.get("result") == "modelled"}
    rows = []
    for world in second:
        copy = tmp / world / "objects.db"
        copy.parent.mkdir(parents=True)
        if not db.exists():  # the first run ended before it stored anything
            rows.append({"world": world, "seed": seed, "first_status": a.get("status"), "second_status": None,
                         "modelled": [], "rerecognised": [], "missed": {"(first run)": a.get("reason", "no metrics")}})
            continue
        shutil.copy(db, copy)
        if db.with_suffix(".meshes").is_dir():
            shutil.copytree(db.with_suffix(".meshes"), copy.with_suffix(".meshes"))
        b = _run(world, seed, copy, tmp / world / "run")
        found = {o["name"]: o for o in b.get("objects", [])}
        missed = {}
        for name, model in modelled.items():
            row = found.get(name, {})
            if not (row.get("result") == "recognised" and row.get("model") == model and row.get("correct_model")):
                seen_as = f" as {row.get('model')}" if row.get("model") else ""
                missed[name] = f"{row.get('result', 'absent')}{seen_as}"
        rows.append({"world": world, "seed": seed, "first_status": a.get("status"), "second_status": b.get("status"),
                     "modelled": sorted(modelled), "rerecognised": sorted(set(modelled) - set(missed)),
                     "missed": missed})
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", default="tabletop")
    parser.add_argument("--worlds", default="tabletop_rearranged,tabletop_rearranged2")
    parser.add_argument("--seeds", default="0-9")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    worlds = [w for w in args.worlds.split(",") if w]
    with tempfile.TemporaryDirectory(prefix="rerecognition-") as tmp, ThreadPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(one_seed, args.first, worlds, seed, Path(tmp) / str(seed))
                   for seed in _seeds(args.seeds)]
        rows = [row for future in futures for row in future.result()]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    for world in worlds:
        mine = [r for r in rows if r["world"] == world]
        print(f"\n{args.first} -> {world}\n")
        print("| seed | modelled in the first run | re-recognised | not re-recognised |")
        print("| ---: | --- | --- | --- |")
        for r in mine:
            missed = ", ".join(f"{k} ({v})" for k, v in r["missed"].items()) or "-"
            print(f"| {r['seed']} | {', '.join(r['modelled']) or '-'} | {len(r['rerecognised'])}/{len(r['modelled'])} "
                  f"| {missed} |")
        total = sum(len(r["modelled"]) for r in mine)
        good = sum(len(r["rerecognised"]) for r in mine)
        complete = sum(1 for r in mine if not r["missed"])
        print(f"\nre-recognised {good} of {total} modelled objects; every one in {complete} of {len(mine)} seeds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
