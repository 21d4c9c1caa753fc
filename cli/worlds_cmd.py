"""``explore worlds list|show``."""

from __future__ import annotations

from typing import Annotated

import typer

from explore.core import BadInput

from .output import JsonOption, print_json, print_rows


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Inspect world files.", no_args_is_help=True)

    @sub.command("list")
    def list_worlds(as_json: JsonOption = False) -> None:
        """List the world files in the search path (./worlds, the shipped worlds, $EXPLORE_WORLDS)."""
        from explore.sim import list_worlds as find
        from explore.sim import load_world_spec

        from .main import console

        worlds = []
        for path in find():
            try:
                spec = load_world_spec(path)
            except BadInput as error:  # one broken file does not hide the others
                worlds.append({"world": path.stem, "file": str(path), "error": error.line()})
                continue
            worlds.append({"world": spec.name, "objects": len(spec.objects), "robot": spec.robot.plugin,
                           "sensor": spec.sensor.plugin, "file": str(path)})
        if as_json:
            print_json(worlds)
            return
        print_rows(("world", "objects", "robot", "sensor", "file"), [
            [w["world"], "-", "-", "-", f"{w['file']} (broken, see below)"] if "error" in w else
            [w["world"], str(w["objects"]), w["robot"], w["sensor"], w["file"]] for w in worlds
        ])
        for w in worlds:
            if "error" in w:
                console.print(f"broken world file: {w['error']}")

    @sub.command("show")
    def show(world: Annotated[str, typer.Argument(help="World name or file.")], as_json: JsonOption = False) -> None:
        """Print objects (with sizes), robot, sensor and region of a world."""
        from explore.sim import Simulation

        from .main import console, registry

        with Simulation(world, registry()) as sim:
            info = sim.describe()
        if as_json:
            print_json(info)
            return
        console.print(f"{info['name']}  {info['file']}")
        if info["description"]:
            console.print(info["description"])
        print_rows(("body", "role", "size [m]", "centre [m]", "triangles"), [
            [row["name"], row["role"], str(row["size_m"]), str(row["center_m"]), str(row["triangles"])]
            for row in info["bodies"]
        ])
        console.print(f"robot:  {info['robot']['plugin']} {info['robot']['params'] or ''}")
        console.print(f"sensor: {info['sensor']['plugin']} {info['sensor']['params'] or ''}")
        console.print(f"region: min {info['region']['min']}  max {info['region']['max']}")

    app.add_typer(sub, name="worlds")
