"""Pose validation of recognition hypotheses against the PVS (Kriegel thesis Sec. 3.4, Eq. 3.11).

A wrong match puts many model points into space the sensor has seen to be free (after Blodow
et al. 2009). The model mesh vertices are moved to the hypothesis pose and sorted by the
occupancy p of their voxel into V_free (p < 0.25), V_unk (0.25 <= p < 0.75) and V_occ
(p >= 0.75); the vote is

    v_h = (0.5 |V_unk| + |V_occ|) / (|V_free| + 0.5 |V_unk| + |V_occ|)        (Eq. 3.11)

and the hypothesis is rejected below 0.66 (the cluster is then treated as unknown).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Points3, Pose, reaches, transform_points

FREE_BELOW = 0.25
OCCUPIED_FROM = 0.75
ACCEPT_FROM = 0.66


@dataclass(frozen=True)
class Validation:
    """Result of :func:`pvs_votes`: score v_h, vertex counts per class and the decision."""

    score: float
    free: int
    unknown: int
    occupied: int
    accepted: bool
    margin: float = float("nan")  # v_h minus the threshold

    def as_dict(self) -> dict[str, Any]:
        return {"score": self.score, "free": self.free, "unknown": self.unknown,
                "occupied": self.occupied, "accepted": self.accepted, "margin": self.margin}


def pvs_votes(
    pvs: Any,
    model_vertices: Points3,
    pose: Pose,
    threshold: float = ACCEPT_FROM,
    free_below: float = FREE_BELOW,
    occupied_from: float = OCCUPIED_FROM,
) -> Validation:
    """Validate a pose hypothesis with the PVS votes of the model vertices (Eq. 3.11).

    Parameters
    ----------
    pvs : object with ``probability(points) -> (n,) float`` (``explore.mapping.pvs.PVS``; 0.5 outside)
    model_vertices : (n, 3) float
        Mesh vertices in the model frame.
    pose : (4, 4) float
        world_T_model of the hypothesis.
    threshold : float
        Accept if v_h >= threshold (thesis: 0.66).
    """
    vertices = np.asarray(model_vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"model_vertices must be (n, 3), got shape {vertices.shape}")
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError("pose must be a finite 4x4 matrix")
    if not 0.0 <= free_below <= occupied_from <= 1.0:
        raise ValueError("need 0 <= free_below <= occupied_from <= 1")
    if len(vertices) == 0:
        return Validation(0.0, 0, 0, 0, False, -threshold)
    p = np.asarray(pvs.probability(transform_points(pose, vertices)), dtype=np.float64)
    free = int(np.count_nonzero(p < free_below))
    occupied = int(np.count_nonzero(p >= occupied_from))
    unknown = len(p) - free - occupied
    denominator = free + 0.5 * unknown + occupied
    score = (0.5 * unknown + occupied) / denominator if denominator > 0 else 0.0
    return Validation(float(score), free, unknown, occupied, reaches(score, threshold), float(score - threshold))
