"""Reproduce Kriegel's thesis Table 4.5 (NBV benchmark) on the pedestal worlds.

Every strategy x world x seed runs the Python modelling loop with a free-flying laser
striper from a random initial scan path (5 sides / 8 edges of the region box) for
``--max-scans`` scans; the termination rule's first "stop" gives n_s (the run goes on
regardless, as in the thesis, until the strategy has no candidate left). Printed per
strategy x world, in the layout of Table 4.5 plus the ground-truth quality columns:

    median n_s, notch = ±1.57 IQR/√s (Eq. 4.41), mean c_a(n_s) %, mean and median c_a(10) %,
    mean c_a(30) % (a run that ended earlier keeps its last value), mean scans taken, mean
    l_s (total scan path, m), mean t_nbs (s per selection) and the largest candidate count,
    RMS error ē and Chamfer distance of the final model (mm), coverage AUC over the budget,
    final ĉ_m %, and the share of scans that came from a fallback generator.

No fallback is used unless ``--fallback sphere`` is given; then its scans are reported in
the ``fallback`` column (and ``fallback_share``) and never hidden in a BS/HR row.

``--json`` prints only the rows as a JSON list of objects with the keys ``strategy``,
``world``, ``median_scans``, ``coverage_at_termination``, ``coverage_at_10``,
``coverage_at_30``, ``path_length_m``, ``selection_s`` (coverages in percent, means over
seeds as in the thesis; ``coverage_at_10`` / ``coverage_at_30`` are null when the budget is
smaller) and the extra keys listed in ``EXTRA_KEYS``.

``--speed`` instead times one selection (best of ``--repeat``) over 10 ... 100 sphere
candidates at the state after 5 scans of the bunny, uniform ray tracing against HRT levels
1 and 2, and prints the time per candidate count, the HRT speed-up and whether HRT chose the
same candidate.

``--png FILE`` draws the median c_a per scan with its inter-quartile band, one curve per
strategy and one panel per world.

``--set broad`` runs the broad object set of issue 20 instead of ``--worlds``: 17 objects
from pybullet_data (``benchmarks/broad_set.yaml``: the thesis objects, containers, a handle,
holes, thin and tall parts, a fixed random draw of ``random_urdfs``), each alone on the
pedestal (``benchmarks/broad_worlds.py``), sensed by ``--sensor laser_striper`` (default) or
``depth_camera``; ``--objects`` picks some of them. ``--missing DIR`` writes, for every run
whose final c_a is below 99 %, a picture of the observable surface with what the model misses
in red (``DIR/<world>_<strategy>_<seed>_<scans>.png``), and one after 10 scans when c_a(10) is
below 97 %.

Quick run (a few minutes on 2 cores)::

    .venv/bin/python benchmarks/reproduce_kriegel.py --quick

Full run::

    .venv/bin/python benchmarks/reproduce_kriegel.py --worlds bunny_pedestal,duck_pedestal,teddy_pedestal \\
        --seeds 0-9 --max-scans 30 --jobs 2 --png kriegel_table45.png

Broad set (issue 20; the table in docs/results.md, about 14 minutes)::

    .venv/bin/python benchmarks/reproduce_kriegel.py --set broad \\
        --strategies ig_quality/bs_hr,ig_quality/sphere,ig/sphere,quality/sphere,random/sphere \\
        --fallback sphere --seeds 0-4 --max-scans 30 --jobs 2 --png broad.png --missing broad_missing
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

QUICK_STRATEGIES = ["ig_quality/bs_hr", "ig_quality/sphere", "random/bs_hr"]
ROW_KEYS = ("strategy", "world", "median_scans", "coverage_at_termination", "coverage_at_10", "coverage_at_30",
            "path_length_m", "selection_s")
EXTRA_KEYS = ("notch", "estimate_at_termination", "min_coverage_last", "stop_reasons",
              "median_coverage_at_10", "median_coverage_at_30", "coverage_at_30_per_seed", "scans_taken",
              "rms_error_mm", "chamfer_mm", "coverage_auc",
              "coverage_estimate_final", "fallback_share", "max_selection_s", "max_candidates", "seeds",
              "variant", "normalise", "hierarchy")


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        elif part:
            out.append(int(part))
    return out


def utility_overrides(registry, strategy: str, variant: str | None, normalise: str | None,  # noqa: ANN001
                      hierarchy: int) -> dict:
    """utility_params for the command-line options that apply to this strategy's utility."""
    info = registry.get("strategy", strategy)
    utility_name = getattr(info.factory, "parts", ("", "", ""))[1]
    out: dict = {}
    if utility_name == "ig_quality":
        if variant:
            out["variant"] = variant
        if normalise:
            out["normalise"] = normalise
    if hierarchy and utility_name not in ("random", "fov_order"):
        out["hierarchy"] = hierarchy
    return out


def warm_up() -> None:
    """Compile (or load) the numba kernels once, so no selection time includes compilation."""
    from explore.mapping import TraceSettings, VoxelGrid, first_blocked, trace

    grid = VoxelGrid(np.full((4, 4, 4), 0.5, dtype=np.float32), np.zeros(3), 0.01)
    origins = np.tile([[-0.05, 0.02, 0.02]], (2, 1))
    dirs = np.tile([[1.0, 0.0, 0.0]], (2, 1))
    for level in (0, 1):
        trace(grid, origins, dirs, np.array([0, 1]), 2, 0.0, 1.0, TraceSettings(hierarchy=level), 1)
        trace(grid, origins, dirs, np.zeros(2, np.int64), 1, 0.0, 1.0, TraceSettings(hierarchy=level), 1)
    first_blocked(grid, origins, dirs, 1.0)


def run_one(job: tuple) -> dict:
    """One modelling run; returns its metrics (plus run time)."""
    world, strategy, seed, max_scans, overrides, fallback, threads, sensor_params, missing = job
    if threads:
        import numba

        numba.set_num_threads(threads)
    from explore.nbv import ModellingSession
    from explore.runtime import Registry
    from explore.sim import Simulation, load_world_spec

    registry = Registry.load()
    warm_up()
    params = {"utility_params": overrides} if overrides else {}
    spec = load_world_spec(world)
    if sensor_params:
        spec = dataclasses.replace(spec, sensor=dataclasses.replace(
            spec.sensor, params={**spec.sensor.params, **sensor_params}))
    with Simulation(spec, registry) as sim:
        session = ModellingSession(sim, (strategy, params), registry, seed=seed, max_scans=max_scans,
                                   continue_after_stop=True, fallback_generator=fallback)
        start = time.perf_counter()
        result = session.run()
        metrics = result.metrics
        metrics["run_s"] = time.perf_counter() - start
        if missing:
            missing_pictures(session, metrics, Path(missing), spec.name, strategy, seed)
    return metrics


def missing_pictures(session, metrics: dict, directory: Path, world: str, strategy: str, seed: int) -> None:  # noqa: ANN001
    """The uncovered surface after 10 scans when c_a(10) < 97 % and at the end when the final
    c_a < 99 % (issue 20's targets): ``<world>_<strategy>_<seed>_<scans>.png``."""
    from broad_worlds import missing_surface_png

    curve = metrics["coverage"]
    shown = [n for n, target in ((10, 0.97), (len(curve), 0.99)) if len(curve) >= n > 0 and curve[n - 1] < target]
    if not shown:
        return
    gt = session.ground_truth()
    for scans in dict.fromkeys(shown):
        name = f"{world}_{strategy.replace('/', '-')}_{seed}_{scans}.png"
        missing_surface_png(gt.observable, session.point_history[scans - 1], gt.tau, directory / name,
                            f"{world}, {strategy}, seed {seed}, after {scans} scans"
                            + (f" ({metrics['reason']})" if scans == len(curve) else ""))


def padded(curve: list[float], length: int) -> np.ndarray:
    """A coverage curve extended with its last value (a run that ended early keeps it)."""
    values = np.asarray(curve, dtype=float)
    if len(values) == 0:
        return np.zeros(length)
    return np.concatenate([values, np.full(max(0, length - len(values)), values[-1])])[:length]


def summarise(runs: list[dict], strategy: str, world: str, max_scans: int, options: dict) -> dict:
    n_s = np.array([r["n_s"] for r in runs], dtype=float)
    q1, q3 = np.percentile(n_s, [25, 75])
    notch = 1.57 * (q3 - q1) / np.sqrt(len(n_s))
    curves = np.array([padded(r["coverage"], max_scans) for r in runs])
    c_term = [curves[i, max(int(r["n_s"]), 1) - 1] for i, r in enumerate(runs)]
    estimate_term = [r["coverage_estimate"][max(int(r["n_s"]), 1) - 1] for r in runs if r["coverage_estimate"]]
    sel = [t for r in runs for t in r["selection_s"]]
    cands = [c for r in runs for c in r["selection_candidates"]]
    scans = [len(r["coverage"]) for r in runs]
    fallback = sum(r.get("fallback_scans", 0) for r in runs) / max(sum(scans), 1)
    return {
        "strategy": strategy,
        "world": world,
        "median_scans": float(np.median(n_s)),
        "coverage_at_termination": 100.0 * float(np.mean(c_term)),
        "estimate_at_termination": 100.0 * float(np.mean(estimate_term)) if estimate_term else float("nan"),
        "min_coverage_last": 100.0 * float(np.min(curves[:, -1])),
        "stop_reasons": sorted({str(r["reason"]) for r in runs}),
        "coverage_at_10": 100.0 * float(np.mean(curves[:, 9])) if max_scans >= 10 else None,
        "coverage_at_30": 100.0 * float(np.mean(curves[:, 29])) if max_scans >= 30 else None,
        "path_length_m": float(np.mean([r["scan_path_m"] for r in runs])),
        "selection_s": float(np.mean(sel)) if sel else 0.0,
        "notch": float(notch),
        "median_coverage_at_10": 100.0 * float(np.median(curves[:, min(10, max_scans) - 1])),
        "median_coverage_at_30": 100.0 * float(np.median(curves[:, 29])) if max_scans >= 30 else None,
        "coverage_at_30_per_seed": [100.0 * float(c) for c in curves[:, 29]] if max_scans >= 30 else None,
        "coverage_last": 100.0 * float(np.mean(curves[:, -1])),
        "scans_taken": float(np.mean(scans)),
        "rms_error_mm": 1000.0 * float(np.nanmean([r.get("rms_error_m", np.nan) for r in runs])),
        "chamfer_mm": 1000.0 * float(np.nanmean([r.get("chamfer_m", np.nan) for r in runs])),
        "coverage_auc": 100.0 * float(np.mean([r.get("coverage_auc", np.nan) for r in runs])),
        "coverage_estimate_final": 100.0 * float(np.mean([r["coverage_estimate"][-1] for r in runs])),
        "fallback_share": float(fallback),
        "max_selection_s": float(max(sel)) if sel else 0.0,
        "max_candidates": int(max(cands)) if cands else 0,
        "travel_m": float(np.mean([r["travel_m"] for r in runs])),
        "seeds": len(runs),
        "curves": curves,
        **options,
    }


def print_table(rows: list[dict], max_scans: int) -> None:
    last = "c_a(30)" if max_scans >= 30 else f"c_a({max_scans})"
    head = (f"{'Selection/Search':20s} {'world':18s} {'ñ_s':>5s} {'notch':>6s} {'c_a(n_s)':>8s} "
            f"{'c_a(10)':>7s} {'med(10)':>7s} {last:>8s} {'scans':>5s} {'l_s/m':>6s} {'t_nbs/s':>7s} "
            f"{'max t':>6s} {'cands':>5s} {'ē/mm':>5s} {'CD/mm':>5s} {'AUC%':>5s} {'ĉ_m%':>5s} {'fallbk':>6s}")
    print(head)
    print("-" * len(head))
    for r in rows:
        c10 = r["coverage_at_10"] if r["coverage_at_10"] is not None else float("nan")
        print(f"{r['strategy']:20s} {r['world']:18s} {r['median_scans']:5.1f} ±{r['notch']:5.2f} "
              f"{r['coverage_at_termination']:8.2f} {c10:7.2f} {r['median_coverage_at_10']:7.2f} "
              f"{r['coverage_last']:8.2f} {r['scans_taken']:5.1f} {r['path_length_m']:6.2f} "
              f"{r['selection_s']:7.3f} {r['max_selection_s']:6.2f} {r['max_candidates']:5d} "
              f"{r['rms_error_mm']:5.2f} {r['chamfer_mm']:5.2f} {r['coverage_auc']:5.1f} "
              f"{r['coverage_estimate_final']:5.1f} {100 * r['fallback_share']:5.1f}%")


def save_png(rows: list[dict], path: str, max_scans: int) -> None:
    """Median c_a per scan with the inter-quartile band; one panel per world."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worlds = list(dict.fromkeys(r["world"] for r in rows))
    columns = min(len(worlds), 4)
    lines = -(-len(worlds) // columns)
    fig, axes = plt.subplots(lines, columns, figsize=(6 * columns, 4.5 * lines), dpi=110, squeeze=False)
    for ax in axes.flat[len(worlds):]:
        ax.set_axis_off()
    x = np.arange(1, max_scans + 1)
    colours = {"random": "tab:gray", "ig": "tab:blue", "quality": "tab:green", "ig_quality": "tab:red"}
    styles = {"sphere": ":", "bs": "--", "bs_hr": "-"}  # colour = selection, line = search
    for ax, world in zip(axes.flat, worlds, strict=False):
        for r in (r for r in rows if r["world"] == world):
            curves = 100.0 * r["curves"]
            median = np.median(curves, axis=0)
            lo, hi = np.percentile(curves, [25, 75], axis=0)
            selection, _, search = r["strategy"].partition("/")
            line, = ax.plot(x, median, color=colours.get(selection), linestyle=styles.get(search, "-"),
                            label=f"{r['strategy']} (ñ_s {r['median_scans']:.0f})")
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.08)
        ax.set_title(f"{world} ({rows[0]['seeds']} seeds)")
        ax.set_xlabel("scans")
        ax.set_ylabel("c_a % (ground truth, τ = 3 mm)")
        ax.set_ylim(max(0.0, min(60.0, float(np.min([np.median(100.0 * r["curves"], axis=0)[-1] for r in rows
                                                          if r["world"] == world])) - 5.0)), 100.5)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def speed(repeat: int, world: str) -> int:
    """Selection time per candidate count, uniform vs HRT, at the state after 5 scans."""
    from explore.nbv import ModellingSession
    from explore.runtime import Registry
    from explore.sim import Simulation

    registry = Registry.load()
    warm_up()
    with Simulation(world, registry) as sim:
        session = ModellingSession(sim, "ig_quality/sphere", registry, seed=0, max_scans=5)
        session.run()
        sphere = registry.create("view_generator", "sphere", {"n_inclination": 10, "n_azimuth": 10}, "<speed>")
        pool = sphere.generate(session.ctx)
        print(f"{world}, PVS {session.pvs.resolution * 1000:.0f} mm, state after 5 scans, "
              f"{len(pool)} sphere scan paths (30 cm), best of {repeat}")
        print(f"{'candidates':>10s} {'beams':>8s} {'uniform/s':>9s} {'HRT a=1/s':>9s} {'speed-up':>8s} {'same':>5s} "
              f"{'HRT a=2/s':>9s} {'speed-up':>8s} {'same':>5s}")
        for count in (10, 25, 50, 81, 100):
            if count > len(pool):
                continue
            cands = pool[:: max(1, len(pool) // count)][:count]
            times, choice = {}, {}
            for level in (0, 1, 2):
                utility = registry.create("utility", "ig_quality", {"hierarchy": level}, "<speed>")
                utility.score(cands, session.ctx)
                best = np.inf
                for _ in range(repeat):
                    start = time.perf_counter()
                    scores = utility.score(cands, session.ctx)
                    best = min(best, time.perf_counter() - start)
                times[level], choice[level] = best, int(np.argmax(scores))
            beams = sum(len(c.beams_cache[1]) for c in cands)
            print(f"{count:10d} {beams:8d} {times[0]:9.3f} {times[1]:9.3f} {times[0] / times[1]:7.2f}x "
                  f"{'yes' if choice[1] == choice[0] else 'no':>5s} {times[2]:9.3f} {times[0] / times[2]:7.2f}x "
                  f"{'yes' if choice[2] == choice[0] else 'no':>5s}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default="bunny_pedestal,duck_pedestal,teddy_pedestal")
    parser.add_argument("--set", default=None,
                        help="run the broad object set (benchmarks/broad_set.yaml), the objects the stop was not "
                        "calibrated on (heldout), the objects neither was chosen on (field), or a set file of that "
                        "layout, instead of --worlds")
    parser.add_argument("--objects", default="", help="--set broad: comma list of the set's objects (default all)")
    parser.add_argument("--sensor", default="laser_striper", help="--set broad: laser_striper or depth_camera")
    parser.add_argument("--missing", default="", help="write pictures of the uncovered surface of every run "
                        "below 97 %% c_a after 10 scans or 99 %% at the end into this directory")
    parser.add_argument("--seeds", default="0-4", help="e.g. 0-9 or 0,3,5")
    parser.add_argument("--strategies", default="table4.5", help="comma list, 'table4.5' or 'iros'")
    parser.add_argument("--max-scans", type=int, default=30)
    parser.add_argument("--variant", choices=("need", "kriegel_literal"), default=None,
                        help="quality term of ig_quality (default: the strategy's, i.e. need)")
    parser.add_argument("--normalise", choices=("n_v", "max"), default=None,
                        help="normalisation of the ig_quality terms (default: the strategy's)")
    parser.add_argument("--hierarchy", type=int, default=0, help="hierarchical ray tracing level a")
    parser.add_argument("--fallback", default="none",
                        help="view generator for runs whose strategy has no candidate left (default none); "
                             "its scans are reported in the fallback column")
    parser.add_argument("--profile", default="", help="the sensor's profile (e.g. triangulation; default: the "
                        "world's own)")
    parser.add_argument("--sensor-param", action="append", default=[], metavar="KEY=VALUE",
                        help="a sensor parameter over the profile's, e.g. camera_shadow=false (repeatable)")
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel (each with one numba thread)")
    parser.add_argument("--quick", action="store_true",
                        help="bunny only, seeds 0-2, 3 strategies, 12 scans (a few minutes)")
    parser.add_argument("--json", action="store_true", help="print only the rows as JSON")
    parser.add_argument("--png", default="", help="write the coverage-vs-scans figure here")
    parser.add_argument("--runs-json", default="", help="write every run's curves (c_a, ĉ_m, d̄_m per scan), n_s, "
                        "stop reason and fallback scans to this file")
    parser.add_argument("--speed", action="store_true", help="time one selection per candidate count and exit")
    parser.add_argument("--repeat", type=int, default=5, help="--speed: repetitions (best is reported)")
    args = parser.parse_args(argv)

    if args.speed:
        return speed(args.repeat, args.worlds.split(",")[0])

    from explore_plugins.strategies import IROS, TABLE_4_5

    from explore.runtime import Registry

    registry = Registry.load()
    worlds = [w for w in args.worlds.split(",") if w]
    if args.set:
        from broad_worlds import FIELD_FILE, HELDOUT_FILE, SET_FILE, write_worlds

        world_dir = Path(tempfile.mkdtemp(prefix="broad_worlds_"))
        try:
            names = [n for n in args.objects.split(",") if n]
            set_file = {"broad": SET_FILE, "heldout": HELDOUT_FILE, "field": FIELD_FILE}.get(args.set) or Path(args.set)
            if not set_file.is_file():
                parser.error(f"--set: expected broad, heldout, field or a set file, got {args.set!r}")
            worlds = [str(p) for p in write_worlds(world_dir, args.sensor, names, set_file)]
        except ValueError as error:
            parser.error(str(error))
    from explore.core import BadInput, parse_assignment

    sensor_params = {"profile": args.profile} if args.profile else {}
    try:
        sensor_params.update(parse_assignment(item, "--sensor-param") for item in args.sensor_param)
    except BadInput as error:
        parser.error(str(error))
    from explore.sim import load_world_spec

    for world in worlds:  # every world (and --sensor-param) checked before the first run: one line, exit 2
        try:
            sensor = load_world_spec(world).sensor
            if sensor_params:
                registry.create("sensor", sensor.plugin, {**sensor.params, **sensor_params},
                                "--profile" if list(sensor_params) == ["profile"] else "--sensor-param")
        except BadInput as error:
            if args.set:  # the world was written from the set file: name that file and the object
                error = BadInput(f"{set_file} ({Path(world).stem.removeprefix('broad_')})", error.field, error.message)
            parser.error(error.line())
    if args.missing:
        try:
            Path(args.missing).mkdir(parents=True, exist_ok=True)
        except OSError as error:
            parser.error(f"--missing: cannot create {args.missing}: {error.strerror}")
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
    fallback = None if args.fallback in ("", "none") else args.fallback
    threads = 1 if args.jobs > 1 else 0
    jobs = [(world, strategy, seed, max_scans,
             utility_overrides(registry, strategy, args.variant, args.normalise, args.hierarchy), fallback, threads,
             sensor_params, args.missing)
            for world in worlds for strategy in strategies for seed in seeds]

    def report(metrics: dict) -> None:
        curve = [round(100 * c, 1) for c in metrics["coverage"]]
        print(f"  {metrics['strategy']} {metrics['world']} seed {metrics['seed']}: n_s={metrics['n_s']} c_a={curve} "
              f"l_s={metrics['scan_path_m']:.2f} m, fallback {metrics['fallback_scans']}, {metrics['run_s']:.1f} s, "
              f"ended: {metrics['reason']}",
              file=sys.stderr, flush=True)

    results: dict[tuple, dict] = {}
    if args.jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(args.jobs) as pool:
            for job, metrics in zip(jobs, pool.map(run_one, jobs), strict=True):
                results[job[:3]] = metrics
                report(metrics)
    else:
        for job in jobs:
            results[job[:3]] = run_one(job)
            report(results[job[:3]])
    if args.runs_json:
        keys = ("strategy", "world", "seed", "n_s", "reason", "coverage", "coverage_estimate", "coverage_off_support",
                "density", "sources", "fallback_scans", "scan_path_m")
        Path(args.runs_json).write_text(json.dumps([{k: m.get(k) for k in keys} for m in results.values()]))
    options = {"variant": args.variant or "need", "normalise": args.normalise or "max", "hierarchy": args.hierarchy}
    rows = [summarise([results[(w, s, seed)] for seed in seeds], s, Path(w).stem if args.set else w, max_scans, options)
            for w in worlds for s in strategies]
    if args.json:
        print(json.dumps([{k: r[k] for k in ROW_KEYS + EXTRA_KEYS} for r in rows], indent=1))
    else:
        print_table(rows, max_scans)
    if args.png:
        save_png(rows, args.png, max_scans)
        if not args.json:
            print(f"figure: {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
