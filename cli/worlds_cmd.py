"""``explore worlds list|show``."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from explore.core import BadInput


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Inspect world files.", no_args_is_help=True)

    @sub.command("list")
    def list_worlds() -> None:
        """List the world files in the search path (./worlds, the shipped worlds, $EXPLORE_WORLDS)."""
        from explore.sim import list_worlds as find
        from explore.sim import load_world_spec

        from .main import console

        table = Table(box=None, header_style="bold")
        for column in ("world", "objects", "robot", "sensor", "file"):
            table.add_column(column)
        broken = []
        for path in find():
            try:
                spec = load_world_spec(path)
            except BadInput as error:  # one broken file does not hide the others
                broken.append(error.line())
                table.add_row(path.stem, "-", "-", "-", f"{path} (broken, see below)")
                continue
            table.add_row(spec.name, str(len(spec.objects)), spec.robot.plugin, spec.sensor.plugin, str(path))
        console.print(table)
        for line in broken:
            console.print(f"broken world file: {line}")

    @sub.command("show")
    def show(world: Annotated[str, typer.Argument(help="World name or file.")]) -> None:
        """Print objects (with sizes), robot, sensor and region of a world."""
        from explore.sim import Simulation

        from .main import console, registry

        with Simulation(world, registry()) as sim:
            info = sim.describe()
        console.print(f"{info['name']}  {info['file']}")
        if info["description"]:
            console.print(info["description"])
        table = Table(box=None, header_style="bold")
        for column in ("body", "role", "size [m]", "centre [m]", "triangles"):
            table.add_column(column)
        for row in info["bodies"]:
            table.add_row(row["name"], row["role"], str(row["size_m"]), str(row["center_m"]), str(row["triangles"]))
        console.print(table)
        console.print(f"robot:  {info['robot']['plugin']} {info['robot']['params'] or ''}")
        console.print(f"sensor: {info['sensor']['plugin']} {info['sensor']['params'] or ''}")
        console.print(f"region: min {info['region']['min']}  max {info['region']['max']}")

    app.add_typer(sub, name="worlds")
