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
