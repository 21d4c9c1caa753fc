"""Robot plugins: the free-flying sensor (more bases in later modules)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from explore.robot import Robot
from explore.typed import Array, Pose


class FreeFlyer(Robot):
    """The sensor itself, flying freely (unlimited workspace, as in the thesis benchmark)."""

    name = "free_flyer"
    dof = 6

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.pose: Pose = np.eye(4)

    def fk(self, q: Array) -> Pose:
        pose = np.eye(4)
        pose[:3, 3] = q[:3]
        pose[:3, :3] = Rotation.from_rotvec(q[3:6]).as_matrix()
        return pose

    def ik(self, world_T_sensor: Pose, rng: np.random.Generator | None = None) -> Array | None:
        return np.concatenate([world_T_sensor[:3, 3], Rotation.from_matrix(world_T_sensor[:3, :3]).as_rotvec()])
PLUGINS = [FreeFlyer]
