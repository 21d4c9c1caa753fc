"""``explore compare``: the product of runs over worlds, strategies, planners, robots, settings variants and seeds.

Every name is checked before the first run starts (one line, exit code 2 when wrong).
``explore compare --plot-only DIR`` redraws the report from ``DIR/results.csv``.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from explore.core import FINISHED, BadInput, Terminated, check_output


def _names(text: str | None, option: str, allow_empty: bool = True) -> list[str | None]:
    """A comma-separated list; absent means [None] (the tree's / world's default)."""
    if text is None:
        return [None]
    items = [t.strip() for t in text.split(",")]
    if not any(items):
        raise BadInput(option, None, "empty list")
    if "" in items:
        raise BadInput(option, text, "empty name in the list")
    if len(set(items)) != len(items):
        raise BadInput(option, text, "a name appears twice")
    return list(items)


def _check_plugins(registry: Any, kind: str, names: list[str | None], option: str) -> None:
    for name in names:
        if name is not None:
            registry.get(kind, name, option)


def parse_variants(items: list[str]) -> dict[str, dict[str, Any]]:
    """``NAME: key=value; key=value`` per ``--variant`` (no settings: the grid's own): named sets of settings that
    a grid compares like strategies (e.g. Vasquez-Gomez's DU without noise, DU-MU and EU-MU)."""
    from explore.core import parse_assignment
    from explore.runtime.compare_grid import slug

    variants: dict[str, dict[str, Any]] = {}
    for item in items:
        name, colon, body = item.partition(":")
        name = name.strip()
        if not colon or not name or slug(name) != name:  # the name is its run ids' folder part as it is
            raise BadInput("--variant", item, "expected NAME: key=value; key=value (NAME: letters, digits, . _ + -)")
        if name in variants:
            raise BadInput("--variant", item, f"the variant {name!r} is given twice")
        variants[name] = dict(parse_assignment(part.strip(), "--variant") for part in body.split(";") if part.strip())
    return variants


def build_grid(
    tree: str | None,
    worlds: str | None,
    strategies: str | None,
    planners: str | None,
    robots: str | None,
    seeds: str,
    max_scans: int | None,
    settings: list[str],
    timeout: float,
    plugins: list[str],
    threads: int,
    videos: bool = False,
    variants: list[str] | None = None,
) -> tuple[Any, Any]:
    """Validate every argument against the registry and the search paths; return (grid, registry)."""
    from explore.runtime import Grid, RunConfig, check_inputs, find_tree, load_tree, make_registry
    from explore.sim import find_world, load_world_spec

    if not tree:
        raise BadInput("--tree", None, "missing (a tree name or file, see `explore tree list`)")
    if worlds is None:
        raise BadInput("--worlds", None, "missing (comma-separated world names, see `explore worlds list`)")
    world_names = _names(worlds, "--worlds")
    seed_list = parse_seeds(seeds)
    if not (math.isfinite(timeout) and timeout > 0):
        raise BadInput("--timeout", str(timeout), "must be a positive finite number of seconds")
    if max_scans is not None and max_scans < 1:
        raise BadInput("--max-scans", str(max_scans), "must be at least 1")
    if threads < 1:
        raise BadInput("--threads", str(threads), "must be at least 1")
    plugin_specs = []
    for item in plugins:
        where, _, attr = item.rpartition(":")
        plugin_specs.append(f"{Path(where).resolve()}:{attr}" if where.endswith(".py") else item)
    registry = make_registry(plugin_specs)
    tree_path = find_tree(tree)
    load_tree(tree_path, registry)
    resolved_worlds = []
    for name in world_names:
        path = find_world(name)
        load_world_spec(path)
        resolved_worlds.append(str(path.resolve()))
    strategy_names = _names(strategies, "--strategies")
    planner_names = _names(planners, "--planners")
    robot_names = _names(robots, "--robots")
    _check_plugins(registry, "strategy", strategy_names, "--strategies")
    _check_plugins(registry, "motion_planner", planner_names, "--planners")
    _check_plugins(registry, "robot", robot_names, "--robots")
    named = parse_variants(variants or [])
    runs = (len(world_names) * len(strategy_names) * len(planner_names) * len(robot_names) * max(1, len(named))
            * len(seed_list))
    if runs > Grid.MAX_RUNS:
        raise BadInput("explore compare", None, f"the grid has {runs} runs, more than {Grid.MAX_RUNS}; "
                                                "split it into several comparisons")
    parsed_settings = RunConfig.parse_settings(settings)
    for world in resolved_worlds:  # every --set and --variant key and value, as each run will check them
        for strategy, planner, robot, (name, extra) in itertools.product(
                strategy_names, planner_names, robot_names, list(named.items()) or [("", {})]):
            try:
                check_inputs(RunConfig(tree=str(tree_path), world=world, strategy=strategy, planner=planner,
                                       robot=robot, max_scans=max_scans, settings={**parsed_settings, **extra}),
                             registry)
            except BadInput as error:  # a variant's own setting: say which variant
                if error.source == "--set" and any(str(error.field).startswith(key) for key in extra):
                    raise BadInput(f"--variant {name}", error.field, error.message) from None
                raise
    grid = Grid(
        tree=str(tree_path.resolve()), worlds=resolved_worlds, strategies=strategy_names, planners=planner_names,
        robots=robot_names, seeds=seed_list, max_scans=max_scans,
        settings=parsed_settings, timeout=timeout, plugins=plugin_specs, threads=threads, videos=videos,
        variants=named,
    )
    return grid, registry


def parse_seeds(text: str) -> list[int]:
    """``N`` (seeds 0..N-1), ``A-B`` (A to B inclusive) or ``a,b,c``: the seeds of a grid."""
    from explore.runtime import Grid

    value = text.strip()
    try:
        if "," in value:
            seeds = [int(part) for part in value.split(",")]
        elif "-" in value.lstrip("-"):
            first, last = (int(part) for part in value.split("-", 1))
            if last < first:
                raise BadInput("--seeds", text, f"the range ends before it starts ({last} < {first})")
            seeds = range(first, last + 1)
        else:
            count = int(value)
            if count < 1:
                raise BadInput("--seeds", text, "needs at least 1 seed")
            seeds = range(count)
    except ValueError:
        raise BadInput("--seeds", text, "expected N, a range A-B or a list a,b,c of whole numbers") from None
    if len(seeds) > Grid.MAX_RUNS:  # before a list of them is built
        raise BadInput("--seeds", text, f"more seeds than a grid may have runs ({Grid.MAX_RUNS})")
    seeds = list(seeds)
    if any(seed < 0 for seed in seeds):
        raise BadInput("--seeds", text, "seeds are whole numbers from 0")
    if len(set(seeds)) != len(seeds):
        raise BadInput("--seeds", text, "a seed is listed twice")
    return seeds


def register(app: typer.Typer) -> None:
    @app.command("compare")
    def compare_cmd(
        tree: Annotated[str | None, typer.Option(
            "--tree", help="Tree name or file run by every run. (required unless --plot-only)")] = None,
        worlds: Annotated[str | None, typer.Option(
            "--worlds", help="Comma-separated world names or files. (required unless --plot-only)")] = None,
        strategies: Annotated[
            str | None, typer.Option("--strategies", help="Comma-separated NBV strategies (default: the tree's).")
        ] = None,
        planners: Annotated[
            str | None, typer.Option("--planners", help="Comma-separated motion planners (default: the tree's).")
        ] = None,
        robots: Annotated[
            str | None, typer.Option("--robots", help="Comma-separated robots (default: each world's).")
        ] = None,
        seeds: Annotated[str, typer.Option(
            "--seeds", help="Seeds of every combination: N (0..N-1), a range A-B or a list such as 0,3,7.")] = "1",
        jobs: Annotated[int, typer.Option("--jobs", "-j", help="Concurrent runs (0: one per core).")] = 0,
        executor: Annotated[str, typer.Option("--executor", help="Executor plugin: local or ray.")] = "local",
        ray_address: Annotated[
            str | None, typer.Option("--ray-address", help="Ray cluster address (default: a local Ray instance).")
        ] = None,
        ray_token_file: Annotated[
            Path | None, typer.Option("--ray-token-file", help="File with the Ray cluster's auth token (token "
                                      "authentication; else RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token).")
        ] = None,
        max_scans: Annotated[int | None, typer.Option("--max-scans", help="Scan budget of every run.")] = None,
        timeout: Annotated[float, typer.Option("--timeout", help="Seconds before a run is ended (timeout).")] = 1800.0,
        threads: Annotated[int, typer.Option("--threads", help="Numeric threads per run.")] = 1,
        set_: Annotated[list[str] | None, typer.Option("--set", help="key=value for every run (repeatable).")] = None,
        variant: Annotated[list[str] | None, typer.Option(
            "--variant", help="A named set of settings compared like a strategy: 'NAME: key=value; key=value' "
            "(repeatable; each over --set).")] = None,
        plugin: Annotated[
            list[str] | None, typer.Option("--plugin", help="Extra plugin object FILE.py:OBJ or MODULE:OBJ.")
        ] = None,
        out: Annotated[Path | None, typer.Option("--out", "-o", help="Results folder (resumable).")] = None,
        video: Annotated[bool, typer.Option("--video/--no-video", help="One video per method (its first seed's "
                                            "run.mp4) in the report; the results are the same.")] = False,
        plot_only: Annotated[
            Path | None, typer.Option("--plot-only", help="Only redraw the report of an existing results folder.")
        ] = None,
    ) -> int:
        """Run a grid of runs (resumable) and write results.csv, summary.md, plots and report.html."""
        from explore.runtime import RESULTS_FILE, compare, read_results, write_report

        from .main import console

        if plot_only is not None:
            if not (plot_only / RESULTS_FILE).is_file():
                raise BadInput(str(plot_only), None, f"no {RESULTS_FILE} here (run `explore compare --out DIR` first)")
            written = write_report(plot_only, read_results(plot_only / RESULTS_FILE))
            console.print(f"report: {written['report.html']}", highlight=False, soft_wrap=True)
            return 0
        grid, registry = build_grid(
            tree, worlds, strategies, planners, robots, seeds, max_scans, set_ or [], timeout, plugin or [], threads,
            video, variant or [],
        )
        if out is None:
            raise BadInput("--out", None, "missing (the results folder)")
        check_output(out, "--out", folder=True)
        if jobs < 0:
            raise BadInput("--jobs", str(jobs), "must be 0 (one per core) or more")
        params: dict[str, Any] = {"jobs": jobs}
        if executor == "ray":
            params["address"] = ray_address or ""
            params["token_file"] = str(ray_token_file or "")
        elif ray_address or ray_token_file:
            option = "--ray-address" if ray_address else "--ray-token-file"
            raise BadInput(option, ray_address or str(ray_token_file), "only applies to --executor ray")
        runner = registry.create("executor", executor, params, "--executor", "executor")
        runner.check()  # e.g. connect to the cluster before the first run starts
        try:
            rows = compare(grid, out, runner, console=console)
        except KeyboardInterrupt as stop:  # SIGINT, or SIGTERM (Terminated)
            console.print(
                f"{'terminated' if isinstance(stop, Terminated) else 'interrupted'}: finished runs are in "
                f"{out / RESULTS_FILE}; run the same command to resume", soft_wrap=True, highlight=False,
            )
            return 143 if isinstance(stop, Terminated) else 130
        bad = [r for r in rows if r["status"] not in FINISHED]
        console.print(
            f"{len(rows)} runs ({len(bad)} crashed or timed out); results: {out / RESULTS_FILE}; "
            f"report: {out / 'report.html'}",
            highlight=False, soft_wrap=True,
        )
        return 1 if bad else 0
