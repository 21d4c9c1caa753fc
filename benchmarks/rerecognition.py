"""Re-recognition: every object modelled in a first scene exploration is recognised in a re-arranged scene.

For each seed: ``explore run scene_exploration`` on the first world with a fresh object database
(unknown objects are modelled and stored), then on each re-arranged world with that database.
An object modelled in the first run counts as re-recognised when the second run recognises it
as its own model (``result: recognised``, ``correct_model: true``).

    python benchmarks/rerecognition.py [--seeds 0-9] [--worlds tabletop_rearranged,tabletop_rearranged2]
                                       [--jobs 2] [--json] [--plot docs/images/qh_margins.png]

Prints a table per re-arranged world (seed, objects modelled, re-recognised, and why not) and the
totals; ``--json`` prints one JSON object instead. Every run also gives, for each recognised
object, the accepted q_h (Kriegel Eq. 3.10) and the best q_h among the hypotheses it rejected
(by q_h or by the PVS votes): how close the call was. ``--plot`` draws their distributions.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from reproduce_kriegel import parse_seeds

EXPLORE = Path(sys.executable).parent / "explore"


def _run(world: str, seed: int, db: Path, out: Path) -> dict:
    args = [str(EXPLORE), "run", "scene_exploration", "--world", world, "--seed", str(seed), "-q", "--threads", "1",
            "--set", f"start_scene.db={db}", "--out", str(out)]
    subprocess.run(args, capture_output=True, text=True, timeout=3600)
    path = out / "metrics.json"
    return json.loads(path.read_text()) if path.exists() else {"status": "crashed", "objects": []}


def q_h_calls(metrics: dict, world: str, seed: int) -> list[dict]:
    """Per object the run found (``objects_found``): the accepted q_h (recognised objects) and the
    best q_h among the hypotheses it rejected (by the q_h threshold or by the PVS votes), if any."""
    calls = []
    for o in metrics.get("objects_found", []):
        rejected = [r for r in o.get("rejected") or [] if r.get("q_h") is not None and math.isfinite(r["q_h"])]
        recognised = o.get("status") == "recognised" and o.get("q_h") is not None
        if not recognised and not rejected:
            continue
        thresholds = [r["q_h"] - r["margin"] for r in rejected if r.get("by") == "q_h"]
        best = max(rejected, key=lambda r: r["q_h"]) if rejected else {}
        calls.append({"world": world, "seed": seed, "object": o.get("id"), "result": o.get("status"),
                      "accepted": o["q_h"] if recognised else None, "model": o.get("model"),
                      "best_rejected": best.get("q_h"), "best_rejected_model": best.get("model"),
                      "best_rejected_by": best.get("by"), "threshold": thresholds[0] if thresholds else None})
    return calls


def plot_margins(calls: list[dict], path: Path) -> None:
    """Histograms of the accepted q_h and of the best rejected q_h per object, with the threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    accepted = [c["accepted"] for c in calls if c["accepted"] is not None]
    rejected = [c["best_rejected"] for c in calls if c["best_rejected"] is not None]
    thresholds = sorted({round(c["threshold"], 6) for c in calls if c["threshold"] is not None})
    fig, ax = plt.subplots(figsize=(8, 4))
    bins = [i / 50 for i in range(51)]
    ax.hist(accepted, bins=bins, alpha=0.7, color="tab:green", label=f"accepted, recognised objects ({len(accepted)})")
    ax.hist(rejected, bins=bins, alpha=0.7, color="tab:red", label=f"best rejected, per object ({len(rejected)})")
    for t in thresholds:
        ax.axvline(t, color="k", linestyle="--", label=f"threshold q_h = {t:g}")
    if accepted and rejected:
        ax.set_title(f"lowest accepted {min(accepted):.3f}, highest rejected {max(rejected):.3f}")
    ax.set_xlabel("q_h (render-and-compare quality, Kriegel Eq. 3.10)")
    ax.set_ylabel("objects")
    ax.legend(loc="upper left")
    fig.suptitle("How close the recognition calls were (every run of the re-recognition benchmark)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def one_seed(first: str, second: list[str], seed: int, tmp: Path) -> list[dict]:
    """The first exploration once, then each re-arranged world with its own copy of the database."""
    db = tmp / "first" / "objects.db"
    db.parent.mkdir(parents=True)
    a = _run(first, seed, db, tmp / "first" / "run")
    first_calls = q_h_calls(a, first, seed)
    # every model the first run stored, also those short of the coverage target
    modelled = {o["name"]: o.get("model") for o in a.get("objects", []) if o.get("result") in ("modelled", "partial")}
    rows = []
    for world in second:
        copy = tmp / world / "objects.db"
        copy.parent.mkdir(parents=True)
        if not db.exists():  # the first run ended before it stored anything
            rows.append({"world": world, "seed": seed, "first_status": a.get("status"), "second_status": None,
                         "modelled": [], "rerecognised": [], "missed": {"(first run)": a.get("reason", "no metrics")},
                         "q_h_calls": first_calls})
            first_calls = []  # the first run's calls are counted once
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
                     "missed": missed, "q_h_calls": first_calls + q_h_calls(b, world, seed)})
        first_calls = []  # the first run's calls are counted once
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", default="tabletop")
    parser.add_argument("--worlds", default="tabletop_rearranged,tabletop_rearranged2")
    parser.add_argument("--seeds", default="0-9")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--plot", type=Path, default=None, help="PNG of the accepted and best rejected q_h")
    args = parser.parse_args()
    worlds = [w for w in args.worlds.split(",") if w]
    with tempfile.TemporaryDirectory(prefix="rerecognition-") as tmp, ThreadPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(one_seed, args.first, worlds, seed, Path(tmp) / str(seed))
                   for seed in parse_seeds(args.seeds)]
        rows = [row for future in futures for row in future.result()]
    calls = [c for r in rows for c in r["q_h_calls"]]
    if args.plot:
        plot_margins(calls, args.plot)
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
    accepted = [c["accepted"] for c in calls if c["accepted"] is not None]
    rejected = [c["best_rejected"] for c in calls if c["best_rejected"] is not None]
    gaps = [c["accepted"] - c["best_rejected"] for c in calls
            if c["accepted"] is not None and c["best_rejected"] is not None]
    if accepted:
        print(f"\nq_h: {len(accepted)} recognised objects accepted at {min(accepted):.3f}-{max(accepted):.3f}; "
              f"{len(rejected)} objects rejected hypotheses, the best at "
              + (f"{min(rejected):.3f}-{max(rejected):.3f}" if rejected else "-")
              + (f"; smallest lead of a recognised object over its best rejected one {min(gaps):.3f}" if gaps else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
