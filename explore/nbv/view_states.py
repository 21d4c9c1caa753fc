"""View/states of Vasquez-Gomez planning and the records of an NBVS run: a candidate robot state with its
filter numbers, plan and (expected) utility; what one iteration did; the stages of the filter pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.core import Array, Pose
from explore.motion import (
    MotionPlan,
)
from explore.nbv.expected_utility import ExpectedUtility

STAGES = (
    "sampled", "ray_hits", "collision_free", "visible", "registration", "surface", "top", "planned", "feasible",
)


# -- the view/state planning loop ------------------------------------------------------------
@dataclass
class ViewState:
    """One candidate view/state through the filter pipeline."""

    q: Array
    pose: Pose
    occ: float = 0.0  # oc_o
    unk: float = 0.0  # un_o
    reg: float = 0.0
    sur: float = 0.0
    pos: float = 0.0
    view: float = 0.0  # the utility plugin's view part at the candidate
    plan: MotionPlan | None = None
    nominal: np.ndarray | None = None  # (m + 1, dof) noise-free rollout of the controls
    length: float = float("nan")  # rho of the nominal path (Eq. 8)
    deterministic: float = 0.0  # g(x) (Eq. 4) at the nominal final state
    expected: ExpectedUtility | None = None
    score: float = 0.0
    margin: float = float("nan")  # lead over the runner-up when chosen (explore.core.decisions)


@dataclass
class ViewRecord:
    """What one NBVS iteration did."""

    index: int
    stages: dict[str, int]
    score: float
    deterministic: float
    margin: float
    expected: float | None
    feasible_share: float  # EU-feasible among the planned candidates
    path_length: float
    steps: int
    collided: bool
    collisions: list[tuple[str, ...]]
    coverage: float = float("nan")
    unknown_voxels: int = 0
    seconds: dict[str, float] = field(default_factory=dict)
    ess: float | None = None  # effective sample size of the chosen candidate's EU weights
    plan_attempts: int = 0  # planning queries of this iteration
    plan_successes: int = 0
    planning_s: float = 0.0  # their total time


class FixedBeams:
    """The world's sensor with its beam directions computed once.

    The utilities ask ``sensor.beams`` for every candidate (thousands per iteration, k per
    candidate in EU), and a depth camera recomputes its 19 200 pixel rays on each call;
    everything else is the sensor's own.
    """

    def __init__(self, sensor: Any) -> None:
        self._sensor = sensor
        self._local: np.ndarray | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sensor, name)

    def local_directions(self) -> np.ndarray:
        if self._local is None:
            self._local = np.asarray(self._sensor.local_directions())
        return self._local

    def beams(self, target: Any, beam_stride: int = 1, frame_stride: int = 1) -> Any:
        return type(self._sensor).beams(self, target, beam_stride, frame_stride)
