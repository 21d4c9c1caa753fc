"""Görner's table patrol: surround a known table's centre and look from every side.

:func:`known_tables` finds the tables of the known environment (Görner assumes table
positions are known); :func:`surround` takes the views of one exploration step around a focus
point c: observation poses p_θ^d(c) at up to ``2π/step`` angles counter-clockwise from the
robot's bearing, at each angle the closest reachable distance between ``d_min`` and ``d_max``
(Görner §4.1-4.2: 12 angles, 0.7-1.5 m), one view each.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from explore.core import Array
from explore.scene.views import as_target, surround_poses


def known_tables(sim: Any, min_height: float = 0.3, max_height: float = 1.2, min_size: float = 0.5,
                 max_size: float = 2.5) -> dict[str, Array]:
    """Environment bodies shaped like tables -> the centre of their top face (focus point c).

    A table's top lies between ``min_height`` and ``max_height`` and both horizontal extents
    between ``min_size`` and ``max_size`` (walls, floors, chairs and boxes fail one of them).
    """
    out: dict[str, Array] = {}
    for body in sim.bodies:
        if body.is_object:
            continue
        lo, hi = body.mesh.bounds
        extent = hi - lo
        if min_height <= hi[2] <= max_height and np.all((extent[:2] >= min_size) & (extent[:2] <= max_size)):
            out[body.name] = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), float(hi[2])])
    return out


def surround(scene: Any, focus: Array, d_min: float = 0.7, d_max: float = 1.5, step: float = 0.5,
             name: str = "the table") -> list[Any]:
    """One exploration step of Görner's surround-point view planning; the views taken (the pose
    graph's corrections of earlier views are re-integrated once, after the last). Observation poses
    the view budget leaves untried are noted in ``scene.budget_cuts``."""
    robot = scene.sim.robot
    here = scene.mover.believed_pose()
    height = robot.camera_height
    if height is None:  # sensors without a mast: eyes 0.6 m above the table top
        height = float(focus[2]) + 0.6
    start = 0.0 if here is None else math.atan2(here[1, 3] - focus[1], here[0, 3] - focus[0])
    taken = []
    rings = surround_poses(focus, float(height), d_min, d_max, step, start)
    for index, ring in enumerate(rings):
        if scene.budget_left <= 0:
            scene.budget_cuts.append(f"{index} of the {len(rings)} observation poses around {name} tried")
            break
        for pose in ring:
            target = as_target(scene.sim.sensor, pose, None, float(np.linalg.norm(pose[:3, 3] - focus)))
            reached = scene.mover.reach(target)
            if reached is None:
                continue
            view = scene.viewing.add_view(reached[0], "surround", configs=reached[1], defer=True)
            if view is not None:
                taken.append(view)
            break
    scene.viewing.settle()
    return taken
