"""``explore scan``: one simulated acquisition written as PLY (and PNG)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from explore.core import BadInput, check_output

DEFAULT_OUT = Path("runs/scan.ply")


def _vector(text: str, option: str) -> np.ndarray:
    from explore.core import parse_vector

    try:
        return parse_vector(text)
    except ValueError as error:
        raise BadInput(option, None, str(error)) from None


def register(app: typer.Typer) -> None:
    @app.command("scan")
    def scan(
        world: Annotated[str, typer.Option("--world", "-w", help="World name or file.")],
        look_from: Annotated[str, typer.Option("--look-from", help="Sensor position x,y,z [m].")],
        look_at: Annotated[str, typer.Option("--look-at", help="Point the sensor looks at x,y,z [m].")],
        out: Annotated[Path | None, typer.Option(
            "--out", "-o", help=f"Output point cloud (.ply; default {DEFAULT_OUT}, overwritten).")] = None,
        sensor: Annotated[
            str | None, typer.Option("--sensor", "-s", help="Sensor plugin (default: the world's).")
        ] = None,
        set_: Annotated[
            list[str] | None, typer.Option("--set", help="Sensor parameter key=value (repeatable).")
        ] = None,
        sweep: Annotated[float, typer.Option("--sweep", min=0.0, help="Scan path length for line sensors [m].")] = 0.3,
        png: Annotated[Path | None, typer.Option("--png", help="Also save a picture of the scan.")] = None,
        seed: Annotated[int, typer.Option("--seed", min=0, help="Noise seed.")] = 0,
        replace: Annotated[bool, typer.Option("--replace", help="Overwrite an existing --out or --png file.")] = False,
    ) -> None:
        """Simulate one scan of a world and write the measured points."""
        from explore.core import parse_assignment, save_points_png
        from explore.sim import Simulation, target_for

        from .main import console, out_path, registry

        eye, target = _vector(look_from, "--look-from"), _vector(look_at, "--look-at")
        if np.linalg.norm(target - eye) < 1e-6:
            raise BadInput("--look-at", None, "must differ from --look-from")
        for option, path, suffix in (("--out", out, ".ply"), ("--png", png, ".png")):
            if path is not None:
                check_output(path, option, suffixes=(suffix,), replace=replace)
        out = out or DEFAULT_OUT
        reg = registry()
        with Simulation(world, None) as sim:
            params = dict(sim.spec.sensor.params) if sensor in (None, sim.spec.sensor.plugin) else {}
            params.update(parse_assignment(item) for item in (set_ or []))
            name = sensor or sim.spec.sensor.plugin
            sim.attach_plugins(reg, sensor=(name, params))
            started = time.perf_counter()
            result = sim.sensor.acquire(sim, target_for(sim.sensor, eye, target, sweep), np.random.default_rng(seed))
            elapsed = time.perf_counter() - started
        hits = int(result.hits.sum())
        if hits == 0:
            raise BadInput("--look-from", look_from, f"the {name} saw nothing from there (no beam returned; "
                           f"the world's region is around {', '.join(f'{v:.2f}' for v in sim.spec.region_center)})")
        result.write_ply(out_path(out))
        console.print(f"{name}: {len(result)} beams, {hits} returns in {elapsed * 1000:.0f} ms -> {out}")
        if png is not None:
            save_points_png(result.points(), out_path(png), f"{sim.spec.name}: {name}, {hits} points")
            console.print(f"picture -> {png}")
