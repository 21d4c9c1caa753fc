"""A utility and a strategy that uses it."""

from __future__ import annotations

import numpy as np

from explore.api import ENTROPY, RAY_PARAMS, Candidate, Param, PlanningContext, RayUtility, make_strategy


class TravelIG(RayUtility):
    """Information gain discounted by travel: IG * exp(-distance / scale)."""

    name = "travel_ig"
    params = RAY_PARAMS + (
        Param("scale", float, 0.5, "m", "travel distance that divides the gain by e", low=1e-3),
    )

    def combine(self, acc: np.ndarray, candidates: list[Candidate], ctx: PlanningContext) -> np.ndarray:
        here = ctx.sensor_pose[:3, 3] if ctx.sensor_pose is not None else ctx.region_centre
        travel = np.array([np.linalg.norm(c.start[:3, 3] - here) for c in candidates])
        return acc[:, ENTROPY] * np.exp(-travel / self.scale)


TravelStrategy = make_strategy(
    "example/travel_ig",
    "Example: the view sphere with travel-discounted IG (from explore-example).",
    "sphere",
    "travel_ig",
    "coverage_target",
    {},
    {"scale": 0.5},
    {"coverage": 0.8, "density": 0.2, "n_abort": 30},
)
