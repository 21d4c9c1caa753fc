"""``explore run TREE --world W``: an exploration run with a live view of the tree."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Group
from rich.markup import escape
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

_STATUS_STYLE = {"SUCCESS": "green", "FAILURE": "red", "RUNNING": "yellow", "INVALID": "dim"}


def _tree_text(root: Any) -> Text:
    text = Text()

    def visit(node: Any, depth: int) -> None:
        status = node.status.value
        line = Text("  " * depth + f"{node.name}  ")
        line.append(status.lower(), style=_STATUS_STYLE.get(status, ""))
        if node.feedback_message and status != "INVALID":
            line.append(f"  {node.feedback_message}", style="dim")
        text.append(line)
        text.append("\n")
        for child in node.children:
            visit(child, depth + 1)

    visit(root, 0)
    return text


def live_view(root: Any, context: Any) -> Group:
    """The tree with node statuses plus the run's numbers (scans, ĉ_m, ground-truth c_a, time)."""
    stats = Table.grid(padding=(0, 2))
    stats.add_column(style="bold")
    stats.add_column()
    stats.add_row("world", context.sim.spec.name)
    running = [n.name for n in root.iterate() if n.status.value == "RUNNING" and not n.children]
    stats.add_row("step", ", ".join(running) or "-")
    if context.activity:
        stats.add_row("doing", context.activity)
    for provider in context.state.values():
        if hasattr(provider, "live_stats"):
            for key, value in provider.live_stats().items():
                stats.add_row(key, value if isinstance(value, str) else f"{value:.3g}")
    stats.add_row("elapsed", f"{context.elapsed():.1f} s")
    return Group(Panel(_tree_text(root), title="tree"), Panel(stats, title="run"))


def register(app: typer.Typer) -> None:
    @app.command("run")
    def run(
        tree: Annotated[str, typer.Argument(help="Tree name or file (see `explore tree list`).")],
        world: Annotated[str, typer.Option("--world", "-w", help="World name or file.")],
        strategy: Annotated[str | None, typer.Option("--strategy", help="NBV strategy (plugin kind strategy).")] = None,
        planner: Annotated[str | None, typer.Option("--planner", help="Motion planner plugin.")] = None,
        robot: Annotated[str | None, typer.Option("--robot", help="Robot plugin (default: the world's).")] = None,
        sensor: Annotated[str | None, typer.Option("--sensor", help="Sensor plugin (default: the world's).")] = None,
        seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (same seed, same metrics).")] = 0,
        max_scans: Annotated[int | None, typer.Option("--max-scans", min=1, help="Stop after this many scans.")] = None,
        set_: Annotated[list[str] | None, typer.Option("--set", help="key=value override (repeatable).")] = None,
        out: Annotated[Path | None, typer.Option("--out", "-o", help="Run directory (default runs/...).")] = None,
        rerun: Annotated[Path | None, typer.Option("--rerun", help="Also log to a Rerun .rrd file.")] = None,
        video: Annotated[bool, typer.Option("--video/--no-video", help="Also write run.mp4: each scan's depth image, "
                                            "the growing model and a PVS slice.")] = False,
        quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No live view.")] = False,
        threads: Annotated[int, typer.Option("--threads", min=0, help="Threads of the numeric kernels (0: every "
                                             "core); the results are the same for any number.")] = 0,
        planning_clock: Annotated[str, typer.Option(
            "--planning-clock", help="Motion-planning time limits in 'work' done (the same seed gives the same "
            "run under any CPU load) or 'wall' time.")] = "work",
    ) -> int:
        """Run an exploration tree on a world; exit 0 on success, 1 if the mission failed."""
        from rich.live import Live

        from explore.core import STYLE, SUCCESS, Terminated
        from explore.runtime import RunConfig, default_out_dir, execute
        from explore.runtime.progress import ProgressLines

        from .main import console, registry

        config = RunConfig(
            tree=tree, world=world, strategy=strategy, planner=planner, robot=robot, sensor=sensor, seed=seed,
            max_scans=max_scans, settings=RunConfig.parse_settings(set_ or []), out=out, rerun=rerun,
            planning_clock=planning_clock, threads=threads, video=video,
        )
        reg = registry()
        interactive = console.is_terminal and not quiet
        last = {"t": 0.0}
        lines = ProgressLines()

        def plain_progress(root: Any, context: Any) -> None:
            line = None if quiet else lines(root, context)
            if line is not None:
                console.print(line, markup=False, highlight=False)

        if config.out is None:
            config.out = default_out_dir(config)
        try:
            if interactive:
                with Live(console=console, auto_refresh=False, transient=False) as live:

                    def on_tick(root: Any, context: Any) -> None:
                        now = time.perf_counter()
                        if now - last["t"] > 0.1 or root.status.value != "RUNNING":
                            last["t"] = now
                            live.update(live_view(root, context), refresh=True)

                    result = execute(config, reg, on_tick)
            else:
                result = execute(config, reg, plain_progress)
        except KeyboardInterrupt as stop:  # SIGINT, or SIGTERM (Terminated): the results so far are written
            what, code = ("terminated", 143) if isinstance(stop, Terminated) else ("interrupted", 130)
            if (config.out / "metrics.json").exists():
                console.print(f"[magenta]{what}[/magenta]: results so far in {escape(str(config.out))}", markup=True)
            raise typer.Exit(code) from None
        style = STYLE.get(result.status, "red")
        console.print(f"[{style}]{result.status}[/{style}]: {escape(result.reason)}", markup=True)
        console.print(summary_line(result.metrics), markup=False, highlight=False)
        console.print(f"results: {result.out_dir}", highlight=False, soft_wrap=True)
        if rerun is not None:
            console.print(f"rerun recording: {rerun} (view with: rerun {rerun})", highlight=False, soft_wrap=True)
        if video:
            console.print(f"video: {result.out_dir / 'run.mp4'}", highlight=False, soft_wrap=True)
        return 0 if result.status == SUCCESS else 1


def summary_line(metrics: dict[str, Any]) -> str:
    """One line of the numbers a run is judged by: the modelling's, or the scene's objects."""
    if "objects_total" in metrics:  # a scene run
        counts: dict[str, int] = {}
        for row in metrics.get("objects") or []:
            counts[row.get("result", "?")] = counts.get(row.get("result", "?"), 0) + 1
        parts = [f"objects {metrics.get('objects_explained', 0)}/{metrics['objects_total']} explained",
                 ", ".join(f"{n} {k}" for k, n in sorted(counts.items())), f"views={metrics.get('views')}"]
        for key in ("collisions", "moves_failed"):
            if metrics.get(key):
                parts.append(f"{key}={metrics[key]}")
        return "  ".join(p for p in parts if p)
    keys = ("scans", "coverage", "coverage_estimate", "path_length_m")
    values = {k: metrics.get(k) for k in keys if metrics.get(k) is not None}
    if metrics.get("collisions"):
        values["collisions"] = metrics["collisions"]
    return " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items())


def register_demo(app: typer.Typer) -> None:
    @app.command("demo")
    def demo(
        max_scans: Annotated[int, typer.Option("--max-scans", min=1, help="Scan budget (the thesis' 30).")] = 30,
        seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed.")] = 0,
    ) -> int:
        """The main job: model the bunny on its pedestal with Kriegel's NBS loop (< 3 min)."""
        from datetime import datetime

        out = Path("runs") / f"{datetime.now():%Y%m%d-%H%M%S}-demo-model_object-bunny_pedestal"
        run_fn = app.registered_commands
        command = next(c for c in run_fn if c.name == "run").callback
        return command(
            tree="model_object", world="bunny_pedestal", strategy=None, planner=None, robot=None, sensor=None,
            seed=seed, max_scans=max_scans, set_=None, out=out, rerun=None, quiet=False,
        )
