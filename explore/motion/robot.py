"""Robot interface shared by the robot plugins.

A robot turns goal sensor poses into configurations (IK), configurations into sensor poses
(FK), and executes plans in the simulation. The free flyer is the sensor itself with an
unlimited workspace, as in the thesis benchmark.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.core import Array, Pose

if TYPE_CHECKING:
    from explore.sim import Simulation


class Robot(ABC):
    """Base class: configuration space, FK/IK, distance, execution."""

    kind = "robot"
    name = "robot"
    params: tuple = ()
    dof: int = 0

    def __init__(self, **values: Any) -> None:
        for key, value in values.items():
            setattr(self, key, value)
        self.sim: Simulation | None = None
        self.q: Array = np.zeros(self.dof)

    def attach(self, sim: Simulation) -> None:
        """Add the robot to the simulation (load bodies, read limits)."""
        self.sim = sim

    @abstractmethod
    def fk(self, q: Array) -> Pose:
        """world_T_sensor for configuration ``q``."""

    @abstractmethod
    def ik(self, world_T_sensor: Pose, rng: np.random.Generator | None = None) -> Array | None:
        """A configuration that puts the sensor at ``world_T_sensor``, or None if unreachable."""

    @property
    def sensor_pose(self) -> Pose:
        return self.fk(self.q)

    def distance(self, a: Array, b: Array) -> float:
        """Weighted configuration distance (Vasquez-Gomez Eq. 8); Euclidean by default."""
        return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))
