"""``explore scan``: one simulated acquisition written as PLY (and PNG)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from explore.core import BadInput, check_output

DEFAULT_OUT = Path("runs/scan.ply")
MAX_COORDINATE = 1e6  # m; beyond it float32 ray casting has no millimetres left


def _vector(text: str, option: str) -> np.ndarray:
    from explore.core import parse_vector

    try:
        vector = parse_vector(text)
    except ValueError as error:
        raise BadInput(option, None, str(error)) from None
    if np.abs(vector).max() > MAX_COORDINATE:
        raise BadInput(option, text, f"a coordinate beyond ±{MAX_COORDINATE:g} m")
    return vector


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
        sweep: Annotated[
            float, typer.Option("--sweep", min=0.0, max=10.0, help="Scan path length for line sensors [m].")
        ] = 0.3,
        png: Annotated[Path | None, typer.Option("--png", help="Also save a picture of the scan.")] = None,
        seed: Annotated[int, typer.Option("--seed", min=0, help="Noise seed.")] = 0,
        replace: Annotated[bool, typer.Option("--replace", help="Overwrite an existing --out or --png file.")] = False,
    ) -> None:
        """Simulate one scan of a world and write the measured points."""
        from explore.core import parse_assignment, save_points_png
        from explore.runtime import attach_plugins
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
            given = dict(parse_assignment(item) for item in (set_ or []))
            params.update(given)
            name = sensor or sim.spec.sensor.plugin
            attach_plugins(sim, reg, {"sensor": (name, params)}, {"sensor": given}, prefixed=False)
            spec = sim.spec
            gap = float(np.abs(eye - np.clip(eye, spec.region_min, spec.region_max)).max())
            if gap > sim.sensor.max_range + sweep:
                raise BadInput("--look-from", look_from, f"{gap:.3g} m from the world's region, beyond the "
                               f"{name}'s range of {sim.sensor.max_range:g} m")
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
