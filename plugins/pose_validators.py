"""Built-in pose_validator plugins."""

from __future__ import annotations

from typing import Any

from explore.api import PoseValidator
from explore.core import Param, Points3, Pose
from explore.perception import ACCEPT_FROM, FREE_BELOW, OCCUPIED_FROM, Validation, pvs_votes


class PvsVotes(PoseValidator):
    """PVS votes of the model vertices at the pose: v_h >= 0.66 accepts (Kriegel Eq. 3.11)."""

    name = "pvs_votes"
    params = (
        Param("threshold", float, ACCEPT_FROM, "", "accept if v_h >= threshold (thesis: 0.66)", low=0.0, high=1.0),
        Param("free_below", float, FREE_BELOW, "", "a vertex is free if p < this", low=0.0, high=1.0),
        Param("occupied_from", float, OCCUPIED_FROM, "", "a vertex is occupied if p >= this", low=0.0, high=1.0),
    )

    def __init__(self, **values: Any) -> None:
        self.threshold = float(values.get("threshold", ACCEPT_FROM))
        self.free_below = float(values.get("free_below", FREE_BELOW))
        self.occupied_from = float(values.get("occupied_from", OCCUPIED_FROM))
        if self.free_below > self.occupied_from:
            raise ValueError("free_below must not exceed occupied_from")

    def validate(self, pvs: Any, model_vertices: Points3, pose: Pose) -> Validation:
        """Score, vertex counts and accept/reject of the model vertices at ``pose`` (world_T_model)."""
        return pvs_votes(pvs, model_vertices, pose, self.threshold, self.free_below, self.occupied_from)


PLUGINS = [PvsVotes]
