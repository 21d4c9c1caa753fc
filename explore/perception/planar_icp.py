"""Sub-centimetre planar scan matching: point-to-plane ICP over (x, y, yaw) of a laser scan against
the known environment's upright surfaces, after the correlative match has found the basin.

A correlative match (:class:`~explore.perception.incremental_graph.LikelihoodField`, Olson 2009)
scores a 2 cm field at 1 cm / 0.25 deg steps: robust, but its answer is a grid cell, 1-2 cm and a
fraction of a degree off. Refining it continuously on the surfaces themselves, as Cartographer
refines its correlative match with a least-squares scan matcher (Hess et al. 2016), takes the
error down to what the beams' noise averaged over the scan allows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from explore.core import Array, Points3, Pose


class PlanarSurface:
    """Upright surface samples with their normals (m, 3 each), ready for :meth:`refine`: the
    horizontal part of each normal and the samples' kd-tree are built once, for every match."""

    def __init__(self, surface: Points3, normals: Points3) -> None:
        flat = np.asarray(normals, dtype=float)[:, :2]
        length = np.linalg.norm(flat, axis=1)
        usable = length > 0.5
        self.points = np.asarray(surface, dtype=float)[usable]
        self.normals = flat[usable] / length[usable, None]
        self.tree = cKDTree(self.points)

    def refine(
        self,
        points: Points3,
        pivot: Array,
        gates: Sequence[float] = (0.03, 0.015),
        iterations: int = 10,
        huber: float = 0.01,
        min_inliers: int = 30,
    ) -> tuple[Pose, int] | None:
        """The planar motion (about the vertical through ``pivot``) that puts the scan ``points``
        (n, 3, world) on the surface, and the number of points that fitted within the last gate;
        None when fewer than ``min_inliers`` did.

        Gauss-Newton on r_i = n_i . (R(yaw)(p_i - c) + c + t - q_i) with Huber weights (``huber``, m),
        the nearest sample q_i within each of ``gates`` in turn. A direction no surface constrains
        (one wall seen face-on) is left where the start put it (the normal equations are damped).
        """
        src = np.asarray(points, dtype=float)
        centre = np.asarray(pivot, dtype=float)[:2]
        yaw, shift = 0.0, np.zeros(2)
        inliers = 0
        for gate in gates:
            for _ in range(iterations):
                moved = _moved(src, centre, yaw, shift)
                distance, index = self.tree.query(moved, distance_upper_bound=gate)
                ok = np.isfinite(distance)
                inliers = int(ok.sum())
                if inliers < min_inliers:
                    return None
                n, q, p = self.normals[index[ok]], self.points[index[ok], :2], moved[ok, :2]
                r = np.einsum("ij,ij->i", n, p - q)
                arm = p - centre - shift  # R(yaw)(p_i - c): what a turn about the pivot moves
                jac = np.column_stack([n, n[:, 1] * arm[:, 0] - n[:, 0] * arm[:, 1]])
                w = np.minimum(1.0, huber / np.maximum(np.abs(r), 1e-12))
                h = jac.T @ (jac * w[:, None]) + 1e-6 * len(r) * np.diag([1.0, 1.0, 0.01])
                step = np.linalg.solve(h, -(jac.T @ (w * r)))
                shift, yaw = shift + step[:2], yaw + float(step[2])
                if np.linalg.norm(step[:2]) < 1e-5 and abs(step[2]) < 1e-6:
                    break
        out = np.eye(4)
        c, s = math.cos(yaw), math.sin(yaw)
        out[:2, :2] = [[c, -s], [s, c]]
        out[:2, 3] = centre - out[:2, :2] @ centre + shift
        return out, inliers


def refine_planar(points: Points3, surface: Points3, normals: Points3, pivot: Array,
                  **options: float | Sequence[float]) -> tuple[Pose, int] | None:
    """:meth:`PlanarSurface.refine` against ``surface`` and ``normals`` (a surface used once)."""
    return PlanarSurface(surface, normals).refine(points, pivot, **options)  # type: ignore[arg-type]


def _moved(points: Points3, centre: Array, yaw: float, shift: Array) -> Points3:
    c, s = math.cos(yaw), math.sin(yaw)
    out = points.copy()
    out[:, :2] = (points[:, :2] - centre) @ np.array([[c, s], [-s, c]]) + centre + shift
    return out
