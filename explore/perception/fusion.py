"""Multi-view fusion of recognition hypotheses (Kriegel thesis Sec. 5.6.2): nearest-neighbour pose clustering
with a distance and an angle cut-off, then the weighted mean of the heaviest cluster (explore.core.mean_pose)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from explore.core import (
    Array,
    Pose,
    mean_pose,
)
from explore.perception.arrays import as_pose


@dataclass(frozen=True)
class FusedPose:
    """Average of the largest pose cluster: ``pose``, member indices and their total weight."""

    pose: Pose
    members: np.ndarray
    weight: float
    clusters: int


def fuse_poses(
    poses: Sequence[Pose] | np.ndarray,
    weights: Sequence[float] | Array | None = None,
    cluster_radius: tuple[float, float] = (0.01, 5.0),
) -> FusedPose:
    """Fuse per-view pose hypotheses of one object on SE(3) (Kriegel thesis Sec. 5.6.2).

    Nearest-neighbour clustering: two poses are neighbours if their translations differ by at
    most ``cluster_radius[0]`` metres *and* their rotations by at most ``cluster_radius[1]``
    degrees; clusters are the connected components. The cluster with the largest total weight
    is averaged: weighted mean of translations and weighted chordal L2 mean of rotations
    (the thesis uses Pham et al. 2011; the chordal mean is its closed-form counterpart).
    """
    stack = np.stack([as_pose(p) for p in poses]) if len(poses) else np.zeros((0, 4, 4))
    if len(stack) == 0:
        raise ValueError("fuse_poses needs at least one pose")
    w = np.ones(len(stack)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if len(w) != len(stack) or np.any(~np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("need one finite, non-negative weight per pose (not all zero)")
    t = stack[:, :3, 3]
    r = stack[:, :3, :3]
    dt = np.linalg.norm(t[:, None] - t[None], axis=2)
    cos = (np.einsum("aij,bij->ab", r, r) - 1.0) / 2.0  # trace(Ra^T Rb)
    dr = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    adjacency = (dt <= cluster_radius[0]) & (dr <= cluster_radius[1])
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(adjacency, directed=False)
    totals = np.bincount(labels, weights=w, minlength=count)
    best = int(np.argmax(totals))
    members = np.nonzero(labels == best)[0]
    return FusedPose(mean_pose(stack[members], w[members]), members, float(totals[best]), int(count))
