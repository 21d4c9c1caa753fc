"""Reproduce Kriegel's thesis Table 4.5 (NBV benchmark) on the pedestal worlds.

Every strategy x world x seed runs the Python modelling loop with a free-flying laser
striper from a random initial scan path (5 sides / 8 edges of the region box) for
``--max-scans`` scans; the termination rule's first "stop" gives n_s (the run goes on to the
end regardless, as in the thesis). Printed per strategy x world, in the layout of Table 4.5:

    median n_s, notch = ±1.57 IQR/√s (Eq. 4.41), mean c_a(n_s) %, mean c_a(10) %,
    median c_a(10) %, mean c_a(30) % (c_a at the last scan if fewer), mean l_s (total scan
    path over all scans, m), mean t_nbs (s per selection), max t_nbs, max candidates scored.

``--json`` prints only the rows as a JSON list of objects with the keys ``strategy``,
``world``, ``median_scans``, ``coverage_at_termination``, ``coverage_at_10``,
``coverage_at_30``, ``path_length_m``, ``selection_s`` (coverages in percent, means over
seeds as in the thesis; ``coverage_at_10`` / ``coverage_at_30`` are null when fewer scans
were run).

Quick run (a few minutes on 2 cores)::

    .venv/bin/python benchmarks/reproduce_kriegel.py --quick

Full run::

    .venv/bin/python benchmarks/reproduce_kriegel.py --worlds bunny_pedestal,duck_pedestal,teddy_pedestal \\
        --seeds 0-9 --max-scans 30
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

QUICK_STRATEGIES = ["ig_quality/bs_hr", "ig_quality/sphere", "random/bs_hr"]


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        elif part:
            out.append(int(part))
    return out


def run_one(registry, world: str, strategy: str, seed: int, max_scans: int, variant: str | None,
            hierarchy: int) -> dict:
    from explore.modelling import ModellingSession
    from explore.simulation import Simulation

    params: dict = {}
    info = registry.get("strategy", strategy)
    utility_name = getattr(info.factory, "parts", ("", "", ""))[1]
    utility_params: dict = {}
    if variant and utility_name == "ig_quality":
        utility_params["variant"] = variant
    if hierarchy and utility_name not in ("random", "fov_order"):
        utility_params["hierarchy"] = hierarchy
    if utility_params:
        params["utility_params"] = utility_params
    with Simulation(world, registry) as sim:
        session = ModellingSession(sim, (strategy, params), registry, seed=seed, max_scans=max_scans,
                                   continue_after_stop=True)
        start = time.perf_counter()
        result = session.run()
        metrics = result.metrics
        metrics["run_s"] = time.perf_counter() - start
    return metrics


def summarise(runs: list[dict], strategy: str, world: str) -> dict:
    n_s = np.array([r["n_s"] for r in runs], dtype=float)
    q1, q3 = np.percentile(n_s, [25, 75])
    notch = 1.57 * (q3 - q1) / np.sqrt(len(n_s))

    def at(curve: list[float], k: int) -> float:
        return curve[min(k, len(curve)) - 1] if curve else float("nan")

    c_term = [at(r["coverage"], r["n_s"]) for r in runs]
    c10 = [at(r["coverage"], 10) for r in runs]
    c30 = [at(r["coverage"], 30) for r in runs]
    sel = [t for r in runs for t in r["selection_s"]]
    cands = [c for r in runs for c in r["selection_candidates"]]
    scans = min(len(r["coverage"]) for r in runs)
    return {
        "strategy": strategy,
        "world": world,
        "median_scans": float(np.median(n_s)),
        "coverage_at_termination": 100.0 * float(np.mean(c_term)),
        "coverage_at_10": 100.0 * float(np.mean(c10)) if scans >= 10 else None,
        "coverage_at_30": 100.0 * float(np.mean(c30)) if scans >= 30 else None,
        "path_length_m": float(np.mean([r["scan_path_m"] for r in runs])),
        "selection_s": float(np.mean(sel)) if sel else 0.0,
        # extra columns for the printed table only
        "_notch": float(notch),
        "_median_c10": 100.0 * float(np.median(c10)),
        "_c_last": 100.0 * float(np.mean([at(r["coverage"], scans) for r in runs])),
        "_scans": scans,
        "_max_sel": float(max(sel)) if sel else 0.0,
        "_max_cands": int(max(cands)) if cands else 0,
        "_travel": float(np.mean([r["travel_m"] for r in runs])),
        "_seeds": len(runs),
    }


ROW_KEYS = ("strategy", "world", "median_scans", "coverage_at_termination", "coverage_at_10", "coverage_at_30",
            "path_length_m", "selection_s")


def print_table(rows: list[dict]) -> None:
    head = (f"{'Selection/Search':22s} {'world':15s} {'ñ_s':>5s} {'notch':>6s} {'c_a(n_s)':>9s} "
            f"{'c_a(10)':>8s} {'med(10)':>8s} {'c_a(last)':>9s} {'l_s/m':>6s} {'travel':>6s} "
            f"{'t_nbs/s':>8s} {'max t':>6s} {'cands':>5s}")
    print(head)
    print("-" * len(head))
    for r in rows:
        last = f"{r['_c_last']:8.2f}" + ("" if r["_scans"] >= 30 else "*")
        c10 = r["coverage_at_10"] if r["coverage_at_10"] is not None else float("nan")
        print(f"{r['strategy']:22s} {r['world']:15s} {r['median_scans']:5.1f} ±{r['_notch']:5.2f} "
              f"{r['coverage_at_termination']:9.2f} {c10:8.2f} {r['_median_c10']:8.2f} {last:>9s} "
              f"{r['path_length_m']:6.2f} {r['_travel']:6.2f} {r['selection_s']:8.3f} {r['_max_sel']:6.2f} "
              f"{r['_max_cands']:5d}")
    if any(r["_scans"] < 30 for r in rows):
        print(f"* c_a after {rows[0]['_scans']} scans (fewer than 30 were run)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default="bunny_pedestal,duck_pedestal,teddy_pedestal")
    parser.add_argument("--seeds", default="0-4", help="e.g. 0-9 or 0,3,5")
    parser.add_argument("--strategies", default="table4.5", help="comma list, 'table4.5' or 'iros'")
    parser.add_argument("--max-scans", type=int, default=30)
    parser.add_argument("--variant", choices=("need", "kriegel_literal"), default=None,
                        help="quality term of ig_quality (default: the strategy's, i.e. need)")
    parser.add_argument("--hierarchy", type=int, default=0, help="hierarchical ray tracing level a")
    parser.add_argument("--quick", action="store_true",
                        help="bunny only, seeds 0-2, 3 strategies, 12 scans (a few minutes)")
    parser.add_argument("--json", action="store_true", help="print only the rows as JSON")
    args = parser.parse_args(argv)

    from explore_plugins.strategies import IROS, TABLE_4_5

    from explore.registry import Registry

    registry = Registry.load()
    worlds = [w for w in args.worlds.split(",") if w]
    seeds = parse_seeds(args.seeds)
    if args.strategies == "table4.5":
        strategies = list(TABLE_4_5)
    elif args.strategies == "iros":
        strategies = [cls.name for cls in IROS]
    else:
        strategies = [s for s in args.strategies.split(",") if s]
    max_scans = args.max_scans
    if args.quick:
        worlds, seeds, strategies, max_scans = ["bunny_pedestal"], [0, 1, 2], QUICK_STRATEGIES, 12
    rows = []
    for world in worlds:
        for strategy in strategies:
            runs = []
            for seed in seeds:
                runs.append(run_one(registry, world, strategy, seed, max_scans, args.variant, args.hierarchy))
                if not args.json:
                    r = runs[-1]
                    curve = [round(100 * c, 1) for c in r["coverage"]]
                    print(f"  {strategy} {world} seed {seed}: n_s={r['n_s']} c_a={curve} "
                          f"l_s={r['scan_path_m']:.2f} m, {r['run_s']:.1f} s", file=sys.stderr, flush=True)
            rows.append(summarise(runs, strategy, world))
    if args.json:
        print(json.dumps([{k: r[k] for k in ROW_KEYS} for r in rows], indent=1))
    else:
        print_table(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
