"""Records of planned and executed motions: the plan (path, controls), its execution and its collisions."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from explore.core import Array, Pose


# -- records ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class CollisionEvent:
    """A collision of the executed motion with the true world (environment + objects)."""

    step: int
    time: float
    config: Array
    bodies: tuple[str, ...]


@dataclass
class MotionPlan:
    """A planned motion: configurations (m, dof) and optionally per-step velocity controls.

    ``controls`` (k, nc) are held for ``dt`` seconds each; ``controls`` is None for a purely
    geometric path (the robot derives controls with ``controls_from_path``).
    """

    path: np.ndarray
    controls: np.ndarray | None = None
    dt: float = 0.0
    planner: str = ""
    planning_time: float = 0.0
    exact: bool = True
    length: float = 0.0  # weighted configuration distance (Vasquez-Gomez Eq. 8)

    @property
    def start(self) -> Array:
        return self.path[0]

    @property
    def goal(self) -> Array:
        return self.path[-1]


@dataclass
class Execution:
    """What happened when a plan was executed (noisy, checked against the true world)."""

    configs: np.ndarray  # (m, dof) executed configurations, the first is the start
    times: Array  # (m,)
    controls: np.ndarray  # (k, nc) nominal controls
    noise: np.ndarray  # (k, nc) sampled control errors (zeros without noise)
    sigma: Array  # (nc,) noise standard deviations
    log_prob: float  # sum of log p(eps) (Eq. 2/3), for expected utility
    final: Array  # final configuration
    sensor_pose: Pose  # world_T_sensor at ``final``
    collisions: list[CollisionEvent] = field(default_factory=list)
    completed: bool = True  # False if the run stopped at a collision

    @property
    def collided(self) -> bool:
        return bool(self.collisions)
