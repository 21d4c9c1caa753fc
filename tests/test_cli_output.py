"""What the list and show commands print: JSON on request, whole names and paths when piped."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPLORE = Path(sys.executable).parent / "explore"


def _explore(*args: str, env: dict[str, str] | None = None) -> str:
    """stdout of ``explore ARGS`` run through a pipe (not a terminal), which must succeed."""
    done = subprocess.run([str(EXPLORE), *args], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "COLUMNS": "80", **(env or {})})
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def database(tmp_path_factory) -> Path:
    """A database holding a cube under a 70-character name."""
    import open3d as o3d

    from explore.sim.meshes import box_mesh

    folder = tmp_path_factory.mktemp("db")
    mesh = folder / "cube.ply"
    o3d.io.write_triangle_mesh(str(mesh), box_mesh([0.05, 0.04, 0.03]).to_open3d())
    _explore("db", "add", "a-modelled-object-with-a-name-far-longer-than-any-column-of-a-narrow-table", str(mesh),
             "--no-descriptors", "--db", str(folder / "objects.db"))
    return folder / "objects.db"


def test_every_list_and_show_command_prints_json(database) -> None:
    from explore.runtime import KINDS

    plugins = json.loads(_explore("plugins", "list", "--json"))
    assert {p["kind"] for p in plugins["plugins"]} == set(KINDS) and plugins["load_errors"] == {}
    strategy = next(p for p in plugins["plugins"] if p["name"] == "ig_quality/bs_hr")
    assert any(p["name"] == "utility_params" and p["default"] for p in strategy["params"])  # effective defaults
    worlds = {w["world"]: w for w in json.loads(_explore("worlds", "list", "--json"))}
    assert worlds["bunny_pedestal"]["robot"] == "free_flyer" and worlds["tabletop"]["objects"] == 6
    trees = {t["tree"] for t in json.loads(_explore("tree", "list", "--json"))}
    assert {"model_object", "scene_exploration", "nbvs_mobile", "table_patrol"} <= trees
    world = json.loads(_explore("worlds", "show", "bunny_pedestal", "--json"))
    assert world["sensor"]["plugin"] == "laser_striper" and len(world["bodies"]) == 2
    (record,) = json.loads(_explore("db", "list", "--db", str(database), "--json"))
    assert record["provenance"] == "given" and len(record["name"]) == 74
    shown = json.loads(_explore("db", "show", record["name"], "--db", str(database), "--json"))
    assert shown == record


def test_piped_lists_keep_whole_names_and_paths(database, tmp_path) -> None:
    """COLUMNS=80 and a pipe: nothing is cut with an ellipsis or wrapped onto a second line."""
    listed = _explore("db", "list", "--db", str(database))
    assert "a-modelled-object-with-a-name-far-longer-than-any-column-of-a-narrow-table" in listed
    assert "…" not in listed and len(listed.splitlines()) == 2
    deep = tmp_path / ("a-folder-with-a-long-name-" * 3) / "worlds"
    deep.mkdir(parents=True)
    (deep / "mine.yaml").write_text((ROOT / "worlds" / "duck_pedestal.yaml").read_text()
                                    .replace("name: duck_pedestal", "name: mine"))
    worlds = _explore("worlds", "list", env={"EXPLORE_WORLDS": str(deep)})
    line = next(line for line in worlds.splitlines() if line.startswith("mine "))
    assert line.endswith(str(deep / "mine.yaml")) and "…" not in worlds
    plugins = _explore("plugins", "list", "--params", "--kind", "strategy")
    assert "…" not in plugins and "utility_params" in plugins


def _commands():  # noqa: ANN202
    """(path, click command) of every explore command and sub-command."""
    import typer
    from explore_cli.main import app

    root = typer.main.get_command(app)
    stack = [((), root)]
    while stack:
        path, command = stack.pop()
        yield path, command
        for name, sub in getattr(command, "commands", {}).items():
            stack.append(((*path, name), sub))


def test_every_command_help_is_consistent() -> None:
    """Every option and argument has help text, flags show no value type, units in brackets survive,
    and an output path is always the ``--out`` option."""
    import typer

    seen = 0
    for path, command in _commands():
        ctx = typer.Context(command, info_name=" ".join(("explore", *path)))
        text = command.get_help(ctx)
        assert "<bool>" not in text, path
        for param in command.params:
            assert param.name == "help" or getattr(param, "help", None), (path, param.name, "no help text")
            if param.name == "out":
                assert "--out" in param.opts, (path, "an output path is the --out option")
            seen += 1
    assert seen > 60
    scan = dict(_commands())[("scan",)]
    assert "x,y,z [m]" in scan.get_help(typer.Context(scan, info_name="explore scan"))


def test_the_run_summary_names_contacts_and_motions_that_failed() -> None:
    """A scene run's closing line counts what went wrong on the way, not only the objects."""
    from explore_cli.run_cmd import summary_line

    scene = {"objects_total": 2, "objects_explained": 1, "views": 9, "collisions": 0, "moves_failed": 3,
             "objects": [{"result": "recognised"}, {"result": "unknown"}]}
    assert summary_line(scene) == "objects 1/2 explained  1 recognised, 1 unknown  views=9  moves_failed=3"
    assert summary_line({**scene, "collisions": 1, "moves_failed": 0}).endswith("views=9  collisions=1")
