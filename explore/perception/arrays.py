"""Point and pose arguments checked at the boundary of the registration functions."""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import (
    Points3,
    Pose,
)


def as_points(points: Any, name: str) -> Points3:
    out = np.asarray(points, dtype=np.float64)
    if out.ndim != 2 or out.shape[1] != 3:
        raise ValueError(f"{name} must be an (n, 3) array, got shape {out.shape}")
    return out


def as_pose(pose: Any | None) -> Pose:
    if pose is None:
        return np.eye(4)
    out = np.asarray(pose, dtype=np.float64)
    if out.shape != (4, 4) or not np.all(np.isfinite(out)):
        raise ValueError("a pose must be a finite 4x4 matrix")
    return out
