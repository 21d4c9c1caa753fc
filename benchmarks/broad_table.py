"""The broad set's table (issue 20, item 2) from the runs ``reproduce_kriegel.py --runs-json`` wrote.

Per object: the main strategy's median c_a after 10 scans, lowest final c_a, median ñ_s (the
strategy's own termination rule, for Table 4.5's strategies the thesis rule ĉ_m 80 %, d̄_m 20 %),
mean ĉ_m → mean c_a at ñ_s, mean scan path l_s and sphere-fallback scans; the sphere variant with
the smallest median ñ_s (ties: the higher median c_a(10)); and, as a measure that no estimate's
bias enters, n_97: the median number of scans until the ground-truth c_a first reaches 97 % (a run
that never does counts as its budget + 1), for the main strategy and the best sphere variant by n_97.

    .venv/bin/python benchmarks/broad_table.py broad.json [--main ig_quality/bs_hr] [--markdown]
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

TARGET = 0.97


def scans_to(curve: list[float], target: float = TARGET) -> int:
    """The first scan (1-based) whose c_a reaches ``target``; len(curve) + 1 if none does."""
    reached = np.flatnonzero(np.asarray(curve) >= target)
    return int(reached[0]) + 1 if len(reached) else len(curve) + 1


def at(curve: list[float], scans: int) -> float:
    """c_a after ``scans`` scans (a run that ended earlier keeps its last value)."""
    return float(curve[min(scans, len(curve)) - 1])


def summary(runs: list[dict]) -> dict[str, float]:
    """The numbers of one strategy on one object over its seeds."""
    stops = [max(int(r["n_s"]), 1) for r in runs]
    at_stop = list(zip(runs, stops, strict=True))
    return {
        "c10": 100.0 * float(np.median([at(r["coverage"], 10) for r in runs])),
        "final_min": 100.0 * min(r["coverage"][-1] for r in runs),
        "n_s": float(np.median(stops)),
        "estimate_at_stop": 100.0 * float(np.mean([at(r["coverage_estimate"], n) for r, n in at_stop])),
        "ca_at_stop": 100.0 * float(np.mean([at(r["coverage"], n) for r, n in at_stop])),
        "l_s": float(np.mean([r["scan_path_m"] for r in runs])),
        "fallback": float(np.mean([r.get("fallback_scans", 0) for r in runs])),
        "n_97": float(np.median([scans_to(r["coverage"]) for r in runs])),
    }


def table(runs: list[dict], main: str) -> list[dict]:
    """One row per object: the main strategy, the best sphere variants and the comparisons."""
    grouped: dict[str, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for run in runs:
        grouped[run["world"]][run["strategy"]].append(run)
    rows = []
    for world, by_strategy in grouped.items():
        if main not in by_strategy:
            continue
        stats = {name: summary(rs) for name, rs in by_strategy.items()}
        spheres = {name: s for name, s in stats.items() if name.endswith("/sphere")}
        row = {"object": world.removeprefix("broad_"), "main": stats[main]}
        if spheres:
            by_ns = min(spheres, key=lambda n: (spheres[n]["n_s"], -spheres[n]["c10"]))
            by_97 = min(spheres, key=lambda n: (spheres[n]["n_97"], -spheres[n]["c10"]))
            row.update(sphere=by_ns, sphere_stats=spheres[by_ns], sphere_97=by_97, sphere_97_stats=spheres[by_97],
                       ns_ok=stats[main]["n_s"] <= spheres[by_ns]["n_s"],
                       n97_ok=stats[main]["n_97"] <= spheres[by_97]["n_97"],
                       shortest=stats[main]["l_s"] <= min(s["l_s"] for s in stats.values()))
        rows.append(row)
    return rows


def markdown(rows: list[dict]) -> str:
    """The rows as the table of docs/results.md."""
    yes = {True: "yes", False: "no"}
    lines = ["| object | c_a(10) median | final c_a min | ñ_s | ĉ_m → c_a at the stop | l_s (m) "
             "| sphere fallback scans | best sphere by ñ_s: variant, ñ_s, l_s (m), c_a(10) median | ñ_s ≤ sphere "
             "| n_97 | best sphere by n_97 | n_97 ≤ sphere | shortest l_s |",
             "|---|---:|---:|---:|---|---:|---:|---|---|---:|---|---|---|"]
    for row in rows:
        m = row["main"]
        text = (f"| {row['object']} | {m['c10']:.1f} | {m['final_min']:.1f} | {m['n_s']:g} | "
                f"{m['estimate_at_stop']:.1f} → {m['ca_at_stop']:.1f} | {m['l_s']:.2f} | {m['fallback']:.1f} |")
        if "sphere" in row:
            s, s97 = row["sphere_stats"], row["sphere_97_stats"]
            text += (f" {row['sphere']}, {s['n_s']:g}, {s['l_s']:.2f}, {s['c10']:.1f} | {yes[row['ns_ok']]} | "
                     f"{m['n_97']:g} | {row['sphere_97']}, {s97['n_97']:g} | {yes[row['n97_ok']]} | "
                     f"{yes[row['shortest']]} |")
        lines.append(text)
    if rows and "sphere" in rows[0]:
        n = len(rows)
        counts = {key: sum(bool(r.get(key)) for r in rows) for key in ("ns_ok", "n97_ok", "shortest")}
        lines.append("")
        lines.append(f"median c_a(10) >= 97 %: {sum(r['main']['c10'] >= 97.0 for r in rows)} of {n}; "
                     f"final c_a >= 99 %: {sum(r['main']['final_min'] >= 99.0 for r in rows)} of {n}; "
                     f"ñ_s <= best sphere: {counts['ns_ok']} of {n}; n_97 <= best sphere: {counts['n97_ok']} of {n}; "
                     f"shortest l_s: {counts['shortest']} of {n}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="the --runs-json file of reproduce_kriegel.py")
    parser.add_argument("--main", default="ig_quality/bs_hr", help="the strategy the rows are about")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args(argv)
    try:
        runs = json.loads(args.runs.read_text())
    except (OSError, ValueError) as error:
        parser.error(f"{args.runs}: cannot read the runs ({error})")
    rows = table(runs, args.main)
    if not rows:
        parser.error(f"{args.runs}: no run of {args.main}")
    print(json.dumps(rows, indent=1) if args.json else markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
