"""Pose validation of recognition hypotheses against the PVS (Kriegel thesis Sec. 3.4, Eq. 3.11).

A wrong match puts many model points into space the sensor has seen to be free (after Blodow
et al. 2009). The model mesh vertices are moved to the hypothesis pose and sorted by the
occupancy p of their voxel into V_free (p < 0.25), V_unk (0.25 <= p < 0.75) and V_occ
(p >= 0.75); the vote is

    v_h = (0.5 |V_unk| + |V_occ|) / (|V_free| + 0.5 |V_unk| + |V_occ|)        (Eq. 3.11)

and the hypothesis is rejected below 0.66 (the cluster is then treated as unknown).

The thesis' models are dense scanned meshes, whose vertices cover the surface. A CAD-like model
is not: a cube has 8 vertices, all on edges whose voxels beams grazing past the object see free,
so v_h falls in steps of 1/8 and the right pose can fail (0.625). :func:`vote_points` adds
surface samples on the large faces of a mesh that coarse.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.core import Points3, Pose, reaches, transform_points
from explore.mapping import sample_surface
from explore.sim import TriMesh

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


def vote_points(mesh: TriMesh, spacing: float, coarse: float = 3.0) -> Points3:
    """The points a model votes with (Eq. 3.11): its vertices; and, for a mesh whose vertices lie
    more than ``coarse`` x ``spacing`` apart on average (a CAD-like model: one vertex per more than
    ``coarse``² voxel areas of surface), about one area-uniform sample per ``spacing``² on every
    triangle larger than that (the same samples on every call).

    A denser mesh (a scanned or modelled one, the mug's 446 vertices over 1 900 voxel areas) votes
    with its vertices alone, as in the thesis: its large triangles are mostly the fans that close
    its holes, which span openings the sensor saw through (the shape sorter's holes), not surface.
    """
    area = mesh.triangle_areas()
    large = area > spacing * spacing
    if len(mesh.vertices) * (coarse * spacing) ** 2 >= area.sum() or not large.any():
        return np.asarray(mesh.vertices, dtype=np.float64)
    samples, _ = sample_surface(TriMesh(mesh.vertices, mesh.triangles[large]), spacing * spacing)
    return np.vstack([mesh.vertices, samples])


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
