"""Rooms that grow (issue 23, item 3): 1, 2 or 4 tables carrying 5 to 40 objects.

Every world is a room with walls, box tables 1.2 x 0.8 x 0.72 m on a 3 m grid and objects
from ``pybullet_data`` on them; the region is the whole room up to 1.1 m (explored at 5 mm in
the sparse PVS). The objects are drawn with a fixed seed, all different: every third one is
known (in the database at the start: the duck, the mug, the teddy, then ``random_urdfs``
shapes), the others are unknown (the broad set's named objects first, then ``random_urdfs``). Each object gets a cell
of a 4 x 3 grid on its table (26 x 24 cm cells: at least 12 cm between neighbours, so that the
segmentation can part them) and a random yaw.

The robots are those of ``two_tables`` (``mobile_base``: a pan-tilt RGB-D camera on a 1.3 m
mast) and ``scene_small_mm`` (``mobile_manipulator``: the camera in the iiwa's hand), both with
the planar localisation laser and legs of a metre; the camera is a Kinect-like 320 x 240 RGB-D camera.
A ``random_urdfs`` shape has the colour its URDF gives it (its mesh's material is plain grey): among
them are shape twins of different colour, which only colour tells apart.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pybullet_data
import yaml

TABLE = (1.2, 0.8, 0.72)
SPACING = 3.0  # between table centres
KNOWN = (("duck", "duck.obj", [90, 0, 0], 0.10), ("mug", "objects/mug.urdf", [0, 0, 0], 0.11),
         ("teddy", "teddy_vhacd.urdf", [90, 0, 0], 0.12))
NAMED = (("bunny", "bunny.obj", [90, 0, 0], 0.12), ("sorter", "toys/shape_sorter.obj", [0, 0, 0], 0.10),
         ("torus", "torus/torus_textured.obj", [60, 0, 0], 0.10), ("lego", "lego/lego.urdf", [90, 0, 0], 0.08),
         ("jenga", "jenga/jenga.urdf", [0, 90, 0], 0.12), ("ball", "soccerball.obj", [0, 0, 0], 0.10),
         ("dish", "toys/concave_box.obj", [0, 0, 0], 0.12), ("domino", "domino/domino.urdf", [0, 0, 30], 0.08))
GRID = (4, 3)  # cells per table along x, y
ROBOTS: dict[str, dict[str, Any]] = {
    "mobile_base": {"plugin": "mobile_base", "params": {"laser_height": 0.2, "replan_distance": 0.25}},
    "mobile_manipulator": {"plugin": "mobile_manipulator",
                           "params": {"laser_height": 0.2, "keep_base": True, "drive_clearance": 0.15,
                                      "replan_distance": 0.25}},
}
SENSOR = {"plugin": "depth_camera", "params": {"profile": "kinect", "width": 320, "height": 240, "min_range": 0.3,
                                                "max_range": 3.5, "color": True}}


def urdf_colour(draw: int) -> list[float]:
    """The RGBA colour the URDF of ``random_urdfs/<draw>`` gives its shape."""
    text = (Path(pybullet_data.getDataPath()) / f"random_urdfs/{draw:03d}/{draw:03d}.urdf").read_text()
    return [float(v) for v in re.search(r'<color rgba="([^"]+)"', text).group(1).split()]


def table_centres(tables: int) -> list[tuple[float, float]]:
    """Table centres: one table north of the start, two east and west of it, four around it."""
    h = SPACING / 2.0
    return {1: [(0.0, 0.8)], 2: [(-h, 0.0), (h, 0.0)], 4: [(-h, -h), (h, -h), (-h, h), (h, h)]}[tables]


def room_size(tables: int) -> tuple[float, float]:
    return {1: (4.0, 4.0), 2: (6.0, 4.0), 4: (6.0, 6.0)}[tables]


def room_problem(tables: int, objects: int) -> str | None:
    """What is wrong with a room of ``tables`` tables and ``objects`` objects (None: nothing)."""
    if tables not in (1, 2, 4):
        return f"tables must be 1, 2 or 4, got {tables}"
    if not 1 <= objects <= tables * GRID[0] * GRID[1]:
        return f"{objects} objects do not fit on {tables} tables (1 to {GRID[0] * GRID[1]} each)"
    return None


def _objects(tables: int, count: int, seed: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng(seed)
    problem = room_problem(tables, count)
    if problem:
        raise ValueError(problem)
    draws = [(f"random_{d:03d}", f"random_urdfs/{d:03d}/{d:03d}.obj", [0, 0, 0], 0.10)
             for d in rng.choice(1000, size=count, replace=False)]
    colours = {label: urdf_colour(int(label[7:])) for label, *_ in draws}
    known, unknown = list(KNOWN) + draws[::2], list(NAMED) + draws[1::2]
    cells = [(t, i, j) for t in range(tables) for i in range(GRID[0]) for j in range(GRID[1])]
    # objects spread evenly over the tables: the k-th object on table k mod tables
    per_table = [[c for c in cells if c[0] == t] for t in range(tables)]
    for table_cells in per_table:
        rng.shuffle(table_cells)
    out = []
    for k in range(count):
        label, source, rpy, size = known.pop(0) if k % 3 == 0 else unknown.pop(0)
        t, i, j = per_table[k % tables].pop()
        cx, cy = table_centres(tables)[t]
        x = cx + (i - (GRID[0] - 1) / 2.0) * 0.26 + rng.uniform(-0.02, 0.02)
        y = cy + (j - (GRID[1] - 1) / 2.0) * 0.24 + rng.uniform(-0.02, 0.02)
        yaw = float(rng.uniform(0.0, 360.0))
        turned = [rpy[0], rpy[1], round(rpy[2] + yaw, 1)]
        out.append({"name": label, "source": source, "size": size, "rpy_deg": turned,
                    "position": [round(x, 3), round(y, 3)], "on_top_of": f"table_{t + 1}",
                    **({"color": colours[label]} if label in colours else {}),
                    **({"known": True} if k % 3 == 0 else {})})
    return out


def world_data(tables: int, objects: int, robot: str = "mobile_base", seed: int = 2026) -> dict[str, Any]:
    """The world file contents of a room with ``tables`` tables and ``objects`` objects."""
    if robot not in ROBOTS:
        raise ValueError(f"--robot: {robot!r} is not one of {', '.join(ROBOTS)}")
    width, depth = room_size(tables)
    walls = [
        {"name": "floor", "box": [width, depth, 0.02], "position": [0.0, 0.0, -0.01]},
        {"name": "wall_north", "box": [width + 0.2, 0.1, 1.2], "position": [0.0, depth / 2 + 0.05, 0.6]},
        {"name": "wall_south", "box": [width + 0.2, 0.1, 1.2], "position": [0.0, -depth / 2 - 0.05, 0.6]},
        {"name": "wall_east", "box": [0.1, depth, 1.2], "position": [width / 2 + 0.05, 0.0, 0.6]},
        {"name": "wall_west", "box": [0.1, depth, 1.2], "position": [-width / 2 - 0.05, 0.0, 0.6]},
    ]
    tabletops = [{"name": f"table_{t + 1}", "box": list(TABLE), "position": [cx, cy, TABLE[2] / 2]}
                 for t, (cx, cy) in enumerate(table_centres(tables))]
    start = [0.0, -1.0, 0.0, 90.0] if tables == 1 else [0.0, 0.0, 0.0, 90.0]
    return {
        "name": f"room_{tables}t_{objects}o",
        "description": f"issue 23's growing rooms: {tables} table(s), {objects} objects "
                       f"(every third known), {robot}",
        "environment": walls + tabletops,
        "objects": _objects(tables, objects, seed),
        "region": {"min": [-width / 2 + 0.05, -depth / 2 + 0.05, 0.0],
                   "max": [width / 2 - 0.05, depth / 2 - 0.05, 1.1]},
        "robot": {**ROBOTS[robot], "base": start},
        "sensor": SENSOR,
    }


GROWTH = ((1, 5), (2, 10), (4, 20), (4, 40))  # (tables, objects): objects and room volume grow together


def write_world(directory: Path, tables: int, objects: int, robot: str = "mobile_base") -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    data = world_data(tables, objects, robot)
    path = directory / f"{data['name']}_{robot}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120))
    return path


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tables", type=int, choices=(1, 2, 4), default=4)
    parser.add_argument("--objects", type=int, default=40)
    parser.add_argument("--robot", choices=tuple(ROBOTS), default="mobile_base")
    parser.add_argument("--out", type=Path, default=Path("."))
    args = parser.parse_args()
    problem = room_problem(args.tables, args.objects)
    if problem:
        parser.exit(2, f"error: --objects: {problem}\n")
    print(write_world(args.out, args.tables, args.objects, args.robot))
